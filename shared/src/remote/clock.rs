//! Clocks across hosts. Every `t_ns` of the protocol is the sender's
//! `CLOCK_MONOTONIC`, which on another host has another origin; the daemon's
//! staleness rules (sample age, samples that outrun wall time) and the
//! simulation's pose timeout compare those stamps with their own clock. So a
//! remote client maps every stamp it receives into its own clock and every
//! stamp it sends into the simulation host's, with the offset measured by
//! Cristian's algorithm (F. Cristian, "Probabilistic clock synchronization",
//! Distributed Computing 3, 1989): ask the bridge for its clock, take the
//! answer as read half-way through the round trip, and keep the round with
//! the shortest trip (its error is at most half that trip). The bridge only
//! relays bytes; the mapping is all on the client side.

use crate::monotonic_ns;
use crate::protocol::{
    ForceMsg, LocalContactMsg, MeshHeader, PoseMsg, RestHeader, SceneInfo, TelemetryBatch,
    TopologyHeader,
};
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};

/// The offset between the simulation host's clock and this one.
#[derive(Debug, Default)]
pub struct ClockMap {
    /// remote - local (ns).
    offset_ns: AtomicI64,
    /// The round trip of the probe the offset came from (ns; 0: same host).
    rtt_ns: AtomicU64,
}

/// One round of the algorithm.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Probe {
    /// remote - local (ns), the remote clock read at the trip's midpoint.
    pub offset_ns: i64,
    /// The round trip (ns): the offset is within half of it.
    pub rtt_ns: u64,
}

impl Probe {
    /// The probe of a round sent at `sent_ns`, answered with `remote_ns`,
    /// received at `received_ns` (local clock).
    pub fn of(sent_ns: u64, remote_ns: u64, received_ns: u64) -> Self {
        let rtt_ns = received_ns.saturating_sub(sent_ns);
        let mid = sent_ns as i128 + (rtt_ns / 2) as i128;
        Self {
            offset_ns: (remote_ns as i128 - mid).clamp(i64::MIN as i128, i64::MAX as i128) as i64,
            rtt_ns,
        }
    }

    /// The round with the shortest trip (None: no rounds).
    pub fn best(probes: impl IntoIterator<Item = Probe>) -> Option<Probe> {
        probes.into_iter().min_by_key(|p| p.rtt_ns)
    }
}

impl ClockMap {
    /// The identity (same host).
    pub fn identity() -> Self {
        Self::default()
    }

    /// Adopts `probe`.
    pub fn set(&self, probe: Probe) {
        self.offset_ns.store(probe.offset_ns, Ordering::Relaxed);
        self.rtt_ns.store(probe.rtt_ns, Ordering::Relaxed);
    }

    /// remote - local (ns).
    pub fn offset_ns(&self) -> i64 {
        self.offset_ns.load(Ordering::Relaxed)
    }

    /// The round trip of the probe in use (ns): the offset's uncertainty is half.
    pub fn rtt_ns(&self) -> u64 {
        self.rtt_ns.load(Ordering::Relaxed)
    }

    /// A remote stamp in this host's clock (0 stays 0: "none").
    pub fn to_local(&self, remote_ns: u64) -> u64 {
        shift(remote_ns, -(self.offset_ns() as i128))
    }

    /// A local stamp in the remote host's clock (0 stays 0).
    pub fn to_remote(&self, local_ns: u64) -> u64 {
        shift(local_ns, self.offset_ns() as i128)
    }
}

fn shift(t_ns: u64, by: i128) -> u64 {
    if t_ns == 0 {
        return 0;
    }
    (t_ns as i128 + by).clamp(1, u64::MAX as i128) as u64
}

/// A message whose `CLOCK_MONOTONIC` stamps can be moved to another clock.
/// Durations and simulated time (`sim_time_ns`, `step_period_ns`,
/// `lateness_ns`, `sample_age_ns`) are not stamps and stay.
pub trait Stamped {
    /// Applies `f` to every stamp.
    fn map_stamps(&mut self, f: impl Fn(u64) -> u64);
}

