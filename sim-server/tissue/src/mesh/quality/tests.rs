//! Mesh quality checks' unit tests.

use super::*;
use crate::mesh::{BoxSpec, CellSize};

fn regular() -> Vec<Vec3> {
    vec![
        Vec3::new(1.0, 1.0, 1.0),
        Vec3::new(1.0, -1.0, -1.0),
        Vec3::new(-1.0, 1.0, -1.0),
        Vec3::new(-1.0, -1.0, 1.0),
    ]
}

#[test]
fn regular_tet_is_perfect() {
    let r = quality_report(&TetMesh::new(regular(), vec![[0, 1, 2, 3]]).unwrap());
    let expected = (1.0 / 3.0 as Real).acos().to_degrees();
    assert!((expected - 70.528_779).abs() < 1e-5);
    assert!((r.min_dihedral_deg - expected).abs() < 1e-9);
    assert!((r.max_dihedral_deg - expected).abs() < 1e-9);
    assert!((r.max_aspect_ratio - 1.0).abs() < 1e-12);
    assert!((r.mean_aspect_ratio - 1.0).abs() < 1e-12);
    assert!((r.shortest_edge_m - 8.0_f64.sqrt()).abs() < 1e-12);
    assert_eq!((r.components, r.non_manifold_vertices), (1, 0));
    assert_eq!((r.duplicate_vertices, r.unused_vertices), (0, 0));
}

#[test]
fn kuhn_box_angles_and_topology() {
    let mesh = BoxSpec::new(Vec3::new(0.03, 0.02, 0.02), CellSize::EdgeM(0.01))
        .generate()
        .unwrap();
    let r = quality_report(&mesh);
    // Kuhn tetrahedra of a cube have dihedral angles of 45, 60 and 90 degrees.
    assert!((r.min_dihedral_deg - 45.0).abs() < 1e-9, "{r}");
    assert!((r.max_dihedral_deg - 90.0).abs() < 1e-9, "{r}");
    assert_eq!(r.components, 1);
    assert_eq!((r.non_manifold_faces, r.non_manifold_vertices), (0, 0));
    assert_eq!((r.duplicate_vertices, r.unused_vertices), (0, 0));
    assert!((r.shortest_edge_m - 0.01).abs() < 1e-12);
    assert!((r.longest_edge_m - 0.01 * 3.0_f64.sqrt()).abs() < 1e-12);
    let text = r.to_string();
    assert!(
        text.contains("1 component(s)") && text.contains("45.00"),
        "{text}"
    );
}

/// Two boxes' vertices and tetrahedra in one mesh.
fn two_boxes(gap_m: Real) -> TetMesh {
    let a = BoxSpec::new(Vec3::splat(0.02), CellSize::EdgeM(0.01))
        .generate()
        .unwrap();
    let mut b = BoxSpec::new(Vec3::splat(0.02), CellSize::EdgeM(0.01));
    b.origin_m = Vec3::new(0.02 + gap_m, 0.0, 0.0);
    let b = b.generate().unwrap();
    let offset = a.vertex_count() as u32;
    let mut positions = a.positions_m().to_vec();
    positions.extend_from_slice(b.positions_m());
    let tets = a
        .tets()
        .iter()
        .map(|t| t.map(|v| v.0))
        .chain(b.tets().iter().map(|t| t.map(|v| v.0 + offset)))
        .collect();
    TetMesh::new(positions, tets).unwrap()
}

#[test]
fn separate_boxes_are_two_components() {
    let r = quality_report(&two_boxes(0.005));
    assert_eq!(r.components, 2);
    assert_eq!((r.non_manifold_vertices, r.duplicate_vertices), (0, 0));
}

#[test]
fn touching_boxes_share_duplicated_vertices() {
    // The boxes touch but their contact vertices are separate copies: the
    // duplicates are found and the pieces stay two components.
    let r = quality_report(&two_boxes(0.0));
    assert_eq!(r.duplicate_vertices, 2 * 9);
    assert_eq!(r.components, 2);
}

#[test]
fn tets_sharing_only_a_vertex_are_non_manifold() {
    let mut p = regular();
    p.extend([
        Vec3::new(3.0, 3.0, 3.0),
        Vec3::new(1.0, 3.0, 3.0),
        Vec3::new(3.0, 1.0, 3.0),
    ]);
    let r = quality_report(&TetMesh::new(p, vec![[0, 1, 2, 3], [0, 4, 5, 6]]).unwrap());
    assert_eq!(r.non_manifold_vertices, 1);
    assert_eq!(r.components, 2);
    assert_eq!(r.non_manifold_faces, 0);
}

#[test]
fn non_manifold_face_and_edge() {
    // Three tetrahedra on one face.
    let mut p = regular();
    p.push(Vec3::new(-2.0, -2.0, -2.0));
    p.push(Vec3::new(0.1, 0.2, -0.1) * 10.0);
    let tets = vec![[0, 1, 2, 3], [1, 2, 3, 4], [1, 2, 3, 5]];
    let r = quality_report(&TetMesh::new(p, tets).unwrap());
    assert_eq!(r.non_manifold_faces, 1);
    assert_eq!(r.non_manifold_vertices, 3);

    // Two tetrahedra sharing only an edge: both edge ends are pinched.
    let p = vec![
        Vec3::ZERO,
        Vec3::Z,
        Vec3::X,
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(-1.0, -1.0, 0.0),
    ];
    let r = quality_report(&TetMesh::new(p, vec![[0, 1, 2, 3], [0, 1, 4, 5]]).unwrap());
    assert_eq!(r.non_manifold_vertices, 2);
}

#[test]
fn duplicate_and_unused_vertices() {
    let mut p = regular();
    p.push(p[2] + Vec3::splat(1e-12));
    p.push(Vec3::splat(5.0));
    let r = quality_report(&TetMesh::new(p, vec![[0, 1, 2, 3]]).unwrap());
    assert_eq!(r.duplicate_vertices, 2);
    assert_eq!(r.unused_vertices, 2);
    assert_eq!(r.used_vertices, 4);
}

#[test]
fn sliver_has_tiny_dihedral_angle() {
    // A square's corners lifted alternately by 1 %: all edges about the
    // same length, yet nearly flat (the classic sliver).
    let h = 0.01;
    let p = vec![
        Vec3::new(0.0, 0.0, h),
        Vec3::new(1.0, 0.0, -h),
        Vec3::new(1.0, 1.0, h),
        Vec3::new(0.0, 1.0, -h),
    ];
    let r = quality_report(&TetMesh::new(p, vec![[0, 1, 2, 3]]).unwrap());
    assert!(r.min_dihedral_deg < 3.0, "{r}");
    assert!(r.max_dihedral_deg > 175.0, "{r}");
    assert!(r.max_aspect_ratio > 20.0, "{r}");
    let edge_ratio = r.longest_edge_m / r.shortest_edge_m;
    assert!(edge_ratio < 1.5);
}
