//! The two processes together: sim-server run on the embedded liver and
//! haptic-daemon run with the simulated hand in one session. Poses reach the
//! simulation, its force samples reach the daemon, the hand's poke touches
//! the liver, and every rendered force is finite and within the limit.

use std::process::{Command, Stdio};
use std::time::Duration;
use system_tests::{binary, daemon_run, finish, read_json, scratch_dir};

#[test]
fn simulation_and_daemon_talk_and_forces_stay_safe() {
    let session = format!("stack{}", std::process::id());
    let dir = scratch_dir("stack");
    let (sim_json, daemon_json, record) = (
        dir.join("sim.json"),
        dir.join("daemon.json"),
        dir.join("rec.csv"),
    );
    let sim = Command::new(binary("sim-server"))
        .args(["run", "--quiet", "--duration-s", "4", "--session", &session])
        .arg("--json")
        .arg(&sim_json)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start sim-server");
    system_tests::wait_for(&session, system_tests::Peer::Simulation);
    let daemon = daemon_run(&session)
        .args(["--duration-s", "3"])
        .args(["--extrapolation", "local-model", "--max-force", "4"])
        .arg("--json")
        .arg(&daemon_json)
        .arg("--record")
        .arg(&record)
        .output()
        .expect("run haptic-daemon");
    assert!(
        daemon.status.success(),
        "daemon: {}",
        String::from_utf8_lossy(&daemon.stderr)
    );
    finish(sim, Duration::from_secs(10), "sim-server");
    let s: serde_json::Value = read_json(&sim_json);
    let d: serde_json::Value = read_json(&daemon_json);
    assert!(s["poses_received"].as_u64().unwrap() > 100, "{s}");
    assert!(d["samples_received"].as_u64().unwrap() > 100, "{d}");
    assert!(s["finite"].as_bool().unwrap());
    let max = d["max_force_n"].as_f64().unwrap();
    assert!(max.is_finite() && max <= 4.0 + 1e-12, "{d}");
    let rec = std::fs::read_to_string(&record).unwrap();
    for line in rec.lines().skip(1) {
        let f: Vec<f64> = line
            .split(',')
            .skip(5)
            .take(3)
            .map(|x| x.parse().unwrap())
            .collect();
        assert!(f.iter().all(|x| x.is_finite()));
    }
}

/// `--device simulated` aims its poke at the organ the simulation says it
/// has (the `scene` stream's bounding box): on hapbench's probe box it
/// presses the box's centre 6 mm deep; the poke down the z axis it made
/// whatever the scene only grazed the box's corner (0.028 N).
#[test]
fn the_simulated_hand_pokes_the_organ_of_the_scene_it_is_given() {
    let session = format!("aim{}", std::process::id());
    let dir = scratch_dir("stack-aim");
    let daemon_json = dir.join("daemon.json");
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/box-probe.toml");
    let sim = Command::new(binary("sim-server"))
        .args(["run", "--quiet", "--duration-s", "5", "--session", &session])
        .arg("--scene")
        .arg(&scene)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start sim-server");
    system_tests::wait_for(&session, system_tests::Peer::Simulation);
    let daemon = daemon_run(&session)
        .args([
            "--device",
            "simulated",
            "--duration-s",
            "3",
            "--max-force",
            "4",
        ])
        .arg("--json")
        .arg(&daemon_json)
        .output()
        .expect("run haptic-daemon");
    assert!(
        daemon.status.success(),
        "daemon: {}",
        String::from_utf8_lossy(&daemon.stderr)
    );
    finish(sim, Duration::from_secs(10), "sim-server");
    let d = read_json(&daemon_json);
    assert_eq!(d["warnings"].as_array().map(Vec::len), Some(0), "{d}");
    let max = d["max_force_n"].as_f64().unwrap();
    assert!(max > 0.2 && max <= 4.0, "the poke pressed the box: {d}");
}

