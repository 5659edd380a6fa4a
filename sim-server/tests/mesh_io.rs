//! Laws of mesh import and export: the reference meshes agree across formats,
//! writers and readers round-trip exactly, malformed files are refused with
//! the line of the fault, and no truncation of a valid file makes a parser
//! panic.

use sim_server::ids::{TetId, VertexId};
use sim_server::math::Vec3;
use sim_server::mesh::io::{
    DataArray, ImportedMesh, MeshFormat, MeshIoError, parse_mesh, read_mesh, write_medit,
    write_msh, write_obj, write_pvd, write_stl, write_vtk, write_vtu, write_vtu_zlib,
};
use std::path::{Path, PathBuf};

const MESHES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/meshes/");

fn reference(name: &str) -> ImportedMesh {
    let path = PathBuf::from(MESHES).join(name);
    read_mesh(&path).unwrap_or_else(|e| panic!("{e}"))
}

fn volume(m: &ImportedMesh) -> f64 {
    (0..m.mesh.tet_count())
        .map(|t| m.mesh.tet_volume_m3(TetId(t as u32)))
        .sum()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mesh_io_test_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// Asserts that parsing fails at `line`, naming the file and the line, and
/// that the message contains `needle`.
fn fails_at(text: &str, format: MeshFormat, line: usize, needle: &str) -> MeshIoError {
    let e = match parse_mesh("t.x", text.as_bytes(), format) {
        Ok(_) => panic!("accepted a malformed file, expected an error at line {line}:\n{text}"),
        Err(e) => e,
    };
    let msg = e.to_string();
    assert!(
        msg.starts_with(&format!("t.x:{line}:")),
        "expected line {line}: {msg}"
    );
    assert_eq!(e.line(), Some(line), "{msg}");
    assert!(msg.contains(needle), "expected {needle:?} in: {msg}");
    e
}

/// Replaces 1-based line `line` of `text`.
fn with_line(text: &str, line: usize, new: &str) -> String {
    let mut lines: Vec<&str> = text.lines().collect();
    lines[line - 1] = new;
    lines.join("\n") + "\n"
}

#[test]
fn reference_meshes_agree_across_formats() {
    for (names, tets, vertices) in [
        (
            &[
                "ellipsoid_v41.msh",
                "ellipsoid_v41bin.msh",
                "ellipsoid_v22.msh",
            ][..],
            2182,
            567,
        ),
        (&["box_v41.msh", "box_v22.msh"][..], 1816, 559),
    ] {
        let meshes: Vec<ImportedMesh> = names.iter().map(|n| reference(n)).collect();
        for (m, name) in meshes.iter().zip(names) {
            assert_eq!(m.mesh.tet_count(), tets, "{name}");
            assert_eq!(m.mesh.vertex_count(), vertices, "{name}");
            assert!(
                m.tet_physical.iter().all(|&p| p == 1),
                "{name}: physical tags {:?}",
                &m.tet_physical[..5]
            );
            assert_eq!(m.tet_physical.len(), tets);
            // The boundary (physical surface 2) is kept for selections;
            // the lines and points Gmsh also wrote are ignored.
            assert!(
                !m.surface_physical.is_empty() && m.surface_physical.iter().all(|(_, t)| *t == 2),
                "{name}"
            );
            assert!(m.warnings.is_empty(), "{name}: {:?}", m.warnings);
        }
        // The ASCII files print 16 significant digits, the binary one stores
        // the exact doubles: the same geometry up to the last bit.
        let first = &meshes[0];
        let (lo0, hi0) = first.mesh.bounds_m();
        for (m, name) in meshes.iter().zip(names).skip(1) {
            let (lo, hi) = m.mesh.bounds_m();
            assert!(
                lo.abs_diff_eq(lo0, 1e-17) && hi.abs_diff_eq(hi0, 1e-17),
                "{name}"
            );
            assert!(
                (volume(m) - volume(first)).abs() <= 1e-12 * volume(first),
                "{name}"
            );
            for (p, q) in m.mesh.positions_m().iter().zip(first.mesh.positions_m()) {
                assert!(p.abs_diff_eq(*q, 1e-17), "{name}: {p} != {q}");
            }
            assert_eq!(m.mesh.tets(), first.mesh.tets(), "{name}");
        }
    }
    let b = reference("box_v41.msh");
    let (lo, hi) = b.mesh.bounds_m();
    assert!(lo.abs_diff_eq(Vec3::ZERO, 1e-12) && hi.abs_diff_eq(Vec3::new(0.1, 0.02, 0.02), 1e-12));
    assert!((volume(&b) - 0.1 * 0.02 * 0.02).abs() < 1e-12 * 4e-5 * 1e3);
    let e = reference("ellipsoid_v41.msh");
    let exact = 4.0 / 3.0 * std::f64::consts::PI * 0.04 * 0.025 * 0.02;
    assert!(
        volume(&e) < exact && volume(&e) > 0.9 * exact,
        "inscribed polyhedron"
    );
}

#[test]
fn legacy_vtk_round_trip_is_exact() {
    let m = reference("box_v41.msh");
    let path = scratch("box.vtk");
    let n = m.mesh.vertex_count();
    let disp: Vec<Vec3> = (0..n).map(|i| Vec3::new(i as f64, -0.5, 1e-300)).collect();
    write_vtk(
        &path,
        m.mesh.positions_m(),
        m.mesh.tets(),
        &[("displacement", DataArray::Vectors(&disp))],
        &[],
    )
    .unwrap();
    let back = read_mesh(&path).unwrap();
    assert_eq!(back.mesh.positions_m(), m.mesh.positions_m());
    assert_eq!(back.mesh.tets(), m.mesh.tets());
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    // A name legacy VTK cannot hold, or a wrong count: no file.
    let bad = scratch("bad.vtk");
    assert!(matches!(
        write_vtk(
            &bad,
            m.mesh.positions_m(),
            m.mesh.tets(),
            &[("two words", DataArray::Vectors(&disp))],
            &[]
        ),
        Err(MeshIoError::BadInput { .. })
    ));
    assert!(matches!(
        write_vtk(
            &bad,
            m.mesh.positions_m(),
            m.mesh.tets(),
            &[("u", DataArray::Vectors(&disp[1..]))],
            &[]
        ),
        Err(MeshIoError::BadInput { .. })
    ));
    assert!(!bad.exists());
}

#[test]
fn vtu_round_trip_is_exact() {
    let m = reference("box_v41.msh");
    let path = scratch("box.vtu");
    let n = m.mesh.vertex_count();
    let disp: Vec<Vec3> = (0..n).map(|i| Vec3::new(i as f64, -0.5, 1e-300)).collect();
    let physical: Vec<f64> = m.tet_physical.iter().map(|&p| f64::from(p)).collect();
    write_vtu(
        &path,
        m.mesh.positions_m(),
        m.mesh.tets(),
        &[("displacement", DataArray::Vectors(&disp))],
        &[
            ("physical", DataArray::Scalars(&physical)),
            (
                "stress",
                DataArray::Scalars(&vec![0.25; m.mesh.tet_count()]),
            ),
        ],
    )
    .unwrap();
    let back = read_mesh(&path).unwrap();
    assert_eq!(back.mesh.positions_m(), m.mesh.positions_m());
    assert_eq!(back.mesh.tets(), m.mesh.tets());
    assert_eq!(back.tet_physical, m.tet_physical);
    assert_eq!(back.mesh.reoriented(), 0);
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);

    let pvd = scratch("run.pvd");
    write_pvd(
        &pvd,
        &[(0.0, path.clone()), (0.001, PathBuf::from("sub/step1.vtu"))],
    )
    .unwrap();
    let text = std::fs::read_to_string(&pvd).unwrap();
    assert!(text.contains("file=\"box.vtu\""), "{text}");
    assert!(
        text.contains("file=\"sub/step1.vtu\"") && text.contains("timestep=\"1e-3\""),
        "{text}"
    );
    assert!(matches!(
        write_pvd(&pvd, &[(f64::NAN, path.clone())]),
        Err(MeshIoError::BadInput { .. })
    ));
    assert!(matches!(
        write_vtu(
            &path,
            m.mesh.positions_m(),
            m.mesh.tets(),
            &[("d", DataArray::Vectors(&disp[1..]))],
            &[]
        ),
        Err(MeshIoError::BadInput { .. })
    ));
}

