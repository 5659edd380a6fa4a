//! The precomputed (quasi-static) backend of Cotin et al. (paper 3.5): the
//! response of every vertex to a unit force on each axis of each free
//! surface vertex is solved once (one sparse factorization, 3 solves per
//! surface vertex); a step is then linear algebra on those responses:
//!
//! - external forces: u = sum over loaded vertices of T_.s F_s;
//! - imposed surface displacements (tool contact): the forces F_c on the d
//!   constrained vertices solve the small 3d x 3d system T_cc F_c =
//!   d_c - u_c (factorised when a hold begins or ends, [`super::holds`]),
//!   then u += sum_c T_.c F_c.
//!
//! It is static (no inertia, no damping), so it is the fastest and the
//! least dynamic backend. Cutting is refused: the responses assume the mesh
//! they were computed on. The responses are cached on disk, keyed by a hash
//! of the mesh, the tensors (hence materials) and the fixed set.

use super::cache::{key, read_cache, write_cache};
use super::compliance::{Compliance, penalty};
use super::holds::Holds;
use super::{Backend, Capabilities};
use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::static_solve::{Dirichlet, Factorized, StaticError};
use crate::tensor_mass::{CutChange, CutError, ElasticModel, ForceTerm};
use std::path::{Path, PathBuf};

mod rows;

const NONE: u32 = u32::MAX;

