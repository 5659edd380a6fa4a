//! The real-time tick's checks end to end, with a scripted device and a
//! simulation played by the test through a real iceoryx2 service: a device
//! glitch is rejected entirely (same force before, during and after), a
//! re-homed device ramps in, and a fast-forward burst is not rendered.

use haptic_daemon::daemon::{RtLoop, Shared};
use haptic_daemon::device::{Device, DeviceError, DeviceSpecs, DeviceState};
use haptic_daemon::extrapolate::Method;
use haptic_daemon::safety::SafetyConfig;
use shared::protocol::{CONTACT, ForceMsg, PROTOCOL_VERSION};
use shared::{SessionName, services};
use std::sync::Arc;
use std::sync::atomic::Ordering;

const MS: u64 = 1_000_000;
const T0: u64 = 1_000 * MS;
const K_N_PER_M: f64 = 300.0;

/// A device whose position is a function of time.
struct Scripted<F: FnMut(u64) -> [f64; 3]>(F);

impl<F: FnMut(u64) -> [f64; 3]> Device for Scripted<F> {
    fn specs(&self) -> DeviceSpecs {
        DeviceSpecs {
            name: "scripted",
            max_force_n: 8.0,
            max_stiffness_n_per_m: 3000.0,
            workspace_min_m: [-2.0; 3],
            workspace_max_m: [2.0; 3],
        }
    }
    fn enable(&mut self, _now_ns: u64) -> Result<(), DeviceError> {
        Ok(())
    }
    fn disable(&mut self) {}
    fn read(&mut self, now_ns: u64) -> Result<DeviceState, DeviceError> {
        Ok(DeviceState {
            position_m: (self.0)(now_ns),
            ..DeviceState::default()
        })
    }
    fn write_force(&mut self, _force_n: [f64; 3], _now_ns: u64) -> Result<(), DeviceError> {
        Ok(())
    }
}

/// A wall z < 0 at 300 N/m, as the simulation would compute it.
fn wall_msg(seq: u64, t_ns: u64, sim_time_ns: u64, p: [f64; 3]) -> ForceMsg {
    let mut msg = ForceMsg {
        version: PROTOCOL_VERSION,
        tool_count: 1,
        seq,
        t_ns,
        sim_time_ns,
        ..ForceMsg::default()
    };
    let depth = (-p[2]).max(0.0);
    msg.tools[0].position_m = p;
    msg.tools[0].force_n = [0.0, 0.0, K_N_PER_M * depth];
    msg.tools[0].stiffness_n_per_m = [[0.0; 3], [0.0; 3], [0.0, 0.0, K_N_PER_M]];
    msg.tools[0].flags = if depth > 0.0 { CONTACT } else { 0 };
    msg
}

struct Bench {
    _node: iceoryx2::node::Node<services::Ipc>,
    publisher: iceoryx2::port::publisher::Publisher<services::Ipc, ForceMsg, ()>,
    subscriber: Option<shared::source::Source<ForceMsg>>,
    shared: Arc<Shared>,
}

fn bench(name: &str) -> Bench {
    let session = SessionName::new(&format!("chain{name}{}", std::process::id())).unwrap();
    let node = services::node("chain-test").unwrap();
    let factory = services::force_service(&node, &session).unwrap();
    let publisher = services::publisher(&factory).unwrap();
    let subscriber = Some(shared::source::Source::Shm(
        services::subscriber(&factory).unwrap(),
    ));
    let shared = Arc::new(Shared::new(1 << 16));
    shared.flags.peer_alive.store(true, Ordering::Relaxed);
    Bench {
        _node: node,
        publisher,
        subscriber,
        shared,
    }
}

