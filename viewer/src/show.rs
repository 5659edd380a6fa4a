//! From what the session says to what is drawn: tool shapes, the organ's
//! colour field and its bar, and overlay text.

use crate::colour::{self, ColourBy};
use crate::overlay::{self, Image};
use crate::render::{ToolShape, tip_state};
use crate::session::Session;
use three_d::vec3;

/// The organ coloured by a field: a colour per vertex and the bar.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// What the colours show.
    pub colour_by: ColourBy,
    /// One colour per vertex of the mesh state.
    pub colours: Vec<[u8; 3]>,
    /// The bar's range (its bottom and top) in `unit`.
    pub range: [f32; 2],
    /// The field's largest value in the frame, in `unit`.
    pub max: f32,
    /// The unit.
    pub unit: &'static str,
}

impl Field {
    /// The colour bar's image.
    pub fn bar(&self) -> Image {
        let title = match self.colour_by {
            ColourBy::Displacement => "displacement",
            ColourBy::Tissue => "",
        };
        overlay::colour_bar(title, self.range, self.unit, colour::viridis)
    }
}

/// The field `colour_by` asks for on the latest mesh state (None: the
/// tissue's own colour, or no rest shape yet to measure from).
pub fn field(session: &Session, colour_by: ColourBy) -> Option<Field> {
    match colour_by {
        ColourBy::Tissue => None,
        ColourBy::Displacement => {
            if session.info.rest_m.is_empty() {
                return None;
            }
            let u = colour::displacement_mm(&session.positions_m, &session.info.rest_m);
            let range = colour::range(&u);
            Some(Field {
                colour_by,
                colours: colour::colours(&u, range),
                range,
                max: u.iter().copied().fold(0.0, f32::max),
                unit: "mm",
            })
        }
    }
}

/// One shape per declared tool that the simulation reports, plus the tool
/// the viewer drives (`driven`: tool index and tip) before the simulation
/// reports it.
pub fn tool_shapes(session: &Session, driven: Option<(usize, [f64; 3])>) -> Vec<ToolShape> {
    let mut out = Vec::new();
    for (i, decl) in session.info.tools.iter().enumerate() {
        let reported = session.tools.get(i).filter(|t| t.position_m != [0.0; 3]);
        let (end, flags, force) = match (reported, driven) {
            (Some(t), _) => (t.position_m, t.flags, t.force_n),
            (None, Some((k, tip))) if k == i => (tip, 0, [0.0; 3]),
            _ => continue,
        };
        let v = |a: [f64; 3]| vec3(a[0] as f32, a[1] as f32, a[2] as f32);
        out.push(ToolShape {
            fulcrum_m: v(decl.fulcrum_m),
            end_m: v(end),
            radius_m: decl.radius_m as f32,
            flags,
            force_n: v(force),
        });
    }
    out
}

/// The overlay's lines, each with its colour: a tool's line in its tip's
/// colour and naming its state (the tip colours' legend), with its force;
/// then the arrows' scale.
pub fn overlay_lines(
    session: &Session,
    now_ns: u64,
    driving: Option<usize>,
    mm_per_n: f32,
) -> Vec<(String, [u8; 3])> {
    let s = &session.stats;
    let name = &session.info.name;
    let mut lines = vec![if name.is_empty() {
        "scene: waiting for the simulation's scene".to_string()
    } else {
        format!("scene: {name}")
    }];
    if session.sim_alive(now_ns) {
        lines.push(format!(
            "sim {:.0} Hz, {} mesh frames in, surface v{}",
            s.sim_hz, session.frames, session.topology_version
        ));
    } else {
        lines.push("sim: waiting for a simulation".into());
    }
    if s.haptic_hz > 0.0 {
        lines.push(format!("haptic {:6.0} Hz", s.haptic_hz));
        lines.push(format!(
            "sample age p50 {:.0} us  p99 {:.0} us",
            s.sample_age_p50_us, s.sample_age_p99_us
        ));
        lines.push(format!(
            "tick lateness p50 {:.0} us  p99 {:.0} us",
            s.lateness_p50_us, s.lateness_p99_us
        ));
    } else if session.daemon_present() {
        // Telemetry comes in batches of 64 ticks: a rate needs two.
        lines.push("haptic: daemon running, waiting for telemetry".into());
    } else {
        lines.push("haptic: no daemon".into());
    }
    let mut out: Vec<(String, [u8; 3])> = lines.into_iter().map(|l| (l, overlay::TEXT)).collect();
    for (i, t) in session.tools.iter().enumerate() {
        let f = (t.force_n[0].powi(2) + t.force_n[1].powi(2) + t.force_n[2].powi(2)).sqrt();
        let name = session.info.tools.get(i).map_or("?", |d| d.name.as_str());
        let (c, state) = tip_state(t.flags);
        out.push((
            format!("tool {i} {name}: {state}, {f:.2} N"),
            [c.r, c.g, c.b],
        ));
    }
    if !session.tools.is_empty() {
        out.push((format!("force arrows {mm_per_n} mm per N"), overlay::TEXT));
    }
    if let Some(i) = driving {
        out.push((
            format!("mouse drives tool {i}: move, W/S depth, left grip, X cut, 1-4 tool"),
            overlay::TEXT,
        ));
    }
    out
}
