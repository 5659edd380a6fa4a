//! The contact stiffness a tool feels: d F / d (tool position) with the
//! tissue in equilibrium, for the local-model extrapolator of the haptic
//! loop.
//!
//! Each active contact point p (weights w_p on its triangle's vertices)
//! stores the Hessian G_p of its spring energy with respect to its
//! position relative to the tool ([`ContactField::hessians`]: the spring
//! along the normal, less the turning of the normal around the round
//! tool). With J_p the map from tissue displacements to the point's
//! motion and K the tissue's stiffness with the scene's fixed vertices
//! held, moving the tool by dx with the tissue in equilibrium gives
//!
//! ```text
//! dF = -K_eff dx,   K_eff = A - B^T (K + H)^-1 B,
//! A = sum G_p,  B = sum J_p^T G_p,  H = sum J_p^T G_p J_p
//! ```
//!
//! (for springs along fixed normals, K_eff = N^T (Kp^-1 + J K^-1 J^T)^-1 N:
//! the springs in series with the tissue's compliance at the contact
//! points, J K^-1 J^T being SOFA's compliance W = H A^-1 H^T, Duriez et
//! al. 2006). Only the rows and columns of K^-1 at the touched vertices V
//! are needed: with S = (K^-1)_VV,
//!
//! ```text
//! K_eff = N^T Kp N - B^T S (I + H S)^-1 B
//! ```
//!
//! a dense solve of size 3|V|. K is factorised once (sparse Cholesky,
//! [`crate::static_solve::Factorized`]) at start; the three columns of
//! K^-1 of each touched vertex are solved for the first time it is touched
//! and kept ([`columns::ColumnCache`]: 16 MiB claimed when the factor is
//! made, emptied when full). A cut changes K: the
//! factor is rebuilt on a worker thread and the old one serves until it is
//! ready. Meshes above [`MAX_FACTOR_VERTICES`] (where a factor costs
//! seconds and the columns megabytes) use S = blockdiag(K_ii)^-1 instead,
//! which neglects the coupling through the tissue and overestimates the
//! stiffness (about 3x on a 5 mm-cell block).
//!
//! The solver works on a [`Snapshot`] of the active points, so that the
//! live simulation can run it on a worker thread
//! ([`crate::contact::response::worker`]).
//!
//! Neglected: the Hunt-Crossley damping (zero at rest), the tissue's
//! inertia (K_eff is the quasi-static stiffness), points entering or
//! leaving contact (they do so at zero force), grips and the other tools'
//! contacts (their vertices count as free tissue).

use crate::contact::local::LocalContact;
use crate::contact::penalty::field::ContactField;
use crate::ids::VertexId;
use crate::math::{Mat3, Real, Vec3};
use crate::static_solve::{Dirichlet, Factorized};
use crate::tensor_mass::ElasticModel;
use std::collections::HashMap;
use std::thread::JoinHandle;

mod columns;
mod local_solves;

use columns::ColumnCache;

/// Above this many vertices the stiffness uses the diagonal blocks only.
pub const MAX_FACTOR_VERTICES: usize = 60_000;

/// One active contact point as the solver needs it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct SnapPoint {
    vertices: [u32; 3],
    weights: [Real; 3],
    /// Its Hessian with the normal's turning ([`ContactField::hessians`]).
    hessian: Mat3,
    /// The spring part alone.
    spring: Mat3,
    tool: usize,
}

/// The active contact points of a step, copied out of the field (buffers
/// reused).
#[derive(Clone, Debug, Default)]
pub(in crate::contact) struct Snapshot {
    points: Vec<SnapPoint>,
}

impl Snapshot {
    /// Copies the field's points in contact.
    pub(in crate::contact) fn fill(&mut self, field: &ContactField) {
        self.points.clear();
        for (i, p) in field.points().iter().enumerate() {
            if field.penetrations_m()[i] > 0.0 {
                self.points.push(SnapPoint {
                    vertices: p.vertices,
                    weights: p.weights,
                    hessian: field.hessians()[i],
                    spring: field.spring_hessians()[i],
                    tool: field.parts()[p.part as usize].tool,
                });
            }
        }
    }

    /// The points touching `tool`.
    fn of(&self, tool: usize) -> impl Iterator<Item = &SnapPoint> + Clone {
        self.points.iter().filter(move |p| p.tool == tool)
    }
}

/// The contact stiffness solver of a scene.
pub(in crate::contact) struct Solver {
    dirichlet: Vec<VertexId>,
    factor: Option<Factorized>,
    /// `ElasticModel::topology_changes` the factor was built for.
    built_for: u64,
    pending: Option<(u64, JoinHandle<Option<Factorized>>)>,
    /// Per touched vertex: K^-1 columns for its x, y and z (3 n vectors),
    /// and the column mass's blocks between them.
    columns: ColumnCache,
    // Scratch reused across steps.
    verts: Vec<u32>,
    slot: HashMap<u32, usize>,
    h: Vec<Real>,
    b: Vec<Real>,
    s: Vec<Real>,
    m: Vec<Real>,
    x: Vec<Real>,
    unit: Vec<Vec3>,
    /// M times a vertex's three K^-1 columns (3 x 3n).
    weighted: Vec<Real>,
}

