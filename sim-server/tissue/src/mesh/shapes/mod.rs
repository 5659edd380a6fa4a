//! Implicit-shape generators: ellipsoid and a liver-like organ meshed on a regular or
//! body-centred grid, trimmed to the shape, boundary vertices snapped to the surface.
//!
//! The steps of [`implicit_mesh`]:
//! 1. lay the lattice over the bounds plus one cell on each side;
//! 2. trim: keep a tetrahedron when the shape function is negative at its
//!    centroid (a tetrahedron straddling the surface stays when more than about
//!    half of it is inside, so the trimmed volume is unbiased to first order);
//! 3. repair: a vertex whose kept tetrahedra do not form one disk or sphere
//!    fan (see [`super::quality`]) loses all but its largest fan, or, when its
//!    fans are joined but pinched, gets back every lattice tetrahedron around
//!    it; then only the largest face-connected piece is kept;
//! 4. renumber the used vertices;
//! 5. snap the surface vertices onto the zero level set with Newton steps
//!    along a numerical gradient, each move shrunk (halved up to 5 times, else
//!    skipped) until every tetrahedron around the vertex keeps a dihedral angle
//!    of at least [`SNAP_MIN_DIHEDRAL_DEG`]; a few passes let a vertex blocked by
//!    a neighbour move once the neighbour has.
//!
//! Lattices are oriented when built, so [`TetMesh::new`] reorients nothing.

use super::quality::tet_components;
use super::{GenerateError, TetMesh};
use crate::math::{Real, Vec3, tet_signed_volume};
use surface::{peel, snap};

mod surface;

/// How the bounds are filled with tetrahedra before trimming.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lattice {
    /// Cubes of edge `cell_m`, each split into six tetrahedra around its main
    /// diagonal (dihedral angles 45, 60 and 90 degrees).
    Cubic,
    /// Cube corners plus cube centres; every pair of face-neighbouring centres
    /// forms four tetrahedra with the edges of their shared face (12 per cube,
    /// all congruent, dihedral angles 60 and 90 degrees): better elements and a
    /// surface with fewer sharp corners than [`Lattice::Cubic`].
    BodyCentred,
}

/// The smallest dihedral angle (degrees) a snapping move may leave in any
/// tetrahedron it changes. The unsnapped lattices have 45 (cubic) or 60
/// (body-centred), so this is the mesh's guaranteed minimum.
pub const SNAP_MIN_DIHEDRAL_DEG: Real = 15.0;

/// Lays out the lattice: positions and positively oriented tetrahedra.
fn build_lattice(
    lo: Vec3,
    hi: Vec3,
    cell: Real,
    kind: Lattice,
) -> Result<(Vec<Vec3>, Vec<[u32; 4]>), GenerateError> {
    // One cell of margin on each side; the body-centred tetrahedra fill the
    // box between the outermost cube centres, which still covers the bounds.
    // Counted in floating point first (see `cell_counts`).
    let exact = ((hi - lo) / cell)
        .to_array()
        .map(|l| l.ceil().max(1.0) + 2.0);
    let n = exact.map(|c| c.min(usize::MAX as Real) as usize);
    let [nx, ny, nz] = n;
    let total: Real =
        exact.iter().map(|c| c + 1.0).product::<Real>() + exact.iter().product::<Real>();
    // NaN (a NaN cell) does not fit either.
    let fits = total <= super::generate::MAX_GENERATED_VERTICES as Real;
    if !fits {
        return Err(GenerateError::TooLarge { cells: n });
    }
    let origin = (lo + hi) / 2.0 - Vec3::new(nx as Real, ny as Real, nz as Real) * cell / 2.0;
    let corner = |i: usize, j: usize, k: usize| (i + (nx + 1) * (j + (ny + 1) * k)) as u32;
    let centres = (nx + 1) * (ny + 1) * (nz + 1);
    let centre = |i: usize, j: usize, k: usize| (centres + i + nx * (j + ny * k)) as u32;
    let mut positions = Vec::with_capacity(centres + nx * ny * nz);
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                positions.push(origin + Vec3::new(i as Real, j as Real, k as Real) * cell);
            }
        }
    }
    let mut tets = Vec::new();
    match kind {
        Lattice::Cubic => {
            tets.reserve(6 * nx * ny * nz);
            for k in 0..nz {
                for j in 0..ny {
                    for i in 0..nx {
                        tets.extend(super::generate::kuhn_cube(i, j, k, corner));
                    }
                }
            }
        }
        Lattice::BodyCentred => {
            for k in 0..nz {
                for j in 0..ny {
                    for i in 0..nx {
                        positions.push(
                            origin + (Vec3::new(i as Real, j as Real, k as Real) + 0.5) * cell,
                        );
                    }
                }
            }
            tets.reserve(12 * nx * ny * nz);
            for k in 0..nz {
                for j in 0..ny {
                    for i in 0..nx {
                        let c = [i, j, k];
                        for axis in 0..3 {
                            if c[axis] + 1 >= n[axis] {
                                continue;
                            }
                            let mut next = c;
                            next[axis] += 1;
                            let (b, d) = ((axis + 1) % 3, (axis + 2) % 3);
                            // The shared face's corners, walked around.
                            let ring = [(0, 0), (1, 0), (1, 1), (0, 1)].map(|(sb, sd)| {
                                let mut q = next;
                                q[b] += sb;
                                q[d] += sd;
                                corner(q[0], q[1], q[2])
                            });
                            for e in 0..4 {
                                tets.push([
                                    centre(c[0], c[1], c[2]),
                                    centre(next[0], next[1], next[2]),
                                    ring[e],
                                    ring[(e + 1) % 4],
                                ]);
                            }
                        }
                    }
                }
            }
        }
    }
    for tet in &mut tets {
        let p = tet.map(|v| positions[v as usize]);
        if tet_signed_volume(p[0], p[1], p[2], p[3]) < 0.0 {
            tet.swap(2, 3);
        }
    }
    Ok((positions, tets))
}

