//! A fixed-size histogram of step wall times: 64 buckets per power of two
//! (at most 1.6% relative error), allocated once, nothing per sample.

use serde::Serialize;

/// Sub-buckets per power of two, as bits.
const SUB_BITS: u32 = 6;
const SUB: usize = 1 << SUB_BITS;
/// Buckets: values below `SUB` one each, then `SUB` per power of two up to 2^64.
const BUCKETS: usize = SUB * (64 - SUB_BITS as usize + 1);

/// Percentiles of the step time (us), the `step_us` of the run summary.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StepPercentiles {
    /// Steps timed.
    pub count: u64,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// 99.9th percentile.
    pub p999: f64,
    /// Largest.
    pub max: f64,
}

/// Counts of durations (ns) in log-linear buckets.
#[derive(Clone, Debug)]
pub struct StepHistogram {
    counts: Box<[u64]>,
    count: u64,
    max_ns: u64,
}

impl Default for StepHistogram {
    fn default() -> Self {
        Self::new()
    }
}

fn bucket(v: u64) -> usize {
    if v < SUB as u64 {
        return v as usize;
    }
    let e = 63 - v.leading_zeros();
    let shift = e - SUB_BITS;
    let sub = ((v >> shift) as usize) - SUB;
    ((shift as usize + 1) << SUB_BITS) | sub
}

/// The middle of bucket `i` (ns).
fn middle(i: usize) -> f64 {
    if i < SUB {
        return i as f64;
    }
    let shift = (i >> SUB_BITS) - 1;
    let low = ((SUB + (i & (SUB - 1))) as u64) << shift;
    low as f64 + ((1u64 << shift) as f64 - 1.0) / 2.0
}

impl StepHistogram {
    /// Empty (the one allocation).
    pub fn new() -> Self {
        Self {
            counts: vec![0; BUCKETS].into_boxed_slice(),
            count: 0,
            max_ns: 0,
        }
    }

    /// Counts a duration.
    pub fn record(&mut self, ns: u64) {
        self.counts[bucket(ns)] += 1;
        self.count += 1;
        self.max_ns = self.max_ns.max(ns);
    }

    /// Durations counted.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The `q` quantile (0..=1, ns): the middle of the bucket holding it,
    /// never above the largest value; 0 when empty.
    pub fn quantile_ns(&self, q: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return middle(i).min(self.max_ns as f64);
            }
        }
        self.max_ns as f64
    }

    /// p50, p99, p99.9 and max in microseconds.
    pub fn percentiles_us(&self) -> StepPercentiles {
        StepPercentiles {
            count: self.count,
            p50: self.quantile_ns(0.5) * 1e-3,
            p90: self.quantile_ns(0.9) * 1e-3,
            p99: self.quantile_ns(0.99) * 1e-3,
            p999: self.quantile_ns(0.999) * 1e-3,
            max: self.max_ns as f64 * 1e-3,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_are_ordered_and_hold_their_values() {
        let mut last = 0;
        for v in (0..100_000u64).chain([u64::MAX / 3, u64::MAX]) {
            let b = bucket(v);
            assert!(b >= last && b < BUCKETS, "{v} -> {b}");
            last = b;
            let m = middle(b);
            assert!(
                (m - v as f64).abs() <= v as f64 / SUB as f64 + 0.5,
                "{v}: middle {m}"
            );
        }
    }

    #[test]
    fn percentiles_of_a_known_distribution() {
        let mut h = StepHistogram::new();
        // 1..=10000 us in ns, once each.
        for k in 1..=10_000u64 {
            h.record(k * 1000);
        }
        let p = h.percentiles_us();
        assert_eq!(p.count, 10_000);
        let close = |got: f64, want: f64| (got - want).abs() <= want * 0.02;
        assert!(close(p.p50, 5000.0), "{p:?}");
        assert!(close(p.p99, 9900.0), "{p:?}");
        assert!(close(p.p999, 9990.0), "{p:?}");
        assert_eq!(p.max, 10_000.0);
    }

    #[test]
    fn one_outlier_shows_in_the_max_and_the_tail_only() {
        let mut h = StepHistogram::new();
        for _ in 0..10_000 {
            h.record(500_000);
        }
        h.record(40_000_000);
        let p = h.percentiles_us();
        assert!((p.p50 - 500.0).abs() < 10.0, "{p:?}");
        assert!((p.p999 - 500.0).abs() < 10.0, "{p:?}");
        assert_eq!(p.max, 40_000.0);
        assert_eq!(
            StepHistogram::new().percentiles_us(),
            StepPercentiles::default()
        );
    }
}