#[test]
fn compressed_vtu_round_trip_is_exact_and_smaller() {
    let m = reference("box_v41.msh");
    let (plain, packed) = (scratch("plain.vtu"), scratch("packed.vtu"));
    let n = m.mesh.vertex_count();
    let disp: Vec<Vec3> = (0..n).map(|i| Vec3::new(i as f64, -0.5, 1e-300)).collect();
    let ids: Vec<u32> = (0..n as u32).rev().collect();
    let physical: Vec<f64> = m.tet_physical.iter().map(|&p| f64::from(p)).collect();
    let point_data = [
        ("displacement", DataArray::Vectors(&disp)),
        ("original_id", DataArray::Ids(&ids)),
    ];
    let cell_data = [("physical", DataArray::Scalars(&physical))];
    for (path, write) in [
        (&plain, write_vtu as fn(_, _, _, _, _) -> _),
        (&packed, write_vtu_zlib),
    ] {
        write(
            path,
            m.mesh.positions_m(),
            m.mesh.tets(),
            &point_data,
            &cell_data,
        )
        .unwrap();
        let back = read_mesh(path).unwrap();
        assert_eq!(back.mesh.positions_m(), m.mesh.positions_m());
        assert_eq!(back.mesh.tets(), m.mesh.tets());
        assert_eq!(back.tet_physical, m.tet_physical);
        assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    }
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    assert!(
        size(&packed) * 2 < size(&plain),
        "{} compressed vs {} bytes",
        size(&packed),
        size(&plain)
    );
}

