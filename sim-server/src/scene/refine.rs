//! A scene's `[[refine]]`: finer cells where the tools work, made on the
//! mesh as loaded (in metres, before renumbering) by conforming longest-edge
//! bisection (`tissue::mesh::refine`), so that materials, constraints,
//! loads, tools and every backend see one ordinary mesh. Children keep their
//! parent's physical tag; tagged surface triangles are split with the faces
//! they became.

pub use super::report::RefineReport;
use super::report::{SceneReport, positive};
use super::select::{Region, Tags};
use super::spec::SceneSpec;
use super::{SceneError, SceneSource};
use crate::ids::{TetId, VertexId};
use crate::math::Vec3;
use crate::mesh::TetMesh;
use crate::mesh::refine::refine;

/// The element budget of a `[[refine]]` without `max_tets`: what a core
/// steps in real time at a few sub-steps a millisecond is far below it, and
/// it bounds the memory a mistaken `cell_m` can take (about 0.5 GB).
pub const DEFAULT_MAX_TETS: usize = 300_000;

/// Whether a tetrahedron with corners `p` touches `region` (its bounding
/// box does: a tetrahedron straddling the region's edge is refined too).
fn touches(region: &Region, tags: &Tags, parent: TetId, p: &[Vec3; 4]) -> bool {
    let lo = p[0].min(p[1]).min(p[2].min(p[3]));
    let hi = p[0].max(p[1]).max(p[2].max(p[3]));
    match *region {
        Region::Box(a, b) => lo.cmple(b).all() && hi.cmpge(a).all(),
        Region::Sphere(c, r) => c.clamp(lo, hi).distance_squared(c) <= r * r,
        Region::Physical(tag) => tags.tets.get(parent.idx()) == Some(&tag),
        Region::Surface(_) => false,
    }
}

/// The mesh refined as every `[[refine]]` asks, in order, with its tags
/// carried over.
pub(super) fn refine_mesh(
    src: &SceneSource,
    spec: &SceneSpec,
    mesh: TetMesh,
    tags: Tags,
    report: &mut SceneReport,
) -> Result<(TetMesh, Tags), SceneError> {
    let (mut mesh, mut tags) = (mesh, tags);
    for (k, r) in spec.refine.iter().enumerate() {
        let span = r.span();
        let r = r.get_ref();
        let name = r
            .name
            .clone()
            .unwrap_or_else(|| format!("refine {}", k + 1));
        let region = Region::for_tets(src, &r.select)?;
        let cell_m = positive(src, &r.cell_m, "[[refine]] cell_m")?;
        super::ranges::REFINE_CELL_M.check(src, &r.cell_m, "[[refine]]", report)?;
        let max_tets = r
            .max_tets
            .as_ref()
            .map_or(DEFAULT_MAX_TETS, |m| *m.get_ref());
        let before = mesh.tet_count();
        let refined = refine(&mesh, max_tets, |parent, p| {
            touches(&region, &tags, parent, p).then_some(cell_m)
        })
        .map_err(|e| src.error(span.clone(), format!("[[refine]] {name}: {e}")))?;
        if refined.mesh.tet_count() == before && !refined.stopped_at_budget {
            let touched = (0..before).any(|t| {
                let t = TetId::from(t);
                touches(&region, &tags, t, &mesh.tet_points(t))
            });
            if !touched {
                return Err(src.error(
                    r.select.span(),
                    format!("[[refine]] {name} touches no tetrahedron of the mesh"),
                ));
            }
        }
        if refined.stopped_at_budget {
            report.warnings.push(format!(
                "[[refine]] {name} stopped at max_tets = {max_tets} before every tetrahedron there reached cell_m = {cell_m} m (raise max_tets or the cell size)"
            ));
        }
        tags = carried(&refined, &tags);
        report.refined.push(RefineReport {
            name,
            cell_m,
            tets_before: before,
            tets_after: refined.mesh.tet_count(),
            stopped_at_budget: refined.stopped_at_budget,
        });
        mesh = refined.mesh;
    }
    Ok((mesh, tags))
}

/// The tags of the mesh `refined` was made from, on its tetrahedra and
/// split triangles.
fn carried(refined: &crate::mesh::refine::Refined, tags: &Tags) -> Tags {
    Tags {
        tets: (refined.parent_tet.iter())
            .map(|&p| tags.tets.get(p as usize).copied().unwrap_or(0))
            .collect(),
        surface: (tags.surface.iter())
            .flat_map(|(tri, tag)| {
                (refined.split_triangle(tri.map(|v| v.0)).into_iter())
                    .map(move |t| (t.map(VertexId), *tag))
            })
            .collect(),
    }
}

/// A sphere of the mesh at rest refined to `cell_m` because a tool is
/// there (`[contact] refine_radius_m`: the refinement that follows the
/// tools, `crate::follow_refine`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineAround {
    /// The centre, in the mesh at rest (m).
    pub centre_m: Vec3,
    /// The radius (m).
    pub radius_m: f64,
    /// The cell size wanted there (m).
    pub cell_m: f64,
    /// The most tetrahedra the whole mesh may have.
    pub max_tets: usize,
}

