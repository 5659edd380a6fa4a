//! A session's streams on zenoh, for peers on other hosts.
//!
//! Shared memory ends at the host; `sim-server bridge` carries a session's
//! iceoryx2 streams to and from zenoh (eclipse-zenoh 1.x), and the viewer
//! and the haptic daemon can join a session through zenoh alone
//! (`--connect ENDPOINT`). The keys are the iceoryx2 service names
//! (`hapsim/<session>/<stream>`), the payloads the same `#[repr(C)]`
//! messages behind a versioned preamble ([`codec`]), and every stamp is
//! moved between the hosts' clocks on the client side ([`clock`]).
//! Besides the streams a bridge answers two queries and declares one
//! liveliness token:
//!
//! - `hapsim/<session>/clock`: its `CLOCK_MONOTONIC` now (8 bytes, LE);
//! - `hapsim/<session>/<stream>` for the once-published streams (`scene`,
//!   `rest`, `surface0`, `topology`): the newest message, so a client that
//!   joins late gets what iceoryx2's history gives a local one;
//! - the token `hapsim/<session>/alive/sim` while a simulation publishes
//!   force samples in the session (a client sees it go when the bridge's
//!   process dies, or after zenoh's lease when the link is cut).
//!
//! A client declares `hapsim/<session>/alive/daemon` while it publishes
//! poses, so the bridge withdraws its local pose publisher when it goes.
//!
//! ```no_run
//! use shared::remote::{Inbox, Link, RemoteConfig};
//! use shared::SessionName;
//! use std::time::Duration;
//! let session = SessionName::new("station-2").unwrap();
//! let config = RemoteConfig::connect_to("tcp/10.0.0.5:7447");
//! let link = Link::join(&config, &session, Duration::from_secs(5)).unwrap();
//! let mut forces = Inbox::<shared::protocol::ForceMsg>::subscribe(&link, "force", 4).unwrap();
//! while let Some(sample) = forces.pop() {
//!     println!("{:?}", sample.tools[0].force_n); // stamps already in this host's clock
//! }
//! ```

pub mod clock;
pub mod codec;
mod inbox;
mod link;
pub mod token;

pub use clock::{ClockMap, Probe, Stamped};
pub use codec::DecodeError;
pub use inbox::{Inbox, InboxCounts, SliceInbox};
pub use link::{Link, RemotePublisher};

use std::path::PathBuf;
use thiserror::Error;

/// A liveliness token: held, it says "here"; dropped (or its host's link
/// lost), peers see it go.
pub type Token = zenoh::liveliness::LivelinessToken;

/// The bridge's default endpoint: loopback only (listening elsewhere is
/// the user's explicit choice).
pub const DEFAULT_LISTEN: &str = "tcp/127.0.0.1:7447";

/// The largest message a peer may send (64 MiB: a mesh frame of a million
/// vertices is 12 MB).
const MAX_MESSAGE_BYTES: &str = "67108864";

/// Key of the clock query.
pub const CLOCK: &str = "clock";
/// Key of the token a bridge holds while a simulation publishes.
pub const ALIVE_SIM: &str = "alive/sim";
/// Key of the token a remote daemon holds while it publishes poses.
pub const ALIVE_DAEMON: &str = "alive/daemon";

/// Where a zenoh session listens and connects, and an optional zenoh
/// configuration file (JSON5) for everything else: TLS certificates,
/// mutual authentication, routers (`docs/guide/remote.md` shows how).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RemoteConfig {
    /// Endpoints to listen on (`tcp/127.0.0.1:7447`, `tls/0.0.0.0:7447`).
    pub listen: Vec<String>,
    /// Endpoints to connect to (a bridge or a zenoh router).
    pub connect: Vec<String>,
    /// A zenoh configuration file; `listen` and `connect` given here
    /// override its endpoints.
    pub config_file: Option<PathBuf>,
    /// Who must know the bridge's token ([`token`]).
    pub auth: Auth,
}

