//! The bridge's token: a client must know it to open a link.
//!
//! A bridge carries a session's forces and takes its tool poses, so a client
//! of the bridge has what a process of the session's user has. Shared
//! memory is private to that user ([`crate::ipc_root`]); the bridge keeps
//! it so by authenticating every client with zenoh's user/password
//! extension (a challenge: the client proves it knows the secret with an
//! HMAC of a nonce the bridge chose; the secret never crosses the link).
//!
//! The secret lives in a token file, `hapsim:<64 hex digits>`, mode 0600:
//! by default `bridge.token` in the user's private directory
//! (`/tmp/hapsim-<uid>/`), created with 32 random bytes from the kernel
//! (`/dev/urandom`) the first time a bridge starts and kept, so a station
//! given a copy keeps working across bridge restarts. Clients on the same
//! host and user find it there; another local user cannot read it; a
//! station on another host is given a copy (`--token-file`), as one would
//! an SSH key. A token file that others may read, or that is not a regular
//! file, is refused.
//!
//! What it does not do: authenticate the bridge to the client (zenoh's
//! extension is one-way; a local user who takes the port first could pose
//! as the bridge, without learning the token) nor encrypt the link: for
//! both, use TLS (`docs/guide/remote.md`).

use std::io::{Read, Write};
use std::os::unix::fs::{MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The user name in every token (zenoh's extension wants one).
pub const TOKEN_USER: &str = "hapsim";
/// The token file's name in the user's private directory.
pub const TOKEN_FILE: &str = "bridge.token";
/// Random bytes in a new token.
const TOKEN_BYTES: usize = 32;

/// Why a token file cannot be used.
#[derive(Debug, Error)]
pub enum TokenError {
    /// The private directory is unusable.
    #[error(transparent)]
    Root(#[from] crate::ipc_root::IpcRootError),
    /// No token file (a client looked for a bridge's).
    #[error(
        "no bridge token at {path}: start `sim-server bridge` on this host as this user (it writes one), or copy the bridge host's token file here and pass --token-file"
    )]
    Missing {
        /// Where it looked.
        path: PathBuf,
    },
    /// Reading or writing failed.
    #[error("bridge token {path}: {reason}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system's message.
        reason: String,
    },
    /// Others may read it, or it is no regular file.
    #[error(
        "bridge token {path}: {problem}; run chmod 600 {path} (a token others may read is no secret)"
    )]
    NotPrivate {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// Not `user:secret` on its first line.
    #[error("bridge token {path}: not a token (one line `hapsim:<hex>` is expected)")]
    Malformed {
        /// The file.
        path: PathBuf,
    },
}

/// A token: the user and the secret zenoh's extension checks.
#[derive(Clone, PartialEq, Eq)]
pub struct Token {
    /// The user name.
    pub user: String,
    /// The secret.
    pub secret: String,
    /// The file it came from (the bridge's dictionary).
    pub path: PathBuf,
}

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never the secret, in logs or messages.
        f.debug_struct("Token")
            .field("user", &self.user)
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

/// `bridge.token` in this user's private directory (made and checked: a
/// bridge writes its token there).
pub fn default_token_path() -> Result<PathBuf, TokenError> {
    Ok(crate::ipc_root::ipc_root()?.dir.join(TOKEN_FILE))
}

/// Where a client on this host looks for its bridge's token: `bridge.token`
/// in this user's private directory, which it does not make (a station
/// that has none is told so, and leaves nothing behind).
pub fn client_token_path() -> PathBuf {
    crate::ipc_root::root_dir().join(TOKEN_FILE)
}

/// A bridge's token: the one at `path`, or a new one written there (mode
/// 0600, never over an existing file).
pub fn load_or_create(path: &Path) -> Result<Token, TokenError> {
    match load(path) {
        Err(TokenError::Missing { .. }) => {}
        other => return other,
    }
    let io = |e: std::io::Error| TokenError::Io {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let mut bytes = [0u8; TOKEN_BYTES];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .map_err(io)?;
    let secret: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    let created = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path);
    match created {
        Ok(mut f) => f
            .write_all(format!("{TOKEN_USER}:{secret}\n").as_bytes())
            .map_err(io)?,
        // Another bridge wrote it meanwhile: use that one.
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => return load(path),
        Err(e) => return Err(io(e)),
    }
    load(path)
}

