//! A device glitch through the real processes (issue 15's acceptance):
//! `sim-server run` (real time) on a stiff, damped box and `haptic-daemon run`
//! replaying a hand that presses a 5 mm-radius probe 15 mm into it (its end
//! 25 mm above the fixed bottom; 3.8 N) and holds still, with a 5 ms glitch
//! of the device's pose (1 m away, or 20 mm deeper) in the middle of the
//! hold. Over the hold after the glitch, the force the daemon renders (its
//! record CSV) is back within 20% of the force just before the glitch, and
//! never below half nor above 1.5x of it. A third test lets the glitch
//! through the daemon to the simulation, whose proxy alone must bring the
//! contact back as it was and stay under 1.5x.
//!
//! The daemon runs with its defaults (extrapolation, pose plausibility,
//! passivity); the simulation in real time (the daemon does not render
//! samples whose simulated time outruns wall time). Both glitch kinds run
//! one after the other (about 5.5 s each), never side by side on a loaded
//! machine.

use shared::{SessionName, services};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};
use system_tests::{STIFF_BOX, binary, daemon_run, finish, read_json, scratch_dir, wait_bounded};

/// The block's top face (m).
const TOP_M: f64 = 0.04;
/// Where the probe presses (x, y; m): the middle of the block.
const AT_M: [f64; 2] = [0.03, 0.02];
/// The tip waits this far above the top (m) while the proxy comes in from
/// its fulcrum (1 m/s at most: 0.12 m in well under the wait).
const ABOVE_M: f64 = 0.01;
/// How deep the probe's end (the lowest point of its round tip) is held
/// below the top (m), as the issue asks; the tool's tip point is the
/// centre of that hemisphere, `RADIUS_M` above it.
const DEPTH_M: f64 = 0.015;
/// The probe's radius (m).
const RADIUS_M: f64 = 0.005;
/// The tip point while held (m).
const HELD_Z_M: f64 = TOP_M + RADIUS_M - DEPTH_M;
/// Replay times (s): waiting above, then the press at 20 mm/s (22.5 mm),
/// the hold, the glitch at `GLITCH_S` for `GLITCH_LEN_S`, the hold after
/// until `END_S`.
const WAIT_S: f64 = 0.5;
const PRESSED_S: f64 = WAIT_S + (TOP_M + ABOVE_M - HELD_Z_M) / 0.02;
const GLITCH_S: f64 = 3.0;
const GLITCH_LEN_S: f64 = 0.005;
const END_S: f64 = 5.0;
/// The daemon runs a little past the replay's last sample.
const DAEMON_S: f64 = END_S + 0.2;

/// "Just before": the force over this window before the glitch (s).
const BEFORE_S: (f64, f64) = (0.1, 0.01);
/// "Afterwards": the force over the last this long of the hold (s).
const AFTER_S: f64 = 0.2;

/// The two runs share the machine's two cores: one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

/// The replay CSV: wait above, press, hold, 5 ms at `hold + offset`, hold.
fn replay_csv(offset_m: [f64; 3]) -> String {
    let [x, y] = AT_M;
    let (above, held) = (TOP_M + ABOVE_M, HELD_Z_M);
    let g = [x + offset_m[0], y + offset_m[1], held + offset_m[2]];
    let rows = [
        (0.0, [x, y, above]),
        (WAIT_S, [x, y, above]),
        (PRESSED_S, [x, y, held]),
        (GLITCH_S, [x, y, held]),
        // 0.1 ms in, 0.1 ms out: the device jumps (linear interpolation
        // between samples would make a ramp otherwise).
        (GLITCH_S + 0.0001, g),
        (GLITCH_S + GLITCH_LEN_S - 0.0001, g),
        (GLITCH_S + GLITCH_LEN_S, [x, y, held]),
        (END_S, [x, y, held]),
    ];
    let mut s = String::from("t_s,x_m,y_m,z_m\n");
    for (t, p) in rows {
        s += &format!("{t},{},{},{}\n", p[0], p[1], p[2]);
    }
    s
}

/// A tick of the daemon's record.
#[derive(Clone, Copy, Debug)]
struct Tick {
    /// Since the first tick (s): the replay's clock.
    t_s: f64,
    pos_z_m: f64,
    force_n: [f64; 3],
    sample_age_ns: u64,
    safety_state: u32,
}

impl Tick {
    fn force(&self) -> f64 {
        norm(self.force_n)
    }

