//! The plausible range of every physical scene key, in one table: a value
//! outside `min ..= max` is refused at its line, one outside the usual
//! `warn_min ..= warn_max` is accepted with a warning (a lab may mean it).
//! docs/guide/scenes.md lists the same table.

use super::report::SceneReport;
use super::report::thousands;
use super::{SceneError, SceneSource};
use crate::math::Real;
use toml::Spanned;

/// Which way a value past its usual range shortens the explicit stable step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shortens {
    /// It does not.
    No,
    /// Large values do (stiffness).
    WhenHigh,
    /// Small values do (density).
    WhenLow,
}

/// One key's range.
#[derive(Clone, Copy, Debug)]
pub struct KeyRange {
    /// The key.
    pub key: &'static str,
    /// Its unit (empty: none).
    pub unit: &'static str,
    /// Smallest accepted value.
    pub min: Real,
    /// Largest accepted value.
    pub max: Real,
    /// `min` itself refused (Poisson's -1).
    pub min_open: bool,
    /// `max` itself refused (Poisson's 0.5).
    pub max_open: bool,
    /// Below this, a warning.
    pub warn_min: Real,
    /// Above this, a warning.
    pub warn_max: Real,
    /// What is usual, for the messages.
    pub typical: &'static str,
    /// Whether the value sizes the explicit step.
    pub shortens: Shortens,
}

const fn key(
    key: &'static str,
    unit: &'static str,
    [min, max]: [Real; 2],
    [warn_min, warn_max]: [Real; 2],
    typical: &'static str,
) -> KeyRange {
    KeyRange {
        key,
        unit,
        min,
        max,
        min_open: false,
        max_open: false,
        warn_min,
        warn_max,
        typical,
        shortens: Shortens::No,
    }
}

const fn shortens(mut r: KeyRange, s: Shortens) -> KeyRange {
    r.shortens = s;
    r
}

