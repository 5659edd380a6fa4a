//! `sim-server bench` end to end: the process runs, prints, and writes the
//! JSON keys that scripts rely on, with values that make sense.

use std::process::Command;
use system_tests::{binary, read_json, run_err, run_ok, scratch_dir};

/// A 4 x 2 x 2 cm block on 1 cm cells, its material, and a blank line: the
/// start of the small scenes below (9 lines).
const BLOCK: &str = r#"[mesh]
generate = { shape = "box", size_m = [0.04, 0.02, 0.02], cell_m = 0.01 }

[material]
young_pa = 5000.0
poisson = 0.45
density_kg_m3 = 1000.0
damping_per_s = 5.0

"#;
#[test]
fn bench_writes_the_documented_json_keys() {
    let dir = scratch_dir("bench");
    let json = dir.join("bench.json");
    let out = run_ok(
        Command::new(binary("sim-server"))
            .args([
                "bench",
                "--generate",
                "box",
                "--tets",
                "3000",
                "--steps",
                "50",
                "--threads",
                "2",
            ])
            .arg("--json")
            .arg(&json),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("steps/s"), "{stdout}");
    let v: serde_json::Value = read_json(&json);
    for key in [
        "tets",
        "vertices",
        "steps_per_s",
        "ns_per_step",
        "bytes_per_step",
        "bandwidth_bound_steps_per_s",
    ] {
        assert!(
            v.get(key).is_some_and(|x| x.is_number()),
            "missing {key} in {v}"
        );
    }
    let tets = v["tets"].as_u64().unwrap();
    assert!((2000..4500).contains(&tets), "asked 3000 tets, got {tets}");
    let rate = v["steps_per_s"].as_f64().unwrap();
    let ns = v["ns_per_step"].as_f64().unwrap();
    assert!(rate > 0.0 && (rate * ns / 1e9 - 1.0).abs() < 1e-9);
    assert!(v["bytes_per_step"].as_u64().unwrap() > 40 * tets);
    assert_eq!(v["threads"].as_u64(), Some(2));
}

#[test]
fn bench_refuses_bad_arguments_clearly() {
    let err = run_err(Command::new(binary("sim-server")).args([
        "bench",
        "--tets",
        "1000",
        "--threads",
        "0",
    ]));
    assert!(err.contains("--threads"), "{err}");
    let err = run_err(Command::new(binary("sim-server")).args(["bench", "--generate", "sphere"]));
    assert!(err.contains("sphere"), "{err}");
}

