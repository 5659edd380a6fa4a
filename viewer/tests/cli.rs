//! The viewer's command line: bad input and missing peers get clear errors.
//! (Being an integration test of this package also makes cargo build the
//! `viewer` binary that the cross-process tests in `tests/` run.)

use std::process::Command;

fn viewer(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_viewer"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("run viewer");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

#[test]
fn a_bad_size_names_the_flag_and_the_value() {
    let (ok, err) = viewer(&["--snapshot", "x.png", "--size", "800by600"]);
    assert!(!ok);
    assert!(err.contains("--size") && err.contains("800by600"), "{err}");
    let (ok, err) = viewer(&["--snapshot", "x.png", "--size", "8x600"]);
    assert!(!ok && err.contains("between 16 and 8192"), "{err}");
}

#[test]
fn a_snapshot_without_a_simulation_says_what_to_start() {
    let session = format!("nosim{}", std::process::id());
    let (ok, err) = viewer(&[
        "--session",
        &session,
        "--snapshot",
        "x.png",
        "--wait-s",
        "0.3",
    ]);
    assert!(!ok);
    assert!(
        err.contains("no mesh state") && err.contains(&session),
        "{err}"
    );
    assert!(!std::path::Path::new("x.png").exists());
}

#[cfg(not(feature = "window"))]
#[test]
fn without_the_window_feature_the_live_view_says_how_to_get_it() {
    let (ok, err) = viewer(&["--session", "nowindow"]);
    assert!(!ok && err.contains("--features window"), "{err}");
}