/// `[material]`, `[[region]]`, `[[vessel]]` `young_pa`.
pub const YOUNG_PA: KeyRange = shortens(
    key(
        "young_pa",
        "Pa",
        [1.0, 1e10],
        [10.0, 1e8],
        "soft tissue 0.1-100 kPa",
    ),
    Shortens::WhenHigh,
);
/// `poisson`: refused at -1 and 0.5 (no stable solid); above 0.49 the
/// explicit step shrinks as sqrt(1 - 2 nu).
pub const POISSON: KeyRange = KeyRange {
    min_open: true,
    max_open: true,
    ..shortens(
        key("poisson", "", [-1.0, 0.5], [0.0, 0.49], "tissue 0.3-0.49"),
        Shortens::WhenHigh,
    )
};
/// `density_kg_m3`.
pub const DENSITY_KG_M3: KeyRange = shortens(
    key(
        "density_kg_m3",
        "kg/m^3",
        [1.0, 1e5],
        [500.0, 3000.0],
        "tissue about 1000",
    ),
    Shortens::WhenLow,
);
/// `damping_per_s` (mass-proportional).
pub const DAMPING_PER_S: KeyRange = key("damping_per_s", "1/s", [0.0, 1e5], [0.0, 1e3], "0-50");
/// `delta_lambda_pa`.
pub const DELTA_LAMBDA_PA: KeyRange = key(
    "delta_lambda_pa",
    "Pa",
    [-1e10, 1e10],
    [-1e8, 1e8],
    "of the order of young_pa",
);
/// `delta_mu_pa`.
pub const DELTA_MU_PA: KeyRange = key(
    "delta_mu_pa",
    "Pa",
    [-1e10, 1e10],
    [-1e8, 1e8],
    "of the order of young_pa",
);
/// `young_fiber_pa`.
pub const YOUNG_FIBER_PA: KeyRange = shortens(
    key(
        "young_fiber_pa",
        "Pa",
        [1.0, 1e10],
        [10.0, 1e8],
        "vessel walls 10 kPa-10 MPa",
    ),
    Shortens::WhenHigh,
);
/// `shear_fiber_pa`.
pub const SHEAR_FIBER_PA: KeyRange = shortens(
    key(
        "shear_fiber_pa",
        "Pa",
        [0.1, 1e10],
        [3.0, 1e8],
        "about young_pa / 3",
    ),
    Shortens::WhenHigh,
);
/// `[[vessel]] radius_m`.
pub const VESSEL_RADIUS_M: KeyRange = key(
    "radius_m",
    "m",
    [1e-5, 1.0],
    [1e-4, 0.05],
    "vessels 0.1-15 mm",
);
/// `[membrane] alpha` (k = alpha h).
pub const MEMBRANE_ALPHA: KeyRange = shortens(
    key(
        "alpha",
        "N/m^2",
        [1e-3, 1e10],
        [1.0, 1e8],
        "capsules 1-100 kPa",
    ),
    Shortens::WhenHigh,
);
/// `[[tool]] length_m`.
pub const TOOL_LENGTH_M: KeyRange = key(
    "length_m",
    "m",
    [0.01, 1.0],
    [0.1, 0.6],
    "laparoscopic 0.3-0.45 m",
);
/// `[[tool]] radius_m`.
pub const TOOL_RADIUS_M: KeyRange = key(
    "radius_m",
    "m",
    [1e-5, 0.1],
    [5e-4, 0.01],
    "3-12 mm tools, 1.5-6 mm radius",
);
/// `[[tool]] tip_length_m`.
pub const TOOL_TIP_LENGTH_M: KeyRange = key(
    "tip_length_m",
    "m",
    [1e-4, 1.0],
    [1e-3, 0.05],
    "jaws 5-30 mm",
);
/// `[[tool]] friction_static`, `friction_dynamic`.
pub const FRICTION: KeyRange = key(
    "friction",
    "",
    [0.0, 10.0],
    [0.0, 2.0],
    "instrument on tissue 0.05-1",
);
/// `[contact] stiffness_factor` (at most 1e4 with implicit springs too).
pub const STIFFNESS_FACTOR: KeyRange = shortens(
    key(
        "stiffness_factor",
        "",
        [1e-3, 1e6],
        [1.0, 1e4],
        "default 64",
    ),
    Shortens::WhenHigh,
);
/// `[contact] damping_s_per_m`.
pub const CONTACT_DAMPING_S_PER_M: KeyRange = key(
    "damping_s_per_m",
    "s/m",
    [0.0, 1e3],
    [0.0, 30.0],
    "default 3",
);
/// `[contact] point_spacing` (a fraction of the tool radius).
pub const POINT_SPACING: KeyRange = key(
    "point_spacing",
    "",
    [0.05, 1.0],
    [0.1, 1.0],
    "default 0.5; points further apart than the radius miss the tool",
);
/// `[contact] max_tool_speed_m_s`.
pub const MAX_TOOL_SPEED_M_S: KeyRange = key(
    "max_tool_speed_m_s",
    "m/s",
    [1e-3, 100.0],
    [0.05, 5.0],
    "default 1",
);
/// `[contact] max_tool_accel_m_s2`.
pub const MAX_TOOL_ACCEL_M_S2: KeyRange = key(
    "max_tool_accel_m_s2",
    "m/s^2",
    [1e-2, 1e5],
    [1.0, 1e3],
    "default 100",
);
/// `[contact] entry_speed_m_s`.
pub const ENTRY_SPEED_M_S: KeyRange = key(
    "entry_speed_m_s",
    "m/s",
    [1e-4, 10.0],
    [1e-3, 1.0],
    "default 0.02",
);
/// `[contact] corotational_radius_m`.
pub const COROTATIONAL_RADIUS_M: KeyRange = key(
    "corotational_radius_m",
    "m",
    [1e-4, 1.0],
    [1e-3, 0.1],
    "a few tool radii",
);
/// `[contact] refine_radius_m`.
pub const REFINE_RADIUS_M: KeyRange = key(
    "refine_radius_m",
    "m",
    [1e-4, 1.0],
    [1e-3, 0.05],
    "a few tool radii",
);
/// `[contact] refine_cell_m`.
pub const FOLLOW_CELL_M: KeyRange = key(
    "refine_cell_m",
    "m",
    [1e-5, 1.0],
    [1e-4, 0.1],
    "about the tool radius",
);
/// `[[refine]] cell_m`.
pub const REFINE_CELL_M: KeyRange = key(
    "cell_m",
    "m",
    [1e-5, 1.0],
    [1e-4, 0.1],
    "about the tool radius",
);
/// `[mesh] scale`.
pub const MESH_SCALE: KeyRange = key(
    "scale",
    "",
    [1e-6, 1e3],
    [1e-6, 1e3],
    "0.001 for millimetres",
);
/// `[[load]] force_n`, by its length.
pub const LOAD_FORCE_N: KeyRange = key(
    "force_n",
    "N",
    [0.0, 1e4],
    [0.0, 100.0],
    "surgical forces up to about 10 N",
);
/// `[[load]] traction_pa`, by its length.
pub const LOAD_TRACTION_PA: KeyRange = key(
    "traction_pa",
    "Pa",
    [0.0, 1e8],
    [0.0, 1e5],
    "up to a few kPa",
);
/// `[[load]] displacement_m`, by its length.
pub const LOAD_DISPLACEMENT_M: KeyRange = key(
    "displacement_m",
    "m",
    [0.0, 1.0],
    [0.0, 0.1],
    "a few mm to cm",
);
/// `[[load]] rotate angle_deg`.
pub const LOAD_ANGLE_DEG: KeyRange = key(
    "angle_deg",
    "deg",
    [-360.0, 360.0],
    [-90.0, 90.0],
    "a few tens of degrees",
);
/// `[simulation] dt_s` (as `--dt-s`; checked by [`super::check_step`]).
pub const DT_S: KeyRange = key(
    "dt_s",
    "s",
    [super::MIN_DT_S, super::MAX_DT_S],
    [super::MIN_DT_S, super::MAX_DT_S],
    "1 ms for haptics",
);
/// `[simulation] rate_hz` (a period within `dt_s`'s range).
pub const RATE_HZ: KeyRange = key(
    "rate_hz",
    "Hz",
    [1.0 / super::MAX_DT_S, 1.0 / super::MIN_DT_S],
    [1.0 / super::MAX_DT_S, 1.0 / super::MIN_DT_S],
    "1000 for haptics",
);

