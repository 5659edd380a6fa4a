//! Helpers for the cross-process tests: find the workspace's binaries and
//! give each test a unique scratch directory.
#![warn(missing_docs)]

use std::path::PathBuf;

/// `haptic-daemon run` in `session`, quiet and at normal priority (the
/// tests share the machine); add the device and the rest.
pub fn daemon_run(session: &str) -> std::process::Command {
    let mut c = std::process::Command::new(binary("haptic-daemon"));
    c.args(["run", "--quiet", "--rt-priority", "0", "--session", session]);
    c
}

/// Starts `sim-server run --quiet` in `session` with `args`, stdout
/// discarded, stderr piped.
pub fn spawn_sim_server(session: &str, args: &[&str]) -> std::process::Child {
    std::process::Command::new(binary("sim-server"))
        .args(["run", "--quiet", "--session", session])
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start sim-server")
}

/// The path of a workspace binary built in the same profile as the running
/// test (`target/<profile>/<name>`).
pub fn binary(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> -> target/<profile>/<name>
    let dir = exe
        .parent()
        .and_then(|d| d.parent())
        .expect("test executable lives in target/<profile>/deps");
    let path = dir.join(name);
    assert!(
        path.exists(),
        "{} is not built; run the tests with `cargo test --workspace`",
        path.display()
    );
    path
}

