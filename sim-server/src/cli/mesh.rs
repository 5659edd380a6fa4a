//! `sim-server mesh SURFACE... --cell-m H | --tets N --out organ.msh`: the
//! surfaces meshed by fTetWild ([`sim_server::mesh::tetrahedralize`]), their
//! faults said, then the result checked as `sim-server check` does.

use anyhow::{Context, Result, bail};
use sim_server::mesh::tetrahedralize::{
    MeshRequest, REFERENCE_MATERIAL, Size, Units, tetrahedralize,
};
use std::path::PathBuf;

/// `sim-server mesh`'s flags.
#[derive(clap::Args, Debug)]
pub struct MeshArgs {
    /// The surfaces: the organ first; each later one (a vessel, a tumour)
    /// tags the tetrahedra it encloses with its number (2, 3, ...).
    #[arg(required = true)]
    pub surfaces: Vec<PathBuf>,
    /// Ideal edge length of the tetrahedra (m).
    #[arg(long, conflicts_with = "tets", required_unless_present = "tets")]
    pub cell_m: Option<f64>,
    /// About this many tetrahedra (the edge length follows from the
    /// surface's volume).
    #[arg(long)]
    pub tets: Option<usize>,
    /// The surfaces' units, m or mm (default: mm when the organ is larger
    /// than 5 "m", said in the output).
    #[arg(long)]
    pub units: Option<Units>,
    /// The tetrahedra, by extension: .msh (Gmsh 2.2), .vtu, .vtk, .mesh.
    #[arg(long)]
    pub out: PathBuf,
    /// Stop the mesher after this long (s).
    #[arg(long, default_value_t = 300.0)]
    pub time_limit_s: f64,
    /// Mesher threads.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Leave fTetWild's vertices where they are (no quality pass for the
    /// explicit step).
    #[arg(long)]
    pub no_improve: bool,
    /// Also write the meshing report as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Meshes, reports, checks.
pub fn run(args: &MeshArgs) -> Result<()> {
    let size = match (args.cell_m, args.tets) {
        (Some(h), None) => Size::CellM(h),
        (None, Some(n)) => Size::Tets(n),
        _ => bail!("give one of --cell-m or --tets"),
    };
    let req = MeshRequest {
        units: args.units,
        time_limit_s: args.time_limit_s,
        threads: args.threads,
        improve: !args.no_improve,
        ..MeshRequest::new(args.surfaces.clone(), size, args.out.clone())
    };
    let report = tetrahedralize(&req)?;
    if report.units_detected && report.scale != 1.0 {
        println!(
            "units: the surfaces are larger than 5 m as metres: read as millimetres (--units m to refuse)"
        );
    }
    for s in &report.inputs {
        println!(
            "{}: {} vertices, {} triangles, {:.1} cm3 enclosed",
            s.path,
            s.vertices,
            s.triangles,
            s.volume_m3 * 1e6
        );
        for h in &s.holes {
            println!(
                "  warning: a hole ({} boundary vertices) around ({:.4}, {:.4}, {:.4}) m: fTetWild meshes across it",
                h.edges, h.centre[0], h.centre[1], h.centre[2]
            );
        }
        if s.boundary_edges > 0 && s.holes.is_empty() {
            println!("  warning: {} boundary edges", s.boundary_edges);
        }
        if s.nonmanifold_edges > 0 {
            println!(
                "  warning: {} non-manifold edges (more than two triangles), e.g.",
                s.nonmanifold_edges
            );
            for [a, b] in s.nonmanifold.iter().take(5) {
                println!(
                    "    ({:.4}, {:.4}, {:.4}) - ({:.4}, {:.4}, {:.4}) m",
                    a[0], a[1], a[2], b[0], b[1], b[2]
                );
            }
        }
    }
    if report.inputs.len() > 1 {
        let tags: Vec<String> = report
            .tags
            .iter()
            .map(|(k, n)| {
                let from = k
                    .parse::<usize>()
                    .ok()
                    .and_then(|i| report.inputs.get(i.wrapping_sub(1)))
                    .map_or("?", |s| s.path.as_str());
                format!("{k} ({from}): {n}")
            })
            .collect();
        println!("physical tags of the tetrahedra: {}", tags.join(", "));
    }
    println!(
        "meshed by fTetWild in {:.1} s: {} tetrahedra, {} vertices, ideal edge {:.2} mm -> {}",
        report.seconds,
        report.tets,
        report.vertices,
        report.edge_length_m * 1e3,
        args.out.display()
    );
    if let Some(q) = &report.improve {
        let (e, nu, rho) = REFERENCE_MATERIAL;
        println!(
            "quality pass (element stable step at E {:.1} kPa, nu {nu}, rho {rho:.0} kg/m3; it scales with sqrt(rho/E)): shortest {:.3e} s -> {:.3e} s ({:.2}x; median element {:.3e} s), elements under half the median {} -> {}; moved {} interior and {} surface vertices (surface at most {:.2} mm, in its tangent plane) in {:.1} s",
            e / 1e3,
            q.before_dt_s,
            q.after_dt_s,
            q.after_dt_s / q.before_dt_s,
            q.median_dt_s,
            q.below_before,
            q.below_after,
            q.moved_interior,
            q.moved_surface,
            q.max_surface_move_m * 1e3,
            q.seconds
        );
    }
    if let Size::Tets(n) = size {
        let ratio = report.tets as f64 / n as f64;
        if !(0.7..=1.3).contains(&ratio) {
            println!(
                "asked for about {n} tetrahedra, got {}: --cell-m {:.4} should give about {n} from this surface",
                report.tets,
                report.edge_length_m * ratio.cbrt()
            );
        }
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report)? + "\n";
        std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    println!();
    super::check::run(Some(&args.out), None)
}
