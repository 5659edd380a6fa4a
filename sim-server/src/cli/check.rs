//! `sim-server check [FILE]`: validate a scene or a mesh and say what it makes.

use super::{load_scene, write_json};
use anyhow::Result;
use serde::Serialize;
use sim_server::mesh::TetMesh;
use sim_server::mesh::extent::{Extent, tag_counts};
use sim_server::mesh::io::read_mesh;
use sim_server::mesh::quality::{QualityReport, quality_report};
use sim_server::scene::BuiltScene;
use sim_server::scene::real_time::RealTime;
use sim_server::tensor_mass::{element_bound, power_iteration, step_outliers};
use std::path::Path;

/// An element whose own stable step is below the median element's over
/// this is named by `check` (it costs that many times the sub-steps).
const SLIVER_FACTOR: f64 = 4.0;

/// The machine-readable form of the check.
#[derive(Serialize)]
struct CheckJson {
    source: String,
    vertices: usize,
    tets: usize,
    edges: usize,
    surface_triangles: usize,
    min_dihedral_deg: f64,
    max_aspect_ratio: f64,
    shortest_edge_m: f64,
    components: usize,
    dt_max_element_s: Option<f64>,
    dt_max_power_iteration_s: Option<f64>,
    anisotropic_tets: Option<usize>,
    membrane: Option<String>,
    tools: Vec<String>,
    cutting: bool,
    warnings: Vec<String>,
    /// Bounding box corners (m).
    bounds_m: [[f64; 3]; 2],
    /// The median edge length (m).
    median_edge_m: f64,
    /// Per physical tag of the tetrahedra, how many carry it (mesh files).
    physical_tags: Vec<(i32, usize)>,
    /// Per physical tag of the surface triangles, how many carry it (mesh
    /// files; `select = { surface_physical = N }` takes their vertices).
    surface_physical_tags: Vec<(i32, usize)>,
    /// What each `[[refine]]` of the scene did (none for a mesh file).
    refined: Vec<sim_server::scene::refine::RefineReport>,
    /// `[contact] refine_radius_m`: the refinement that follows the tools.
    follow_refine: Option<FollowJson>,
}

/// The refinement that follows the tools, as `check` reports it.
#[derive(Serialize)]
struct FollowJson {
    radius_m: f64,
    cell_m: f64,
    max_tets: usize,
}

/// Prints where the mesh is, its typical edge and a warning when that is
/// not plausibly metres (unless `said` already has it: a scene's build
/// reports it among its warnings); returns the extent and the warning.
fn print_extent(mesh: &TetMesh, said: &[String]) -> (Extent, Option<String>) {
    let e = Extent::of(mesh);
    let (lo, hi) = (e.min_m, e.max_m);
    println!(
        "extent: [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}] m ({:.4} x {:.4} x {:.4} m), typical edge {:.3e} m",
        lo.x,
        lo.y,
        lo.z,
        hi.x,
        hi.y,
        hi.z,
        hi.x - lo.x,
        hi.y - lo.y,
        hi.z - lo.z,
        e.median_edge_m
    );
    let warning = e.units_warning().filter(|w| !said.contains(w));
    if let Some(w) = &warning {
        println!("warning: {w}");
    }
    (e, warning)
}

fn print_quality(q: &QualityReport) {
    println!("quality:\n{q}");
}