    fn show(&self) -> String {
        let f = self.force_n;
        let age = if self.sample_age_ns == u64::MAX {
            "none".to_string()
        } else {
            format!("{:.2} ms", self.sample_age_ns as f64 * 1e-6)
        };
        format!(
            "t {:.4} s  z {:.4} m  F ({:+.3}, {:+.3}, {:+.3}) |F| {:.3} N  sample age {age}  safety {}",
            self.t_s,
            self.pos_z_m,
            f[0],
            f[1],
            f[2],
            self.force(),
            self.safety_state
        )
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The daemon's record (`t_ns,seq,pos_x_m,pos_y_m,pos_z_m,force_x_n,
/// force_y_n,force_z_n,sample_age_ns,lateness_ns,method,safety_state`).
fn read_record(path: &Path) -> Vec<Tick> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header = lines.next().expect("a header line");
    assert!(header.starts_with("t_ns,seq,pos_x_m"), "{header}");
    let mut t0 = None;
    lines
        .filter(|l| !l.is_empty())
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            assert_eq!(c.len(), 12, "{l}");
            let f = |i: usize| -> f64 { c[i].parse().unwrap_or_else(|_| panic!("{l}")) };
            let t_ns: u64 = c[0].parse().unwrap();
            let t0 = *t0.get_or_insert(t_ns);
            let tick = Tick {
                t_s: (t_ns - t0) as f64 * 1e-9,
                pos_z_m: f(4),
                force_n: [f(5), f(6), f(7)],
                // Empty before the first force sample.
                sample_age_ns: c[8].parse().unwrap_or(u64::MAX),
                safety_state: match c[11] {
                    "waiting" => 0,
                    "ramping-in" => 1,
                    "active" => 2,
                    "ramping-down" => 3,
                    "stopped" => 4,
                    other => panic!("safety state {other:?}: {l}"),
                },
            };
            assert!(tick.force_n.iter().all(|x| x.is_finite()), "{l}");
            tick
        })
        .collect()
}