/// Runs `ticks` 1 kHz ticks; the simulation answers every tick from the
/// pose the daemon published the tick before (sim time = wall time).
/// Returns the forces and the poses the simulation saw.
fn run_glitch(glitch: [f64; 3]) -> (Vec<[f64; 3]>, Vec<[f64; 3]>, Arc<Shared>) {
    let mut b = bench(&format!("g{}", (glitch[0] * 100.0) as i64));
    let rest = [0.0, 0.0, -0.015];
    let device = Scripted(move |t: u64| {
        let k = (t - T0) / MS;
        if (500..505).contains(&k) {
            glitch
        } else {
            rest
        }
    });
    let mut rt = RtLoop::new(
        device,
        Method::LocalModel,
        SafetyConfig::new(8.0).unwrap(),
        b.subscriber.take(),
        b.shared.clone(),
    );
    rt.enable(T0).unwrap();
    let (mut forces, mut seen) = (Vec::new(), Vec::new());
    for k in 0..700u64 {
        let now = T0 + k * MS;
        if let Some(p) = b.shared.pose.read() {
            seen.push(p.position_m);
            b.publisher
                .send_copy(wall_msg(k, now, now - T0, p.position_m))
                .unwrap();
        }
        rt.tick(now, 0);
        forces.push(rt.last_force_n());
        while b.shared.telemetry.pop().is_some() {}
    }
    (forces, seen, b.shared)
}

#[test]
fn a_5_ms_glitch_renders_the_same_force_before_during_and_after() {
    for glitch in [[1.0, 0.0, -0.015], [0.0, 0.0, -0.035]] {
        let (forces, seen, shared) = run_glitch(glitch);
        // 15 mm into 300 N/m: 4.5 N, reached after the 200 ms ramp-in.
        let before = forces[499];
        assert!((before[2] - 4.5).abs() < 1e-9, "{before:?}");
        for (k, f) in forces.iter().enumerate().skip(300) {
            assert_eq!(*f, before, "{glitch:?}: tick {k}");
        }
        assert!(seen.iter().all(|p| *p == [0.0, 0.0, -0.015]), "{glitch:?}");
        assert_eq!(shared.poses_rejected.load(Ordering::Relaxed), 5);
        assert_eq!(shared.pose_rereferences.load(Ordering::Relaxed), 0);
    }
}

/// Free space at z = +5 mm, then re-homed to `to` for good: the number of
/// rejected samples, and the forces.
fn rehome(to: [f64; 3], name: &str) -> (u64, Vec<f64>) {
    let mut b = bench(name);
    let device = Scripted(move |t: u64| {
        if t < T0 + 500 * MS {
            [0.0, 0.0, 0.005]
        } else {
            to
        }
    });
    let mut rt = RtLoop::new(
        device,
        Method::LocalModel,
        SafetyConfig::new(8.0).unwrap(),
        b.subscriber.take(),
        b.shared.clone(),
    );
    rt.enable(T0).unwrap();
    let mut forces = Vec::new();
    for k in 0..1_000u64 {
        let now = T0 + k * MS;
        if let Some(p) = b.shared.pose.read() {
            b.publisher
                .send_copy(wall_msg(k, now, now - T0, p.position_m))
                .unwrap();
        }
        rt.tick(now, 0);
        forces.push(rt.last_force_n()[2]);
        while b.shared.telemetry.pop().is_some() {}
    }
    assert_eq!(b.shared.pose_rereferences.load(Ordering::Relaxed), 1);
    (b.shared.poses_rejected.load(Ordering::Relaxed), forces)
}

#[test]
fn a_rehomed_device_ramps_in() {
    // 15 mm in one tick: rejected until the widening envelope (2 mm +
    // 100 m/s^2 dt^2 / 2) takes it in 17 ms after the last good pose (16
    // rejections), as a new reference. 10 cm
    // aside: rejected for the 20 ms bound, then the new reference.
    for (to, want, name) in [
        ([0.0, 0.0, -0.010], 16, "rehomez"),
        ([0.1, 0.0, -0.010], 20, "rehomex"),
    ] {
        let (rejected, forces) = rehome(to, name);
        assert_eq!(rejected, want, "{to:?}");
        // Held in free space through the rejections, then a ramp to 3 N
        // over 200 ms: never a step above 3 N / 200 per tick.
        let from = 500 + rejected as usize;
        assert!(forces[..=from].iter().all(|f| *f == 0.0), "{to:?}");
        for w in forces[from..].windows(2) {
            assert!((w[1] - w[0]).abs() <= 3.0 / 200.0 + 1e-9, "{to:?}: {w:?}");
        }
        assert!((forces[999] - 3.0).abs() < 1e-9, "{}", forces[999]);
    }
}