#[test]
fn medit_round_trip_is_exact() {
    let m = reference("ellipsoid_v22.msh");
    let path = scratch("ellipsoid.mesh");
    let refs: Vec<i32> = (0..m.mesh.tet_count() as i32).map(|t| t % 5).collect();
    write_medit(&path, m.mesh.positions_m(), m.mesh.tets(), &refs).unwrap();
    let back = read_mesh(&path).unwrap();
    assert_eq!(back.mesh.positions_m(), m.mesh.positions_m());
    assert_eq!(back.mesh.tets(), m.mesh.tets());
    assert_eq!(back.tet_physical, refs);
}

#[test]
fn obj_and_stl_have_the_right_sizes() {
    let m = reference("box_v22.msh");
    // Every tetrahedron's faces: not a surface, but any triangle list will do.
    let tris: Vec<[VertexId; 3]> = m
        .mesh
        .tets()
        .iter()
        .flat_map(|t| sim_server::mesh::TET_FACES.map(|f| f.map(|k| t[k])))
        .collect();
    let stl = scratch("faces.stl");
    write_stl(&stl, m.mesh.positions_m(), &tris).unwrap();
    let bytes = std::fs::read(&stl).unwrap();
    assert_eq!(bytes.len(), 84 + 50 * tris.len());
    assert_eq!(
        u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize,
        tris.len()
    );
    assert!(
        !bytes.starts_with(b"solid"),
        "a binary STL must not look like ASCII STL"
    );
    // The first facet normal is the unit normal of the first triangle.
    let f = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()) as f64;
    let n = Vec3::new(f(84), f(88), f(92));
    let [a, b, c] = tris[0].map(|v| m.mesh.positions_m()[v.idx()]);
    assert!((n - (b - a).cross(c - a).normalize()).length() < 1e-6);

    let obj = scratch("faces.obj");
    write_obj(&obj, m.mesh.positions_m(), &tris).unwrap();
    let text = std::fs::read_to_string(&obj).unwrap();
    assert_eq!(
        text.lines().filter(|l| l.starts_with("f ")).count(),
        tris.len()
    );
    assert_eq!(
        text.lines().filter(|l| l.starts_with("v ")).count(),
        m.mesh.vertex_count()
    );

    let bad = [[VertexId(0), VertexId(1), VertexId(9999)]];
    assert!(matches!(
        write_stl(&stl, m.mesh.positions_m(), &bad),
        Err(MeshIoError::BadInput { .. })
    ));
}

#[test]
fn unknown_extension_and_missing_file() {
    assert!(matches!(
        read_mesh(Path::new("a.stl")),
        Err(MeshIoError::UnknownFormat { .. })
    ));
    let e = read_mesh(Path::new("/nonexistent/a.msh")).unwrap_err();
    assert!(
        matches!(e, MeshIoError::Io { .. }) && e.to_string().starts_with("/nonexistent/a.msh:")
    );
}

// Two tetrahedra and a triangle, sparse node tags, physical 3 on the volume.
const MSH41: &str = "$MeshFormat
4.1 0 8
$EndMeshFormat
$Entities
0 0 1 1
5 0 0 0 1 1 1 1 2 0
7 0 0 0 1 1 1 1 3 1 5
$EndEntities
$Nodes
1 5 10 50
3 7 0 5
10
20
30
40
50
0 0 0
1 0 0
0 1 0
0 0 1
1 1 1
$EndNodes
$Elements
2 3 1 3
2 5 2 1
1 10 20 30
3 7 4 2
2 10 20 30 40
3 20 30 40 50
$EndElements
";