/// Waits until the simulation of `session` publishes force samples (at most
/// 20 s: a scene build on a loaded machine).
fn wait_until_simulating(session: &str, sim: &mut Child) {
    let session = SessionName::new(session).unwrap();
    let node = services::node("glitch-observer").unwrap();
    let sub = services::subscriber(&services::force_service(&node, &session).unwrap()).unwrap();
    let start = Instant::now();
    loop {
        if let Ok(Some(_)) = sub.receive() {
            return;
        }
        if let Some(status) = sim.try_wait().unwrap() {
            panic!("sim-server exited before it simulated: {status}");
        }
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "the simulation did not start within 20 s"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Runs the simulation and the daemon replaying a 5 ms glitch of `offset_m`;
/// checks the acceptance on the record.
/// Who stops the glitch: the daemon's pose plausibility check (the system
/// as shipped), or the simulation's proxy alone (the daemon's check opened
/// so wide that the glitch reaches the simulation, and the daemon rendering
/// the simulation's samples as they come: its local model would otherwise
/// extrapolate the glitched pose itself).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Guard {
    System,
    ProxyOnly,
}

/// One glitch run; `Err` when its checks failed, with what disturbed it
/// if the machine did.
fn glitch_once(tag: &str, offset_m: [f64; 3], guard: Guard) -> Result<(), Option<String>> {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let session = format!("glitch{tag}{}", std::process::id());
    let dir = scratch_dir(&format!("glitch-{tag}"));
    let p = |f: &str| dir.join(f);
    std::fs::write(p("box-stiff.toml"), STIFF_BOX).unwrap();
    std::fs::write(p("hand.csv"), replay_csv(offset_m)).unwrap();

    let mut sim = Command::new(binary("sim-server"))
        .args(["run", "--quiet", "--session", &session])
        .arg("--scene")
        .arg(p("box-stiff.toml"))
        // A bound only: SIGTERM ends it when the daemon is done.
        .args(["--duration-s", "60"])
        .arg("--json")
        .arg(p("sim.json"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start sim-server");
    wait_until_simulating(&session, &mut sim);
    let daemon = daemon_run(&session)
        .arg("--device")
        .arg(format!("replay:{}", p("hand.csv").display()))
        .args(["--duration-s", &DAEMON_S.to_string()])
        .arg("--record")
        .arg(p("rec.csv"))
        .arg("--json")
        .arg(p("daemon.json"))
        .args(match guard {
            Guard::System => &[][..],
            // The rendered force is then the simulation's latest sample:
            // what the simulation alone makes of the glitch.
            Guard::ProxyOnly => &[
                "--max-speed-m-s",
                "1e6",
                "--max-accel-m-s2",
                "1e12",
                "--extrapolation",
                "constant",
            ][..],
        })
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start haptic-daemon");
    let d_out = finish(daemon, Duration::from_secs(30), "haptic-daemon");
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(sim.id() as libc::pid_t, libc::SIGTERM) };
    let status = wait_bounded(&mut sim, Duration::from_secs(10), "sim-server");
    let s_out = sim.wait_with_output().unwrap();
    assert!(
        status.success(),
        "sim-server failed ({status}): {}",
        String::from_utf8_lossy(&s_out.stderr)
    );
    let (s, d) = (read_json(&p("sim.json")), read_json(&p("daemon.json")));
    eprintln!(
        "[{tag}] sim-server: {}[{tag}] haptic-daemon: {}[{tag}] daemon summary: poses_rejected {} pose_rereferences {} samples_not_live {} passivity_active_ticks {} max_force_n {}",
        String::from_utf8_lossy(&s_out.stdout),
        String::from_utf8_lossy(&d_out.stdout),
        d["poses_rejected"],
        d["pose_rereferences"],
        d["samples_not_live"],
        d["passivity_active_ticks"],
        d["max_force_n"],
    );
    assert_eq!(s["finite"], true, "{s}");

    let rec = read_record(&p("rec.csv"));
    // A run the machine disturbed (the simulation fell behind real time,
    // or its samples stopped reaching the daemon for a while) does not
    // measure the glitch: if it fails, it is run again (at most three
    // times); an undisturbed run that fails fails the test.
    let max_age_ms = rec
        .iter()
        .filter(|t| t.t_s >= PRESSED_S)
        .map(|t| t.sample_age_ns as f64 * 1e-6)
        .fold(0.0, f64::max);
    let stalls = s["stalls"].as_u64().unwrap_or(0);
    let disturbed = (stalls > 0 || max_age_ms > DISTURBED_AGE_MS).then(|| {
        format!("{stalls} simulation stalls, samples up to {max_age_ms:.1} ms old in the hold")
    });
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let rec = read_record(&p("rec.csv"));
        let last = rec.last().expect("a recorded tick").t_s;
        assert!(
            last >= END_S,
            "the record ends at {last} s, before the hold does ({END_S} s)"
        );
        let between = |a: f64, b: f64| rec.iter().filter(move |t| (a..b).contains(&t.t_s));
        let mean = |a: f64, b: f64| -> [f64; 3] {
            let (mut sum, mut n) = ([0.0; 3], 0);
            for t in between(a, b) {
                (0..3).for_each(|i| sum[i] += t.force_n[i]);
                n += 1;
            }
            assert!(n > 0, "no tick between {a} and {b} s");
            sum.map(|x| x / n as f64)
        };
        let mean_norm = |a: f64, b: f64| -> f64 {
            let f: Vec<f64> = between(a, b).map(Tick::force).collect();
            f.iter().sum::<f64>() / f.len().max(1) as f64
        };
        // Before and after: the mean force (vector) and the mean of its
        // magnitude (what the hand feels: a force that flips sideways from
        // tick to tick averages to less than it is). "Before" is the steady
        // force the glitch interrupts: where a stall of the shared machine
        // made the daemon ramp out and in again just before the glitch (seen
        // once in CI: the simulation's samples went stale at 2.85 s), its
        // window moves back to end at the last tick the filter was active
        // after at least as long active, so that the baseline is not the ramp.
        let (before_from, before_to) =
            steady_window(&rec, GLITCH_S - BEFORE_S.0, GLITCH_S - BEFORE_S.1);
        let before = mean(before_from, before_to);
        let after = mean(END_S - AFTER_S, END_S);
        let f0 = mean_norm(before_from, before_to);
        let f1 = mean_norm(END_S - AFTER_S, END_S);
        // The hold after the glitch: from the glitch to the end of the replay,
        // the hand (not the device's reading) still.
        let hold: Vec<Tick> = between(GLITCH_S - BEFORE_S.1, END_S).copied().collect();
        let low = hold
            .iter()
            .min_by(|a, b| a.force().total_cmp(&b.force()))
            .unwrap();
        let high = hold
            .iter()
            .max_by(|a, b| a.force().total_cmp(&b.force()))
            .unwrap();
        let gap = hold
            .windows(2)
            .map(|w| w[1].t_s - w[0].t_s)
            .fold(0.0, f64::max);

        // The press and the hold before the glitch, for the report: the largest
        // force while pressing in, its largest fall below the running maximum
        // (pressing deeper should never lessen it), and the range of the hold.
        let (mut press_max, mut fall, mut fall_at) = (0.0_f64, 0.0_f64, None);
        // The largest fall of |F| in one tick while pressing in, and when.
        let (mut drop, mut drop_t_s, mut last) = (0.0_f64, f64::NAN, None::<f64>);
        for t in between(WAIT_S, PRESSED_S) {
            press_max = press_max.max(t.force());
            if press_max - t.force() > fall {
                fall = press_max - t.force();
                fall_at = Some(*t);
            }
            if let Some(f) = last
                && f - t.force() > drop
            {
                drop = f - t.force();
                drop_t_s = t.t_s;
            }
            last = Some(t.force());
        }
        // What the record shows: every tick from 5 ms before the glitch to 25 ms
        // after and within 10 ms of the largest fall in a tick while pressing
        // in, every 10 ms from 50 ms before the glitch to 300 ms after and over
        // the last 0.3 s of the press, every 100 ms elsewhere, and the lowest
        // and highest tick of the hold.
        let mut shown = String::new();
        let mut prev = f64::NEG_INFINITY;
        for t in &rec {
            let since = t.t_s - GLITCH_S;
            let every = if (-0.005..0.025).contains(&since) || (t.t_s - drop_t_s).abs() <= 0.01 {
                1e-9
            } else if (-0.05..0.3).contains(&since) || (PRESSED_S - 0.3..PRESSED_S).contains(&t.t_s)
            {
                0.01
            } else {
                0.1
            };
            // The first tick past each multiple of `every`.
            let first = (t.t_s / every).floor() > (prev / every).floor();
            if first || t.t_s == low.t_s || t.t_s == high.t_s {
                shown += &t.show();
                shown.push('\n');
            }
            prev = t.t_s;
        }
        let held: Vec<Tick> = between(PRESSED_S + 0.2, GLITCH_S - BEFORE_S.1)
            .copied()
            .collect();
        let held_range = (
            held.iter().map(Tick::force).fold(f64::INFINITY, f64::min),
            held.iter().map(Tick::force).fold(0.0, f64::max),
        );
        let diff = |a: [f64; 3], b: [f64; 3]| norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]]);
        // The largest change of the force vector from one tick to the next.
        let largest_step = |t: &[Tick]| -> f64 {
            t.windows(2)
                .map(|w| diff(w[1].force_n, w[0].force_n))
                .fold(0.0, f64::max)
        };
        let back = diff(after, before);
        let report = format!(
            "[{tag}] glitch {offset_m:?} m at {GLITCH_S} s for {} ms; probe end held {DEPTH_M} m deep (tip point z {HELD_Z_M:.4} m) from {PRESSED_S} s\n\
             pressing in: largest |F| {press_max:.4} N, largest fall below the running maximum {fall:.4} N{}, largest fall in one tick {drop:.4} N at {drop_t_s:.4} s\n\
             hold before the glitch (from {:.2} s): |F| {:.4}..{:.4} N, largest change in a tick {:.4} N\n\
             before (mean over {:.3}..{:.3} s before the glitch): F {before:.4?} N, mean |F| {f0:.4} N\n\
             after (mean over the last {AFTER_S} s): F {after:.4?} N, mean |F| {f1:.4} N ({:+.1}%), |F_after - F_before| {back:.4} N ({:.1}%)\n\
             hold from the glitch: lowest |F| {:.4} N ({:.2}x) at {:.4} s, highest {:.4} N ({:.2}x) at {:.4} s, largest change in a tick {:.4} N, longest gap between ticks {:.1} ms\n\
             record:\n{shown}",
            GLITCH_LEN_S * 1e3,
            fall_at.map_or(String::new(), |t| format!(" (at {})", t.show())),
            PRESSED_S + 0.2,
            held_range.0,
            held_range.1,
            largest_step(&held),
            GLITCH_S - before_from,
            GLITCH_S - before_to,
            100.0 * (f1 - f0) / f0,
            100.0 * back / f0,
            low.force(),
            low.force() / f0,
            low.t_s,
            high.force(),
            high.force() / f0,
            high.t_s,
            largest_step(&hold),
            gap * 1e3,
        );
        eprintln!("{report}");

        // The probe really presses down on the tissue before the glitch (the
        // tissue pushes the hand up).
        assert!(
            f0 > 0.5 && before[2] > 0.5 * f0,
            "the probe does not press down on the tissue before the glitch: F {before:?} N \
             (did it go through the surface while pressing in?)\n{report}"
        );
        // Afterwards the force is back within 20% of before (in magnitude and
        // as a vector).
        assert!(
            (f1 - f0).abs() <= 0.2 * f0 && back <= 0.2 * f0,
            "not back: |F| {f1} N after, {f0} N before, the mean force {back} N from before\n{report}"
        );
        // Never below half, never above 1.5x while the hand holds still. With
        // the glitch let through, the proxy follows the device's jump at its
        // bounded speed for the 5 ms (1 m/s: 5 mm of the 15 mm) and the force
        // falls for that long: only the way back and the ceiling are asked.
        if guard == Guard::System {
            assert!(
                low.force() >= 0.5 * f0,
                "fell to {} N of {f0} N\n{report}",
                low.force()
            );
        } else {
            assert!(
                d["poses_rejected"] == 0,
                "the daemon rejected the glitch: {d}"
            );
        }
        assert!(
            high.force() <= 1.5 * f0,
            "rose to {} N of {f0} N\n{report}",
            high.force()
        );
    }));
    let _ = std::fs::remove_dir_all(&dir);
    outcome.map_err(|_| disturbed)
}

