//! The hybrid's precomputed part, condensed onto the vertices it shares
//! with the tensor-mass part. With the shared vertices I held at
//! displacements u_I and forces f on its free surface vertices, the part
//! is in static equilibrium at
//!
//!   u = C0 f + H u_I,
//!
//! C0 the responses to unit forces with I (and the fixed set) clamped, H the
//! responses to unit displacements of each shared degree of freedom (the
//! static "lifting" of I into the part). The force the part exerts on the
//! shared vertices is
//!
//!   F_I = -S u_I + H^T f,   S = K_II - K_IP K_PP^-1 K_PI,
//!
//! (S the part's stiffness condensed on I, H^T f by reciprocity). Surface
//! vertices held by a tool solve the small system C0_TT f_T = d_T - (C0
//! f + H u_I)_T, as in the precomputed backend. Everything is computed once
//! from one sparse factorization (3 solves per free surface vertex and per
//! shared vertex) and cached on disk like the precomputed backend's.

use super::super::cache::{key, read_cache, write_cache};
use super::super::holds::Holds;
use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::static_solve::{Dirichlet, Factorized};
use crate::tensor_mass::ElasticModel;
use std::path::Path;

const NONE: u32 = u32::MAX;

/// The precomputed part, condensed on the shared vertices.
pub(super) struct StaticPart {
    /// Vertices of the part.
    n: usize,
    /// Shared degrees of freedom (3 per shared vertex): S is dofs x dofs.
    dofs: usize,
    /// Source index of each vertex (NONE: interior, fixed or shared).
    source_of: Vec<u32>,
    /// Vertex of each source (free surface vertex, not shared).
    sources: Vec<u32>,
    /// c0[(3 s + a) * n + j]: displacement of j under a unit force along a
    /// on source s, shared vertices clamped.
    c0: Vec<Vec3>,
    /// lift[(3 j + b) * stride + c]: displacement along b of vertex j
    /// under a unit displacement of shared degree of freedom c (rows padded
    /// to `stride`, a multiple of 8), in single precision: it only places
    /// the part's vertices (a relative 1e-7 is far below the discretisation
    /// error) and streaming it is most of a step's cost. By vertex, so that
    /// a vertex is three contiguous dot products.
    lift: Vec<f32>,
    stride: usize,
    /// The shared displacements, flattened and padded like a lift row.
    u_flat: Vec<f64>,
    /// The same at the sources, in double precision and by source:
    /// lift_at_sources[s * 3 ni + c] (the forces use these).
    lift_at_sources: Vec<Vec3>,
    /// S, (3 ni) x (3 ni), row-major.
    schur: Vec<Real>,
    /// External forces per source (N).
    fext: Vec<Vec3>,
    /// Sources with a non-zero external force.
    loaded: Vec<u32>,
    /// Imposed displacement per vertex (tool holds).
    held: Vec<Option<Vec3>>,
    /// Held sources and the factorisation of their mutual responses.
    holds: Holds,
    /// Forces applied on the part this sub-step: (source, force).
    applied: Vec<(u32, Vec3)>,
    /// Whether the responses came from the disk cache.
    pub from_cache: bool,
}

