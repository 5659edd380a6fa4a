//! Fault injection with the real processes (unique sessions, every wait
//! bounded): the simulation SIGKILLed while the tool is in contact, restarted
//! over what the crash left in shared memory, stalled by SIGSTOP and resumed;
//! a second simulation in a busy session; a scene that makes the explicit
//! integration diverge. The daemon's recorded force must stay finite, within
//! the device limit and the slew limit, go to zero within the watchdog and
//! ramp, and come back when the simulation does.

use shared::monotonic_ns;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;
use system_tests::{
    binary, daemon_run, finish, read_json, scratch_dir, spawn_sim_server, wait_bounded,
    write_liver_press,
};

const MAX_FORCE_N: f64 = 4.0;
/// The daemon's default slew limit: full scale in 5 ms.
const SLEW_N_PER_S: f64 = MAX_FORCE_N / 0.005;
/// Sample age limit (50 ms) + ramp (10 ms) + scheduling slack on a busy machine.
const ZERO_AFTER_NS: u64 = 100_000_000;

fn signal(child: &Child, sig: i32) -> u64 {
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(child.id() as libc::pid_t, sig) };
    monotonic_ns()
}

/// Sends SIGCONT and returns the time just *before* it: on a loaded machine
/// this thread may be descheduled right after kill(2), and a window that
/// must end before the process runs again must not end after it (a CI run
/// saw the daemon's ramp-in, 4e-5 N, inside "the stall").
fn resume(child: &Child) -> u64 {
    let before = monotonic_ns();
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGCONT) };
    before
}

/// (t_ns, |F|) per tick of a daemon record, checking every row on the way.
fn read_record(path: &Path) -> Vec<(u64, f64)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut rows = Vec::new();
    let mut prev: Option<(u64, [f64; 3])> = None;
    for line in text.lines().skip(1) {
        let c: Vec<f64> = line
            .split(',')
            .map(|x| x.parse().unwrap_or(f64::NAN))
            .collect();
        let (t, f) = (c[0] as u64, [c[5], c[6], c[7]]);
        assert!(f.iter().all(|x| x.is_finite()), "non-finite force at {t}");
        let n = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        assert!(n <= MAX_FORCE_N + 1e-12, "{n} N above the limit at {t}");
        if let Some((t0, f0)) = prev {
            let d =
                ((f[0] - f0[0]).powi(2) + (f[1] - f0[1]).powi(2) + (f[2] - f0[2]).powi(2)).sqrt();
            let allowed = SLEW_N_PER_S * (t - t0) as f64 * 1e-9 + 1e-9;
            assert!(d <= allowed, "force jumped {d} N in {} ns at {t}", t - t0);
        }
        prev = Some((t, f));
        rows.push((t, n));
    }
    rows
}

fn max_between(rows: &[(u64, f64)], from_ns: u64, to_ns: u64) -> f64 {
    rows.iter()
        .filter(|(t, _)| (from_ns..to_ns).contains(t))
        .map(|r| r.1)
        .fold(0.0, f64::max)
}

