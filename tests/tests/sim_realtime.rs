//! The simulation's real-time rules with the real processes (unique
//! sessions, every wait bounded), observed on the force stream by this test:
//!
//! - a simulation stopped (SIGSTOP) and resumed drops the missed time instead
//!   of fast-forwarding: simulated time advances at the real-time rate after
//!   the resume, the daemon's live-sample guard judges the samples live again
//!   at once, and the run summary counts the stall and the dropped time;
//! - a tool whose pose publisher (the haptic daemon) stops publishing or is
//!   killed lets go within the pose timeout (50 ms) plus a margin, and takes
//!   the tissue again when poses come back; a killed publisher is noticed
//!   from the publisher count even when the pose timeout is long.

use haptic_daemon::live::{Live, LiveConfig, LiveGuard};
use shared::protocol::CONTACT;
use shared::{SessionName, monotonic_ns, services};
use std::process::{Child, Stdio};
use std::time::Duration;
use system_tests::{
    daemon_run, finish, read_json, scratch_dir, spawn_sim_server, wait_bounded, write_liver_press,
};

const MS: u64 = 1_000_000;
/// The pose timeout's default (50 ms) plus scheduling slack on a busy machine.
const RELEASE_WITHIN_NS: u64 = 100 * MS;

fn signal(child: &Child, sig: i32) -> u64 {
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(child.id() as libc::pid_t, sig) };
    monotonic_ns()
}

/// A force sample as received here.
#[derive(Clone, Copy, Debug)]
struct Got {
    arrival_ns: u64,
    t_ns: u64,
    sim_time_ns: u64,
    force_n: f64,
    contact: bool,
    /// Tool 0's `pose_seq` and whether its `position_m` is zero.
    pose_seq: u64,
    at_origin: bool,
}

/// Receives force samples for `d`, polling every 100 us.
fn pump(sub: &services::ForceSubscriber, d: Duration, out: &mut Vec<Got>) {
    let end = monotonic_ns() + d.as_nanos() as u64;
    while monotonic_ns() < end {
        while let Ok(Some(s)) = sub.receive() {
            let f = s.tools[0].force_n;
            out.push(Got {
                arrival_ns: monotonic_ns(),
                t_ns: s.t_ns,
                sim_time_ns: s.sim_time_ns,
                force_n: (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt(),
                contact: s.tools[0].flags & CONTACT != 0,
                pose_seq: s.tools[0].pose_seq,
                at_origin: s.tools[0].position_m == [0.0; 3],
            });
        }
        std::thread::sleep(Duration::from_micros(100));
    }
}

/// Receives until the first sample arrives (the simulation has started;
/// at most 20 s).
fn pump_until_running(sub: &services::ForceSubscriber, out: &mut Vec<Got>) {
    let start = std::time::Instant::now();
    while out.is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "the simulation did not start"
        );
        pump(sub, Duration::from_millis(10), out);
    }
}