/// Refuses a NaN or infinite component, naming it.
fn check_finite(fields: [&'static str; 3], v: Vec3) -> Result<(), GenerateError> {
    match fields
        .into_iter()
        .zip(v.to_array())
        .find(|(_, x)| !x.is_finite())
    {
        Some((field, value)) => Err(GenerateError::NotFinite { field, value }),
        None => Ok(()),
    }
}

/// Refuses a component that is not a positive finite number, naming it.
fn check_positive(fields: [&'static str; 3], v: Vec3) -> Result<(), GenerateError> {
    match fields
        .into_iter()
        .zip(v.to_array())
        .find(|(_, x)| !(x.is_finite() && *x > 0.0))
    {
        Some((field, value)) => Err(GenerateError::NotPositive { field, value }),
        None => Ok(()),
    }
}

/// Meshes the shape `{p : inside(p) < 0}` within `lo_m..hi_m` with lattice
/// cells of edge `cell_m` (see the module docs for the steps). `inside`
/// should be a signed-distance-like function: negative inside, zero on the
/// surface, smooth near it (snapping uses its gradient). NaN counts as outside.
pub fn implicit_mesh(
    inside: &dyn Fn(Vec3) -> Real,
    lo_m: Vec3,
    hi_m: Vec3,
    cell_m: Real,
    lattice: Lattice,
) -> Result<TetMesh, GenerateError> {
    check_finite(["lo_m.x", "lo_m.y", "lo_m.z"], lo_m)?;
    check_finite(["hi_m.x", "hi_m.y", "hi_m.z"], hi_m)?;
    check_positive(
        ["hi_m.x - lo_m.x", "hi_m.y - lo_m.y", "hi_m.z - lo_m.z"],
        hi_m - lo_m,
    )?;
    check_positive(["cell_m"; 3], Vec3::splat(cell_m))?;
    let (positions, tets) = build_lattice(lo_m, hi_m, cell_m, lattice)?;
    let mut kept: Vec<bool> = tets
        .iter()
        .map(|t| inside(t.iter().map(|v| positions[*v as usize]).sum::<Vec3>() / 4.0) < 0.0)
        .collect();
    let empty = || GenerateError::Empty {
        reason: format!(
            "no {lattice:?} lattice tetrahedron of {cell_m} m has its centroid inside the shape \
             within {lo_m}..{hi_m} m"
        ),
    };
    if !kept.contains(&true) {
        return Err(empty());
    }
    peel(inside, &positions, &tets, &mut kept, cell_m, lattice)?;
    let mut tets: Vec<[u32; 4]> = tets
        .into_iter()
        .zip(&kept)
        .filter_map(|(t, k)| k.then_some(t))
        .collect();
    if tets.is_empty() {
        return Err(empty());
    }
    // Only the largest piece: stray islands of a cell or two would be
    // separate bodies to the simulation.
    let (pieces, piece) = tet_components(&tets);
    if pieces > 1 {
        let mut size = vec![0usize; pieces];
        for p in &piece {
            size[*p as usize] += 1;
        }
        let largest = (0..pieces).max_by_key(|&p| size[p]).unwrap_or(0) as u32;
        let mut t = 0;
        tets.retain(|_| {
            t += 1;
            piece[t - 1] == largest
        });
    }
    let mut new_of_old = vec![u32::MAX; positions.len()];
    let mut used = Vec::new();
    for tet in &mut tets {
        for v in tet.iter_mut() {
            if new_of_old[*v as usize] == u32::MAX {
                new_of_old[*v as usize] = used.len() as u32;
                used.push(positions[*v as usize]);
            }
            *v = new_of_old[*v as usize];
        }
    }
    snap(inside, &mut used, &tets, cell_m);
    let mesh = TetMesh::new(used, tets)?;
    debug_assert_eq!(mesh.reoriented(), 0);
    Ok(mesh)
}

/// A signed-distance-like function of an axis-aligned ellipsoid: exact on the
/// surface and at the centre, a close bound near the surface (the gradient
/// form k0 (k0 - 1) / k1 with k0 = |p / r|, k1 = |p / r^2|).
fn ellipsoid_distance(p: Vec3, center: Vec3, radii: Vec3) -> Real {
    let q = (p - center) / radii;
    let k0 = q.length();
    let k1 = (q / radii).length();
    if k1 > 0.0 {
        k0 * (k0 - 1.0) / k1
    } else {
        -radii.min_element()
    }
}

/// An ellipsoid with axis-aligned radii.
pub fn ellipsoid(
    center_m: Vec3,
    radii_m: Vec3,
    cell_m: Real,
    lattice: Lattice,
) -> Result<TetMesh, GenerateError> {
    check_finite(["center_m.x", "center_m.y", "center_m.z"], center_m)?;
    check_positive(["radii_m.x", "radii_m.y", "radii_m.z"], radii_m)?;
    let f = move |p: Vec3| ellipsoid_distance(p, center_m, radii_m);
    implicit_mesh(&f, center_m - radii_m, center_m + radii_m, cell_m, lattice)
}

/// Polynomial smooth minimum: equals `min(a, b)` when they differ by more
/// than `k`, rounds the crease over a width of about `k` otherwise.
fn smooth_min(a: Real, b: Real, k: Real) -> Real {
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - h * h * k / 4.0
}

/// Polynomial smooth maximum (smooth intersection), see [`smooth_min`].
fn smooth_max(a: Real, b: Real, k: Real) -> Real {
    -smooth_min(-a, -b, k)
}

/// Axis-aligned bounds (min, max) of the liver shape (m), with a margin of
/// about a millimetre (a test samples the shape to check them).
pub const LIVER_BOUNDS_M: (Vec3, Vec3) = (
    Vec3::new(-0.111, -0.076, -0.044),
    Vec3::new(0.112, 0.076, 0.048),
);

/// The cell (m) for which [`liver`] on [`Lattice::BodyCentred`] yields about
/// 8000 tetrahedra (7910 measured; a test checks 6500..9500). Each cube of
/// the lattice holds 12 tetrahedra of volume cell^3 / 12, so the count is
/// about 12 V / cell^3 with V = 1.4 L.
pub const LIVER_CELL_M_8K: Real = 0.0125;

/// The liver shape, negative inside (m), signed-distance-like near the surface.
///
/// Axes: x across the body towards the patient's left, y anterior, z
/// superior; origin near the centre. A large right lobe (x < 0) and a smaller
/// left lobe whose thickness tapers towards its tip, joined by a polynomial
/// smooth union; the inferior (visceral) side is flattened by a smooth cut.
/// 0.220 x 0.149 x 0.089 m, 1.40 L (an adult liver is 1.4-1.6 L).
pub fn liver_signed_distance(p: Vec3) -> Real {
    let right = ellipsoid_distance(
        p,
        Vec3::new(-0.03, 0.0, -0.003),
        Vec3::new(0.08, 0.075, 0.05),
    );
    // The left lobe's half-thickness shrinks linearly from its root to its tip.
    let left_center = Vec3::new(0.045, 0.012, 0.003);
    let left_radii = Vec3::new(0.066, 0.052, 0.030);
    let along = ((p.x - left_center.x) / left_radii.x * 0.5 + 0.5).clamp(0.0, 1.0);
    let taper = 1.0 - 0.6 * along;
    let left = ellipsoid_distance(
        p,
        left_center,
        Vec3::new(left_radii.x, left_radii.y, left_radii.z * taper),
    );
    let lobes = smooth_min(right, left, 0.03);
    // Flatter inferior surface.
    smooth_max(lobes, -0.045 - p.z, 0.02)
}

/// The liver-like organ of [`liver_signed_distance`] (see
/// [`LIVER_CELL_M_8K`] for a cell that gives about 8000 tetrahedra).
pub fn liver(cell_m: Real, lattice: Lattice) -> Result<TetMesh, GenerateError> {
    let (lo, hi) = LIVER_BOUNDS_M;
    implicit_mesh(&liver_signed_distance, lo, hi, cell_m, lattice)
}