#[test]
fn the_daemon_survives_the_simulation_killed_restarted_and_stalled() {
    let session = format!("faults{}", std::process::id());
    let dir = scratch_dir("faults");
    let (record, json, traj) = (
        dir.join("rec.csv"),
        dir.join("d.json"),
        dir.join("press.csv"),
    );
    // The hand comes down over 1 s to 6 mm into the liver and stays there.
    write_liver_press(&traj);
    let mut first = spawn_sim_server(&session, &["--duration-s", "60"]);
    system_tests::wait_for(&session, system_tests::Peer::Simulation);
    let daemon = daemon_run(&session)
        .args([
            "--duration-s",
            "9",
            "--max-force",
            "4",
            "--extrapolation",
            "constant",
        ])
        .arg("--device")
        .arg(format!("simulated:{}", traj.display()))
        .arg("--record")
        .arg(&record)
        .arg("--json")
        .arg(&json)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start haptic-daemon");
    std::thread::sleep(Duration::from_millis(3000));
    let killed = signal(&first, libc::SIGKILL);
    wait_bounded(&mut first, Duration::from_secs(5), "killed sim-server");
    std::thread::sleep(Duration::from_millis(1000));
    // Restart over the dead simulation's shared memory.
    let restarted = monotonic_ns();
    let second = spawn_sim_server(&session, &["--duration-s", "60"]);
    std::thread::sleep(Duration::from_millis(2500));
    let stopped = signal(&second, libc::SIGSTOP);
    std::thread::sleep(Duration::from_millis(400));
    let resumed = resume(&second);
    finish(daemon, Duration::from_secs(30), "haptic-daemon");
    signal(&second, libc::SIGTERM);
    finish(second, Duration::from_secs(10), "restarted sim-server");

    let rows = read_record(&record);
    let end = rows.last().unwrap().0;
    let ms = 1_000_000;
    assert!(
        max_between(&rows, killed - 500 * ms, killed) > 0.05,
        "the tool was not pressing when the simulation was killed"
    );
    assert_eq!(
        max_between(&rows, killed + ZERO_AFTER_NS, restarted),
        0.0,
        "after the kill"
    );
    assert!(
        max_between(&rows, restarted + 1000 * ms, stopped) > 0.05,
        "forces did not come back after the restart"
    );
    assert_eq!(
        max_between(&rows, stopped + ZERO_AFTER_NS, resumed),
        0.0,
        "during the stall"
    );
    assert!(
        max_between(&rows, resumed + 1000 * ms, end) > 0.05,
        "forces did not come back after the stall"
    );
    let d = read_json(&json);
    assert!(d["max_force_n"].as_f64().unwrap() <= MAX_FORCE_N + 1e-12);
}

#[test]
fn a_second_simulation_in_a_busy_session_refuses_clearly() {
    let session = format!("busy{}", std::process::id());
    let dir = scratch_dir("busy");
    let json = dir.join("first.json");
    let mut first = spawn_sim_server(
        &session,
        &["--duration-s", "3", "--json", json.to_str().unwrap()],
    );
    system_tests::wait_for(&session, system_tests::Peer::Simulation);
    let second = Command::new(binary("sim-server"))
        .args(["run", "--quiet", "--duration-s", "2", "--session", &session])
        .output()
        .expect("run the second sim-server");
    assert!(!second.status.success());
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(
        err.contains("already has a running simulation") && err.contains(&session),
        "{err}"
    );
    let status = wait_bounded(&mut first, Duration::from_secs(15), "first sim-server");
    assert!(status.success(), "the first simulation was disturbed");
    assert!(read_json(&json)["steps"].as_u64().unwrap() > 1000);
}

#[test]
fn a_diverging_scene_is_detected_and_the_user_told() {
    let session = format!("diverge{}", std::process::id());
    let dir = scratch_dir("diverge");
    let scene = dir.join("unstable.toml");
    // A step far above the stable bound, taken as given: it must blow up.
    std::fs::write(
        &scene,
        r#"
[mesh]
generate = { shape = "box", size_m = [0.04, 0.02, 0.02], cell_m = 0.005 }

[material]
young_pa = 5000.0
poisson = 0.45
density_kg_m3 = 1000.0
damping_per_s = 1.0

[[fixed]]
name = "left"
select = { box_m = [[-0.001, -0.001, -0.001], [0.0001, 0.021, 0.021]] }

[[load]]
name = "pull"
select = { box_m = [[0.0399, -0.001, -0.001], [0.041, 0.021, 0.021]] }
force_n = [0.0, 0.0, -0.5]

[simulation]
dt_s = 0.01
dt_policy = "unchecked"
"#,
    )
    .unwrap();
    let mut sim = Command::new(binary("sim-server"))
        .args([
            "run",
            "--quiet",
            "--headless",
            "--steps",
            "100000",
            "--session",
            &session,
        ])
        .arg("--scene")
        .arg(&scene)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let status = wait_bounded(&mut sim, Duration::from_secs(30), "diverging sim-server");
    let out = sim.wait_with_output().unwrap();
    assert!(!status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("diverged") && err.contains("forces were set to zero"),
        "{err}"
    );
}

