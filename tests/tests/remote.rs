//! A remote station (issue 19's acceptance): the simulation (embedded
//! liver, real time) and `sim-server bridge` run on this host; a viewer
//! snapshot, a haptic daemon replaying a press and a recorder run in a
//! private mount namespace (`unshare -m`) with their own empty `/dev/shm`
//! and `/tmp`, so no shared memory of the session is reachable, and join
//! through zenoh over TCP on loopback. The station also has its own time
//! namespace whose `CLOCK_MONOTONIC` runs 1000 s ahead of this host's, as
//! another machine's would: every stamp must be mapped between the clocks
//! (a daemon that compared the simulation's stamps with its own clock
//! would find every sample 1000 s old and render nothing). The snapshot shows the organ (its scene, rest
//! shape and surface came from the streams: the viewer reads no file), the
//! daemon renders the contact force within the device limit, the press
//! reaches the simulation (its force samples on this host show contact),
//! and a SIGKILL of the bridge zeroes the remote daemon's force within
//! 100 ms. Afterwards the namespace's `/dev/shm` and `/tmp` are still
//! empty: nothing of the remote side touched shared memory.

use shared::protocol::CONTACT;
use shared::{SessionName, monotonic_ns, services};
use std::process::{Command, Stdio};
use std::time::Duration;
use system_tests::{
    Peer, binary, read_json, scratch_dir, spawn_sim_server, wait_for, wait_until, write_liver_press,
};

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// The remote station's commands, run in a new mount namespace where only
/// the binaries and the scratch directory are visible (bound under /mnt
/// before /tmp and /dev/shm are replaced by empty ones).
fn station_script(endpoint: &str, session: &str) -> String {
    format!(
        r#"set -e
mount -t tmpfs none /mnt
mkdir /mnt/bin /mnt/work
mount --bind "$BIN" /mnt/bin
mount --bind "$WORK" /mnt/work
mount -t tmpfs none /tmp
mount -t tmpfs none /dev/shm
# Without the bridge's token, or with another, a client is refused.
if /mnt/bin/viewer --connect {endpoint} --session {session} --snapshot /mnt/work/x.png \
  --wait-s 2 >/dev/null 2>/mnt/work/no-token.err; then echo "joined without a token"; exit 1; fi
if /mnt/bin/viewer --connect {endpoint} --session {session} --snapshot /mnt/work/x.png \
  --token-file /mnt/work/wrong.token --wait-s 2 >/dev/null 2>/mnt/work/wrong-token.err; then
  echo "joined with a wrong token"; exit 1; fi
T=/mnt/work/bridge.token
/mnt/bin/viewer --connect {endpoint} --session {session} --snapshot /mnt/work/remote.png \
  --json /mnt/work/snapshot.json --view top --wait-s 20 --token-file $T >/dev/null
/mnt/bin/haptic-daemon record --connect {endpoint} --session {session} --duration-s 5 \
  --token-file $T --forces /mnt/work/recorded.csv --json /mnt/work/recorded.json 2>/dev/null &
/mnt/bin/haptic-daemon run --quiet --rt-priority 0 --connect {endpoint} --session {session} \
  --token-file $T --device replay:/mnt/work/press.csv --duration-s 7 --record /mnt/work/daemon.csv \
  --json /mnt/work/daemon.json >/dev/null
wait
echo "shm=$(ls -A /dev/shm | wc -l) tmp=$(ls -A /tmp | wc -l)"
"#
    )
}

/// How far the station's monotonic clock runs ahead of this host's (s).
const STATION_AHEAD_S: u64 = 1000;

/// (t_ns, |force| N) of each tick in the daemon's record.
fn record_forces(csv: &str) -> Vec<(u64, f64)> {
    csv.lines()
        .skip(1)
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            let f = |i: usize| c[i].parse::<f64>().expect("a number");
            (
                c[0].parse().expect("t_ns"),
                (f(5).powi(2) + f(6).powi(2) + f(7).powi(2)).sqrt(),
            )
        })
        .collect()
}

