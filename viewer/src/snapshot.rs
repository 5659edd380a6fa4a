//! `viewer --snapshot FILE.png`: waits for the session's mesh, renders one
//! frame into an offscreen framebuffer on a surfaceless EGL context (no
//! display needed) and writes it as PNG.

use crate::camera::{View, bounds, framing};
use crate::egl::{Headless, HeadlessError};
use crate::overlay;
use crate::render::arrow_length_m;
use crate::render::{Layers, Renderer};
use crate::session::Session;
use crate::show::{field, overlay_lines, tool_shapes};
use shared::monotonic_ns;
use std::path::{Path, PathBuf};

use std::time::Duration;
use three_d::{DepthTexture2D, Interpolation, RenderTarget, Texture2D, Viewport, Wrapping};

/// Why a snapshot failed.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// No headless OpenGL.
    #[error(transparent)]
    Headless(#[from] HeadlessError),
    /// Nothing to draw in time.
    #[error(
        "no mesh state in session {session:?} within {wait_s} s: is `sim-server run --session {session}` running?"
    )]
    NoMesh {
        /// The session.
        session: String,
        /// How long it waited.
        wait_s: f64,
    },
    /// The simulation runs, but all of its tissue was cut away.
    #[error(
        "the simulation in session {session:?} runs, but its tissue has no surface left (every tetrahedron was cut away): nothing to draw"
    )]
    AllCut {
        /// The session.
        session: String,
    },
    /// The PNG could not be written.
    #[error("cannot write {path}: {reason}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
}

/// What a snapshot showed.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SnapshotReport {
    /// Image width (px).
    pub width: u32,
    /// Image height (px).
    pub height: u32,
    /// Vertices of the mesh state drawn.
    pub vertices: usize,
    /// Surface triangles drawn.
    pub triangles: usize,
    /// Of which made by cuts.
    pub cut_triangles: usize,
    /// The topology version drawn.
    pub topology_version: u64,
    /// Pixels not of the background colour.
    pub covered_pixels: usize,
    /// The tools drawn by name (the simulation's `scene` stream).
    pub tools: Vec<String>,
    /// The scene's name (the simulation's `rest` stream; empty if it
    /// never came).
    pub scene: String,
    /// Fibres the scene has (drawn with `--fibres`).
    pub fibres: usize,
    /// What the organ's colour showed (`--colour`).
    pub colour_by: crate::colour::ColourBy,
    /// The colour bar's range, bottom and top (mm for displacement); absent
    /// when the organ has its tissue colour.
    pub colour_bar: Option<[f32; 2]>,
    /// The largest displacement of any vertex in the frame drawn (mm; from
    /// the rest shape, absent before it came).
    pub max_displacement_mm: Option<f32>,
    /// Each reported tool's force arrow as drawn.
    pub arrows: Vec<ArrowReport>,
    /// The clipping plane (`--clip`): its axis (`x`, `y`, `z`) and where
    /// (m); absent without one.
    pub clip: Option<(char, f32)>,
    /// Surface triangles drawn after clipping.
    pub triangles_drawn: usize,
    /// Fibres drawn (`--fibres`, after clipping).
    pub fibres_drawn: usize,
}

/// A tool's force and its arrow.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ArrowReport {
    /// The tool's index.
    pub tool: usize,
    /// |force| (N).
    pub force_n: f32,
    /// The arrow's length (m; 0 when too short to draw or arrows are off).
    pub length_m: f32,
    /// The scale (mm per N).
    pub mm_per_n: f32,
}

/// How to take a snapshot.
#[derive(Clone, Debug, PartialEq)]
pub struct SnapshotConfig {
    /// The session's name (for messages).
    pub session: String,
    /// The PNG to write.
    pub out: PathBuf,
    /// Width and height (px).
    pub size: (u32, u32),
    /// Where the camera looks from.
    pub view: View,
    /// What to draw.
    pub layers: Layers,
    /// How long to wait for the simulation (s).
    pub wait_s: f64,
}

