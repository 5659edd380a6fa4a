//! `[[refine]]`: finer cells where a tool works, by conforming longest-edge
//! bisection at load. The refined mesh passes the patch test (a hanging
//! vertex would not), carries the file's tags (tetrahedra and surface
//! triangles) to its children, is what every later section of the scene
//! sees, and a refinement past its element budget stops and says so once.

use sim_server::ids::{TetId, VertexId};
use sim_server::math::{Mat3, Vec3};
use sim_server::scene::{BuiltScene, SceneError, SceneSource, build_scene};

fn build(text: &str) -> Result<BuiltScene, SceneError> {
    let src = SceneSource {
        name: "refine.toml".into(),
        dir: std::path::PathBuf::from("."),
        text: text.into(),
    };
    build_scene(&src, &src.parse()?)
}

const BOX: &str = r#"
[mesh]
generate = { shape = "box", size_m = [0.04, 0.02, 0.02], cell_m = 0.005 }

[material]
young_pa = 4500.0
poisson = 0.45
density_kg_m3 = 1060.0
"#;

fn longest_edge_m(p: [Vec3; 4]) -> f64 {
    let mut l: f64 = 0.0;
    for a in 0..4 {
        for b in a + 1..4 {
            l = l.max(p[a].distance(p[b]));
        }
    }
    l
}

#[test]
fn a_refined_sphere_has_its_cells_and_the_rest_keeps_its_own() {
    let coarse = build(BOX).unwrap();
    let b = build(&format!(
        "{BOX}\n[[refine]]\nname = \"under the tool\"\nselect = {{ sphere_m = [0.02, 0.01, 0.02, 0.005] }}\ncell_m = 0.0025\n"
    ))
    .unwrap();
    let (m0, m) = (coarse.model.mesh(), b.model.mesh());
    assert!(m.tet_count() > m0.tet_count());
    let r = &b.report.refined[0];
    assert_eq!(r.name, "under the tool");
    assert_eq!(
        (r.tets_before, r.tets_after),
        (m0.tet_count(), m.tet_count())
    );
    assert!(!r.stopped_at_budget);
    let mut volume = 0.0;
    for t in 0..m.tet_count() {
        let p = m.tet_points(TetId::from(t));
        volume += m.tet_volume_m3(TetId::from(t));
        let near = p
            .iter()
            .any(|x| x.distance(Vec3::new(0.02, 0.01, 0.02)) < 0.004);
        if near {
            let cell = (6.0 * m.tet_volume_m3(TetId::from(t))).cbrt();
            assert!(cell <= 0.0025 + 1e-12, "tet {t}: cell {cell} m");
            assert!(longest_edge_m(p) <= 0.0025 * 3f64.sqrt() + 1e-12, "tet {t}");
        }
        // The far end is the generator's cells.
        if p.iter().all(|x| x.x < 0.005) {
            assert!(
                longest_edge_m(p) > 0.005,
                "tet {t} at the far end was split"
            );
        }
    }
    assert!((volume - 0.04 * 0.02 * 0.02).abs() < 1e-15);
    // The top's surface is the same area with more triangles.
    let surface = |b: &BuiltScene| b.model.topology().surface_len();
    assert!(surface(&b) > surface(&coarse));
}

/// A constant strain gives zero force at every vertex off the boundary:
/// the patch test, which a hanging vertex (a non-conforming refinement)
/// fails.
#[test]
fn the_refined_mesh_passes_the_patch_test() {
    let b = build(&format!(
        "{BOX}\n[[refine]]\nselect = {{ box_m = [[0.012, 0.004, 0.006], [0.028, 0.016, 0.02]] }}\ncell_m = 0.0015\n"
    ))
    .unwrap();
    let model = &b.model;
    let mesh = model.mesh();
    let grad = Mat3::from_cols(
        Vec3::new(1e-3, 2e-4, -3e-4),
        Vec3::new(-1e-4, 2e-3, 5e-4),
        Vec3::new(4e-4, -2e-4, 1.5e-3),
    );
    let u: Vec<Vec3> = mesh.positions_m().iter().map(|x| grad * *x).collect();
    let mut f = vec![Vec3::ZERO; mesh.vertex_count()];
    model.elastic_forces(&u, &mut f);
    let mut on_surface = vec![false; mesh.vertex_count()];
    for tri in model.topology().surface_triangles(mesh) {
        for v in tri {
            on_surface[v.idx()] = true;
        }
    }
    let scale = f.iter().map(|x| x.length()).fold(0.0, f64::max);
    let interior = (0..mesh.vertex_count()).filter(|&v| !on_surface[v]);
    let mut worst: f64 = 0.0;
    let mut new_interior = 0;
    let base = build(BOX).unwrap().model.mesh().vertex_count();
    for v in interior {
        worst = worst.max(f[v].length());
        new_interior += usize::from(v >= base);
    }
    assert!(scale > 0.0);
    assert!(new_interior > 0, "no interior vertex was added");
    assert!(
        worst < 1e-9 * scale,
        "interior force {worst} N against {scale} N"
    );
}

