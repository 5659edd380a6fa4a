//! Surfaces to tetrahedra: `sim-server mesh SURFACE... --cell-m H | --tets N`.
//!
//! Labs get organs from CT segmentations as closed triangle surfaces (3D
//! Slicer writes STL, OBJ, PLY, VTK/VTP, usually in millimetres), with
//! small holes, self-intersections and spikes. The mesher is fTetWild (Hu,
//! Schneider, Wang, Zorin, Panozzo 2020, "Fast Tetrahedral Meshing in the
//! Wild", ACM TOG 39(4); MPL-2.0), made for exactly such inputs: it meshes
//! within an envelope of the input, so a hole or an intersection does not
//! stop it, and it optimises the elements' quality (AMIPS energy) as it
//! goes, which is what keeps slivers out of the explicit step. It runs as a
//! separate Python process (the `pytetwild` wheel, installed by
//! `scripts/setup.sh`) with a time limit, and the surfaces' faults (holes
//! with their centres, non-manifold edges with their end points) are
//! reported before it runs. Why not the others: TetGen is AGPL (not as a
//! linked dependency) and needs a clean, closed, non-intersecting input;
//! Gmsh (GPL, usable as a process), measured on the same surfaces
//! (docs/guide/own-organ.md), was faster on a clean organ, but gave no mesh
//! for a holed sphere and refused two overlapping ones.
//!
//! fTetWild's result is then improved for the explicit step by
//! [`crate::mesh::improve`] (its worst elements' vertices moved, Irons'
//! element bound as the objective) and written by sim-server's own writers
//! in the format asked for, the tags kept.
//!
//! Several surfaces: the first is the organ, each later one (a vessel, a
//! tumour) becomes a physical tag (2, 3, ...) on the tetrahedra whose
//! centroid it encloses (by the generalised winding number), so scene
//! regions can select it (`select = { physical = 2 }`).
//!
//! ```no_run
//! use sim_server::mesh::tetrahedralize::{MeshRequest, Size, tetrahedralize};
//! let req = MeshRequest::new(vec!["liver.stl".into()], Size::CellM(0.008), "liver.msh".into());
//! let report = tetrahedralize(&req).unwrap();
//! println!("{} tetrahedra in {:.1} s", report.tets, report.seconds);
//! ```

use crate::mesh::improve::{ImproveOptions, ImproveReport, improve_for_step};
use serde::{Deserialize, Serialize};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The worker script (run with `python3 -c`).
const SCRIPT: &str = include_str!("tetwild.py");

/// The most tetrahedra a request may ask for (about 1 GB of mesher memory).
pub const MAX_TETS: usize = 2_000_000;

/// How fine the result is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Size {
    /// The ideal edge length (m).
    CellM(f64),
    /// About this many tetrahedra.
    Tets(usize),
}

/// The inputs' units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Units {
    /// Metres.
    M,
    /// Millimetres (3D Slicer's default).
    Mm,
}

impl std::str::FromStr for Units {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "m" => Ok(Units::M),
            "mm" => Ok(Units::Mm),
            _ => Err(format!("{s:?}: the units are m or mm")),
        }
    }
}

/// One meshing job.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshRequest {
    /// The surfaces (the first is the organ; more are merged into it).
    pub surfaces: Vec<PathBuf>,
    /// How fine.
    pub size: Size,
    /// The inputs' units (None: millimetres when the first surface is
    /// larger than [`MM_DETECT_EXTENT`] "metres", said in the report).
    pub units: Option<Units>,
    /// Where the tetrahedra go (.msh, .vtu, .vtk, .mesh).
    pub out: PathBuf,
    /// The mesher is stopped after this long (s).
    pub time_limit_s: f64,
    /// Mesher threads.
    pub threads: usize,
    /// Whether the quality pass ([`crate::mesh::improve`]) runs after
    /// fTetWild.
    pub improve: bool,
}

/// An input larger than this (m) along any axis is taken as millimetres.
pub const MM_DETECT_EXTENT: f64 = 5.0;

impl MeshRequest {
    /// A request with the defaults: units detected, 300 s, 2 threads, the
    /// quality pass on.
    pub fn new(surfaces: Vec<PathBuf>, size: Size, out: PathBuf) -> Self {
        Self {
            surfaces,
            size,
            units: None,
            out,
            time_limit_s: 300.0,
            threads: 2,
            improve: true,
        }
    }
}

