//! Which material each tetrahedron gets: the scene's `[material]`, then its
//! `[[region]]`s in order, then its `[[vessel]]`s (fibres along the vessel),
//! each checked at its own line.

use super::materials::resolve;
use super::report::SceneReport;
use super::select::{Region, Tags};
use super::spec::{MaterialKeys, SceneSpec};
use super::{SceneError, SceneSource};
use crate::ids::TetId;
use crate::material_map::TetMaterials;
use crate::math::{Real, Vec3};
use crate::mesh::TetMesh;
use std::ops::Range;

/// The materials of `mesh`'s tetrahedra, as `spec` assigns them; what was
/// assigned goes into `report`.
pub(super) fn tet_materials(
    src: &SceneSource,
    spec: &SceneSpec,
    mesh: &TetMesh,
    physical: &Tags,
    report: &mut SceneReport,
) -> Result<TetMaterials, SceneError> {
    let n_tets = mesh.tet_count();
    let default_keys = spec.material.get_ref().material_keys();
    let default_fiber = spec
        .material
        .get_ref()
        .fiber
        .as_ref()
        .map(|f| unit(src, f, "[material] fiber"))
        .transpose()?;
    let default = resolve(
        src,
        &default_keys,
        default_fiber.is_some(),
        spec.material.span(),
        "[material]",
        report,
    )?;
    report.default_material = describe(&default);
    let mut mats = TetMaterials::uniform(default, n_tets);
    if let Some(f) = default_fiber {
        for t in 0..n_tets {
            mats.set_fiber(TetId::from(t), f)
                .expect("valid tet and fibre");
        }
    }
    let defaults = Defaults {
        keys: default_keys,
        fiber: default_fiber,
    };
    regions(src, spec, mesh, physical, &defaults, &mut mats, report)?;
    super::vessel::vessels(src, spec, mesh, physical, &defaults, &mut mats, report)?;
    Ok(mats)
}

/// The `[material]` table's keys and fibre, which regions and vessels
/// inherit.
pub(super) struct Defaults<'s> {
    pub(super) keys: MaterialKeys<'s>,
    pub(super) fiber: Option<Vec3>,
}

/// The error for a material past the 65,535 a map can hold.
pub(super) fn too_many(src: &SceneSource, span: Range<usize>) -> SceneError {
    src.error(span, "too many distinct materials (at most 65535)")
}

/// The `[[region]]`s, in order.
fn regions(
    src: &SceneSource,
    spec: &SceneSpec,
    mesh: &TetMesh,
    physical: &Tags,
    defaults: &Defaults,
    mats: &mut TetMaterials,
    report: &mut SceneReport,
) -> Result<(), SceneError> {
    for (i, region) in spec.region.iter().enumerate() {
        let r = region.get_ref();
        let name = r
            .name
            .clone()
            .unwrap_or_else(|| format!("region {}", i + 1));
        let what = format!("[[region]] {name:?}");
        let fiber = match &r.fiber {
            Some(f) => Some(unit(src, f, &format!("{what} fiber"))?),
            None => defaults.fiber,
        };
        let keys = r.material_keys().over(defaults.keys);
        let material = resolve(src, &keys, fiber.is_some(), region.span(), &what, report)?;
        let tets = Region::for_tets(src, &r.select)?.tets(mesh, physical);
        if tets.is_empty() {
            return Err(src.error(r.select.span(), format!("{what} selects no tetrahedron")));
        }
        let id = mats
            .add(material)
            .map_err(|_| too_many(src, region.span()))?;
        for &t in &tets {
            mats.assign(t, id).expect("tet in range");
            if let Some(f) = fiber {
                mats.set_fiber(t, f).expect("unit fibre");
            }
        }
        report.regions.push((name, tets.len(), describe(&material)));
    }
    Ok(())
}

/// One line describing a material, for the scene report.
fn describe(m: &crate::material::Material) -> String {
    let l = m.lame();
    let mut s = format!(
        "{}, E {:.4} kPa, nu {:.3}, rho {:.0} kg/m3, damping {:.3} /s",
        m.model().name(),
        l.young_pa() / 1e3,
        l.poisson(),
        m.density_kg_m3(),
        m.damping_per_s()
    );
    if let crate::material::Elasticity::Transverse(t) = m.elasticity() {
        let e = t.engineering();
        s += &format!(
            ", transversally isotropic: delta_lambda {:.4} kPa, delta_mu {:.4} kPa, E_fibre {:.4} kPa, G_fibre {:.4} kPa, terms {}",
            t.delta_lambda_pa() / 1e3,
            t.delta_mu_pa() / 1e3,
            e.young_fiber_pa / 1e3,
            e.shear_fiber_pa / 1e3,
            t.terms()
        );
    }
    s
}

fn unit(src: &SceneSource, v: &toml::Spanned<[Real; 3]>, what: &str) -> Result<Vec3, SceneError> {
    let a = Vec3::from_array(*v.get_ref());
    // Scaled by its largest component first: the length of [1e300, 0, 0]
    // overflows and that of [1e-300, 0, 0] underflows, yet both have a
    // direction (found by the scene fuzz test: the first normalised to 0).
    let largest = a.abs().max_element();
    match (a / largest).try_normalize() {
        Some(n) if a.is_finite() && largest > 0.0 => Ok(n),
        _ => Err(src.error(v.span(), format!("{what} must be a finite non-zero vector"))),
    }
}