#[test]
fn a_fast_forward_burst_is_not_rendered() {
    let mut b = bench("burst");
    let device = Scripted(|_| [0.0, 0.0, -0.005]);
    let mut rt = RtLoop::new(
        device,
        Method::Constant,
        SafetyConfig::new(8.0).unwrap(),
        b.subscriber.take(),
        b.shared.clone(),
    );
    rt.enable(T0).unwrap();
    let step = 33 * MS;
    let (mut seq, mut sim) = (0u64, 0u64);
    let mut next_sample = T0;
    let mut forces = Vec::new();
    // 1 s live (1.5 N), 2 s stalled, 0.3 s of burst carrying 1.9 s of
    // simulated time (at 6 N), then 1 s live again (1.5 N).
    let (stall, burst, live_again) = (T0 + 1_000 * MS, T0 + 3_000 * MS, T0 + 3_300 * MS);
    for k in 0..4_300u64 {
        let now = T0 + k * MS;
        let mut send = |sim_ns: u64, f: f64| {
            let mut msg = wall_msg(seq, now, sim_ns, [0.0, 0.0, -0.005]);
            msg.tools[0].force_n[2] = f;
            b.publisher.send_copy(msg).unwrap();
            seq += 1;
        };
        if now < stall || now >= live_again {
            if now >= next_sample {
                sim += step;
                send(sim, 1.5);
                next_sample = now + step;
            }
        } else if now >= burst && (now - burst).is_multiple_of(5 * MS) {
            sim += step;
            send(sim, 6.0);
            next_sample = now;
        }
        rt.tick(now, 0);
        forces.push(rt.last_force_n()[2]);
        while b.shared.telemetry.pop().is_some() {}
    }
    let at = |t: u64| forces[((t - T0) / MS) as usize];
    assert!((at(stall - MS) - 1.5).abs() < 1e-9);
    // Stalled: the age watchdog ramps down; the burst renders nothing.
    for k in (burst - T0) / MS..(live_again - T0) / MS {
        assert!(
            forces[k as usize].abs() < 1e-12,
            "tick {k}: {}",
            forces[k as usize]
        );
    }
    // Live again: ramps in to 1.5 N, never above.
    assert!(forces.iter().all(|f| *f <= 1.5 + 1e-9));
    assert!((forces[4_299] - 1.5).abs() < 1e-9, "{}", forces[4_299]);
    let not_live = b.shared.samples_not_live.load(Ordering::Relaxed);
    assert!(not_live >= 57, "{not_live}");
}

/// What a faulty driver returns on a tick: a reading, or an error.
type Reading = Result<DeviceState, DeviceError>;