#[test]
fn the_headless_demo_cuts_touches_and_stays_within_the_device_limit() {
    let dir = scratch_dir("demo");
    let frames = dir.join("frames");
    let frames_arg = frames.to_str().expect("a UTF-8 scratch path");
    let v = headless_demo(&dir, &["--duration-s", "7", "--save-frames", frames_arg]);
    for key in [
        "sim_steps_per_s",
        "haptic_ticks_per_s",
        "tets_removed",
        "contact_steps",
        "max_force_n",
        "device_max_force_n",
    ] {
        assert!(v[key].is_number(), "missing {key} in {v}");
    }
    assert!(
        v["tets_removed"].as_u64().unwrap() > 0,
        "the cavitron removed nothing: {v}"
    );
    assert!(v["contact_steps"].as_u64().unwrap() > 0, "{v}");
    assert_eq!(v["sim_contact_law"], "penalty", "{v}");
    let (max, limit) = (
        v["max_force_n"].as_f64().unwrap(),
        v["device_max_force_n"].as_f64().unwrap(),
    );
    assert!(max.is_finite() && max <= limit, "{v}");
    check_saved_frames(&frames);
}

#[test]
fn the_implicit_demo_keeps_its_steps_within_the_iteration_budget() {
    // The grasper's jaws close 2.0-2.5 s in and its grip holds dozens of
    // vertices at once: solved to the tolerance, the stale factor then
    // takes up to ~16 iterations a step; with `--implicit-iterations 1`
    // every step takes at most one, the grip's steps are counted as
    // capped, and the demo runs as before.
    let v = headless_demo(
        &scratch_dir("demo-implicit"),
        &[
            "--duration-s",
            "4",
            "--backend",
            "implicit",
            "--dt-s",
            "0.004",
            "--implicit-iterations",
            "1",
        ],
    );
    assert_eq!(v["sim_solve_iterations_max"], 1, "{v}");
    assert!(
        v["sim_solve_iterations_mean"].as_f64().unwrap() > 0.0,
        "{v}"
    );
    assert!(v["sim_solve_capped_steps"].as_u64().unwrap() > 0, "{v}");
    assert!(v["contact_steps"].as_u64().unwrap() > 0, "{v}");
    // The implicit backend cannot integrate the penalty springs.
    assert_eq!(v["sim_contact_law"], "projection", "{v}");
}

#[test]
fn the_precomputed_demo_presses_with_the_penalty_law_by_default() {
    // The grasper's jaws close on the liver 2.0-2.5 s after the daemon
    // starts and pull it from there; the demo starts the daemon once the
    // backend is prepared (here its
    // responses are computed afresh in the scratch cache: 2-3 s, and
    // under other tests' load more; the daemon used to start at once and
    // the grasp was over before the first step); under the penalty
    // law the precomputed backend's largest force is the explicit
    // backend's (2.20 N against 2.04, docs/results/precomputed-contact.md), under the projection law it
    // was 1.36 N (the probe held on a plane between the vertices).
    let v = headless_demo(
        &scratch_dir("demo-precomputed"),
        &["--duration-s", "9", "--backend", "precomputed"],
    );
    assert_eq!(v["sim_contact_law"], "penalty", "{v}");
    let contact = v["contact_steps"].as_u64().unwrap();
    assert!(contact > 1000, "{v}");
    assert!(
        v["sim_solve_iterations_mean"].as_f64().unwrap() > 0.0,
        "{v}"
    );
    // How many steps end at the iteration limit depends on the machine's
    // load here (12-20 of ~7,300 on a quiet 2-core VM, 393 once under the
    // other stack tests on CI, the largest force unchanged): a real-time
    // run's poses arrive as the load lets them. Convergence is asserted
    // where it is deterministic (contact_static.rs, the liver poke with a
    // stall: no step capped).
    let (max, limit) = (
        v["max_force_n"].as_f64().unwrap(),
        v["device_max_force_n"].as_f64().unwrap(),
    );
    assert!(max > 1.8 && max <= limit, "{v}");
}

/// Runs `sim-server demo --headless` with `args`, its JSON in `dir` (and
/// the precomputed responses' cache, not the user's); returns the JSON.
fn headless_demo(dir: &std::path::Path, args: &[&str]) -> serde_json::Value {
    let json = dir.join("demo.json");
    let out = Command::new(binary("sim-server"))
        .args(["demo", "--headless"])
        .args(args)
        .arg("--json")
        .arg(&json)
        .env("XDG_CACHE_HOME", dir.join("cache"))
        .output()
        .expect("run sim-server demo");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    read_json(&json)
}

