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

/// The step's worker threads of `pid` (named `tensor-mass-*`): how many
/// run under scheduling `policy`, and how many there are.
fn step_workers_under(pid: u32, policy: i32) -> (usize, usize) {
    let (mut under, mut all) = (0, 0);
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return (0, 0);
    };
    for t in tasks.flatten() {
        let comm = std::fs::read_to_string(t.path().join("comm")).unwrap_or_default();
        if !comm.starts_with("tensor-mass-") {
            continue;
        }
        let stat = std::fs::read_to_string(t.path().join("stat")).unwrap_or_default();
        // Field 41 (policy); the fields after the command's ')' start at 3.
        let found = stat
            .rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().nth(41 - 3))
            .and_then(|p| p.parse::<i32>().ok());
        all += 1;
        under += usize::from(found == Some(policy));
    }
    (under, all)
}

/// Presses and slides the probe over the box with two step workers
/// (`sim_args` added to `sim-server run`) and, late in the slide, after
/// meshes have been swapped in, looks five times at the step workers: the
/// two of the mesh in use must run under `policy` (a mesh being built
/// beside it has workers of its own in the background, hence "at least").
/// Each look is tried three times, 10 ms apart, for the few microseconds
/// between a swap and the change of its workers. The run summary.
fn slide_with_step_workers_under(tag: &str, sim_args: &[&str], policy: i32) -> serde_json::Value {
    let dir = scratch_dir(tag);
    let scene = dir.join("box.toml");
    // The scene's [simulation] table is its last.
    let text = scene_text().replacen("\n[contact]", "threads = 2\n\n[contact]", 1);
    std::fs::write(&scene, text).unwrap();
    let top = 0.02 + 0.0025;
    let hand = dir.join("hand.csv");
    std::fs::write(
        &hand,
        format!(
            "t_s,x_m,y_m,z_m\n0,0.02,0.02,{a}\n0.5,0.02,0.02,{a}\n1.0,0.02,0.02,{d}\n4.0,0.04,0.02,{d}\n",
            a = top + 0.003,
            d = top - 0.005,
        ),
    )
    .unwrap();
    let session = format!("{tag}{}", std::process::id()).replace('-', "");
    let json = dir.join("sim.json");
    let mut args = vec![
        "--scene",
        scene.to_str().unwrap(),
        "--duration-s",
        "6",
        "--json",
        json.to_str().unwrap(),
    ];
    args.extend_from_slice(sim_args);
    let sim = spawn_sim_server(&session, &args);
    system_tests::wait_for(&session, system_tests::Peer::Simulation);
    let daemon = daemon_run(&session)
        .args(["--device", &format!("replay:{}", hand.display())])
        .args(["--duration-s", "4.2"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(3000));
    let mut seen = Vec::new();
    for _ in 0..5 {
        let mut ok = false;
        for _ in 0..3 {
            let (under, all) = step_workers_under(sim.id(), policy);
            seen.push((under, all));
            if under >= 2 {
                ok = true;
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        assert!(
            ok,
            "step workers (under policy {policy}, all) seen: {seen:?}"
        );
        std::thread::sleep(Duration::from_millis(150));
    }
    finish(daemon, Duration::from_secs(30), "haptic-daemon");
    finish(sim, Duration::from_secs(30), "sim-server");
    let s = read_json(&json);
    assert!(s["remesh_swaps"].as_u64().unwrap() >= 3, "{s}");
    s
}

#[test]
fn a_mesh_swapped_in_steps_on_workers_at_the_loops_priority() {
    if shared::rt::set_fifo(1).is_err() {
        eprintln!("skipped: this machine refuses SCHED_FIFO");
        return;
    }
    // Back to normal for the test's own thread.
    shared::rt::normal().unwrap();
    let s = slide_with_step_workers_under("follow-rt", &["--rt-priority", "5"], libc::SCHED_FIFO);
    assert_eq!(s["rt_priority"], 5, "{s}");
    assert_eq!(s["rt_step_workers"], 2, "{s}");
}

#[test]
fn a_mesh_swapped_in_steps_on_normal_workers_not_background_ones() {
    // Made on the follower's SCHED_IDLE thread, its workers were SCHED_IDLE.
    let s = slide_with_step_workers_under("follow-normal", &[], libc::SCHED_OTHER);
    assert_eq!(s["rt_priority"], 0, "{s}");
}
