//! What a caller sets and reads on [`Explicit`] between steps: holds,
//! loads, cuts (each telling the prediction which rows it touched), the
//! state, and the displacements, velocities and energy.

use super::Explicit;
use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::tensor_mass::huge_pages::huge_vec;
use crate::tensor_mass::kernel::{Kernel, Storage, V3, kind};
use crate::tensor_mass::large_strain::VertexForce;
use crate::tensor_mass::model::{CutChange, CutError, ElasticModel};
use crate::tensor_mass::stability::StableStep;

impl<S: Storage> Explicit<S> {
    /// Fixes vertex `v` at its rest position.
    pub fn fix(&mut self, v: VertexId) {
        self.prescribe(v, Vec3::ZERO);
    }

    /// Imposes displacement `d_m` on vertex `v` from the next step on.
    pub fn prescribe(&mut self, v: VertexId, d_m: Vec3) {
        self.finish_step();
        self.constraint[v.idx()] = kind::PRESCRIBED;
        self.target[v.idx()] = d_m.to_array();
        self.refresh_vertex(v.idx());
        self.ahead.prediction.touch(v.idx());
    }

    /// Frees vertex `v` (its current displacement and velocity are kept).
    pub fn release(&mut self, v: VertexId) {
        self.finish_step();
        self.constraint[v.idx()] = kind::FREE;
        self.refresh_vertex(v.idx());
        self.ahead.prediction.touch(v.idx());
    }

    /// Sets the external force (N) on vertex `v`. The first call allocates the
    /// force array; a simulation without loads never reads one.
    pub fn set_external_force(&mut self, v: VertexId, f_n: Vec3) {
        self.finish_step();
        if self.fext.is_empty() {
            self.fext = huge_vec(self.u.len(), [0.0; 3]);
        }
        self.fext[v.idx()] = f_n.to_array();
        self.ahead.prediction.touch(v.idx());
    }

    /// Removes all external forces.
    pub fn clear_external_forces(&mut self) {
        self.forget_prepared();
        self.fext = Vec::new();
    }

    /// Sets U(t) and U(t-1) (m), e.g. to start with an initial velocity
    /// (U(t) - U(t-1)) / dt.
    pub fn set_state(&mut self, u_m: &[Vec3], u_prev_m: &[Vec3]) {
        self.forget_prepared();
        for (d, s) in self.u.iter_mut().zip(u_m) {
            *d = s.to_array();
        }
        for (d, s) in self.next.iter_mut().zip(u_prev_m) {
            *d = s.to_array();
        }
    }

    /// Sets U(t) (m) and the velocity (m/s) of every vertex, U(t-1) from
    /// each vertex's own sub-step: a state carried from another mesh of the
    /// tissue, whose sub-steps differ from this one's.
    pub fn set_motion(&mut self, u_m: &[Vec3], v_m_s: &[Vec3]) {
        self.forget_prepared();
        for (v, (u, w)) in u_m.iter().zip(v_m_s).enumerate().take(self.u.len()) {
            let h = self.size.dt_s / self.own_substeps(v) as Real;
            self.u[v] = u.to_array();
            self.next[v] = (*u - *w * h).to_array();
        }
    }

    /// Makes the linear tetrahedra flagged in `corotational` (per
    /// tetrahedron) corotational from the next step on, and every other
    /// linear one linear again: the region round the tools that the contact
    /// moves with them (the scene's `[contact] corotational_radius_m`).
    /// The kernel keeps every element's linear tensors; the nonlinear pass
    /// adds the region's corrections (rebuilt here, with fresh rotations).
    /// A scene whose every element is already nonlinear has nothing to
    /// change. Allocates (the region's rest data): call when the region
    /// changes, not every step.
    pub fn set_corotational_region(&mut self, corotational: &[bool]) {
        self.finish_step();
        if self
            .large
            .as_ref()
            .is_some_and(|l| l.computes_whole_forces())
        {
            return;
        }
        self.large = crate::tensor_mass::large_strain::LargeStrain::with_region(
            &self.model,
            S::LANES,
            corotational,
        );
        let n = self.u.len();
        if self.large.is_some() {
            if self.fnl.len() != n {
                self.fnl = huge_vec(n, [0.0; 3]);
            } else {
                self.fnl.fill([0.0; 3]);
            }
        } else {
            self.fnl = Vec::new();
        }
        // A step computed ahead used the old elements.
        self.forget_prepared();
        // The region's vertices step at the fine step.
        self.multirate_follow_region();
    }

    /// Removes tetrahedron `t` (10 tensor updates in the model, copied to the kernel).
    pub fn remove_tet(&mut self, t: TetId) -> Result<CutChange, CutError> {
        self.finish_step();
        let change = self.model.remove_tet(t)?;
        self.after_cut(t, false, &change);
        Ok(change)
    }

    /// Adds a removed tetrahedron back.
    pub fn restore_tet(&mut self, t: TetId) -> Result<CutChange, CutError> {
        self.finish_step();
        let change = self.model.restore_tet(t)?;
        self.after_cut(t, true, &change);
        Ok(change)
    }