/// Sample age above which a run counts as disturbed by the machine (ms):
/// the simulation publishes a sample every millisecond.
const DISTURBED_AGE_MS: f64 = 20.0;

/// [`glitch_once`], again when the machine disturbed a failing run.
fn glitch(tag: &str, offset_m: [f64; 3], guard: Guard) {
    for attempt in 1..=3 {
        match glitch_once(tag, offset_m, guard) {
            Ok(()) => return,
            Err(Some(why)) if attempt < 3 => {
                eprintln!(
                    "[{tag}] attempt {attempt} failed, disturbed by the machine ({why}): again"
                )
            }
            Err(Some(why)) => {
                panic!("[{tag}] failed three times, each disturbed by the machine (last: {why})")
            }
            Err(None) => panic!("[{tag}] failed in an undisturbed run (its report is above)"),
        }
    }
}

#[test]
fn a_5_ms_glitch_1_m_away_leaves_the_held_force_as_it_was() {
    glitch("away", [0.0, 0.0, 1.0], Guard::System);
}

#[test]
fn a_5_ms_glitch_20_mm_deeper_leaves_the_held_force_as_it_was() {
    glitch("deeper", [0.0, 0.0, -0.02], Guard::System);
}

#[test]
fn a_glitch_the_daemon_lets_through_is_held_by_the_simulation_proxy() {
    glitch("proxy-away", [0.0, 0.0, 1.0], Guard::ProxyOnly);
    glitch("proxy-deeper", [0.0, 0.0, -0.02], Guard::ProxyOnly);
}

