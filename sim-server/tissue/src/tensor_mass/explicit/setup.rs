//! Setting up the explicit integrator: the step checked against the
//! stability bound, the worker threads and their parts of the kernel, the
//! nonlinear elements' lanes (whole forces or corrections), the nonlinear
//! membrane's vertices, and every buffer a step reuses. A part of
//! [`super`], which owns the integrator.

use super::partition::{PartBuffers, plan_parts};
use super::predicted::Prediction;
use super::{
    Ahead, Explicit, ExplicitConfig, ExplicitError, MAX_THREADS, Parts, StepSize, substeps_for,
};
use crate::tensor_mass::huge_pages::huge_vec;
use crate::tensor_mass::kernel::{Kernel, Storage, kind};
use crate::tensor_mass::large_strain::LargeStrain;
use crate::tensor_mass::model::ElasticModel;
use crate::tensor_mass::stability::{BoundMethod, element_bound, power_iteration};

impl<S: Storage> Explicit<S> {
    /// Sets up the integrator at rest (U = 0).
    pub fn new(model: ElasticModel, config: ExplicitConfig) -> Result<Self, ExplicitError> {
        Self::build(model, config, true)
    }

    /// The same, keeping every element's linear tensors in the kernel and
    /// the nonlinear pass's differences from them even where every element
    /// is nonlinear (the two forms are tested equal).
    #[cfg(test)]
    pub(crate) fn with_linear_tensors(
        model: ElasticModel,
        config: ExplicitConfig,
    ) -> Result<Self, ExplicitError> {
        Self::build(model, config, false)
    }

    fn build(
        model: ElasticModel,
        config: ExplicitConfig,
        whole_forces: bool,
    ) -> Result<Self, ExplicitError> {
        let dt_s = config.dt_s;
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(ExplicitError::BadDt(dt_s));
        }
        let stable = match config.bound {
            BoundMethod::Element => element_bound(&model),
            BoundMethod::PowerIteration => power_iteration(&model, 1e-6, 2000).step,
        };
        let substeps = substeps_for(dt_s, &stable, config.policy)?;
        let threads = config.threads.max(1);
        if threads > MAX_THREADS {
            return Err(ExplicitError::Threads {
                threads,
                reason: format!("at most {MAX_THREADS} worker threads"),
            });
        }
        let pool = if threads > 1 {
            Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .thread_name(|i| format!("tensor-mass-{i}"))
                    .build()
                    .map_err(|e| ExplicitError::Threads {
                        threads,
                        reason: e.to_string(),
                    })?,
            )
        } else {
            None
        };
        // The nonlinear lanes in the kernel's precision: with f32 tensors,
        // eight f32 elements to a register. When every element is
        // nonlinear the pass computes the whole elastic force and the
        // kernel carries only a linear capsule membrane's springs, or no
        // tensors (it only integrates); otherwise the kernel keeps the
        // linear tensors and the pass adds the nonlinear elements'
        // differences.
        let large = LargeStrain::with_precision(&model, S::LANES);
        let (kernel, large) = match large {
            Some(l) if l.covers_every_tetrahedron() && whole_forces => (
                Kernel::beside_whole_forces(&model),
                Some(l.computing_whole_forces()),
            ),
            other => (Kernel::new(&model), other),
        };
        let n = model.vertex_count();
        let plans = plan_parts(&kernel, threads);
        // Each part has a ring of the mesh's bandwidth: on a large mesh
        // numbered at random that is about the vertex count, and many parts
        // of it would allocate without bound. Refused past four vertex
        // arrays' worth of rows and 64 MiB (2^21 rows of 32 bytes): small
        // meshes, whose bandwidth is their size, still split freely.
        let ring_rows = plans.len() * kernel.ring_len();
        if plans.len() > 1 && ring_rows > (4 * n).max(1 << 21) {
            return Err(ExplicitError::Threads {
                threads,
                reason: format!(
                    "each part needs a ring of {} rows (the mesh's bandwidth) for {n} vertices: renumber the mesh (RCM, a scene's default) or use fewer threads",
                    kernel.ring_len()
                ),
            });
        }
        let (fmem, capsule_vertices) = match model.membrane() {
            Some(m) if m.model() == crate::membrane::MembraneModel::Nonlinear => {
                let edges = model.topology().edges();
                let mut vs: Vec<u32> = m
                    .capsule_edges()
                    .iter()
                    .flat_map(|e| edges[e.idx()].map(|v| v.0))
                    .collect();
                vs.sort_unstable();
                vs.dedup();
                (vec![[0.0; 3]; n], vs)
            }
            _ => (Vec::new(), Vec::new()),
        };
        let fnl = if large.is_some() {
            huge_vec(n, [0.0; 3])
        } else {
            Vec::new()
        };
        let buffers = plans
            .iter()
            .map(|p| PartBuffers {
                ring: vec![[0.0; 4]; kernel.ring_len()],
                deferred: vec![[0.0; 3]; p.deferred_end - p.start],
                spill: vec![[0.0; 3]; p.spill_len],
            })
            .collect();
        let mut sim = Self {
            kernel,
            u: huge_vec(n, [0.0; 3]),
            next: huge_vec(n, [0.0; 3]),
            coef: huge_vec(n, [0.0; 3]),
            constraint: vec![kind::FREE; n],
            kind: huge_vec(n, kind::FREE),
            target: huge_vec(n, [0.0; 3]),
            fext: Vec::new(),
            fmem,
            capsule_vertices,
            large,
            fnl,
            parts: Parts {
                threads,
                plans,
                buffers,
                pool,
            },
            size: StepSize {
                contact_omega2: 0.0,
                tangent_lambda: 0.0,
                stable,
                elastic_stable: stable,
                policy: config.policy,
                dt_s,
                substeps,
                coarse_substeps: substeps,
                elastic_substeps: substeps,
                substep_factor: 1,
                resubsteps: 0,
            },
            steps: 0,
            ahead: Ahead {
                ku_ahead: Vec::new(),
                ku_ready: false,
                prediction: Prediction::default(),
                predicted_steps: 0,
                resample_every_s: None,
            },
            multirate: None,
            model,
        };
        for v in 0..n {
            sim.refresh_vertex(v);
        }
        Ok(sim)
    }
}
