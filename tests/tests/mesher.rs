//! `sim-server mesh`: surfaces the test writes (a closed sphere in
//! millimetres, one with a hole, two overlapping blobs in one file, a
//! self-intersecting pair) become tetrahedra `sim-server check` accepts,
//! with their faults said; bad requests are refused with the reason and a
//! mesher that runs out of time is stopped.

use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use system_tests::{binary, read_json, scratch_dir};

/// A surface: vertices and triangles (0-based).
type Surface = (Vec<[f64; 3]>, Vec<[usize; 3]>);

/// A UV sphere (`rings` x 2 `rings`) of `radius` about `centre`, its
/// triangles turned outward.
fn sphere(centre: [f64; 3], radius: f64, rings: usize) -> Surface {
    let cols = 2 * rings;
    let mut v = vec![[centre[0], centre[1], centre[2] + radius]];
    for r in 1..rings {
        let th = std::f64::consts::PI * r as f64 / rings as f64;
        for c in 0..cols {
            let ph = 2.0 * std::f64::consts::PI * c as f64 / cols as f64;
            v.push([
                centre[0] + radius * th.sin() * ph.cos(),
                centre[1] + radius * th.sin() * ph.sin(),
                centre[2] + radius * th.cos(),
            ]);
        }
    }
    v.push([centre[0], centre[1], centre[2] - radius]);
    let idx = |r: usize, c: usize| 1 + r * cols + c % cols;
    let last = v.len() - 1;
    let mut f = Vec::new();
    for c in 0..cols {
        f.push([0, idx(0, c), idx(0, c + 1)]);
        f.push([idx(rings - 2, c), last, idx(rings - 2, c + 1)]);
    }
    for r in 0..rings - 2 {
        for c in 0..cols {
            let (a, b, d, e) = (idx(r, c), idx(r + 1, c), idx(r + 1, c + 1), idx(r, c + 1));
            f.push([a, b, d]);
            f.push([a, d, e]);
        }
    }
    (v, f)
}

/// Writes OBJ (1-based faces).
fn write_obj(path: &Path, parts: &[Surface]) {
    let mut s = String::new();
    let mut base = 1;
    for (v, f) in parts {
        for p in v {
            let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
        }
        for t in f {
            let _ = writeln!(s, "f {} {} {}", t[0] + base, t[1] + base, t[2] + base);
        }
        base += v.len();
    }
    std::fs::write(path, s).unwrap();
}

fn mesh(args: &[&str]) -> Output {
    Command::new(binary("sim-server"))
        .arg("mesh")
        .args(args)
        .output()
        .expect("run sim-server mesh")
}

