//! Static equilibrium on the model's tensors: K u = f with some degrees of
//! freedom imposed (fixed sets, prescribed displacements, per axis), solved by
//! a sparse Cholesky factorization (faer) of the free block.

use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::tensor_mass::ElasticModel;
use faer::prelude::Solve;
use faer::sparse::{SparseColMat, Triplet};
use thiserror::Error;

/// Imposed displacements per vertex and axis (`None` = free).
#[derive(Clone, Debug, PartialEq)]
pub struct Dirichlet {
    dofs: Vec<[Option<Real>; 3]>,
}

impl Dirichlet {
    /// Nothing imposed on `vertex_count` vertices.
    pub fn new(vertex_count: usize) -> Self {
        Self {
            dofs: vec![[None; 3]; vertex_count],
        }
    }

    /// Fixes `v` at rest on all axes.
    pub fn fix(&mut self, v: VertexId) {
        self.prescribe(v, Vec3::ZERO);
    }

    /// Imposes displacement `d_m` on `v`.
    pub fn prescribe(&mut self, v: VertexId, d_m: Vec3) {
        self.dofs[v.idx()] = d_m.to_array().map(Some);
    }

    /// Imposes `value_m` on one axis (0 = x) of `v`.
    pub fn prescribe_axis(&mut self, v: VertexId, axis: usize, value_m: Real) {
        self.dofs[v.idx()][axis] = Some(value_m);
    }

    /// The imposed value of (v, axis), if any.
    pub fn get(&self, v: VertexId, axis: usize) -> Option<Real> {
        self.dofs[v.idx()][axis]
    }

    /// Number of imposed degrees of freedom.
    pub fn count(&self) -> usize {
        self.dofs.iter().flatten().filter(|d| d.is_some()).count()
    }

    /// Whether the imposed degrees of freedom hold every rigid motion of a
    /// body at `positions_m` (its three translations and three rotations):
    /// the 6 x 6 Gram matrix of the rigid modes restricted to them has
    /// full rank. A body held nowhere, at one vertex or along one line
    /// has a singular stiffness that a factorization can still get
    /// through by round-off (a free box under 1 N "moved" 1e11 m).
    pub fn holds_rigid_motions(&self, positions_m: &[Vec3]) -> bool {
        let held: Vec<(usize, usize)> = (self.dofs.iter().enumerate())
            .flat_map(|(v, d)| (0..3).filter(move |&a| d[a].is_some()).map(move |a| (v, a)))
            .collect();
        if held.len() < 6 {
            return false;
        }
        // Rotations about the held vertices' centre, in units of their
        // extent, so that all six columns are of one scale.
        let centre = held.iter().map(|&(v, _)| positions_m[v]).sum::<Vec3>() / held.len() as Real;
        let extent = (held.iter())
            .map(|&(v, _)| (positions_m[v] - centre).length())
            .fold(0.0, Real::max)
            .max(Real::MIN_POSITIVE);
        let mut gram = [[0.0; 6]; 6];
        for &(v, a) in &held {
            let r = (positions_m[v] - centre) / extent;
            let mut row = [0.0; 6];
            row[a] = 1.0;
            for (k, e) in [Vec3::X, Vec3::Y, Vec3::Z].into_iter().enumerate() {
                row[3 + k] = e.cross(r)[a];
            }
            for i in 0..6 {
                for j in 0..6 {
                    gram[i][j] += row[i] * row[j];
                }
            }
        }
        // Each mode to unit weight: a large face held along one axis
        // (N^2 rows) would otherwise swamp the one or two rows that hold
        // the others, and a determinate support read as singular.
        let d: [Real; 6] = std::array::from_fn(|i| gram[i][i]);
        if d.iter().any(|x| *x <= 0.0) {
            return false;
        }
        let scaled: [[Real; 6]; 6] =
            std::array::from_fn(|i| std::array::from_fn(|j| gram[i][j] / (d[i] * d[j]).sqrt()));
        full_rank(scaled, 1e-9)
    }
}