#[test]
fn tags_follow_the_refinement() {
    let meshes = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/meshes");
    let scene = |extra: &str| {
        let src = SceneSource {
            name: "tags.toml".into(),
            dir: std::path::PathBuf::from(meshes),
            text: format!(
                "[mesh]\nfile = \"box_v41.msh\"\n[material]\nyoung_pa = 3000.0\npoisson = 0.4\ndensity_kg_m3 = 1000.0\n{extra}"
            ),
        };
        build_scene(&src, &src.parse().unwrap())
    };
    let coarse = scene("").unwrap();
    let (lo, hi) = coarse.model.mesh().bounds_m();
    let c = (lo + hi) * 0.5;
    let cm = coarse.model.mesh();
    let h = (0..cm.tet_count())
        .map(|t| (6.0 * cm.tet_volume_m3(TetId::from(t))).cbrt())
        .fold(f64::INFINITY, f64::min)
        / 2.0;
    let refine = format!(
        "[[refine]]\nselect = {{ sphere_m = [{}, {}, {}, {}] }}\ncell_m = {h}\n",
        lo.x,
        c.y,
        c.z,
        (hi - lo).max_element() / 3.0
    );
    // The boundary's tag holds exactly the refined boundary's vertices.
    let b = scene(&format!(
        "{refine}[[fixed]]\nselect = {{ surface_physical = 2 }}\n"
    ))
    .unwrap();
    assert!(b.model.mesh().tet_count() > coarse.model.mesh().tet_count());
    let m = &b.model;
    let mut boundary: Vec<VertexId> = m.topology().surface_triangles(m.mesh()).flatten().collect();
    boundary.sort_unstable();
    boundary.dedup();
    assert_eq!(b.fixed, boundary);
    // The volume's tag selects every child: a region on it changes all.
    let b = scene(&format!(
        "{refine}[[region]]\nselect = {{ physical = 1 }}\nyoung_pa = 9000.0\n"
    ))
    .unwrap();
    assert_eq!(b.report.regions[0].1, b.model.mesh().tet_count());
    // Vertices the refinement added are numbered after the file's.
    let ids = b.original_vertex_ids.as_ref().unwrap();
    let file_vertices = coarse.model.mesh().vertex_count() as u32;
    assert_eq!(
        ids.iter().filter(|&&o| o >= file_vertices).count(),
        b.model.mesh().vertex_count() - file_vertices as usize
    );
}

#[test]
fn a_refinement_past_its_budget_stops_and_says_so_once() {
    let b = build(&format!(
        "{BOX}\n[[refine]]\nname = \"everywhere\"\nselect = {{ box_m = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]] }}\ncell_m = 0.0001\nmax_tets = 5000\n"
    ))
    .unwrap();
    assert!(b.model.mesh().tet_count() <= 5000);
    assert!(b.report.refined[0].stopped_at_budget);
    let said: Vec<_> = b
        .report
        .warnings
        .iter()
        .filter(|w| w.contains("max_tets"))
        .collect();
    assert_eq!(said.len(), 1, "{:?}", b.report.warnings);
    assert!(said[0].contains("everywhere"), "{}", said[0]);
    // Without `max_tets` the default budget bounds a mistaken size (the
    // smallest `cell_m` accepted, 1e-5 m; below it is refused).
    let b = build(&format!(
        "{BOX}\n[[refine]]\nselect = {{ box_m = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]] }}\ncell_m = 1e-5\n"
    ))
    .unwrap();
    assert!(b.model.mesh().tet_count() <= sim_server::scene::refine::DEFAULT_MAX_TETS);
}

#[test]
fn mistakes_in_a_refinement_name_their_line() {
    for (body, line, needle) in [
        (
            "select = { sphere_m = [0.02, 0.01, 0.02, 0.005] }\ncell_m = 0.0",
            12,
            "cell_m must be a positive",
        ),
        (
            "select = { sphere_m = [1.0, 1.0, 1.0, 0.005] }\ncell_m = 0.001",
            11,
            "touches no tetrahedron",
        ),
        (
            "select = { surface_physical = 2 }\ncell_m = 0.001",
            11,
            "surface_physical selects the vertices",
        ),
        (
            "select = { sphere_m = [0.02, 0.01, 0.02, 0.005] }\ncell = 0.001",
            12,
            "unknown field",
        ),
    ] {
        let text = format!("{BOX}\n[[refine]]\n{body}\n");
        let Err(e) = build(&text) else {
            panic!("accepted: {body}")
        };
        let msg = e.to_string();
        assert!(msg.contains(needle), "{body}: {msg}");
        assert_eq!(e.position().map(|p| p.0), Some(line), "{body}: {msg}");
    }
}
