//! `--connect` and `--zenoh-config`: joining a session on another host
//! through `sim-server bridge` instead of shared memory.

use anyhow::Result;
use haptic_daemon::transport::Transport;
use shared::SessionName;
use shared::remote::{Link, RemoteConfig};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

/// How long to wait for the bridge's first answer at start.
const BRIDGE_WAIT: Duration = Duration::from_secs(5);

/// The remote flags.
#[derive(clap::Args)]
pub struct RemoteArgs {
    /// Join the session through zenoh at this endpoint (a `sim-server
    /// bridge` or a zenoh router, e.g. tcp/10.0.0.5:7447), touching no
    /// shared memory; repeatable.
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// A zenoh configuration file (JSON5: TLS, mutual authentication;
    /// docs/guide/remote.md); implies a remote session.
    #[arg(long, value_name = "FILE")]
    zenoh_config: Option<PathBuf>,
    /// The bridge's token (default: bridge.token in this user's private
    /// directory, where a bridge on this host writes it; on another host,
    /// a copy of the bridge's; docs/guide/security.md).
    #[arg(long, value_name = "FILE")]
    token_file: Option<PathBuf>,
}

impl RemoteArgs {
    /// Shared memory, or a link that a bridge answered within 5 s.
    pub fn transport(&self, session: &SessionName) -> Result<Transport> {
        let Some(cfg) = RemoteConfig::client(
            &self.connect,
            self.zenoh_config.as_deref(),
            self.token_file.as_deref(),
        )?
        else {
            return Ok(Transport::Shm);
        };
        let link = Link::join(&cfg, session, BRIDGE_WAIT)?;
        eprintln!("haptic-daemon: {}", link.summary());
        Ok(Transport::Remote(Arc::new(link)))
    }
}
