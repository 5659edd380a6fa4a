//! Implicit-shape generators: volumes converge, the surface is on the shape,
//! the meshes are valid, manifold, in one piece, and bad inputs are refused.

use std::collections::HashMap;
use std::f64::consts::PI;
use std::time::Instant;
use tissue::ids::TetId;
use tissue::math::{Real, Vec3};
use tissue::mesh::quality::{QualityReport, quality_report};
use tissue::mesh::shapes::{
    LIVER_BOUNDS_M, LIVER_CELL_M_8K, Lattice, SNAP_MIN_DIHEDRAL_DEG, ellipsoid, implicit_mesh,
    liver, liver_signed_distance,
};
use tissue::mesh::{GenerateError, TET_FACES, TetMesh};

fn volume(mesh: &TetMesh) -> Real {
    (0..mesh.tet_count())
        .map(|t| mesh.tet_volume_m3(TetId(t as u32)))
        .sum()
}

/// Vertices on faces that only one tetrahedron has.
fn surface_vertices(mesh: &TetMesh) -> Vec<usize> {
    let mut count: HashMap<[u32; 3], u32> = HashMap::new();
    for tet in mesh.tets() {
        for f in TET_FACES {
            let mut key = f.map(|i| tet[i].0);
            key.sort_unstable();
            *count.entry(key).or_default() += 1;
        }
    }
    let mut out: Vec<usize> = count
        .into_iter()
        .filter(|(_, c)| *c == 1)
        .flat_map(|(f, _)| f.map(|v| v as usize))
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// What every generated mesh must satisfy.
fn assert_sound(mesh: &TetMesh) -> QualityReport {
    let r = quality_report(mesh);
    assert_eq!(mesh.reoriented(), 0, "{r}");
    assert_eq!(r.components, 1, "{r}");
    assert_eq!(
        (r.non_manifold_faces, r.non_manifold_vertices),
        (0, 0),
        "{r}"
    );
    assert_eq!((r.duplicate_vertices, r.unused_vertices), (0, 0), "{r}");
    assert!(r.min_volume_m3 > 0.0, "{r}");
    assert!(r.min_dihedral_deg >= SNAP_MIN_DIHEDRAL_DEG - 1e-9, "{r}");
    r
}

/// Fraction of surface vertices within `tolerance` of the zero level set of
/// `f`, and the largest |f| over them.
fn on_surface(mesh: &TetMesh, f: impl Fn(Vec3) -> Real, tolerance: Real) -> (Real, Real) {
    let surface = surface_vertices(mesh);
    let d: Vec<Real> = surface
        .iter()
        .map(|&v| f(mesh.positions_m()[v]).abs())
        .collect();
    let close = d.iter().filter(|x| **x <= tolerance).count();
    (
        close as Real / d.len() as Real,
        d.iter().copied().fold(0.0, Real::max),
    )
}

#[test]
fn ellipsoid_volume_converges_and_surface_is_snapped() {
    let (c, r) = (Vec3::new(0.01, -0.02, 0.03), Vec3::new(0.05, 0.04, 0.03));
    let exact = 4.0 / 3.0 * PI * r.x * r.y * r.z;
    // Radial distance to the surface, in metres along the ray from the centre.
    let radial = |p: Vec3| (((p - c) / r).length() - 1.0) * r.min_element();
    let mut errors = Vec::new();
    for cell in [0.008, 0.004, 0.002] {
        let t = Instant::now();
        let mesh = ellipsoid(c, r, cell, Lattice::BodyCentred).unwrap();
        let elapsed = t.elapsed();
        let report = assert_sound(&mesh);
        let error = (volume(&mesh) - exact).abs() / exact;
        let (fraction, worst) = on_surface(&mesh, radial, 1e-3 * cell);
        println!(
            "cell {cell}: {} tets in {elapsed:?}, volume error {:.3} %, {:.2} % of the surface \
             within 1e-3 cell (worst {:.3} cell), dihedral {:.1}..{:.1}",
            mesh.tet_count(),
            100.0 * error,
            100.0 * fraction,
            worst / cell,
            report.min_dihedral_deg,
            report.max_dihedral_deg
        );
        assert!(fraction > 0.99, "cell {cell}: {fraction}");
        assert!(worst < 0.5 * cell, "cell {cell}: {worst}");
        errors.push(error);
    }
    assert!(errors[2] < 0.02, "{errors:?}");
    assert!(errors[2] < errors[0], "{errors:?}");
}

#[test]
fn cubic_lattice_is_sound_too() {
    let (c, r) = (Vec3::ZERO, Vec3::new(0.05, 0.04, 0.03));
    let mesh = ellipsoid(c, r, 0.004, Lattice::Cubic).unwrap();
    assert_sound(&mesh);
    let exact = 4.0 / 3.0 * PI * r.x * r.y * r.z;
    assert!((volume(&mesh) - exact).abs() / exact < 0.03);
    // Fewer of its surface vertices can move all the way (see the peel rule).
    let radial = |p: Vec3| (((p - c) / r).length() - 1.0) * r.min_element();
    let (fraction, worst) = on_surface(&mesh, radial, 1e-3 * 0.004);
    assert!(fraction > 0.85 && worst < 0.5 * 0.004, "{fraction} {worst}");
}

#[test]
fn torus_is_one_manifold_piece() {
    // Not convex and not simply connected: the repair must not pinch it.
    let torus = |p: Vec3| (Vec3::new(p.x, p.y, 0.0).length() - 0.04).hypot(p.z) - 0.015;
    let mesh = implicit_mesh(
        &torus,
        Vec3::new(-0.055, -0.055, -0.015),
        Vec3::new(0.055, 0.055, 0.015),
        0.004,
        Lattice::BodyCentred,
    )
    .unwrap();
    assert_sound(&mesh);
    let exact = 2.0 * PI * PI * 0.04 * 0.015 * 0.015;
    assert!((volume(&mesh) - exact).abs() / exact < 0.05);
}

#[test]
fn liver_at_8k_cells() {
    let t = Instant::now();
    let mesh = liver(LIVER_CELL_M_8K, Lattice::BodyCentred).unwrap();
    let elapsed = t.elapsed();
    let r = assert_sound(&mesh);
    let litres = volume(&mesh) * 1000.0;
    let (fraction, worst) = on_surface(&mesh, liver_signed_distance, 1e-3 * LIVER_CELL_M_8K);
    println!(
        "liver: {elapsed:?}, {litres:.3} L, {:.2} % of the surface snapped (worst {:.3} cell)\n{r}",
        100.0 * fraction,
        worst / LIVER_CELL_M_8K
    );
    assert!((6500..=9500).contains(&mesh.tet_count()), "{r}");
    assert!((1.0..=1.8).contains(&litres), "{litres} L");
    assert!(fraction > 0.98 && worst < 0.5 * LIVER_CELL_M_8K);
    let (lo, hi) = mesh.bounds_m();
    let size = hi - lo;
    assert!(
        size.x > 0.2 && size.x < 0.24 && size.y > 0.13 && size.z > 0.07,
        "{size}"
    );
}

#[test]
fn liver_bounds_hold_the_shape_tightly() {
    let (lo, hi) = LIVER_BOUNDS_M;
    let step = 0.002;
    let (mut seen_lo, mut seen_hi) = (Vec3::splat(Real::INFINITY), Vec3::splat(-Real::INFINITY));
    let margin = Vec3::splat(0.01);
    let n = ((hi - lo + 2.0 * margin) / step).ceil().as_uvec3();
    for k in 0..=n.z {
        for j in 0..=n.y {
            for i in 0..=n.x {
                let p = lo - margin + Vec3::new(i as Real, j as Real, k as Real) * step;
                if liver_signed_distance(p) < 0.0 {
                    seen_lo = seen_lo.min(p);
                    seen_hi = seen_hi.max(p);
                }
            }
        }
    }
    assert!(
        seen_lo.cmpge(lo).all() && seen_hi.cmple(hi).all(),
        "{seen_lo} {seen_hi}"
    );
    assert!((seen_lo - lo).max_element() < 0.004, "{seen_lo}");
    assert!((hi - seen_hi).max_element() < 0.004, "{seen_hi}");
    // The origin is near the centre.
    assert!(((lo + hi) / 2.0).length() < 0.01);
}

#[test]
fn bad_inputs_are_refused() {
    let r = Vec3::splat(0.02);
    let e = |c: Vec3, r: Vec3, cell: Real| ellipsoid(c, r, cell, Lattice::BodyCentred).unwrap_err();
    assert!(matches!(
        e(Vec3::ZERO, r, Real::NAN),
        GenerateError::NotPositive {
            field: "cell_m",
            ..
        }
    ));
    assert!(matches!(
        e(Vec3::ZERO, r, -0.01),
        GenerateError::NotPositive {
            field: "cell_m",
            ..
        }
    ));
    assert!(matches!(
        e(Vec3::ZERO, Vec3::new(0.02, -0.01, 0.02), 0.005),
        GenerateError::NotPositive {
            field: "radii_m.y",
            ..
        }
    ));
    assert!(matches!(
        e(Vec3::ZERO, Vec3::new(0.02, 0.02, Real::NAN), 0.005),
        GenerateError::NotPositive {
            field: "radii_m.z",
            ..
        }
    ));
    assert!(matches!(
        e(Vec3::new(Real::INFINITY, 0.0, 0.0), r, 0.005),
        GenerateError::NotFinite {
            field: "center_m.x",
            ..
        }
    ));
    assert!(matches!(
        e(Vec3::ZERO, r, 1e-7),
        GenerateError::TooLarge { .. }
    ));
    let nothing = |_: Vec3| 1.0;
    let err = implicit_mesh(&nothing, Vec3::ZERO, r, 0.005, Lattice::Cubic).unwrap_err();
    assert!(matches!(err, GenerateError::Empty { .. }));
    assert!(err.to_string().contains("nothing to mesh"), "{err}");
    let err = implicit_mesh(&nothing, r, Vec3::ZERO, 0.005, Lattice::Cubic).unwrap_err();
    assert!(matches!(
        err,
        GenerateError::NotPositive {
            field: "hi_m.x - lo_m.x",
            ..
        }
    ));
    assert!(err.to_string().contains("hi_m.x - lo_m.x"), "{err}");
}
