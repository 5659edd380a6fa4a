//! Where a user's sessions live: iceoryx2's records and shared memory,
//! private to the user who runs them.
//!
//! iceoryx2's default configuration shares one root, `/tmp/iceoryx2` (its
//! node and service records), and one `iox2_` prefix in `/dev/shm` between
//! all users of a machine, and its global management segment (from which
//! every node takes its unique id) is created mode 0666. Another local user
//! could then corrupt that segment (every new node fails with
//! `UnableToGenerateUniqueNodeId`), or create `/tmp/iceoryx2` first and
//! delete the service records of running sessions. Every process of this
//! project instead uses a configuration of its own user:
//!
//! - root: [`ROOT_ENV`] if set, else `/tmp/hapsim-<uid>/`; created 0700 if
//!   missing, and refused unless it is a real directory (not a symlink)
//!   owned by this user that no one else may enter or write;
//! - prefix: `hapsim_<uid>_`, so `/dev/shm` names never meet another
//!   user's; a `/dev/shm` entry with this prefix owned by another user is
//!   refused (someone made it to be opened by us);
//! - the global management segment is made 0600 as soon as a node exists
//!   ([`make_segments_private`]): iceoryx2 0.10 sets 0666 on it by design.
//!
//! What remains (reported upstream): iceoryx2 creates that segment 0666 and
//! only then is it made private, so a process of another user that opens it
//! in that microsecond window, at the first start of this user's first
//! node, keeps a writable descriptor. The Python package
//! (`python/hapsim/ipc.py`) applies the same rules.

use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Environment variable naming the directory of a user's sessions instead
/// of `/tmp/hapsim-<uid>/` (every process of a session must see the same).
pub const ROOT_ENV: &str = "HAPSIM_IPC_DIR";

/// Where POSIX shared memory appears on Linux.
pub const SHM_DIR: &str = "/dev/shm";

/// Longest root path (bytes): iceoryx2 puts event sockets in it, named by
/// the prefix and a 39-digit id, and a Unix socket path holds 107 bytes.
pub const MAX_ROOT_BYTES: usize = 50;

/// Why the private root cannot be used.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum IpcRootError {
    /// The directory could not be created or inspected.
    #[error("{path}: {reason} (the directory of this user's sessions; set {ROOT_ENV} to another)")]
    Io {
        /// The directory.
        path: PathBuf,
        /// The system's message.
        reason: String,
    },
    /// Not a directory (a file, or a symlink someone may have planted).
    #[error(
        "{path} is not a directory but a {kind}: it holds this user's sessions; remove it, or set {ROOT_ENV} to another directory"
    )]
    NotDirectory {
        /// The path.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
    },
    /// Another user owns it.
    #[error(
        "{path} belongs to uid {owner}, not to this user (uid {uid}): another user may have made it to read or spoil this user's sessions; remove it as root, or set {ROOT_ENV} to a directory of your own"
    )]
    NotOwned {
        /// The path.
        path: PathBuf,
        /// Its owner.
        owner: u32,
        /// This process's effective uid.
        uid: u32,
    },
    /// Group or others may use it.
    #[error(
        "{path} has mode {mode:o}: other users may enter or change it; run chmod 700 {path} (sessions' records must be private)"
    )]
    NotPrivate {
        /// The path.
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
    },
    /// Too long for iceoryx2's socket names.
    #[error(
        "{path} is {len} bytes long; at most {MAX_ROOT_BYTES} (iceoryx2 names Unix sockets inside it): set {ROOT_ENV} to a shorter path"
    )]
    TooLong {
        /// The path.
        path: PathBuf,
        /// Its length.
        len: usize,
    },
    /// A shared memory object of this user's namespace made by another.
    #[error(
        "{path} belongs to uid {owner}, not to this user (uid {uid}), yet has this user's prefix: another user made it to be opened by this user's sessions; remove it as root"
    )]
    ForeignSegment {
        /// The object.
        path: PathBuf,
        /// Its owner.
        owner: u32,
        /// This process's effective uid.
        uid: u32,
    },
}