impl Solver {
    /// For `model` with `held` vertices fixed (the scene's fixed and
    /// prescribed ones); factorises K now unless the mesh is too large.
    pub(in crate::contact) fn new(model: &ElasticModel, held: &[VertexId]) -> Self {
        let mut out = Self {
            dirichlet: held.to_vec(),
            factor: None,
            built_for: model.topology_changes(),
            pending: None,
            columns: ColumnCache::unsized_for(model.topology_changes()),
            verts: Vec::new(),
            slot: HashMap::new(),
            h: Vec::new(),
            b: Vec::new(),
            s: Vec::new(),
            m: Vec::new(),
            x: Vec::new(),
            unit: Vec::new(),
            weighted: Vec::new(),
        };
        if model.vertex_count() <= MAX_FACTOR_VERTICES {
            out.factor = build(model, &out.dirichlet);
        }
        if out.factor.is_some() {
            out.size_scratch(model);
        }
        out
    }

    /// The columns' cache and the per-vertex scratch for `model`'s vertex
    /// count, claimed (and touched) now: at start or when a factor for a
    /// changed mesh comes in, not as contacts touch new vertices.
    /// Nothing is done when they are sized already (`unit` is all zeros
    /// between solves: each column's solve puts its 1 back to 0).
    fn size_scratch(&mut self, model: &ElasticModel) {
        let n = model.vertex_count();
        if self.columns.vertex_count() != n || self.columns.slots() == 0 {
            self.columns = ColumnCache::new(n, model.topology_changes());
        }
        if self.unit.len() != n {
            self.unit.clear();
            self.unit.resize(n, Vec3::ZERO);
        }
        if self.weighted.len() != 9 * n {
            self.weighted.clear();
            self.weighted.resize(9 * n, 0.0);
        }
    }

    /// Whether K_eff uses the tissue's full compliance (else the diagonal
    /// blocks only).
    pub(in crate::contact) fn exact(&self) -> bool {
        self.factor.is_some()
    }

    /// Keeps the factor in step with cuts: starts a rebuild on a worker
    /// thread after a cut, swaps it in when done.
    fn refresh(&mut self, model: &ElasticModel) {
        let now = model.topology_changes();
        if let Some((version, handle)) = &self.pending
            && handle.is_finished()
        {
            let version = *version;
            if let Some((_, handle)) = self.pending.take()
                && let Ok(Some(f)) = handle.join()
            {
                self.factor = Some(f);
                self.built_for = version;
                self.columns.clear();
                self.size_scratch(model);
            }
        }
        if now != self.built_for
            && self.pending.is_none()
            && model.vertex_count() <= MAX_FACTOR_VERTICES
        {
            let (model, held) = (model.clone(), self.dirichlet.clone());
            let handle = std::thread::Builder::new()
                .name("contact-factor".into())
                .spawn(move || {
                    crate::background::lower_this_thread();
                    build(&model, &held)
                });
            if let Ok(handle) = handle {
                self.pending = Some((now, handle));
            }
        }
    }

    /// K_eff (N/m) of tool `tool` from the snapshot's points.
    pub(in crate::contact) fn stiffness(
        &mut self,
        model: &ElasticModel,
        snap: &Snapshot,
        tool: usize,
    ) -> Mat3 {
        self.refresh(model);
        let full = self.effective(model, snap, tool, |p| p.hessian);
        // With the normals' turning, K + H can lose definiteness (a round
        // tool on a crease is laterally unstable) and the Schur complement
        // then means nothing: it must stay below the springs alone.
        let springs: Mat3 = snap.of(tool).fold(Mat3::ZERO, |s, p| s + p.spring);
        // Cheap and sufficient: a valid K_eff is A less a positive
        // semidefinite term, so its size stays of the order of the
        // springs' trace; a near-singular K + H blows far past it.
        let size = full
            .to_cols_array()
            .iter()
            .map(|x| x * x)
            .sum::<Real>()
            .sqrt();
        let trace = springs.x_axis.x + springs.y_axis.y + springs.z_axis.z;
        if full.is_finite() && size <= 2.0 * trace {
            full
        } else {
            self.effective(model, snap, tool, |p| p.spring)
        }
    }

