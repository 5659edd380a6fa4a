//! `hapbench tradeoff --large`: the material models under a large
//! deformation. The 4 x 2 x 2 cm block of `tradeoff`, fixed at x = 0,
//! carries 0.04 N down on its free end (a linear tip deflection of about a
//! third of its length). Each model (linear, corotational, StVK) runs on the
//! explicit tensor-mass backend (f32 tensors, 90% of the rest bound,
//! sub-stepping as the tangent asks) until the response has settled; its tip
//! displacement is compared with the converged StVK reference: Newton's
//! static solution on a mesh twice finer than the finest in the sweep. The
//! linear and corotational errors include their difference from the StVK
//! material (the point of the comparison); StVK's is discretisation and
//! settling alone. Speed is steps per second of wall time.

use anyhow::{Context, Result};
use serde::Serialize;
use sim_server::material::MaterialModel;
use sim_server::prelude::*;
use sim_server::static_newton::{NewtonConfig, solve_static_nonlinear};
use sim_server::tensor_mass::element_bound;
use std::time::Instant;

use super::tradeoff::{PROBE, SIZE, block, find};

const LOAD_N: f64 = 0.04;
const CELLS_M: [f64; 3] = [0.01, 0.005, 0.0025];
const MODELS: [MaterialModel; 3] = [
    MaterialModel::Linear,
    MaterialModel::Corotational,
    MaterialModel::Stvk,
];

/// One model on one mesh.
#[derive(Clone, Debug, Serialize)]
pub struct LargePoint {
    /// "linear", "corotational" or "stvk".
    pub model: String,
    /// Cell edge (m).
    pub cell_m: f64,
    /// Tetrahedra.
    pub tets: usize,
    /// Steps per second of wall time.
    pub steps_per_s: f64,
    /// Sub-steps per step at the end (the tangent's bound).
    pub substeps: usize,
    /// |u - u_ref| / |u_ref| at the tip, against the StVK reference.
    pub error: f64,
    /// The tip displacement (m).
    pub tip_m: [f64; 3],
}

/// The block's supports and load.
struct Boundary {
    /// Clamped vertices (x = 0).
    wall: Vec<VertexId>,
    /// The end's vertices with their share of the load.
    loads: Vec<(VertexId, Vec3)>,
    /// The free end's centre.
    tip: VertexId,
}

/// `tradeoff`'s supports with this load, and the tip vertex.
fn boundary(m: &ElasticModel) -> Result<Boundary> {
    let (wall, loads) = super::tradeoff::boundary(m, LOAD_N);
    let tip = find(m, PROBE).context("the probe is not a vertex")?;
    Ok(Boundary { wall, loads, tip })
}

/// The converged StVK tip displacement (Newton on the finest cells / 2).
pub fn reference() -> Result<Vec3> {
    let m = block(CELLS_M[CELLS_M.len() - 1] / 2.0, MaterialModel::Stvk)?;
    let Boundary { wall, loads, tip } = boundary(&m)?;
    let mut bc = Dirichlet::new(m.vertex_count());
    for v in &wall {
        bc.fix(*v);
    }
    let mut f = vec![Vec3::ZERO; m.vertex_count()];
    for (v, l) in &loads {
        f[v.idx()] = *l;
    }
    let sol = solve_static_nonlinear(&m, &bc, &f, NewtonConfig::default())?;
    Ok(sol.solution.displacement_m[tip.idx()])
}

/// Every model on every mesh of the sweep, `duration_s` simulated each.
pub fn sweep(u_ref: Vec3, duration_s: f64, tick: &mut dyn FnMut()) -> Result<Vec<LargePoint>> {
    let mut points = Vec::new();
    for cell in CELLS_M {
        for model in MODELS {
            let m = block(cell, model)?;
            let Boundary { wall, loads, tip } = boundary(&m)?;
            let bound = element_bound(&m).dt_max_s;
            let mut sim = Explicit::<f32>::new(m, ExplicitConfig::new(0.9 * bound))?;
            for v in &wall {
                sim.fix(*v);
            }
            for (v, l) in &loads {
                sim.set_external_force(*v, *l);
            }
            let steps = (duration_s / sim.dt_s()).ceil() as usize;
            let start = Instant::now();
            for _ in 0..steps {
                sim.step();
            }
            let wall_s = start.elapsed().as_secs_f64().max(1e-9);
            let u = sim.displacement(tip);
            anyhow::ensure!(u.is_finite(), "{} on {cell} m cells diverged", model.name());
            points.push(LargePoint {
                model: model.name().into(),
                cell_m: cell,
                tets: sim.model().mesh().tet_count(),
                steps_per_s: steps as f64 / wall_s,
                substeps: sim.substeps(),
                error: (u - u_ref).length() / u_ref.length(),
                tip_m: u.to_array(),
            });
            tick();
        }
    }
    Ok(points)
}

/// Prints the table.
pub fn print(points: &[LargePoint], u_ref: Vec3) {
    println!(
        "large deformation: StVK reference tip displacement {:?} m ({:.0}% of the length)",
        u_ref.to_array(),
        100.0 * u_ref.length() / SIZE[0]
    );
    println!(
        "{:<13} {:>7} {:>6} {:>10} {:>9} {:>9}",
        "model", "cell mm", "tets", "steps/s", "substeps", "error %"
    );
    for p in points {
        println!(
            "{:<13} {:>7.1} {:>6} {:>10.0} {:>9} {:>9.2}",
            p.model,
            p.cell_m * 1e3,
            p.tets,
            p.steps_per_s,
            p.substeps,
            p.error * 100.0
        );
    }
}

/// The count of sweep points (for the progress bar).
pub fn count() -> usize {
    CELLS_M.len() * MODELS.len()
}