/// Waits up to `cfg.wait_s` for drawable mesh state in `session`, then
/// renders it into `cfg.out` (PNG).
pub fn snapshot(
    session: &mut Session,
    cfg: &SnapshotConfig,
) -> Result<SnapshotReport, SnapshotError> {
    let SnapshotConfig {
        session: session_name,
        out,
        size: (width, height),
        view,
        layers,
        wait_s,
    } = cfg;
    let (width, height, view, layers, wait_s) = (*width, *height, *view, *layers, *wait_s);
    let start = monotonic_ns();
    loop {
        let now = monotonic_ns();
        session.poll(now);
        // Two frames: a topology that arrived with the first may be older
        // than the state a running simulation is in. With a daemon running,
        // also its telemetry rate (two batches, ~130 ms) for the overlay,
        // for at most half a second.
        // Likewise the uncut surface (cut faces) and the scene's name, which
        // a simulation publishes once at start.
        let early = now - start < 500_000_000;
        let telemetry_pending = session.daemon_present() && session.stats.haptic_hz == 0.0 && early;
        let scene_pending = (session.info.surface.is_empty()
            || session.info.name.is_empty()
            || !session.info.tools_known)
            && early;
        // Force samples name tools the scene message has not declared yet:
        // wait for it too, or the tools would be missing from the picture.
        // And the other way: declared tools but no force sample yet (where
        // they are and what they feel comes only with one).
        let tools_pending = (session.tools.len() > session.info.tools.len()
            || (!session.info.tools.is_empty() && session.tools.is_empty()))
            && early;
        if session.drawable()
            && session.frames >= 2
            && !telemetry_pending
            && !scene_pending
            && !tools_pending
        {
            break;
        }
        if (now - start) as f64 * 1e-9 > wait_s {
            if session.drawable() {
                break;
            }
            if session.all_cut() {
                return Err(SnapshotError::AllCut {
                    session: session_name.to_string(),
                });
            }
            return Err(SnapshotError::NoMesh {
                session: session_name.to_string(),
                wait_s,
            });
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let headless = Headless::new()?;
    let ctx = &headless.context;
    let mut renderer = Renderer::new(ctx);
    let is_cut = |t| session.same_scene() && session.info.is_cut_face(t);
    let Some((lo, hi)) = bounds(&session.positions_m) else {
        return Err(SnapshotError::NoMesh {
            session: session_name.to_string(),
            wait_s,
        });
    };
    let clip = layers.clip.map(|c| (c, c.at_m(lo, hi)));
    renderer.set_clip(clip);
    let colour_field = field(session, layers.colour_by);
    let triangles_drawn = renderer.set_surface(
        &session.positions_m,
        &session.triangles,
        is_cut,
        colour_field.as_ref().map(|f| f.colours.as_slice()),
    );
    renderer.set_colour_bar(colour_field.as_ref().map(|f| f.bar()).as_ref());
    let shapes = tool_shapes(session, None);
    renderer.set_tools(&shapes, layers.forces, layers.force_mm_per_n);
    let fibres_drawn = if layers.fibres {
        renderer.set_fibres(&session.info.fibres, (hi - lo).x.max((hi - lo).y) * 0.004)
    } else {
        0
    };
    renderer.set_overlay(&overlay::fit(
        overlay::render_coloured(&overlay_lines(
            session,
            monotonic_ns(),
            None,
            layers.force_mm_per_n,
        )),
        width.saturating_sub(16) as usize,
    ));
    let viewport = Viewport::new_at_origo(width, height);
    let camera = framing(viewport, lo, hi, view);
    let mut color = Texture2D::new_empty::<[u8; 4]>(
        ctx,
        width,
        height,
        Interpolation::Nearest,
        Interpolation::Nearest,
        None,
        Wrapping::ClampToEdge,
        Wrapping::ClampToEdge,
    );
    let mut depth = DepthTexture2D::new::<f32>(
        ctx,
        width,
        height,
        Wrapping::ClampToEdge,
        Wrapping::ClampToEdge,
    );
    let target = RenderTarget::new(color.as_color_target(None), depth.as_depth_target());
    renderer.draw(&target, &camera, &layers);
    let pixels: Vec<[u8; 4]> = target.read_color();
    // The bottom-right corner is background: framing leaves a margin there.
    let background = pixels.last().map_or([0; 3], |p| [p[0], p[1], p[2]]);
    let report = SnapshotReport {
        width,
        height,
        vertices: session.positions_m.len(),
        triangles: session.triangles.len(),
        cut_triangles: session.triangles.iter().filter(|t| is_cut(**t)).count(),
        clip: clip.map(|(c, at)| (['x', 'y', 'z'][c.axis], at)),
        triangles_drawn,
        fibres_drawn,
        topology_version: session.topology_version,
        covered_pixels: pixels.iter().filter(|p| p[..3] != background).count(),
        tools: session.info.tools.iter().map(|t| t.name.clone()).collect(),
        scene: session.info.name.clone(),
        fibres: session.info.fibres.len(),
        colour_by: layers.colour_by,
        colour_bar: colour_field.as_ref().map(|f| f.range),
        max_displacement_mm: (!session.info.rest_m.is_empty()).then(|| {
            crate::colour::displacement_mm(&session.positions_m, &session.info.rest_m)
                .into_iter()
                .fold(0.0, f32::max)
        }),
        arrows: session
            .tools
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let force_n = t.force_n.iter().map(|f| f * f).sum::<f64>().sqrt() as f32;
                let radius = shapes.get(i).map_or(0.0, |s| s.radius_m);
                ArrowReport {
                    tool: i,
                    force_n,
                    length_m: if layers.forces {
                        arrow_length_m(force_n, layers.force_mm_per_n, radius)
                    } else {
                        0.0
                    },
                    mm_per_n: layers.force_mm_per_n,
                }
            })
            .collect(),
    };
    write_png(out, width, height, &pixels)?;
    Ok(report)
}

fn write_png(path: &Path, w: u32, h: u32, pixels: &[[u8; 4]]) -> Result<(), SnapshotError> {
    let err = |e: String| SnapshotError::Write {
        path: path.to_path_buf(),
        reason: e,
    };
    let file = std::fs::File::create(path).map_err(|e| err(e.to_string()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(png::ColorType::Rgba);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(|e| err(e.to_string()))?;
    let flat: Vec<u8> = pixels.iter().flatten().copied().collect();
    writer
        .write_image_data(&flat)
        .map_err(|e| err(e.to_string()))?;
    writer.finish().map_err(|e| err(e.to_string()))
}