/// Whether a symmetric positive semi-definite matrix has full rank: every
/// pivot of its Cholesky factorization above `relative` times the largest
/// diagonal entry.
fn full_rank<const N: usize>(mut m: [[Real; N]; N], relative: Real) -> bool {
    let scale = (0..N).map(|i| m[i][i]).fold(0.0, Real::max);
    if scale <= 0.0 {
        return false;
    }
    for k in 0..N {
        let pivot = m[k][k];
        if pivot <= relative * scale {
            return false;
        }
        let pivot_row = m[k];
        for row in m.iter_mut().skip(k + 1) {
            let f = row[k] / pivot;
            for (x, p) in row.iter_mut().zip(&pivot_row).skip(k) {
                *x -= f * p;
            }
        }
    }
    true
}

/// The solution: displacements and forces per vertex.
#[derive(Clone, Debug, PartialEq)]
pub struct StaticSolution {
    /// Displacement (m).
    pub displacement_m: Vec<Vec3>,
    /// Per axis: at imposed degrees of freedom the force the support exerts
    /// on the body (N), elsewhere the applied load.
    pub force_n: Vec<Vec3>,
}

/// Why the static problem could not be solved.
#[derive(Debug, Error, PartialEq)]
pub enum StaticError {
    /// Sizes do not match the model.
    #[error("{what} has {got} entries, the model has {expected} vertices")]
    Size {
        /// Which input.
        what: &'static str,
        /// Given.
        got: usize,
        /// Expected.
        expected: usize,
    },
    /// A load or imposed value is not finite.
    #[error("{what} of vertex {vertex} is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// The vertex.
        vertex: usize,
    },
    /// The free block is singular: the body can move rigidly.
    #[error(
        "the stiffness is singular: the constraints ({constrained} fixed or prescribed degrees of freedom) do not prevent rigid motion; fix at least three non-aligned vertices"
    )]
    Singular {
        /// Imposed degrees of freedom.
        constrained: usize,
    },
    /// The solution overflowed (a load too large for the stiffness).
    #[error(
        "the displacement of vertex {vertex} is not finite: the loads are too large for this stiffness"
    )]
    NonFiniteSolution {
        /// The first vertex concerned.
        vertex: usize,
    },
    /// The factorization failed for another reason.
    #[error("sparse factorization failed: {0}")]
    Factorization(String),
    /// A nonlinear material model.
    #[error(transparent)]
    LinearOnly(#[from] crate::tensor_mass::LinearOnly),
}

/// Solves K u = f for the model as it is (removed tetrahedra excluded;
/// orphaned vertices keep zero displacement). `loads_n` are per-vertex forces.
pub fn solve_static(
    model: &ElasticModel,
    dirichlet: &Dirichlet,
    loads_n: &[Vec3],
) -> Result<StaticSolution, StaticError> {
    model.require_linear(
        "static solver",
        "it solves K u = f with the linear stiffness; static_newton solves the others",
        |_| true,
    )?;
    check_inputs(model, dirichlet, loads_n)?;
    let n = model.vertex_count();
    let asm = assemble(model, dirichlet);
    let mut u = asm.u.clone();
    let free = &asm.free;
    let membrane_blocks = &asm.membrane_blocks;
    let f: Vec<Real> = loads_n.iter().flat_map(|l| l.to_array()).collect();
    let mut rhs = asm.rhs_imposed.clone();
    for (d, &i) in free.iter().enumerate() {
        if i != usize::MAX {
            rhs[i] += f[d];
        }
    }
    if let Some(llt) = factor(&asm, dirichlet, model.mesh().positions_m())? {
        let mut x = faer::Mat::<Real>::from_fn(asm.nf, 1, |i, _| rhs[i]);
        llt.solve_in_place(x.as_mut());
        for (d, &i) in free.iter().enumerate() {
            if i != usize::MAX {
                u[d] = x[(i, 0)];
            }
        }
    }
    let displacement_m: Vec<Vec3> = u
        .chunks_exact(3)
        .map(|c| Vec3::new(c[0], c[1], c[2]))
        .collect();
    if let Some(vertex) = displacement_m.iter().position(|d| !d.is_finite()) {
        return Err(StaticError::NonFiniteSolution { vertex });
    }
    let mut ku = vec![Vec3::ZERO; n];
    model.elastic_forces(&displacement_m, &mut ku);
    for (a, b, t) in membrane_blocks {
        ku[*a] -= *t * displacement_m[*b];
    }
    // elastic_forces gives -K u; reaction = K u - f at imposed dofs.
    let force_n = (0..n)
        .map(|v| {
            let mut out = loads_n[v];
            for a in 0..3 {
                if free[3 * v + a] == usize::MAX && dirichlet.dofs[v][a].is_some() {
                    out[a] = -ku[v][a] - loads_n[v][a];
                }
            }
            out
        })
        .collect();
    Ok(StaticSolution {
        displacement_m,
        force_n,
    })
}