/// The safety filter's code for `Active` in the record (`state_code`).
const SAFETY_ACTIVE: u32 = 2;

/// The window `[from, to)` if the safety filter was active through it;
/// otherwise the latest window of the same length inside the hold (from
/// 0.2 s after the press) and before `to` through which it was (a ramp
/// after a stall of the machine is not the steady force). Fails if there
/// is none.
fn steady_window(rec: &[Tick], from: f64, to: f64) -> (f64, f64) {
    let len = to - from;
    let active = |a: f64, b: f64| {
        rec.iter()
            .filter(|t| (a..b).contains(&t.t_s))
            .all(|t| t.safety_state == SAFETY_ACTIVE)
    };
    if active(from, to) {
        return (from, to);
    }
    rec.iter()
        .rev()
        .filter(|t| t.t_s < to && t.t_s - len >= PRESSED_S + 0.2)
        .map(|t| (t.t_s - len, t.t_s))
        .find(|&(a, b)| active(a, b) && rec.iter().any(|t| (a..b).contains(&t.t_s)))
        .unwrap_or_else(|| {
            panic!("the safety filter was never active for {len} s in the hold before {to} s")
        })
}

#[test]
fn the_baseline_skips_a_ramp_after_a_stall_and_only_that() {
    // Ticks each millisecond of the hold, the filter active except for a
    // ramp (after a stall) from 2.85 to 2.95 s.
    let tick = |ms: u32, state: u32| Tick {
        t_s: ms as f64 * 1e-3,
        pos_z_m: HELD_Z_M,
        force_n: [0.0; 3],
        sample_age_ns: 0,
        safety_state: state,
    };
    let from_ms = (PRESSED_S * 1e3) as u32;
    let ramp = |ms: u32| (2850..2950).contains(&ms);
    let rec: Vec<Tick> = (from_ms..3000)
        .map(|ms| tick(ms, if ramp(ms) { 1 } else { SAFETY_ACTIVE }))
        .collect();
    // A window clear of the ramp is kept as it is.
    assert_eq!(steady_window(&rec, 2.7, 2.79), (2.7, 2.79));
    // One that holds it moves back to end before the ramp's first tick.
    let (a, b) = steady_window(&rec, 2.9, 2.99);
    assert!(
        (b - 2.8495).abs() < 1e-3 && (b - a - 0.09).abs() < 1e-9,
        "{a}..{b}"
    );
}
