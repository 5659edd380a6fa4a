//! A session's shared memory belongs to the user who runs it: every segment
//! of a running session (iceoryx2's global management segment included) is
//! readable and writable by its owner only, its records live in a 0700
//! directory of its own, and another Unix user can neither read nor spoil a
//! segment, list or delete the records, nor join the session; a directory
//! another user made for the records is refused with a clear error. The
//! second-user part needs root (to switch to `nobody` with setpriv); where
//! the tests do not run as root it is skipped with a message, and the mode
//! checks still run.

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
    // Segments of this user's sessions, under this user's own prefix.
    let prefix = format!("hapsim_{uid}_");
    let segments: Vec<std::path::PathBuf> = std::fs::read_dir("/dev/shm")
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            name.starts_with(&prefix)
        })
        .collect();
    assert!(!segments.is_empty(), "no shared memory segments found");
    assert!(
        segments
            .iter()
            .any(|p| p.to_string_lossy().ends_with("global_mgmt")),
        "{segments:?}"
    );
    for p in &segments {
        assert_eq!(std::fs::metadata(p).unwrap().uid(), uid, "{}", p.display());
    }
    let records = std::path::PathBuf::from(format!("/tmp/hapsim-{uid}"));
    let mode = std::fs::metadata(&records).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o700, "{}", records.display());
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
        for seg in &segments {
            let seg = seg.to_str().unwrap();
            let read = as_nobody(&["cat", seg]);
            assert!(!read.status.success(), "nobody read {seg}");
            // 16 bytes of 0xff into the global management segment made every
            // new node of every user fail before it was private.
            let write = as_nobody(&[
                "sh",
                "-c",
                &format!("printf '\\377%.0s' 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 > {seg}"),
            ]);
            assert!(!write.status.success(), "nobody wrote {seg}");
        }
        let list = as_nobody(&["ls", records.to_str().unwrap()]);
        assert!(
            !list.status.success(),
            "nobody listed {}",
            records.display()
        );
        let delete = as_nobody(&["rm", "-rf", &format!("{}/services", records.display())]);
        assert!(
            !delete.status.success() && records.join("services").exists(),
            "nobody deleted the service records"
        );
        // Another user's copy of the daemon lives in its own namespace: it
        // never sees this user's session. A copy nobody may execute, so the
        // only obstacle is the session.
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
        let said = format!("{err}{}", String::from_utf8_lossy(&join.stdout));
        assert!(
            said.contains("recorded 0 force samples"),
            "nobody saw the session: {said}"
        );
        assert!(
            !err.contains("setpriv:"),
            "the copy did not even start: {err}"
        );
        // The bridge does not open the session to another user on
        // loopback: nobody has no token of root's, cannot read root's, and
        // one of its own is not the bridge's.
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let mut bridge = Command::new(binary("sim-server"))
            .args(["bridge", "--session", &session, "--listen", &endpoint])
            .args(["--duration-s", "20"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let token = records.join("bridge.token");
        system_tests::wait_until(
            "the bridge's token",
            std::time::Duration::from_secs(10),
            || token.exists(),
        );
        let record = |extra: &[&str]| {
            let mut args = vec![
                bin.to_str().unwrap(),
                "record",
                "--session",
                &session,
                "--connect",
                &endpoint,
                "--duration-s",
                "0.5",
                "--json",
                "/dev/null",
            ];
            args.extend_from_slice(extra);
            let out = as_nobody(&args);
            (
                out.status.success(),
                String::from_utf8_lossy(&out.stderr).to_string(),
            )
        };
        let (ok, err) = record(&[]);
        assert!(
            !ok && err.contains("no bridge token at /tmp/hapsim-65534/"),
            "{err}"
        );
        let (ok, err) = record(&["--token-file", token.to_str().unwrap()]);
        assert!(!ok && err.contains("Permission denied"), "{err}");
        let own = dir.join("own.token");
        std::fs::write(&own, "hapsim:00ff00ff\n").unwrap();
        std::os::unix::fs::chown(&own, Some(65534), Some(65534)).unwrap();
        std::fs::set_permissions(&own, std::fs::Permissions::from_mode(0o600)).unwrap();
        let (ok, err) = record(&["--token-file", own.to_str().unwrap()]);
        assert!(!ok && err.contains("no bridge answers"), "{err}");
        let _ = bridge.kill();
        let _ = bridge.wait();
        // A records directory another user made first is refused, named.
        let planted =
            std::path::PathBuf::from(format!("/tmp/hapsim-planted-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&planted);
        let mk = as_nobody(&["mkdir", "-m", "777", planted.to_str().unwrap()]);
        assert!(mk.status.success());
        let run = Command::new(binary("sim-server"))
            .args([
                "run",
                "--quiet",
                "--duration-s",
                "0.5",
                "--session",
                &format!("{session}p"),
            ])
            .env("HAPSIM_IPC_DIR", &planted)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "ran in a directory nobody made");
        assert!(
            err.contains(planted.to_str().unwrap()) && err.contains("belongs to uid 65534"),
            "{err}"
        );
        std::fs::remove_dir_all(&planted).unwrap();
    } else {
        eprintln!("not root or no setpriv: the second-user part is skipped (modes checked)");
    }
    let _ = sim.wait();
}