#[test]
fn check_reports_the_embedded_scene_and_refuses_bad_ones_with_a_position() {
    let out = run_ok(Command::new(binary("sim-server")).arg("check"));
    let text = String::from_utf8_lossy(&out.stdout);
    for needle in [
        "tetrahedra",
        "dihedral",
        "stable step",
        "membrane: linear",
        "anisotropy",
        "vessel",
        // The step and sample rate a run will use, said.
        "a run steps every 1.0000e-3 s (the scene's dt_s)",
        "1000 force samples per second",
    ] {
        assert!(text.contains(needle), "missing {needle:?} in:\n{text}");
    }
    let dir = scratch_dir("check");
    // A missing file is said once: the message, no "Caused by" repeating it.
    for (bin, args) in [
        ("sim-server", vec!["check", "/no/such/organ.msh"]),
        (
            "haptic-daemon",
            vec!["run", "--device", "replay:/no/such/path.csv"],
        ),
    ] {
        let err = run_err(
            Command::new(binary(bin))
                .args(&args)
                .env("RUST_BACKTRACE", "0"),
        );
        assert!(err.contains("No such file"), "{err}");
        assert!(
            !err.contains("Caused by"),
            "{bin}: the reason said twice:\n{err}"
        );
    }
    // Without dt_s the step is the stability bound, and check says so.
    let ellipsoid = dir.join("ellipsoid.toml");
    std::fs::write(
        &ellipsoid,
        "[mesh]\ngenerate = { shape = \"ellipsoid\", radii_m = [0.04, 0.03, 0.02], cell_m = 0.004 }\n[material]\nyoung_pa = 5000.0\npoisson = 0.45\ndensity_kg_m3 = 1000.0\n",
    )
    .unwrap();
    let out = run_ok(
        Command::new(binary("sim-server"))
            .arg("check")
            .arg(&ellipsoid),
    );
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains("(no dt_s: 0.9 of the stable step; set [simulation] dt_s = 0.001 for 1 kHz)"),
        "{said}"
    );
    // A refined corner with multirate stepping: check says the partition
    // (few vertices fast, fewer whole passes than fast sub-steps).
    let refined = dir.join("refined.toml");
    std::fs::write(
        &refined,
        "[mesh]\ngenerate = { shape = \"box\", size_m = [0.16, 0.08, 0.02], cell_m = 0.005 }\n[material]\nyoung_pa = 5000.0\npoisson = 0.45\ndensity_kg_m3 = 1000.0\n[[refine]]\nselect = { sphere_m = [0.02, 0.02, 0.02, 0.004] }\ncell_m = 0.0025\n[simulation]\ndt_s = 0.002\nmultirate = true\n",
    )
    .unwrap();
    let out = run_ok(
        Command::new(binary("sim-server"))
            .arg("check")
            .arg(&refined),
    );
    let said = String::from_utf8_lossy(&out.stdout);
    let line = said
        .lines()
        .find(|l| l.starts_with("multirate: "))
        .unwrap_or_else(|| panic!("no multirate line in:\n{said}"));
    let numbers: Vec<usize> = line
        .split(|c: char| !c.is_ascii_digit())
        .filter_map(|w| w.parse().ok())
        .collect();
    // fast, vertices, interface, whole passes, fast sub-steps, one step for all.
    let [fast, vertices, _, whole, fine, uniform] = numbers[..] else {
        panic!("{line}");
    };
    assert!(
        fast * 2 < vertices && whole < fine && fine >= uniform,
        "{line}"
    );
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        "[mesh]\ngenerate = { shape = \"box\", size_m = [0.1, 0.1, 0.1], cell_m = 0.05 }\n[material]\nyoung_pa = 1000.0\npoisson = 0.7\ndensity_kg_m3 = 1000.0\n",
    )
    .unwrap();
    // `check FILE` must fail: its stderr.
    let refused = |file: &std::path::Path| {
        let out = Command::new(binary("sim-server"))
            .arg("check")
            .arg(file)
            .output()
            .unwrap();
        assert!(!out.status.success(), "check accepted {}", file.display());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = refused(&bad);
    assert!(
        err.contains("bad.toml:5:11") && err.contains("poisson"),
        "{err}"
    );
    // A surface mesh is refused by name, not parsed as a scene.
    let stl = dir.join("organ.stl");
    std::fs::write(&stl, "solid organ\nendsolid organ\n").unwrap();
    let err = refused(&stl);
    assert!(
        err.contains("organ.stl") && err.contains("surface mesh") && !err.contains("TOML"),
        "{err}"
    );
    // A scene `run` refuses is refused by `check` too, with run's reason
    // (nearly incompressible: 44,722 sub-steps for its 1 ms step).
    let stiff = dir.join("stiff.toml");
    std::fs::write(
        &stiff,
        "[mesh]\ngenerate = { shape = \"box\", size_m = [0.1, 0.1, 0.1], cell_m = 0.05 }\n[material]\nyoung_pa = 4500.0\npoisson = 0.4999999999\ndensity_kg_m3 = 1000.0\n[simulation]\ndt_s = 0.001\n",
    )
    .unwrap();
    let err = refused(&stiff);
    assert!(
        err.contains("stiff.toml") && err.contains("would refuse") && err.contains("4096"),
        "{err}"
    );
}

