//! A force the integrators add beside the elastic one, owned here so that
//! the integrators (`tensor_mass`, `backend`) depend on what they call and
//! not on who provides it: the tools' penalty contact
//! ([`crate::contact::ContactField`]) implements [`ForceTerm`], and the
//! dependency points from `contact` to the integrators only (checked by
//! `tests/tests/module_graph.rs`).
//!
//! Two integrators use it. The explicit step evaluates the term at every
//! sub-step ([`ForceTerm::zero`], [`ForceTerm::add_forces`], then the
//! optional linearly implicit correction [`ForceTerm::correct_implicit`]);
//! the precomputed backend solves each step's static equilibrium with it
//! by Newton's method on the term's forces, energy and Hessians, applied
//! at its points ([`ForcePoint`]). Generic, not `dyn`: it runs at every
//! sub-step.

use crate::math::{Mat3, Real, Vec3};

/// Where in a step an evaluation is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubStep<'a> {
    /// The sub-step (s): `u` and `u_prev` are this far apart.
    pub h_s: Real,
    /// The whole step (s): the tools sweep across it.
    pub step_s: Real,
    /// The fraction of the step the tools have swept (0 to 1).
    pub s: Real,
    /// The vertex masses (kg): bound the damping (empty: no damping).
    pub masses_kg: &'a [Real],
}

/// A point through which a force term acts: a point of a surface
/// triangle, moving with its three vertices by barycentric weights.
pub trait ForcePoint {
    /// The triangle's vertices (indices into the mesh).
    fn vertices(&self) -> [u32; 3];
    /// The point's barycentric weights on them (summing to 1).
    fn weights(&self) -> [Real; 3];
}

/// A force on the mesh beside the elastic one, acting through points.
pub trait ForceTerm {
    /// What the term's points are.
    type Point: ForcePoint;

    /// True when the term has no point and left no force to clear: a step
    /// can run without it.
    fn is_idle(&self) -> bool;
    /// Clears the rows of `out` the term wrote at its last evaluation
    /// (before the next one adds to them).
    fn zero(&mut self, out: &mut [[Real; 3]]);
    /// Adds the term's forces (N) at displacements `u` (and `u_prev` one
    /// sub-step earlier, for its velocities) to `out`.
    fn add_forces(
        &mut self,
        rest_m: &[Vec3],
        u: &[[Real; 3]],
        u_prev: &[[Real; 3]],
        at: SubStep,
        out: &mut [[Real; 3]],
    );
    /// Whether [`ForceTerm::correct_implicit`] has work to do.
    fn implicit_springs(&self) -> bool;
    /// Corrects the explicit prediction `u_new` (from `u_old`) for the
    /// term's stiff part taken implicitly, with `inverse_d(i)` the free
    /// vertex `i`'s integration coefficient h^2 / m' (`None`: its motion
    /// is imposed); returns the solver's iterations.
    fn correct_implicit(
        &mut self,
        inverse_d: impl Fn(usize) -> Option<Real>,
        u_old: &[[Real; 3]],
        u_new: &mut [[Real; 3]],
    ) -> usize;

    /// The term's points.
    fn points(&self) -> &[Self::Point];
    /// Each point's depth (m) at the last evaluation: it acts where
    /// positive.
    fn penetrations_m(&self) -> &[Real];
    /// Each point's whole Hessian of the energy (N/m) at the last
    /// evaluation.
    fn hessians(&self) -> &[Mat3];
    /// Each point's normal slope alone (k n n^T, N/m), a cheaper and
    /// positive semi-definite part of [`ForceTerm::hessians`].
    fn spring_hessians(&self) -> &[Mat3];
    /// The static forces (no velocity) at displacements `u` into `out`
    /// (cleared first).
    fn static_forces(&mut self, rest_m: &[Vec3], u: &[[Real; 3]], out: &mut [[Real; 3]]);
    /// The energy (J) of the last evaluation.
    fn spring_energy_j(&self) -> Real;
    /// Forgets what the evaluations of this step reported: a solver that
    /// evaluates the term several times in a step reports its last only.
    fn restart_report(&mut self);
}

/// The absent force term: no point, never acts (a step without one).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoForce;

/// The point of [`NoForce`], which has none.
#[derive(Clone, Copy, Debug)]
pub enum NoPoint {}

impl ForcePoint for NoPoint {
    fn vertices(&self) -> [u32; 3] {
        match *self {}
    }
    fn weights(&self) -> [Real; 3] {
        match *self {}
    }
}

impl ForceTerm for NoForce {
    type Point = NoPoint;

    fn is_idle(&self) -> bool {
        true
    }
    fn zero(&mut self, _: &mut [[Real; 3]]) {}
    fn add_forces(
        &mut self,
        _: &[Vec3],
        _: &[[Real; 3]],
        _: &[[Real; 3]],
        _: SubStep,
        _: &mut [[Real; 3]],
    ) {
    }
    fn implicit_springs(&self) -> bool {
        false
    }
    fn correct_implicit(
        &mut self,
        _: impl Fn(usize) -> Option<Real>,
        _: &[[Real; 3]],
        _: &mut [[Real; 3]],
    ) -> usize {
        0
    }
    fn points(&self) -> &[NoPoint] {
        &[]
    }
    fn penetrations_m(&self) -> &[Real] {
        &[]
    }
    fn hessians(&self) -> &[Mat3] {
        &[]
    }
    fn spring_hessians(&self) -> &[Mat3] {
        &[]
    }
    fn static_forces(&mut self, _: &[Vec3], _: &[[Real; 3]], out: &mut [[Real; 3]]) {
        out.fill([0.0; 3]);
    }
    fn spring_energy_j(&self) -> Real {
        0.0
    }
    fn restart_report(&mut self) {}
}