/// A user's root and prefix.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct IpcRoot {
    /// The directory of node and service records (ends with `/`).
    pub dir: PathBuf,
    /// The prefix of every shared memory object.
    pub prefix: String,
    /// The user they belong to.
    pub uid: u32,
}

/// This process's effective uid.
pub fn effective_uid() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

/// This user's root and prefix (see the module documentation), checked:
/// the directory is created 0700 when missing.
pub fn ipc_root() -> Result<IpcRoot, IpcRootError> {
    let uid = effective_uid();
    let root = root_at(&root_dir(), uid)?;
    check_segments(Path::new(SHM_DIR), &root.prefix, uid)?;
    Ok(root)
}

/// This user's directory ([`ROOT_ENV`], else `/tmp/hapsim-<uid>`), neither
/// made nor checked.
pub fn root_dir() -> PathBuf {
    match std::env::var_os(ROOT_ENV) {
        Some(d) if !d.is_empty() => PathBuf::from(d),
        _ => PathBuf::from(format!("/tmp/hapsim-{}", effective_uid())),
    }
}

/// The root at `dir` for `uid`: created 0700 when missing, then checked.
pub fn root_at(dir: &Path, uid: u32) -> Result<IpcRoot, IpcRootError> {
    let mut text = dir.as_os_str().to_string_lossy().to_string();
    if !text.ends_with('/') {
        text.push('/');
    }
    if text.len() > MAX_ROOT_BYTES {
        return Err(IpcRootError::TooLong {
            path: dir.to_path_buf(),
            len: text.len(),
        });
    }
    let io = |e: std::io::Error| IpcRootError::Io {
        path: dir.to_path_buf(),
        reason: e.to_string(),
    };
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(io(e)),
    }
    check_private_dir(dir, uid)?;
    Ok(IpcRoot {
        dir: PathBuf::from(text),
        prefix: format!("hapsim_{uid}_"),
        uid,
    })
}

/// Refuses `dir` unless it is a directory (not a symlink) owned by `uid`
/// with no permission for group or others.
pub fn check_private_dir(dir: &Path, uid: u32) -> Result<(), IpcRootError> {
    let md = std::fs::symlink_metadata(dir).map_err(|e| IpcRootError::Io {
        path: dir.to_path_buf(),
        reason: e.to_string(),
    })?;
    let ft = md.file_type();
    if !ft.is_dir() {
        let kind = if ft.is_symlink() {
            "symbolic link"
        } else {
            "file"
        };
        return Err(IpcRootError::NotDirectory {
            path: dir.to_path_buf(),
            kind,
        });
    }
    if md.uid() != uid {
        return Err(IpcRootError::NotOwned {
            path: dir.to_path_buf(),
            owner: md.uid(),
            uid,
        });
    }
    let mode = md.permissions().mode() & 0o777;
    if mode & 0o077 != 0 {
        return Err(IpcRootError::NotPrivate {
            path: dir.to_path_buf(),
            mode,
        });
    }
    Ok(())
}

/// Refuses any object in `shm_dir` named with `prefix` that `uid` does not
/// own. A missing `shm_dir` (not Linux) has none.
pub fn check_segments(shm_dir: &Path, prefix: &str, uid: u32) -> Result<(), IpcRootError> {
    match objects_with_prefix(shm_dir, prefix).find(|(_, md)| md.uid() != uid) {
        Some((path, md)) => Err(IpcRootError::ForeignSegment {
            path,
            owner: md.uid(),
            uid,
        }),
        None => Ok(()),
    }
}

/// The objects in `shm_dir` whose names start with `prefix`, with their
/// metadata (not followed through symlinks); none when `shm_dir` cannot be
/// read (not Linux), and one that vanished meanwhile (a session ending) is
/// skipped.
fn objects_with_prefix<'a>(
    shm_dir: &Path,
    prefix: &'a str,
) -> impl Iterator<Item = (PathBuf, std::fs::Metadata)> + 'a {
    std::fs::read_dir(shm_dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter(move |e| e.file_name().to_string_lossy().starts_with(prefix))
        .filter_map(|e| {
            let path = e.path();
            std::fs::symlink_metadata(&path).ok().map(|md| (path, md))
        })
}

