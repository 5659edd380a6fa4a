//! Loop statistics: one histogram type for every duration a loop measures
//! (the simulation's step, turnaround and hand-over times, the haptic
//! tick's lateness and render time), on the HdrHistogram design (Gil
//! Tene's High Dynamic Range histogram, the `hdrhistogram` crate): values
//! from 1 ns to an hour at three significant digits (0.1% relative
//! error), allocated once at creation, nothing per sample, so a
//! hard-real-time loop may record into it.

use hdrhistogram::Histogram;
use serde::Serialize;

/// The largest duration kept apart (ns): an hour. Longer ones are counted
/// as an hour (the exact maximum is kept beside).
pub const HIGHEST_NS: u64 = 3_600_000_000_000;
/// Significant digits of every recorded value.
const SIGNIFICANT_DIGITS: u8 = 3;

/// Percentiles of a [`LoopHistogram`] (us); the `*_us` records of the
/// run summaries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PercentilesUs {
    /// Samples.
    pub count: u64,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// 99.9th percentile.
    pub p999: f64,
    /// The largest, exact.
    pub max: f64,
}

/// Durations (ns) counted in a preallocated HDR histogram, with the exact
/// largest value.
#[derive(Clone, Debug)]
pub struct LoopHistogram {
    hist: Histogram<u64>,
    max_ns: i64,
}

impl Default for LoopHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl LoopHistogram {
    /// Empty: the one allocation (about 250 KB of counts).
    pub fn new() -> Self {
        let hist = Histogram::new_with_bounds(1, HIGHEST_NS, SIGNIFICANT_DIGITS)
            .expect("constant bounds are valid");
        Self {
            hist,
            max_ns: i64::MIN,
        }
    }

    /// Counts a duration (ns); a negative one (a tick early) counts as 0,
    /// one above [`HIGHEST_NS`] as that. Never allocates.
    pub fn record_ns(&mut self, ns: i64) {
        self.hist.saturating_record(ns.max(0) as u64);
        self.max_ns = self.max_ns.max(ns);
    }

    /// Counts an elapsed time (ns, from a monotonic difference).
    pub fn record_elapsed_ns(&mut self, ns: u64) {
        self.record_ns(i64::try_from(ns).unwrap_or(i64::MAX));
    }

    /// Durations counted.
    pub fn count(&self) -> u64 {
        self.hist.len()
    }

    /// The `q` quantile (0..=1, ns): the highest value equivalent to the
    /// one at that rank (within 0.1%), never above the largest; 0 when
    /// empty; the exact largest for q >= 1.
    pub fn quantile_ns(&self, q: f64) -> f64 {
        if self.count() == 0 {
            return 0.0;
        }
        if q >= 1.0 {
            return self.max_ns();
        }
        (self.hist.value_at_quantile(q.max(0.0)) as f64).min(self.max_ns())
    }

    /// [`LoopHistogram::quantile_ns`] in microseconds.
    pub fn quantile_us(&self, q: f64) -> f64 {
        self.quantile_ns(q) * 1e-3
    }

    /// The largest duration (ns, exact; negative if every one was early);
    /// 0 when empty.
    pub fn max_ns(&self) -> f64 {
        if self.count() == 0 {
            0.0
        } else {
            self.max_ns as f64
        }
    }

    /// The largest duration (us).
    pub fn max_us(&self) -> f64 {
        self.max_ns() * 1e-3
    }

    /// p50, p90, p99, p99.9 and the maximum in microseconds.
    pub fn percentiles_us(&self) -> PercentilesUs {
        PercentilesUs {
            count: self.count(),
            p50: self.quantile_us(0.5),
            p90: self.quantile_us(0.9),
            p99: self.quantile_us(0.99),
            p999: self.quantile_us(0.999),
            max: self.max_us(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(got: f64, want: f64) -> bool {
        (got - want).abs() <= want * 1e-3
    }

    #[test]
    fn percentiles_of_a_known_distribution() {
        let mut h = LoopHistogram::new();
        // 1..=10000 us in ns, once each.
        for k in 1..=10_000i64 {
            h.record_ns(k * 1000);
        }
        let p = h.percentiles_us();
        assert_eq!(p.count, 10_000);
        assert!(close(p.p50, 5000.0), "{p:?}");
        assert!(close(p.p90, 9000.0), "{p:?}");
        assert!(close(p.p99, 9900.0), "{p:?}");
        assert!(close(p.p999, 9990.0), "{p:?}");
        assert_eq!(p.max, 10_000.0);
    }

    #[test]
    fn one_outlier_shows_in_the_max_and_the_tail_only() {
        let mut h = LoopHistogram::new();
        for _ in 0..10_000 {
            h.record_ns(500_000);
        }
        h.record_ns(40_000_000);
        let p = h.percentiles_us();
        assert!(close(p.p50, 500.0), "{p:?}");
        assert!(close(p.p999, 500.0), "{p:?}");
        assert_eq!(p.max, 40_000.0);
        assert_eq!(
            LoopHistogram::new().percentiles_us(),
            PercentilesUs::default()
        );
    }

    #[test]
    fn early_ticks_count_as_zero_and_huge_ones_saturate() {
        let mut h = LoopHistogram::new();
        h.record_ns(-5_000);
        assert_eq!(h.count(), 1);
        assert_eq!(h.quantile_ns(0.5), -5_000.0, "never above the exact max");
        assert_eq!(h.max_us(), -5.0);
        h.record_ns(i64::MAX);
        assert_eq!(h.count(), 2);
        assert_eq!(h.max_ns(), i64::MAX as f64);
        assert!(h.quantile_ns(0.99) >= HIGHEST_NS as f64 * 0.999);
    }

    #[test]
    fn sub_microsecond_resolution_below_a_millisecond() {
        let mut h = LoopHistogram::new();
        for us in 0..1000i64 {
            h.record_ns(us * 1000 + 500);
        }
        assert!(
            (h.quantile_us(0.5) - 499.5).abs() <= 0.5,
            "{}",
            h.quantile_us(0.5)
        );
        assert!(
            (h.quantile_us(0.99) - 989.5).abs() <= 1.0,
            "{}",
            h.quantile_us(0.99)
        );
        assert!((h.max_us() - 999.5).abs() < 1e-9);
    }
}
