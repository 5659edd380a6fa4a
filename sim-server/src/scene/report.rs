//! What building a scene found and made, for `sim-server check` and the
//! logs ([`SceneReport`], [`RefineReport`]), and the small checks and
//! formats every part of the build reports with. The leaf of the scene
//! module: the parts import it, it imports none of them.

use super::{SceneError, SceneSource};
use crate::math::Real;
use serde::Serialize;

/// What the scene made, for `check` and logs.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SceneReport {
    /// Where the mesh came from.
    pub mesh_source: String,
    /// Importer and builder warnings.
    pub warnings: Vec<String>,
    /// (name, tetrahedra, material) per region, in order.
    pub regions: Vec<(String, usize, String)>,
    /// (name, tetrahedra made anisotropic) per vessel.
    pub vessels: Vec<(String, usize)>,
    /// Tetrahedra with an anisotropic material.
    pub anisotropic_tets: usize,
    /// The default material.
    pub default_material: String,
    /// Membrane: alpha and model, if any.
    pub membrane: Option<(Real, String)>,
    /// Vertices held fixed.
    pub fixed_vertices: usize,
    /// Vertices with an imposed displacement.
    pub prescribed_vertices: usize,
    /// Vertices carrying a force.
    pub loaded_vertices: usize,
    /// Tetrahedra of the hybrid's tensor-mass part, when `[hybrid]` is given.
    pub hybrid_tets: Option<usize>,
    /// What each `[[refine]]` did, in order.
    pub refined: Vec<RefineReport>,
    /// The values past their usual range that shorten the explicit stable
    /// step (`poisson 0.4999 at line 8`), named by the real-time warning
    /// ([`super::real_time::RealTime`]).
    #[serde(skip)]
    pub step_notes: Vec<String>,
}

/// What one `[[refine]]` did, for `check` and the run's report.
#[derive(Clone, Debug, Serialize)]
pub struct RefineReport {
    /// Its name (or `refine N`).
    pub name: String,
    /// The cell size asked for (m).
    pub cell_m: Real,
    /// Tetrahedra before and after.
    pub tets_before: usize,
    /// Tetrahedra after.
    pub tets_after: usize,
    /// Whether it stopped at its element budget.
    pub stopped_at_budget: bool,
}

/// A scene value that must be a positive finite number, or its error.
pub(super) fn positive(
    src: &SceneSource,
    v: &toml::Spanned<Real>,
    what: &str,
) -> Result<Real, SceneError> {
    let x = *v.get_ref();
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(src.error(
            v.span(),
            format!("{what} must be a positive finite number, got {x}"),
        ))
    }
}

/// 106383 as "106,383".
pub(super) fn thousands(x: Real) -> String {
    if x >= 1e15 {
        return format!("{x:.1e}");
    }
    let digits = format!("{x:.0}");
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}