/// Sizes match the model and every load and imposed value is finite.
pub(crate) fn check_inputs(
    model: &ElasticModel,
    dirichlet: &Dirichlet,
    loads_n: &[Vec3],
) -> Result<(), StaticError> {
    let n = model.vertex_count();
    for (what, got) in [
        ("loads", loads_n.len()),
        ("constraints", dirichlet.dofs.len()),
    ] {
        if got != n {
            return Err(StaticError::Size {
                what,
                got,
                expected: n,
            });
        }
    }
    if let Some(v) = loads_n.iter().position(|f| !f.is_finite()) {
        return Err(StaticError::NonFinite {
            what: "load",
            vertex: v,
        });
    }
    if let Some(v) = dirichlet
        .dofs
        .iter()
        .position(|d| d.iter().flatten().any(|x| !x.is_finite()))
    {
        return Err(StaticError::NonFinite {
            what: "imposed displacement",
            vertex: v,
        });
    }
    Ok(())
}

/// The free block of K (lower triangle) for the imposed degrees of
/// freedom, and what the imposed values contribute to the right side.
struct Assembly {
    /// Free index of each degree of freedom (`usize::MAX`: imposed or dead).
    free: Vec<usize>,
    nf: usize,
    /// Imposed values (free entries 0).
    u: Vec<Real>,
    triplets: Vec<Triplet<usize, usize, Real>>,
    /// -K_fp u_p.
    rhs_imposed: Vec<Real>,
    /// A nonlinear membrane's tangent at rest (not in the model's K).
    membrane_blocks: Vec<(usize, usize, crate::math::Mat3)>,
}

fn assemble(model: &ElasticModel, dirichlet: &Dirichlet) -> Assembly {
    let n = model.vertex_count();
    // Number the free degrees of freedom of vertices that still have material.
    let topo = model.topology();
    let mut free = vec![usize::MAX; 3 * n];
    let mut u = vec![0.0; 3 * n];
    let mut nf = 0;
    for v in 0..n {
        let live = topo.vertex_tet_count(VertexId::from(v)) > 0;
        for a in 0..3 {
            match dirichlet.dofs[v][a] {
                Some(x) => u[3 * v + a] = x,
                None if live => {
                    free[3 * v + a] = nf;
                    nf += 1;
                }
                None => {}
            }
        }
    }
    // Stiffness blocks as (row vertex, col vertex, block) for both triangles.
    let blocks = model
        .vertex_tensors()
        .iter()
        .enumerate()
        .map(|(v, k)| (v, v, *k))
        .chain(
            topo.edges()
                .iter()
                .zip(model.edge_tensors())
                .flat_map(|([a, b], k)| {
                    [(a.idx(), b.idx(), *k), (b.idx(), a.idx(), k.transpose())]
                }),
        );
    // A nonlinear membrane enters the static (small-displacement) problem by
    // its tangent at rest, the same springs linearised.
    let membrane_blocks: Vec<(usize, usize, crate::math::Mat3)> = match model.membrane() {
        Some(m) if m.model() == crate::membrane::MembraneModel::Nonlinear => {
            let rest = model.mesh().positions_m();
            m.capsule_edges()
                .iter()
                .filter(|e| m.stiffness_n_per_m()[e.idx()] > 0.0)
                .flat_map(|e| {
                    let [a, b] = topo.edges()[e.idx()];
                    let t = crate::membrane::Membrane::linear_tensor(
                        rest,
                        a,
                        b,
                        m.stiffness_n_per_m()[e.idx()],
                    );
                    [
                        (a.idx(), a.idx(), t),
                        (b.idx(), b.idx(), t),
                        (a.idx(), b.idx(), -t),
                        (b.idx(), a.idx(), -t),
                    ]
                })
                .collect()
        }
        _ => Vec::new(),
    };
    let blocks = blocks.chain(membrane_blocks.iter().copied());
    let mut triplets = Vec::new();
    let mut rhs = vec![0.0; nf];
    for (a, b, k) in blocks {
        for r in 0..3 {
            let fr = free[3 * a + r];
            if fr == usize::MAX {
                continue;
            }
            for c in 0..3 {
                let val = k.col(c)[r];
                let fc = free[3 * b + c];
                if fc == usize::MAX {
                    rhs[fr] -= val * u[3 * b + c];
                } else if fr >= fc {
                    triplets.push(Triplet::new(fr, fc, val));
                }
            }
        }
    }
    Assembly {
        free,
        nf,
        u,
        triplets,
        rhs_imposed: rhs,
        membrane_blocks,
    }
}

