//! `sim-server bench` end to end: the process runs, prints, and writes the
//! JSON keys that scripts rely on, with values that make sense.

use std::process::Command;
use system_tests::{binary, scratch_dir};

#[test]
fn bench_writes_the_documented_json_keys() {
    let dir = scratch_dir("bench");
    let json = dir.join("bench.json");
    let out = Command::new(binary("sim-server"))
        .args([
            "bench",
            "--generate",
            "box",
            "--tets",
            "3000",
            "--steps",
            "50",
            "--threads",
            "2",
        ])
        .arg("--json")
        .arg(&json)
        .output()
        .expect("run sim-server");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("steps/s"), "{stdout}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for key in [
        "tets",
        "vertices",
        "steps_per_s",
        "ns_per_step",
        "bytes_per_step",
        "bandwidth_bound_steps_per_s",
    ] {
        assert!(
            v.get(key).is_some_and(|x| x.is_number()),
            "missing {key} in {v}"
        );
    }
    let tets = v["tets"].as_u64().unwrap();
    assert!((2000..4500).contains(&tets), "asked 3000 tets, got {tets}");
    let rate = v["steps_per_s"].as_f64().unwrap();
    let ns = v["ns_per_step"].as_f64().unwrap();
    assert!(rate > 0.0 && (rate * ns / 1e9 - 1.0).abs() < 1e-9);
    assert!(v["bytes_per_step"].as_u64().unwrap() > 40 * tets);
    assert_eq!(v["threads"].as_u64(), Some(2));
}

#[test]
fn bench_refuses_bad_arguments_clearly() {
    let out = Command::new(binary("sim-server"))
        .args(["bench", "--tets", "1000", "--threads", "0"])
        .output()
        .expect("run sim-server");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--threads"), "{err}");
    let out = Command::new(binary("sim-server"))
        .args(["bench", "--generate", "sphere"])
        .output()
        .expect("run sim-server");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("sphere"));
}