#[test]
fn msh41_small_file_and_its_faults() {
    let m = parse_mesh("t.x", MSH41.as_bytes(), MeshFormat::Msh).unwrap();
    assert_eq!((m.mesh.vertex_count(), m.mesh.tet_count()), (5, 2));
    assert_eq!(m.tet_physical, [3, 3]);
    assert_eq!(m.mesh.tets()[1].map(|v| v.0)[0], 1, "tag 20 is vertex 1");
    // The triangle is on surface 5, physical group 2: kept for surface
    // selections, not ignored.
    assert_eq!(m.surface_physical, [([0, 1, 2], 2)]);
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    // On a surface in no physical group it is ignored, with a warning.
    let untagged = MSH41.replace("5 0 0 0 1 1 1 1 2 0", "5 0 0 0 1 1 1 0 0");
    let m = parse_mesh("t.x", untagged.as_bytes(), MeshFormat::Msh).unwrap();
    assert!(m.surface_physical.is_empty());
    assert!(
        m.warnings.iter().any(|w| w.contains("ignored 1 triangles")),
        "{:?}",
        m.warnings
    );

    let f = MeshFormat::Msh;
    fails_at(
        &with_line(MSH41, 28, "2 10 20 30"),
        f,
        28,
        "expected 4 node tags for a tetrahedron, found 3",
    );
    fails_at(
        &with_line(MSH41, 19, "0 abc 0"),
        f,
        19,
        "expected y, found 'abc'",
    );
    fails_at(
        &with_line(MSH41, 29, "3 20 30 40 99"),
        f,
        29,
        "references node 99",
    );
    fails_at(&with_line(MSH41, 21, "1 NaN 1"), f, 21, "non-finite");
    let e = fails_at(
        &with_line(MSH41, 27, "3 7 11 2"),
        f,
        27,
        "10-node tetrahedra (Gmsh type 11)",
    );
    assert!(matches!(e, MeshIoError::UnsupportedElement { .. }));
    fails_at(
        &with_line(MSH41, 10, "1 6 10 50"),
        f,
        9,
        "declares 6 nodes but its blocks hold 5",
    );
    fails_at(
        &with_line(MSH41, 10, "1 1000000000000 10 50"),
        f,
        9,
        "declares 1000000000000 nodes",
    );
    fails_at(
        &with_line(MSH41, 11, "3 7 0 1000000000000"),
        f,
        17,
        "unexpected extra value",
    );
    fails_at(
        &with_line(MSH41, 11, "3 7 0 4"),
        f,
        16,
        "line ends early: expected y",
    );
    let e = fails_at(
        &with_line(MSH41, 21, "0.5 0.5 0"),
        f,
        29,
        // In the file's own numbering: element and node tags.
        "element 3 (nodes 20 30 40 50) has zero volume",
    );
    assert!(matches!(e, MeshIoError::Element { .. }), "{e}");
    let cut: String = MSH41.lines().take(28).map(|l| format!("{l}\n")).collect();
    fails_at(&cut, f, 29, "file ends before a tetrahedron");
    fails_at(
        &with_line(MSH41, 2, "4.0 0 8"),
        f,
        2,
        "version '4.0' is not supported",
    );
}

const MSH22: &str = "$MeshFormat
2.2 0 8
$EndMeshFormat
$Nodes
5
10 0 0 0
20 1 0 0
30 0 1 0
40 0 0 1
50 1 1 1
$EndNodes
$Elements
3
1 2 2 2 5 10 20 30
2 4 2 3 7 10 20 30 40
3 4 2 3 7 20 30 40 50
$EndElements
";

#[test]
fn msh22_small_file_and_its_faults() {
    let m = parse_mesh("t.x", MSH22.as_bytes(), MeshFormat::Msh).unwrap();
    assert_eq!((m.mesh.vertex_count(), m.mesh.tet_count()), (5, 2));
    assert_eq!(m.tet_physical, [3, 3]);
    let f = MeshFormat::Msh;
    fails_at(
        &with_line(MSH22, 5, "6"),
        f,
        11,
        "declares 6 nodes but Nodes ends after 5",
    );
    fails_at(&with_line(MSH22, 13, "2"), f, 16, "expected $EndElements");
    fails_at(
        &with_line(MSH22, 15, "2 4 2 3 7 10 20 30"),
        f,
        15,
        "found 3",
    );
    fails_at(
        &with_line(MSH22, 15, "2 5 2 3 7 10 20 30 40 1 2 3 4"),
        f,
        15,
        "hexahedra (Gmsh type 5)",
    );
    fails_at(
        &with_line(MSH22, 16, "3 4 2 3 7 20 30 40 51"),
        f,
        16,
        "node 51",
    );
    fails_at(
        &with_line(MSH22, 8, "30 0 1.0.0 0"),
        f,
        8,
        "expected a node",
    );
    fails_at(&with_line(MSH22, 8, "30 0 inf 0"), f, 8, "non-finite");
    fails_at(
        &with_line(MSH22, 13, "3000000000000"),
        f,
        17,
        "declares 3000000000000 elements",
    );
    // Inverted input is reoriented with a warning.
    let inv = with_line(MSH22, 15, "2 4 2 3 7 10 30 20 40");
    let m = parse_mesh("t.x", inv.as_bytes(), f).unwrap();
    assert_eq!(m.mesh.reoriented(), 1);
    assert!(
        m.warnings
            .iter()
            .any(|w| w == "1 inverted tetrahedra reoriented: element 2 (line 15)"),
        "{:?}",
        m.warnings
    );
    let only_tri = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n$EndNodes\n$Elements\n1\n1 2 0 1 2 3\n$EndElements\n";
    let e = parse_mesh("t.x", only_tri.as_bytes(), f).unwrap_err();
    assert!(matches!(e, MeshIoError::NoTetrahedra { .. }), "{e}");
}

#[test]
fn msh41_binary_faults_give_byte_offsets() {
    let bytes = std::fs::read(PathBuf::from(MESHES).join("ellipsoid_v41bin.msh")).unwrap();
    for cut in [bytes.len() / 2, bytes.len() - 20, 100] {
        let e = parse_mesh("b.msh", &bytes[..cut], MeshFormat::Msh).unwrap_err();
        assert!(e.to_string().starts_with("b.msh:byte "), "{e}");
    }
}