#[test]
fn check_tells_where_a_mesh_is_its_units_and_its_tags() {
    let dir = scratch_dir("check_extent");
    let meshes = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../sim-server/tests/data/meshes"
    );
    let check = |file: &std::path::Path, json: &std::path::Path| {
        let out = run_ok(
            Command::new(binary("sim-server"))
                .arg("check")
                .arg(file)
                .arg("--json")
                .arg(json),
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    // SOFA's format (MSH 1), in metres: extent, typical edge, tags, no warning.
    let json = dir.join("v1.json");
    let text = check(
        &std::path::Path::new(meshes).join("ellipsoid_v1.msh"),
        &json,
    );
    assert!(
        text.contains("extent: [-0.0398, -0.0249, -0.0200] .. [0.0396, 0.0249, 0.0200] m"),
        "{text}"
    );
    assert!(
        text.contains("physical tags of the tetrahedra (count): 1 (2182)"),
        "{text}"
    );
    assert!(!text.contains("not plausibly"), "{text}");
    let j = read_json(&json);
    assert_eq!(j["physical_tags"], serde_json::json!([[1, 2182]]));
    assert_eq!(j["surface_physical_tags"], serde_json::json!([[2, 762]]));
    assert!(
        (j["median_edge_m"].as_f64().unwrap() - 7.275e-3).abs() < 1e-5,
        "{j}"
    );
    // The same body in millimetres: named, with the key that fixes it.
    let text =
        std::fs::read_to_string(std::path::Path::new(meshes).join("ellipsoid_v1.msh")).unwrap();
    let nod_end = text.find("$ENDNOD").unwrap();
    let scaled: String = text[..nod_end]
        .lines()
        .map(|l| match l.split_whitespace().collect::<Vec<_>>()[..] {
            [tag, x, y, z] => {
                let mm = |v: &str| v.parse::<f64>().unwrap() * 1000.0;
                format!("{tag} {} {} {}\n", mm(x), mm(y), mm(z))
            }
            _ => format!("{l}\n"),
        })
        .collect();
    let mm = dir.join("ellipsoid_mm.msh");
    std::fs::write(&mm, scaled + &text[nod_end..]).unwrap();
    let out = check(&mm, &dir.join("mm.json"));
    assert!(
        out.contains("not plausibly an organ in metres") && out.contains("scale = 0.001"),
        "{out}"
    );
}

#[test]
fn solve_writes_displacement_and_force_and_balances_the_load() {
    let dir = scratch_dir("solve");
    let scene = dir.join("sag.toml");
    std::fs::write(
        &scene,
        r#"[mesh]
generate = { shape = "box", size_m = [0.1, 0.02, 0.02], cell_m = 0.005 }
[material]
young_pa = 4500.0
poisson = 0.45
density_kg_m3 = 1060.0
[[fixed]]
select = { box_m = [[-1, -1, -1], [0.0001, 1, 1]] }
[[load]]
select = { box_m = [[0.0999, -1, -1], [1, 1, 1]] }
force_n = [0.0, 0.0, -0.01]
"#,
    )
    .unwrap();
    let (vtu, json) = (dir.join("sag.vtu"), dir.join("sag.json"));
    run_ok(
        Command::new(binary("sim-server"))
            .args(["solve", "--scene"])
            .arg(&scene)
            .arg("--out")
            .arg(&vtu)
            .arg("--json")
            .arg(&json),
    );
    let xml = std::fs::read_to_string(&vtu).unwrap();
    assert!(xml.contains("Name=\"displacement\"") && xml.contains("Name=\"force\""));
    let v: serde_json::Value = read_json(&json);
    let load = v["total_load_n"][2].as_f64().unwrap();
    let reaction = v["total_reaction_n"][2].as_f64().unwrap();
    assert!(
        (load + 0.01).abs() < 1e-12 && (reaction - 0.01).abs() < 1e-9,
        "{v}"
    );
    assert!(v["max_displacement_m"].as_f64().unwrap() > 0.0);
    // The deformed surface by extension: OBJ (text) and binary STL; the
    // free end sags (its z below the rest 0 at the bottom face).
    let solve_to = |name: &str| {
        let path = dir.join(name);
        let out = Command::new(binary("sim-server"))
            .args(["solve", "--scene"])
            .arg(&scene)
            .arg("--out")
            .arg(&path)
            .output()
            .unwrap();
        (path, out)
    };
    // Solved and written: the file's path.
    let solved = |name: &str| {
        let (path, out) = solve_to(name);
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        path
    };
    let obj = solved("sag.obj");
    let text = std::fs::read_to_string(&obj).unwrap();
    let lowest = text
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| l.split_whitespace().nth(2).unwrap().parse::<f64>().unwrap())
        .fold(f64::INFINITY, f64::min);
    assert!(
        lowest < -1e-4,
        "the deformed surface should sag: lowest z {lowest}"
    );
    assert!(text.lines().any(|l| l.starts_with("f ")));
    let stl = solved("sag.stl");
    let bytes = std::fs::read(&stl).unwrap();
    let count = u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize;
    assert!(
        count > 0 && bytes.len() == 84 + 50 * count,
        "{} bytes",
        bytes.len()
    );
    // Legacy VTK with the point data; medit with the deformed mesh.
    let vtk = solved("sag.vtk");
    let text = std::fs::read_to_string(&vtk).unwrap();
    assert!(text.contains("VECTORS displacement double") && text.contains("VECTORS force double"));
    let medit = solved("sag.mesh");
    let text = std::fs::read_to_string(&medit).unwrap();
    assert!(text.starts_with("MeshVersionFormatted 2") && text.contains("Tetrahedra"));
    // meshio, an independent reader, reads every file solve wrote: the
    // counts of the JSON, the displacement's largest length, the vertices'
    // original ids (the generated box was renumbered) as a permutation.
    let seen = system_tests::meshio_describe(&[&vtu, &vtk, &medit, &obj, &stl]);
    let (tets, max_u) = (v["tets"].clone(), v["max_displacement_m"].as_f64().unwrap());
    for s in &seen[..2] {
        assert_eq!(s["tetrahedra"], tets, "{s}");
        let u = s["point_data"]["displacement"]["max_norm"]
            .as_f64()
            .unwrap();
        assert!((u - max_u).abs() <= 1e-12 * max_u, "{s}: {u} vs {max_u}");
        assert_eq!(s["point_data"]["force"]["shape"][1], 3, "{s}");
        assert_eq!(s["point_data"]["original_id"]["permutation"], true, "{s}");
    }
    // VTK's own readers (what ParaView uses) read the same from VTU and
    // legacy VTK, every array included.
    let n = v["vertices"].as_u64().unwrap() as f64;
    for s in system_tests::vtk_describe(&[&vtu, &vtk]) {
        assert_eq!(s["tetrahedra"], tets, "{s}");
        let u = s["point_data"]["displacement"]["max_norm"]
            .as_f64()
            .unwrap();
        assert!((u - max_u).abs() <= 1e-12 * max_u, "{s}: {u} vs {max_u}");
        assert_eq!(s["point_data"]["force"]["components"], 3, "{s}");
        assert_eq!(
            s["point_data"]["original_id"]["range"],
            serde_json::json!([0.0, n - 1.0]),
            "{s}"
        );
    }
    assert_eq!(seen[2]["tetrahedra"], tets, "{}", seen[2]);
    assert_eq!(seen[3]["triangles"], count, "{}", seen[3]);
    assert_eq!(seen[4]["triangles"], count, "{}", seen[4]);
    // Any other extension is refused before solving, naming what works.
    let (ply, out) = solve_to("sag.ply");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(".ply") && err.contains(".vtu") && !ply.exists(),
        "{err}"
    );
}

