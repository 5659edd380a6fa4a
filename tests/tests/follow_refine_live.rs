//! `[contact] refine_radius_m` through the real processes: `sim-server run`
//! with a daemon replaying a press, a slide and a lift-off over a box of
//! 5 mm cells. The simulation makes its mesh again round the probe on a
//! worker thread and swaps it in; the viewer's streams carry each mesh (the
//! rest state with its vertex count, frames of that count), and after the
//! probe has left the mesh is the scene's own again. `--save-frames`, which
//! records one mesh, is refused with the reason.

use shared::{SessionName, services};
use std::collections::BTreeSet;
use std::time::Duration;
use system_tests::{daemon_run, finish, read_json, run_err, scratch_dir, spawn_sim_server};

/// The soft box of the slide measurements (60 x 40 x 20 mm of 5 mm cells,
/// E 3 kPa, a 2.5 mm probe) with the mesh following the probe.
fn scene_text() -> String {
    let path = system_tests::workspace_root().join("tests/data/box-probe-soft.toml");
    let base = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    format!("{base}\n[contact]\nrefine_radius_m = 0.008\n")
}

/// The box's tetrahedra and vertices as generated.
const BASE_TETS: u64 = 2304;
const BASE_VERTICES: u32 = 585;

#[test]
fn the_live_mesh_follows_the_probe_and_the_streams_carry_it() {
    let dir = scratch_dir("follow-live");
    let scene = dir.join("box.toml");
    std::fs::write(&scene, scene_text()).unwrap();
    // Above the top at x = 20 mm, down 5 mm into it, 20 mm along x in 2 s,
    // up and away.
    let top = 0.02 + 0.0025;
    let hand = dir.join("hand.csv");
    std::fs::write(
        &hand,
        format!(
            "t_s,x_m,y_m,z_m\n0,0.02,0.02,{a}\n0.5,0.02,0.02,{a}\n1.0,0.02,0.02,{d}\n3.0,0.04,0.02,{d}\n3.5,0.04,0.02,{u}\n5.0,0.04,0.02,{u}\n",
            a = top + 0.003,
            d = top - 0.005,
            u = top + 0.03
        ),
    )
    .unwrap();
    let session = format!("follow{}", std::process::id());
    let json = dir.join("sim.json");
    let sim = spawn_sim_server(
        &session,
        &[
            "--scene",
            scene.to_str().unwrap(),
            "--duration-s",
            "7",
            "--json",
            json.to_str().unwrap(),
        ],
    );
    system_tests::wait_for(&session, system_tests::Peer::Simulation);
    // What a viewer sees: every rest state published, and the frames.
    let name = SessionName::new(&session).unwrap();
    let node = services::node("follow-test").unwrap();
    let rest = services::slice_subscriber(&services::rest_service(&node, &name).unwrap()).unwrap();
    let mesh = services::slice_subscriber(&services::mesh_service(&node, &name).unwrap()).unwrap();
    let daemon = daemon_run(&session)
        .args(["--device", &format!("replay:{}", hand.display())])
        .args(["--duration-s", "5.5"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut rest_counts = BTreeSet::new();
    let (mut frames, mut last_rest, mut last_frame) = (0u64, 0u32, 0u32);
    let start = std::time::Instant::now();
    while start.elapsed() < Duration::from_secs(6) {
        while let Some(s) = rest.receive().unwrap() {
            let h = *s.user_header();
            rest_counts.insert(h.vertex_count);
            last_rest = h.vertex_count;
        }
        while let Some(f) = mesh.receive().unwrap() {
            let h = *f.user_header();
            assert_eq!(h.vertex_count as usize, f.payload().len());
            last_frame = h.vertex_count;
            frames += 1;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    finish(daemon, Duration::from_secs(30), "haptic-daemon");
    finish(sim, Duration::from_secs(30), "sim-server");
    let s = read_json(&json);
    assert_eq!(s["finite"], true, "{s}");
    let swaps = s["remesh_swaps"].as_u64().unwrap();
    assert!(swaps >= 3, "{s}");
    // Each mesh swapped in had its first step timed apart.
    assert_eq!(
        s["remesh_first_step_us"]["count"].as_u64(),
        Some(swaps),
        "{s}"
    );
    assert!(s["remesh_most_tets"].as_u64().unwrap() > BASE_TETS, "{s}");
    // The probe has gone: the scene's own mesh, and the streams say so.
    assert_eq!(s["remesh_tets"].as_u64().unwrap(), BASE_TETS, "{s}");
    assert_eq!(last_rest, BASE_VERTICES, "{rest_counts:?}");
    assert_eq!(last_frame, BASE_VERTICES);
    assert!(frames > 30, "{frames} frames");
    // Refined meshes went out on the rest stream while it pressed.
    assert!(
        rest_counts.iter().any(|&n| n > BASE_VERTICES),
        "{rest_counts:?}"
    );
}

#[test]
fn frames_of_one_mesh_are_refused_with_a_following_mesh() {
    let dir = scratch_dir("follow-frames");
    let scene = dir.join("box.toml");
    std::fs::write(&scene, scene_text()).unwrap();
    let session = format!("followframes{}", std::process::id());
    let e = run_err(
        std::process::Command::new(system_tests::binary("sim-server")).args([
            "run",
            "--quiet",
            "--session",
            &session,
            "--scene",
            scene.to_str().unwrap(),
            "--steps",
            "10",
            "--save-frames",
            dir.join("frames").to_str().unwrap(),
        ]),
    );
    assert!(
        e.contains("refine_radius_m") && e.contains("--save-frames"),
        "{e}"
    );
}