impl StaticPart {
    /// Precomputes `model` (the part, local numbering) with `fixed` held at
    /// rest and `shared` clamped; `progress` gets (done, total) solves.
    pub fn new(
        model: &ElasticModel,
        fixed: &[VertexId],
        shared: &[VertexId],
        cache_dir: Option<&Path>,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Self, super::HybridError> {
        let n = model.vertex_count();
        let mut clamped = vec![false; n];
        for v in fixed.iter().chain(shared) {
            clamped[v.idx()] = true;
        }
        let mut source_of = vec![NONE; n];
        let mut sources = Vec::new();
        for tri in model.topology().surface_triangles(model.mesh()) {
            for v in tri {
                if source_of[v.idx()] == NONE && !clamped[v.idx()] {
                    source_of[v.idx()] = sources.len() as u32;
                    sources.push(v.0);
                }
            }
        }
        let (ns, ni) = (sources.len(), shared.len());
        let total = 3 * (ns + ni);
        let ids: Vec<u32> = shared.iter().map(|v| v.0).collect();
        let cache =
            cache_dir.map(|d| d.join(format!("hybrid-{:016x}.bin", key(model, fixed, &ids))));
        // Refused before the cache is read or anything factorised.
        let len = super::super::cache::check_responses(total, n)?;
        let mut all = cache
            .as_deref()
            .and_then(|p| read_cache(p, len))
            .unwrap_or_default();
        let from_cache = all.len() == len;
        if !from_cache {
            let mut bc = Dirichlet::new(n);
            for v in fixed.iter().chain(shared) {
                bc.fix(*v);
            }
            let k = Factorized::new(model, &bc)?;
            all = super::super::cache::response_buffer(total, n)?;
            let mut load = vec![Vec3::ZERO; n];
            let mut unit = vec![Vec3::ZERO; n];
            for c in 0..total {
                let (a, out) = (c % 3, &mut all[c * n..(c + 1) * n]);
                if c < 3 * ns {
                    let v = sources[c / 3] as usize;
                    load[v][a] = 1.0;
                    k.solve_into(&load, out);
                    load[v] = Vec3::ZERO;
                } else {
                    // Lifting: the free vertices' response to the forces a
                    // unit displacement of (i, a) exerts, -K e_ia.
                    let v = shared[c / 3 - ns].idx();
                    unit[v][a] = 1.0;
                    model.elastic_forces(&unit, &mut load);
                    k.solve_into(&load, out);
                    out[v] = unit[v];
                    unit[v] = Vec3::ZERO;
                    load.fill(Vec3::ZERO);
                }
                progress(c + 1, total);
            }
            if let Some(p) = &cache {
                // A cache that cannot be written costs the next start time only.
                let _ = write_cache(p, &all);
            }
        }
        let lift = all.split_off(3 * ns * n);
        let m = 3 * ni;
        let stride = m.div_ceil(8) * 8;
        let mut lift_at_sources = vec![Vec3::ZERO; ns * m];
        for (s, &v) in sources.iter().enumerate() {
            for c in 0..m {
                lift_at_sources[s * m + c] = lift[c * n + v as usize];
            }
        }
        // S column (i, a) = the force holding the lifted shape at I: K h_ia
        // there, minus the elastic force.
        let mut schur = vec![0.0; m * m];
        let mut f = vec![Vec3::ZERO; n];
        for c in 0..m {
            model.elastic_forces(&lift[c * n..(c + 1) * n], &mut f);
            for (j, v) in shared.iter().enumerate() {
                for b in 0..3 {
                    schur[(3 * j + b) * m + c] = -f[v.idx()][b];
                }
            }
        }
        Ok(Self {
            n,
            dofs: m,
            source_of,
            sources,
            c0: all,
            lift: {
                let mut t = vec![0.0f32; 3 * n * stride];
                for c in 0..m {
                    for (j, h) in lift[c * n..(c + 1) * n].iter().enumerate() {
                        for b in 0..3 {
                            t[(3 * j + b) * stride + c] = h[b] as f32;
                        }
                    }
                }
                t
            },
            stride,
            u_flat: vec![0.0; stride],
            lift_at_sources,
            schur,
            fext: vec![Vec3::ZERO; ns],
            loaded: Vec::new(),
            held: vec![None; n],
            holds: Holds::new(),
            applied: Vec::new(),
            from_cache,
        })
    }

    /// Free surface vertices that are not shared (the force sources).
    pub fn source_count(&self) -> usize {
        self.sources.len()
    }

    /// A proven bound on the largest eigenvalue of M^-1/2 S M^-1/2 for the
    /// shared vertices' masses `mass_kg` (Gershgorin on the scaled rows).
    pub fn condensed_lambda(&self, mass_kg: &[Real]) -> Real {
        let m = self.dofs;
        (0..m)
            .map(|r| {
                let row = &self.schur[r * m..(r + 1) * m];
                row.iter()
                    .enumerate()
                    .map(|(c, s)| s.abs() / (mass_kg[r / 3] * mass_kg[c / 3]).sqrt())
                    .sum::<Real>()
            })
            .fold(0.0, Real::max)
    }

    /// Whether local vertex `v` is a force source (free surface vertex).
    pub fn is_source(&self, v: usize) -> bool {
        self.source_of[v] != NONE
    }

    /// Sets the external force on local vertex `v` (only sources carry one:
    /// the precomputation covers forces on the surface).
    pub fn set_force(&mut self, v: usize, f_n: Vec3) {
        let s = self.source_of[v];
        if s == NONE {
            return;
        }
        self.fext[s as usize] = f_n;
        self.loaded.retain(|&x| x != s);
        if f_n != Vec3::ZERO {
            self.loaded.push(s);
        }
    }

    /// Holds (`Some`) or frees local vertex `v`.
    pub fn hold(&mut self, v: usize, d_m: Option<Vec3>) {
        let was = self.held[v].is_some();
        self.held[v] = d_m;
        if was != d_m.is_some() && self.source_of[v] != NONE {
            self.holds.changed();
        }
    }

    fn c0(&self, s: u32, a: usize) -> &[Vec3] {
        let at = (3 * s as usize + a) * self.n;
        &self.c0[at..at + self.n]
    }

    /// H at source s, all shared degrees of freedom.
    fn lift_at(&self, s: u32) -> &[Vec3] {
        let m = self.dofs;
        &self.lift_at_sources[s as usize * m..(s as usize + 1) * m]
    }

    /// The forces on the part this sub-step (external loads plus the forces
    /// holding tool-held sources where `u_shared` puts the shared vertices),
    /// then the force the part exerts on each shared vertex, into `out`.
    pub fn shared_forces(&mut self, u_shared: &[Vec3], out: &mut [Vec3]) {
        let (n, dofs) = (self.n, self.dofs);
        let (c0, sources) = (&self.c0, &self.sources);
        let c0 = |s: u32, a: usize| {
            let at = (3 * s as usize + a) * n;
            &c0[at..at + n]
        };
        if self.holds.is_dirty() {
            let source_of = &self.source_of;
            let held = (self.held.iter().enumerate())
                .filter(|(v, h)| h.is_some() && source_of[*v] != NONE)
                .map(|(v, _)| source_of[v]);
            self.holds
                .refresh(held, |i, j, b| c0(j, b)[sources[i as usize] as usize]);
        }
        self.applied.clear();
        for &s in &self.loaded {
            self.applied.push((s, self.fext[s as usize]));
        }
        let (loaded, fext, held, lift) =
            (&self.loaded, &self.fext, &self.held, &self.lift_at_sources);
        let applied = &mut self.applied;
        self.holds.solve(
            |s| {
                let v = sources[s as usize] as usize;
                let mut free = Vec3::ZERO;
                for &l in loaded {
                    let f = fext[l as usize];
                    for a in 0..3 {
                        free += f[a] * c0(l, a)[v];
                    }
                }
                let at = &lift[s as usize * dofs..(s as usize + 1) * dofs];
                for (u, h) in u_shared.iter().zip(at.chunks_exact(3)) {
                    free += u.x * h[0] + u.y * h[1] + u.z * h[2];
                }
                held[v].unwrap_or(Vec3::ZERO) - free
            },
            |s, f| applied.push((s, f)),
        );
        let m = 3 * u_shared.len();
        for (j, o) in out.iter_mut().enumerate() {
            for b in 0..3 {
                let row = &self.schur[(3 * j + b) * m..(3 * j + b + 1) * m];
                let mut f = 0.0;
                for (r, u) in row.chunks_exact(3).zip(u_shared) {
                    f -= r[0] * u.x + r[1] * u.y + r[2] * u.z;
                }
                o[b] = f;
            }
        }
        for &(s, fs) in &self.applied {
            for (o, h) in out.iter_mut().zip(self.lift_at(s).chunks_exact(3)) {
                *o += Vec3::new(h[0].dot(fs), h[1].dot(fs), h[2].dot(fs));
            }
        }
    }

    /// The part's displacements for the forces of the last
    /// [`StaticPart::shared_forces`] and `u_shared`, into `out` (held
    /// vertices at their imposed displacement).
    pub fn displacements(&mut self, u_shared: &[Vec3], out: &mut [Vec3]) {
        for (d, u) in self.u_flat.chunks_exact_mut(3).zip(u_shared) {
            d.copy_from_slice(&u.to_array());
        }
        let w = self.stride;
        if w == 0 {
            // No free shared vertex (the parts meet only at fixed ones): the
            // part moves under its own forces alone.
            out.fill(Vec3::ZERO);
        } else {
            for (o, r) in out.iter_mut().zip(self.lift.chunks_exact(3 * w)) {
                *o = Vec3::new(
                    dot(&r[..w], &self.u_flat),
                    dot(&r[w..2 * w], &self.u_flat),
                    dot(&r[2 * w..], &self.u_flat),
                );
            }
        }
        for &(s, f) in &self.applied {
            for a in 0..3 {
                if f[a] != 0.0 {
                    for (o, r) in out.iter_mut().zip(self.c0(s, a)) {
                        *o += f[a] * *r;
                    }
                }
            }
        }
        for (o, h) in out.iter_mut().zip(&self.held) {
            if let Some(d) = h {
                *o = *d;
            }
        }
    }
}

/// A lift row (single precision) dotted with the shared displacements, in
/// eight double-precision lanes the compiler vectorises.
fn dot(row: &[f32], u: &[f64]) -> f64 {
    let mut acc = [0.0f64; 8];
    for (r, x) in row.chunks_exact(8).zip(u.chunks_exact(8)) {
        for k in 0..8 {
            acc[k] += f64::from(r[k]) * x[k];
        }
    }
    acc.iter().sum()
}