const VTK: &str = "# vtk DataFile Version 3.0
test
ASCII
DATASET UNSTRUCTURED_GRID
POINTS 5 double
0 0 0 1 0 0 0 1 0
0 0 1 1 1 1
CELLS 3 14
3 0 1 2
4 0 1 2 3
4 1 2 3 4
CELL_TYPES 3
5
10
10
CELL_DATA 3
SCALARS gmsh:physical int 1
LOOKUP_TABLE default
2
3
3
";

#[test]
fn legacy_vtk_both_layouts_and_faults() {
    let m = parse_mesh("t.x", VTK.as_bytes(), MeshFormat::VtkLegacy).unwrap();
    assert_eq!((m.mesh.vertex_count(), m.mesh.tet_count()), (5, 2));
    assert_eq!(m.tet_physical, [3, 3]);
    let v5 = VTK.replace(
        "CELLS 3 14\n3 0 1 2\n4 0 1 2 3\n4 1 2 3 4\n",
        "CELLS 4 11\nOFFSETS vtktypeint64\n0 3 7 11\nCONNECTIVITY vtktypeint64\n0 1 2 0 1 2 3 1 2 3 4\n",
    );
    let m5 = parse_mesh("t.x", v5.as_bytes(), MeshFormat::VtkLegacy).unwrap();
    assert_eq!(m5.mesh.tets(), m.mesh.tets());
    assert_eq!(m5.tet_physical, [3, 3]);

    let f = MeshFormat::VtkLegacy;
    fails_at(&with_line(VTK, 7, "0 0 1 1 x 1"), f, 7, "found 'x'");
    fails_at(
        &with_line(VTK, 11, "4 1 2 3 5"),
        f,
        11,
        "references point 5",
    );
    fails_at(&with_line(VTK, 11, "3 1 2 3"), f, 8, "list size of 14");
    fails_at(
        &with_line(VTK, 15, "12"),
        f,
        11,
        "hexahedron (VTK cell type 12)",
    );
    fails_at(
        &with_line(VTK, 5, "POINTS 500000000000 double"),
        f,
        8,
        "expected a point coordinate, found 'CELLS'",
    );
    // An ASCII body under a BINARY header: the binary reader names the byte.
    let e = parse_mesh("t.x", with_line(VTK, 3, "BINARY").as_bytes(), f).unwrap_err();
    assert!(e.to_string().contains("byte"), "{e}");
    fails_at(&with_line(VTK, 20, "2.5"), f, 20, "not a 32-bit integer");
}

const MEDIT: &str = "MeshVersionFormatted 2
Dimension 3
Vertices
5
0 0 0 0
1 0 0 0
0 1 0 0
0 0 1 0
1 1 1 0
Triangles
1
1 2 3 2
Tetrahedra
2
1 2 3 4 3
2 3 4 5 3 # a comment
End
";

#[test]
fn medit_small_file_and_its_faults() {
    let m = parse_mesh("t.x", MEDIT.as_bytes(), MeshFormat::Medit).unwrap();
    assert_eq!((m.mesh.vertex_count(), m.mesh.tet_count()), (5, 2));
    assert_eq!(m.tet_physical, [3, 3]);
    // The triangle's reference 2 makes it a surface for selections; a
    // triangle past the vertices is an error at its line.
    assert_eq!(m.surface_physical, [([0, 1, 2], 2)]);
    let f = MeshFormat::Medit;
    fails_at(
        &with_line(MEDIT, 12, "1 2 9 2"),
        f,
        12,
        "triangle 1 references vertex 9",
    );
    fails_at(
        &with_line(MEDIT, 16, "2 3 4 6 3"),
        f,
        16,
        "references vertex 6",
    );
    fails_at(&with_line(MEDIT, 7, "0 one 0 0"), f, 7, "found 'one'");
    fails_at(&with_line(MEDIT, 7, "0 NaN 0 0"), f, 7, "non-finite");
    fails_at(
        &with_line(MEDIT, 13, "Hexahedra"),
        f,
        13,
        "unsupported element hexahedra",
    );
    fails_at(&with_line(MEDIT, 14, "3"), f, 17, "found 'End'");
    fails_at(&with_line(MEDIT, 2, "Dimension 2"), f, 2, "only 3D");
    let e = fails_at(
        &with_line(MEDIT, 9, "0.5 0.5 0 0"),
        f,
        16,
        // Medit numbers from 1, as the message does.
        "tetrahedron 2 (vertices 2 3 4 5) has zero volume",
    );
    assert!(matches!(e, MeshIoError::Element { .. }), "{e}");
    // A repeated vertex, as the file numbers it (it said 0-based indices
    // beside the file's element number before).
    let e = fails_at(
        &with_line(MEDIT, 16, "2 3 3 5 3"),
        f,
        16,
        "tetrahedron 2 repeats a vertex: vertices 2 3 3 5",
    );
    assert!(!e.to_string().contains('['), "{e}");
}

