//! Steps 3 and 5 of [`super::implicit_mesh`]: the trimmed lattice made
//! manifold (repair, then peeling what snapping would flatten) and its
//! surface vertices snapped onto the shape's zero level set.

use super::super::quality::{VertexStars, dihedral_angles_deg, sorted_faces, vertex_link};
use super::{Lattice, SNAP_MIN_DIHEDRAL_DEG};
use crate::math::{Real, Vec3, tet_signed_volume};
use crate::mesh::GenerateError;

/// Snapping passes over the surface vertices.
const SNAP_PASSES: usize = 4;

/// Repair rounds before giving up with [`GenerateError::NotManifold`].
const REPAIR_ROUNDS: usize = 32;

/// Rounds of removing tetrahedra that snapping would flatten.
const PEEL_ROUNDS: usize = 6;

/// Makes every vertex of the kept set manifold (step 3 of the module docs),
/// looking again only at the vertices of tetrahedra a round changed.
fn repair(vertex_count: usize, tets: &[[u32; 4]], kept: &mut [bool]) -> Result<(), GenerateError> {
    let stars = VertexStars::new(vertex_count, tets);
    let mut star = Vec::new();
    let mut todo: Vec<u32> = (0..vertex_count as u32).collect();
    let mut queued = vec![false; vertex_count];
    for _ in 0..REPAIR_ROUNDS {
        let mut changed: Vec<u32> = Vec::new();
        for &v in &todo {
            star.clear();
            star.extend(stars.of(v as usize).iter().filter(|t| kept[**t as usize]));
            if star.is_empty() {
                continue;
            }
            let link = vertex_link(v, &star, tets);
            if link.manifold {
                continue;
            }
            if link.fans.len() > 1 {
                // Thin bridges through one vertex or edge: keep the bulk.
                let largest = (0..link.fans.len())
                    .max_by_key(|&f| link.fans[f].len())
                    .unwrap_or(0);
                for (f, fan) in link.fans.iter().enumerate() {
                    if f != largest {
                        for &t in fan {
                            kept[t as usize] = false;
                            changed.push(t);
                        }
                    }
                }
            } else {
                // Pinched but joined (a notch around an edge): fill it.
                for &t in stars.of(v as usize) {
                    if !kept[t as usize] {
                        kept[t as usize] = true;
                        changed.push(t);
                    }
                }
            }
        }
        if changed.is_empty() {
            return Ok(());
        }
        todo.clear();
        for t in changed {
            for &w in &tets[t as usize] {
                if !queued[w as usize] {
                    queued[w as usize] = true;
                    todo.push(w);
                }
            }
        }
        for &w in &todo {
            queued[w as usize] = false;
        }
    }
    let left = (0..vertex_count as u32)
        .filter(|&v| {
            star.clear();
            star.extend(stars.of(v as usize).iter().filter(|t| kept[**t as usize]));
            !star.is_empty() && !vertex_link(v, &star, tets).manifold
        })
        .count();
    match left {
        0 => Ok(()),
        vertices => Err(GenerateError::NotManifold {
            vertices,
            rounds: REPAIR_ROUNDS,
        }),
    }
}

/// Repairs the kept set, then removes the tetrahedra that snapping would
/// flatten: those with all four (body-centred: at least three) vertices on
/// the surface that would be inverted or below [`SNAP_MIN_DIHEDRAL_DEG`]
/// with their surface vertices at their snapping targets (typically a
/// staircase corner whose corners land on a short patch of the surface). Without them the vertex
/// underneath becomes a surface vertex and snaps out, so the volume comes
/// back with good elements. Repeats, as removal exposes new surface vertices.
pub(super) fn peel(
    f: &dyn Fn(Vec3) -> Real,
    positions: &[Vec3],
    tets: &[[u32; 4]],
    kept: &mut [bool],
    cell: Real,
    lattice: Lattice,
) -> Result<(), GenerateError> {
    // Body-centred: also tetrahedra with three surface vertices, whose fourth
    // vertex sits too close under the surface (then all surface vertices
    // snap, measured). On the cubic lattice that rule cascades into deep
    // peeling, so only fully-surface tetrahedra go (about 5 % of its surface
    // vertices then stay off the surface, by up to a third of a cell).
    let min_on_surface = match lattice {
        Lattice::BodyCentred => 3,
        Lattice::Cubic => 4,
    };
    let mut target: Vec<Option<Vec3>> = vec![None; positions.len()];
    for _ in 0..PEEL_ROUNDS {
        repair(positions.len(), tets, kept)?;
        let live: Vec<usize> = (0..tets.len()).filter(|&t| kept[t]).collect();
        let sub: Vec<[u32; 4]> = live.iter().map(|&t| tets[t]).collect();
        let on_surface = surface_vertices(positions.len(), &sub);
        let mut removed = false;
        for (&t, tet) in live.iter().zip(&sub) {
            if tet.iter().filter(|v| on_surface[**v as usize]).count() < min_on_surface {
                continue;
            }
            let p = tet.map(|v| {
                if on_surface[v as usize] {
                    *target[v as usize]
                        .get_or_insert_with(|| newton_target(f, positions[v as usize], cell))
                } else {
                    positions[v as usize]
                }
            });
            if !good_tet(p) {
                kept[t] = false;
                removed = true;
            }
        }
        if !removed {
            break;
        }
    }
    repair(positions.len(), tets, kept)
}

