//! The simulation survives its peers disappearing and reappearing: a
//! viewer (a mesh-stream subscriber in this process) leaves and joins again,
//! a haptic daemon is SIGKILLed while driving its tool, and a second daemon
//! then gets force samples from the same, still running, simulation.

use shared::SessionName;
use shared::protocol::PROTOCOL_VERSION;
use shared::services;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use system_tests::{
    Peer, binary, finish, read_json, scratch_dir, spawn_sim_server, wait_bounded, wait_for,
    wait_until,
};

/// Joins the session as a viewer would, waits for one mesh frame and
/// returns its vertex count; the node leaves when this returns.
fn view_one_frame(session: &SessionName) -> u32 {
    let node = services::node("test-viewer").expect("viewer node");
    let sub =
        services::slice_subscriber(&services::mesh_service(&node, session).expect("mesh service"))
            .expect("mesh subscriber");
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(5) {
        if let Some(frame) = sub.receive().expect("receive mesh") {
            let h = frame.user_header();
            assert_eq!(h.version, PROTOCOL_VERSION);
            assert_eq!(h.vertex_count as usize, frame.payload().len());
            return h.vertex_count;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    panic!("no mesh frame within 5 s");
}

fn daemon(session: &str, duration_s: &str) -> Command {
    let mut c = Command::new(binary("haptic-daemon"));
    c.args(["run", "--quiet", "--rt-priority", "0", "--max-force", "4"])
        .args(["--duration-s", duration_s, "--session", session]);
    c
}

#[test]
fn simulation_outlives_its_viewer_and_daemon_leaving_and_coming_back() {
    let name = format!("peers{}", std::process::id());
    let session = SessionName::new(&name).unwrap();
    let dir = scratch_dir("peers");
    let (sim_json, daemon_json) = (dir.join("sim.json"), dir.join("daemon.json"));
    let sim = Command::new(binary("sim-server"))
        .args(["run", "--quiet", "--duration-s", "9", "--session", &name])
        .arg("--json")
        .arg(&sim_json)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start sim-server");
    system_tests::wait_for(&name, system_tests::Peer::Simulation);

    let vertices = view_one_frame(&session);
    assert!(vertices > 100);

    let mut first = daemon(&name, "30")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start the first daemon");
    std::thread::sleep(Duration::from_millis(1500));
    first.kill().expect("SIGKILL the first daemon");
    first.wait().unwrap();
    std::thread::sleep(Duration::from_millis(300));

    // The viewer comes back after the daemon died.
    assert_eq!(view_one_frame(&session), vertices);

    let second = daemon(&name, "2")
        .arg("--json")
        .arg(&daemon_json)
        .output()
        .expect("run the second daemon");
    assert!(
        second.status.success(),
        "second daemon: {}",
        String::from_utf8_lossy(&second.stderr)
    );
    let d = read_json(&daemon_json);
    assert!(d["samples_received"].as_u64().unwrap() > 100, "{d}");
    let max = d["max_force_n"].as_f64().unwrap();
    assert!(max.is_finite() && max <= 4.0 + 1e-12, "{d}");

    finish(sim, Duration::from_secs(15), "sim-server");
    let s = read_json(&sim_json);
    assert!(s["finite"].as_bool().unwrap(), "{s}");
    // Both daemons' poses arrived (the second one ran 2 s at 1 kHz).
    assert!(s["poses_received"].as_u64().unwrap() > 1000, "{s}");
}

/// Two daemons in one session take turns at every tool (each pose carries
/// all of them): the simulation says so; a third cannot publish and is
/// told why by name, not with iceoryx2's error code.
#[test]
fn two_pose_publishers_are_told_and_a_third_is_refused_by_name() {
    let session = format!("twopub{}", std::process::id());
    let sim = spawn_sim_server(&session, &["--duration-s", "4", "--headless"]);
    wait_for(&session, Peer::Simulation);
    let mut first = daemon(&session, "3").spawn().unwrap();
    let mut second = daemon(&session, "3").spawn().unwrap();
    wait_until("two pose publishers", Duration::from_secs(20), || {
        let name = SessionName::new(&session).unwrap();
        let node = services::node("test-count").unwrap();
        services::publisher_count(&services::pose_service(&node, &name).unwrap()) == 2
    });
    let third = daemon(&session, "1")
        .stderr(std::process::Stdio::piped())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&third.stderr);
    assert!(
        !third.status.success() && err.contains("already has its 2 publishers"),
        "{err}"
    );
    wait_bounded(&mut first, Duration::from_secs(20), "first daemon");
    wait_bounded(&mut second, Duration::from_secs(20), "second daemon");
    let out = finish(sim, Duration::from_secs(30), "sim-server");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("poses alternate between two publishers"),
        "{err}"
    );
}
