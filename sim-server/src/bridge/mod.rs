//! `sim-server bridge`: a session's shared-memory streams on zenoh, for
//! viewers, recorders and haptic daemons on other hosts.
//!
//! Two loops on two threads, so that a slow viewer link never holds up a
//! haptic one. The main loop carries the haptic streams: it waits for a
//! remote pose (zenoh delivers it to a channel; the wait ends as it
//! arrives, so a pose goes into shared memory and wakes the simulation one
//! thread hop after the network) or for the poll period, then relays force
//! samples and contact problems ([`inbound`], [`outbound::LiveOut`]). The
//! bulk loop, every millisecond, relays mesh frames, the scene streams and
//! telemetry ([`outbound::BulkOut`], [`telemetry`]). The bridge answers
//! clock probes and late joiners' queries and holds the session's
//! `alive/sim` token while a simulation publishes (see `shared::remote` for
//! the keys). It holds no state of the simulation's: kill it and restart it
//! at any time; the daemons on the far side see the token go and ramp their
//! force to zero.

mod inbound;
mod outbound;
mod telemetry;

use inbound::{InCounts, Inbound};
use outbound::{BulkOut, Kept, LiveOut, OutCounts};
use shared::SessionName;
use shared::remote::{ALIVE_DAEMON, ALIVE_SIM, RemoteConfig, RemoteError, clock};
use shared::services::{self, ServiceError};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use telemetry::{TelemetryCounts, TelemetryRelay};
use thiserror::Error;
use zenoh::Wait;

/// The bulk loop's period.
const BULK_PERIOD: Duration = Duration::from_millis(1);

/// How often peers are checked (the simulation's presence, remote interest
/// in contact problems, a remote daemon's token) and dead nodes reaped (on
/// a reaper thread; a pass also triggers a check).
const PEER_CHECK: Duration = Duration::from_millis(20);

/// What `sim-server bridge` runs.
#[derive(Clone, Debug)]
pub struct BridgeConfig {
    /// The session.
    pub session: SessionName,
    /// Where zenoh listens and connects.
    pub remote: RemoteConfig,
    /// How long the loop waits for a remote pose before it polls shared
    /// memory again: the most a force sample waits in the bridge.
    pub poll: Duration,
    /// Stop after this long (None: until SIGINT/SIGTERM).
    pub duration: Option<Duration>,
}

/// Why the bridge stopped.
#[derive(Debug, Error)]
pub enum BridgeError {
    /// A shared-memory service.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// The zenoh session.
    #[error(transparent)]
    Remote(#[from] RemoteError),
    /// The bulk thread could not start or panicked.
    #[error("the bridge's bulk thread {0}")]
    Thread(String),
}

/// What the bridge did.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct BridgeSummary {
    /// The session.
    pub session: String,
    /// Where it listened and connected.
    pub endpoints: String,
    /// Seconds it ran.
    pub duration_s: f64,
    /// Shared memory -> zenoh.
    pub outbound: OutCounts,
    /// zenoh -> shared memory (poses).
    pub inbound: InCounts,
    /// Telemetry both ways.
    pub telemetry: TelemetryCounts,
    /// Times a simulation appeared in the session.
    pub sim_arrivals: u64,
}

/// Answers late joiners' queries on the once-published streams.
fn serve_kept(
    z: &zenoh::Session,
    session: &SessionName,
    kept: &Kept,
) -> Result<Vec<zenoh::query::Queryable<()>>, BridgeError> {
    use services::stream::{REST, SCENE, SURFACE0, TOPOLOGY};
    [SCENE, REST, SURFACE0, TOPOLOGY]
        .into_iter()
        .map(|stream| {
            let key = session.service(stream);
            let kept = kept.clone();
            let k = key.clone();
            z.declare_queryable(key.clone())
                .callback(move |q| {
                    let bytes = kept.lock().ok().and_then(|m| m.get(&k).cloned());
                    if let Some(b) = bytes {
                        let _ = q.reply(q.key_expr().clone(), b).wait();
                    }
                })
                .wait()
                .map_err(|e| RemoteError::declare(&key, e).into())
        })
        .collect()
}

/// A subscriber to what other hosts put on `key` (the bridge's own puts
/// must not come back), delivered to a channel.
fn subscribe_remote(
    z: &zenoh::Session,
    key: &str,
) -> Result<
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    BridgeError,
> {
    z.declare_subscriber(key.to_string())
        .allowed_origin(zenoh::sample::Locality::Remote)
        .wait()
        .map_err(|e| RemoteError::declare(key, e).into())
}

/// Follows the remote daemons' liveliness tokens: true while at least one
/// is held (zenoh reports each token's arrival and departure).
fn watch_daemon(
    z: &zenoh::Session,
    session: &SessionName,
) -> Result<(Arc<AtomicBool>, zenoh::pubsub::Subscriber<()>), BridgeError> {
    let alive = Arc::new(AtomicBool::new(false));
    let flag = alive.clone();
    let holders = std::sync::atomic::AtomicI64::new(0);
    let key = session.service(ALIVE_DAEMON);
    let watch = z
        .liveliness()
        .declare_subscriber(&key)
        .history(true)
        .callback(move |s| {
            let step = if s.kind() == zenoh::sample::SampleKind::Put {
                1
            } else {
                -1
            };
            let now = (holders.fetch_add(step, Ordering::Relaxed) + step).max(0);
            flag.store(now > 0, Ordering::Relaxed)
        })
        .wait()
        .map_err(|e| RemoteError::declare(&key, e))?;
    Ok((alive, watch))
}

