//! Scene files: one TOML file describes a surgical scene (mesh, materials,
//! regions, vessels, membrane, fixed sets, loads, tools, simulation
//! settings). Errors name the file, line and column. Building a scene makes
//! only what it declares: no anisotropy data without fibres, no membrane
//! without `[membrane]`, no load arrays without loads.

mod assign;
mod build;
mod centreline;
mod loads;
mod materials;
mod mesh_load;
pub mod ranges;
pub mod real_time;
pub mod refine;
mod report;
mod select;
mod settings;
pub mod spec;
mod tool_decls;
mod vessel;

pub use build::{BuiltScene, ToolDecl, build_scene, build_scene_around};
pub use mesh_load::BaseMesh;
pub use report::SceneReport;
pub use settings::{HYBRID_NEEDS_SPLIT, MAX_DT_S, MIN_DT_S, SimSettings, check_step};

use std::ops::Range;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The embedded default scene: a liver with vessels, capsule, attachment and two tools.
pub const DEFAULT_SCENE: &str = include_str!("../../scenes/liver.toml");
/// The name the embedded scene reports in messages.
pub const DEFAULT_SCENE_NAME: &str = "<embedded liver.toml>";

/// A scene's text and where it came from (for messages and relative paths).
#[derive(Clone, Debug)]
pub struct SceneSource {
    /// File name used in messages.
    pub name: String,
    /// Directory that relative mesh paths start from.
    pub dir: PathBuf,
    /// The TOML text.
    pub text: String,
}

impl SceneSource {
    /// Reads a scene file.
    pub fn read(path: &Path) -> Result<Self, SceneError> {
        let io = |source| SceneError::Io {
            file: path.display().to_string(),
            reason: source,
        };
        let bytes = crate::input_file::read_at_most(path, crate::input_file::MAX_SCENE_BYTES)
            .map_err(io)?;
        let text = String::from_utf8(bytes).map_err(|e| {
            io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "not UTF-8 text (byte {}): not a scene file",
                    e.utf8_error().valid_up_to()
                ),
            ))
        })?;
        Ok(Self {
            name: path.display().to_string(),
            dir: path.parent().map(Path::to_path_buf).unwrap_or_default(),
            text,
        })
    }

    /// The embedded default scene.
    pub fn embedded() -> Self {
        Self {
            name: DEFAULT_SCENE_NAME.into(),
            dir: PathBuf::from("."),
            text: DEFAULT_SCENE.into(),
        }
    }

    /// 1-based line and column of a byte offset.
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        let offset = offset.min(self.text.len());
        let before = &self.text[..offset];
        let line = before.matches('\n').count() + 1;
        let column = before.rfind('\n').map_or(offset, |nl| offset - nl - 1) + 1;
        (line, column)
    }

    /// An error at `span`.
    pub fn error(&self, span: Range<usize>, message: impl Into<String>) -> SceneError {
        let (line, column) = self.line_col(span.start);
        SceneError::Invalid {
            file: self.name.clone(),
            line,
            column,
            message: message.into(),
        }
    }

    /// Parses the TOML into the typed scene.
    pub fn parse(&self) -> Result<spec::SceneSpec, SceneError> {
        toml::from_str(&self.text).map_err(|e| {
            let (line, column) = e.span().map_or((0, 0), |s| self.line_col(s.start));
            SceneError::Syntax {
                file: self.name.clone(),
                line,
                column,
                message: e.message().trim().to_string(),
            }
        })
    }
}

/// Why a scene was refused.
#[derive(Debug, Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{file}: {reason}")]
    Io {
        /// The file.
        file: String,
        /// The OS error.
        reason: std::io::Error,
    },
    /// Not valid TOML, an unknown key, or a value of the wrong type.
    #[error("{file}:{line}:{column}: {message}")]
    Syntax {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// A value that is well-formed but not acceptable.
    #[error("{file}:{line}:{column}: {message}")]
    Invalid {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
}

impl SceneError {
    /// (line, column) of the error, when it has a position.
    pub fn position(&self) -> Option<(usize, usize)> {
        match self {
            SceneError::Io { .. } => None,
            SceneError::Syntax { line, column, .. } | SceneError::Invalid { line, column, .. } => {
                Some((*line, *column))
            }
        }
    }
}