#[test]
fn a_remote_station_sees_the_organ_feels_the_press_and_lets_go_when_the_bridge_dies() {
    let session = format!("remote-{}", std::process::id());
    let dir = scratch_dir("remote");
    write_liver_press(&dir.join("press.csv"));
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    // Bounded: a failing assertion must not leave them running.
    let mut sim = spawn_sim_server(&session, &["--duration-s", "120"]);
    wait_for(&session, Peer::Simulation);
    // The station is given a copy of the bridge's token (as another host
    // would be); a wrong one is made beside it.
    let token = dir.join("bridge.token");
    let wrong = dir.join("wrong.token");
    std::fs::write(&wrong, "hapsim:0123456789abcdef\n").unwrap();
    std::fs::set_permissions(&wrong, std::os::unix::fs::PermissionsExt::from_mode(0o600)).unwrap();
    let mut bridge = Command::new(binary("sim-server"))
        .args(["bridge", "--session", &session, "--listen", &endpoint])
        .args(["--duration-s", "120"])
        .arg("--token-file")
        .arg(&token)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start the bridge");
    // The simulation's force samples, watched on this host.
    let name = SessionName::new(&session).unwrap();
    let node = services::node("test-remote").unwrap();
    let forces = services::subscriber(&services::force_service(&node, &name).unwrap()).unwrap();
    let bin = binary("haptic-daemon").parent().unwrap().to_path_buf();
    let station = Command::new("unshare")
        .args([
            "--fork",
            "--mount",
            "--time",
            "--monotonic",
            &STATION_AHEAD_S.to_string(),
            "sh",
            "-c",
            &station_script(&endpoint, &session),
        ])
        .env("BIN", &bin)
        .env("WORK", &dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("unshare (util-linux) starts the station");
    // The remote press reaches the simulation through the bridge: contact
    // in its samples, held for a second.
    let mut first_contact_ns = None;
    wait_until(
        "the remote daemon's press in the simulation",
        Duration::from_secs(40),
        || {
            while let Ok(Some(s)) = forces.receive() {
                if s.tools[0].flags & CONTACT != 0 {
                    first_contact_ns.get_or_insert(s.t_ns);
                }
            }
            first_contact_ns.is_some_and(|t| monotonic_ns().saturating_sub(t) > 1_000_000_000)
        },
    );
    let killed_ns = monotonic_ns();
    bridge.kill().expect("SIGKILL the bridge");
    let _ = bridge.wait();
    let out = station.wait_with_output().expect("the station ends");
    let _ = sim.kill();
    let _ = sim.wait();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the station failed ({}): {}{}",
        out.status,
        stdout,
        String::from_utf8_lossy(&out.stderr)
    );
    let no_token = std::fs::read_to_string(dir.join("no-token.err")).unwrap();
    assert!(
        no_token.contains("no bridge token at /tmp/hapsim-") && no_token.contains("--token-file"),
        "{no_token}"
    );
    let wrong_token = std::fs::read_to_string(dir.join("wrong-token.err")).unwrap();
    assert!(
        wrong_token.contains("no bridge answers") && wrong_token.contains("token"),
        "{wrong_token}"
    );
    assert!(
        stdout.contains("shm=0 tmp=0"),
        "the remote side left files in its /dev/shm or /tmp: {stdout}"
    );
    // The snapshot: the liver, from the session's streams alone.
    let snap = read_json(&dir.join("snapshot.json"));
    assert!(snap["triangles"].as_u64().unwrap() > 1000, "{snap}");
    assert!(!snap["scene"].as_str().unwrap().is_empty(), "{snap}");
    assert!(std::fs::metadata(dir.join("remote.png")).unwrap().len() > 1000);
    // The daemon: contact force within the device limit before the kill,
    // zero within 100 ms after it and from then on.
    let summary = read_json(&dir.join("daemon.json"));
    // Its default extrapolator got the simulation's contact problems
    // through the bridge (which subscribes to them only while a remote
    // client wants them).
    assert!(summary["local_problems"].as_u64().unwrap() > 0, "{summary}");
    let limit = summary["device_max_force_n"].as_f64().unwrap();
    assert!(
        summary["max_force_n"].as_f64().unwrap() <= limit + 1e-9,
        "{summary}"
    );
    // The daemon's stamps are the station's clock: back to this host's.
    let ahead_ns = STATION_AHEAD_S * 1_000_000_000;
    let ticks: Vec<(u64, f64)> =
        record_forces(&std::fs::read_to_string(dir.join("daemon.csv")).unwrap())
            .into_iter()
            .map(|(t, f)| (t - ahead_ns, f))
            .collect();
    // The recorder on the station, until the bridge died (about 2 s): the
    // simulation's samples, stamped in the station's clock,
    // and the station daemon's telemetry (which only the bridge can pass
    // from one zenoh client to another).
    let recorded = read_json(&dir.join("recorded.json"));
    assert!(
        recorded["forces"]["received"].as_u64().unwrap() > 500,
        "{recorded}"
    );
    assert!(
        recorded["telemetry"]["received"].as_u64().unwrap() > 200,
        "{recorded}"
    );
    // Force samples go best-effort (dropped, not queued, under congestion,
    // and counted): a loaded machine may lose a few, never many.
    let lost = recorded["forces"]["lost"].as_u64().unwrap();
    assert!(
        lost * 100 <= recorded["forces"]["received"].as_u64().unwrap(),
        "{recorded}"
    );
    let rows = std::fs::read_to_string(dir.join("recorded.csv")).unwrap();
    let first_t: u64 = rows
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    let lag_s = (first_t as f64 - killed_ns as f64) * 1e-9;
    assert!(
        (STATION_AHEAD_S as f64 - 10.0..STATION_AHEAD_S as f64).contains(&lag_s),
        "a recorded stamp {lag_s:.3} s from this host's clock, not in the station's"
    );
    let held: Vec<f64> = ticks
        .iter()
        .filter(|(t, _)| (killed_ns - 300_000_000..killed_ns).contains(t))
        .map(|&(_, f)| f)
        .collect();
    assert!(
        held.len() > 200,
        "{} ticks in the 300 ms before the kill",
        held.len()
    );
    let weakest = held.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(
        weakest > 0.2,
        "the remote daemon rendered {weakest} N during the press (ticks before the kill)"
    );
    let zero_at = ticks
        .iter()
        .find(|&&(t, f)| t >= killed_ns && f == 0.0)
        .map(|&(t, _)| t)
        .expect("the force reached zero after the bridge died");
    let after_ms = (zero_at - killed_ns) as f64 * 1e-6;
    eprintln!(
        "remote station: {} N at least during the press, zero {after_ms:.1} ms after the bridge's SIGKILL",
        weakest
    );
    assert!(after_ms <= 100.0, "zero {after_ms:.1} ms after the kill");
    assert!(
        ticks
            .iter()
            .filter(|(t, _)| *t >= zero_at)
            .all(|&(_, f)| f == 0.0),
        "a force came back without a bridge"
    );
}