/// Why the precomputation failed.
#[derive(Debug, thiserror::Error)]
pub enum PrecomputedError {
    /// The stiffness could not be factorized.
    #[error(transparent)]
    Static(#[from] StaticError),
    /// The mesh is too large to keep its responses.
    #[error(transparent)]
    TooLarge(#[from] super::cache::TooManyResponses),
}

/// The precomputed backend.
pub struct Precomputed {
    model: ElasticModel,
    dt_s: Real,
    /// Surface index of each vertex (NONE: interior or fixed).
    slot: Vec<u32>,
    surface: Vec<VertexId>,
    /// responses[(3 s + a) * n + j]: displacement of vertex j under a unit
    /// force along axis a on surface vertex s.
    responses: Vec<Vec3>,
    u: Vec<[Real; 3]>,
    held: Vec<Option<Vec3>>,
    fext: Vec<Vec3>,
    holds: Holds,
    /// Holding forces of this step: (surface index, force).
    applied: Vec<(u32, Vec3)>,
    work: Vec<Vec3>,
    /// The penalty contact's forces on the vertices listed in
    /// `contact_loaded` (zero elsewhere; the penalty solve in `backend::compliance::penalty`).
    contact_n: Vec<Vec3>,
    contact_loaded: Vec<u32>,
    /// The loads' part of a contact step's solution ([`Precomputed::prepare_rows`]).
    u_ext: Vec<Vec3>,
    /// The contact solve's scratch.
    contact: penalty::ContactSolve,
    /// The responses at the contact step's rows ([`Precomputed::step_rows`]).
    row_responses: rows::RowResponses,
    /// Whether the last load came from the disk cache.
    pub from_cache: bool,
}

impl Precomputed {
    /// Refuses nonlinear material models (the scene checks with this too).
    pub fn check_model(model: &ElasticModel) -> Result<(), crate::tensor_mass::LinearOnly> {
        model.require_linear(
            "precomputed backend",
            "its responses are solved once for the linear stiffness",
            |_| true,
        )
    }

    /// Precomputes `model` with `fixed` held at rest (reads or writes
    /// `cache_dir` when given; `progress` gets (done, total) solves).
    pub fn new(
        model: ElasticModel,
        fixed: &[VertexId],
        dt_s: Real,
        cache_dir: Option<&Path>,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Self, PrecomputedError> {
        Self::check_model(&model).map_err(StaticError::from)?;
        let n = model.vertex_count();
        let mut slot = vec![NONE; n];
        let mut surface = Vec::new();
        let is_fixed = {
            let mut f = vec![false; n];
            for v in fixed {
                f[v.idx()] = true;
            }
            f
        };
        for tri in model.topology().surface_triangles(model.mesh()) {
            for v in tri {
                if slot[v.idx()] == NONE && !is_fixed[v.idx()] {
                    slot[v.idx()] = surface.len() as u32;
                    surface.push(v);
                }
            }
        }
        let cache: Option<PathBuf> =
            cache_dir.map(|d| d.join(format!("precomputed-{:016x}.bin", key(&model, fixed, &[]))));
        // Refused before the cache is read or anything factorised.
        let expected = super::cache::check_responses(3 * surface.len(), n)?;
        let mut responses = cache
            .as_deref()
            .and_then(|p| read_cache(p, expected))
            .unwrap_or_default();
        let from_cache = responses.len() == expected;
        if !from_cache {
            let mut bc = Dirichlet::new(n);
            for v in fixed {
                bc.fix(*v);
            }
            let k = Factorized::new(&model, &bc)?;
            responses = super::cache::response_buffer(3 * surface.len(), n)?;
            let mut load = vec![Vec3::ZERO; n];
            for (s, v) in surface.iter().enumerate() {
                for a in 0..3 {
                    load[v.idx()] = Vec3::ZERO;
                    load[v.idx()][a] = 1.0;
                    let at = (3 * s + a) * n;
                    k.solve_into(&load, &mut responses[at..at + n]);
                    load[v.idx()] = Vec3::ZERO;
                    progress(3 * s + a + 1, 3 * surface.len());
                }
            }
            if let Some(p) = &cache {
                // A cache that cannot be written costs the next start time only.
                let _ = write_cache(p, &responses);
            }
        }
        Ok(Self {
            model,
            dt_s,
            slot,
            surface,
            responses,
            u: vec![[0.0; 3]; n],
            held: vec![None; n],
            fext: vec![Vec3::ZERO; n],
            holds: Holds::new(),
            applied: Vec::new(),
            work: Vec::new(),
            contact_n: vec![Vec3::ZERO; n],
            contact_loaded: Vec::new(),
            u_ext: Vec::new(),
            contact: Default::default(),
            row_responses: Default::default(),
            from_cache,
        })
    }

    /// Whether a force on `v` is represented: the responses cover forces
    /// on free surface vertices only.
    pub fn can_load(&self, v: VertexId) -> bool {
        self.slot.get(v.idx()).is_some_and(|&s| s != NONE)
    }

    /// Free surface vertices (the precomputed sources).
    pub fn surface_len(&self) -> usize {
        self.surface.len()
    }

    fn response(&self, s: u32, a: usize) -> &[Vec3] {
        response(&self.responses, self.u.len(), s, a)
    }

    fn refresh_holds(&mut self) {
        if self.holds.is_dirty() {
            let n = self.u.len();
            let (surface, responses, slot) = (&self.surface, &self.responses, &self.slot);
            let held = (self.held.iter().enumerate())
                .filter(|(v, h)| h.is_some() && slot[*v] != NONE)
                .map(|(v, _)| slot[v]);
            self.holds.refresh(held, |i, j, b| {
                response(responses, n, j, b)[surface[i as usize].idx()]
            });
        }
    }
}

impl Compliance for Precomputed {
    fn vertex_len(&self) -> usize {
        self.u.len()
    }
    fn loadable(&self, v: usize) -> bool {
        self.slot[v] != NONE && self.held[v].is_none()
    }
    fn response_of(&self, v: u32, a: usize) -> &[Vec3] {
        self.response(self.slot[v as usize], a)
    }
    fn displacement_of(&self, v: u32) -> Vec3 {
        Vec3::from_array(self.u[v as usize])
    }
    fn set_displacement(&mut self, v: u32, d_m: Vec3) {
        self.u[v as usize] = d_m.to_array();
    }
    fn clear_contact_forces(&mut self) {
        for &v in &self.contact_loaded {
            self.contact_n[v as usize] = Vec3::ZERO;
        }
        self.contact_loaded.clear();
    }
    fn hold_count(&self) -> usize {
        self.holds.len()
    }
    fn holding_response(&mut self, v: u32, a: usize, out: &mut Vec<(u32, Vec3)>) {
        out.clear();
        let n = self.u.len();
        let (responses, surface) = (&self.responses, &self.surface);
        let column = response(responses, n, self.slot[v as usize], a);
        self.holds.solve(
            |s| -column[surface[s as usize].idx()],
            |s, f| out.push((s, f)),
        );
    }
    fn source_response(&self, s: u32, a: usize) -> &[Vec3] {
        self.response(s, a)
    }
    fn contact_forces(&self) -> impl Iterator<Item = (u32, Vec3)> + '_ {
        (self.contact_loaded.iter()).map(|&v| (v, self.contact_n[v as usize]))
    }
    fn set_contact_forces(&mut self, vertices: &[u32], force: &[[Real; 3]]) {
        self.clear_contact_forces();
        for &v in vertices {
            self.contact_n[v as usize] = Vec3::from_array(force[v as usize]);
            self.contact_loaded.push(v);
        }
    }
    fn prepare_rows(&mut self) {
        let n = self.u.len();
        self.u_ext.clear();
        self.u_ext.resize(n, Vec3::ZERO);
        let (responses, slot) = (&self.responses, &self.slot);
        add_responses(
            responses,
            slot,
            &mut self.u_ext,
            self.fext.iter().enumerate(),
        );
        self.refresh_holds();
    }
    fn step_rows(&mut self, rows: &[u32]) {
        let n = self.u.len();
        let (responses, slot, surface) = (&self.responses, &self.slot, &self.surface);
        let (contact_n, loaded, u_ext) = (&self.contact_n, &self.contact_loaded, &self.u_ext);
        let free = |v: usize| {
            let mut u = u_ext[v];
            for &c in loaded {
                let (f, s) = (contact_n[c as usize], slot[c as usize]);
                for a in 0..3 {
                    u += f[a] * response(responses, n, s, a)[v];
                }
            }
            u
        };
        let held = &self.held;
        solve_holds(&mut self.holds, held, surface, &mut self.applied, free);
        // free(v) at the rows, from the responses gathered at them.
        let sums = self.row_responses.superpose(
            n,
            rows,
            u_ext,
            loaded.iter().map(|&c| (c, contact_n[c as usize])),
            |v, a| response(responses, n, slot[v as usize], a),
        );
        for (&v, &free_v) in rows.iter().zip(sums) {
            let v = v as usize;
            let u = match held[v] {
                Some(d) => d,
                None => (self.applied.iter()).fold(free_v, |u, &(s, f)| {
                    (0..3).fold(u, |u, b| u + f[b] * response(responses, n, s, b)[v])
                }),
            };
            self.u[v] = u.to_array();
        }
    }
    fn step_static(&mut self) {
        let n = self.u.len();
        let mut u = std::mem::take(&mut self.work);
        u.clear();
        u.resize(n, Vec3::ZERO);
        self.refresh_holds();
        let (responses, slot) = (&self.responses, &self.slot);
        let contact =
            (self.contact_loaded.iter()).map(|&v| (v as usize, &self.contact_n[v as usize]));
        add_responses(
            responses,
            slot,
            &mut u,
            self.fext.iter().enumerate().chain(contact),
        );
        let (surface, held) = (&self.surface, &self.held);
        solve_holds(&mut self.holds, held, surface, &mut self.applied, |v| u[v]);
        for &(s, f) in &self.applied {
            add_source(&mut u, responses, s, f);
        }
        for (v, o) in self.u.iter_mut().enumerate() {
            *o = match self.held[v] {
                Some(d) => d.to_array(),
                None => u[v].to_array(),
            };
        }
        self.work = u;
    }
}

/// Adds to `out` (every vertex) the responses to the forces `loads`
/// ((vertex, force)) on the vertices that have responses (`slot`).
fn add_responses<'a>(
    responses: &[Vec3],
    slot: &[u32],
    out: &mut [Vec3],
    loads: impl Iterator<Item = (usize, &'a Vec3)>,
) {
    for (v, f) in loads {
        let s = slot[v];
        if s == NONE || *f == Vec3::ZERO {
            continue;
        }
        add_source(out, responses, s, *f);
    }
}

/// Adds to `out` (every vertex) the responses to the force `f` on surface
/// vertex (source) `s`: one pass over the vertices for the three axes
/// where each axis took a pass of its own (the whole body's application is
/// about half a contact step's time on the precomputed backend, `perf`),
/// each vertex's three additions in the order of those passes, so the sums
/// are the same to the bit. An axis with no force is skipped.
fn add_source(out: &mut [Vec3], responses: &[Vec3], s: u32, f: Vec3) {
    let n = out.len();
    let [r0, r1, r2] = [0, 1, 2].map(|a| response(responses, n, s, a));
    if f.x != 0.0 && f.y != 0.0 && f.z != 0.0 {
        for (((o, a), b), c) in out.iter_mut().zip(r0).zip(r1).zip(r2) {
            *o += f.x * *a;
            *o += f.y * *b;
            *o += f.z * *c;
        }
        return;
    }
    for (a, r) in [r0, r1, r2].into_iter().enumerate() {
        if f[a] != 0.0 {
            for (o, x) in out.iter_mut().zip(r) {
                *o += f[a] * *x;
            }
        }
    }
}

/// The holds' forces into `applied` ((surface index, force)), `free(v)`
/// being vertex v's displacement without them.
fn solve_holds(
    holds: &mut Holds,
    held: &[Option<Vec3>],
    surface: &[VertexId],
    applied: &mut Vec<(u32, Vec3)>,
    free: impl Fn(usize) -> Vec3,
) {
    applied.clear();
    holds.solve(
        |s| {
            let v = surface[s as usize].idx();
            held[v].unwrap_or(Vec3::ZERO) - free(v)
        },
        |s, f| applied.push((s, f)),
    );
}

/// The response of all `n` vertices to a unit force along `a` on surface vertex `s`.
fn response(responses: &[Vec3], n: usize, s: u32, a: usize) -> &[Vec3] {
    let at = (3 * s as usize + a) * n;
    &responses[at..at + n]
}

impl Backend for Precomputed {
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            dynamic: false,
            integrates_contact: true,
            ..Capabilities::dynamic("precomputed")
        }
    }
    fn model(&self) -> &ElasticModel {
        &self.model
    }
    fn dt_s(&self) -> Real {
        self.dt_s
    }

