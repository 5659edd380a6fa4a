//! The crate boundaries ARCHITECTURE.md promises, checked on the resolved
//! dependency graph (`cargo tree`, offline, the lock file's versions): the
//! simulation core `tissue` pulls in no transport, command line, scene
//! format or process machinery, and the viewer links neither the core nor
//! the simulation process (it learns the scene from the session).

use std::process::Command;

/// The crates `package` depends on (normal dependencies, transitively).
fn normal_dependencies(package: &str) -> Vec<String> {
    let out = Command::new(env!("CARGO"))
        .args([
            "tree",
            "-p",
            package,
            "-e",
            "normal",
            "--prefix",
            "none",
            "--locked",
            "--offline",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run cargo tree");
    assert!(
        out.status.success(),
        "cargo tree -p {package}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut names: Vec<String> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(String::from))
        .collect();
    names.sort();
    names.dedup();
    names
}

#[test]
fn the_core_needs_no_transport_cli_scene_format_or_signals() {
    let deps = normal_dependencies("tissue");
    assert!(deps.contains(&"faer".to_string()), "{deps:?}");
    for forbidden in [
        "iceoryx2",
        "clap",
        "toml",
        "serde_json",
        "signal-hook",
        "shared",
        "sim-server",
    ] {
        assert!(
            !deps.iter().any(|d| d == forbidden),
            "tissue depends on {forbidden}: {deps:?}"
        );
    }
}

#[test]
fn the_viewer_links_neither_the_core_nor_the_simulation() {
    let deps = normal_dependencies("viewer");
    assert!(deps.contains(&"shared".to_string()), "{deps:?}");
    for forbidden in ["tissue", "sim-server"] {
        assert!(
            !deps.iter().any(|d| d == forbidden),
            "the viewer depends on {forbidden}: {deps:?}"
        );
    }
}