/// The bulk loop (its own thread and shared-memory node): until `stop`.
fn run_bulk(
    z: zenoh::Session,
    session: SessionName,
    kept: Kept,
    daemon_alive: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    ready: std::sync::mpsc::Sender<()>,
) -> Result<(OutCounts, TelemetryCounts), BridgeError> {
    let node = services::node("hapsim-bridge-bulk")?;
    let mut bulk = BulkOut::new(&node, &session, &z, kept)?;
    let mut telemetry = TelemetryRelay::new(&node, &session, &z, daemon_alive)?;
    // The scene streams' history is kept now: clients may join.
    bulk.pump();
    let _ = ready.send(());
    while !stop.load(Ordering::Relaxed) {
        bulk.pump();
        telemetry.pump();
        std::thread::sleep(BULK_PERIOD);
    }
    Ok((bulk.counts(), telemetry.counts()))
}

/// Runs the bridge until `stop` (or the configured duration).
pub fn run(cfg: &BridgeConfig, stop: &AtomicBool) -> Result<BridgeSummary, BridgeError> {
    let z = cfg.remote.open()?;
    let node = services::node("hapsim-bridge")?;
    let (daemon_alive, _daemon_watch) = watch_daemon(&z, &cfg.session)?;
    let mut live = LiveOut::new(&node, &cfg.session, &z)?;
    let mut inbound = Inbound::new(&node, &cfg.session, &z, daemon_alive.clone())?;
    let kept = Kept::default();
    let _kept = serve_kept(&z, &cfg.session, &kept)?;
    let bulk_stop = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready) = std::sync::mpsc::channel();
    let bulk = {
        let (z, session, kept, alive, stop) = (
            z.clone(),
            cfg.session.clone(),
            kept.clone(),
            daemon_alive.clone(),
            bulk_stop.clone(),
        );
        std::thread::Builder::new()
            .name("bridge-bulk".into())
            .spawn(move || run_bulk(z, session, kept, alive, stop, ready_tx))
            .map_err(|e| BridgeError::Thread(format!("could not start: {e}")))?
    };
    // Clients start joining when the clock answers: not before the bulk
    // thread holds the scene streams a joiner asks for (an error there
    // ends the wait and is returned below).
    let _ = ready.recv();
    let _clock = clock::serve(&z, &cfg.session)?;
    let alive_key = cfg.session.service(ALIVE_SIM);
    let mut sim_token: Option<zenoh::liveliness::LivelinessToken> = None;
    let mut summary = BridgeSummary {
        session: cfg.session.as_str().to_string(),
        endpoints: cfg.remote.describe(),
        ..BridgeSummary::default()
    };
    // Dead peers' resources removed off this loop, which carries the force
    // samples (the listing takes ~0.7 ms).
    let reaper = shared::reaper::Reaper::spawn("hapsim-bridge-reaper", PEER_CHECK)?;
    let mut reaped = reaper.passes();
    let start = Instant::now();
    let mut checked = start - PEER_CHECK;
    while !stop.load(Ordering::Relaxed)
        && cfg.duration.is_none_or(|d| start.elapsed() < d)
        && !bulk.is_finished()
    {
        inbound.wait_and_pump(cfg.poll);
        live.pump();
        // After each reaper pass (a dead simulation's publisher is gone
        // then), and at least every PEER_CHECK.
        if checked.elapsed() >= PEER_CHECK || reaper.passes() != reaped {
            checked = Instant::now();
            reaped = reaper.passes();
            match (live.sim_present(), sim_token.is_some()) {
                (true, false) => {
                    sim_token = z.liveliness().declare_token(alive_key.clone()).wait().ok();
                    summary.sim_arrivals += 1;
                }
                (false, true) => {
                    // A later simulation publishes its own scene.
                    sim_token = None;
                    if let Ok(mut k) = kept.lock() {
                        k.clear();
                    }
                }
                _ => {}
            }
            live.follow_local_contact_interest();
            inbound.follow_daemon();
        }
    }
    // Clients see the simulation go before the bulk thread is joined
    // (which may wait on a congested viewer link).
    drop(sim_token);
    bulk_stop.store(true, Ordering::Relaxed);
    let (bulk_counts, telemetry) = bulk
        .join()
        .map_err(|_| BridgeError::Thread("panicked".into()))??;
    summary.duration_s = start.elapsed().as_secs_f64();
    let l = live.counts();
    summary.outbound = OutCounts {
        force: l.force,
        force_gaps: l.force_gaps,
        local_contact: l.local_contact,
        ..bulk_counts
    };
    summary.inbound = inbound.counts().clone();
    summary.telemetry = telemetry;
    Ok(summary)
}
