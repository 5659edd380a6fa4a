//! A device's workspace placed in the scene (`--workspace-offset-m`,
//! `--workspace-scale`, `--workspace-rotate-deg`; docs/guide/devices.md) through
//! the real processes: a replayed hand that presses the stiff box in the
//! scene's frame, and the same hand given in a device's frame (turned,
//! scaled, moved) with the map that places it back, hold the same force;
//! the summary reports the map and the stiffness as the hand feels it. The
//! simulated device's built-in poke reaches the organ through a map too.

use system_tests::{
    Peer, STIFF_BOX, daemon_run, read_json, record_force_norms, scratch_dir, spawn_sim_server,
    wait_for,
};

/// The map of the second run: the device's y up, twice as small as the
/// scene, its origin at the box's top centre.
const OFFSET: [f64; 3] = [0.03, 0.02, 0.04];
const SCALE: f64 = 2.0;
/// Rx(90): device (x, y, z) -> scene (x, -z, y).
fn to_device(p: [f64; 3]) -> [f64; 3] {
    let d = [p[0] - OFFSET[0], p[1] - OFFSET[1], p[2] - OFFSET[2]];
    [d[0] / SCALE, d[2] / SCALE, -d[1] / SCALE]
}

/// Wait above, press 15 mm in at 20 mm/s, hold (scene frame, the tip's
/// centre); `map` turns each point into the frame the CSV is written in.
fn press_csv(map: fn([f64; 3]) -> [f64; 3]) -> String {
    let rows = [
        (0.0, [0.03, 0.02, 0.055]),
        (0.5, [0.03, 0.02, 0.055]),
        (1.75, [0.03, 0.02, 0.03]),
        (3.5, [0.03, 0.02, 0.03]),
    ];
    let mut s = String::from("t_s,x_m,y_m,z_m\n");
    for (t, p) in rows {
        let q = map(p);
        s += &format!("{t},{},{},{}\n", q[0], q[1], q[2]);
    }
    s
}

#[test]
fn a_placed_workspace_holds_the_same_force_at_the_same_scene_point() {
    let dir = scratch_dir("workspace");
    let session = format!("workspace{}", std::process::id());
    let scene = dir.join("box.toml");
    std::fs::write(&scene, STIFF_BOX).unwrap();
    let mut sim = spawn_sim_server(
        &session,
        &["--scene", scene.to_str().unwrap(), "--duration-s", "60"],
    );
    wait_for(&session, Peer::Simulation);
    let run = |name: &str, csv: String, map: &[&str]| {
        let path = dir.join(format!("{name}.csv"));
        std::fs::write(&path, csv).unwrap();
        let (json, record) = (
            dir.join(format!("{name}.json")),
            dir.join(format!("{name}-rec.csv")),
        );
        let out = daemon_run(&session)
            .args(["--duration-s", "3.4", "--device"])
            .arg(format!("replay:{}", path.display()))
            .args(map)
            .arg("--json")
            .arg(&json)
            .arg("--record")
            .arg(&record)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        (read_json(&json), record_force_norms(&record))
    };
    let (plain_json, plain) = run("scene-frame", press_csv(|p| p), &[]);
    let (placed_json, placed) = run(
        "device-frame",
        press_csv(to_device),
        &[
            "--workspace-offset-m",
            "0.03,0.02,0.04",
            "--workspace-scale",
            "2",
            "--workspace-rotate-deg",
            "90,0,0",
        ],
    );
    // The same placement from a file (`--workspace FILE.toml`).
    let file = dir.join("device.toml");
    std::fs::write(
        &file,
        "device = \"test\"\noffset_m = [0.03, 0.02, 0.04]\nscale = 2.0\nrotate_deg = [90.0, 0.0, 0.0]\n",
    )
    .unwrap();
    let (file_json, from_file) = run(
        "device-frame-file",
        press_csv(to_device),
        &["--workspace", file.to_str().unwrap()],
    );
    let _ = sim.kill();
    let _ = sim.wait();
    assert_eq!(
        file_json["workspace"], placed_json["workspace"],
        "the file and the flags place the device alike"
    );
    // The hold's last 0.5 s.
    let hold = |f: &[f64]| {
        let tail = &f[f.len().saturating_sub(500)..];
        tail.iter().sum::<f64>() / tail.len() as f64
    };
    let (a, b, c) = (hold(&plain), hold(&placed), hold(&from_file));
    assert!(a > 1.0, "the probe does not press: {a} N");
    assert!(
        (a - b).abs() <= 0.05 * a && (a - c).abs() <= 0.05 * a,
        "scene frame {a:.3} N, device frame {b:.3} N, from the file {c:.3} N"
    );
    let ws = &placed_json["workspace"];
    assert_eq!(ws["scale"], 2.0, "{placed_json}");
    let (cap, hand) = (
        placed_json["max_stiffness_n_per_m"].as_f64().unwrap(),
        ws["hand_max_stiffness_n_per_m"].as_f64().unwrap(),
    );
    assert!((hand - 2.0 * cap).abs() < 1e-9, "{placed_json}");
    assert!(
        (cap - plain_json["max_stiffness_n_per_m"].as_f64().unwrap() / 2.0).abs() < 1e-9,
        "the scene's cap is the device's over the scale: {placed_json}"
    );
}

