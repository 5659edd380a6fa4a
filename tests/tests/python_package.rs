//! The Python package (`python/hapsim`) against the real simulation: it
//! installs with pip from the checkout, and its README example attaches to
//! `sim-server run`, finds the organ from a mesh frame, presses it with
//! tool 0 and reads the force samples as numpy arrays.

use std::process::Command;
use system_tests::{finish, scratch_dir, spawn_sim_server};

#[test]
fn the_python_package_installs_and_its_example_presses_the_liver() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf();
    let dir = scratch_dir("python-package");
    let site = dir.join("site");
    // Installable with pip from the checkout (into a scratch directory).
    let out = Command::new("python3")
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
        ])
        .args(["--no-deps", "--target"])
        .arg(&site)
        .arg(root.join("python"))
        .output()
        .expect("python3 -m pip (scripts/setup.sh installs Python)");
    assert!(
        out.status.success(),
        "pip install python/: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let session = format!("pypkg{}", std::process::id());
    let sim = spawn_sim_server(&session, &["--duration-s", "20"]);
    let out = Command::new("python3")
        .arg(root.join("python/examples/press.py"))
        .args(["--session", &session])
        .env("PYTHONPATH", &site)
        .output()
        .expect("run the example");
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(sim.id() as libc::pid_t, libc::SIGTERM) };
    finish(sim, std::time::Duration::from_secs(20), "sim-server");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // "organ [x y z] .. [x y z] m, peak force on tool 0 F N": the liver is
    // 0.22 m across, and the tool pressed it 10 mm.
    let peak: f64 = stdout
        .split("peak force on tool 0 ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no peak force in {stdout:?}"));
    assert!(peak > 0.2 && peak < 5.0, "{stdout}");
    assert!(stdout.contains("organ [-0.11"), "{stdout}");
}
