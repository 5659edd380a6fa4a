//! The warning that a scene's stable step needs more sub-steps per
//! real-time step than real time allows, printed by `check` and `run`:
//! the step, the sub-steps, the work they take and the scene's values
//! that shortened the step ([`super::ranges`] notes them).

use super::build::BuiltScene;
use super::report::thousands;
use crate::math::Real;

/// The explicit kernel's time per edge and sub-step (s), rounded up from
/// the embedded liver (10,469 edges, 3 sub-steps: a step's whole work
/// 111 us at p50, 3.5 ns an edge, on a 2-core VM): the estimate behind the
/// real-time warning.
pub const EDGE_SUBSTEP_S: Real = 4e-9;
/// The loop's own time per step (pose, sample, status), when the scene
/// gives no step and each sub-step is a whole step (s).
pub const LOOP_STEP_S: Real = 2e-5;

/// What the real-time warning needs of a scene, taken before the scene
/// goes to its backend.
#[derive(Clone, Debug)]
pub struct RealTime {
    /// The scene's step, if it gives one (else the run steps at 0.9 of the
    /// bound and the haptic millisecond is the measure).
    pub dt_s: Option<Real>,
    /// Edges of the mesh.
    pub edges: usize,
    /// Worker threads.
    pub threads: usize,
    /// The values that shorten the step ([`super::SceneReport::step_notes`]).
    pub notes: Vec<String>,
}

impl RealTime {
    /// Of a built scene.
    pub fn of(b: &BuiltScene) -> Self {
        Self {
            dt_s: b.settings.dt_s,
            edges: b.model.topology().edges().len(),
            threads: b.settings.threads,
            notes: b.report.step_notes.clone(),
        }
    }

    /// The warning, when the stable step `dt_max_s` needs more sub-steps
    /// per real-time step than a step may take ([`crate::tensor_mass::explicit::MAX_SUBSTEPS`])
    /// or more work than the step lasts (at [`EDGE_SUBSTEP_S`]).
    pub fn warning(&self, dt_max_s: Real) -> Option<String> {
        let step = self.dt_s.unwrap_or(1e-3);
        if dt_max_s.is_nan() || dt_max_s <= 0.0 {
            return None;
        }
        let substeps = (step / dt_max_s).ceil().max(1.0);
        let mut work_s =
            substeps * self.edges as Real * EDGE_SUBSTEP_S / self.threads.max(1) as Real;
        if self.dt_s.is_none() {
            work_s += substeps * LOOP_STEP_S;
        }
        let max = crate::tensor_mass::explicit::MAX_SUBSTEPS as Real;
        if substeps <= max && work_s <= step {
            return None;
        }
        let why = if self.notes.is_empty() {
            "the mesh's smallest cells and the materials set it".to_string()
        } else {
            self.notes.join(", ")
        };
        Some(format!(
            "the stable step {dt_max_s:.2e} s needs {} sub-steps per {} step (about {} of work on {} thread{}, at {:.0} ns an edge and sub-step): the run cannot keep real time ({why})",
            thousands(substeps),
            duration(step),
            duration(work_s),
            self.threads,
            if self.threads == 1 { "" } else { "s" },
            EDGE_SUBSTEP_S * 1e9,
        ))
    }
}

/// A duration in the unit that reads best: 1 ms, 1.104 s, 12.5 us.
fn duration(s: Real) -> String {
    let (v, u) = if s >= 1.0 {
        (s, "s")
    } else if s >= 1e-3 {
        (s * 1e3, "ms")
    } else {
        (s * 1e6, "us")
    };
    let v = format!("{v:.3}");
    format!("{} {u}", v.trim_end_matches('0').trim_end_matches('.'))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_durations_read_well() {
        assert_eq!(thousands(106_383.0), "106,383");
        assert_eq!(thousands(999.0), "999");
        assert_eq!(duration(1e-3), "1 ms");
        assert_eq!(duration(1.1042), "1.104 s");
    }

    #[test]
    fn a_short_stable_step_warns_that_real_time_cannot_be_kept() {
        let rt = RealTime {
            dt_s: None,
            edges: 1000,
            threads: 1,
            notes: vec!["poisson 0.4999999999 at line 8".into()],
        };
        let w = rt.warning(9.4e-9).expect("a warning");
        assert!(w.contains("106,383 sub-steps per 1 ms step"), "{w}");
        assert!(w.contains("poisson 0.4999999999 at line 8"), "{w}");
        assert_eq!(rt.warning(3.5e-4), None);
    }
}