#[test]
fn run_takes_every_backend_and_refuses_unknown_ones() {
    let dir = scratch_dir("run-backend");
    let json = dir.join("implicit.json");
    let session = format!("implicit{}", std::process::id());
    run_ok(
        Command::new(binary("sim-server"))
            .args(["run", "--backend", "implicit", "--headless", "--quiet"])
            .args(["--steps", "200", "--session", &session])
            .arg("--json")
            .arg(&json),
    );
    let v = read_json(&json);
    assert_eq!(v["steps"], 200);
    assert!(v["finite"].as_bool().unwrap());
    // Precomputed: the responses are computed once, then read from the cache.
    for round in 0..2 {
        let out = Command::new(binary("sim-server"))
            .args(["run", "--backend", "precomputed", "--headless", "--quiet"])
            .args(["--steps", "100", "--session", &session])
            .env("XDG_CACHE_HOME", dir.join("cache"))
            .output()
            .expect("run sim-server");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        assert_eq!(err.contains("read from the cache"), round == 1, "{err}");
    }
    // Hybrid on the embedded liver (its [hybrid] section splits it): the
    // precomputed part's responses are cached the same way.
    for round in 0..2 {
        let out = Command::new(binary("sim-server"))
            .args(["run", "--backend", "hybrid", "--headless", "--quiet"])
            .args(["--steps", "100", "--session", &session])
            .env("XDG_CACHE_HOME", dir.join("cache"))
            .output()
            .expect("run sim-server");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        assert!(err.contains("shared vertices"), "{err}");
        assert_eq!(err.contains("read from the cache"), round == 1, "{err}");
    }
    // A scene asking for the hybrid without saying where to split: refused
    // at its [simulation] backend line.
    let scene = dir.join("unsplit.toml");
    std::fs::write(
        &scene,
        format!("{BLOCK}[simulation]\nbackend = \"hybrid\"\n"),
    )
    .unwrap();
    let err = run_err(
        Command::new(binary("sim-server"))
            .args(["run", "--headless", "--steps", "1", "--scene"])
            .arg(&scene),
    );
    assert!(
        err.contains("unsplit.toml:11:") && err.contains("[hybrid]"),
        "{err}"
    );
    let err = run_err(Command::new(binary("sim-server")).args([
        "run",
        "--backend",
        "hybird",
        "--headless",
        "--steps",
        "1",
    ]));
    assert!(
        err.contains("invalid value 'hybird'")
            && err.contains("[possible values: tensor-mass, implicit, precomputed, hybrid]"),
        "{err}"
    );
}

#[test]
fn static_backends_refuse_a_force_their_responses_cannot_carry() {
    let dir = scratch_dir("interior-load");
    let scene = dir.join("interior.toml");
    std::fs::write(
        &scene,
        format!(
            r#"{BLOCK}[[fixed]]
select = {{ box_m = [[-1, -1, -1], [0.0001, 1, 1]] }}

# The centre of the block: an interior vertex.
[[load]]
select = {{ sphere_m = [0.02, 0.01, 0.01, 0.001] }}
force_n = [0.0, 0.0, -0.01]

[hybrid]
select = {{ box_m = [[0.03, -1, -1], [1, 1, 1]] }}
"#
        ),
    )
    .unwrap();
    for backend in ["precomputed", "hybrid"] {
        let out = Command::new(binary("sim-server"))
            .args(["run", "--headless", "--steps", "1", "--backend", backend])
            .arg("--scene")
            .arg(&scene)
            .env("XDG_CACHE_HOME", dir.join("cache"))
            .output()
            .expect("run sim-server");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{backend}: {err}");
        assert!(
            err.contains(backend) && err.contains("surface") && err.contains("vertex"),
            "{backend}: {err}"
        );
    }
    // The explicit backend takes it.
    run_ok(
        Command::new(binary("sim-server"))
            .args(["run", "--headless", "--quiet", "--steps", "1", "--session"])
            .arg(format!("interior{}", std::process::id()))
            .arg("--scene")
            .arg(&scene),
    );
}