#[test]
fn a_stalled_simulation_drops_the_missed_time_and_is_live_again_at_once() {
    let name = format!("stall{}", std::process::id());
    let session = SessionName::new(&name).unwrap();
    let dir = scratch_dir("sim-stall");
    let json = dir.join("sim.json");
    let node = services::node("stall-observer").unwrap();
    let sub = services::subscriber(&services::force_service(&node, &session).unwrap()).unwrap();
    let sim = spawn_sim_server(
        &name,
        &["--duration-s", "4", "--json", json.to_str().unwrap()],
    );
    let mut got = Vec::new();
    pump_until_running(&sub, &mut got);
    pump(&sub, Duration::from_millis(1000), &mut got);
    let stopped = signal(&sim, libc::SIGSTOP);
    pump(&sub, Duration::from_millis(400), &mut got);
    let resumed = signal(&sim, libc::SIGCONT);
    pump(&sub, Duration::from_millis(1000), &mut got);
    finish(sim, Duration::from_secs(20), "sim-server");
    assert!(
        got.iter().filter(|g| g.arrival_ns < stopped).count() > 200,
        "too few samples before the stall"
    );

    // No fast-forward: from the first sample after the resume, simulated
    // time advances no faster than wall time (a step of slack).
    let after: Vec<&Got> = got.iter().filter(|g| g.t_ns > resumed).collect();
    assert!(
        after.len() > 300,
        "{} samples after the resume",
        after.len()
    );
    let first = after[0];
    for g in &after {
        let d_sim = g.sim_time_ns - first.sim_time_ns;
        let d_wall = g.t_ns - first.t_ns;
        assert!(
            d_sim <= d_wall + 3 * MS,
            "{} ms simulated in {} ms of wall time after the resume: fast-forward",
            d_sim as f64 / 1e6,
            d_wall as f64 / 1e6
        );
    }

    // The daemon's guard: live again within 100 ms of the resume, and never
    // not live after that.
    let mut guard = LiveGuard::new(LiveConfig::default());
    let mut live_again = None;
    for g in &got {
        let v = guard.observe(g.arrival_ns, g.sim_time_ns);
        if g.arrival_ns > resumed {
            match v {
                Live::NotLive => assert!(
                    live_again.is_none(),
                    "a sample {} ms after the resume was not live",
                    (g.arrival_ns - resumed) / MS
                ),
                _ => {
                    live_again.get_or_insert(g.arrival_ns);
                }
            }
        }
    }
    let live_again = live_again.expect("never live again after the stall");
    assert!(
        live_again - resumed < 100 * MS,
        "live again {} ms after the resume",
        (live_again - resumed) / MS
    );

    let s = read_json(&json);
    assert!(s["stalls"].as_u64().unwrap() >= 1, "{s}");
    let dropped = s["dropped_time_s"].as_f64().unwrap();
    assert!(dropped >= 0.35, "{s}");
    for key in ["p50", "p99", "p999", "max"] {
        let v = s["step_us"][key].as_f64().unwrap();
        assert!(v > 0.0 && v.is_finite(), "step_us.{key}: {s}");
    }
    assert!(s["step_us"]["p50"].as_f64() <= s["step_us"]["max"].as_f64());
    // The CPU time of a step's whole work contains the step itself (the
    // median step is not preempted), and never the stall: a stopped
    // process runs no CPU, wherever in the loop the signal found it.
    let cpu = &s["step_cpu_us"];
    let (cpu_p50, cpu_max) = (cpu["p50"].as_f64().unwrap(), cpu["max"].as_f64().unwrap());
    assert!(
        cpu_p50 >= 0.5 * s["step_us"]["p50"].as_f64().unwrap(),
        "step_cpu_us {cpu} against step_us {}",
        s["step_us"]
    );
    assert!(
        cpu_max < 0.5 * dropped * 1e6,
        "step_cpu_us {cpu}, dropped {dropped} s"
    );
    // The step after the pose on the CPU clock: one sample per step, never
    // the stall, and step by step no longer than on the wall clock (to the
    // two clock reads between the spans: a few microseconds).
    let own = &s["step_after_pose_cpu_us"];
    assert_eq!(own["count"], s["step_us"]["count"], "{s}");
    assert!(
        own["max"].as_f64().unwrap() < 0.5 * dropped * 1e6,
        "step_after_pose_cpu_us {own}, dropped {dropped} s"
    );
    for key in ["p50", "p99", "p999", "max"] {
        let (c, st) = (
            own[key].as_f64().unwrap(),
            s["step_us"][key].as_f64().unwrap(),
        );
        assert!(
            c.is_finite() && c <= st + 5.0,
            "step_after_pose_cpu_us.{key} {c} against step_us.{key} {st}: {s}"
        );
    }
    // The wall time of a step's whole work contains its step after the
    // pose, step by step, so every percentile is at least the step's.
    let work = &s["step_work_us"];
    for key in ["p50", "p99", "p999", "max"] {
        let (w, st) = (
            work[key].as_f64().unwrap(),
            s["step_us"][key].as_f64().unwrap(),
        );
        assert!(
            w.is_finite() && w >= st,
            "step_work_us.{key} {w} against step_us.{key} {st}: {s}"
        );
    }
    // Simulated time + dropped time = wall time, to the other stalls a
    // busy machine adds (all counted in dropped) and the start-up.
    let wall = s["steps"].as_f64().unwrap() / s["steps_per_s"].as_f64().unwrap();
    let sim = s["sim_time_s"].as_f64().unwrap();
    assert!(
        (sim + dropped - wall).abs() < 0.1,
        "sim {sim} s + dropped {dropped} s vs wall {wall} s"
    );
}

/// A daemon whose simulated hand comes down over 1 s to 6 mm into the liver
/// and stays there.
fn pressing_daemon(session: &str, dir: &std::path::Path) -> Child {
    let traj = dir.join("press.csv");
    write_liver_press(&traj);
    daemon_run(session)
        .args(["--duration-s", "30", "--max-force", "4"])
        .arg("--device")
        .arg(format!("simulated:{}", traj.display()))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start haptic-daemon")
}

fn pressing(got: &[Got], from_ns: u64, to_ns: u64) -> bool {
    got.iter()
        .any(|g| (from_ns..to_ns).contains(&g.t_ns) && g.contact && g.force_n > 0.05)
}

