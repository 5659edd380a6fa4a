//! One tool's contact state, updated in the phases [`super::Tools`] runs
//! for all tools in turn each step: cut, hold the gripped vertices, detect
//! and project the sliding contacts, then commit to the simulation.

use super::ToolDecl;
use super::ToolKind;
use super::config::ContactLaw;
use super::{CUT_BELOW, Constraint, ConstraintKind, ContactReport, GRIP_BELOW};
use crate::backend::Backend;
use crate::contact::instrument::{Plane, Segment, ToolPose};
use crate::contact::penalty::field::{ContactField, PartSweep};
use crate::contact::response::reaction::{self, Reaction};
use crate::contact::surface::adjacency::Adjacency;
use crate::contact::surface::index::SurfaceIndex;
use crate::contact::tool::claims::Claims;
use crate::contact::tool::proxy::Proxy;
use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::mesh::TET_FACES;
use crate::tensor_mass::{CutError, ElasticModel};

/// How far (fraction of the radius) below the new plane a persisting
/// contact vertex may be and still be re-projected.
const KEEP_BELOW: Real = 0.05;
/// |N_proj| below which the shaft plane is undefined (sin of ~6 degrees).
const MIN_SHAFT_SIN: Real = 0.1;

#[derive(Clone, Copy, PartialEq)]
enum Part {
    Tip,
    Shaft,
}

/// The buffers one tool's detection pass reuses (allocated once, cleared
/// each step).
struct Scratch {
    /// Per vertex: among this pass's hits or kept vertices.
    mark: Vec<bool>,
    candidates: Vec<VertexId>,
    hits: Vec<VertexId>,
    kept: Vec<VertexId>,
    /// Tetrahedra a cut removes.
    doomed: Vec<TetId>,
}

/// One tool's contact with the tissue, its state kept between steps.
pub struct ToolContact {
    decl: ToolDecl,
    slot: usize,
    law: ContactLaw,
    proxy: Proxy,
    direction: Vec3,
    pose: Option<ToolPose>,
    /// The pose of the update before (the start of the penalty sweep).
    prev_pose: Option<ToolPose>,
    /// Vertices the tip touched in the last step (what the jaws grip).
    touched: Vec<VertexId>,
    jaw: Real,
    constraints: Vec<Constraint>,
    previous: Vec<Constraint>,
    scratch: Scratch,
    gripped: Vec<(VertexId, Vec3)>,
    grip_end_m: Vec3,
    gripping: bool,
    armed: bool,
    removed: usize,
    /// The surface stopped the tip short of the pose asked this step.
    held_outside: bool,
    /// The proxy was slowed near the tissue this step (it is catching up).
    slowed: bool,
    cut_refused: Option<&'static str>,
    /// Simulated time since the cavitron last burnt (s).
    since_burn_s: Real,
    /// Simulated time since the proxy last followed the hand (s; infinite
    /// after a let-go, until it has caught up).
    catching_up_s: Real,
}

/// The cavitron burns at most this often (simulated s): every step of a
/// scene stepping at 1 ms or slower, every few steps of a faster one. Its
/// scan looks at every vertex, and at a 0.25 ms step it was a third of the
/// contact update; tissue does not vaporise faster than a millisecond shows.
pub const BURN_EVERY_S: Real = 1e-3;

impl ToolContact {
    /// Tool number `slot` over `model`, touching nothing.
    pub(super) fn new(
        decl: &ToolDecl,
        slot: usize,
        model: &ElasticModel,
        law: ContactLaw,
        proxy: Proxy,
    ) -> Self {
        let n = model.vertex_count();
        Self {
            decl: decl.clone(),
            slot,
            law,
            proxy,
            prev_pose: None,
            touched: Vec::new(),
            jaw: 1.0,
            // Used only while the tip sits on the fulcrum: point down.
            direction: Vec3::NEG_Z,
            pose: None,
            constraints: Vec::new(),
            previous: Vec::new(),
            scratch: Scratch {
                mark: vec![false; n],
                candidates: Vec::new(),
                hits: Vec::new(),
                kept: Vec::new(),
                doomed: Vec::new(),
            },
            gripped: Vec::new(),
            grip_end_m: Vec3::ZERO,
            gripping: false,
            armed: false,
            removed: 0,
            held_outside: false,
            slowed: false,
            cut_refused: None,
            since_burn_s: Real::INFINITY,
            catching_up_s: Real::INFINITY,
        }
    }

