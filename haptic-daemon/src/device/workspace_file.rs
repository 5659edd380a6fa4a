//! A device's workspace placement as a file (`haptic-daemon run --workspace
//! FILE.toml`), so that a lab keeps one per device and scene instead of
//! three flags (`haptic-daemon/workspaces/` has the guide's examples):
//!
//! ```toml
//! # 3D Systems Touch over the embedded liver
//! device = "touch"          # a note for the reader; not checked
//! offset_m = [0.0, 0.0, 0.087]
//! scale = 1.0
//! rotate_deg = [90.0, 0.0, 0.0]
//! ```
//!
//! Keys left out take the flags' defaults (no offset, scale 1, no
//! rotation); an unknown key is refused with its line, so that a misspelt
//! `rotate_deg` does not leave the device unrotated without a word.

use super::workspace::{WorkspaceError, WorkspaceMap};
use crate::math::V3;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Files larger than this are not workspace files (refused before reading).
const MAX_FILE_BYTES: u64 = 64 * 1024;

/// A workspace placement as the flags or a file give it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorkspaceSpec {
    /// The scene point of the device's origin (m).
    pub offset_m: V3,
    /// Scene metres per device metre.
    pub scale: f64,
    /// Degrees about the device's x, then y, then z axis.
    pub rotate_deg: V3,
}

fn one() -> f64 {
    1.0
}

/// The file form: the placement and its note (serde's `flatten` would
/// not refuse unknown keys, so the fields are spelt out).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileForm {
    /// Which device the placement is for (a note; not checked).
    #[serde(default)]
    #[allow(dead_code)]
    device: Option<String>,
    #[serde(default)]
    offset_m: V3,
    #[serde(default = "one")]
    scale: f64,
    #[serde(default)]
    rotate_deg: V3,
}

/// Why a workspace file could not be used.
#[derive(Debug, Error)]
pub enum WorkspaceFileError {
    /// It could not be read.
    #[error("cannot read the workspace file {path}: {reason}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system's reason (in the message, not a separate cause, so
        /// that it is said once).
        reason: std::io::Error,
    },
    /// It is larger than a workspace file can be.
    #[error("{path}: {bytes} bytes is not a workspace file (at most {MAX_FILE_BYTES})")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size.
        bytes: u64,
    },
    /// It is not TOML with the keys `offset_m`, `scale`, `rotate_deg`
    /// (and `device`); the parser's message names the line and the key.
    #[error("{path}: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's error, with its line and column.
        reason: toml::de::Error,
    },
    /// Its values are out of range.
    #[error("{path}: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Which value and its range.
        reason: WorkspaceError,
    },
}

impl Default for WorkspaceSpec {
    fn default() -> Self {
        Self {
            offset_m: [0.0; 3],
            scale: 1.0,
            rotate_deg: [0.0; 3],
        }
    }
}

impl WorkspaceSpec {
    /// Reads a workspace file (see the module docs) and checks its values.
    pub fn read(path: &Path) -> Result<Self, WorkspaceFileError> {
        let io = |reason| WorkspaceFileError::Io {
            path: path.to_path_buf(),
            reason,
        };
        let bytes = std::fs::metadata(path).map_err(io)?.len();
        if bytes > MAX_FILE_BYTES {
            return Err(WorkspaceFileError::TooLarge {
                path: path.to_path_buf(),
                bytes,
            });
        }
        let text = std::fs::read_to_string(path).map_err(io)?;
        let spec = Self::parse(&text).map_err(|reason| WorkspaceFileError::Parse {
            path: path.to_path_buf(),
            reason,
        })?;
        spec.map().map_err(|reason| WorkspaceFileError::Invalid {
            path: path.to_path_buf(),
            reason,
        })?;
        Ok(spec)
    }

    /// The placement in TOML text (unchecked values; [`WorkspaceSpec::map`]
    /// checks them).
    pub fn parse(text: &str) -> Result<Self, toml::de::Error> {
        toml::from_str::<FileForm>(text).map(|f| Self {
            offset_m: f.offset_m,
            scale: f.scale,
            rotate_deg: f.rotate_deg,
        })
    }

    /// The device-to-scene map it gives, checked.
    pub fn map(&self) -> Result<WorkspaceMap, WorkspaceError> {
        WorkspaceMap::new(self.offset_m, self.scale, self.rotate_deg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_gives_the_map_the_same_flags_give() {
        let spec = WorkspaceSpec::parse(
            "device = \"touch\"\noffset_m = [0.0, 0.0, 0.087]\nscale = 1.5\nrotate_deg = [90.0, 0.0, 0.0]\n",
        )
        .unwrap();
        let flags = WorkspaceMap::new([0.0, 0.0, 0.087], 1.5, [90.0, 0.0, 0.0]).unwrap();
        assert_eq!(spec.map().unwrap(), flags);
    }

    #[test]
    fn keys_left_out_take_the_flags_defaults() {
        let spec = WorkspaceSpec::parse("scale = 2.0\n").unwrap();
        assert_eq!(
            spec,
            WorkspaceSpec {
                scale: 2.0,
                ..WorkspaceSpec::default()
            }
        );
        assert!(
            WorkspaceSpec::parse("")
                .unwrap()
                .map()
                .unwrap()
                .is_identity()
        );
    }

    #[test]
    fn a_misspelt_key_is_refused_with_its_line() {
        let err = WorkspaceSpec::parse("scale = 1.0\nrotate = [90.0, 0.0, 0.0]\n").unwrap_err();
        let text = err.to_string();
        assert!(text.contains("rotate") && text.contains("line 2"), "{text}");
    }

    #[test]
    fn a_file_with_a_bad_value_names_the_file_and_the_range() {
        let dir = std::env::temp_dir().join(format!("hapsim-ws-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("falcon.toml");
        std::fs::write(&path, "scale = 1000.0\n").unwrap();
        let text = WorkspaceSpec::read(&path).unwrap_err().to_string();
        assert!(
            text.contains("falcon.toml") && text.contains("scale must lie in"),
            "{text}"
        );
        let missing = WorkspaceSpec::read(&dir.join("none.toml"))
            .unwrap_err()
            .to_string();
        assert!(missing.contains("none.toml"), "{missing}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