macro_rules! stamped_t_ns {
    ($($t:ty),*) => {$(
        impl Stamped for $t {
            fn map_stamps(&mut self, f: impl Fn(u64) -> u64) {
                self.t_ns = f(self.t_ns);
            }
        }
    )*};
}
stamped_t_ns!(ForceMsg, PoseMsg, MeshHeader, LocalContactMsg);

/// Messages without stamps (the scene, topology, rest).
macro_rules! unstamped {
    ($($t:ty),*) => {$(
        impl Stamped for $t {
            fn map_stamps(&mut self, _: impl Fn(u64) -> u64) {}
        }
    )*};
}
unstamped!(SceneInfo, TopologyHeader, RestHeader);

impl Stamped for TelemetryBatch {
    fn map_stamps(&mut self, f: impl Fn(u64) -> u64) {
        let n = (self.count as usize).min(self.ticks.len());
        for t in &mut self.ticks[..n] {
            t.t_ns = f(t.t_ns);
        }
    }
}

/// The answer a bridge gives to a clock probe: its clock now.
pub fn clock_answer() -> [u8; 8] {
    monotonic_ns().to_le_bytes()
}

/// Answers clock probes for `name` on `session` (what a bridge does) for
/// as long as the returned queryable lives.
pub fn serve(
    session: &zenoh::Session,
    name: &crate::SessionName,
) -> Result<zenoh::query::Queryable<()>, super::RemoteError> {
    use zenoh::Wait;
    let key = name.service(super::CLOCK);
    session
        .declare_queryable(key.clone())
        .callback(|query| {
            let _ = query
                .reply(query.key_expr().clone(), clock_answer().to_vec())
                .wait();
        })
        .wait()
        .map_err(|e| super::RemoteError::declare(&key, e))
}

/// The remote clock from a probe's answer (None: not eight bytes).
pub fn read_answer(bytes: &[u8]) -> Option<u64> {
    Some(u64::from_le_bytes(bytes.try_into().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shortest_round_wins_and_stamps_map_both_ways() {
        // Remote clock = local + 1 s; trips of 300 and 100 us, the first
        // answered late (asymmetric), the second at its midpoint.
        let s = 1_000_000_000u64;
        let slow = Probe::of(5_000_000, 5_000_000 + s + 290_000, 5_300_000);
        let fast = Probe::of(6_000_000, 6_000_000 + s + 50_000, 6_100_000);
        assert_eq!(fast.offset_ns, s as i64);
        assert_eq!(slow.offset_ns, s as i64 + 140_000);
        let best = Probe::best([slow, fast]).unwrap();
        assert_eq!(best, fast);
        let map = ClockMap::identity();
        assert_eq!(map.to_local(42), 42);
        map.set(best);
        assert_eq!(map.to_local(7 * s), 6 * s);
        assert_eq!(map.to_remote(6 * s), 7 * s);
        assert_eq!(map.to_local(0), 0, "no stamp stays no stamp");
        // A stamp older than the remote clock's origin here: clamped, not wrapped.
        assert_eq!(map.to_local(5), 1);
        let mut f = ForceMsg {
            t_ns: 3 * s,
            sim_time_ns: 11,
            ..ForceMsg::default()
        };
        f.map_stamps(|t| map.to_local(t));
        assert_eq!((f.t_ns, f.sim_time_ns), (2 * s, 11));
        let mut b = TelemetryBatch {
            count: 2,
            ..TelemetryBatch::default()
        };
        b.ticks[0].t_ns = 2 * s;
        b.ticks[1].t_ns = 3 * s;
        b.ticks[2].t_ns = 4 * s;
        b.map_stamps(|t| map.to_remote(t));
        assert_eq!(
            [b.ticks[0].t_ns, b.ticks[1].t_ns, b.ticks[2].t_ns],
            [3 * s, 4 * s, 4 * s],
            "only the batch's own ticks"
        );
        assert_eq!(read_answer(&clock_answer()).map(|t| t > 0), Some(true));
        assert_eq!(read_answer(b"short"), None);
    }
}