    /// After the model removed (`alive` false) or restored `t`: the
    /// nonlinear pass, the kernel and the rows a prediction recomputes.
    fn after_cut(&mut self, t: TetId, alive: bool, change: &CutChange) {
        if let Some(large) = &mut self.large {
            large.set_alive(t, alive);
        }
        // K U ahead is stale; a prediction is not: only the removed
        // element's four rows read its tensors (its edges join only those
        // vertices) and their masses, so they are recomputed like rows
        // whose hold changed.
        self.ahead.ku_ready = false;
        self.kernel.update(&self.model, change);
        for v in change.vertices {
            self.refresh_vertex(v.idx());
            self.ahead.prediction.touch(v.idx());
        }
    }

    /// Displacement of vertex `v` (m).
    pub fn displacement(&self, v: VertexId) -> Vec3 {
        Vec3::from_array(self.u[v.idx()])
    }

    /// All displacements (m).
    pub fn displacements(&self) -> &[V3] {
        &self.u
    }

    /// Current position of vertex `v` (m).
    pub fn position(&self, v: VertexId) -> Vec3 {
        self.model.mesh().positions_m()[v.idx()] + self.displacement(v)
    }

    /// The model (tensors, topology, surface).
    pub fn model(&self) -> &ElasticModel {
        &self.model
    }

    /// The nonlinear elements' force at vertex `v` from the last pass (the
    /// state at the start of the last sub-step), `None` in a linear model.
    /// A whole force includes a linear capsule's springs there, which the
    /// kernel then holds alone (at the current state).
    pub fn nonlinear_force_n(&self, v: VertexId) -> Option<VertexForce> {
        let large = self.large.as_ref()?;
        let f = Vec3::from_array(self.fnl[v.idx()]);
        Some(if large.computes_whole_forces() {
            let capsule = self.kernel.capsule_force_n(v, &self.u).unwrap_or([0.0; 3]);
            VertexForce::Whole(f + Vec3::from_array(capsule))
        } else {
            VertexForce::Correction(f)
        })
    }

    /// Runs `f` once on each of the step's worker threads (the pool of a
    /// configuration with `threads` above 1; the step hands its passes to
    /// them and waits) and returns how many: none on one thread, where
    /// the caller's thread steps.
    pub fn on_step_workers(&self, f: &(dyn Fn() + Sync)) -> usize {
        match &self.parts.pool {
            Some(pool) => pool.broadcast(|_| f()).len(),
            None => 0,
        }
    }

    /// The hot kernel (without the elements' tensors when every element is
    /// nonlinear: see [`Kernel::beside_whole_forces`]).
    pub fn kernel(&self) -> &Kernel<S> {
        &self.kernel
    }

    /// The enforced stability bound.
    pub fn stable_step(&self) -> StableStep {
        self.size.stable
    }

    /// Sub-steps per step (1 when dt is under the bound).
    pub fn substeps(&self) -> usize {
        self.size.substeps
    }

    /// The step (s).
    pub fn dt_s(&self) -> Real {
        self.size.dt_s
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Velocity of `v` (m/s): the last sub-step's backward difference.
    pub fn velocity(&self, v: VertexId) -> Vec3 {
        let h = self.size.dt_s / self.own_substeps(v.idx()) as Real;
        (Vec3::from_array(self.u[v.idx()]) - Vec3::from_array(self.next[v.idx()])) / h
    }

    /// Kinetic plus elastic energy (J), velocities by the centred difference
    /// of the last two states (for tests and diagnostics; allocates).
    pub fn energy_j(&self) -> Real {
        let u: Vec<Vec3> = self.u.iter().map(|a| Vec3::from_array(*a)).collect();
        let kinetic: Real = self
            .u
            .iter()
            .zip(&self.next)
            .zip(self.model.masses_kg())
            .enumerate()
            .map(|(i, ((a, b), m))| {
                let h = self.size.dt_s / self.own_substeps(i) as Real;
                let v = (Vec3::from_array(*a) - Vec3::from_array(*b)) / h;
                0.5 * m * v.length_squared()
            })
            .sum();
        kinetic + self.model.energy_j(&u)
    }

    /// Bytes the step streams per sub-step: the kernel's tensors and indices
    /// plus the state arrays (U read, U(t-1) read and U(t+1) written in its
    /// place, coefficients and kinds read), and the nonlinear pass's rest
    /// data, forces and rotations. The K U accumulators live in a
    /// cache-sized ring and are not counted.
    pub fn bytes_per_substep(&self) -> usize {
        let n = self.u.len();
        // The nonlinear pass's rest data and buffers, and the vertex
        // forces it hands the step.
        let large = self.large.as_ref().map_or(0, |l| l.bytes() + n * 24);
        self.kernel.bytes() + n * (24 + 48 + 24 + 1) + large
    }

    /// The number of parts a step is split into.
    pub fn parts(&self) -> usize {
        self.parts.plans.len()
    }
}