/// Runs the check; `path` None = the embedded scene.
pub fn run(path: Option<&Path>, json: Option<&Path>) -> Result<()> {
    let extension = path
        .and_then(|p| p.extension())
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let is_mesh = matches!(extension.as_deref(), Some("msh" | "vtk" | "vtu" | "mesh"));
    // Anything else but a scene is refused by name, not parsed as TOML.
    if let (Some(p), Some(e)) = (path, extension.as_deref())
        && !is_mesh
        && e != "toml"
    {
        let why = match e {
            "stl" | "obj" | "ply" | "off" => {
                " (a surface mesh: the simulation needs tetrahedra; mesh its volume first, e.g. with Gmsh or TetGen, and save .msh, .vtu or .mesh)"
            }
            _ => "",
        };
        anyhow::bail!(
            "{}: .{e} is neither a scene (.toml) nor a tetrahedral mesh (.msh, .vtk, .vtu, .mesh){why}",
            p.display()
        );
    }
    if let (true, Some(p)) = (is_mesh, path) {
        let imported = read_mesh(p)?;
        let q = quality_report(&imported.mesh);
        println!(
            "mesh {}: {} vertices, {} tetrahedra",
            p.display(),
            imported.mesh.vertex_count(),
            imported.mesh.tet_count()
        );
        for w in &imported.warnings {
            println!("warning: {w}");
        }
        let (extent, units) = print_extent(&imported.mesh, &[]);
        let tags = tag_counts(&imported.tet_physical);
        let listed: Vec<String> = tags.iter().map(|(t, n)| format!("{t} ({n})")).collect();
        println!(
            "physical tags of the tetrahedra (count): {}",
            listed.join(", ")
        );
        let surface: Vec<i32> = imported.surface_physical.iter().map(|(_, t)| *t).collect();
        let surface_tags = tag_counts(&surface);
        if !surface_tags.is_empty() {
            let listed: Vec<String> = surface_tags
                .iter()
                .map(|(t, n)| format!("{t} ({n})"))
                .collect();
            println!(
                "physical tags of the surface triangles (count; select = {{ surface_physical = N }}): {}",
                listed.join(", ")
            );
        }
        print_quality(&q);
        let mut warnings = imported.warnings;
        warnings.extend(units);
        if let Some(j) = json {
            let topo = sim_server::topology::Topology::new(&imported.mesh);
            write_json(
                j,
                &CheckJson {
                    source: p.display().to_string(),
                    vertices: imported.mesh.vertex_count(),
                    tets: imported.mesh.tet_count(),
                    edges: topo.edges().len(),
                    surface_triangles: topo.surface_len(),
                    min_dihedral_deg: q.min_dihedral_deg,
                    max_aspect_ratio: q.max_aspect_ratio,
                    shortest_edge_m: q.shortest_edge_m,
                    components: q.components,
                    dt_max_element_s: None,
                    dt_max_power_iteration_s: None,
                    anisotropic_tets: None,
                    membrane: None,
                    tools: Vec::new(),
                    cutting: false,
                    warnings,
                    bounds_m: [extent.min_m.to_array(), extent.max_m.to_array()],
                    median_edge_m: extent.median_edge_m,
                    physical_tags: tags,
                    surface_physical_tags: surface_tags,
                    refined: Vec::new(),
                    follow_refine: None,
                },
            )?;
        }
        return Ok(());
    }
    let (src, built) = load_scene(path)?;
    report_scene(&src.name, &built, json)
}