/// One input surface as read.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SurfaceReport {
    /// The file.
    pub path: String,
    /// Vertices after merging duplicates.
    pub vertices: usize,
    /// Triangles.
    pub triangles: usize,
    /// Its enclosed volume (m^3; meaningful when closed).
    pub volume_m3: f64,
    /// Edges with one triangle (0: closed).
    pub boundary_edges: usize,
    /// The holes (loops of boundary edges): centre (m) and edge count.
    pub holes: Vec<Hole>,
    /// Edges with more than two triangles.
    pub nonmanifold_edges: usize,
    /// Up to 20 of them, by their end points (m).
    pub nonmanifold: Vec<[[f64; 3]; 2]>,
}

/// A hole in a surface.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Hole {
    /// The centre of its boundary's vertices (m).
    pub centre: [f64; 3],
    /// Boundary vertices around it.
    pub edges: usize,
}

/// What meshing made.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshReport {
    /// The surfaces as read.
    pub inputs: Vec<SurfaceReport>,
    /// The ideal edge length used (m).
    pub edge_length_m: f64,
    /// Vertices of the result.
    pub vertices: usize,
    /// Tetrahedra of the result.
    pub tets: usize,
    /// The mesher's time (s).
    pub seconds: f64,
    /// The inputs' bounds after scaling (m).
    pub bounds_m: [[f64; 3]; 2],
    /// The scale applied to the inputs (1e-3: millimetres).
    #[serde(default)]
    pub scale: f64,
    /// Whether the units were detected (not given).
    #[serde(default)]
    pub units_detected: bool,
    /// Tetrahedra per physical tag: "1" the organ (the first surface), "2"
    /// and on those whose centroid a later surface encloses.
    #[serde(default)]
    pub tags: std::collections::BTreeMap<String, usize>,
    /// The volume of each tag's tetrahedra (m^3).
    #[serde(default)]
    pub tag_volumes_m3: std::collections::BTreeMap<String, f64>,
    /// The quality pass after fTetWild: the element stable step before and
    /// after, at [`REFERENCE_MATERIAL`] (None when it did not run).
    #[serde(default)]
    pub improve: Option<ImproveReport>,
}

/// The material the quality pass's bound is computed for: a soft
/// parenchyma, E 4.5 kPa, nu 0.45, rho 1060 kg/m^3 (the step of another
/// material scales with sqrt(rho / E); the ratio before / after depends
/// only on nu).
pub const REFERENCE_MATERIAL: (f64, f64, f64) = (4500.0, 0.45, 1060.0);

/// Why meshing failed.
#[derive(Debug, thiserror::Error)]
pub enum TetrahedralizeError {
    /// A request that cannot be run.
    #[error("{0}")]
    Request(String),
    /// An input that cannot be read.
    #[error("{path}: {reason}")]
    Input {
        /// The file.
        path: String,
        /// Why.
        reason: String,
    },
    /// The mesher is not installed.
    #[error("{0}")]
    Missing(String),
    /// The result would be too large.
    #[error("{0}")]
    TooLarge(String),
    /// The mesher ran out of time.
    #[error(
        "the mesher did not finish within {limit_s} s (--time-limit-s): ask for a larger --cell-m or fewer --tets, or allow more time"
    )]
    TimedOut {
        /// The limit (s).
        limit_s: f64,
    },
    /// The mesher failed.
    #[error("the mesher failed: {0}")]
    Failed(String),
    /// The worker could not be started.
    #[error("cannot run python3 (the mesher's worker): {0}")]
    Spawn(#[source] std::io::Error),
    /// The mesher's result could not be read back or written out.
    #[error(transparent)]
    Io(Box<crate::mesh::io::MeshIoError>),
}

impl From<crate::mesh::io::MeshIoError> for TetrahedralizeError {
    fn from(e: crate::mesh::io::MeshIoError) -> Self {
        // Boxed: the mesh error is large and this is the cold path.
        Self::Io(Box::new(e))
    }
}