    /// The tool as declared.
    pub fn decl(&self) -> &ToolDecl {
        &self.decl
    }

    /// The pose of the last update (None before the first, or withdrawn).
    pub fn pose(&self) -> Option<&ToolPose> {
        self.pose.as_ref()
    }

    /// The vertices imposed by the last update.
    pub fn constraints(&self) -> &[Constraint] {
        &self.constraints
    }

    /// Whether the jaws hold tissue.
    pub fn gripping(&self) -> bool {
        self.gripping
    }

    /// Phase 1: places the tool (`None`: withdrawn, it lets go of
    /// everything) and cuts.
    pub(super) fn begin<B: Backend + ?Sized>(
        &mut self,
        sim: &mut B,
        adj: &Adjacency,
        input: Option<(Vec3, Real)>,
    ) {
        std::mem::swap(&mut self.constraints, &mut self.previous);
        self.constraints.clear();
        self.removed = 0;
        self.held_outside = false;
        self.slowed = false;
        self.cut_refused = None;
        self.prev_pose = self.pose;
        let Some((tip_m, jaw)) = input else {
            self.since_burn_s = Real::INFINITY;
            self.catching_up_s = Real::INFINITY;
            self.pose = None;
            self.proxy.reset();
            self.gripped.clear();
            self.touched.clear();
            self.gripping = false;
            self.armed = false;
            return;
        };
        self.jaw = jaw;
        let tip_m = match self.law {
            // The proxy: under the penalty law the simulated tool follows
            // the requested pose at a bounded speed, so a pose that jumps
            // (a device glitch) drags it, at most this far per step,
            // instead of teleporting it through or into the tissue. A tool
            // that appears starts at its fulcrum (the trocar, outside the
            // organ) and comes in from there.
            ContactLaw::Penalty => {
                let fulcrum = Vec3::from_array(self.decl.fulcrum_m);
                self.proxy.follow(tip_m, fulcrum, sim.dt_s())
            }
            ContactLaw::Projection => tip_m,
        };
        let pose = ToolPose::new(&self.decl, tip_m, self.direction);
        self.direction = pose.direction;
        self.pose = Some(pose);
        self.removed = match self.decl.kind {
            ToolKind::Grasper => self.grasp(sim, adj, &pose, jaw),
            ToolKind::Cavitron => {
                // Half a step of slack: a 0.25 ms step burns every 4th step.
                self.since_burn_s += sim.dt_s();
                if self.since_burn_s >= BURN_EVERY_S - 0.5 * sim.dt_s() {
                    self.since_burn_s = 0.0;
                    self.burn(sim, adj, &pose)
                } else {
                    0
                }
            }
            ToolKind::Hook => 0,
        };
    }

    /// Phase 2: the gripped vertices follow the tool end's translation.
    pub(super) fn hold<B: Backend + ?Sized>(&mut self, sim: &B, claims: &mut Claims) {
        let Some(pose) = self.pose else { return };
        let offset = pose.end_m - self.grip_end_m;
        for i in 0..self.gripped.len() {
            let (v, p) = self.gripped[i];
            if sim.model().topology().vertex_tet_count(v) > 0 {
                self.push(claims, v, ConstraintKind::Grip, p + offset);
            }
        }
    }