/// The demo's `--save-frames` series: a PVD listing VTU frames in time
/// order, each read back by the mesh reader, the cuts visible as
/// tetrahedra gone from later frames, the vertices' original ids a
/// permutation (the liver is renumbered), the grasped lobe displaced.
fn check_saved_frames(dir: &std::path::Path) {
    let pvd = std::fs::read_to_string(dir.join("frames.pvd")).expect("frames.pvd");
    let entries: Vec<(f64, String)> = pvd
        .lines()
        .filter(|l| l.contains("<DataSet"))
        .map(|l| {
            let attr = |k: &str| {
                let s = &l[l.find(&format!("{k}=\"")).unwrap() + k.len() + 2..];
                s[..s.find('"').unwrap()].to_string()
            };
            (attr("timestep").parse().unwrap(), attr("file"))
        })
        .collect();
    // 7 s at 30 Hz, less what a busy disk dropped.
    assert!(entries.len() > 100, "{} frames: {pvd}", entries.len());
    assert!(entries.windows(2).all(|w| w[0].0 < w[1].0), "{pvd}");
    let read = |file: &str| {
        let path = dir.join(file);
        let xml = std::fs::read_to_string(&path).unwrap();
        let mesh = sim_server::mesh::io::read_mesh(&path).unwrap();
        (xml, mesh)
    };
    let (first_xml, first) = read(&entries[0].1);
    let (last_xml, last) = read(&entries[entries.len() - 1].1);
    for (xml, name) in [(&first_xml, "first"), (&last_xml, "last")] {
        for array in ["displacement", "elastic_force", "original_id", "tet_id"] {
            assert!(
                xml.contains(&format!("Name=\"{array}\"")),
                "{name} frame has no {array}"
            );
        }
    }
    assert_eq!(first.mesh.vertex_count(), last.mesh.vertex_count());
    // An independent reader agrees, and sees the arrays' contents.
    let paths = [
        dir.join(&entries[0].1),
        dir.join(&entries[entries.len() - 1].1),
    ];
    let seen = system_tests::meshio_describe(&[&paths[0], &paths[1]]);
    for (s, m) in seen.iter().zip([&first, &last]) {
        assert_eq!(s["points"], m.mesh.vertex_count(), "{s}");
        assert_eq!(s["tetrahedra"], m.mesh.tet_count(), "{s}");
        assert_eq!(s["point_data"]["original_id"]["permutation"], true, "{s}");
        assert_eq!(s["cell_data"]["tet_id"]["increasing"], true, "{s}");
        assert_eq!(s["point_data"]["elastic_force"]["shape"][1], 3, "{s}");
        // One value per point or cell: 1-D arrays, not (n, 1).
        for (kind, array) in [("point_data", "original_id"), ("cell_data", "tet_id")] {
            let shape = s[kind][array]["shape"].as_array().unwrap();
            assert_eq!(shape.len(), 1, "{array}: {s}");
        }
    }
    // VTK's own reader takes the zlib-compressed frames as ParaView would,
    // with the same arrays and values.
    let by_vtk = system_tests::vtk_describe(&[&paths[0], &paths[1]]);
    for (v, m) in by_vtk.iter().zip(&seen) {
        assert_eq!(v["points"], m["points"], "{v}");
        assert_eq!(v["tetrahedra"], m["tetrahedra"], "{v}");
        let (a, b) = (
            v["point_data"]["displacement"]["max_norm"]
                .as_f64()
                .unwrap(),
            m["point_data"]["displacement"]["max_norm"]
                .as_f64()
                .unwrap(),
        );
        assert!((a - b).abs() <= 1e-12 * b.max(1e-300), "{a} vs {b}");
        assert_eq!(v["cell_data"]["tet_id"]["components"], 1, "{v}");
    }
    // The grasper has pulled the lobe by centimetres by the end.
    let moved = seen[1]["point_data"]["displacement"]["max_norm"]
        .as_f64()
        .unwrap();
    assert!(
        moved > 5e-3,
        "largest displacement {moved} m in the last frame"
    );
    assert!(
        last.mesh.tet_count() < first.mesh.tet_count(),
        "no cut shows: {} then {} tetrahedra",
        first.mesh.tet_count(),
        last.mesh.tet_count()
    );
}