/// Every range, for the documentation and its test.
pub const ALL: &[KeyRange] = &[
    YOUNG_PA,
    POISSON,
    DENSITY_KG_M3,
    DAMPING_PER_S,
    DELTA_LAMBDA_PA,
    DELTA_MU_PA,
    YOUNG_FIBER_PA,
    SHEAR_FIBER_PA,
    VESSEL_RADIUS_M,
    MEMBRANE_ALPHA,
    TOOL_LENGTH_M,
    TOOL_RADIUS_M,
    TOOL_TIP_LENGTH_M,
    FRICTION,
    STIFFNESS_FACTOR,
    CONTACT_DAMPING_S_PER_M,
    POINT_SPACING,
    MAX_TOOL_SPEED_M_S,
    MAX_TOOL_ACCEL_M_S2,
    ENTRY_SPEED_M_S,
    COROTATIONAL_RADIUS_M,
    REFINE_RADIUS_M,
    FOLLOW_CELL_M,
    REFINE_CELL_M,
    MESH_SCALE,
    LOAD_FORCE_N,
    LOAD_TRACTION_PA,
    LOAD_DISPLACEMENT_M,
    LOAD_ANGLE_DEG,
    DT_S,
    RATE_HZ,
];

impl KeyRange {
    /// The accepted range as the messages write it: `0 .. 0.5 (both
    /// excluded)`, `1 ..= 1e10 Pa`.
    pub fn accepted(&self) -> String {
        let dots = if self.max_open { ".." } else { "..=" };
        let open = match (self.min_open, self.max_open) {
            (true, true) => " (both ends excluded)",
            (true, false) => " (min excluded)",
            _ => "",
        };
        format!(
            "{} {dots} {}{}{open}",
            num(self.min),
            num(self.max),
            unit(self.unit)
        )
    }

