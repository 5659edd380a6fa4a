//! Moving the tools' state to another mesh of the same tissue: what a
//! refinement that follows the tools does when it swaps the refined mesh
//! (`sim_server::follow_refine`). A part of [`super`], which owns the state.

use super::Tools;
use crate::ids::VertexId;

impl Tools {
    /// Why the tools' state cannot move to another mesh now (a grip, a
    /// cut), if it cannot.
    pub fn pins_the_mesh(&self) -> Option<&'static str> {
        self.tools.iter().find_map(|t| t.pins_the_mesh())
    }

    /// Takes over `old`'s state as the same tools over another mesh of the
    /// tissue (`self` made from the same declarations on the new mesh):
    /// each tool's motion, the last inputs, the contact stiffness last
    /// handed over and the step count; the vertices they touched are
    /// renumbered by `new_of_old`. The contact points are selected again
    /// at the next step, and the corotational region round the tips is
    /// rebuilt on the new mesh at the next update (its counts carried on).
    pub fn carry_from(&mut self, old: &Tools, new_of_old: &[Option<VertexId>]) {
        for (new, old) in self.tools.iter_mut().zip(&old.tools) {
            new.carry_from(old, new_of_old);
        }
        self.last_inputs.clone_from(&old.last_inputs);
        self.stiffness_n_per_m.clone_from(&old.stiffness_n_per_m);
        self.steps = old.steps;
        self.deferred_hand_over = old.deferred_hand_over;
        self.local.spec = old.local.spec;
        if let (Some(new), Some(old)) = (&mut self.stiffness, &old.stiffness) {
            new.set_solves(old.solves());
        }
        if let (Some(new), Some(old)) = (&mut self.follow, &old.follow) {
            new.carry_counts(old);
        }
    }
}