/// The token at `path`, refused unless it is a regular file only its owner
/// may read.
pub fn load(path: &Path) -> Result<Token, TokenError> {
    let md = match std::fs::symlink_metadata(path) {
        Ok(md) => md,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(TokenError::Missing {
                path: path.to_path_buf(),
            });
        }
        Err(e) => {
            return Err(TokenError::Io {
                path: path.to_path_buf(),
                reason: e.to_string(),
            });
        }
    };
    let not_private = |problem: String| TokenError::NotPrivate {
        path: path.to_path_buf(),
        problem,
    };
    if !md.is_file() {
        return Err(not_private("not a regular file".into()));
    }
    let mode = md.permissions().mode() & 0o777;
    if mode & 0o077 != 0 {
        return Err(not_private(format!("mode {mode:o}")));
    }
    let uid = crate::ipc_root::effective_uid();
    if md.uid() != uid {
        return Err(not_private(format!(
            "owned by uid {}, not by this user (uid {uid})",
            md.uid()
        )));
    }
    // A token is one short line; a huge file is not one.
    if md.len() > 4096 {
        return Err(TokenError::Malformed {
            path: path.to_path_buf(),
        });
    }
    let text = std::fs::read_to_string(path).map_err(|e| TokenError::Io {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let line = text.lines().map(str::trim).find(|l| !l.is_empty());
    let Some((user, secret)) = line.and_then(|l| l.split_once(':')) else {
        return Err(TokenError::Malformed {
            path: path.to_path_buf(),
        });
    };
    let (user, secret) = (user.trim(), secret.trim());
    let plain = |s: &str| {
        !s.is_empty()
            && s.chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
    };
    if !plain(user) || !plain(secret) {
        return Err(TokenError::Malformed {
            path: path.to_path_buf(),
        });
    }
    Ok(Token {
        user: user.to_string(),
        secret: secret.to_string(),
        path: path.to_path_buf(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hapsim-token-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir(&d).unwrap();
        d
    }

    #[test]
    fn a_new_token_is_private_random_and_kept() {
        let d = scratch("new");
        let p = d.join("t");
        let a = load_or_create(&p).unwrap();
        assert_eq!(a.user, TOKEN_USER);
        assert_eq!(a.secret.len(), 2 * TOKEN_BYTES);
        let mode = std::fs::metadata(&p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        assert_eq!(load_or_create(&p).unwrap(), a, "kept across restarts");
        let q = d.join("u");
        assert_ne!(load_or_create(&q).unwrap().secret, a.secret);
        assert!(!format!("{a:?}").contains(&a.secret), "the secret leaked");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_readable_missing_or_malformed_token_is_refused() {
        let d = scratch("bad");
        let p = d.join("t");
        let e = load(&p).unwrap_err();
        assert!(matches!(e, TokenError::Missing { .. }), "{e}");
        assert!(e.to_string().contains("--token-file"), "{e}");
        load_or_create(&p).unwrap();
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = load(&p).unwrap_err();
        assert!(
            e.to_string().contains("mode 644") && e.to_string().contains("chmod 600"),
            "{e}"
        );
        for text in ["", "nocolon\n", "hapsim:\n", "a b:c\n", "hapsim:\"x\"\n"] {
            std::fs::remove_file(&p).unwrap();
            std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .mode(0o600)
                .open(&p)
                .unwrap()
                .write_all(text.as_bytes())
                .unwrap();
            let e = load(&p).unwrap_err();
            assert!(matches!(e, TokenError::Malformed { .. }), "{text:?}: {e}");
        }
        let link = d.join("link");
        std::os::unix::fs::symlink(&p, &link).unwrap();
        assert!(matches!(load(&link), Err(TokenError::NotPrivate { .. })));
        std::fs::remove_dir_all(&d).unwrap();
    }
}
