//! A client's link to a session through zenoh: the clock mapping kept up to
//! date on a thread of its own, publishers that stamp in the simulation
//! host's clock, and whether a simulation is there.

use super::clock::{ClockMap, Probe, Stamped, read_answer};
use super::{ALIVE_DAEMON, ALIVE_SIM, CLOCK, RemoteConfig, RemoteError, codec};
use crate::SessionName;
use bytemuck::Pod;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Weak};
use std::time::Duration;
use zenoh::Wait;
use zenoh::sample::SampleKind;

/// Clock probes kept: the offset comes from the shortest of the last ones.
const PROBE_WINDOW: usize = 16;
/// How often the clock is probed once it is known.
const PROBE_EVERY: Duration = Duration::from_millis(500);
/// How long one probe may take.
const PROBE_TIMEOUT: Duration = Duration::from_millis(500);
/// Probes whose estimate is taken as it is; after them the offset slews.
const DIRECT_PROBES: usize = 4;
/// The most the offset moves per probe once slewing (ns): a better round
/// trip does not make consecutive stamps jump (a sample's spacing, 1 ms at
/// 1 kHz, would be off by the jump), and 50 us per 500 ms (100 ppm) follows
/// the drift of hosts without NTP.
const SLEW_NS: i64 = 50_000;

/// A client's link to one session.
pub struct Link {
    session: zenoh::Session,
    name: SessionName,
    clock: Arc<ClockMap>,
    synced: Arc<AtomicBool>,
    sim_alive: Arc<AtomicBool>,
    what: String,
    _alive_watch: zenoh::pubsub::Subscriber<()>,
}

impl Link {
    /// Opens a zenoh session with `config` and joins `name`: the clock is
    /// probed at once and then every 500 ms on a thread (messages carry
    /// stamps only once it is known: see [`Link::clock_known`]).
    pub fn connect(config: &RemoteConfig, name: &SessionName) -> Result<Self, RemoteError> {
        let session = config.open()?;
        let sim_alive = Arc::new(AtomicBool::new(false));
        let alive = sim_alive.clone();
        let key = name.service(ALIVE_SIM);
        let alive_watch = session
            .liveliness()
            .declare_subscriber(&key)
            .history(true)
            .callback(move |s| alive.store(s.kind() == SampleKind::Put, Ordering::Relaxed))
            .wait()
            .map_err(|e| RemoteError::declare(&key, e))?;
        let link = Self {
            session,
            name: name.clone(),
            clock: Arc::new(ClockMap::identity()),
            synced: Arc::new(AtomicBool::new(false)),
            sim_alive,
            what: config.describe(),
            _alive_watch: alive_watch,
        };
        link.spawn_clock_sync()?;
        Ok(link)
    }

    fn spawn_clock_sync(&self) -> Result<(), RemoteError> {
        let session = self.session.clone();
        let key = self.name.service(CLOCK);
        let clock: Weak<ClockMap> = Arc::downgrade(&self.clock);
        let synced = self.synced.clone();
        std::thread::Builder::new()
            .name("hapsim-clock".into())
            .spawn(move || {
                let mut window: Vec<Probe> = Vec::with_capacity(PROBE_WINDOW);
                let mut taken = 0usize;
                // Until the link is dropped (the clock with it).
                while let Some(map) = clock.upgrade() {
                    if let Some(p) = probe(&session, &key) {
                        if window.len() == PROBE_WINDOW {
                            window.remove(0);
                        }
                        window.push(p);
                        if let Some(best) = Probe::best(window.iter().copied()) {
                            let next = if taken < DIRECT_PROBES {
                                best
                            } else {
                                slew(map.offset_ns(), best)
                            };
                            map.set(next);
                            taken += 1;
                            synced.store(true, Ordering::Release);
                        }
                    }
                    drop(map);
                    let pause = if window.len() < 4 {
                        Duration::from_millis(20)
                    } else {
                        PROBE_EVERY
                    };
                    std::thread::sleep(pause);
                }
            })
            .map_err(|e| RemoteError::Declare {
                key: self.name.service(CLOCK),
                reason: format!("cannot start the clock thread: {e}"),
            })?;
        Ok(())
    }

    /// [`Link::connect`], then [`Link::wait_for_bridge`]: a link a bridge
    /// answered within `timeout`, or why not.
    pub fn join(
        config: &RemoteConfig,
        name: &SessionName,
        timeout: Duration,
    ) -> Result<Self, RemoteError> {
        let link = Self::connect(config, name)?;
        link.wait_for_bridge(timeout)?;
        Ok(link)
    }

