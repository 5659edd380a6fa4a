//! The tools of a scene, updated together each step so that they share one
//! surface index and never fight over a vertex.

use super::adjacency::Adjacency;
use super::claims::Claims;
use super::surface_index::SurfaceIndex;
use super::tool::ToolContact;
use super::{ContactReport, Reaction};
use crate::backend::Backend;
use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::scene::ToolDecl;
use crate::tensor_mass::ElasticModel;

/// Where a tool is this step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolInput {
    /// The requested tip position (m).
    pub tip_m: Vec3,
    /// Jaw opening, 0 closed to 1 open (ignored by tools without jaws).
    pub jaw_opening: Real,
}

/// Every tool of a scene with its contact state.
///
/// Each step, [`Tools::update`] runs, for all tools in turn: placing and
/// cutting; holding gripped tissue; sliding contact of the tips, then of
/// the shafts; and last, releasing what no tool holds any more and imposing
/// the rest. A vertex belongs to at most one tool per step: grips come
/// first (a held vertex is never taken by another tool's plane), then tools
/// in declaration order.
pub struct Tools {
    tools: Vec<ToolContact>,
    index: SurfaceIndex,
    adjacency: Adjacency,
    claims: Claims,
    reports: Vec<ContactReport>,
}

impl Tools {
    /// The tools `decls` over `model`, touching nothing.
    pub fn new(decls: &[ToolDecl], model: &ElasticModel) -> Self {
        let tools: Vec<ToolContact> = decls
            .iter()
            .enumerate()
            .map(|(i, d)| ToolContact::new(d, i, model))
            .collect();
        // A leaf is updated once its vertex has moved half the smallest
        // tool radius: few leaves per step, few false candidates per query.
        let margin_m = decls
            .iter()
            .map(|d| d.radius_m)
            .fold(Real::INFINITY, Real::min)
            .min(0.01)
            * 0.5;
        Self {
            reports: vec![ContactReport::default(); tools.len()],
            tools,
            index: SurfaceIndex::new(model, margin_m),
            adjacency: Adjacency::new(model),
            claims: Claims::new(model.vertex_count()),
        }
    }

    /// No tool ever imposes nor releases `v` (a vertex the scene fixes or
    /// prescribes).
    pub fn reserve(&mut self, v: VertexId) {
        self.claims.reserve(v);
    }

    /// Number of tools.
    pub fn len(&self) -> usize {
        self.tools.len()
    }

    /// Whether the scene has no tool.
    pub fn is_empty(&self) -> bool {
        self.tools.is_empty()
    }

    /// Tool `i`.
    pub fn tool(&self, i: usize) -> &ToolContact {
        &self.tools[i]
    }

    /// The tools in declaration order.
    pub fn iter(&self) -> impl Iterator<Item = &ToolContact> {
        self.tools.iter()
    }

    /// The tool holding `v` after the last update, if any.
    pub fn owner(&self, v: VertexId) -> Option<usize> {
        self.claims.owner(v)
    }

    /// The surface index the tools query.
    pub fn surface_index(&self) -> &SurfaceIndex {
        &self.index
    }

    /// Detects contact, cuts, and imposes the contact vertices for the
    /// coming step; `inputs[i]` places tool `i` (`None` or missing: the tool
    /// is withdrawn and lets go). Call once before each `sim.step()`.
    /// Returns one report per tool.
    pub fn update<B: Backend + ?Sized>(
        &mut self,
        sim: &mut B,
        inputs: &[Option<ToolInput>],
    ) -> &[ContactReport] {
        if self.tools.is_empty() {
            return &self.reports;
        }
        let input = |i: usize| inputs.get(i).copied().flatten();
        self.claims.clear();
        for (i, t) in self.tools.iter_mut().enumerate() {
            t.begin(
                sim,
                &self.adjacency,
                input(i).map(|p| (p.tip_m, p.jaw_opening)),
            );
        }
        // After the cuts: the index follows them and the new positions.
        self.index.refit(sim);
        for t in &mut self.tools {
            t.hold(sim, &mut self.claims);
        }
        for t in &mut self.tools {
            t.detect(sim, &self.index, &self.adjacency, &mut self.claims);
        }
        for (i, t) in self.tools.iter_mut().enumerate() {
            let jaw = input(i).map_or(1.0, |p| p.jaw_opening);
            self.reports[i] = t.commit(sim, &self.claims, jaw);
        }
        &self.reports
    }

    /// The force on tool `i` and its contact stiffness after the step.
    pub fn reaction<B: Backend + ?Sized>(&self, i: usize, sim: &B) -> Reaction {
        self.tools[i].reaction(sim, &self.adjacency)
    }
}