/// `mesh` refined in every sphere of `around` at once (one bisection
/// pass, so the result does not depend on the spheres' order); past the
/// smallest `max_tets` it stops, conforming, and the report says so.
pub(super) fn refine_around(
    src: &SceneSource,
    spec: &SceneSpec,
    mesh: TetMesh,
    tags: Tags,
    around: &[RefineAround],
    report: &mut SceneReport,
) -> Result<(TetMesh, Tags), SceneError> {
    if around.is_empty() {
        return Ok((mesh, tags));
    }
    let max_tets = around
        .iter()
        .map(|a| a.max_tets)
        .min()
        .unwrap_or(DEFAULT_MAX_TETS);
    let before = mesh.tet_count();
    let refined = refine(&mesh, max_tets, |parent, p| {
        (around.iter())
            .filter(|a| touches(&Region::Sphere(a.centre_m, a.radius_m), &tags, parent, p))
            .map(|a| a.cell_m)
            .reduce(f64::min)
    })
    .map_err(|e| {
        let span = (spec.contact.as_ref())
            .and_then(|c| c.get_ref().refine_radius_m.as_ref())
            .map_or(0..0, |r| r.span());
        src.error(span, format!("[contact] refine_radius_m: {e}"))
    })?;
    report.refined.push(RefineReport {
        name: "round the tools".into(),
        cell_m: around
            .iter()
            .map(|a| a.cell_m)
            .fold(f64::INFINITY, f64::min),
        tets_before: before,
        tets_after: refined.mesh.tet_count(),
        stopped_at_budget: refined.stopped_at_budget,
    });
    let tags = carried(&refined, &tags);
    Ok((refined.mesh, tags))
}

/// What `[contact] refine_radius_m` asks: the cells within `radius_m` of
/// where each tool touches refined to `cell_m` while it is there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FollowSettings {
    /// The refined sphere's radius round a tool (m).
    pub radius_m: f64,
    /// The cell size there (m).
    pub cell_m: f64,
    /// The most tetrahedra the refined mesh may have.
    pub max_tets: usize,
}

/// A refinement that follows the tools: what it asks, and the mesh it
/// refines again each time they move.
#[derive(Clone, Debug)]
pub struct FollowScene {
    /// What the scene asks.
    pub settings: FollowSettings,
    /// The mesh before any refinement.
    pub base: super::mesh_load::BaseMesh,
}

/// `[contact] refine_radius_m`, `refine_cell_m`, `refine_max_tets`,
/// checked: positive, in range, with a tool to follow, on the tensor-mass
/// backend with the penalty law (the backends that fix their model and
/// matrices at start cannot change their mesh while they run).
pub(super) fn follow_settings(
    src: &SceneSource,
    spec: &SceneSpec,
    tools: &[crate::contact::ToolDecl],
    backend: crate::scene::spec::BackendName,
    law: Option<crate::contact::ContactLaw>,
    report: &mut SceneReport,
) -> Result<Option<FollowSettings>, SceneError> {
    let Some(c) = &spec.contact else {
        return Ok(None);
    };
    let c = c.get_ref();
    let Some(r) = &c.refine_radius_m else {
        if let Some(span) = (c.refine_cell_m.as_ref().map(|k| k.span()))
            .or(c.refine_max_tets.as_ref().map(|k| k.span()))
        {
            return Err(src.error(
                span,
                "[contact] refine_cell_m and refine_max_tets size the refinement that follows the tools: give refine_radius_m too",
            ));
        }
        return Ok(None);
    };
    let radius_m = positive(src, r, "[contact] refine_radius_m")?;
    super::ranges::REFINE_RADIUS_M.check(src, r, "[contact]", report)?;
    if backend != crate::scene::spec::BackendName::TensorMass {
        return Err(src.error(
            r.span(),
            format!(
                "[contact] refine_radius_m needs the tensor-mass backend, which can change its mesh while it runs; the {} backend fixes its matrices when it starts: refine the working region at load with a [[refine]] instead",
                backend.as_str()
            ),
        ));
    }
    if law == Some(crate::contact::ContactLaw::Projection) {
        return Err(src.error(
            r.span(),
            "[contact] refine_radius_m needs the penalty law (the projection law's constraints are on the vertices of one mesh): remove law = \"projection\"",
        ));
    }
    let Some(smallest) = tools.iter().map(|t| t.radius_m).reduce(f64::min) else {
        return Err(src.error(
            r.span(),
            "[contact] refine_radius_m refines where the tools touch, and the scene has no [[tool]]",
        ));
    };
    let cell_m = match &c.refine_cell_m {
        Some(h) => {
            let h0 = positive(src, h, "[contact] refine_cell_m")?;
            super::ranges::FOLLOW_CELL_M.check(src, h, "[contact]", report)?;
            h0
        }
        None => smallest,
    };
    let max_tets = match &c.refine_max_tets {
        Some(m) if *m.get_ref() == 0 => {
            return Err(src.error(
                m.span(),
                "[contact] refine_max_tets must be a positive number of tetrahedra",
            ));
        }
        Some(m) => *m.get_ref(),
        None => DEFAULT_MAX_TETS,
    };
    Ok(Some(FollowSettings {
        radius_m,
        cell_m,
        max_tets,
    }))
}