const VTU: &str = r#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">
  <UnstructuredGrid>
    <Piece NumberOfPoints="5" NumberOfCells="3">
      <Points>
        <DataArray type="Float32" NumberOfComponents="3" format="ascii">
          0 0 0 1 0 0 0 1 0
          0 0 1 1 1 1
        </DataArray>
      </Points>
      <Cells>
        <DataArray type="Int32" Name="connectivity" format="ascii">0 1 2 0 1 2 3 1 2 3 4</DataArray>
        <DataArray type="Int32" Name="offsets" format="ascii">3 7 11</DataArray>
        <DataArray type="UInt8" Name="types" format="ascii">5 10 10</DataArray>
      </Cells>
      <CellData>
        <DataArray type="Int32" Name="CellEntityIds" format="ascii">2 3 3</DataArray>
      </CellData>
    </Piece>
  </UnstructuredGrid>
</VTKFile>
"#;

#[test]
fn vtu_ascii_and_appended_and_faults() {
    let m = parse_mesh("t.x", VTU.as_bytes(), MeshFormat::Vtu).unwrap();
    assert_eq!((m.mesh.vertex_count(), m.mesh.tet_count()), (5, 2));
    assert_eq!(m.tet_physical, [3, 3]);
    let f = MeshFormat::Vtu;
    fails_at(&with_line(VTU, 8, "0 0 1 1 x 1"), f, 8, "found 'x'");
    fails_at(&VTU.replace("5 10 10", "5 10 12"), f, 12, "hexahedron");
    fails_at(
        &VTU.replace("2 3 4</", "2 3 5</"),
        f,
        12,
        "references point 5",
    );
    fails_at(
        &VTU.replace("3 7 11", "3 7"),
        f,
        13,
        "expected 3 values, found 2",
    );
    fails_at(
        &VTU.replace("</Cells>", "</Points>"),
        f,
        15,
        "</Points> closes <Cells>",
    );
    fails_at(
        &VTU.replace(
            "<VTKFile type",
            "<VTKFile compressor=\"vtkLZ4DataCompressor\" type",
        ),
        f,
        2,
        "compressor 'vtkLZ4DataCompressor' is not supported (vtkZLibDataCompressor is)",
    );

    // An appended array's offset that is not a byte count says so (it was
    // reported as a missing attribute).
    let appended = r#"<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">
<UnstructuredGrid><Piece NumberOfPoints="5" NumberOfCells="2">
<Points><DataArray type="Float64" NumberOfComponents="3" format="appended" offset="-5"/></Points>
</Piece></UnstructuredGrid>
<AppendedData encoding="raw">
_
</AppendedData>
</VTKFile>
"#;
    fails_at(
        appended,
        f,
        3,
        "offset must be a byte count (a non-negative integer), found '-5'",
    );

    // The same mesh with appended raw data (UInt32 headers).
    let mut raw = Vec::new();
    let mut block = |payload: Vec<u8>| {
        let offset = raw.len();
        raw.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        raw.extend(payload);
        offset
    };
    let pts = [0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1., 1., 1., 1.];
    let o_pts = block(pts.iter().flat_map(|x: &f64| x.to_le_bytes()).collect());
    let o_conn = block(
        [0i64, 1, 2, 3, 1, 2, 3, 4]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect(),
    );
    let o_off = block([4i64, 8].iter().flat_map(|x| x.to_le_bytes()).collect());
    let o_ty = block(vec![10u8, 10]);
    let head = format!(
        r#"<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">
<UnstructuredGrid><Piece NumberOfPoints="5" NumberOfCells="2">
<Points><DataArray type="Float64" NumberOfComponents="3" format="appended" offset="{o_pts}"/></Points>
<Cells><DataArray type="Int64" Name="connectivity" format="appended" offset="{o_conn}"/>
<DataArray type="Int64" Name="offsets" format="appended" offset="{o_off}"/>
<DataArray type="UInt8" Name="types" format="appended" offset="{o_ty}"/></Cells>
</Piece></UnstructuredGrid>
<AppendedData encoding="raw">
_"#
    );
    let mut file = head.into_bytes();
    file.extend(&raw);
    file.extend(b"\n</AppendedData>\n</VTKFile>\n");
    let a = parse_mesh("t.x", &file, f).unwrap();
    assert_eq!(a.mesh.tets(), m.mesh.tets());
    assert_eq!(a.mesh.positions_m(), m.mesh.positions_m());
    assert_eq!(a.tet_physical, [0, 0]);
}