fn report_scene(name: &str, b: &BuiltScene, json: Option<&Path>) -> Result<()> {
    let model = &b.model;
    let mesh = model.mesh();
    let topo = model.topology();
    let q = quality_report(mesh);
    let r = &b.report;
    println!("scene {name}");
    println!(
        "mesh: {} ({} vertices, {} tetrahedra, {} edges, {} surface triangles)",
        r.mesh_source,
        mesh.vertex_count(),
        mesh.tet_count(),
        topo.edges().len(),
        topo.surface_len()
    );
    for w in &r.warnings {
        println!("warning: {w}");
    }
    if let Some(f) = &b.follow {
        println!(
            "[contact] refine_radius_m: cells up to {:.3} mm within {:.1} mm of each tool where it touches, made again as the tools move (at most {} tetrahedra)",
            f.settings.cell_m * 1e3,
            f.settings.radius_m * 1e3,
            f.settings.max_tets
        );
    }
    for f in &r.refined {
        println!(
            "[[refine]] {:?}: cells up to {:.3} mm, {} -> {} tetrahedra{}",
            f.name,
            f.cell_m * 1e3,
            f.tets_before,
            f.tets_after,
            if f.stopped_at_budget {
                " (stopped at its max_tets)"
            } else {
                ""
            }
        );
    }
    let (extent, units) = print_extent(mesh, &r.warnings);
    print_quality(&q);
    println!("materials:");
    println!("  default: {}", r.default_material);
    for (region, tets, m) in &r.regions {
        // Named as the scene's messages name them: `[[region]] "liver"`.
        println!("  [[region]] {region:?}: {tets} tetrahedra: {m}");
    }
    for (vessel, tets) in &r.vessels {
        println!(
            "  [[vessel]] {vessel:?}: {tets} tetrahedra made transversally isotropic along it"
        );
    }
    let element = element_bound(model);
    let power = power_iteration(model, 1e-6, 2000);
    println!(
        "stable step: {:.4e} s (element bound, enforced: survives cutting); {:.4e} s (power iteration, {} iterations; ratio {:.2})",
        element.dt_max_s,
        power.step.dt_max_s,
        power.iterations,
        power.step.dt_max_s / element.dt_max_s
    );
    // Slivers that set the step: what each costs, by name (a mesher's
    // 3-degree sliver once cut the step to a tenth without a word).
    let slivers = step_outliers(model, SLIVER_FACTOR, 5).map(|o| {
        let names: Vec<String> = (o.shortest.iter())
            .map(|(t, dt)| format!("{} ({dt:.3e} s)", t.0))
            .collect();
        let w = format!(
            "{} tetrahedra allow less than 1/{SLIVER_FACTOR} of the median element's stable step ({:.3e} s); the shortest make every step take {:.0}x the sub-steps the median element needs: tetrahedra {}{} (indices as in the quality line and the frames' tet_id; remesh or improve them)",
            o.count,
            o.median_dt_s,
            (o.median_dt_s / o.shortest[0].1).ceil(),
            names.join(", "),
            if o.count > o.shortest.len() { ", ..." } else { "" }
        );
        println!("warning: {w}");
        w
    });
    if let Some(dt) = b.settings.dt_s {
        let verdict = if dt <= element.dt_max_s {
            "under the bound".to_string()
        } else {
            match b.settings.policy {
                sim_server::tensor_mass::DtPolicy::Refuse => {
                    "ABOVE the bound: the simulation will refuse it".into()
                }
                _ => format!(
                    "above the bound: {} sub-steps per step",
                    (dt / element.dt_max_s).ceil()
                ),
            }
        };
        println!("dt_s = {dt:.4e} s: {verdict}");
    }
    // What `run` would refuse, refused here too (the same check, on the
    // step the tensor-mass backend would take).
    let mut real_time = None;
    if b.settings.backend == sim_server::scene::spec::BackendName::TensorMass {
        // The bound the scene asks the integrator to use; the default step
        // is 0.9 of the element bound either way (`prepare`).
        let bound = match b.settings.bound {
            sim_server::tensor_mass::BoundMethod::PowerIteration => &power.step,
            sim_server::tensor_mass::BoundMethod::Element => &element,
        };
        let dt = b.settings.dt_s.unwrap_or(0.9 * element.dt_max_s);
        let substeps =
            sim_server::tensor_mass::explicit::substeps_for(dt, bound, b.settings.policy).map_err(
                |e| anyhow::anyhow!("{name}: the tensor-mass backend would refuse this scene: {e}"),
            )?;
        // The defaults a run will take, said (without dt_s the step is the
        // stability bound, a rate no one chose).
        let why = if b.settings.dt_s.is_some() {
            "the scene's dt_s"
        } else {
            "no dt_s: 0.9 of the stable step; set [simulation] dt_s = 0.001 for 1 kHz"
        };
        println!(
            "a run steps every {dt:.4e} s ({why}), {substeps} sub-step{} each: {:.0} force samples per second",
            if substeps == 1 { "" } else { "s" },
            1.0 / dt
        );
        if b.settings.multirate {
            print_multirate(b, dt, name)?;
        }
        // What `run` warns of too (after it prepares the backend).
        if let Some(w) = RealTime::of(b).warning(bound.dt_max_s) {
            println!("warning: {w}");
            real_time = Some(w);
        }
    }
    if b.settings.backend != sim_server::scene::spec::BackendName::TensorMass {
        let dt = super::real_time_step(b);
        let why = if b.settings.dt_s.is_some() {
            "the scene's dt_s"
        } else {
            "no dt_s: 1 ms"
        };
        println!(
            "a run steps every {dt:.4e} s ({why}): {:.0} force samples per second",
            1.0 / dt
        );
    }
    let cutting = b
        .tools
        .iter()
        .any(|t| !matches!(t.kind, sim_server::scene::spec::ToolKind::Hook));
    println!("models enabled:");
    println!(
        "  anisotropy: {}",
        if r.anisotropic_tets > 0 {
            format!("{} tetrahedra", r.anisotropic_tets)
        } else {
            "off".into()
        }
    );
    println!(
        "  membrane: {}",
        r.membrane
            .as_ref()
            .map_or("off".to_string(), |(a, m)| format!(
                "{m}, alpha {a} N/m^2, {} capsule edges",
                model.membrane().map_or(0, |m| m.capsule_edges().len())
            ))
    );
    println!(
        "  constraints: {} fixed, {} prescribed vertices; loads on {} vertices",
        r.fixed_vertices, r.prescribed_vertices, r.loaded_vertices
    );
    println!(
        "  tools: {}",
        if b.tools.is_empty() {
            "none".to_string()
        } else {
            b.tools
                .iter()
                .map(|t| {
                    let kind = format!("{:?}", t.kind).to_lowercase();
                    let f = t.friction;
                    if f.is_active() {
                        format!(
                            "{} ({kind}, friction mu_s {}, mu_d {})",
                            t.name, f.static_coefficient, f.dynamic_coefficient
                        )
                    } else {
                        format!("{} ({kind})", t.name)
                    }
                })
                .collect::<Vec<_>>()
                .join(", ")
        }
    );
    println!(
        "  cutting: {}",
        if cutting {
            "yes (cutting tools declared)"
        } else {
            "off"
        }
    );
    if let Some(t) = r.hybrid_tets {
        println!(
            "  hybrid split: {t} tensor-mass (cuttable) tetrahedra, {} precomputed (read by --backend hybrid)",
            mesh.tet_count() - t
        );
    }
    if let Some(j) = json {
        write_json(
            j,
            &CheckJson {
                source: name.to_string(),
                vertices: mesh.vertex_count(),
                tets: mesh.tet_count(),
                edges: topo.edges().len(),
                surface_triangles: topo.surface_len(),
                min_dihedral_deg: q.min_dihedral_deg,
                max_aspect_ratio: q.max_aspect_ratio,
                shortest_edge_m: q.shortest_edge_m,
                components: q.components,
                dt_max_element_s: Some(element.dt_max_s),
                dt_max_power_iteration_s: Some(power.step.dt_max_s),
                anisotropic_tets: Some(r.anisotropic_tets),
                membrane: r.membrane.as_ref().map(|(a, m)| format!("{m} {a}")),
                tools: b.tools.iter().map(|t| t.name.clone()).collect(),
                cutting,
                warnings: (r.warnings.iter().cloned())
                    .chain(units)
                    .chain(real_time)
                    .chain(slivers)
                    .collect(),
                bounds_m: [extent.min_m.to_array(), extent.max_m.to_array()],
                median_edge_m: extent.median_edge_m,
                physical_tags: Vec::new(),
                surface_physical_tags: Vec::new(),
                refined: r.refined.clone(),
                follow_refine: b.follow.as_ref().map(|f| FollowJson {
                    radius_m: f.settings.radius_m,
                    cell_m: f.settings.cell_m,
                    max_tets: f.settings.max_tets,
                }),
            },
        )?;
    }
    Ok(())
}

