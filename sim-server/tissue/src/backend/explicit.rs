//! The tensor-mass explicit integrator as a [`Backend`].

use super::{Backend, Capabilities};
use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::tensor_mass::{CutChange, CutError, ElasticModel, Explicit, ForceTerm, Storage};

impl<S: Storage> Backend for Explicit<S> {
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            integrates_contact: true,
            corotational_region: true,
            ..Capabilities::dynamic("tensor-mass")
        }
    }
    fn model(&self) -> &ElasticModel {
        Explicit::model(self)
    }
    fn step(&mut self) {
        Explicit::step(self);
    }
    fn prepare_step(&mut self) {
        Explicit::prepare_step(self);
    }
    fn defer_far_rows(&mut self, on: bool) {
        Explicit::defer_far_rows(self, on);
    }
    fn finish_step(&mut self) {
        Explicit::finish_step(self);
    }
    fn predicted(&self) -> Option<(u64, u64)> {
        Some((self.predicted_steps(), self.predicted_rows()))
    }
    fn multirate(&self) -> Option<crate::tensor_mass::MultirateReport> {
        Explicit::multirate(self)
    }
    fn dt_s(&self) -> Real {
        Explicit::dt_s(self)
    }
    fn displacement(&self, v: VertexId) -> Vec3 {
        Explicit::displacement(self, v)
    }
    fn displacements(&self) -> &[[Real; 3]] {
        Explicit::displacements(self)
    }
    fn velocity(&self, v: VertexId) -> Vec3 {
        Explicit::velocity(self, v)
    }
    fn position(&self, v: VertexId) -> Vec3 {
        Explicit::position(self, v)
    }
    fn prescribe(&mut self, v: VertexId, d_m: Vec3) {
        Explicit::prescribe(self, v, d_m);
    }
    fn release(&mut self, v: VertexId) {
        Explicit::release(self, v);
    }
    fn set_external_force(&mut self, v: VertexId, f_n: Vec3) {
        Explicit::set_external_force(self, v, f_n);
    }
    fn remove_tet(&mut self, t: TetId) -> Result<CutChange, CutError> {
        Explicit::remove_tet(self, t)
    }
    fn set_corotational_region(&mut self, corotational: &[bool]) {
        Explicit::set_corotational_region(self, corotational);
    }
    fn large_strain(&self) -> Option<crate::tensor_mass::large_strain::PassReport> {
        Explicit::large_strain(self).map(|l| l.last())
    }
    fn nonlinear_force_n(
        &self,
        v: VertexId,
    ) -> Option<crate::tensor_mass::large_strain::VertexForce> {
        Explicit::nonlinear_force_n(self, v)
    }
    fn on_step_workers(&self, f: &(dyn Fn() + Sync)) -> usize {
        Explicit::on_step_workers(self, f)
    }
    fn set_contact_bound(&mut self, omega2: Real) {
        Explicit::set_contact_bound(self, omega2);
    }
    fn step_with_contact<F: ForceTerm, R: FnMut(&Self, &mut F)>(
        &mut self,
        field: &mut F,
        resample_every_s: Real,
        resample: &mut R,
    ) {
        Explicit::step_with_contact(self, field, resample_every_s, resample);
    }
}