    /// K_eff with each point's Hessian `hessian(p)`.
    fn effective(
        &mut self,
        model: &ElasticModel,
        snap: &Snapshot,
        tool: usize,
        hessian: impl Fn(&SnapPoint) -> Mat3,
    ) -> Mat3 {
        let mut a = Mat3::ZERO;
        self.verts.clear();
        self.slot.clear();
        for p in snap.of(tool) {
            for v in p.vertices {
                if !self.slot.contains_key(&v) {
                    self.slot.insert(v, self.verts.len());
                    self.verts.push(v);
                }
            }
        }
        let nv = 3 * self.verts.len();
        if nv == 0 {
            return a;
        }
        // H (nv x nv), B (nv x 3), A = N^T Kp N.
        self.h.clear();
        self.h.resize(nv * nv, 0.0);
        self.b.clear();
        self.b.resize(nv * 3, 0.0);
        for p in snap.of(tool) {
            let nn = hessian(p);
            a += nn;
            for (i, vi) in p.vertices.iter().enumerate() {
                let si = 3 * self.slot[vi];
                let wi = p.weights[i];
                for r in 0..3 {
                    for c in 0..3 {
                        self.b[(si + r) * 3 + c] += wi * nn.col(c)[r];
                    }
                }
                for (j, vj) in p.vertices.iter().enumerate() {
                    let sj = 3 * self.slot[vj];
                    let w = wi * p.weights[j];
                    for r in 0..3 {
                        for c in 0..3 {
                            self.h[(si + r) * nv + sj + c] += w * nn.col(c)[r];
                        }
                    }
                }
            }
        }
        self.fill_s(model, nv);
        // M = I + H S, X = M^-1 B, K_eff = A - B^T S X.
        self.m.clear();
        self.m.resize(nv * nv, 0.0);
        for i in 0..nv {
            for k in 0..nv {
                let hik = self.h[i * nv + k];
                if hik != 0.0 {
                    for j in 0..nv {
                        self.m[i * nv + j] += hik * self.s[k * nv + j];
                    }
                }
            }
            self.m[i * nv + i] += 1.0;
        }
        self.x.clear();
        self.x.extend_from_slice(&self.b);
        if !crate::math::solve_in_place(&mut self.m, &mut self.x, nv, 3) {
            return a;
        }
        let mut k = a;
        for r in 0..3 {
            for c in 0..3 {
                let mut sum = 0.0;
                for i in 0..nv {
                    let mut sx = 0.0;
                    for j in 0..nv {
                        sx += self.s[i * nv + j] * self.x[j * 3 + c];
                    }
                    sum += self.b[i * 3 + r] * sx;
                }
                k.col_mut(c)[r] -= sum;
            }
        }
        // Symmetric in exact arithmetic; remove the rounding.
        (k + k.transpose()) * 0.5
    }

    /// Solves and caches the K^-1 columns of the vertices in `verts` not
    /// cached yet (nothing without a factor).
    fn ensure_columns(&mut self, model: &ElasticModel) {
        if self.factor.is_none() {
            return;
        }
        // A cut may have changed the vertex count before its factor came in.
        self.size_scratch(model);
        let Some(factor) = &self.factor else {
            return;
        };
        let n = model.vertex_count();
        // Only the vertices not cached yet count: the compliance and the
        // column mass of one problem ask for the same ones in turn.
        let new = self
            .verts
            .iter()
            .filter(|v| !self.columns.contains(**v))
            .count();
        self.columns.make_room(new, self.verts.len());
        for &v in &self.verts {
            if self.columns.contains(v) {
                continue;
            }
            let unit = &mut self.unit;
            self.columns.insert_with(v, |cols| {
                for axis in 0..3 {
                    unit[v as usize] = Vec3::ZERO;
                    unit[v as usize][axis] = 1.0;
                    factor.solve_into(unit, &mut cols[axis * n..(axis + 1) * n]);
                }
                unit[v as usize] = Vec3::ZERO;
            });
        }
    }

    /// S = (K^-1)_VV from the cached columns (solved for new vertices), or
    /// blockdiag(K_ii)^-1 without a factor.
    fn fill_s(&mut self, model: &ElasticModel, nv: usize) {
        self.s.clear();
        self.s.resize(nv * nv, 0.0);
        if self.factor.is_none() {
            for (slot, &v) in self.verts.iter().enumerate() {
                let kinv = model.vertex_tensors()[v as usize].inverse();
                if !kinv.is_finite() {
                    continue;
                }
                for r in 0..3 {
                    for c in 0..3 {
                        self.s[(3 * slot + r) * nv + 3 * slot + c] = kinv.col(c)[r];
                    }
                }
            }
            return;
        }
        self.ensure_columns(model);
        for (sj, &vj) in self.verts.iter().enumerate() {
            for c in 0..3 {
                let col = self.columns.column(vj, c);
                for (si, vi) in self.verts.iter().enumerate() {
                    let x = col[*vi as usize];
                    for r in 0..3 {
                        self.s[(3 * si + r) * nv + 3 * sj + c] = x[r];
                    }
                }
            }
        }
    }
}

/// K factorised with `held` fixed; `None` if it cannot be (then the
/// diagonal approximation serves).
fn build(model: &ElasticModel, held: &[VertexId]) -> Option<Factorized> {
    let mut d = Dirichlet::new(model.vertex_count());
    for v in held {
        d.fix(*v);
    }
    // Vertices no live tetrahedron holds any more (cut free) are fixed so
    // that K stays definite.
    for v in 0..model.vertex_count() {
        if model.topology().vertex_tet_count(VertexId::from(v)) == 0 {
            d.fix(VertexId::from(v));
        }
    }
    Factorized::new(model, &d).ok()
}
