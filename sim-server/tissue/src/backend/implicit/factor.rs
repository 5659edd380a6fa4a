//! The implicit backend's Cholesky preconditioner: A = M + h C + h^2 K on
//! the degrees of freedom that were free when it was factorised.
//!
//! While the held set is the one it was factorised for, it is A^-1 and the
//! conjugate gradients converge in one or two iterations; when tools hold
//! or release vertices, or cuts change K, it is the inverse of a nearby
//! matrix and they take a few more, and the backend refactorises once they
//! take too many. It stays symmetric positive definite on whatever rows are
//! free: rows it covers get (A_F0^-1 r) restricted to them, rows it does
//! not cover (released since) get the Jacobi step r / diag, held rows 0.
//! The solve runs on one thread into buffers allocated here, so applying it
//! allocates nothing.
//!
//! It is assembled from an [`Assembly`]: borrowed from the model for an
//! inline build, or from a [`Snapshot`](super::rebuild::Snapshot) the
//! stepping thread copied for the background worker. Either way the factor
//! records which rows were free in the held set it was given (`index`), not
//! the backend's current one, so [`Factor::apply`] compares that set with
//! the current one at every use, however much it changed since.

use crate::ids::VertexId;
use crate::math::{Mat3, Real, Vec3};
use crate::tensor_mass::ElasticModel;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholesky, factorize_symbolic_cholesky};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Par, Side};

const NOT_FREE: usize = usize::MAX;

/// The arrays A is assembled from (see [`ElasticModel`] for each).
#[derive(Clone, Copy)]
pub(super) struct Assembly<'a> {
    pub masses_kg: &'a [Real],
    pub damping_kg_s: &'a [Real],
    pub vertex_tensors: &'a [Mat3],
    pub edges: &'a [[VertexId; 2]],
    pub edge_tensors: &'a [Mat3],
}

impl<'a> Assembly<'a> {
    /// The model's current arrays.
    pub fn of(model: &'a ElasticModel) -> Self {
        Self {
            masses_kg: model.masses_kg(),
            damping_kg_s: model.damping_kg_s(),
            vertex_tensors: model.vertex_tensors(),
            edges: model.topology().edges(),
            edge_tensors: model.edge_tensors(),
        }
    }
}

/// A factorised A over the rows free at construction.
pub(super) struct Factor {
    /// Index in the factor of each degree of freedom (NOT_FREE: held then).
    index: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
    values: Vec<Real>,
    rhs: faer::Mat<Real>,
    scratch: MemBuffer,
}

impl Factor {
    /// Assembles and factorises A = diag(m + h c) + h^2 K over the vertices
    /// not `held`. `Err` names what failed (the backend then stays on Jacobi).
    pub fn new(model: &Assembly, h: Real, held: &[bool]) -> Result<Self, String> {
        let n = model.masses_kg.len();
        assert_eq!(held.len(), n, "one held flag per vertex");
        // Every buffer that grows with the mesh is reserved fallibly: a mesh
        // too large to factorise gets an Err (and Jacobi), not an abort.
        let mut index = Vec::new();
        index
            .try_reserve_exact(3 * n)
            .map_err(|e| format!("index: {e}"))?;
        index.resize(3 * n, NOT_FREE);
        let mut nf = 0;
        for (v, &is_held) in held.iter().enumerate() {
            if !is_held {
                for a in 0..3 {
                    index[3 * v + a] = nf;
                    nf += 1;
                }
            }
        }
        let (m, c) = (model.masses_kg, model.damping_kg_s);
        // Lower triangle: 6 entries per vertex block, 9 per edge block.
        let mut triplets = Vec::new();
        triplets
            .try_reserve(6 * n + 9 * model.edge_tensors.len())
            .map_err(|e| format!("assembly: {e}"))?;
        let mut push = |a: usize, b: usize, k: &Mat3, shift: Real| {
            for r in 0..3 {
                let fr = index[3 * a + r];
                for col in 0..3 {
                    let fc = index[3 * b + col];
                    if fr != NOT_FREE && fc != NOT_FREE && fr >= fc {
                        let diag = if r == col { shift } else { 0.0 };
                        triplets.push(Triplet::new(fr, fc, h * h * k.col(col)[r] + diag));
                    }
                }
            }
        };
        for (v, k) in model.vertex_tensors.iter().enumerate() {
            push(v, v, k, m[v] + h * c[v]);
        }
        for ([a, b], k) in model.edges.iter().zip(model.edge_tensors) {
            push(a.idx(), b.idx(), k, 0.0);
            push(b.idx(), a.idx(), &k.transpose(), 0.0);
        }
        let mat = SparseColMat::<usize, Real>::try_new_from_triplets(nf, nf, &triplets)
            .map_err(|e| format!("assembly: {e:?}"))?;
        let symbolic = factorize_symbolic_cholesky(
            mat.symbolic(),
            Side::Lower,
            Default::default(),
            Default::default(),
        )
        .map_err(|e| format!("ordering: {e:?}"))?;
        let mut values = Vec::new();
        values
            .try_reserve_exact(symbolic.len_val())
            .map_err(|e| format!("factor of {} values: {e}", symbolic.len_val()))?;
        values.resize(symbolic.len_val(), 0.0);
        let mut factor_scratch = MemBuffer::try_new(
            symbolic.factorize_numeric_llt_scratch::<Real>(Par::Seq, Default::default()),
        )
        .map_err(|e| format!("workspace: {e:?}"))?;
        symbolic
            .factorize_numeric_llt::<Real>(
                &mut values,
                mat.as_ref(),
                Side::Lower,
                Default::default(),
                Par::Seq,
                MemStack::new(&mut factor_scratch),
                Default::default(),
            )
            .map_err(|e| format!("factorisation: {e:?}"))?;
        let scratch = MemBuffer::try_new(symbolic.solve_in_place_scratch::<Real>(1, Par::Seq))
            .map_err(|e| format!("workspace: {e:?}"))?;
        Ok(Self {
            index,
            symbolic,
            values,
            rhs: faer::Mat::zeros(nf, 1),
            scratch,
        })
    }

    /// z = P r: the factor's solve on the rows it covers, r / diag on free
    /// rows it does not, 0 on `held` rows.
    pub fn apply(&mut self, r: &[Vec3], held: &[bool], diag: &[Vec3], z: &mut [Vec3]) {
        for (d, &i) in self.index.iter().enumerate() {
            if i != NOT_FREE {
                self.rhs[(i, 0)] = if held[d / 3] { 0.0 } else { r[d / 3][d % 3] };
            }
        }
        LltRef::<usize, Real>::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            self.rhs.as_mut(),
            Par::Seq,
            MemStack::new(&mut self.scratch),
        );
        for (v, zv) in z.iter_mut().enumerate() {
            for a in 0..3 {
                zv[a] = match (held[v], self.index[3 * v + a]) {
                    (true, _) => 0.0,
                    (false, NOT_FREE) => r[v][a] / diag[v][a],
                    (false, i) => self.rhs[(i, 0)],
                };
            }
        }
    }
}