/// Samples in [from, to) where tool 0 still touches or pushes.
fn holding(got: &[Got], from_ns: u64, to_ns: u64) -> Vec<Got> {
    got.iter()
        .filter(|g| (from_ns..to_ns).contains(&g.t_ns) && (g.contact || g.force_n > 1e-9))
        .copied()
        .collect()
}

#[test]
fn a_tool_lets_go_when_its_pose_publisher_stops_and_when_it_is_killed() {
    let name = format!("poseage{}", std::process::id());
    let session = SessionName::new(&name).unwrap();
    let dir = scratch_dir("pose-age");
    let json = dir.join("sim.json");
    let node = services::node("pose-age-observer").unwrap();
    let sub = services::subscriber(&services::force_service(&node, &session).unwrap()).unwrap();
    let sim = spawn_sim_server(
        &name,
        &["--duration-s", "12", "--json", json.to_str().unwrap()],
    );
    let mut got = Vec::new();
    pump_until_running(&sub, &mut got);
    let mut daemon = pressing_daemon(&name, &dir);
    pump(&sub, Duration::from_millis(2500), &mut got);
    let stopped = signal(&daemon, libc::SIGSTOP);
    assert!(
        pressing(&got, stopped - 500 * MS, stopped),
        "the tool was not pressing before the daemon stopped"
    );
    pump(&sub, Duration::from_millis(400), &mut got);
    let resumed = signal(&daemon, libc::SIGCONT);
    pump(&sub, Duration::from_millis(1500), &mut got);
    let killed = signal(&daemon, libc::SIGKILL);
    wait_bounded(&mut daemon, Duration::from_secs(5), "killed haptic-daemon");
    pump(&sub, Duration::from_millis(500), &mut got);
    signal(&sim, libc::SIGTERM);
    finish(sim, Duration::from_secs(20), "sim-server");

    let held = holding(&got, stopped + RELEASE_WITHIN_NS, resumed);
    assert!(
        held.is_empty(),
        "the tool still pressed {} ms after its poses stopped: {:?}",
        (held[0].t_ns - stopped) / MS,
        held[0]
    );
    assert!(
        pressing(&got, resumed + 500 * MS, killed),
        "the tool did not take the tissue again when poses came back"
    );
    let held = holding(&got, killed + RELEASE_WITHIN_NS, u64::MAX);
    assert!(
        held.is_empty(),
        "the tool still pressed {} ms after its publisher was killed",
        (held[0].t_ns - killed) / MS
    );
    // The protocol's "no pose": pose_seq 0 and the position zero, before the
    // daemon came and after its publisher died; its poses count from 1.
    let first = got[0];
    assert!(first.pose_seq == 0 && first.at_origin, "{first:?}");
    let last = got[got.len() - 1];
    assert!(last.pose_seq == 0 && last.at_origin, "{last:?}");
    let pressed = got.iter().find(|g| g.contact).expect("a pressing sample");
    assert!(pressed.pose_seq >= 1 && !pressed.at_origin, "{pressed:?}");
    let s = read_json(&json);
    assert!(s["pose_timeouts"].as_u64().unwrap() >= 2, "{s}");
}

#[test]
fn a_killed_pose_publisher_is_noticed_before_its_pose_is_stale() {
    let name = format!("posepub{}", std::process::id());
    let session = SessionName::new(&name).unwrap();
    let dir = scratch_dir("pose-publisher");
    let node = services::node("pose-pub-observer").unwrap();
    let sub = services::subscriber(&services::force_service(&node, &session).unwrap()).unwrap();
    // A pose stays valid for 10 s: only the publisher count can release it.
    let sim = spawn_sim_server(&name, &["--duration-s", "8", "--pose-timeout-ms", "10000"]);
    let mut got = Vec::new();
    pump_until_running(&sub, &mut got);
    let mut daemon = pressing_daemon(&name, &dir);
    pump(&sub, Duration::from_millis(2500), &mut got);
    let killed = signal(&daemon, libc::SIGKILL);
    wait_bounded(&mut daemon, Duration::from_secs(5), "killed haptic-daemon");
    pump(&sub, Duration::from_millis(800), &mut got);
    signal(&sim, libc::SIGTERM);
    finish(sim, Duration::from_secs(20), "sim-server");
    assert!(
        pressing(&got, killed - 500 * MS, killed),
        "the tool was not pressing before the daemon was killed"
    );
    let held = holding(&got, killed + RELEASE_WITHIN_NS, u64::MAX);
    assert!(
        held.is_empty(),
        "the tool still pressed {} ms after its publisher was killed",
        (held[0].t_ns - killed) / MS
    );
}