/// Where hapsim keeps what it computed and can compute again (precomputed
/// responses, meshes made from a scene's `surface`):
/// `$XDG_CACHE_HOME/hapsim`, else `~/.cache/hapsim` (none without a home).
pub fn cache_dir() -> Option<PathBuf> {
    std::env::var_os("XDG_CACHE_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .map(|d| d.join("hapsim"))
}

/// The cache key of `req` without its output: an FNV-1a hash of the
/// worker (so a changed mesher is a miss), each surface's bytes, the size
/// and the units. Unreadable surfaces are the caller's error.
pub fn cache_key(req: &MeshRequest) -> Result<u64, TetrahedralizeError> {
    use tissue::backend::{FNV_OFFSET, fnv};
    let mut h = fnv(SCRIPT.bytes(), FNV_OFFSET);
    for s in &req.surfaces {
        let bytes = std::fs::read(s).map_err(|e| TetrahedralizeError::Input {
            path: s.display().to_string(),
            reason: e.to_string(),
        })?;
        h = fnv(bytes.len().to_le_bytes().into_iter(), h);
        h = fnv(bytes.into_iter(), h);
    }
    let size = match req.size {
        Size::CellM(m) => format!("cell {m:e}"),
        Size::Tets(n) => format!("tets {n}"),
    };
    Ok(fnv(
        format!("{size} {:?}", req.units).into_bytes().into_iter(),
        h,
    ))
}

/// Runs the mesher on `req`.
pub fn tetrahedralize(req: &MeshRequest) -> Result<MeshReport, TetrahedralizeError> {
    check_request(req)?;
    run_worker(req)
}

fn check_request(req: &MeshRequest) -> Result<(), TetrahedralizeError> {
    let bad = |m: String| Err(TetrahedralizeError::Request(m));
    if req.surfaces.is_empty() {
        return bad("no surface given".into());
    }
    for s in &req.surfaces {
        let ext = s
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(
            ext.as_deref(),
            Some("stl" | "obj" | "ply" | "vtk" | "vtp" | "off")
        ) {
            return Err(TetrahedralizeError::Input {
                path: s.display().to_string(),
                reason: "not a surface format the mesher reads (STL, OBJ, PLY, OFF, VTK, VTP)"
                    .into(),
            });
        }
        if !s.is_file() {
            return Err(TetrahedralizeError::Input {
                path: s.display().to_string(),
                reason: "no such file".into(),
            });
        }
    }
    let out_ext = req
        .out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(out_ext.as_deref(), Some("msh" | "vtu" | "vtk" | "mesh")) {
        return bad(format!(
            "{}: the output must be .msh, .vtu, .vtk or .mesh",
            req.out.display()
        ));
    }
    match req.size {
        Size::CellM(h) if !(h.is_finite() && h > 1e-5 && h < 1.0) => {
            bad(format!("--cell-m must be between 1e-5 and 1 m, got {h}"))
        }
        Size::Tets(n) if !(100..=MAX_TETS).contains(&n) => bad(format!(
            "--tets must be between 100 and {MAX_TETS}, got {n}"
        )),
        _ if !(req.time_limit_s.is_finite() && req.time_limit_s > 0.0) => {
            bad("--time-limit-s must be a positive number of seconds".into())
        }
        _ => Ok(()),
    }
}

/// One worker run: reads the surfaces (detecting millimetres when `units`
/// is not given), meshes into a scratch file of raw arrays, reports; then
/// the quality pass and the output in the format asked for.
fn run_worker(req: &MeshRequest) -> Result<MeshReport, TetrahedralizeError> {
    let scale = req.units.map(|u| match u {
        Units::Mm => 1e-3,
        Units::M => 1.0,
    });
    let (cell_m, tets) = match req.size {
        Size::CellM(h) => (Some(h), None),
        Size::Tets(n) => (None, Some(n)),
    };
    // The worker runs in a scratch directory (fTetWild leaves
    // `__tracked_surface.stl` in its working directory): paths absolute.
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let scratch = Scratch::new()?;
    let raw = scratch.0.join("raw.bin");
    let args = serde_json::json!({
        "surfaces": req.surfaces.iter().map(|p| abs(p).display().to_string()).collect::<Vec<_>>(),
        "scale": scale,
        "mm_detect_extent": MM_DETECT_EXTENT,
        "cell_m": cell_m,
        "tets": tets,
        "max_tets": MAX_TETS,
        "out": raw.display().to_string(),
        "threads": req.threads.max(1),
    });
    let out = worker_in(SCRIPT, &args.to_string(), req.time_limit_s, &scratch.0)?;
    let mut report: MeshReport = serde_json::from_str(&out)
        .map_err(|e| TetrahedralizeError::Failed(format!("unreadable report ({e}): {out}")))?;
    finish(&raw, req, &mut report)?;
    Ok(report)
}

/// The mesher's tetrahedra improved for the explicit step (unless asked
/// not to) and written to `req.out` in its format, the tags' volumes
/// measured on the result.
fn finish(
    raw: &Path,
    req: &MeshRequest,
    report: &mut MeshReport,
) -> Result<(), TetrahedralizeError> {
    use crate::mesh::io::{DataArray, write_medit, write_msh, write_vtk, write_vtu};
    let Raw {
        mut positions,
        tets,
        tags,
    } = read_raw(raw)?;
    if req.improve {
        let (e, nu, rho) = REFERENCE_MATERIAL;
        let material = crate::material::Material::isotropic(e, nu, rho, 0.0)
            .map_err(|e| TetrahedralizeError::Failed(format!("reference material: {e}")))?;
        report.improve = Some(improve_for_step(
            &mut positions,
            &tets,
            &tags,
            &material,
            &ImproveOptions::default(),
        ));
    }
    // What a reader would refuse is refused here, before any file exists.
    let mesh = crate::mesh::TetMesh::new(positions, tets).map_err(|e| {
        TetrahedralizeError::Failed(if req.improve {
            format!("fTetWild's mesh keeps a degenerate element after the quality pass ({e}): try another --cell-m")
        } else {
            format!("fTetWild's mesh has a degenerate element ({e}): leave out --no-improve (the quality pass opens such elements) or try another --cell-m")
        })
    })?;
    let (positions, tets_v, tags) = (mesh.positions_m(), mesh.tets(), &tags);
    // Measured again on the moved vertices (a tag with no tetrahedron
    // keeps its 0).
    report.tag_volumes_m3.values_mut().for_each(|v| *v = 0.0);
    for (t, tag) in tags.iter().enumerate() {
        *report.tag_volumes_m3.entry(tag.to_string()).or_default() +=
            mesh.tet_volume_m3(crate::ids::TetId::from(t));
    }
    let tags_u: Vec<u32> = tags.iter().map(|&t| t.max(0) as u32).collect();
    let ext = req
        .out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("msh") => write_msh(&req.out, positions, tets_v, tags)?,
        Some(e @ ("vtu" | "vtk")) => {
            // The same arrays either way: the tags as cell data `physical`.
            let write = if e == "vtu" { write_vtu } else { write_vtk };
            write(
                &req.out,
                positions,
                tets_v,
                &[],
                &[("physical", DataArray::Ids(&tags_u))],
            )?
        }
        _ => write_medit(&req.out, positions, tets_v, tags)?,
    }
    Ok(())
}

