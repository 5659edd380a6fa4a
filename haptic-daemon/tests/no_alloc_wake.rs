//! The RT tick's wake of the I/O thread (`Thread::unpark` after each pose
//! write) allocates nothing and does not block: a counting global allocator
//! counts allocations on the ticking thread while another thread, registered
//! as the I/O thread, parks and is woken; every tick's pose reaches it.

use haptic_daemon::daemon::{RtLoop, Shared};
use haptic_daemon::device::{HandModel, Path, Simulated};
use haptic_daemon::extrapolate::Method;
use haptic_daemon::safety::SafetyConfig;
use shared::alloc_count::{Counting, count};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

#[global_allocator]
static ALLOCATOR: Counting = Counting;

#[test]
fn waking_the_io_thread_allocates_nothing_and_every_pose_wakes_it() {
    let shared = Arc::new(Shared::new(1 << 15));
    let done = Arc::new(AtomicBool::new(false));
    let wakes = Arc::new(AtomicU64::new(0));
    let seen = Arc::new(AtomicU64::new(0));
    let io = {
        let (shared, done, wakes, seen) =
            (shared.clone(), done.clone(), wakes.clone(), seen.clone());
        std::thread::spawn(move || {
            shared.io_thread.set(std::thread::current()).unwrap();
            let mut last = 0;
            while !done.load(Ordering::Acquire) {
                // Long enough that only the wake ends it in time.
                std::thread::park_timeout(Duration::from_secs(1));
                wakes.fetch_add(1, Ordering::Relaxed);
                if let Some(p) = shared.pose.read()
                    && p.seq != last
                {
                    last = p.seq;
                    seen.fetch_add(1, Ordering::Relaxed);
                }
            }
        })
    };
    while shared.io_thread.get().is_none() {
        std::thread::yield_now();
    }
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
    let mut rt = RtLoop::new(
        device,
        Method::Constant,
        SafetyConfig::new(5.0).unwrap(),
        None,
        shared.clone(),
    );
    let t0 = 1_000_000_000u64;
    rt.enable(t0).unwrap();
    let ticks = 2000u64;
    let mut allocations = 0;
    let started = Instant::now();
    for k in 0..ticks {
        let before = seen.load(Ordering::Relaxed);
        allocations += count(|| rt.tick(t0 + k * 1_000_000, 0)).1;
        while shared.telemetry.pop().is_some() {}
        // The I/O side sees this tick's pose well before its 1 s park ends.
        let wait = Instant::now();
        while seen.load(Ordering::Relaxed) == before {
            assert!(
                wait.elapsed() < Duration::from_millis(500),
                "tick {k}: the I/O thread was not woken"
            );
            std::hint::spin_loop();
        }
    }
    done.store(true, Ordering::Release);
    shared.wake_io();
    io.join().unwrap();
    assert_eq!(allocations, 0, "{allocations} allocations in {ticks} ticks");
    assert!(seen.load(Ordering::Relaxed) >= ticks);
    assert!(wakes.load(Ordering::Relaxed) >= ticks);
    // 2000 wakes, not 2000 park timeouts of 1 s.
    assert!(started.elapsed() < Duration::from_secs(60));
}