/// `sim-server check PATH` with the cache in `cache` (None: the user's):
/// whether it succeeded and what it said.
fn check(path: &Path, cache: Option<&Path>) -> (bool, String) {
    let mut cmd = Command::new(binary("sim-server"));
    cmd.arg("check").arg(path);
    if let Some(c) = cache {
        cmd.env("XDG_CACHE_HOME", c);
    }
    let o = cmd.output().expect("run sim-server check");
    (o.status.success(), text(&o))
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Meshes `surface` at 20 mm into `out`, expecting success; the report.
fn mesh_ok(surface: &Path, out: &Path, extra: &[&str]) -> (serde_json::Value, String) {
    mesh_all(&[surface], "0.02", out, extra)
}

/// `sim-server mesh SURFACES --cell-m CELL --out OUT --json` (plus
/// `extra`), which must succeed: its report and output.
fn mesh_all(
    surfaces: &[&Path],
    cell_m: &str,
    out: &Path,
    extra: &[&str],
) -> (serde_json::Value, String) {
    let json = out.with_extension("json");
    let args: Vec<&str> = surfaces
        .iter()
        .map(|s| s.to_str().unwrap())
        .chain([
            "--cell-m",
            cell_m,
            "--out",
            out.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
        ])
        .chain(extra.iter().copied())
        .collect();
    let o = mesh(&args);
    assert!(o.status.success(), "{}", text(&o));
    (read_json(&json), text(&o))
}

/// `sim-server check` of a scene on `mesh_file` (with `regions`, TOML
/// placed before `[simulation]`): its output.
fn check_scene(dir: &Path, mesh_file: &Path, regions: &str) -> String {
    let scene: PathBuf = dir.join(format!(
        "{}.toml",
        mesh_file.file_stem().unwrap().to_string_lossy()
    ));
    std::fs::write(
        &scene,
        format!(
            "[mesh]\nfile = {:?}\n\n[material]\nyoung_pa = 4500.0\npoisson = 0.45\ndensity_kg_m3 = 1060.0\n\n{regions}[simulation]\ndt_s = 0.001\n",
            mesh_file.display().to_string()
        ),
    )
    .unwrap();
    let (ok, said) = check(&scene, None);
    assert!(ok, "{said}");
    said
}

#[test]
fn a_closed_surface_in_millimetres_becomes_a_checked_organ() {
    let dir = scratch_dir("mesher-closed");
    let surface = dir.join("ball.obj");
    // 50 mm radius, written in millimetres as a segmentation would be.
    write_obj(&surface, &[sphere([0.0; 3], 50.0, 16)]);
    let out = dir.join("ball.msh");
    let (report, said) = mesh_ok(&surface, &out, &[]);
    assert!(said.contains("read as millimetres"), "{said}");
    // fTetWild writes a scratch file where it runs: not here.
    let stray = Path::new(env!("CARGO_MANIFEST_DIR")).join("__tracked_surface.stl");
    assert!(!stray.exists(), "the mesher left {}", stray.display());
    assert_eq!(report["scale"], 1e-3, "{report}");
    let tets = report["tets"].as_u64().unwrap();
    assert!(tets > 300, "{report}");
    assert_eq!(report["inputs"][0]["boundary_edges"], 0, "closed: {report}");
    // The result loads as a scene and is a ball of 50 mm radius.
    let checked = check_scene(&dir, &out, "");
    assert!(checked.contains("stable step"), "{checked}");
    assert!(!checked.contains("inverted"), "{checked}");
    let hi = report["bounds_m"][1][0].as_f64().unwrap();
    assert!((hi - 0.05).abs() < 1e-3, "{report}");
    // The quality pass: reported before and after, and what it reports is
    // the bound the scene's check finds on the written file (same
    // material).
    let before = report["improve"]["before_dt_s"].as_f64().unwrap();
    let after = report["improve"]["after_dt_s"].as_f64().unwrap();
    assert!(after >= before, "{report}");
    let step: f64 = checked
        .lines()
        .find_map(|l| l.strip_prefix("stable step: "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{checked}"));
    assert!(
        (step / after - 1.0).abs() < 1e-3,
        "check {step} s, report {after} s"
    );
    assert!(said.contains("quality pass"), "{said}");
    // The mesher's quality: no sliver below 5 degrees.
    let line = said
        .lines()
        .find(|l| l.starts_with("dihedral angles"))
        .unwrap();
    let min: f64 = line.split_whitespace().nth(2).unwrap().parse().unwrap();
    assert!(min > 5.0, "{line}");
}

#[test]
fn a_holed_surface_is_meshed_and_its_hole_located_and_overlaps_are_meshed_as_one() {
    let dir = scratch_dir("mesher-messy");
    // A hole: the triangles around the north pole removed.
    let (v, f) = sphere([0.0; 3], 0.05, 16);
    let open: Vec<[usize; 3]> = f.into_iter().filter(|t| !t.contains(&0)).collect();
    let holed = dir.join("holed.obj");
    write_obj(&holed, &[(v, open)]);
    let (report, said) = mesh_ok(&holed, &dir.join("holed.msh"), &["--units", "m"]);
    let hole = &report["inputs"][0]["holes"][0];
    let z = hole["centre"][2].as_f64().unwrap();
    assert!(z > 0.045, "the hole is at the north pole: {report}");
    assert!(said.contains("warning: a hole"), "{said}");
    assert!(report["tets"].as_u64().unwrap() > 300, "{report}");
    // Two overlapping blobs in one file (each closed, intersecting the
    // other): one volume.
    let blobs = dir.join("blobs.obj");
    write_obj(
        &blobs,
        &[
            sphere([0.0; 3], 0.04, 14),
            sphere([0.035, 0.0, 0.0], 0.03, 14),
        ],
    );
    let out = dir.join("blobs.msh");
    let (report, _) = mesh_ok(&blobs, &out, &["--units", "m"]);
    let lo = report["bounds_m"][0][0].as_f64().unwrap();
    let hi = report["bounds_m"][1][0].as_f64().unwrap();
    assert!(
        (lo + 0.04).abs() < 1e-3 && (hi - 0.065).abs() < 1e-3,
        "{report}"
    );
    let checked = check_scene(&dir, &out, "");
    assert!(checked.contains("1 component(s)"), "one volume: {checked}");
    // A self-intersecting shell: the north pole pulled down through the
    // ball to 70 mm below its centre, its fan of triangles crossing the
    // rest (a segmentation's spike folded through): meshed all the same.
    let (mut v, f) = sphere([0.0; 3], 0.05, 16);
    v[0] = [0.0, 0.0, -0.07];
    let folded = dir.join("folded.obj");
    write_obj(&folded, &[(v, f)]);
    let out = dir.join("folded.msh");
    let (report, _) = mesh_ok(&folded, &out, &["--units", "m"]);
    assert!(report["tets"].as_u64().unwrap() > 300, "{report}");
    let checked = check_scene(&dir, &out, "");
    assert!(!checked.contains("inverted"), "{checked}");
}

#[test]
fn an_inner_surface_becomes_a_physical_tag_a_scene_region_selects() {
    let dir = scratch_dir("mesher-tags");
    let organ = dir.join("organ.obj");
    let tumour = dir.join("tumour.obj");
    write_obj(&organ, &[sphere([0.0; 3], 0.05, 16)]);
    // A 20 mm tumour off centre: 6.4% of the organ's volume.
    write_obj(&tumour, &[sphere([0.015, 0.0, 0.0], 0.02, 12)]);
    let out = dir.join("tagged.msh");
    let (report, said_mesh) = mesh_all(&[&organ, &tumour], "0.012", &out, &["--units", "m"]);
    let two = report["tags"]["2"].as_u64().unwrap() as f64;
    // The tagged tetrahedra fill the tumour: their volume is its enclosed
    // volume (the surface's, from the report) to within the cells'
    // staircase.
    let tagged = report["tag_volumes_m3"]["2"].as_f64().unwrap();
    let enclosed = report["inputs"][1]["volume_m3"].as_f64().unwrap();
    assert!(
        (tagged / enclosed - 1.0).abs() < 0.15,
        "tagged {tagged} m3 against the tumour's {enclosed} m3: {report}"
    );
    assert!(said_mesh.contains("2 ("), "{said_mesh}");
    // A scene gives the tumour its own stiffness by the tag.
    let said = check_scene(
        &dir,
        &out,
        "[[region]]\nname = \"tumour\"\nselect = { physical = 2 }\nyoung_pa = 40000.0\n\n",
    );
    let line = said
        .lines()
        .find(|l| l.contains("tumour"))
        .unwrap_or_else(|| panic!("{said}"));
    assert!(line.contains(&format!("{}", two as u64)), "{line}\n{said}");
}

#[test]
fn a_scene_meshes_its_surface_at_load_once_and_reads_the_cache_after() {
    let dir = scratch_dir("mesher-scene");
    write_obj(&dir.join("ball.obj"), &[sphere([0.0; 3], 50.0, 16)]);
    let scene = |cell: &str| {
        let path = dir.join(format!("ball-{cell}.toml"));
        std::fs::write(
            &path,
            format!(
                "[mesh]\nsurface = \"ball.obj\"\ncell_m = {cell}\nunits = \"mm\"\n\n[material]\nyoung_pa = 4500.0\npoisson = 0.45\ndensity_kg_m3 = 1060.0\n\n[simulation]\ndt_s = 0.001\n"
            ),
        )
        .unwrap();
        path
    };
    let cache = dir.join("cache");
    let check_cached = |path: &Path| {
        let (ok, said) = check(path, Some(&cache));
        assert!(ok, "{said}");
        said
    };
    let cached = |n: usize| {
        let d = dir.join("cache/hapsim/meshes");
        let files = std::fs::read_dir(&d).map_or(0, |r| r.count());
        assert_eq!(files, n, "{}", d.display());
    };
    let first = check_cached(&scene("0.02"));
    assert!(first.contains("meshed by fTetWild"), "{first}");
    assert!(first.contains("stable step"), "{first}");
    cached(1);
    let again = check_cached(&scene("0.02"));
    assert!(again.contains("meshed surface, cached"), "{again}");
    assert!(!again.contains("meshed by fTetWild"), "{again}");
    cached(1);
    // Another size is another mesh.
    let finer = check_cached(&scene("0.018"));
    assert!(finer.contains("meshed by fTetWild"), "{finer}");
    cached(2);
    // `cell_m` without a surface is refused at its line.
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        "[mesh]\nfile = \"ball.msh\"\ncell_m = 0.01\n\n[material]\nyoung_pa = 4500.0\npoisson = 0.45\ndensity_kg_m3 = 1060.0\n",
    )
    .unwrap();
    let (ok, said) = check(&bad, None);
    assert!(!ok);
    assert!(said.contains("bad.toml:3"), "{said}");
    assert!(said.contains("size a `surface`"), "{said}");
}

#[test]
fn a_scene_rotates_then_moves_its_organ_under_the_tools() {
    let dir = scratch_dir("mesher-place");
    let write = |name: &str, place: &str| {
        let path = dir.join(name);
        std::fs::write(
            &path,
            format!(
                "[mesh]\ngenerate = {{ shape = \"box\", size_m = [0.1, 0.2, 0.05], cell_m = 0.025 }}\n{place}\n[material]\nyoung_pa = 4500.0\npoisson = 0.45\ndensity_kg_m3 = 1060.0\n"
            ),
        )
        .unwrap();
        check(&path, None)
    };
    let extent = |said: &str| -> Vec<f64> {
        let line = said.lines().find(|l| l.starts_with("extent:")).unwrap();
        line.replace(['[', ']', ','], " ")
            .split_whitespace()
            .filter_map(|w| w.parse().ok())
            .take(6)
            .collect()
    };
    let (ok, plain) = write("plain.toml", "");
    assert!(ok, "{plain}");
    let (ok, placed) = write(
        "placed.toml",
        "rotate_deg = [0.0, 0.0, 90.0]\ntranslate_m = [0.01, 0.0, 0.3]",
    );
    assert!(ok, "{placed}");
    let (a, b) = (extent(&plain), extent(&placed));
    // x' = -y + 0.01, y' = x, z' = z + 0.3.
    let want = [
        -a[4] + 0.01,
        a[0],
        a[2] + 0.3,
        -a[1] + 0.01,
        a[3],
        a[5] + 0.3,
    ];
    for (k, (got, w)) in b.iter().zip(want).enumerate() {
        assert!((got - w).abs() < 2e-4, "extent[{k}] {got} vs {w}: {placed}");
    }
    let (ok, bad) = write("bad.toml", "translate_m = [0.0, 50.0, 0.0]");
    assert!(
        !ok && bad.contains("bad.toml:3") && bad.contains("more than"),
        "{bad}"
    );
}

#[test]
fn bad_requests_are_refused_with_the_reason_and_a_slow_mesher_is_stopped() {
    let dir = scratch_dir("mesher-bad");
    let surface = dir.join("ball.obj");
    write_obj(&surface, &[sphere([0.0; 3], 0.05, 16)]);
    let out = dir.join("ball.msh");
    let s = surface.to_str().unwrap();
    let o = out.to_str().unwrap();
    for (args, says) in [
        (
            vec!["missing.stl", "--cell-m", "0.01", "--out", o],
            "no such file",
        ),
        (
            vec![s, "--cell-m", "0.01", "--out", "ball.txt"],
            ".msh, .vtu",
        ),
        (vec![s, "--cell-m", "-1", "--out", o], "--cell-m must be"),
        (
            vec![s, "--cell-m", "0.0002", "--out", o],
            "exceeds the limit",
        ),
        (
            vec![s, "--cell-m", "0.004", "--out", o, "--time-limit-s", "0.5"],
            "did not finish within 0.5 s",
        ),
    ] {
        let r = mesh(&args);
        assert!(!r.status.success(), "{args:?}: {}", text(&r));
        assert!(text(&r).contains(says), "{args:?}: {}", text(&r));
        assert!(!text(&r).contains("panicked"), "{}", text(&r));
    }
    // The stopped mesher is gone, interpreter and all (a launcher such as
    // pyenv's shim runs it as a child of its own).
    std::thread::sleep(std::time::Duration::from_millis(300));
    let left = Command::new("pgrep")
        .args(["-f", &dir.display().to_string()])
        .output()
        .expect("pgrep");
    assert!(
        left.stdout.is_empty(),
        "a mesher still runs: {}",
        String::from_utf8_lossy(&left.stdout)
    );
    let not_surface = dir.join("table.csv");
    std::fs::write(&not_surface, "a,b\n1,2\n").unwrap();
    let r = mesh(&[
        not_surface.to_str().unwrap(),
        "--cell-m",
        "0.01",
        "--out",
        o,
    ]);
    assert!(
        text(&r).contains("table.csv") && text(&r).contains("not a surface format"),
        "{}",
        text(&r)
    );
}

/// A closed tube of `radius` from `a` to `b` (along x), `n` sides.
fn tube(a: f64, b: f64, radius: f64, n: usize) -> Surface {
    let mut v = vec![[a, 0.0, 0.0], [b, 0.0, 0.0]];
    let mut f = Vec::new();
    for i in 0..n {
        let t = std::f64::consts::TAU * i as f64 / n as f64;
        v.push([a, radius * t.cos(), radius * t.sin()]);
        v.push([b, radius * t.cos(), radius * t.sin()]);
    }
    for i in 0..n {
        let j = (i + 1) % n;
        let (a0, b0, a1, b1) = (2 + 2 * i, 3 + 2 * i, 2 + 2 * j, 3 + 2 * j);
        f.push([0, a1, a0]);
        f.push([1, b0, b1]);
        f.push([a0, a1, b1]);
        f.push([a0, b1, b0]);
    }
    (v, f)
}

#[test]
fn a_vessel_surface_meshed_with_the_organ_sets_its_fibres_along_it() {
    let dir = scratch_dir("mesher-vessel");
    let organ = dir.join("organ.obj");
    let vessel = dir.join("vessel.obj");
    write_obj(&organ, &[sphere([0.0; 3], 0.05, 16)]);
    // A 16 mm-wide vessel along x across most of the organ.
    write_obj(&vessel, &[tube(-0.035, 0.035, 0.008, 16)]);
    let out = dir.join("vessel.vtu");
    let (report, _) = mesh_all(&[&organ, &vessel], "0.006", &out, &["--units", "m"]);
    let tagged = report["tags"]["2"].as_u64().unwrap();
    assert!(tagged > 50, "{report}");
    let said = check_scene(
        &dir,
        &out,
        "[[vessel]]\nname = \"portal\"\nselect = { physical = 2 }\nyoung_fiber_pa = 9000.0\nshear_fiber_pa = 3000.0\n\n",
    );
    let line = said
        .lines()
        .find(|l| l.contains("[[vessel]] \"portal\""))
        .unwrap_or_else(|| panic!("{said}"));
    assert!(line.contains(&format!("{tagged} tetrahedra")), "{line}");
    assert!(!said.contains("do not form a tube"), "{said}");
}