/// A fresh directory under the system temp dir, unique to this process and `tag`.
/// The scratch directories of test processes that ended over an hour ago
/// are removed first (a failed run's stay to be looked at), so runs do not
/// pile them up in the temp dir (gigabytes of saved frames over weeks).
pub fn scratch_dir(tag: &str) -> PathBuf {
    remove_dead_scratch();
    let dir = std::env::temp_dir().join(format!("hapsim-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    dir
}

/// Removes `hapsim-<tag>-<pid>` directories in the temp dir whose process
/// is gone, last changed over an hour ago.
fn remove_dead_scratch() {
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        let Some(pid) = name
            .strip_prefix("hapsim-")
            .and_then(|rest| rest.rsplit_once('-'))
            .and_then(|(_, pid)| pid.parse::<u32>().ok())
        else {
            continue;
        };
        let alive = std::path::Path::new(&format!("/proc/{pid}")).exists();
        let old = e
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age.as_secs() > 3600);
        if !alive && old && e.file_type().is_ok_and(|t| t.is_dir()) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// A force sample as a simulation would send it: tool 0 in contact with
/// force `force_n`, stamped now.
pub fn contact_sample(seq: u64, force_n: [f64; 3]) -> shared::protocol::ForceMsg {
    let mut msg = shared::protocol::ForceMsg {
        version: shared::protocol::PROTOCOL_VERSION,
        tool_count: 1,
        seq,
        t_ns: shared::monotonic_ns(),
        ..Default::default()
    };
    msg.tools[0].force_n = force_n;
    msg.tools[0].flags = shared::protocol::CONTACT;
    msg
}

/// Runs `cmd` to completion and returns its output, failing the test with
/// its stderr if it did not succeed.
pub fn run_ok(mut cmd: impl std::borrow::BorrowMut<std::process::Command>) -> std::process::Output {
    let cmd = cmd.borrow_mut();
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {:?}: {e}", cmd.get_program()));
    assert!(
        out.status.success(),
        "{:?} failed ({}): {}",
        cmd.get_program(),
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Runs `cmd` to completion and returns its stderr, failing the test if it
/// succeeded (for the refusals a user meets).
pub fn run_err(mut cmd: impl std::borrow::BorrowMut<std::process::Command>) -> String {
    let cmd = cmd.borrow_mut();
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {:?}: {e}", cmd.get_program()));
    assert!(
        !out.status.success(),
        "{:?} succeeded where it should have refused",
        cmd.get_program()
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Reads a JSON file a binary wrote (panics naming the file if it cannot).
pub fn read_json(path: &std::path::Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// What meshio (an independent reader; `scripts/setup.sh` installs it)
/// finds in each file: `tests/python/read_with_meshio.py`'s JSON, one
/// object per file (points, tetrahedra, triangles, arrays with their shapes,
/// largest vector lengths, whether integer arrays are permutations).
/// Panics with meshio's own error if it refuses a file.
pub fn meshio_describe(files: &[&std::path::Path]) -> Vec<serde_json::Value> {
    python_describe("read_with_meshio.py", "meshio", files)
}

/// What VTK's own readers (the library ParaView is built on;
/// `scripts/setup.sh` installs its wheel) find in each `.vtu` or `.vtk`
/// file: `tests/python/read_with_vtk.py`'s JSON (points, tetrahedra,
/// arrays with components, tuples, largest vector length or range).
pub fn vtk_describe(files: &[&std::path::Path]) -> Vec<serde_json::Value> {
    python_describe("read_with_vtk.py", "vtk", files)
}

fn python_describe(
    script: &str,
    package: &str,
    files: &[&std::path::Path],
) -> Vec<serde_json::Value> {
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("python")
        .join(script);
    let out = std::process::Command::new("python3")
        .arg(&script)
        .args(files)
        .output()
        .expect("python3 (scripts/setup.sh installs it)");
    assert!(
        out.status.success(),
        "{package} could not read {files:?} (is {package} installed? scripts/setup.sh installs it): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("the script prints JSON")
}

/// Waits for `child` at most `limit`: a process that hangs is a test
/// failure, not a stuck CI, so past the limit it is killed and the test
/// panics naming `what`.
pub fn wait_bounded(
    child: &mut std::process::Child,
    limit: std::time::Duration,
    what: &str,
) -> std::process::ExitStatus {
    let start = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            return status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("{what} did not stop within {limit:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// [`wait_bounded`], then asserts that `child` succeeded (showing its
/// stderr when it was piped) and returns its output.
pub fn finish(
    mut child: std::process::Child,
    limit: std::time::Duration,
    what: &str,
) -> std::process::Output {
    let status = wait_bounded(&mut child, limit, what);
    let out = child.wait_with_output().expect("collect output");
    assert!(
        status.success(),
        "{what} failed ({status}): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The embedded liver's top (z, m) near the vertical axis through the
/// origin, where the tests' hand presses.
pub fn liver_top_z() -> f64 {
    use sim_server::scene::{SceneSource, build_scene};
    let src = SceneSource::embedded();
    let model = build_scene(&src, &src.parse().unwrap()).unwrap().model;
    let p = model.mesh().positions_m();
    model
        .topology()
        .surface_triangles(model.mesh())
        .flatten()
        .map(|v| p[v.idx()])
        .filter(|x| x.x.hypot(x.y) < 0.006)
        .map(|x| x.z)
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Writes a replay trajectory that presses the embedded liver 6 mm deep
/// from 10 mm above its top and holds for a minute.
pub fn write_liver_press(path: &std::path::Path) {
    let top = liver_top_z();
    assert!(top.is_finite());
    std::fs::write(
        path,
        format!(
            "t_s,x_m,y_m,z_m\n0,0,0,{}\n1,0,0,{}\n60,0,0,{}\n",
            top + 0.01,
            top - 0.006,
            top - 0.006
        ),
    )
    .unwrap();
}

/// Waits until `cond` holds, polling every 5 ms, for at most `timeout`;
/// panics naming `what` if it never does. Cross-process tests wait on a
/// condition like this rather than sleeping a guessed time.
pub fn wait_until(what: &str, timeout: std::time::Duration, mut cond: impl FnMut() -> bool) {
    let start = std::time::Instant::now();
    while !cond() {
        assert!(start.elapsed() < timeout, "{what}: not within {timeout:?}");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// A peer whose arrival in a session a test waits for ([`wait_for`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Peer {
    /// A simulation: the session's force publisher exists.
    Simulation,
    /// A pose source (a daemon): a pose publisher exists.
    PoseSource,
    /// A recorder or daemon reading telemetry: a telemetry subscriber exists.
    TelemetryReader,
}

/// Waits (at most 20 s) until `peer` has joined `session`, by looking at
/// the session's services (opening them, as any participant may).
pub fn wait_for(session: &str, peer: Peer) {
    use shared::services;
    let name = shared::SessionName::new(session).expect("session name");
    let node = services::node("test-waiter").expect("iceoryx2 node");
    let timeout = std::time::Duration::from_secs(20);
    let what = format!("{peer:?} in session {session}");
    match peer {
        Peer::Simulation => {
            let f = services::force_service(&node, &name).expect("force service");
            wait_until(&what, timeout, || services::publisher_count(&f) > 0);
        }
        Peer::PoseSource => {
            let f = services::pose_service(&node, &name).expect("pose service");
            wait_until(&what, timeout, || services::publisher_count(&f) > 0);
        }
        Peer::TelemetryReader => {
            let f = services::telemetry_service(&node, &name).expect("telemetry service");
            wait_until(&what, timeout, || services::subscriber_count(&f) > 0);
        }
    }
}

/// tests/data/box-probe.toml made stiffer (5 -> 20 kPa), more damped
/// (20 -> 40 /s), twice as thick and probed with a 5 mm probe: a 60 x 40 x
/// 40 mm block on 5 mm cells, bottom fixed, the probe entering from above.
/// (The box's own 2.5 mm probe, half a cell wide, slips off the vertex it
/// presses past about 13 mm on these cells: a limit of the discretisation
/// that docs/design/contact.md's penalty-law limits state, not of the glitch handling.)
pub const STIFF_BOX: &str = r#"
[mesh]
generate = { shape = "box", size_m = [0.06, 0.04, 0.04], cell_m = 0.005 }

[material]
young_pa = 20000.0
poisson = 0.45
density_kg_m3 = 1000.0
damping_per_s = 40.0

[[fixed]]
name = "bottom"
select = { box_m = [[-0.001, -0.001, -0.001], [0.061, 0.041, 0.0001]] }

[[tool]]
name = "probe"
kind = "hook"
fulcrum_m = [0.03, 0.02, 0.15]
length_m = 0.3
radius_m = 0.005
tip_length_m = 0.01

[simulation]
dt_s = 0.001
"#;

/// |F| (N) of each tick of a daemon's `--record` CSV (columns 5-7 are
/// `force_x_n,force_y_n,force_z_n`), panicking on a row that does not parse.
pub fn record_force_norms(path: &std::path::Path) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .skip(1)
        .map(|l| {
            let c: Vec<f64> = l
                .split(',')
                .skip(5)
                .take(3)
                .map(|x| {
                    x.parse()
                        .unwrap_or_else(|_| panic!("{}: {l}", path.display()))
                })
                .collect();
            (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
        })
        .collect()
}

/// The workspace's root (the folder above this crate).
pub fn workspace_root() -> PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace")
        .to_path_buf()
}

/// Every file under `dir` whose name ends in `.EXT`, skipping hidden
/// folders and build output (`target`): the sources and documents the
/// structure tests read.
pub fn files_with_extension(dir: &std::path::Path, ext: &str) -> Vec<PathBuf> {
    fn walk(dir: &std::path::Path, ext: &str, out: &mut Vec<PathBuf>) {
        let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        for entry in entries {
            let entry = entry.unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
            let path = entry.path();
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if path.is_dir() {
                if !name.starts_with('.') && name != "target" {
                    walk(&path, ext, out);
                }
            } else if path.extension().is_some_and(|e| e == ext) {
                out.push(path);
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, ext, &mut out);
    out
}
