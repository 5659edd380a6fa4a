//! Subcommand implementations of the `sim-server` binary (the clap
//! definitions are in main.rs).

pub mod check;
pub mod demo;
pub mod run;
pub mod solve;

use anyhow::{Context, Result};
use sim_server::scene::{BuiltScene, SceneSource, build_scene};
use std::path::Path;

/// Reads and builds a scene file, or the embedded scene when `path` is `None`.
pub fn load_scene(path: Option<&Path>) -> Result<(SceneSource, BuiltScene)> {
    let src = match path {
        Some(p) => SceneSource::read(p)?,
        None => SceneSource::embedded(),
    };
    let spec = src.parse()?;
    let built =
        build_scene(&src, &spec).with_context(|| format!("cannot build scene {}", src.name))?;
    Ok((src, built))
}

/// Writes pretty JSON to `path`.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text + "\n").with_context(|| format!("cannot write {}", path.display()))
}
