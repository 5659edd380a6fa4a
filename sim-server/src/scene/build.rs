//! Building a scene: the mesh, per-tetrahedron materials (default, regions,
//! vessels), the membrane, constraints, loads, tools and settings. Only what
//! the scene declares is built.

use super::assign::tet_materials;
use super::loads::loads;
use super::mesh_load::{BaseMesh, LoadedMesh, finish_mesh, load_base};
use super::refine::{FollowScene, RefineAround, follow_settings};
use super::report::SceneReport;
use super::select::Region;
use super::settings::{SimSettings, backend_runs_models, contact_config, settings};
use super::spec::{MembraneModelName, SceneSpec};
use super::tool_decls::tool_decls;
use super::{SceneError, SceneSource};
use crate::ids::{TetId, VertexId};
use crate::math::Vec3;
use crate::membrane::MembraneModel;

use crate::tensor_mass::ElasticModel;

pub use crate::contact::ToolDecl;

/// A built scene.
pub struct BuiltScene {
    /// The model (mesh, materials, tensors, membrane).
    pub model: ElasticModel,
    /// Fixed vertices.
    pub fixed: Vec<VertexId>,
    /// Imposed displacements (m).
    pub prescribed: Vec<(VertexId, Vec3)>,
    /// Per-vertex forces (N); empty when the scene has no force or traction load.
    pub loads_n: Vec<Vec3>,
    /// Declared tools.
    pub tools: Vec<ToolDecl>,
    /// The hybrid's tensor-mass (cuttable) part, when `[hybrid]` is given.
    pub hybrid_tets: Option<Vec<TetId>>,
    /// Settings.
    pub settings: SimSettings,
    /// Contact law and constants.
    pub contact: crate::contact::ContactConfig,
    /// Summary.
    pub report: SceneReport,
    /// Each vertex's index in the mesh as read or generated, when the
    /// scene renumbered the vertices (RCM, `[mesh] reorder`): outputs write
    /// it as the `original_id` point array. `None`: the file's order kept.
    pub original_vertex_ids: Option<Vec<u32>>,
    /// The refinement that follows the tools, when `[contact]
    /// refine_radius_m` asks for one (`crate::follow_refine`).
    pub follow: Option<FollowScene>,
}

/// Builds everything `spec` declares.
pub fn build_scene(src: &SceneSource, spec: &SceneSpec) -> Result<BuiltScene, SceneError> {
    let mut report = SceneReport::default();
    let base = load_base(src, spec, &mut report)?;
    // Kept only when the scene asks for a refinement that follows the tools.
    let keep = (spec.contact.as_ref()).is_some_and(|c| c.get_ref().refine_radius_m.is_some());
    build_from(src, spec, base, &[], keep, report)
}

/// Builds everything `spec` declares on `base` (the scene's mesh before
/// refinement, [`BuiltScene::follow`]) with the cells in `around` refined
/// too: the same scene with its mesh refined where the tools are now
/// (its [`BuiltScene::follow`] is `None`: the caller has the base).
pub fn build_scene_around(
    src: &SceneSource,
    spec: &SceneSpec,
    base: BaseMesh,
    around: &[RefineAround],
) -> Result<BuiltScene, SceneError> {
    build_from(src, spec, base, around, false, SceneReport::default())
}

fn build_from(
    src: &SceneSource,
    spec: &SceneSpec,
    base: BaseMesh,
    around: &[RefineAround],
    keep_base: bool,
    mut report: SceneReport,
) -> Result<BuiltScene, SceneError> {
    let kept = keep_base.then(|| base.clone());
    let LoadedMesh {
        mesh,
        physical,
        original_ids: original_vertex_ids,
    } = finish_mesh(src, spec, base, around, &mut report)?;
    let n_tets = mesh.tet_count();

    let mats = tet_materials(src, spec, &mesh, &physical, &mut report)?;
    report.anisotropic_tets = (0..n_tets)
        .filter(|&t| mats.material(TetId::from(t)).is_anisotropic())
        .count();
    let mut model = ElasticModel::new(mesh, mats).map_err(|e| {
        // A mesh that overlaps itself is the mesh's fault, not the material's.
        let span = match e {
            crate::tensor_mass::ModelError::OversharedFace(_) => spec.mesh.span(),
            _ => spec.material.span(),
        };
        src.error(span, e.to_string())
    })?;

    if let Some(m) = &spec.membrane {
        let alpha = *m.get_ref().alpha.get_ref();
        let kind = match m.get_ref().model.unwrap_or(MembraneModelName::Linear) {
            MembraneModelName::Linear => MembraneModel::Linear,
            MembraneModelName::Nonlinear => MembraneModel::Nonlinear,
        };
        if !(alpha.is_finite() && alpha > 0.0) {
            return Err(src.error(
                m.get_ref().alpha.span(),
                format!("[membrane] alpha must be a positive finite number (N/m^2), got {alpha}"),
            ));
        }
        super::ranges::MEMBRANE_ALPHA.check(src, &m.get_ref().alpha, "[membrane]", &mut report)?;
        model = model.with_membrane(alpha, kind).expect("alpha checked");
        report.membrane = Some((alpha, format!("{kind:?}").to_lowercase()));
    }

    let mesh = model.mesh();
    let mut fixed = Vec::new();
    for f in &spec.fixed {
        let vs = Region::new(src, &f.get_ref().select)?.vertices(mesh, &physical);
        if vs.is_empty() {
            return Err(src.error(f.get_ref().select.span(), "[[fixed]] selects no vertex"));
        }
        fixed.extend(vs);
    }
    fixed.sort_unstable();
    fixed.dedup();
    let hybrid_tets = match &spec.hybrid {
        Some(h) => {
            let select = &h.get_ref().select;
            let tets = Region::for_tets(src, select)?.tets(mesh, &physical);
            if tets.is_empty() || tets.len() == mesh.tet_count() {
                return Err(src.error(
                    select.span(),
                    format!(
                        "[hybrid] select picks {} of {} tetrahedra; the tensor-mass part and the precomputed rest must both be non-empty",
                        tets.len(),
                        mesh.tet_count()
                    ),
                ));
            }
            report.hybrid_tets = Some(tets.len());
            Some(tets)
        }
        None => None,
    };
    let (prescribed, loads_n) = loads(src, spec, &model, &physical, &mut report)?;
    // A vertex both fixed and prescribed is an error in the scene.
    if let Some((v, _)) = prescribed
        .iter()
        .find(|(v, _)| fixed.binary_search(v).is_ok())
    {
        let span = spec.load.first().map_or(spec.mesh.span(), |l| l.span());
        return Err(src.error(
            span,
            format!("vertex {} is both fixed and given a displacement", v.0),
        ));
    }
    report.fixed_vertices = fixed.len();
    report.prescribed_vertices = prescribed.len();
    report.loaded_vertices = loads_n.iter().filter(|f| **f != Vec3::ZERO).count();

    let tools = tool_decls(src, spec, &model, &mut report)?;
    let settings = settings(src, spec)?;
    backend_runs_models(src, spec, &model, settings.backend, hybrid_tets.as_deref())?;
    let contact = contact_config(src, spec, &mut report)?;
    let follow = follow_settings(
        src,
        spec,
        &tools,
        settings.backend,
        contact.law,
        &mut report,
    )?
    .zip(kept)
    .map(|(settings, base)| FollowScene { settings, base });
    Ok(BuiltScene {
        follow,
        contact,
        model,
        fixed,
        prescribed,
        loads_n,
        tools,
        hybrid_tets,
        settings,
        report,
        original_vertex_ids,
    })
}
