//! Fixtures shared by the contact modules' unit tests: a point on a swept
//! part, a single sub-step.

use super::*;

/// Adds a part swept from `from` to `to` (radius `radius_m`) and one
/// point on it with `vertices`, `weights` and stiffness `k_n_per_m`.
pub(crate) fn add_point(
    f: &mut ContactField,
    (from, to): (Segment, Segment),
    tip: bool,
    radius_m: Real,
    (vertices, weights): ([u32; 3], [Real; 3]),
    k_n_per_m: Real,
) {
    let part = f.add_part(PartSweep {
        tool: 0,
        tip,
        from,
        to,
        radius_m,
    });
    f.push(ContactPoint {
        vertices,
        weights,
        part,
        stiffness_n_per_m: k_n_per_m,
    });
}

/// The end of a single sub-step of `h_s`, without damping.
pub(crate) fn whole_step(h_s: Real) -> SubStep<'static> {
    SubStep {
        h_s,
        step_s: h_s,
        s: 1.0,
        masses_kg: &[],
    }
}
