//! Static equilibrium of a model with StVK or corotational tetrahedra:
//! Newton's method on f_int(u) + f_ext = 0 with the loads and imposed
//! displacements applied in increments, a backtracking line search on the
//! residual norm, and the exact sparse tangent (the linear tensors plus each
//! nonlinear element's tangent minus its linear blocks), solved by a sparse
//! LU (faer; the corotational tangent of an anisotropic element is not
//! symmetric, and StVK's is indefinite in strong compression).
//!
//! A model without nonlinear tetrahedra is solved in one Newton step; its
//! result is then the linear solver's.

use crate::ids::{TetId, VertexId};
use crate::math::{Mat3, Real, Vec3};
use crate::static_solve::{Dirichlet, StaticError, StaticSolution};
use crate::tensor_mass::ElasticModel;
use crate::tensor_mass::large_strain::LargeStrain;
use crate::tensor_mass::nonlinear::element_tangent;
use faer::prelude::Solve;
use faer::sparse::{SparseColMat, Triplet};
use glam::DQuat;
use thiserror::Error;

/// Newton settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NewtonConfig {
    /// Load increments (loads and imposed displacements scaled by k / n).
    pub increments: usize,
    /// Newton iterations per increment at most.
    pub max_iterations: usize,
    /// Converged when the free residual is below this fraction of the
    /// force scale (the loads and the forces the imposed displacements need).
    pub relative_tolerance: Real,
}

impl Default for NewtonConfig {
    fn default() -> Self {
        Self {
            increments: 10,
            max_iterations: 50,
            relative_tolerance: 1e-10,
        }
    }
}

/// Why the nonlinear static solve failed.
#[derive(Debug, Error)]
pub enum NewtonError {
    /// Inputs or the linear part (sizes, non-finite values, singular K).
    #[error(transparent)]
    Static(#[from] StaticError),
    /// The nonlinear membrane has no tangent here.
    #[error(
        "the nonlinear static solver supports the linear membrane only; use [membrane] model = \"linear\""
    )]
    NonlinearMembrane,
    /// Newton did not reach the tolerance.
    #[error(
        "Newton did not converge in increment {increment} of {increments}: residual {residual_n:.3e} N after {iterations} iterations (tolerance {tolerance_n:.3e} N); try more increments or a smaller load"
    )]
    NotConverged {
        /// 1-based increment.
        increment: usize,
        /// Increments in all.
        increments: usize,
        /// Residual norm reached.
        residual_n: Real,
        /// Iterations spent.
        iterations: usize,
        /// The tolerance.
        tolerance_n: Real,
    },
    /// The tangent could not be factorized.
    #[error("sparse LU of the tangent failed: {0}")]
    Factorization(String),
}

/// The solution and how it was reached.
#[derive(Clone, Debug)]
pub struct NewtonSolution {
    /// Displacements and support reactions, as [`crate::static_solve::solve_static`] gives them.
    pub solution: StaticSolution,
    /// Newton iterations over all increments.
    pub iterations: usize,
    /// Final free residual norm (N).
    pub residual_n: Real,
}

/// Solves the nonlinear static problem.
pub fn solve_static_nonlinear(
    model: &ElasticModel,
    dirichlet: &Dirichlet,
    loads_n: &[Vec3],
    cfg: NewtonConfig,
) -> Result<NewtonSolution, NewtonError> {
    if model
        .membrane()
        .is_some_and(|m| m.model() == crate::membrane::MembraneModel::Nonlinear)
    {
        return Err(NewtonError::NonlinearMembrane);
    }
    let n = model.vertex_count();
    crate::static_solve::check_inputs(model, dirichlet, loads_n)?;
    if !dirichlet.holds_rigid_motions(model.mesh().positions_m()) {
        return Err(StaticError::Singular {
            constrained: dirichlet.count(),
        }
        .into());
    }
    let free = free_dofs(model, dirichlet);
    let nf = free.iter().filter(|i| **i != usize::MAX).count();
    let mut large = LargeStrain::new(model);
    let mut u = vec![Vec3::ZERO; n];
    let mut fint = vec![Vec3::ZERO; n];
    let mut iterations = 0;
    let mut residual_n = 0.0;
    let increments = cfg.increments.max(1);
    for k in 1..=increments {
        let t = k as Real / increments as Real;
        for (v, d) in u.iter_mut().enumerate() {
            for a in 0..3 {
                if let Some(x) = dirichlet.get(VertexId::from(v), a) {
                    d[a] = t * x;
                }
            }
        }
        let residual = |u: &[Vec3], large: &mut Option<LargeStrain>, fint: &mut [Vec3]| {
            internal_forces(model, large, u, fint);
            let mut r = vec![0.0; nf];
            for (d, &i) in free.iter().enumerate() {
                if i != usize::MAX {
                    r[i] = fint[d / 3][d % 3] + t * loads_n[d / 3][d % 3];
                }
            }
            r
        };
        let mut r = residual(&u, &mut large, &mut fint);
        // The force scale: the loads and what the imposed values pull with.
        let scale = norm(&r).max(
            t * loads_n
                .iter()
                .map(|l| l.length_squared())
                .sum::<Real>()
                .sqrt(),
        );
        let tolerance_n = (cfg.relative_tolerance * scale).max(1e-300);
        let mut it = 0;
        while norm(&r) > tolerance_n {
            if it == cfg.max_iterations {
                return Err(NewtonError::NotConverged {
                    increment: k,
                    increments,
                    residual_n: norm(&r),
                    iterations: it,
                    tolerance_n,
                });
            }
            let du = solve_tangent(model, &u, &free, nf, &r)?;
            // Backtracking on |r|: Newton's full step unless it raises the residual.
            let r0 = norm(&r);
            let mut alpha = 1.0;
            let mut trial = u.clone();
            loop {
                for (d, &i) in free.iter().enumerate() {
                    if i != usize::MAX {
                        trial[d / 3][d % 3] = u[d / 3][d % 3] + alpha * du[i];
                    }
                }
                let rt = residual(&trial, &mut large, &mut fint);
                if norm(&rt) <= (1.0 - 1e-4 * alpha) * r0 || alpha < 1e-6 {
                    u.copy_from_slice(&trial);
                    r = rt;
                    break;
                }
                alpha *= 0.5;
            }
            it += 1;
        }
        iterations += it;
        residual_n = norm(&r);
    }
    internal_forces(model, &mut large, &u, &mut fint);
    let force_n = (0..n)
        .map(|v| {
            let mut out = loads_n[v];
            for a in 0..3 {
                if free[3 * v + a] == usize::MAX && dirichlet.get(VertexId::from(v), a).is_some() {
                    out[a] = -fint[v][a] - loads_n[v][a];
                }
            }
            out
        })
        .collect();
    Ok(NewtonSolution {
        solution: StaticSolution {
            displacement_m: u,
            force_n,
        },
        iterations,
        residual_n,
    })
}