    /// Phase 3: sliding contact of the tip, then of the shaft.
    pub(super) fn detect<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &SurfaceIndex,
        adj: &Adjacency,
        claims: &mut Claims,
    ) {
        let Some(pose) = self.pose else { return };
        if self.law == ContactLaw::Penalty {
            return;
        }
        if self.decl.kind != ToolKind::Cavitron {
            self.plane_pass(sim, index, adj, claims, &pose.tip, Part::Tip);
        }
        if let Some(shaft) = pose.shaft {
            self.plane_pass(sim, index, adj, claims, &shaft, Part::Shaft);
        }
    }

    /// Phase 4 (after every tool's phases 1-3): lets go of what no tool
    /// holds any more and imposes this tool's constraints.
    pub(super) fn commit<B: Backend + ?Sized>(
        &mut self,
        sim: &mut B,
        claims: &Claims,
        jaw: Real,
    ) -> ContactReport {
        for c in &self.previous {
            if claims.is_free(c.vertex) {
                sim.release(c.vertex);
            }
        }
        if self.law == ContactLaw::Projection {
            self.touched.clear();
        }
        for c in &self.constraints {
            let rest_m = sim.model().mesh().positions_m()[c.vertex.idx()];
            sim.prescribe(c.vertex, c.target_m - rest_m);
            if matches!(c.kind, ConstraintKind::Tip(_)) {
                self.touched.push(c.vertex);
            }
        }
        self.armed = !self.touched.is_empty() && jaw > GRIP_BELOW;
        ContactReport {
            contact: !self.constraints.is_empty(),
            gripping: self.gripping,
            tets_removed: self.removed,
            cut_refused: self.cut_refused,
            constrained_vertices: self.constraints.len(),
            held_outside: self.held_outside,
            catching_up: self.slowed || self.held_outside || self.proxy.catching_up(),
        }
    }

    /// The force on the tool and the contact stiffness after the step, from
    /// the vertices the last update imposed (see the module documentation).
    pub(super) fn reaction<B: Backend + ?Sized>(
        &self,
        sim: &B,
        adj: &Adjacency,
        field: &ContactField,
        penalty_stiffness: crate::math::Mat3,
    ) -> Reaction {
        let penalty = (self.law == ContactLaw::Penalty)
            .then(|| (field.force_n(self.slot), penalty_stiffness));
        reaction::tool_reaction(sim, adj, &self.constraints, penalty)
    }

    /// The parts the penalty law samples this step, each swept from the
    /// previous update's pose (or standing still when the tool or the
    /// part just appeared): the tip unless the jaws grip or the tool is a
    /// cavitron (whose tip burns), and the inserted shaft.
    pub(super) fn sweeps(&self) -> [Option<PartSweep>; 2] {
        let Some(pose) = self.pose else {
            return [None, None];
        };
        let prev = self.prev_pose.unwrap_or(pose);
        let sweep = |to: Segment, from: Option<Segment>, tip: bool| PartSweep {
            tool: self.slot,
            tip,
            from: from.unwrap_or(to),
            to,
            radius_m: pose.radius_m,
        };
        let tip = (self.decl.kind != ToolKind::Cavitron && !self.gripping)
            .then(|| sweep(pose.tip, Some(prev.tip), true));
        let shaft = pose.shaft.map(|s| sweep(s, prev.shaft, false));
        [tip, shaft]
    }

    /// After a penalty step: the vertices of the triangles the tip pressed
    /// (`mark` is all false on entry and on exit).
    pub(super) fn after_step(&mut self, field: &ContactField, mark: &mut [bool]) -> bool {
        if self.law != ContactLaw::Penalty {
            return !self.constraints.is_empty();
        }
        self.touched.clear();
        let mut contact = false;
        for (p, depth) in field.points().iter().zip(field.penetrations_m()) {
            let part = &field.parts()[p.part as usize];
            if *depth <= 0.0 || part.tool != self.slot {
                continue;
            }
            contact = true;
            if part.tip {
                for v in p.vertices {
                    if !mark[v as usize] {
                        mark[v as usize] = true;
                        self.touched.push(VertexId(v));
                    }
                }
            }
        }
        for v in &self.touched {
            mark[v.idx()] = false;
        }
        self.armed = !self.touched.is_empty() && self.jaw > GRIP_BELOW;
        contact || !self.constraints.is_empty()
    }

    fn push(&mut self, claims: &mut Claims, v: VertexId, kind: ConstraintKind, target_m: Vec3) {
        claims.take(v, self.slot);
        self.constraints.push(Constraint {
            vertex: v,
            kind,
            target_m,
        });
    }

    /// Detects and projects the contact of one part (tip or shaft).
    fn plane_pass<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &SurfaceIndex,
        adj: &Adjacency,
        claims: &mut Claims,
        segment: &Segment,
        part: Part,
    ) {
        let Some(pose) = self.pose else { return };
        let r = pose.radius_m;
        self.scratch.candidates.clear();
        index.candidates(segment, r, &mut self.scratch.candidates);
        self.scratch.hits.clear();
        for &v in &self.scratch.candidates {
            if claims.is_free(v) && segment.distance_m(sim.position(v)) < r {
                self.scratch.hits.push(v);
                self.scratch.mark[v.idx()] = true;
            }
        }
        // Persistence: what this part held at the previous update.
        self.scratch.kept.clear();
        for c in &self.previous {
            let same = match c.kind {
                ConstraintKind::Tip(_) => part == Part::Tip,
                ConstraintKind::Shaft(_) => part == Part::Shaft,
                ConstraintKind::Grip => false,
            };
            let v = c.vertex;
            if same && !self.scratch.mark[v.idx()] && claims.is_free(v) && index.contains(v) {
                self.scratch.kept.push(v);
                self.scratch.mark[v.idx()] = true;
            }
        }
        let normal = self.mean_normal(sim, adj);
        for v in self.scratch.hits.iter().chain(&self.scratch.kept) {
            self.scratch.mark[v.idx()] = false;
        }
        if self.scratch.hits.is_empty() && self.scratch.kept.is_empty() {
            return;
        }
        let n = normal.unwrap_or(-pose.direction);
        let (n, kind): (Vec3, fn(Vec3) -> ConstraintKind) = match part {
            Part::Tip => (n, ConstraintKind::Tip),
            Part::Shaft => {
                let t = pose.direction;
                let proj = t.cross(n).cross(t);
                if proj.length() < MIN_SHAFT_SIN {
                    return;
                }
                (proj.normalize(), ConstraintKind::Shaft)
            }
        };
        let plane = Plane::tangent(segment, r, n);
        for i in 0..self.scratch.hits.len() {
            let v = self.scratch.hits[i];
            let target = plane.project(sim.position(v));
            self.push(claims, v, kind(n), target);
        }
        for i in 0..self.scratch.kept.len() {
            let v = self.scratch.kept[i];
            let x = sim.position(v);
            let pushing = reaction::vertex_force_n(sim, adj, v).dot(n) > 0.0;
            if pushing
                && plane.footprint_distance_m(x, segment) <= r
                && plane.height_m(x) >= -KEEP_BELOW * r
            {
                self.push(claims, v, kind(n), plane.project(x));
            }
        }
    }

    /// Mean outward normal (area-weighted, current positions) of the surface
    /// triangles touching the marked vertices (this pass's hits and kept),
    /// found through each vertex's tetrahedra, each triangle counted once.
    fn mean_normal<B: Backend + ?Sized>(&self, sim: &B, adj: &Adjacency) -> Option<Vec3> {
        let model = sim.model();
        let topo = model.topology();
        let tets = model.mesh().tets();
        let mut sum = Vec3::ZERO;
        for &v in self.scratch.hits.iter().chain(&self.scratch.kept) {
            for &t in adj.tets_of(v) {
                if !topo.is_alive(t) {
                    continue;
                }
                let tet = tets[t.idx()];
                for (k, face) in TET_FACES.iter().enumerate() {
                    let [a, b, c] = face.map(|l| tet[l]);
                    // Face k leaves out local vertex k; count the face from
                    // its lowest-numbered marked vertex only.
                    let first = [a, b, c]
                        .into_iter()
                        .filter(|w| self.scratch.mark[w.idx()])
                        .min();
                    if tet[k] == v || first != Some(v) || !topo.is_surface_face(t, k) {
                        continue;
                    }
                    let (pa, pb, pc) = (sim.position(a), sim.position(b), sim.position(c));
                    sum += (pb - pa).cross(pc - pa);
                }
            }
        }
        sum.try_normalize()
    }

    /// The grasper's state: grip, let go, cut. Returns tetrahedra removed.
    fn grasp<B: Backend + ?Sized>(
        &mut self,
        sim: &mut B,
        adj: &Adjacency,
        pose: &ToolPose,
        jaw: Real,
    ) -> usize {
        if self.gripping && jaw > GRIP_BELOW {
            self.gripped.clear();
            self.gripping = false;
        } else if !self.gripping && jaw < GRIP_BELOW && self.armed {
            self.gripped.clear();
            for &v in &self.touched {
                self.gripped.push((v, sim.position(v)));
            }
            self.gripping = !self.gripped.is_empty();
            self.grip_end_m = pose.end_m;
        }
        if !(self.gripping && jaw < CUT_BELOW) {
            return 0;
        }
        self.scratch.doomed.clear();
        for &(v, _) in &self.gripped {
            self.scratch.doomed.extend_from_slice(adj.tets_of(v));
        }
        self.gripped.clear();
        self.gripping = false;
        self.remove_doomed(sim)
    }

    /// The cavitron: removes the live tetrahedra with a vertex within the
    /// radius of the tip. Returns how many.
    fn burn<B: Backend + ?Sized>(
        &mut self,
        sim: &mut B,
        adj: &Adjacency,
        pose: &ToolPose,
    ) -> usize {
        self.scratch.doomed.clear();
        let topo = sim.model().topology();
        // The tip's box first (arithmetic on the position only): this scan
        // visits every vertex each millisecond, and most are far.
        let reach = Vec3::splat(pose.radius_m);
        let (lo, hi) = (
            pose.tip.a_m.min(pose.tip.b_m) - reach,
            pose.tip.a_m.max(pose.tip.b_m) + reach,
        );
        let rest = sim.model().mesh().positions_m();
        for (v, (x0, u)) in rest.iter().zip(sim.displacements()).enumerate() {
            let x = *x0 + Vec3::from_array(*u);
            if !(x.cmpge(lo).all() && x.cmple(hi).all()) {
                continue;
            }
            let v = VertexId::from(v);
            if topo.vertex_tet_count(v) > 0 && pose.tip.distance_m(x) < pose.radius_m {
                self.scratch.doomed.extend_from_slice(adj.tets_of(v));
            }
        }
        self.remove_doomed(sim)
    }

    fn remove_doomed<B: Backend + ?Sized>(&mut self, sim: &mut B) -> usize {
        let mut removed = 0;
        for &t in &self.scratch.doomed {
            // A tetrahedron may be listed once per doomed vertex.
            if !sim.model().topology().is_alive(t) {
                continue;
            }
            match sim.remove_tet(t) {
                Ok(_) => removed += 1,
                // A backend that cannot cut says so; the cut is not made.
                Err(CutError::Unsupported { why, .. }) => self.cut_refused = Some(why),
                Err(_) => {}
            }
        }
        removed
    }
}