#[test]
fn a_diverging_run_still_writes_its_json() {
    // Twenty times the stable step, unchecked, under a load: the explicit
    // step blows up; the run stops with an error and its summary is kept.
    let dir = scratch_dir("run-diverged");
    let (scene, json) = (dir.join("unstable.toml"), dir.join("run.json"));
    std::fs::write(
        &scene,
        format!(
            "{BLOCK}[[load]]\nselect = {{ box_m = [[0.039, -1.0, -1.0], [1.0, 1.0, 1.0]] }}\nforce_n = [0.0, 0.0, -0.01]\n\n[simulation]\ndt_s = 0.02\ndt_policy = \"unchecked\"\n"
        ),
    )
    .unwrap();
    let session = format!("diverged{}", std::process::id());
    let out = Command::new(binary("sim-server"))
        .args(["run", "--headless", "--quiet", "--steps", "5000"])
        .args(["--session", &session, "--scene"])
        .arg(&scene)
        .arg("--json")
        .arg(&json)
        .output()
        .expect("run sim-server");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "a diverging run must fail: {err}");
    assert!(err.contains("diverged"), "{err}");
    let v = read_json(&json);
    assert_eq!(v["finite"], false, "{v}");
    assert!(v["steps"].as_u64().unwrap() > 0, "{v}");
}

/// The pids whose parent is `pid` (from /proc).
fn children_of(pid: u32) -> Vec<u32> {
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    entries
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter(|p| {
            std::fs::read_to_string(format!("/proc/{p}/stat"))
                .ok()
                .and_then(|s| {
                    // pid (comm) state ppid ...: comm may hold spaces.
                    let after = &s[s.rfind(')')? + 1..];
                    after.split_whitespace().nth(1)?.parse::<u32>().ok()
                })
                == Some(pid)
        })
        .collect()
}

