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
    std::thread::sleep(Duration::from_millis(300));
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

#[test]
fn the_headless_demo_cuts_touches_and_stays_within_the_device_limit() {
    let dir = scratch_dir("demo");
    let json = dir.join("demo.json");
    let out = Command::new(binary("sim-server"))
        .args(["demo", "--headless", "--duration-s", "7"])
        .arg("--json")
        .arg(&json)
        .output()
        .expect("run sim-server demo");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = read_json(&json);
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
    let (max, limit) = (
        v["max_force_n"].as_f64().unwrap(),
        v["device_max_force_n"].as_f64().unwrap(),
    );
    assert!(max.is_finite() && max <= limit, "{v}");
}
