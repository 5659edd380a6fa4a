//! The protocol is open: `python/examples/backend.py`, a simulation
//! backend written in Python from docs/protocol.md with iceoryx2's Python
//! package, drives the real haptic daemon (scripts/setup.sh installs the
//! package).

use std::process::{Command, Stdio};
use system_tests::{daemon_run, read_json, scratch_dir};

#[test]
fn a_python_backend_drives_the_real_daemon() {
    let check = Command::new("python3")
        .args(["-c", "import iceoryx2"])
        .output()
        .expect("python3 (scripts/setup.sh installs it)");
    assert!(
        check.status.success(),
        "iceoryx2's Python package is missing: run scripts/setup.sh ({})",
        String::from_utf8_lossy(&check.stderr)
    );
    let session = format!("python{}", std::process::id());
    let dir = scratch_dir("python-backend");
    let json = dir.join("daemon.json");
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../python/examples/backend.py");
    let backend = Command::new("python3")
        .arg(&script)
        .args(["--session", &session, "--duration-s", "5"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the Python backend");
    system_tests::wait_for(&session, system_tests::Peer::Simulation);
    // The simulated hand pokes from z = 5 cm down to 2 cm; the Python
    // tissue's surface is at 3 cm.
    let daemon = daemon_run(&session)
        .args(["--duration-s", "3", "--max-force", "4"])
        .arg("--json")
        .arg(&json)
        .output()
        .expect("run haptic-daemon");
    assert!(
        daemon.status.success(),
        "{}",
        String::from_utf8_lossy(&daemon.stderr)
    );
    let out = backend.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "python backend: {stdout} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let d = read_json(&json);
    assert!(d["samples_received"].as_u64().unwrap() > 500, "{d}");
    let f = d["max_force_n"].as_f64().unwrap();
    assert!(
        f > 0.05 && f <= 4.0,
        "the daemon rendered the Python tissue's force: {d}"
    );
    assert!(!stdout.contains(" 0 in contact"), "{stdout}");
}