#[test]
fn daemon_first_then_simulation_with_a_killed_viewer_in_the_session() {
    let session = format!("order{}", std::process::id());
    let dir = scratch_dir("order");
    let (d_json, s_json) = (dir.join("d.json"), dir.join("s.json"));
    let mut daemon = daemon_run(&session)
        .args(["--duration-s", "5", "--max-force", "4"])
        .arg("--json")
        .arg(&d_json)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start haptic-daemon");
    // A viewer joins, waiting for a simulation, and is SIGKILLed: its
    // subscriber ports stay behind in the session.
    let mut viewer = Command::new(binary("viewer"))
        .args(["--session", &session, "--wait-s", "30", "--snapshot"])
        .arg(dir.join("never.png"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start viewer");
    std::thread::sleep(Duration::from_millis(1000));
    signal(&viewer, libc::SIGKILL);
    wait_bounded(&mut viewer, Duration::from_secs(5), "killed viewer");
    let mut sim = spawn_sim_server(
        &session,
        &["--duration-s", "3", "--json", s_json.to_str().unwrap()],
    );
    let status = wait_bounded(&mut sim, Duration::from_secs(20), "sim-server");
    assert!(status.success(), "the simulation after a dead viewer");
    let status = wait_bounded(&mut daemon, Duration::from_secs(20), "haptic-daemon");
    assert!(status.success());
    let (d, s) = (read_json(&d_json), read_json(&s_json));
    assert!(d["samples_received"].as_u64().unwrap() > 1000, "{d}");
    assert!(s["poses_received"].as_u64().unwrap() > 1000, "{s}");
    assert!(s["frames_published"].as_u64().unwrap() > 30, "{s}");
}

#[test]
fn sigterm_flushes_every_recorded_row() {
    let session = format!("flush{}", std::process::id());
    let dir = scratch_dir("flush");
    let p = |f: &str| dir.join(f).to_str().unwrap().to_string();
    let mut sim = spawn_sim_server(&session, &["--duration-s", "6"]);
    let mut recorder = Command::new(binary("haptic-daemon"))
        .args(["record", "--session", &session, "--forces", &p("f.csv")])
        .args(["--telemetry", &p("t.csv"), "--json", &p("r.json")])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut daemon = daemon_run(&session)
        .args(["--record", &p("d.csv"), "--json", &p("d.json")])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(2500));
    signal(&daemon, libc::SIGTERM);
    assert!(wait_bounded(&mut daemon, Duration::from_secs(10), "daemon").success());
    std::thread::sleep(Duration::from_millis(300));
    signal(&recorder, libc::SIGTERM);
    assert!(wait_bounded(&mut recorder, Duration::from_secs(10), "recorder").success());
    signal(&sim, libc::SIGTERM);
    assert!(wait_bounded(&mut sim, Duration::from_secs(10), "sim-server").success());
    let rows = |f: &str| {
        std::fs::read_to_string(dir.join(f))
            .unwrap()
            .lines()
            .count() as u64
            - 1
    };
    let (d, r) = (
        read_json(&dir.join("d.json")),
        read_json(&dir.join("r.json")),
    );
    let ticks = d["ticks"].as_u64().unwrap();
    assert!(ticks > 1000, "{d}");
    assert_eq!(rows("d.csv"), ticks, "the daemon's record after SIGTERM");
    assert_eq!(rows("t.csv"), r["telemetry"]["received"].as_u64().unwrap());
    assert_eq!(r["telemetry"]["received"].as_u64().unwrap(), ticks, "{r}");
    // Two tools per force sample in the liver scene.
    assert_eq!(
        rows("f.csv"),
        2 * r["forces"]["received"].as_u64().unwrap(),
        "{r}"
    );
    assert_eq!(r["forces"]["gaps"], 0, "{r}");
}