/// The worker's result: positions (m), tetrahedra (oriented), tags.
struct Raw {
    positions: Vec<crate::math::Vec3>,
    tets: Vec<[u32; 4]>,
    tags: Vec<i32>,
}

/// Reads the worker's `HAPRAW1` file, every count and index checked.
fn read_raw(path: &Path) -> Result<Raw, TetrahedralizeError> {
    let bad = |m: String| TetrahedralizeError::Failed(format!("{}: {m}", path.display()));
    let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let word = |i: usize| -> [u8; 8] {
        bytes
            .get(i..i + 8)
            .and_then(|b| b.try_into().ok())
            .unwrap_or([0; 8])
    };
    if bytes.get(..8) != Some(b"HAPRAW1\n".as_slice()) {
        return Err(bad("not the worker's output".into()));
    }
    let (nv, nt) = (u64::from_le_bytes(word(8)), u64::from_le_bytes(word(16)));
    let expected = (nv as u128) * 24 + (nt as u128) * 40 + 24;
    if expected != bytes.len() as u128 || nt as usize > MAX_TETS * 2 {
        return Err(bad(format!(
            "{} bytes for {nv} vertices and {nt} tetrahedra",
            bytes.len()
        )));
    }
    let (nv, nt) = (nv as usize, nt as usize);
    let f = |i: usize| f64::from_le_bytes(word(i));
    let int = |i: usize| i64::from_le_bytes(word(i));
    let positions: Vec<crate::math::Vec3> = (0..nv)
        .map(|k| crate::math::Vec3::new(f(24 + 24 * k), f(32 + 24 * k), f(40 + 24 * k)))
        .collect();
    let at = 24 + 24 * nv;
    let tets = (0..nt)
        .map(|k| {
            let mut t = [0u32; 4];
            for (j, v) in t.iter_mut().enumerate() {
                let i = int(at + 32 * k + 8 * j);
                *v = u32::try_from(i)
                    .ok()
                    .filter(|&i| (i as usize) < nv)
                    .ok_or_else(|| bad(format!("tetrahedron {k} has vertex {i} of {nv}")))?;
            }
            Ok(t)
        })
        .collect::<Result<Vec<_>, TetrahedralizeError>>()?;
    let at = at + 32 * nt;
    let tags = (0..nt)
        .map(|k| i32::try_from(int(at + 8 * k)).unwrap_or(0))
        .collect();
    Ok(Raw {
        positions,
        tets,
        tags,
    })
}

