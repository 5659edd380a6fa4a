//! The Python package (`python/hapsim`) against the real simulation: it
//! installs with pip from the checkout, and docs/guide/python.md's example attaches to
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
    // The flag bits are the protocol's.
    let out = Command::new("python3")
        .args([
            "-c",
            "import hapsim; print(hapsim.CONTACT, hapsim.GRIPPING, hapsim.CUTTING, hapsim.CATCHING_UP)",
        ])
        .env("PYTHONPATH", &site)
        .output()
        .expect("python3");
    use shared::protocol::{CATCHING_UP, CONTACT, CUTTING, GRIPPING};
    assert_eq!(
        String::from_utf8_lossy(&out.stdout).trim(),
        format!("{CONTACT} {GRIPPING} {CUTTING} {CATCHING_UP}"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let session = format!("pypkg{}", std::process::id());
    let sim = spawn_sim_server(&session, &["--duration-s", "20"]);
    // A pose's jaw outside 0..1 (or NaN) is refused by its own name; a
    // NaN jaw was blamed on the (finite) tip, and -5 passed silently.
    let bad = Command::new("python3")
        .arg("-c")
        .arg(
            "import sys; from hapsim import Session\n\
             with Session(sys.argv[1]) as s:\n\
             \x20   for tip, jaw in [([0, 0, 0], float('nan')), ([0, 0, 0], -5.0), ([0, float('inf'), 0], 1.0)]:\n\
             \x20       try:\n\
             \x20           s.publish_pose(tip, jaw_opening=jaw)\n\
             \x20           print('accepted')\n\
             \x20       except ValueError as e:\n\
             \x20           print(str(e).split(' must ')[0])",
        )
        .arg(&session)
        .env("PYTHONPATH", &site)
        .output()
        .expect("run python3");
    assert_eq!(
        String::from_utf8_lossy(&bad.stdout),
        "jaw_opening\njaw_opening\ntip_m\n",
        "{}",
        String::from_utf8_lossy(&bad.stderr)
    );
    // The scene at rest, without the scene file: name, rest positions,
    // fibres and the uncut surface, as numpy arrays.
    let rest = Command::new("python3")
        .arg("-c")
        .arg(
            "import sys; from hapsim import Session\n\
             with Session(sys.argv[1]) as s:\n\
             \x20   r = s.wait_rest(); sc = s.wait_scene()\n\
             \x20   t = r.original_triangles\n\
             \x20   print(r.name, r.positions_m.shape[0] == sc.vertex_count, r.fibres.shape[1:],\n\
             \x20         len(r.fibres) > 50, t.shape[1], int(t.max()) < r.positions_m.shape[0])",
        )
        .arg(&session)
        .env("PYTHONPATH", &site)
        .output()
        .expect("run python3");
    let rest_out = String::from_utf8_lossy(&rest.stdout);
    assert!(
        rest.status.success(),
        "{rest_out}{}",
        String::from_utf8_lossy(&rest.stderr)
    );
    assert_eq!(
        rest_out.trim(),
        format!(
            "{} True (2, 3) True 3 True",
            sim_server::scene::DEFAULT_SCENE_NAME
        ),
        "{rest_out}"
    );
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

    // Read-only beside the whole demo (its daemon drives the tools, its
    // session is demo<PID>): samples of both tools, frames, and the
    // cavitron's cuts as new surface versions.
    let mut demo = Command::new(system_tests::binary("sim-server"))
        .args(["demo", "--headless", "--no-viewer", "--duration-s", "8"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start the demo");
    let session = format!("demo{}", demo.id());
    system_tests::wait_for(&session, system_tests::Peer::Simulation);
    let out = system_tests::run_ok(
        Command::new("python3")
            .arg(root.join("python/examples/watch.py"))
            .args(["--session", &session, "--seconds", "5"])
            .env("PYTHONPATH", &site),
    );
    system_tests::wait_bounded(&mut demo, std::time::Duration::from_secs(30), "demo");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let number = |after: &str| -> f64 {
        stdout
            .split(after)
            .next()
            .and_then(|s| s.split_whitespace().last())
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("no number before {after:?} in {stdout:?}"))
    };
    assert!(number(" force samples") > 2000.0, "{stdout}");
    assert!(number(" mesh frames") > 60.0, "{stdout}");
    let versions = stdout.split("(topology v").nth(1).unwrap_or_default();
    let (from, to) = versions.split_once(" -> v").unwrap_or(("", ""));
    let to = to.split(')').next().unwrap_or_default();
    assert!(
        to.parse::<u64>().unwrap_or(0) > from.parse::<u64>().unwrap_or(u64::MAX),
        "no cut seen: {stdout}"
    );
    assert!(stdout.contains("peak force per tool ["), "{stdout}");
    // The scene's tools, from the simulation's scene stream.
    assert!(
        stdout.contains(
            "tools: grasper (grasper, radius 5.0 mm), cavitron (cavitron, radius 4.0 mm)"
        ),
        "{stdout}"
    );
}
