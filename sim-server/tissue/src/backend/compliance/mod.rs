//! A linear static body as a compliance, and the penalty contact solved on
//! it ([`penalty`]).
//!
//! A backend that maps the forces on its surface to displacements by
//! superposition of unit responses (u = a + T G: the precomputed backend,
//! Cotin et al. 1999) implements [`Compliance`]; the penalty law's static
//! contact problem (u = S(f(u)), Newton on the contact vertices with the
//! compliance T_CC among them, as SOFA's constraint solvers and
//! LCPForceFeedback pose it on W: Duriez et al. 2006, Saupin et al. 2008)
//! is written against that trait and the integrator's
//! [`crate::tensor_mass::ForceTerm`], so it knows neither the backend's
//! storage nor the contact field's.
//!
//! Vertices are `u32` indices into the body's vertex arrays (the solve's
//! per-vertex scratch is indexed the same way); forces are in N,
//! displacements in m.

pub(crate) mod penalty;

use super::Backend;
use crate::math::{Real, Vec3};

/// A body whose static displacements are the superposition of unit
/// responses to forces on its loadable vertices, with some vertices held
/// (the holds' forces solved so that they stay put). The contact solve
/// drives it through these operations only.
pub trait Compliance: Backend {
    /// Vertices of the body.
    fn vertex_len(&self) -> usize;
    /// Whether a force on vertex `v` has a response and `v` is not held.
    fn loadable(&self, v: usize) -> bool;
    /// The responses of every vertex to a unit force along axis `a` on the
    /// loadable vertex `v` (m/N).
    fn response_of(&self, v: u32, a: usize) -> &[Vec3];
    /// The responses of every vertex to a unit force along `a` on hold
    /// source `s` (a surface vertex that can be held).
    fn source_response(&self, s: u32, a: usize) -> &[Vec3];
    /// Held vertices (hold sources) now.
    fn hold_count(&self) -> usize;
    /// The holding forces ((hold source, force) into `out`) that keep the
    /// held vertices in place under a unit force along `a` on the loadable
    /// vertex `v`: with them, its response is the one the holds allow
    /// (nothing without holds).
    fn holding_response(&mut self, v: u32, a: usize, out: &mut Vec<(u32, Vec3)>);
    /// The current displacement of `v` (m).
    fn displacement_of(&self, v: u32) -> Vec3;
    /// Overwrites the current displacement of `v` (m): the solve's trial
    /// states at its rows.
    fn set_displacement(&mut self, v: u32, d_m: Vec3);
    /// The contact forces of the last solve, (vertex, force in N).
    fn contact_forces(&self) -> impl Iterator<Item = (u32, Vec3)> + '_;
    /// Removes every contact force.
    fn clear_contact_forces(&mut self);
    /// The contact forces `force` (per vertex, N) on `vertices` (loadable
    /// ones) for the next [`Compliance::step_static`] or
    /// [`Compliance::step_rows`].
    fn set_contact_forces(&mut self, vertices: &[u32], force: &[[Real; 3]]);
    /// Prepares [`Compliance::step_rows`] for this step (the external
    /// loads' part of the solution, the holds brought up to date).
    fn prepare_rows(&mut self);
    /// [`Compliance::step_static`] at `rows` only (the other vertices keep
    /// their displacements).
    fn step_rows(&mut self, rows: &[u32]);
    /// The static solution of every vertex for the loads, the contact
    /// forces and the holds.
    fn step_static(&mut self);
}