/// The partition `[simulation] multirate` gives the scene's model at `dt`
/// (the run's own: the same integrator set up the same way).
fn print_multirate(b: &sim_server::scene::BuiltScene, dt: f64, name: &str) -> anyhow::Result<()> {
    use sim_server::tensor_mass::{Explicit, ExplicitConfig};
    let mut sim = Explicit::<f32>::new(
        b.model.clone(),
        ExplicitConfig {
            dt_s: dt,
            policy: b.settings.policy,
            bound: b.settings.bound,
            threads: 1,
        },
    )
    .map_err(|e| anyhow::anyhow!("{name}: the tensor-mass backend would refuse this scene: {e}"))?;
    let uniform = sim.substeps();
    let Some(m) = sim
        .set_multirate(true)
        .map_err(|e| anyhow::anyhow!("{name}: [simulation] multirate: {e}"))?
    else {
        return Ok(());
    };
    if m.engaged {
        println!(
            "multirate: {} of {} vertices fast ({} slow neighbours interpolated): {} whole passes and {} fast sub-steps a step, against {} whole passes for one step for all (contact and the corotational region add their vertices at run time)",
            m.fast_vertices,
            m.vertices,
            m.interface_vertices,
            m.coarse_substeps,
            m.fine_substeps,
            uniform
        );
    } else {
        println!(
            "multirate: does not pay here ({} of {} vertices would be fast, {} whole passes and {} fast sub-steps a step against {}): the run steps every vertex alike",
            m.fast_vertices, m.vertices, m.coarse_substeps, m.fine_substeps, uniform
        );
    }
    Ok(())
}