/// Makes this user's objects in `shm_dir` named with `prefix` readable and
/// writable by their owner only (iceoryx2 leaves its global management
/// segment 0666); returns how many it changed. Best effort: an object that
/// vanished or cannot be changed is left as it is.
pub fn make_segments_private(shm_dir: &Path, prefix: &str, uid: u32) -> usize {
    let mut changed = 0;
    for (path, md) in objects_with_prefix(shm_dir, prefix) {
        let mode = md.permissions().mode() & 0o777;
        if md.uid() == uid && md.is_file() && mode & 0o077 != 0 {
            let private = std::fs::Permissions::from_mode(mode & 0o700);
            if std::fs::set_permissions(&path, private).is_ok() {
                changed += 1;
            }
        }
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hapsim-ipc-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_missing_root_is_made_private_and_an_open_one_is_refused() {
        let uid = effective_uid();
        let d = scratch("mk");
        let root = root_at(&d, uid).unwrap();
        assert!(root.dir.to_string_lossy().ends_with('/'));
        assert_eq!(root.prefix, format!("hapsim_{uid}_"));
        let mode = std::fs::metadata(&d).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o700);
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = root_at(&d, uid).unwrap_err();
        assert!(
            matches!(e, IpcRootError::NotPrivate { mode: 0o777, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("chmod 700"), "{e}");
        // Another owner (as seen by a check for another uid).
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o700)).unwrap();
        let e = root_at(&d, uid.wrapping_add(1)).unwrap_err();
        assert!(matches!(e, IpcRootError::NotOwned { .. }), "{e}");
        assert!(e.to_string().contains(&d.display().to_string()), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_symlink_a_file_and_a_long_path_are_refused() {
        let uid = effective_uid();
        let target = scratch("target");
        std::fs::create_dir(&target).unwrap();
        std::fs::set_permissions(&target, std::fs::Permissions::from_mode(0o700)).unwrap();
        let link = scratch("link");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let e = root_at(&link, uid).unwrap_err();
        assert!(
            matches!(
                e,
                IpcRootError::NotDirectory {
                    kind: "symbolic link",
                    ..
                }
            ),
            "{e}"
        );
        let file = scratch("file");
        std::fs::write(&file, b"x").unwrap();
        let e = root_at(&file, uid).unwrap_err();
        assert!(
            matches!(e, IpcRootError::NotDirectory { kind: "file", .. }),
            "{e}"
        );
        let long = PathBuf::from(format!("/tmp/{}", "x".repeat(60)));
        assert!(matches!(
            root_at(&long, uid),
            Err(IpcRootError::TooLong { .. })
        ));
        for p in [&link, &file] {
            std::fs::remove_file(p).unwrap();
        }
        std::fs::remove_dir_all(&target).unwrap();
    }

    #[test]
    fn objects_of_the_prefix_made_by_another_user_are_refused_and_own_ones_made_private() {
        let uid = effective_uid();
        let shm = scratch("shm");
        std::fs::create_dir(&shm).unwrap();
        let own = shm.join("hapsim_7_node.global_mgmt");
        std::fs::write(&own, b"").unwrap();
        std::fs::set_permissions(&own, std::fs::Permissions::from_mode(0o666)).unwrap();
        std::fs::write(shm.join("iox2_other"), b"").unwrap();
        assert_eq!(check_segments(&shm, "hapsim_7_", uid), Ok(()));
        let e = check_segments(&shm, "hapsim_7_", uid.wrapping_add(1)).unwrap_err();
        assert!(matches!(e, IpcRootError::ForeignSegment { .. }), "{e}");
        assert_eq!(make_segments_private(&shm, "hapsim_7_", uid), 1);
        let mode = std::fs::metadata(&own).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        // Another prefix is not touched.
        assert_eq!(make_segments_private(&shm, "hapsim_7_", uid), 0);
        std::fs::remove_dir_all(&shm).unwrap();
    }
}