/// A scratch directory for one worker, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new() -> Result<Self, TetrahedralizeError> {
        let dir = std::env::temp_dir().join(format!(
            "hapsim-mesher-{}-{}",
            std::process::id(),
            SCRATCH_SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir).map_err(TetrahedralizeError::Spawn)?;
        Ok(Self(dir))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The worker's failure line.
#[derive(Deserialize)]
struct WorkerError {
    error: String,
    message: String,
    #[serde(default)]
    path: Option<String>,
}

/// Numbers the workers' scratch directories within a process.
static SCRATCH_SEQ: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Runs `code` with `arg` in `dir`, at most `limit_s`; its last stdout line.
fn worker_in(
    code: &str,
    arg: &str,
    limit_s: f64,
    dir: &Path,
) -> Result<String, TetrahedralizeError> {
    use std::os::unix::process::CommandExt;
    // Its own process group, killed whole on timeout: `python3` may be a
    // launcher (pyenv's shim) whose child is the interpreter, and killing
    // only the launcher left the mesher running.
    let mut child = Command::new("python3")
        .process_group(0)
        .current_dir(dir)
        .arg("-c")
        .arg(code)
        .arg(arg)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(TetrahedralizeError::Spawn)?;
    // Drained as it runs: a full pipe would stall the worker.
    let drain = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut s = String::new();
            let _ = r.read_to_string(&mut s);
            s
        })
    };
    let out = child.stdout.take().map(|s| drain(Box::new(s)));
    let err = child.stderr.take().map(|s| drain(Box::new(s)));
    let deadline = Instant::now() + Duration::from_secs_f64(limit_s.min(86_400.0));
    let status = loop {
        match child.try_wait().map_err(TetrahedralizeError::Spawn)? {
            Some(status) => break status,
            None if Instant::now() > deadline => {
                // SAFETY: kill(2) on the process group this function made
                // (the child's pid is its group id).
                unsafe { libc::kill(-(child.id() as libc::pid_t), libc::SIGKILL) };
                let _ = child.wait();
                return Err(TetrahedralizeError::TimedOut { limit_s });
            }
            None => std::thread::sleep(Duration::from_millis(20)),
        }
    };
    let stdout = out.and_then(|h| h.join().ok()).unwrap_or_default();
    let stderr = err.and_then(|h| h.join().ok()).unwrap_or_default();
    let last = stdout.lines().last().unwrap_or("").to_string();
    if let Ok(e) = serde_json::from_str::<WorkerError>(&last) {
        return Err(match (e.error.as_str(), e.path) {
            ("input", Some(path)) => TetrahedralizeError::Input {
                path,
                reason: e.message,
            },
            ("missing", _) => TetrahedralizeError::Missing(e.message),
            ("size", _) => TetrahedralizeError::TooLarge(e.message),
            _ => TetrahedralizeError::Failed(e.message),
        });
    }
    if !status.success() {
        let tail: Vec<&str> = stderr.lines().rev().take(5).collect();
        let tail: Vec<&str> = tail.into_iter().rev().collect();
        return Err(TetrahedralizeError::Failed(format!(
            "the worker exited with {status}: {}",
            tail.join(" / ")
        )));
    }
    Ok(last)
}