mod approach;
pub(super) mod claims;
mod outside;
pub(super) mod proxy;

impl ToolContact {
    /// Why this tool's state cannot move to another mesh of the tissue
    /// now (what a refinement that follows the tools waits for): a grip
    /// holds vertices and a cut has removed elements, neither of which a
    /// mesh made again from the scene has.
    pub fn pins_the_mesh(&self) -> Option<&'static str> {
        if self.gripping || !self.gripped.is_empty() {
            Some("a tool grips tissue")
        } else if self.removed > 0 {
            Some("a tool has cut tissue")
        } else {
            None
        }
    }

    /// Takes over `old`'s motion (its proxy, poses, jaw and timers) as the
    /// same tool over another mesh of the tissue; the vertices it touched
    /// are renumbered by `new_of_old` (those the new mesh dropped are
    /// forgotten). The contact set itself is selected again at the next step.
    pub fn carry_from(&mut self, old: &ToolContact, new_of_old: &[Option<VertexId>]) {
        self.proxy = old.proxy;
        self.direction = old.direction;
        self.pose = old.pose;
        self.prev_pose = old.prev_pose;
        self.jaw = old.jaw;
        self.touched.clear();
        self.touched.extend(
            (old.touched.iter()).filter_map(|v| new_of_old.get(v.idx()).copied().flatten()),
        );
        self.armed = old.armed && !self.touched.is_empty();
        self.held_outside = old.held_outside;
        self.slowed = old.slowed;
        self.since_burn_s = old.since_burn_s;
        self.catching_up_s = old.catching_up_s;
    }
}
