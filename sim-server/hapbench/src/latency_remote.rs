//! `hapbench latency --bridge`: the same measurements with the daemon on
//! the far side of `sim-server bridge` (zenoh over loopback TCP), beside a
//! bare zenoh baseline measured in the same run (a child process puts a
//! stamped sample every millisecond, this process receives it).
//!
//! Force samples are observed by a zenoh client of the bridge (as the
//! daemon receives them), stamped in zenoh's delivery callback. Everything
//! runs on one host, so stamps compare directly; the daemon still maps its
//! pose stamps by its clock estimate (Cristian's algorithm against the
//! bridge), whose value here is its error (the true offset is zero): the
//! daemon reports it in its summary and the pose figures are corrected.

use anyhow::{Context, Result};
use shared::protocol::ForceMsg;
use shared::remote::{Auth, RemoteConfig, codec, token};
use shared::{SessionName, monotonic_ns, services};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::Wait;

/// The bare baseline's key.
const PROBE_KEY: &str = "hapbench/probe";

/// A loopback endpoint on a port free now.
pub fn free_endpoint() -> Result<String> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port();
    Ok(format!("tcp/127.0.0.1:{port}"))
}

/// Force messages received on a zenoh key, with their receipt time.
pub struct Observer {
    got: Arc<Mutex<Vec<(u64, ForceMsg)>>>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    _session: zenoh::Session,
}

impl Observer {
    /// Connects to `endpoint` (with `auth`: a bridge wants its token, the
    /// baseline's probe none) and subscribes to `key`.
    pub fn connect(endpoint: &str, key: &str, auth: Auth) -> Result<Self> {
        let session = RemoteConfig {
            auth,
            ..RemoteConfig::connect_to(endpoint)
        }
        .open()?;
        let got = Arc::new(Mutex::new(Vec::new()));
        let sink = got.clone();
        let k = key.to_string();
        let subscriber = session
            .declare_subscriber(key.to_string())
            .callback(move |s| {
                let now = monotonic_ns();
                if let Ok(m) = codec::decode::<ForceMsg>(&k, &s.payload().to_bytes())
                    && let Ok(mut v) = sink.lock()
                {
                    v.push((now, m));
                }
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("subscribe {key}: {e}"))?;
        Ok(Self {
            got,
            _subscriber: subscriber,
            _session: session,
        })
    }

    /// What arrived since the last call.
    pub fn drain(&self) -> Vec<(u64, ForceMsg)> {
        self.got
            .lock()
            .map(|mut v| std::mem::take(&mut *v))
            .unwrap_or_default()
    }
}

/// `sim-server bridge` for a session on a free loopback port, and a zenoh
/// client of it observing the force samples as a remote daemon gets them.
pub struct Bridged {
    bridge: std::process::Child,
    /// Where the bridge listens.
    pub endpoint: String,
    /// The force samples, with their receipt times.
    pub observer: Observer,
}

impl Bridged {
    /// Starts the bridge (`sim_server`'s) for `run_s` seconds.
    pub fn start(session: &SessionName, run_s: f64, sim_server: &std::path::Path) -> Result<Self> {
        let endpoint = free_endpoint()?;
        let bridge = crate::latency::spawn(
            &[
                "bridge",
                "--session",
                session.as_str(),
                "--listen",
                &endpoint,
                "--duration-s",
                &run_s.to_string(),
            ],
            sim_server.to_path_buf(),
        )?;
        std::thread::sleep(Duration::from_millis(300));
        // The bridge's token, where the bridge on this host wrote it.
        let token = token::load(&token::client_token_path())?;
        let observer = Observer::connect(
            &endpoint,
            &session.service(services::stream::FORCE),
            Auth::Present(token),
        )?;
        Ok(Self {
            bridge,
            endpoint,
            observer,
        })
    }

    /// SIGTERM, then waits.
    pub fn stop(mut self) {
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(self.bridge.id() as libc::pid_t, libc::SIGTERM) };
        let _ = self.bridge.wait();
    }
}

/// The baseline's publisher (child process): listens on `endpoint` and puts
/// a stamped sample every millisecond for `duration_s`.
pub fn probe(endpoint: &str, duration_s: f64) -> Result<()> {
    let session = RemoteConfig::listen_on(endpoint).open()?;
    let publisher = session
        .declare_publisher(PROBE_KEY)
        .priority(zenoh::qos::Priority::RealTime)
        .congestion_control(zenoh::qos::CongestionControl::Drop)
        .express(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("declare {PROBE_KEY}: {e}"))?;
    crate::latency_probe::every_ms(duration_s, |msg| {
        let _ = publisher.put(codec::encode(&msg)).wait();
    });
    Ok(())
}

/// Bare zenoh one-way latencies (us) over loopback TCP between two
/// processes, for `duration_s`.
pub fn bare(duration_s: f64) -> Result<Vec<f64>> {
    let endpoint = free_endpoint()?;
    let mut child = std::process::Command::new(std::env::current_exe()?)
        .args([
            "probe",
            "--session",
            "unused",
            "--duration-s",
            &(duration_s + 0.5).to_string(),
            "--zenoh",
            &endpoint,
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .context("cannot start the zenoh probe")?;
    // The child listens once started: retry the connection briefly.
    std::thread::sleep(Duration::from_millis(300));
    let observer = Observer::connect(&endpoint, PROBE_KEY, Auth::None)?;
    let mut out = Vec::new();
    let end = monotonic_ns() + ((duration_s + 0.5) * 1e9) as u64;
    while monotonic_ns() < end {
        std::thread::sleep(Duration::from_millis(20));
        for (now, m) in observer.drain() {
            out.push((now as i128 - m.t_ns as i128) as f64 * 1e-3);
        }
    }
    let _ = child.wait();
    // The first messages wait for the subscription to reach the publisher.
    let skip = out.len().min(100);
    Ok(out.split_off(skip))
}