/// A compressed array may not inflate past what its points and cells
/// hold: a small file declaring five points whose zlib Points block
/// inflates to 1 MiB (well within zlib's ratio: a 1.4 MB file asked for
/// 1 GiB this way) is refused at the array's line before inflating.
#[test]
fn a_compressed_array_larger_than_its_points_need_is_refused() {
    use base64::Engine;
    use std::io::Write;
    let n = 1u64 << 20;
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(&vec![0u8; n as usize]).unwrap();
    let block = z.finish().unwrap();
    let header: Vec<u8> = [1, n, n, block.len() as u64]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let b64 = base64::engine::general_purpose::STANDARD;
    let text = format!(
        r#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64" compressor="vtkZLibDataCompressor">
<UnstructuredGrid><Piece NumberOfPoints="5" NumberOfCells="2">
<Points><DataArray type="Float64" NumberOfComponents="3" format="binary">{}{}</DataArray></Points>
<Cells>
<DataArray type="Int64" Name="connectivity" format="ascii">0 1 2 3 1 2 3 4</DataArray>
<DataArray type="Int64" Name="offsets" format="ascii">4 8</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">10 10</DataArray>
</Cells></Piece></UnstructuredGrid></VTKFile>
"#,
        b64.encode(&header),
        b64.encode(&block)
    );
    fails_at(
        &text,
        MeshFormat::Vtu,
        4,
        "Points: compressed header claims 1048576 bytes, the array holds 120",
    );
}

/// Every prefix of a valid file, and every single-byte corruption of a
/// small one, gives a result or an error, never a panic.
#[test]
fn truncations_and_corruptions_never_panic() {
    let bin = std::fs::read(PathBuf::from(MESHES).join("ellipsoid_v41bin.msh")).unwrap();
    let cases: [(&[u8], MeshFormat); 6] = [
        (MSH41.as_bytes(), MeshFormat::Msh),
        (MSH22.as_bytes(), MeshFormat::Msh),
        (&bin[..4000], MeshFormat::Msh),
        (VTK.as_bytes(), MeshFormat::VtkLegacy),
        (MEDIT.as_bytes(), MeshFormat::Medit),
        (VTU.as_bytes(), MeshFormat::Vtu),
    ];
    for (bytes, format) in cases {
        for cut in 0..bytes.len() {
            let _ = parse_mesh("t", &bytes[..cut], format);
        }
        for i in 0..bytes.len().min(1200) {
            for b in [b'0', b'9', b'-', b' ', b'\n', b'$', b'<', 0xff] {
                let mut v = bytes.to_vec();
                v[i] = b;
                let _ = parse_mesh("t", &v, format);
            }
        }
    }
}

/// The fuzzers' seed files are valid meshes (so that fuzzing starts from
/// inputs that reach every section, binary MSH and base64 VTU included).
#[test]
fn fuzz_seeds_parse() {
    let seeds = concat!(env!("CARGO_MANIFEST_DIR"), "/../fuzz/seeds");
    let mut n = 0;
    for dir in std::fs::read_dir(seeds).unwrap() {
        for f in std::fs::read_dir(dir.unwrap().path()).unwrap() {
            let path = f.unwrap().path();
            let m = read_mesh(&path).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(m.mesh.tet_count(), 2, "{}", path.display());
            assert_eq!(m.tet_physical, [3, 3], "{}", path.display());
            n += 1;
        }
    }
    assert_eq!(n, 7);
}

/// The files other tools write (meshio's defaults, binary MSH 2.2, MSH 1 as
/// SOFA ships it, zlib VTU inline and appended, VTU under a .vtk name), made
/// from the Gmsh reference ellipsoid by `scripts/make-interop-fixtures.py`:
/// each reads to the reference's 2182 tetrahedra, vertices and tags.
const INTEROP: [&str; 7] = [
    "ellipsoid_v1.msh",
    "ellipsoid_v22bin.msh",
    "ellipsoid_zlib.vtu",
    "ellipsoid_zlib_appended.vtu",
    "ellipsoid_bin51.vtk",
    "ellipsoid_bin42.vtk",
    "ellipsoid_xml.vtk",
];

#[test]
fn files_from_meshio_sofa_and_paraview_read_as_the_reference() {
    let gmsh = reference("ellipsoid_v22.msh");
    for name in INTEROP {
        let m = reference(name);
        assert_eq!(m.mesh.tet_count(), 2182, "{name}");
        assert_eq!(m.mesh.vertex_count(), 567, "{name}");
        assert_eq!(m.mesh.tets(), gmsh.mesh.tets(), "{name}");
        for (p, q) in m.mesh.positions_m().iter().zip(gmsh.mesh.positions_m()) {
            assert!(p.abs_diff_eq(*q, 1e-17), "{name}: {p} != {q}");
        }
        assert!(m.tet_physical.iter().all(|&p| p == 1), "{name}");
        // The boundary triangles (physical surface 2) where the file keeps
        // them: the same 762 triangles as Gmsh's own file.
        if name != "ellipsoid_zlib_appended.vtu" {
            assert_eq!(m.surface_physical, gmsh.surface_physical, "{name}");
            assert_eq!(m.surface_physical.len(), 762, "{name}");
        }
        let xml_warning = m.warnings.iter().any(|w| w.contains("holds VTK XML"));
        assert_eq!(
            xml_warning,
            name == "ellipsoid_xml.vtk",
            "{name}: {:?}",
            m.warnings
        );
    }
}

