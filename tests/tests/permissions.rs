//! A session's shared memory belongs to the user who runs it: every segment
//! of a running session is readable and writable by its owner only, and
//! another Unix user can neither read a segment nor join the session. The
//! second-user part needs root (to switch to `nobody` with setpriv); where
//! the tests do not run as root it is skipped with a message, and the mode
//! check still runs.

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::process::{Command, Stdio};
use system_tests::binary;

#[test]
fn session_memory_is_private_to_its_user() {
    let session = format!("perm{}", std::process::id());
    let mut sim = Command::new(binary("sim-server"))
        .args(["run", "--quiet", "--duration-s", "4", "--session", &session])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start sim-server");
    system_tests::wait_for(&session, system_tests::Peer::Simulation);
    let uid = unsafe { libc::geteuid() };
    // Segments of this user's sessions (the global management file is
    // iceoryx2's own, shared by design, and holds no session data).
    let segments: Vec<std::path::PathBuf> = std::fs::read_dir("/dev/shm")
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            name.starts_with("iox2_") && !name.ends_with("global_mgmt")
        })
        .filter(|p| std::fs::metadata(p).is_ok_and(|m| m.uid() == uid))
        .collect();
    assert!(!segments.is_empty(), "no shared memory segments found");
    for p in &segments {
        let mode = std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode & 0o077, 0, "{} has mode {mode:o}", p.display());
    }
    let setpriv_ok = uid == 0
        && Command::new("setpriv")
            .arg("--version")
            .stdout(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
    if setpriv_ok {
        let as_nobody = |args: &[&str]| {
            Command::new("setpriv")
                .args(["--reuid=65534", "--regid=65534", "--clear-groups", "--"])
                .args(args)
                .output()
                .expect("setpriv")
        };
        let seg = segments[0].to_str().unwrap();
        let read = as_nobody(&["cat", seg]);
        assert!(!read.status.success(), "nobody read {seg}");
        let write = as_nobody(&["sh", "-c", &format!("echo x >> {seg}")]);
        assert!(!write.status.success(), "nobody wrote {seg}");
        // Joining the session as another user fails with a clear error.
        // A copy nobody may execute, so the only obstacle is the session.
        let dir = system_tests::scratch_dir("perm-bin");
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
        let bin = dir.join("haptic-daemon");
        std::fs::copy(binary("haptic-daemon"), &bin).unwrap();
        std::fs::set_permissions(&bin, std::fs::Permissions::from_mode(0o755)).unwrap();
        let join = as_nobody(&[
            bin.to_str().unwrap(),
            "record",
            "--session",
            &session,
            "--duration-s",
            "0.5",
            "--json",
            "/dev/null",
        ]);
        let err = String::from_utf8_lossy(&join.stderr);
        eprintln!("as nobody: {}", err.lines().next().unwrap_or(""));
        assert!(!join.status.success(), "nobody joined the session");
        assert!(err.contains("another user"), "{err}");
        assert!(
            !err.contains("setpriv:"),
            "the copy did not even start: {err}"
        );
    } else {
        eprintln!("not root or no setpriv: the second-user part is skipped (modes checked)");
    }
    let _ = sim.wait();
}