#[test]
fn a_killed_demo_takes_its_haptic_daemon_with_it() {
    // SIGKILL leaves the demo no chance to clean up: its haptic daemon (a
    // device driver) must still not outlive it.
    let mut demo = Command::new(binary("sim-server"))
        .args(["demo", "--headless", "--no-viewer", "--duration-s", "30"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("start the demo");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    let daemon = loop {
        if let Some(&d) = children_of(demo.id()).first() {
            break d;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the demo started no daemon"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    std::thread::sleep(std::time::Duration::from_millis(500));
    demo.kill().unwrap();
    demo.wait().unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while std::path::Path::new(&format!("/proc/{daemon}")).exists()
        && std::fs::read_to_string(format!("/proc/{daemon}/stat"))
            .is_ok_and(|s| !s.contains(") Z "))
    {
        assert!(
            std::time::Instant::now() < deadline,
            "haptic-daemon {daemon} still runs 10 s after its demo was killed"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

#[test]
fn a_negative_number_gets_the_flags_own_message() {
    // Taken as a value (not as an unknown flag "-1") and refused by name.
    for (bin, sub) in [
        ("sim-server", "run"),
        ("sim-server", "bridge"),
        ("haptic-daemon", "run"),
    ] {
        let err = run_err(Command::new(binary(bin)).args([sub, "--duration-s", "-1"]));
        assert!(
            err.contains("--duration-s must be a positive number of seconds, got -1"),
            "{bin}: {err}"
        );
    }
}

/// The daemon's flags that were accepted out of range (clamped, or a
/// SCHED_FIFO call refused with the wrong advice), a recorder told to
/// write two streams into one file and a run told to record over the
/// trajectory it replays are refused up front, by name.
#[test]
fn the_daemon_refuses_flags_out_of_range_and_one_file_for_two_streams() {
    let dir = scratch_dir("daemon-flags");
    let same = dir.join("same.csv");
    let same_again = dir.join(".").join("same.csv");
    let traj = dir.join("press.csv");
    std::fs::write(&traj, "0,0,0,0.2\n1,0,0,0.2\n").unwrap();
    let replay = std::ffi::OsString::from(format!("replay:{}", traj.display()));
    let cases: [(Vec<&std::ffi::OsStr>, &str); 7] = [
        (
            vec![
                "run".as_ref(),
                "--device".as_ref(),
                replay.as_os_str(),
                "--record".as_ref(),
                traj.as_os_str(),
            ],
            "--record and --device name the same file",
        ),
        (
            vec![
                "run".as_ref(),
                "--record".as_ref(),
                same.as_os_str(),
                "--json".as_ref(),
                same_again.as_os_str(),
            ],
            "--record and --json name the same file",
        ),
        (
            vec!["run".as_ref(), "--rt-priority".as_ref(), "200".as_ref()],
            "not in 0..=99",
        ),
        (
            vec!["run".as_ref(), "--rt-priority=-1".as_ref()],
            "not in 0..=99",
        ),
        (
            vec!["run".as_ref(), "--spin-us".as_ref(), "100000".as_ref()],
            "--spin-us must be at most half the period (500 us at 1000 Hz)",
        ),
        (
            vec!["run".as_ref(), "--io-spin-us".as_ref(), "5000".as_ref()],
            "--io-spin-us must be at most the period",
        ),
        (
            vec![
                "record".as_ref(),
                "--forces".as_ref(),
                same.as_os_str(),
                "--telemetry".as_ref(),
                same_again.as_os_str(),
            ],
            "--forces and --telemetry name the same file",
        ),
    ];
    for (args, needle) in cases {
        let out = Command::new(binary("haptic-daemon"))
            .args(&args)
            .args(["--duration-s", "0.5"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(needle),
            "{args:?}: {err}"
        );
    }
    assert!(!same.exists(), "a refused recorder wrote nothing");
    assert_eq!(
        std::fs::read_to_string(&traj).unwrap(),
        "0,0,0,0.2\n1,0,0,0.2\n",
        "the trajectory is left as it was"
    );
}

/// Processes whose command line contains `needle` (from /proc).
fn processes_with(needle: &str) -> Vec<String> {
    std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| {
            let cmd = std::fs::read(e.ok()?.path().join("cmdline")).ok()?;
            let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
            cmd.contains(needle).then_some(cmd)
        })
        .collect()
}

#[test]
fn a_demo_killed_outright_leaves_no_daemon_and_no_file() {
    // SIGKILL gives the demo no chance to clean up: the kernel stops its
    // daemon (PR_SET_PDEATHSIG), and nothing was written to the temp
    // directory in the first place (pipes, not files).
    let tmp = scratch_dir("demo-tmp");
    let keep = tmp.join("hapsim-demo-notes.txt");
    std::fs::write(&keep, "not ours").unwrap();
    let mut demo = Command::new(binary("sim-server"))
        .args(["demo", "--headless", "--no-viewer", "--duration-s", "30"])
        .env("TMPDIR", &tmp)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let session = format!("--session demo{}", demo.id());
    // Running: its daemon is up.
    let start = std::time::Instant::now();
    while processes_with(&session).is_empty() {
        assert!(
            start.elapsed().as_secs() < 20,
            "the demo's daemon never started"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    std::thread::sleep(std::time::Duration::from_millis(500));
    demo.kill().unwrap();
    demo.wait().unwrap();
    let start = std::time::Instant::now();
    while !processes_with(&session).is_empty() {
        assert!(
            start.elapsed().as_secs() < 5,
            "the daemon outlived its demo: {:?}",
            processes_with(&session)
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let left: Vec<_> = std::fs::read_dir(&tmp)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, vec!["hapsim-demo-notes.txt".to_string()], "{left:?}");
}

#[test]
fn a_nonlinear_scene_runs_solves_and_is_refused_where_a_backend_cannot_run_it() {
    let dir = scratch_dir("nonlinear");
    let scene = dir.join("stvk.toml");
    std::fs::write(
        &scene,
        r#"[mesh]
generate = { shape = "box", size_m = [0.06, 0.02, 0.02], cell_m = 0.005 }

[material]
young_pa = 4500.0
poisson = 0.45
density_kg_m3 = 1060.0
damping_per_s = 30.0
model = "stvk"

[[fixed]]
select = { box_m = [[-1.0, -1.0, -1.0], [0.0001, 1.0, 1.0]] }

[[load]]
select = { box_m = [[0.0599, -1.0, -1.0], [1.0, 1.0, 1.0]] }
rotate = { axis = [1.0, 0.0, 0.0], origin_m = [0.0, 0.01, 0.01], angle_deg = 30.0 }
"#,
    )
    .unwrap();
    let session = format!("nonlin{}", std::process::id());
    let json = dir.join("run.json");
    run_ok(
        Command::new(binary("sim-server"))
            .args([
                "run",
                "--headless",
                "--quiet",
                "--steps",
                "100",
                "--session",
                &session,
            ])
            .arg("--scene")
            .arg(&scene)
            .arg("--json")
            .arg(&json),
    );
    let v = read_json(&json);
    assert_eq!(v["nonlinear_tets"], 1152);
    assert!(v["finite"].as_bool().unwrap());
    // Static equilibrium by Newton.
    let solved = dir.join("solve.json");
    run_ok(
        Command::new(binary("sim-server"))
            .arg("solve")
            .arg("--scene")
            .arg(&scene)
            .arg("--out")
            .arg(dir.join("twist.vtu"))
            .arg("--json")
            .arg(&solved),
    );
    let v = read_json(&solved);
    assert!(v["newton_iterations"].as_u64().unwrap() >= 10, "{v}");
    let reaction = v["total_reaction_n"].as_array().unwrap();
    assert!(
        reaction.iter().all(|r| r.as_f64().unwrap().abs() < 1e-9),
        "{v}"
    );
    // The implicit backend refuses, naming the model.
    let err = run_err(
        Command::new(binary("sim-server"))
            .args([
                "run",
                "--backend",
                "implicit",
                "--headless",
                "--quiet",
                "--steps",
                "10",
            ])
            .args(["--session", &session])
            .arg("--scene")
            .arg(&scene),
    );
    assert!(
        err.contains("implicit backend runs the linear model only"),
        "{err}"
    );
    assert!(err.contains("model = \"stvk\""), "{err}");
}

#[test]
fn save_frames_writes_a_series_or_says_why_it_cannot() {
    let dir = scratch_dir("save-frames");
    let frames = dir.join("run frames");
    let json = dir.join("run.json");
    let session = format!("frames{}", std::process::id());
    // Headless: 400 steps of 1 ms, a frame at 100 Hz: every 10th step, 40.
    let out = run_ok(
        Command::new(binary("sim-server"))
            .args(["run", "--headless", "--quiet", "--steps", "400"])
            .args(["--viewer-rate", "100", "--session", &session])
            .arg("--save-frames")
            .arg(&frames)
            .arg("--json")
            .arg(&json),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let pvd = std::fs::read_to_string(frames.join("frames.pvd")).unwrap();
    let listed = pvd.matches("<DataSet").count() as u64;
    let v = read_json(&json);
    let (saved, dropped) = (
        v["frames_saved"].as_u64().unwrap(),
        v["frames_dropped"].as_u64().unwrap(),
    );
    // Every frame published was saved or counted as dropped; the series
    // lists exactly the saved ones.
    assert_eq!(v["frames_published"], 40, "{v}");
    assert_eq!(saved + dropped, 40, "{v}");
    assert!(
        listed == saved && saved > 0 && stdout.contains(&format!("{listed} frames saved")),
        "{stdout}\n{pvd}"
    );
    assert!(!frames.join("frames.pvd.tmp").exists());
    assert!(frames.join(format!("frame_{:06}.vtu", listed - 1)).exists());
    // A directory that cannot be made: refused at start, naming the flag.
    let out = Command::new(binary("sim-server"))
        .args([
            "run",
            "--headless",
            "--quiet",
            "--steps",
            "10",
            "--session",
            &session,
        ])
        .args(["--save-frames", "/dev/null/frames"])
        .output()
        .expect("run sim-server");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--save-frames /dev/null/frames"),
        "{err}"
    );
}

#[test]
fn run_takes_the_step_from_the_command_line() {
    let dir = scratch_dir("run-dt");
    let json = dir.join("run.json");
    let session = format!("dt{}", std::process::id());
    let run = |dt: &str| {
        Command::new(binary("sim-server"))
            .args(["run", "--headless", "--quiet", "--steps", "400"])
            .args(["--dt-s", dt, "--session", &session])
            .arg("--json")
            .arg(&json)
            .output()
            .expect("run sim-server")
    };
    let out = run("0.00025");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = read_json(&json);
    let sim_time = v["sim_time_s"].as_f64().unwrap();
    assert!((sim_time - 0.1).abs() < 1e-12, "{v}");
    for bad in ["0", "-0.001", "NaN", "1"] {
        let out = run(bad);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains("--dt-s"),
            "{bad}: {err}"
        );
    }
}

#[test]
fn an_implicit_run_reports_its_linear_solves() {
    // A clamped block pulled at its free end: every step solves.
    let dir = scratch_dir("run-solves");
    let (scene, json) = (dir.join("pulled.toml"), dir.join("run.json"));
    std::fs::write(
        &scene,
        format!(
            "{BLOCK}[[fixed]]\nselect = {{ box_m = [[-0.001, -0.001, -0.001], [0.0001, 0.021, 0.021]] }}\n\n[[load]]\nselect = {{ box_m = [[0.0399, -0.001, -0.001], [0.041, 0.021, 0.021]] }}\nforce_n = [0.0, 0.0, -0.01]\n"
        ),
    )
    .unwrap();
    let session = format!("solves{}", std::process::id());
    let out = run_ok(
        Command::new(binary("sim-server"))
            .args(["run", "--backend", "implicit", "--headless", "--quiet"])
            .args(["--steps", "20", "--session", &session, "--scene"])
            .arg(&scene)
            .arg("--json")
            .arg(&json),
    );
    let v = read_json(&json);
    let mean = v["solve_iterations_mean"].as_f64().unwrap();
    assert!(
        mean > 0.0 && v["solve_iterations_max"].as_u64().unwrap() >= 1,
        "{v}"
    );
    assert!(v["solve_capped_steps"].is_u64(), "{v}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("linear solves:") && stdout.contains("--implicit-iterations budget"),
        "{stdout}"
    );
}

#[test]
fn run_asks_for_sched_fifo_and_says_what_it_got() {
    let dir = scratch_dir("run-rt");
    let json = dir.join("rt.json");
    let session = format!("rt{}", std::process::id());
    // Real time only: a headless run never sleeps and would hold a core.
    let err = run_err(Command::new(binary("sim-server")).args([
        "run",
        "--headless",
        "--steps",
        "1",
        "--rt-priority",
        "10",
    ]));
    assert!(
        err.contains("--rt-priority") && err.contains("--headless"),
        "{err}"
    );
    let out = Command::new(binary("sim-server"))
        .args(["run", "--quiet", "--steps", "50"])
        .args(["--rt-priority", "10", "--session", &session])
        .arg("--json")
        .arg(&json)
        .output()
        .expect("run sim-server");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let v = read_json(&json);
    assert_eq!(v["steps"], 50);
    // Every step after the first was predicted while the loop waited.
    assert_eq!(v["predicted_steps"], 49, "{v}");
    assert!(v["predicted_rows"].is_u64(), "{v}");
    // Granted where the user may (root, CAP_SYS_NICE, an rtprio limit);
    // refused, the run goes on at normal priority and says how to grant it.
    match v["rt_priority"].as_i64() {
        Some(10) => assert!(!err.contains("SCHED_FIFO refused"), "{err}"),
        Some(0) => assert!(
            err.contains("SCHED_FIFO refused") && err.contains("CAP_SYS_NICE"),
            "{err}"
        ),
        other => panic!("rt_priority {other:?}"),
    }
    let err = run_err(Command::new(binary("sim-server")).args([
        "run",
        "--headless",
        "--steps",
        "1",
        "--rt-priority",
        "99",
    ]));
    assert!(
        err.contains("--rt-priority") && err.contains("0..=98"),
        "{err}"
    );
}

#[test]
fn run_takes_the_contact_law_and_a_backend_refuses_one_it_cannot_run() {
    let dir = scratch_dir("run-law");
    let scene = dir.join("probe.toml");
    let probe = r#"[[fixed]]
name = "bottom"
select = { box_m = [[-0.001, -0.001, -0.001], [0.041, 0.021, 0.0001]] }

[[tool]]
name = "probe"
kind = "hook"
fulcrum_m = [0.02, 0.01, 0.15]
length_m = 0.3
radius_m = 0.0025
tip_length_m = 0.01
"#;
    std::fs::write(&scene, format!("{BLOCK}{probe}")).unwrap();
    let session = format!("law{}", std::process::id());
    for (backend, law, expect) in [
        ("tensor-mass", None, "penalty"),
        ("tensor-mass", Some("projection"), "projection"),
        ("precomputed", None, "penalty"),
        ("precomputed", Some("projection"), "projection"),
    ] {
        let json = dir.join(format!("{backend}-{expect}.json"));
        let mut cmd = Command::new(binary("sim-server"));
        cmd.args(["run", "--headless", "--quiet", "--steps", "5"])
            .args(["--session", &session, "--backend", backend, "--scene"])
            .arg(&scene)
            .arg("--json")
            .arg(&json)
            .env("XDG_CACHE_HOME", dir.join("cache"));
        if let Some(law) = law {
            cmd.args(["--contact-law", law]);
        }
        run_ok(&mut cmd);
        assert_eq!(read_json(&json)["contact_law"], expect, "{backend} {law:?}");
    }
    let err = run_err(
        Command::new(binary("sim-server"))
            .args(["run", "--headless", "--steps", "1", "--session", &session])
            .args([
                "--backend",
                "implicit",
                "--contact-law",
                "penalty",
                "--scene",
            ])
            .arg(&scene),
    );
    assert!(
        err.contains("the implicit backend has only the projection law"),
        "{err}"
    );
}