/// A named way for a read to go wrong.
type Fault = (&'static str, fn() -> Reading);

/// A device whose every reading (or error) is a function of the tick.
struct Faulty<F: FnMut(u64) -> Reading>(F);

impl<F: FnMut(u64) -> Reading> Device for Faulty<F> {
    fn specs(&self) -> DeviceSpecs {
        Scripted(|_| [0.0; 3]).specs()
    }
    fn enable(&mut self, _now_ns: u64) -> Result<(), DeviceError> {
        Ok(())
    }
    fn disable(&mut self) {}
    fn read(&mut self, now_ns: u64) -> Reading {
        (self.0)((now_ns - T0) / MS)
    }
    fn write_force(&mut self, _force_n: [f64; 3], _now_ns: u64) -> Result<(), DeviceError> {
        Ok(())
    }
}

/// Held 15 mm deep (4.5 N against the wall), the device misbehaving on the
/// ticks `bad` with `fault`: the forces over 1 s, and the counters.
fn held_through(bad: std::ops::Range<u64>, fault: fn() -> Reading) -> (Vec<f64>, Arc<Shared>) {
    let mut b = bench(&format!("bad{}x{}", bad.start, bad.end));
    let good = DeviceState {
        position_m: [0.0, 0.0, -0.015],
        gripper: 1.0,
        ..DeviceState::default()
    };
    let device = Faulty(move |k| if bad.contains(&k) { fault() } else { Ok(good) });
    let mut rt = RtLoop::new(
        device,
        Method::LocalModel,
        SafetyConfig::new(8.0).unwrap(),
        b.subscriber.take(),
        b.shared.clone(),
    );
    rt.enable(T0).unwrap();
    let mut forces = Vec::new();
    for k in 0..1_000u64 {
        let now = T0 + k * MS;
        if let Some(p) = b.shared.pose.read() {
            assert_eq!(
                p.position_m, good.position_m,
                "tick {k}: a bad pose went out"
            );
            b.publisher
                .send_copy(wall_msg(k, now, now - T0, p.position_m))
                .unwrap();
        }
        rt.tick(now, 0);
        forces.push(rt.last_force_n()[2]);
        while b.shared.telemetry.pop().is_some() {}
    }
    (forces, b.shared)
}

/// The faults a driver shows: an error code, NaN or infinite fields.
fn faults() -> [Fault; 5] {
    /// The held reading with one field spoiled by `f`.
    fn spoiled(f: fn(&mut DeviceState)) -> Reading {
        let mut s = DeviceState {
            position_m: [0.0, 0.0, -0.015],
            ..DeviceState::default()
        };
        f(&mut s);
        Ok(s)
    }
    [
        ("error", || {
            Err(DeviceError::Disconnected("read returned -42".into()))
        }),
        ("nan position", || spoiled(|s| s.position_m[0] = f64::NAN)),
        ("inf position", || {
            spoiled(|s| s.position_m[2] = f64::INFINITY)
        }),
        ("nan velocity", || spoiled(|s| s.velocity_m_s[1] = f64::NAN)),
        ("nan gripper", || spoiled(|s| s.gripper = f64::NAN)),
    ]
}

#[test]
fn a_bad_read_or_a_short_run_of_them_keeps_the_held_force() {
    for (name, fault) in faults() {
        for bad in [500..501, 500..515] {
            let n = bad.end - bad.start;
            let (forces, shared) = held_through(bad, fault);
            let before = forces[499];
            assert!((before - 4.5).abs() < 1e-9, "{name}: {before}");
            for (k, f) in forces.iter().enumerate().skip(300) {
                assert_eq!(*f, before, "{name} x{n}: tick {k}");
            }
            assert_eq!(shared.device_bad_reads.load(Ordering::Relaxed), n, "{name}");
            assert_eq!(shared.poses_rejected.load(Ordering::Relaxed), n, "{name}");
            assert_eq!(shared.pose_rereferences.load(Ordering::Relaxed), 0);
        }
    }
}

#[test]
fn bad_reads_that_persist_ramp_the_force_down_and_good_ones_ramp_it_in() {
    for (name, fault) in faults() {
        // 100 ms of bad reads: past the 20 ms bound the force ramps to
        // zero (never a step), and good reads ramp it in again.
        let (forces, shared) = held_through(500..600, fault);
        let before = forces[499];
        assert!(forces[525..600].contains(&0.0), "{name}: never stopped");
        assert!(
            forces[..520].iter().skip(300).all(|f| *f == before),
            "{name}"
        );
        for w in forces.windows(2) {
            // The safety filter ramps down over 10 ms: never a step.
            assert!((w[1] - w[0]).abs() <= before / 10.0 + 1e-9, "{name}: {w:?}");
        }
        assert!(forces.iter().all(|f| *f <= before + 1e-9), "{name}");
        assert!(
            (forces[999] - before).abs() < 1e-9,
            "{name}: {}",
            forces[999]
        );
        assert_eq!(
            shared.device_bad_reads.load(Ordering::Relaxed),
            100,
            "{name}"
        );
    }
}

/// A device at a fixed pose in its own frame that keeps what it is told
/// to render.
struct Recording {
    at_m: [f64; 3],
    written: std::sync::Arc<std::sync::Mutex<Vec<[f64; 3]>>>,
}

impl Device for Recording {
    fn specs(&self) -> DeviceSpecs {
        Scripted(|_| [0.0; 3]).specs()
    }
    fn enable(&mut self, _now_ns: u64) -> Result<(), DeviceError> {
        Ok(())
    }
    fn disable(&mut self) {}
    fn read(&mut self, _now_ns: u64) -> Result<DeviceState, DeviceError> {
        Ok(DeviceState {
            position_m: self.at_m,
            ..DeviceState::default()
        })
    }
    fn write_force(&mut self, force_n: [f64; 3], _now_ns: u64) -> Result<(), DeviceError> {
        self.written.lock().unwrap().push(force_n);
        Ok(())
    }
}

#[test]
fn a_placed_workspace_gives_the_same_force_at_the_same_scene_point() {
    use haptic_daemon::device::{Mapped, WorkspaceMap};
    let scene_point = [0.0, 0.0, -0.015];
    let run = |map: WorkspaceMap, name: &str| {
        let mut b = bench(name);
        let written = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let device = Mapped::new(
            Recording {
                at_m: map.to_device(scene_point),
                written: written.clone(),
            },
            map,
        );
        let specs = device.specs();
        let mut rt = RtLoop::new(
            device,
            Method::LocalModel,
            SafetyConfig::new(8.0).unwrap(),
            b.subscriber.take(),
            b.shared.clone(),
        );
        rt.enable(T0).unwrap();
        let mut seen = Vec::new();
        for k in 0..400u64 {
            let now = T0 + k * MS;
            if let Some(p) = b.shared.pose.read() {
                seen.push(p.position_m);
                b.publisher
                    .send_copy(wall_msg(k, now, now - T0, p.position_m))
                    .unwrap();
            }
            rt.tick(now, 0);
            while b.shared.telemetry.pop().is_some() {}
        }
        let last = *written.lock().unwrap().last().unwrap();
        (last, seen, specs)
    };
    let (plain, _, plain_specs) = run(WorkspaceMap::IDENTITY, "wsid");
    // A workspace turned a quarter about x (the device's y is the scene's
    // up) and about z, twice as large in the scene, its origin 10 cm aside
    // and 5 cm up.
    let map = WorkspaceMap::new([0.1, 0.0, 0.05], 2.0, [90.0, 0.0, 90.0]).unwrap();
    let (placed, seen, specs) = run(map, "wsmap");
    assert!((plain[2] - 4.5).abs() < 1e-9, "{plain:?}");
    // The simulation saw the same scene point...
    for p in &seen {
        let d: f64 = (0..3).map(|i| (p[i] - scene_point[i]).powi(2)).sum();
        assert!(d.sqrt() < 1e-12, "{p:?}");
    }
    // ... and the device renders the same force in its own axes.
    let expected = map.force_to_device(plain);
    assert!(
        (expected[2]).abs() < 1e-9,
        "the scene's up is not the device's: {expected:?}"
    );
    for i in 0..3 {
        assert!(
            (placed[i] - expected[i]).abs() < 1e-9,
            "{placed:?} vs {expected:?}"
        );
    }
    // The stiffness the scene may render is the device's over the scale.
    assert_eq!(
        specs.max_stiffness_n_per_m,
        plain_specs.max_stiffness_n_per_m / 2.0
    );
    assert!(specs.workspace_max_m[0] > plain_specs.workspace_max_m[0]);
}