#[test]
fn broken_interop_files_are_errors_never_panics() {
    for name in INTEROP {
        let path = PathBuf::from(MESHES).join(name);
        let bytes = std::fs::read(&path).unwrap();
        let format = MeshFormat::from_path(&path).unwrap();
        let stride = (bytes.len() / 150).max(1);
        for cut in (0..bytes.len()).step_by(stride) {
            assert!(
                parse_mesh("t", &bytes[..cut], format).is_err(),
                "{name} cut at {cut} accepted"
            );
        }
        for i in (0..bytes.len()).step_by(stride) {
            for b in [b'0', b'\n', 0x00, 0xff] {
                let mut v = bytes.clone();
                v[i] = b;
                let _ = parse_mesh("t", &v, format);
            }
        }
    }
    // A binary MSH 2.2 element block claiming more elements than declared,
    // and a zlib header claiming a huge array, name the fault.
    let v22 = std::fs::read(PathBuf::from(MESHES).join("ellipsoid_v22bin.msh")).unwrap();
    let at = v22.windows(10).position(|w| w == b"$Elements\n").unwrap() + 10;
    // Past the ASCII count line: the first block's type, then its count.
    let count_end = at + v22[at..].iter().position(|&c| c == b'\n').unwrap() + 1;
    let mut bad = v22.clone();
    bad[count_end + 4..count_end + 8].copy_from_slice(&i32::MAX.to_le_bytes());
    let e = parse_mesh("t.msh", &bad, MeshFormat::Msh)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("element block") && e.starts_with("t.msh:"),
        "{e}"
    );
    // Binary legacy VTK physical tags must be integers, as in ASCII files:
    // the int array's bits read as floats are tiny fractions.
    let vtk = std::fs::read(PathBuf::from(MESHES).join("ellipsoid_bin42.vtk")).unwrap();
    let key = b"gmsh:physical 1 2944 int\n";
    let at = vtk.windows(key.len()).position(|w| w == key).unwrap();
    let mut floats = vtk[..at].to_vec();
    floats.extend_from_slice(b"gmsh:physical 1 2944 float\n");
    floats.extend_from_slice(&vtk[at + key.len()..]);
    let e = parse_mesh("t.vtk", &floats, MeshFormat::VtkLegacy)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("is not a 32-bit integer") && e.contains("byte"),
        "{e}"
    );
    let msh1 = std::fs::read_to_string(PathBuf::from(MESHES).join("ellipsoid_v1.msh")).unwrap();
    let elm = msh1.lines().position(|l| l == "$ELM").unwrap() + 3;
    let broken = with_line(&msh1, elm, "1 4 1 1 3 1 2 3 4");
    fails_at(
        &broken,
        MeshFormat::Msh,
        elm,
        "declares 3 nodes but the line has 4",
    );
    let broken = with_line(&msh1, elm, "1 4 1 1 4 1 2 3 99999");
    fails_at(&broken, MeshFormat::Msh, elm, "node 99999");
}

#[test]
fn the_mesher_s_writers_keep_every_tetrahedron_s_physical_tag() {
    // The formats `sim-server mesh` writes: MSH 2.2, legacy VTK and VTU
    // with the tags as cell data, medit with them as references.
    let m = reference("ellipsoid_v41.msh");
    let tags: Vec<i32> = (0..m.mesh.tet_count())
        .map(|t| 1 + (t % 3) as i32)
        .collect();
    let ids: Vec<u32> = tags.iter().map(|&t| t as u32).collect();
    let cells = [("physical", DataArray::Ids(&ids))];
    let (p, t) = (m.mesh.positions_m(), m.mesh.tets());
    let written = [
        ("tags.msh", write_msh(&scratch("tags.msh"), p, t, &tags)),
        (
            "tags.vtk",
            write_vtk(&scratch("tags.vtk"), p, t, &[], &cells),
        ),
        (
            "tags.vtu",
            write_vtu(&scratch("tags.vtu"), p, t, &[], &cells),
        ),
        ("tags.mesh", write_medit(&scratch("tags.mesh"), p, t, &tags)),
    ];
    for (name, result) in written {
        result.unwrap();
        let back = read_mesh(&scratch(name)).unwrap();
        assert_eq!(back.mesh.positions_m(), p, "{name}");
        assert_eq!(back.mesh.tets(), t, "{name}");
        assert_eq!(back.tet_physical, tags, "{name}");
    }
    // A tag per tetrahedron or none.
    assert!(matches!(
        write_msh(&scratch("short.msh"), p, t, &tags[1..]),
        Err(MeshIoError::BadInput { .. })
    ));
    assert!(!scratch("short.msh").exists());
}