type Cholesky = faer::sparse::linalg::solvers::Llt<usize, Real>;

/// Factorizes the free block (`None` when nothing is free).
fn factor(
    asm: &Assembly,
    dirichlet: &Dirichlet,
    positions_m: &[Vec3],
) -> Result<Option<Cholesky>, StaticError> {
    if asm.nf == 0 {
        return Ok(None);
    }
    if !dirichlet.holds_rigid_motions(positions_m) {
        return Err(StaticError::Singular {
            constrained: dirichlet.count(),
        });
    }
    let k = SparseColMat::<usize, Real>::try_new_from_triplets(asm.nf, asm.nf, &asm.triplets)
        .map_err(|e| StaticError::Factorization(format!("{e:?}")))?;
    k.sp_cholesky(faer::Side::Lower)
        .map(Some)
        .map_err(|e| match e {
            faer::sparse::linalg::LltError::Numeric(_) => StaticError::Singular {
                constrained: dirichlet.count(),
            },
            other => StaticError::Factorization(other.to_string()),
        })
}

/// K factorized once for a set of imposed degrees of freedom, then solved
/// for many load cases (the precomputed backend's unit responses).
pub struct Factorized {
    asm: Assembly,
    llt: Option<Cholesky>,
}

impl Factorized {
    /// Assembles and factorizes K with `dirichlet` imposed.
    pub fn new(model: &ElasticModel, dirichlet: &Dirichlet) -> Result<Self, StaticError> {
        let asm = assemble(model, dirichlet);
        let llt = factor(&asm, dirichlet, model.mesh().positions_m())?;
        Ok(Self { asm, llt })
    }

    /// The displacements (m) under per-vertex loads `loads_n`, written to `out`.
    pub fn solve_into(&self, loads_n: &[Vec3], out: &mut [Vec3]) {
        let asm = &self.asm;
        let mut x = faer::Mat::<Real>::from_fn(asm.nf, 1, |i, _| asm.rhs_imposed[i]);
        for (d, &i) in asm.free.iter().enumerate() {
            if i != usize::MAX {
                x[(i, 0)] += loads_n[d / 3][d % 3];
            }
        }
        if let Some(llt) = &self.llt {
            llt.solve_in_place(x.as_mut());
        }
        for (v, o) in out.iter_mut().enumerate() {
            *o = Vec3::from_array(std::array::from_fn(|a| {
                let d = 3 * v + a;
                match asm.free[d] {
                    usize::MAX => asm.u[d],
                    i => x[(i, 0)],
                }
            }));
        }
    }
}