/// Positive volume and every dihedral angle at least [`SNAP_MIN_DIHEDRAL_DEG`].
fn good_tet(p: [Vec3; 4]) -> bool {
    tet_signed_volume(p[0], p[1], p[2], p[3]) > 0.0
        && dihedral_angles_deg(p)
            .iter()
            .all(|a| *a >= SNAP_MIN_DIHEDRAL_DEG)
}

/// Which vertices are on a face that only one tetrahedron has.
fn surface_vertices(vertex_count: usize, tets: &[[u32; 4]]) -> Vec<bool> {
    let faces = sorted_faces(tets);
    let mut on_surface = vec![false; vertex_count];
    let mut i = 0;
    while i < faces.len() {
        let j = i + faces[i..].iter().take_while(|x| x.0 == faces[i].0).count();
        if j - i == 1 {
            for v in faces[i].0 {
                on_surface[v as usize] = true;
            }
        }
        i = j;
    }
    on_surface
}

/// The point where Newton steps along the numerical gradient of `f` from `p`
/// meet the zero level set (or wherever they stop after a few steps).
fn newton_target(f: &dyn Fn(Vec3) -> Real, p: Vec3, cell: Real) -> Vec3 {
    let h = 1e-4 * cell;
    let mut q = p;
    for _ in 0..8 {
        let value = f(q);
        if !value.is_finite() || value.abs() < 1e-9 * cell {
            break;
        }
        let g = Vec3::new(
            f(q + Vec3::X * h) - f(q - Vec3::X * h),
            f(q + Vec3::Y * h) - f(q - Vec3::Y * h),
            f(q + Vec3::Z * h) - f(q - Vec3::Z * h),
        ) / (2.0 * h);
        let g2 = g.length_squared();
        if !(g2.is_finite() && g2 > 0.0) {
            break;
        }
        // A step longer than a cell means the gradient is misleading here.
        let step = (g * (value / g2)).clamp_length_max(cell);
        q -= step;
    }
    if q.is_finite() { q } else { p }
}

/// Step 5 of the module docs, on the renumbered mesh.
pub(super) fn snap(
    f: &dyn Fn(Vec3) -> Real,
    positions: &mut [Vec3],
    tets: &[[u32; 4]],
    cell: Real,
) {
    let on_surface = surface_vertices(positions.len(), tets);
    let stars = VertexStars::new(positions.len(), tets);
    let acceptable = |positions: &[Vec3], v: usize, at: Vec3| {
        stars.of(v).iter().all(|&t| {
            let p = tets[t as usize].map(|w| {
                if w as usize == v {
                    at
                } else {
                    positions[w as usize]
                }
            });
            good_tet(p)
        })
    };
    for _ in 0..SNAP_PASSES {
        let mut moved = false;
        for v in (0..positions.len()).filter(|&v| on_surface[v]) {
            let from = positions[v];
            let delta = newton_target(f, from, cell) - from;
            if delta.length() < 1e-9 * cell {
                continue;
            }
            let mut scale = 1.0;
            for _ in 0..=5 {
                if acceptable(positions, v, from + delta * scale) {
                    positions[v] = from + delta * scale;
                    moved = true;
                    break;
                }
                scale *= 0.5;
            }
        }
        if !moved {
            break;
        }
    }
}