#[test]
fn the_simulated_poke_reaches_the_organ_through_a_map() {
    let dir = scratch_dir("workspace-poke");
    let session = format!("wspoke{}", std::process::id());
    let scene = dir.join("box.toml");
    std::fs::write(&scene, STIFF_BOX).unwrap();
    let mut sim = spawn_sim_server(
        &session,
        &["--scene", scene.to_str().unwrap(), "--duration-s", "30"],
    );
    wait_for(&session, Peer::Simulation);
    let json = dir.join("poke.json");
    let out = daemon_run(&session)
        .args(["--duration-s", "4", "--device", "simulated"])
        .args([
            "--workspace-offset-m",
            "0.05,0,0.1",
            "--workspace-scale",
            "0.5",
        ])
        .args(["--workspace-rotate-deg", "0,0,45", "--json"])
        .arg(&json)
        .output()
        .unwrap();
    let _ = sim.kill();
    let _ = sim.wait();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = read_json(&json);
    assert!(
        v["max_force_n"].as_f64().unwrap() > 0.5,
        "the poke missed the box: {v}"
    );
}

/// A workspace file with a misspelt key or a value out of range is
/// refused before the loop starts, naming the file and the line or the
/// range; a file and the flags together are refused too.
#[test]
fn a_bad_workspace_file_is_refused_with_its_line() {
    let dir = scratch_dir("workspace-file");
    let hand = dir.join("hand.csv");
    std::fs::write(&hand, "t_s,x_m,y_m,z_m\n0,0,0,0.1\n1,0,0,0.1\n").unwrap();
    let session = format!("wsfile{}", std::process::id());
    for (name, text, extra, needles) in [
        (
            "misspelt.toml",
            "scale = 2.0\nrotate = [90.0, 0.0, 0.0]\n",
            &[][..],
            &["misspelt.toml", "line 2", "unknown field `rotate`"][..],
        ),
        (
            "huge.toml",
            "scale = 1000.0\n",
            &[][..],
            &["huge.toml", "scale must lie in"][..],
        ),
        (
            "both.toml",
            "scale = 2.0\n",
            &["--workspace-scale", "2"][..],
            &["cannot be used with"][..],
        ),
    ] {
        let file = dir.join(name);
        std::fs::write(&file, text).unwrap();
        let out = daemon_run(&session)
            .args(["--duration-s", "0.5", "--device"])
            .arg(format!("replay:{}", hand.display()))
            .arg("--workspace")
            .arg(&file)
            .args(extra)
            .env("RUST_BACKTRACE", "0")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name}: accepted");
        for n in needles {
            assert!(err.contains(n), "{name}: {n:?} not in {err}");
        }
        assert!(!err.contains("Caused by"), "{name}: said twice: {err}");
    }
}
