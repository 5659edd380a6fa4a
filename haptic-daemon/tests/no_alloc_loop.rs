//! The real-time tick allocates nothing: a counting global allocator counts
//! allocations made on this thread while `RtLoop::tick` runs, over 10,000
//! ticks per extrapolation method, with force samples arriving through a
//! real iceoryx2 subscriber (published between ticks, outside the count).

use haptic_daemon::daemon::{RtLoop, Shared};
use haptic_daemon::device::{HandModel, Path, Simulated};
use haptic_daemon::extrapolate::Method;
use haptic_daemon::safety::SafetyConfig;
use shared::alloc_count::{Counting, count};
use shared::protocol::{CONTACT, ForceMsg, PROTOCOL_VERSION};
use shared::{SessionName, services};
use std::sync::Arc;

#[global_allocator]
static ALLOCATOR: Counting = Counting;

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
        let device = Simulated::new(
            Path::Poke {
                start_m: [0.0, 0.0, 0.05],
                direction: [0.0, 0.0, -1.0],
                depth_m: 0.02,
                period_s: 1.0,
            },
            HandModel::default(),
            8.0,
        );
        let sub = services::subscriber(&factory).unwrap();
        let mut rt = RtLoop::new(
            device,
            method,
            SafetyConfig::new(5.0).unwrap(),
            Some(sub),
            shared.clone(),
        );
        let t0 = 1_000_000_000u64;
        rt.enable(t0).unwrap();
        let mut allocations = 0;
        for k in 0..10_000u64 {
            let now = t0 + k * 1_000_000;
            if k % 3 == 0 {
                let mut msg = ForceMsg {
                    version: PROTOCOL_VERSION,
                    tool_count: 1,
                    seq: k,
                    t_ns: now,
                    ..ForceMsg::default()
                };
                msg.tools[0].force_n = [0.0, 0.0, (k as f64 * 1e-3).sin()];
                msg.tools[0].position_m = [0.0, 0.0, 0.05 - (k as f64 * 1e-3).sin() * 0.01];
                msg.tools[0].stiffness_n_per_m =
                    [[100.0, 0.0, 0.0], [0.0, 100.0, 0.0], [0.0, 0.0, 100.0]];
                msg.tools[0].flags = CONTACT;
                publisher.send_copy(msg).unwrap();
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
        assert!(shared.samples.load(std::sync::atomic::Ordering::Relaxed) > 3000);
        let f = rt.last_force_n();
        assert!(f.iter().all(|x| x.is_finite()));
    }
}
