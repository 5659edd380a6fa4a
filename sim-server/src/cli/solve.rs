//! `sim-server solve --scene FILE --out FILE.{vtu,vtk,mesh,obj,stl} [--json
//! FILE]`: static equilibrium of a scene's fixed sets, prescribed
//! displacements and loads. The writer follows the extension: VTU or legacy
//! VTK with the `displacement` and `force` point data, the deformed mesh as
//! medit, or the deformed surface as OBJ or binary STL; any other extension
//! is refused before solving. A scene with StVK or corotational
//! tetrahedra is solved by Newton with load increments
//! ([`sim_server::static_newton`]), the others by one linear solve.

use super::{load_scene, write_json};
use anyhow::{Context, Result};
use serde::Serialize;
use sim_server::math::Vec3;
use sim_server::mesh::io::{DataArray, write_medit, write_obj, write_stl, write_vtk, write_vtu};
use sim_server::static_newton::{NewtonConfig, solve_static_nonlinear};
use sim_server::static_solve::{Dirichlet, solve_static};
use std::path::Path;
use std::time::Instant;

#[derive(Serialize)]
struct SolveJson {
    scene: String,
    out: String,
    vertices: usize,
    tets: usize,
    fixed_vertices: usize,
    prescribed_vertices: usize,
    loaded_vertices: usize,
    max_displacement_m: f64,
    total_load_n: [f64; 3],
    total_reaction_n: [f64; 3],
    solve_s: f64,
    /// Newton iterations (nonlinear materials), absent for a linear solve.
    #[serde(skip_serializing_if = "Option::is_none")]
    newton_iterations: Option<usize>,
}

/// Runs the solve.
/// What `--out` asks for.
#[derive(Clone, Copy, PartialEq, Eq)]
enum OutFormat {
    Vtu,
    Vtk,
    Medit,
    Obj,
    Stl,
}

fn out_format(out: &Path) -> Result<OutFormat> {
    let ext = out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("vtu") => Ok(OutFormat::Vtu),
        Some("vtk") => Ok(OutFormat::Vtk),
        Some("mesh") => Ok(OutFormat::Medit),
        Some("obj") => Ok(OutFormat::Obj),
        Some("stl") => Ok(OutFormat::Stl),
        other => anyhow::bail!(
            "--out {}: {} is not a format solve writes: .vtu or .vtk (the mesh with displacement and force), .mesh (medit: the deformed mesh), .obj or .stl (the deformed surface)",
            out.display(),
            other.map_or("no extension".to_string(), |e| format!(".{e}"))
        ),
    }
}

pub fn run(scene: Option<&Path>, out: &Path, json: Option<&Path>) -> Result<()> {
    let format = out_format(out)?;
    let (src, b) = load_scene(scene)?;
    let model = &b.model;
    let n = model.vertex_count();
    let mut bc = Dirichlet::new(n);
    for v in &b.fixed {
        bc.fix(*v);
    }
    for (v, d) in &b.prescribed {
        bc.prescribe(*v, *d);
    }
    let loads = if b.loads_n.is_empty() {
        vec![Vec3::ZERO; n]
    } else {
        b.loads_n.clone()
    };
    let t0 = Instant::now();
    let (sol, newton_iterations) = if model.nonlinear_tets() > 0 {
        let s = solve_static_nonlinear(model, &bc, &loads, NewtonConfig::default())
            .with_context(|| format!("nonlinear static solve of {}", src.name))?;
        (s.solution, Some(s.iterations))
    } else {
        let s = solve_static(model, &bc, &loads)
            .with_context(|| format!("static solve of {}", src.name))?;
        (s, None)
    };
    let solve_s = t0.elapsed().as_secs_f64();
    let alive: Vec<_> = (0..model.mesh().tet_count())
        .map(sim_server::ids::TetId::from)
        .filter(|t| model.topology().is_alive(*t))
        .map(|t| model.mesh().tets()[t.idx()])
        .collect();
    let mut point_data = vec![
        ("displacement", DataArray::Vectors(&sol.displacement_m)),
        ("force", DataArray::Vectors(&sol.force_n)),
    ];
    if let Some(ids) = &b.original_vertex_ids {
        point_data.push(("original_id", DataArray::Ids(ids)));
    }
    match format {
        OutFormat::Vtu => write_vtu(out, model.mesh().positions_m(), &alive, &point_data, &[])?,
        OutFormat::Vtk => write_vtk(out, model.mesh().positions_m(), &alive, &point_data, &[])?,
        OutFormat::Medit | OutFormat::Obj | OutFormat::Stl => {
            // Formats without point data: the deformed geometry itself.
            let deformed: Vec<Vec3> = model
                .mesh()
                .positions_m()
                .iter()
                .zip(&sol.displacement_m)
                .map(|(p, u)| *p + *u)
                .collect();
            let triangles: Vec<_> = model.topology().surface_triangles(model.mesh()).collect();
            match format {
                OutFormat::Medit => write_medit(out, &deformed, &alive, &[])?,
                OutFormat::Obj => write_obj(out, &deformed, &triangles)?,
                _ => write_stl(out, &deformed, &triangles)?,
            }
        }
    }
    let constrained: Vec<bool> = (0..n)
        .map(|v| (0..3).any(|a| bc.get(sim_server::ids::VertexId::from(v), a).is_some()))
        .collect();
    let reaction: Vec3 = sol
        .force_n
        .iter()
        .zip(&constrained)
        .filter(|(_, c)| **c)
        .map(|(f, _)| *f)
        .sum();
    let load: Vec3 = loads.iter().sum();
    let max_u = sol
        .displacement_m
        .iter()
        .map(|u| u.length())
        .fold(0.0, f64::max);
    if let Some(it) = newton_iterations {
        println!(
            "nonlinear materials: Newton, {} load increments, {it} iterations",
            NewtonConfig::default().increments
        );
    }
    println!(
        "solved {} ({} vertices, {} tetrahedra) in {:.3} s: max displacement {:.4e} m, total load {:?} N, total reaction {:?} N -> {}",
        src.name,
        n,
        alive.len(),
        solve_s,
        max_u,
        load.to_array(),
        reaction.to_array(),
        out.display()
    );
    if let Some(j) = json {
        write_json(
            j,
            &SolveJson {
                scene: src.name.clone(),
                out: out.display().to_string(),
                vertices: n,
                tets: alive.len(),
                fixed_vertices: b.fixed.len(),
                prescribed_vertices: b.prescribed.len(),
                loaded_vertices: b.report.loaded_vertices,
                max_displacement_m: max_u,
                total_load_n: load.to_array(),
                total_reaction_n: reaction.to_array(),
                solve_s,
                newton_iterations,
            },
        )?;
    }
    Ok(())
}