    /// One line for the user: the session, the endpoints and the clock.
    pub fn summary(&self) -> String {
        format!(
            "session {} through zenoh ({}); clock offset {:+.3} ms +- {:.3} ms",
            self.name.as_str(),
            self.what,
            self.clock.offset_ns() as f64 * 1e-6,
            self.clock.rtt_ns() as f64 * 0.5e-6
        )
    }

    /// Waits up to `timeout` for the clock (the bridge's first answer).
    pub fn wait_for_bridge(&self, timeout: Duration) -> Result<(), RemoteError> {
        let start = std::time::Instant::now();
        while !self.clock_known() {
            if start.elapsed() >= timeout {
                return Err(RemoteError::NoBridge {
                    session: self.name.as_str().to_string(),
                    what: self.what.clone(),
                    waited_ms: timeout.as_millis() as u64,
                });
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        Ok(())
    }

    /// Whether a bridge has answered a clock probe.
    pub fn clock_known(&self) -> bool {
        self.synced.load(Ordering::Acquire)
    }

    /// The flag [`Link::clock_known`] reads, for the inboxes.
    pub(super) fn synced(&self) -> Arc<AtomicBool> {
        self.synced.clone()
    }

    /// The clock mapping (remote = the simulation host).
    pub fn clock(&self) -> &Arc<ClockMap> {
        &self.clock
    }

    /// Whether the bridge reports a simulation publishing (false as soon
    /// as the link to the bridge is lost).
    pub fn sim_alive(&self) -> bool {
        self.sim_alive.load(Ordering::Relaxed)
    }

    /// The session name.
    pub fn name(&self) -> &SessionName {
        &self.name
    }

    /// The zenoh session (for the bridge and the tests).
    pub fn zenoh(&self) -> &zenoh::Session {
        &self.session
    }

    /// The endpoints, for messages.
    pub fn describe(&self) -> &str {
        &self.what
    }

    /// A publisher on `stream`; its messages' stamps go out in the
    /// simulation host's clock.
    pub fn publisher(&self, stream: &str) -> Result<RemotePublisher, RemoteError> {
        let key = self.name.service(stream);
        let publisher = self
            .session
            .declare_publisher(key.clone())
            .congestion_control(zenoh::qos::CongestionControl::Drop)
            .priority(zenoh::qos::Priority::RealTime)
            .express(true)
            .wait()
            .map_err(|e| RemoteError::declare(&key, e))?;
        Ok(RemotePublisher {
            publisher,
            clock: self.clock.clone(),
            synced: self.synced.clone(),
        })
    }

    /// Declares this client a pose publisher (a daemon) for as long as the
    /// token lives.
    pub fn declare_daemon(&self) -> Result<zenoh::liveliness::LivelinessToken, RemoteError> {
        let key = self.name.service(ALIVE_DAEMON);
        self.session
            .liveliness()
            .declare_token(&key)
            .wait()
            .map_err(|e| RemoteError::declare(&key, e))
    }
}

/// `best`, its offset moved from `current` by at most [`SLEW_NS`] (a step
/// of more than a millisecond is a real change, a restarted bridge or
/// host, and is taken at once).
fn slew(current: i64, best: Probe) -> Probe {
    let step = best.offset_ns.saturating_sub(current);
    if step.abs() > 1_000_000 {
        return best;
    }
    Probe {
        offset_ns: current + step.clamp(-SLEW_NS, SLEW_NS),
        rtt_ns: best.rtt_ns,
    }
}

/// One clock probe (None: no answer in time).
fn probe(session: &zenoh::Session, key: &str) -> Option<Probe> {
    let sent = crate::monotonic_ns();
    let replies = session.get(key).timeout(PROBE_TIMEOUT).wait().ok()?;
    let reply = replies.recv().ok()?;
    let received = crate::monotonic_ns();
    let remote = read_answer(&reply.result().ok()?.payload().to_bytes())?;
    Some(Probe::of(sent, remote, received))
}

/// Publishes messages of one stream, stamps moved to the simulation host's
/// clock (nothing is sent before the clock is known).
pub struct RemotePublisher {
    publisher: zenoh::pubsub::Publisher<'static>,
    clock: Arc<ClockMap>,
    synced: Arc<AtomicBool>,
}

impl RemotePublisher {
    /// Sends `msg`; false when not sent (clock unknown, or zenoh refused).
    pub fn put<T: Pod + Stamped>(&self, mut msg: T) -> bool {
        if !self.synced.load(Ordering::Acquire) {
            return false;
        }
        msg.map_stamps(|t| self.clock.to_remote(t));
        self.publisher.put(codec::encode(&msg)).wait().is_ok()
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Inbox, SliceInbox, clock};
    use super::*;
    use crate::protocol::{ForceMsg, PROTOCOL_VERSION, TopologyHeader};

    fn free_port() -> u16 {
        std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port()
    }

    fn wait_until(what: &str, f: impl Fn() -> bool) {
        let start = std::time::Instant::now();
        while !f() {
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "timed out: {what}"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    #[test]
    fn a_client_gets_the_clock_and_its_sessions_messages_and_no_other_sessions() {
        let endpoint = format!("tcp/127.0.0.1:{}", free_port());
        let name = SessionName::new(&format!("t{}-link", std::process::id())).unwrap();
        let other = SessionName::new(&format!("t{}-other", std::process::id())).unwrap();
        let server = RemoteConfig::listen_on(&endpoint).open().unwrap();
        let _clock = clock::serve(&server, &name).unwrap();
        let link = Link::connect(&RemoteConfig::connect_to(&endpoint), &name).unwrap();
        link.wait_for_bridge(Duration::from_secs(10)).unwrap();
        // Same host: the offset is within half the round trip of zero.
        let (offset, rtt) = (link.clock().offset_ns(), link.clock().rtt_ns());
        assert!(
            offset.unsigned_abs() <= rtt / 2 + 1000,
            "{offset} ns, rtt {rtt} ns"
        );
        // A peer that names another session: its clock query is unanswered.
        let stranger = Link::connect(&RemoteConfig::connect_to(&endpoint), &other).unwrap();
        let e = stranger
            .wait_for_bridge(Duration::from_millis(300))
            .unwrap_err();
        assert!(e.to_string().contains("no bridge answers"), "{e}");
        let mut forces = Inbox::<ForceMsg>::subscribe(&link, "force", 4).unwrap();
        let mut spy = Inbox::<ForceMsg>::subscribe(&stranger, "force", 4).unwrap();
        let publisher = server
            .declare_publisher(name.service("force"))
            .wait()
            .unwrap();
        let msg = ForceMsg {
            version: PROTOCOL_VERSION,
            seq: 3,
            t_ns: 5_000_000_000,
            ..ForceMsg::default()
        };
        // Until the subscription has propagated: then exactly what was sent,
        // its stamp in this host's clock.
        wait_until("a force sample", || {
            publisher.put(codec::encode(&msg)).wait().unwrap();
            forces.counts().received.load(Ordering::Relaxed) > 0
        });
        let got = forces.pop().unwrap();
        assert_eq!(got.seq, 3);
        assert_eq!(got.t_ns, link.clock().to_local(msg.t_ns));
        // Another version is refused and said.
        let mut bad = codec::encode(&msg);
        bad[4] = 99;
        publisher.put(bad).wait().unwrap();
        wait_until("a refusal", || {
            forces.counts().refused.load(Ordering::Relaxed) > 0
        });
        assert!(
            forces
                .counts()
                .first_refusal()
                .unwrap()
                .contains("version 99")
        );
        // The other session's client saw nothing of it.
        assert!(spy.pop().is_none());
        assert_eq!(spy.counts().received.load(Ordering::Relaxed), 0);
        // A slice stream: what comes later is taken, newest wins.
        let topo = SliceInbox::<TopologyHeader, [u32; 3]>::subscribe(&link, "topology").unwrap();
        let tp = server
            .declare_publisher(name.service("topology"))
            .wait()
            .unwrap();
        let h = TopologyHeader {
            version: PROTOCOL_VERSION,
            triangle_count: 1,
            topology_version: 2,
        };
        wait_until("a topology", || {
            tp.put(codec::encode_slice(&h, &[[0u32, 1, 2]]))
                .wait()
                .unwrap();
            topo.counts().received.load(Ordering::Relaxed) > 0
        });
        let (got, tris) = topo.take().unwrap();
        assert_eq!((got, tris), (h, vec![[0, 1, 2]]));
    }
}
