//! The real-time tick allocates nothing: a counting global allocator counts
//! allocations made on this thread while `RtLoop::tick` runs, over 10,000
//! ticks per extrapolation method, with force samples arriving through a
//! real iceoryx2 subscriber (published between ticks, outside the count),
//! a fast-forward burst among them, and a device that glitches, reports NaN
//! and is re-homed.

use haptic_daemon::daemon::{RtLoop, Shared};
use haptic_daemon::device::{
    Device, DeviceError, DeviceSpecs, DeviceState, HandModel, Path, Simulated,
};
use haptic_daemon::extrapolate::Method;
use haptic_daemon::extrapolate::local_problem::{Capsule, LocalContactMsg, LocalProblem, Point};
use haptic_daemon::safety::SafetyConfig;
use shared::alloc_count::{Counting, count};
use shared::protocol::{CONTACT, ForceMsg, PROTOCOL_VERSION};
use shared::{SessionName, services};
use std::sync::Arc;

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The simulated hand with glitches: 1 m away for 5 ticks every second,
/// NaN every 777th tick, and re-homed 20 cm aside from tick 8000.
struct Glitchy(Simulated, u64);

impl Device for Glitchy {
    fn specs(&self) -> DeviceSpecs {
        self.0.specs()
    }
    fn enable(&mut self, now_ns: u64) -> Result<(), DeviceError> {
        self.0.enable(now_ns)
    }
    fn disable(&mut self) {
        self.0.disable()
    }
    fn read(&mut self, now_ns: u64) -> Result<DeviceState, DeviceError> {
        let mut s = self.0.read(now_ns)?;
        let k = self.1;
        self.1 += 1;
        if k % 1000 < 5 {
            s.position_m[0] += 1.0;
        }
        if k % 777 == 3 {
            s.position_m[1] = f64::NAN;
        }
        if k >= 8000 {
            s.position_m[0] += 0.2;
        }
        Ok(s)
    }
    fn write_force(&mut self, force_n: [f64; 3], now_ns: u64) -> Result<(), DeviceError> {
        self.0.write_force(force_n, now_ns)
    }
}