    fn step(&mut self) {
        self.clear_contact_forces();
        self.step_static();
    }

    /// The penalty law's Newton iterations (0 without contact or under the
    /// projection law), capped at the iteration limit short of the
    /// tolerance.
    fn linear_solve(&self) -> Option<super::SolveReport> {
        Some(super::SolveReport {
            iterations: self.contact.iterations,
            capped: self.contact.capped,
        })
    }

    fn step_with_contact<F: ForceTerm, R: FnMut(&Self, &mut F)>(
        &mut self,
        field: &mut F,
        _resample_every_s: Real,
        _resample: &mut R,
    ) {
        // Static: one solve a step, nothing to re-select within it.
        let mut scratch = std::mem::take(&mut self.contact);
        penalty::step_with_penalty(self, field, &mut scratch);
        self.contact = scratch;
    }

    fn displacement(&self, v: VertexId) -> Vec3 {
        Vec3::from_array(self.u[v.idx()])
    }
    fn displacements(&self) -> &[[Real; 3]] {
        &self.u
    }
    fn prescribe(&mut self, v: VertexId, d_m: Vec3) {
        if self.held[v.idx()].is_none() && self.can_load(v) {
            self.holds.changed();
        }
        self.held[v.idx()] = Some(d_m);
    }
    fn release(&mut self, v: VertexId) {
        if self.held[v.idx()].is_some() && self.can_load(v) {
            self.holds.changed();
        }
        self.held[v.idx()] = None;
    }
    fn set_external_force(&mut self, v: VertexId, f_n: Vec3) {
        self.fext[v.idx()] = f_n;
    }
    fn can_cut(&self, _t: TetId) -> bool {
        false
    }
    fn remove_tet(&mut self, _t: TetId) -> Result<CutChange, CutError> {
        Err(CutError::Unsupported {
            backend: "precomputed",
            why: "its responses were computed on the uncut mesh; cut with tensor-mass, implicit, or hybrid (precomputed where nothing is cut)",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One pass for the three axes gives the sums of three passes to the
    /// bit (each vertex's additions in the same order), a zero axis
    /// included.
    #[test]
    fn one_pass_per_source_equals_a_pass_per_axis_to_the_bit() {
        let n = 37;
        // Two sources' responses, irregular values.
        let responses: Vec<Vec3> = (0..2 * 3 * n)
            .map(|i| {
                let x = i as Real;
                Vec3::new(
                    (x * 0.37).sin(),
                    (x * 1.3).cos() * 1e-3,
                    (x * 0.11).sin() * 7.0,
                )
            })
            .collect();
        for f in [Vec3::new(0.3, -1.7, 2.9), Vec3::new(0.0, 4.1, -0.2)] {
            let start: Vec<Vec3> = (0..n).map(|i| Vec3::splat(i as Real * 0.013)).collect();
            let mut fused = start.clone();
            let mut passes = start;
            for s in 0..2 {
                add_source(&mut fused, &responses, s, f);
                for a in 0..3 {
                    if f[a] != 0.0 {
                        for (o, r) in passes.iter_mut().zip(response(&responses, n, s, a)) {
                            *o += f[a] * *r;
                        }
                    }
                }
            }
            let bits = |v: &[Vec3]| -> Vec<u64> {
                v.iter()
                    .flat_map(|x| x.to_array().map(Real::to_bits))
                    .collect()
            };
            assert_eq!(bits(&fused), bits(&passes));
        }
    }
}