/// A link's authentication with the bridge's token ([`token`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Auth {
    /// None: zenoh links of one program to itself (tests, benchmarks), or a
    /// zenoh configuration file that sets its own.
    #[default]
    None,
    /// A bridge: every client must prove it knows this token.
    Serve(token::Token),
    /// A client: prove to the bridge that it knows this token.
    Present(token::Token),
}

impl RemoteConfig {
    /// A client of the bridge or router at `endpoint`.
    pub fn connect_to(endpoint: &str) -> Self {
        Self {
            connect: vec![endpoint.to_string()],
            ..Self::default()
        }
    }

    /// A client's configuration from its `--connect` endpoints,
    /// `--zenoh-config` file and `--token-file` (default: this user's,
    /// [`token::client_token_path`]): None when neither endpoints nor a
    /// file are given (shared memory).
    pub fn client(
        connect: &[String],
        config_file: Option<&std::path::Path>,
        token_file: Option<&std::path::Path>,
    ) -> Result<Option<Self>, token::TokenError> {
        if connect.is_empty() && config_file.is_none() {
            return Ok(None);
        }
        let path = token_file.map_or_else(token::client_token_path, std::path::Path::to_path_buf);
        Ok(Some(Self {
            listen: Vec::new(),
            connect: connect.to_vec(),
            config_file: config_file.map(std::path::Path::to_path_buf),
            auth: Auth::Present(token::load(&path)?),
        }))
    }

    /// A server listening at `endpoint`.
    pub fn listen_on(endpoint: &str) -> Self {
        Self {
            listen: vec![endpoint.to_string()],
            ..Self::default()
        }
    }

    /// What this configuration is for, for messages (`tcp/... (file x)`).
    pub fn describe(&self) -> String {
        let mut parts: Vec<String> = self.listen.iter().map(|e| format!("listen {e}")).collect();
        parts.extend(self.connect.iter().map(|e| format!("connect {e}")));
        if let Some(f) = &self.config_file {
            parts.push(format!("config {}", f.display()));
        }
        parts.join(", ")
    }

    /// The zenoh configuration: a peer that listens only where told (no
    /// default `tcp/[::]:0`), does no multicast scouting (it would answer
    /// on the LAN), takes no message over 64 MiB (zenoh's default is 1 GiB,
    /// a peer could make it allocate that) and connects where told. A
    /// configuration file is taken as written (its own listen, scouting and
    /// size settings: `docs/guide/remote.md` shows them).
    pub fn zenoh_config(&self) -> Result<zenoh::Config, RemoteError> {
        let mut config = match &self.config_file {
            Some(path) => zenoh::Config::from_file(path).map_err(|e| RemoteError::ConfigFile {
                file: path.display().to_string(),
                reason: e.to_string(),
            })?,
            None => {
                let mut c = zenoh::Config::default();
                insert(&mut c, "mode", "\"peer\"")?;
                insert(&mut c, "scouting/multicast/enabled", "false")?;
                insert(&mut c, "listen/endpoints", "[]")?;
                insert(
                    &mut c,
                    "transport/link/rx/max_message_size",
                    MAX_MESSAGE_BYTES,
                )?;
                c
            }
        };
        let list = |v: &[String]| {
            let quoted: Vec<String> = v.iter().map(|e| format!("{e:?}")).collect();
            format!("[{}]", quoted.join(","))
        };
        if !self.listen.is_empty() {
            insert(&mut config, "listen/endpoints", &list(&self.listen))?;
        }
        if !self.connect.is_empty() {
            insert(&mut config, "connect/endpoints", &list(&self.connect))?;
        }
        // After the file: the token is not the file's to drop.
        match &self.auth {
            Auth::None => {}
            Auth::Serve(t) => {
                let value = format!(
                    "{{user:{:?},password:{:?},dictionary_file:{:?}}}",
                    t.user,
                    t.secret,
                    t.path.display().to_string()
                );
                insert_secret(&mut config, "transport/auth/usrpwd", &value)?;
            }
            Auth::Present(t) => {
                let value = format!("{{user:{:?},password:{:?}}}", t.user, t.secret);
                insert_secret(&mut config, "transport/auth/usrpwd", &value)?;
            }
        }
        Ok(config)
    }

