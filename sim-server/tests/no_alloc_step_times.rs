//! The run loop's step-time histogram (`step_us` of `sim-server run --json`)
//! allocates nothing per step: a counting global allocator counts
//! allocations while 100,000 step times are recorded.

use shared::alloc_count::{Counting, count};
use sim_server::step_time::LoopHistogram;

#[global_allocator]
static ALLOCATOR: Counting = Counting;

#[test]
fn recording_step_times_allocates_nothing() {
    let mut h = LoopHistogram::new();
    let ((), allocations) = count(|| {
        for k in 0..100_000i64 {
            h.record_ns(400_000 + (k * 7919) % 300_000);
        }
    });
    assert_eq!(allocations, 0);
    let p = h.percentiles_us();
    assert_eq!(p.count, 100_000);
    assert!(p.p50 > 400.0 && p.p50 < 700.0 && p.max < 700.0, "{p:?}");
}
