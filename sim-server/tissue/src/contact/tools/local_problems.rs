//! The contact problems [`Tools`] makes for the daemon's `local-problem`
//! renderer: which one is asked for ([`LocalSpec`]), its points sampled
//! around the tool as it stands after the step, and the hand-over of
//! finished problems (the compliance is added by the stiffness solver).

use super::Tools;
use crate::backend::Backend;
use crate::contact::local::LocalContact;
use crate::contact::penalty::field::{ContactField, PartSweep};
use crate::contact::penalty::sampling::Sampler;
use crate::contact::response::worker::ContactStiffness;
use crate::contact::surface::adjacency::Adjacency;
use crate::contact::surface::index::SurfaceIndex;
use crate::contact::tool::ToolContact;
use crate::ids::VertexId;
use crate::math::Real;

/// Which contact problem [`Tools::set_local_contact`] makes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalSpec {
    /// The tool.
    pub tool: usize,
    /// How far beyond the step's reach of its parts points are taken (m).
    pub margin_m: Real,
    /// At most this many vertices (the points nearest the tool first).
    pub max_vertices: usize,
    /// At most this many points.
    pub max_points: usize,
    /// With the tissue's inertia at the vertices (see
    /// [`LocalContact::column_mass`]): the velocities and damping taken
    /// with the points, the column mass solved with the compliance.
    pub inertia: bool,
    /// At least this much simulated time between two problems (s; 0: one
    /// at every snapshot of the stiffness solver).
    pub every_s: Real,
}

/// The contact problems' request and scratch, kept across calls.
#[derive(Default)]
pub(super) struct LocalScratch {
    pub(super) spec: Option<LocalSpec>,
    /// Simulated time since the last problem was made (s).
    pub(super) since_s: Real,
    pub(super) field: ContactField,
    pub(super) slot: Vec<u32>,
    pub(super) order: Vec<(Real, usize)>,
}

/// What sampling a contact problem's points borrows from [`Tools`].
pub(super) struct LocalSampling<'a> {
    pub(super) sampler: &'a mut Sampler,
    pub(super) index: &'a mut SurfaceIndex,
    pub(super) adjacency: &'a Adjacency,
    pub(super) scratch: &'a mut LocalScratch,
    pub(super) tools: &'a [ToolContact],
    pub(super) step: u64,
}

impl LocalSampling<'_> {
    /// The points, vertices and parts of `spec`'s problem into `out` (no
    /// compliance); false if there is none.
    pub(super) fn sample<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        spec: LocalSpec,
        out: &mut LocalContact,
    ) -> bool {
        out.clear();
        let Some(t) = self.tools.get(spec.tool) else {
            return false;
        };
        // The problem is frictionless and knows no grip: with friction it
        // would let the tissue slide where the simulation holds it, and a
        // gripping tool's force is the grip's.
        let Some(pose) = t
            .pose()
            .filter(|_| !t.decl().friction.is_active() && !t.gripping())
        else {
            return false;
        };
        let local = &mut *self.scratch;
        local.field.clear();
        for sweep in t.sweeps().into_iter().flatten() {
            // Standing at the step's end: the reach is the tool's alone.
            local.field.add_part(PartSweep {
                from: sweep.to,
                ..sweep
            });
        }
        self.index.refit(sim);
        for part in 0..local.field.parts().len() {
            self.sampler.sample_around(
                sim,
                self.index,
                self.adjacency,
                part as u16,
                &mut local.field,
                spec.margin_m,
            );
        }
        local.slot.resize(sim.model().vertex_count(), u32::MAX);
        out.take_points(
            &local.field,
            |v| sim.position(VertexId(v)),
            spec.max_vertices.min(u16::MAX as usize),
            spec.max_points,
            &mut local.slot,
            &mut local.order,
        );
        out.tool_position_m = pose.end_m;
        out.step = self.step;
        if spec.inertia {
            out.take_motion(sim);
        }
        !out.points.is_empty()
    }
}

impl Tools {
    /// Makes a contact problem ([`LocalContact`]) alongside the contact
    /// stiffness, every time the stiffness solver takes a snapshot (each
    /// step offline, every few milliseconds live: the worker thread adds
    /// the compliance); [`Tools::take_local_contact`] gives the newest.
    /// `None` stops it.
    pub fn set_local_contact(&mut self, spec: Option<LocalSpec>) {
        self.local.spec = spec;
    }

    /// The newest finished contact problem (see
    /// [`Tools::set_local_contact`]), once; give it back with
    /// [`Tools::recycle_local_contact`] to reuse its buffers.
    pub fn take_local_contact(&mut self) -> Option<Box<LocalContact>> {
        self.stiffness
            .as_mut()
            .and_then(ContactStiffness::take_local)
    }

    /// Steps taken (what [`LocalContact::step`] counts).
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Gives a contact problem's buffers back.
    pub fn recycle_local_contact(&mut self, lc: Box<LocalContact>) {
        if let Some(k) = &mut self.stiffness {
            k.recycle_local(lc);
        }
    }

    /// The contact problem around tool `spec.tool` after the last step into
    /// `out`, now (see [`LocalContact`]). False (and `out` empty) when
    /// there is none: the projection law, a tool without a pose or with
    /// friction (the problem is frictionless), no surface near it, or no
    /// exact compliance here (the stiffness solved on its worker thread: use
    /// [`Tools::set_local_contact`] then, or a mesh above
    /// `contact::stiffness::MAX_FACTOR_VERTICES`).
    pub fn local_contact<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        spec: LocalSpec,
        out: &mut LocalContact,
    ) -> bool {
        let (Some(sampler), Some(stiffness)) = (&mut self.sampler, &mut self.stiffness) else {
            out.clear();
            return false;
        };
        let mut ctx = LocalSampling {
            sampler,
            index: &mut self.index,
            adjacency: &self.adjacency,
            scratch: &mut self.local,
            tools: &self.tools,
            step: self.steps,
        };
        if !ctx.sample(sim, spec, out) || !stiffness.solve_local(sim.model(), out) {
            out.clear();
            return false;
        }
        true
    }
}