fn norm(r: &[Real]) -> Real {
    r.iter().map(|x| x * x).sum::<Real>().sqrt()
}

/// Free index of each degree of freedom (`usize::MAX`: imposed, or of a
/// vertex without live tetrahedra).
fn free_dofs(model: &ElasticModel, dirichlet: &Dirichlet) -> Vec<usize> {
    let mut free = vec![usize::MAX; 3 * model.vertex_count()];
    let mut nf = 0;
    for (v, slot) in free.chunks_exact_mut(3).enumerate() {
        let vertex = VertexId::from(v);
        if model.topology().vertex_tet_count(vertex) == 0 {
            continue;
        }
        for (a, s) in slot.iter_mut().enumerate() {
            if dirichlet.get(vertex, a).is_none() {
                *s = nf;
                nf += 1;
            }
        }
    }
    free
}

/// f_int(u): -K u over every tetrahedron plus each nonlinear element's
/// difference to its linear force.
fn internal_forces(
    model: &ElasticModel,
    large: &mut Option<LargeStrain>,
    u: &[Vec3],
    out: &mut [Vec3],
) {
    model.elastic_forces(u, out);
    if let Some(large) = large {
        let state: Vec<[Real; 3]> = u.iter().map(|v| v.to_array()).collect();
        let mut correction = vec![[0.0; 3]; u.len()];
        large.pass(&state, &mut correction, 1);
        for (o, c) in out.iter_mut().zip(&correction) {
            *o += Vec3::from_array(*c);
        }
    }
}

/// Solves K_T(u) du = r on the free block.
fn solve_tangent(
    model: &ElasticModel,
    u: &[Vec3],
    free: &[usize],
    nf: usize,
    r: &[Real],
) -> Result<Vec<Real>, NewtonError> {
    let mut triplets = Vec::new();
    let mut put = |a: usize, b: usize, k: &Mat3| {
        for row in 0..3 {
            let fr = free[3 * a + row];
            if fr == usize::MAX {
                continue;
            }
            for col in 0..3 {
                let fc = free[3 * b + col];
                if fc != usize::MAX {
                    triplets.push(Triplet::new(fr, fc, k.col(col)[row]));
                }
            }
        }
    };
    for (v, k) in model.vertex_tensors().iter().enumerate() {
        put(v, v, k);
    }
    for ([a, b], k) in model.topology().edges().iter().zip(model.edge_tensors()) {
        put(a.idx(), b.idx(), k);
        put(b.idx(), a.idx(), &k.transpose());
    }
    let mesh = model.mesh();
    for t in (0..mesh.tet_count()).map(TetId::from) {
        let m = model.materials().material(t).model();
        if !m.is_nonlinear() || !model.topology().is_alive(t) {
            continue;
        }
        let (elastic, geom) = model.element(t);
        let tet = mesh.tets()[t.idx()];
        let ut = tet.map(|v| u[v.idx()]);
        let kt = element_tangent(m, &elastic, &geom, &ut, &mut DQuat::default());
        for i in 0..4 {
            for j in 0..4 {
                put(
                    tet[i].idx(),
                    tet[j].idx(),
                    &(kt[i][j] - elastic.block(&geom, i, j)),
                );
            }
        }
    }
    let k = SparseColMat::<usize, Real>::try_new_from_triplets(nf, nf, &triplets)
        .map_err(|e| NewtonError::Factorization(format!("{e:?}")))?;
    let lu = k
        .sp_lu()
        .map_err(|e| NewtonError::Factorization(format!("{e:?}")))?;
    let mut x = faer::Mat::<Real>::from_fn(nf, 1, |i, _| r[i]);
    lu.solve_in_place(x.as_mut());
    let du: Vec<Real> = (0..nf).map(|i| x[(i, 0)]).collect();
    if du.iter().all(|d| d.is_finite()) {
        Ok(du)
    } else {
        Err(NewtonError::Factorization(
            "the tangent is singular at this state (the constraints may not prevent rigid motion)"
                .into(),
        ))
    }
}