#[test]
fn ten_thousand_ticks_allocate_nothing() {
    let session = SessionName::new(&format!("noalloc{}", std::process::id())).unwrap();
    let node = services::node("noalloc-test").unwrap();
    let factory = services::force_service(&node, &session).unwrap();
    let publisher = services::publisher(&factory).unwrap();
    for method in Method::ALL {
        let shared = Arc::new(Shared::new(1 << 15));
        shared
            .flags
            .peer_alive
            .store(true, std::sync::atomic::Ordering::Relaxed);
        let device = Glitchy(
            Simulated::new(
                Path::Poke {
                    start_m: [0.0, 0.0, 0.05],
                    direction: [0.0, 0.0, -1.0],
                    depth_m: 0.02,
                    period_s: 1.0,
                },
                HandModel::default(),
                8.0,
            ),
            0,
        );
        let sub = services::subscriber(&factory).unwrap();
        let mut rt = RtLoop::new(
            device,
            method,
            SafetyConfig::new(5.0).unwrap(),
            Some(shared::source::Source::Shm(sub)),
            shared.clone(),
        );
        // local-problem: contact problems handed over as the I/O thread
        // does (set up outside the count), solved in the tick.
        let (mut local_in, local_out) = triple_buffer::triple_buffer(&LocalProblem::new());
        if method == Method::LocalProblem {
            rt = rt.with_local_problems(local_out);
        }
        let mut problem = Box::<LocalContactMsg>::default();
        let t0 = 1_000_000_000u64;
        rt.enable(t0).unwrap();
        let mut allocations = 0;
        let mut sim_ns = 0u64;
        for k in 0..10_000u64 {
            let now = t0 + k * 1_000_000;
            if k % 3 == 0 {
                // A fast-forward burst: 20 ms of simulated time per 3 ms.
                sim_ns += if (6000..6300).contains(&k) { 20 } else { 3 } * 1_000_000;
                let mut msg = ForceMsg {
                    version: PROTOCOL_VERSION,
                    tool_count: 1,
                    seq: k,
                    t_ns: now,
                    sim_time_ns: sim_ns,
                    ..ForceMsg::default()
                };
                msg.tools[0].force_n = [0.0, 0.0, (k as f64 * 1e-3).sin()];
                msg.tools[0].position_m = [0.0, 0.0, 0.05 - (k as f64 * 1e-3).sin() * 0.01];
                msg.tools[0].stiffness_n_per_m =
                    [[100.0, 0.0, 0.0], [0.0, 100.0, 0.0], [0.0, 0.0, 100.0]];
                msg.tools[0].flags = CONTACT;
                publisher.send_copy(msg).unwrap();
                if k % 12 == 0 {
                    surface_under(&mut problem, msg.tools[0].position_m, k, now);
                    // Every other one with the tissue's inertia (the
                    // samples after it re-base on its history).
                    problem.inertia = ((k / 12) % 2) as u32;
                    let lp = local_in.input_buffer_mut();
                    lp.set_from_wire(&problem).unwrap();
                    lp.set_inertia_from_wire(&problem, 3e-3, 1e-3).unwrap();
                    local_in.publish();
                }
            }
            allocations += count(|| rt.tick(now, 0)).1;
            // Keep the telemetry queue from filling (the I/O thread's job).
            while shared.telemetry.pop().is_some() {}
        }
        assert_eq!(
            allocations,
            0,
            "{}: {allocations} allocations in 10,000 ticks",
            method.name()
        );
        let load = |a: &std::sync::atomic::AtomicU64| a.load(std::sync::atomic::Ordering::Relaxed);
        assert!(load(&shared.samples) > 3000);
        assert!(load(&shared.samples_not_live) > 0);
        assert!(load(&shared.poses_rejected) > 0);
        assert!(load(&shared.pose_rereferences) > 0);
        let f = rt.last_force_n();
        assert!(f.iter().all(|x| x.is_finite()));
    }
}

/// A contact problem: a 5 x 5 cm triangle 4 cm up, with 25 points, under a
/// probe at `tool_m`.
fn surface_under(msg: &mut LocalContactMsg, tool_m: [f64; 3], seq: u64, t_ns: u64) {
    msg.seq = seq;
    msg.t_ns = t_ns;
    msg.tool_position_m = tool_m;
    msg.part_count = 1;
    msg.parts[0] = Capsule {
        a_m: tool_m,
        b_m: [tool_m[0], tool_m[1], tool_m[2] + 0.01],
        radius_m: 0.005,
        onset_m: 1e-4,
    };
    msg.vertex_count = 3;
    msg.positions_m[..3].copy_from_slice(&[
        [-0.02, -0.02, 0.04],
        [0.03, -0.02, 0.04],
        [-0.02, 0.03, 0.04],
    ]);
    let mut n = 0;
    for i in 0..5 {
        for j in 0..5 - i {
            let (a, b) = ((i as f64 + 0.3) / 5.0, (j as f64 + 0.3) / 5.0);
            msg.points[n] = Point {
                weights: [1.0 - a - b, a, b],
                stiffness_n_per_m: 200.0,
                slots: [0, 1, 2],
                part: 0,
            };
            n += 1;
        }
    }
    msg.point_count = n as u32;
    msg.compliance_m_per_n[..81].fill(0.0);
    for d in 0..9 {
        msg.compliance_m_per_n[d * 9 + d] = 0.002;
    }
    // With `inertia`: 10 g at each coordinate once condensed (G = m W W).
    msg.column_mass[..81].fill(0.0);
    for d in 0..9 {
        msg.column_mass[d * 9 + d] = 0.01 * 0.002 * 0.002;
    }
    msg.velocities_m_per_s[..3].fill([0.0, 0.0, -0.01]);
    msg.damping_per_s = 10.0;
}
