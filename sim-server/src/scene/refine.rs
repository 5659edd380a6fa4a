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
        tags = Tags {
            tets: (refined.parent_tet.iter())
                .map(|&p| tags.tets.get(p as usize).copied().unwrap_or(0))
                .collect(),
            surface: (tags.surface.iter())
                .flat_map(|(tri, tag)| {
                    (refined.split_triangle(tri.map(|v| v.0)).into_iter())
                        .map(move |t| (t.map(VertexId), *tag))
                })
                .collect(),
        };
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