    fn contains(&self, x: Real) -> bool {
        let above = if self.min_open {
            x > self.min
        } else {
            x >= self.min
        };
        let below = if self.max_open {
            x < self.max
        } else {
            x <= self.max
        };
        x.is_finite() && above && below
    }

    /// `x` if within the range, else the error at `span` naming `what`
    /// (the table, e.g. `[material]`), the key and the range; outside the
    /// usual range, a warning in `report` (with the position, once per
    /// position) and, for a value that shortens the explicit step, a note
    /// for the real-time warning ([`super::real_time::RealTime`]).
    pub fn check_at(
        &self,
        src: &SceneSource,
        span: std::ops::Range<usize>,
        x: Real,
        what: &str,
        report: &mut SceneReport,
    ) -> Result<Real, SceneError> {
        let name = if what.is_empty() {
            self.key.to_string()
        } else {
            format!("{what} {}", self.key)
        };
        if !self.contains(x) {
            return Err(src.error(
                span,
                format!(
                    "{name} = {} is outside its range {} ({})",
                    num(x),
                    self.accepted(),
                    self.typical
                ),
            ));
        }
        let low = x < self.warn_min;
        if !(low || x > self.warn_max) {
            return Ok(x);
        }
        let (line, column) = src.line_col(span.start);
        let at = format!("{}:{line}:{column}: ", src.name);
        if report.warnings.iter().any(|w| w.starts_with(&at)) {
            return Ok(x);
        }
        let extra = if self.key == POISSON.key {
            let r = poisson_step_ratio(x);
            let r = if r >= 100.0 {
                thousands(r.round())
            } else {
                format!("{r:.1}")
            };
            format!("; it shortens the explicit stable step {r}x against poisson 0.45")
        } else {
            String::new()
        };
        report.warnings.push(format!(
            "{at}{name} = {}{} is outside the usual {} ..= {} ({}){extra}",
            num(x),
            unit(self.unit),
            num(self.warn_min),
            num(self.warn_max),
            self.typical
        ));
        let shortens = match self.shortens {
            Shortens::No => false,
            Shortens::WhenHigh => !low,
            Shortens::WhenLow => low,
        };
        if shortens {
            report
                .step_notes
                .push(format!("{} {} at line {line}", self.key, num(x)));
        }
        Ok(x)
    }

    /// [`Self::check_at`] on a spanned value.
    pub fn check(
        &self,
        src: &SceneSource,
        v: &Spanned<Real>,
        what: &str,
        report: &mut SceneReport,
    ) -> Result<Real, SceneError> {
        self.check_at(src, v.span(), *v.get_ref(), what, report)
    }
}

fn unit(u: &str) -> String {
    if u.is_empty() {
        String::new()
    } else {
        format!(" {u}")
    }
}

/// How many times shorter the explicit stable step is at Poisson's ratio
/// `nu` than at 0.45, at the same Young's modulus and density: the step
/// goes as 1 / sqrt(lambda + 2 mu), and lambda + 2 mu = E (1 - nu) /
/// ((1 + nu) (1 - 2 nu)).
pub fn poisson_step_ratio(nu: Real) -> Real {
    let m = |nu: Real| (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu));
    (m(nu) / m(0.45)).sqrt()
}

/// A number as a scene would write it: 0.45, 4500, 1e-5, 1e300.
pub fn num(x: Real) -> String {
    if x == 0.0 || !x.is_finite() || (x.abs() > 1e-3 && x.abs() < 1e4) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_usual_range_lies_within_its_accepted_one() {
        for r in ALL {
            assert!(r.min <= r.warn_min && r.warn_max <= r.max, "{}", r.key);
            assert!(r.min < r.max, "{}", r.key);
        }
    }

    #[test]
    fn numbers_read_well() {
        assert_eq!(num(1e300), "1e300");
        assert_eq!(num(1e-5), "1e-5");
        assert_eq!(num(0.4999999999), "0.4999999999");
        assert_eq!(num(4500.0), "4500");
        assert_eq!(num(1e5), "1e5");
        assert_eq!(num(0.001), "1e-3");
        assert!((poisson_step_ratio(0.45) - 1.0).abs() < 1e-12);
        assert!(poisson_step_ratio(0.499) > 6.0);
    }
}