    /// Opens a zenoh session with this configuration.
    pub fn open(&self) -> Result<zenoh::Session, RemoteError> {
        use zenoh::Wait;
        let config = self.zenoh_config()?;
        zenoh::open(config).wait().map_err(|e| RemoteError::Open {
            what: self.describe(),
            reason: e.to_string(),
        })
    }
}

/// [`insert`] of a value holding a secret: a refusal does not print it.
fn insert_secret(c: &mut zenoh::Config, key: &str, value: &str) -> Result<(), RemoteError> {
    c.insert_json5(key, value)
        .map_err(|e| RemoteError::Setting {
            key: key.to_string(),
            value: "(the bridge token)".to_string(),
            reason: e.to_string(),
        })
}

fn insert(c: &mut zenoh::Config, key: &str, value: &str) -> Result<(), RemoteError> {
    c.insert_json5(key, value)
        .map_err(|e| RemoteError::Setting {
            key: key.to_string(),
            value: value.to_string(),
            reason: e.to_string(),
        })
}

/// Why a zenoh link could not be used.
#[derive(Debug, Error)]
pub enum RemoteError {
    /// The configuration file could not be read.
    #[error("zenoh configuration {file}: {reason}")]
    ConfigFile {
        /// The file.
        file: String,
        /// zenoh's message.
        reason: String,
    },
    /// An endpoint or setting zenoh refused (`tcp/host:port`, `tls/...`).
    #[error(
        "zenoh setting {key} = {value}: {reason} (endpoints look like tcp/127.0.0.1:7447 or tls/host:7447)"
    )]
    Setting {
        /// The key.
        key: String,
        /// The value.
        value: String,
        /// zenoh's message.
        reason: String,
    },
    /// The session could not be opened (an endpoint busy or unreachable).
    #[error("cannot open a zenoh session ({what}): {reason}")]
    Open {
        /// The endpoints.
        what: String,
        /// zenoh's message.
        reason: String,
    },
    /// A publisher, subscriber, query or token could not be declared.
    #[error("zenoh {key}: {reason}")]
    Declare {
        /// The key.
        key: String,
        /// zenoh's message.
        reason: String,
    },
    /// No bridge answered for the session.
    #[error(
        "no bridge answers for session {session} ({what}) within {waited_ms} ms: is `sim-server bridge --session {session}` running and reachable, and is this client's --token-file a copy of its token (docs/guide/security.md)?"
    )]
    NoBridge {
        /// The session.
        session: String,
        /// The endpoints.
        what: String,
        /// How long it waited.
        waited_ms: u64,
    },
}

impl RemoteError {
    /// zenoh refused to declare something on `key` (a publisher,
    /// subscriber, queryable or token).
    pub fn declare(key: &str, e: impl std::fmt::Display) -> Self {
        Self::Declare {
            key: key.to_string(),
            reason: e.to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_configuration_listens_only_where_told_and_does_not_scout() {
        let c = RemoteConfig::listen_on("tcp/127.0.0.1:7999")
            .zenoh_config()
            .unwrap();
        assert_eq!(
            c.get_json("listen/endpoints").unwrap(),
            r#"["tcp/127.0.0.1:7999"]"#
        );
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
        let c = RemoteConfig::connect_to("tcp/127.0.0.1:7999")
            .zenoh_config()
            .unwrap();
        assert_eq!(c.get_json("listen/endpoints").unwrap(), "[]");
        assert_eq!(
            c.get_json("connect/endpoints").unwrap(),
            r#"["tcp/127.0.0.1:7999"]"#
        );
        let e = RemoteConfig::listen_on("nonsense")
            .zenoh_config()
            .unwrap_err();
        assert!(e.to_string().contains("listen/endpoints"), "{e}");
        let e = RemoteConfig {
            config_file: Some("/nonexistent/z.json5".into()),
            ..RemoteConfig::default()
        }
        .zenoh_config()
        .unwrap_err();
        assert!(e.to_string().contains("/nonexistent/z.json5"), "{e}");
    }
}
