//! Tool contact on the tensor-mass simulation (paper 4.1-4.3): detection
//! between a posed tool and the deformed surface, projection of the collided
//! vertices on contact planes (frictionless sliding), gripping, cutting by
//! the jaws and by the cavitron, and the reaction force and contact
//! stiffness the haptic device renders.
//!
//! One [`ToolContact`] per tool. Each simulation step:
//! `contact.update(&mut sim, tip_m, jaw_opening)` (detect and impose),
//! `sim.step()`, then `contact.reaction(&sim)` (what the tool feels).
//!
//! # Rules (and where they simplify the paper)
//! - **Geometry.** The shaft runs from the fulcrum through the tip; the tip
//!   is its last `tip_length_m`, the rest inside the fulcrum is the shaft;
//!   both are capsules of radius `radius_m`. A tip further than `length_m`
//!   from the fulcrum is pulled back to `length_m`.
//! - **Detection.** A live, non-excluded surface vertex (at its current
//!   position) collides with the tip if it is closer than `radius_m` to the
//!   tip segment, with the shaft likewise; the tip takes precedence. The
//!   paper used OpenGL picking; here every surface vertex is tested against
//!   the two segments (a few arithmetic operations each; update plus
//!   reaction measured 7 us on a 726-vertex block, and the scan is linear in
//!   the surface, so no spatial grid or collision library is used:
//!   parry3d-f64 0.31 builds in 23 s on 2 cores, but a point-capsule
//!   distance is all this needs and it would add no speed). The
//!   surface vertex list is rebuilt from the live surface each update, into
//!   reused buffers, so cuts by any tool are seen at once.
//! - **Tip contact.** N = the mean (area-weighted) outward normal, at current
//!   positions, of the surface triangles touching the contact vertices. The
//!   contact plane has normal N and is tangent to the tip capsule on the
//!   tissue side (the paper's "plane through the tool end", moved by the
//!   radius so that projected vertices are outside the tool). Each contact
//!   vertex is prescribed, for the coming step, at its orthogonal projection
//!   on the plane.
//! - **Shaft contact.** N_proj = (T x N) x T normalised (T the shaft
//!   direction); the plane contains a line parallel to the shaft, tangent to
//!   the shaft cylinder on the tissue side; a vertex V moves by
//!   -((V - X0) . N_proj) N_proj, the paper's dV up to the radius offset.
//!   When N is within about 6 degrees of T (shaft entering the surface
//!   head-on) N_proj is undefined and the shaft imposes nothing that step.
//! - **Persistence.** Projection leaves a vertex on the tangent plane, i.e.
//!   at distance >= radius from the segment, where the detection above no
//!   longer sees it. So the paper's "re-projected after each step" is
//!   implemented as: a vertex the same part (tip or shaft) constrained at the
//!   previous update stays constrained, re-projected on the new plane, while
//!   it is in the tool's footprint (its projection on the plane within
//!   `radius_m` of the projected segment), the tissue still pushes on the
//!   tool there (its elastic force has a positive component along the
//!   normal: contact is unilateral) and it is not more than 5% of the radius
//!   below the new plane (a tool pulled away fast lets go at once). Every
//!   update releases the previous constraints first, so vertices slide along
//!   the plane without friction and leave it at the footprint's edge.
//! - **Gripping** (grasper): contact with the jaws open (opening > 0.5) at
//!   one update, then the jaws below 0.5: the vertices in tip contact at
//!   that previous update are gripped and follow the tool end's translation
//!   (the tool's rotation about the end is not applied to them) until the
//!   jaws open above 0.5.
//! - **Jaw cutting** (grasper gripping with the jaws below 0.1): every live
//!   tetrahedron with a vertex among the gripped ones is removed (the tissue
//!   "between the jaws" is taken as the gripped vertices' one-ring, a
//!   simplification of the jaws' real swept volume); the grip ends, and a new
//!   one needs the jaws open on tissue again.
//! - **Cavitron**: every live tetrahedron with a vertex (any vertex, at its
//!   current position) closer than `radius_m` to the tip segment is removed
//!   before detection; its shaft still pushes like any other. This scans
//!   every vertex (O(n) per update, not only the surface): the tip may be
//!   inside the tissue, where no surface vertex is near it.
//! - **Excluded vertices** (those the scene fixes or prescribes): the tool
//!   never prescribes nor releases them ([`ToolContact::exclude`]).
//!
//! # Reaction
//! The force on the tool is the sum, over the vertices it constrains, of the
//! elastic force F_i = -(K U)_i after the step: the tissue pushes on the
//! tool with the force the tool must hold each vertex against (inertia and
//! damping of those vertices are neglected, exact at equilibrium). A tool
//! pressing down on a top face is pushed up. A nonlinear membrane's forces
//! are not included (a linear one is in K).
//!
//! The contact stiffness is sum_i n_i (n_i^T K_ii n_i) n_i^T over
//! plane-constrained vertices (n_i their plane normal: only motion along the
//! normal is resisted, sliding is free) plus K_ii over gripped vertices.
//! It uses each vertex's own tensor only: the coupling through the free
//! vertices (the Schur complement) is neglected, so it overestimates the
//! quasi-static stiffness; it is what a local-model extrapolator needs to
//! stay stiff enough on contact, not an exact compliance.

mod geometry;
mod reaction;

pub use geometry::{Plane, Segment, ToolPose};
pub use reaction::Reaction;

use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::scene::ToolDecl;
use crate::scene::spec::ToolKind;
use crate::tensor_mass::{ElasticModel, Explicit, Storage};
use reaction::{VertexEdges, along};

/// Jaw opening below which jaws that touched tissue open grip it.
pub const GRIP_BELOW: Real = 0.5;
/// Jaw opening below which gripping jaws cut what they hold.
pub const CUT_BELOW: Real = 0.1;
/// How far (fraction of the radius) below the new plane a persisting
/// contact vertex may be and still be re-projected.
const KEEP_BELOW: Real = 0.05;
/// |N_proj| below which the shaft plane is undefined (sin of ~6 degrees).
const MIN_SHAFT_SIN: Real = 0.1;

const FREE: u8 = 0;
const TIP: u8 = 1;
const SHAFT: u8 = 2;
const GRIP: u8 = 3;

/// How a vertex is constrained.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ConstraintKind {
    /// On the tip's contact plane with this unit normal.
    Tip(Vec3),
    /// On the shaft's contact plane with this unit normal (N_proj).
    Shaft(Vec3),
    /// Held by the jaws.
    Grip,
}

/// A vertex a tool imposes for the coming step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Constraint {
    /// The vertex.
    pub vertex: VertexId,
    /// Why.
    pub kind: ConstraintKind,
    /// Where it is put (m).
    pub target_m: Vec3,
}

/// What one update did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ContactReport {
    /// The tool touches tissue (some vertex constrained).
    pub contact: bool,
    /// The jaws hold tissue.
    pub gripping: bool,
    /// Tetrahedra removed by this update (jaws or cavitron).
    pub tets_removed: usize,
    /// Vertices constrained for the coming step.
    pub constrained_vertices: usize,
}

/// One tool's contact with the tissue, its state kept between steps.
pub struct ToolContact {
    decl: ToolDecl,
    direction: Vec3,
    pose: Option<ToolPose>,
    excluded: Vec<bool>,
    /// The role of each vertex at the last update, and the one being built.
    role: Vec<u8>,
    next_role: Vec<u8>,
    constraints: Vec<Constraint>,
    previous: Vec<Constraint>,
    surface: Vec<VertexId>,
    on_surface: Vec<bool>,
    /// `ElasticModel::topology_changes` when `surface` was built.
    surface_seen: Option<u64>,
    near: Vec<bool>,
    hits: Vec<VertexId>,
    kept: Vec<VertexId>,
    gripped: Vec<(VertexId, Vec3)>,
    grip_end_m: Vec3,
    gripping: bool,
    armed: bool,
    vertex_edges: VertexEdges,
    tet_offsets: Vec<u32>,
    vertex_tets: Vec<TetId>,
    doomed: Vec<TetId>,
}

impl ToolContact {
    /// A tool over `model` (its vertex count and adjacency), touching nothing.
    pub fn new(decl: &ToolDecl, model: &ElasticModel) -> Self {
        let n = model.vertex_count();
        let tets = model.mesh().tets();
        let mut tet_offsets = vec![0u32; n + 1];
        for tet in tets {
            for v in tet {
                tet_offsets[v.idx() + 1] += 1;
            }
        }
        for i in 0..n {
            tet_offsets[i + 1] += tet_offsets[i];
        }
        let mut fill = tet_offsets.clone();
        let mut vertex_tets = vec![TetId(0); tet_offsets[n] as usize];
        for (t, tet) in tets.iter().enumerate() {
            for v in tet {
                vertex_tets[fill[v.idx()] as usize] = TetId::from(t);
                fill[v.idx()] += 1;
            }
        }
        Self {
            decl: decl.clone(),
            // Used only while the tip sits on the fulcrum: point down.
            direction: Vec3::NEG_Z,
            pose: None,
            excluded: vec![false; n],
            role: vec![FREE; n],
            next_role: vec![FREE; n],
            constraints: Vec::new(),
            previous: Vec::new(),
            surface: Vec::new(),
            on_surface: vec![false; n],
            surface_seen: None,
            near: vec![false; n],
            hits: Vec::new(),
            kept: Vec::new(),
            gripped: Vec::new(),
            grip_end_m: Vec3::ZERO,
            gripping: false,
            armed: false,
            vertex_edges: VertexEdges::new(model),
            tet_offsets,
            vertex_tets,
            doomed: Vec::new(),
        }
    }

    /// Never constrain nor release `v` (a vertex the scene fixes or prescribes).
    pub fn exclude(&mut self, v: VertexId) {
        self.excluded[v.idx()] = true;
    }

    /// The tool as declared.
    pub fn decl(&self) -> &ToolDecl {
        &self.decl
    }

    /// The pose of the last update.
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

    /// Detects contact with the tool at `tip_m` (jaws at `jaw_opening`, 0
    /// closed to 1 open; ignored by other tools), cuts, and imposes the
    /// contact vertices for the coming step. Call once before each `sim.step()`.
    pub fn update<S: Storage>(
        &mut self,
        sim: &mut Explicit<S>,
        tip_m: Vec3,
        jaw_opening: Real,
    ) -> ContactReport {
        let pose = ToolPose::new(&self.decl, tip_m, self.direction);
        self.direction = pose.direction;
        self.pose = Some(pose);
        std::mem::swap(&mut self.constraints, &mut self.previous);
        self.constraints.clear();
        let mut removed = 0;
        match self.decl.kind {
            ToolKind::Grasper => removed += self.grasp(sim, &pose, jaw_opening),
            ToolKind::Cavitron => removed += self.burn(sim, &pose),
            ToolKind::Hook => {}
        }
        // The surface vertex set changes only with cuts (by any tool).
        let changes = sim.model().topology_changes();
        if self.surface_seen != Some(changes) {
            self.refresh_surface(sim.model());
            self.surface_seen = Some(changes);
        }
        let offset = pose.end_m - self.grip_end_m;
        for i in 0..self.gripped.len() {
            let (v, p) = self.gripped[i];
            if sim.model().topology().vertex_tet_count(v) > 0 {
                self.push(v, ConstraintKind::Grip, p + offset, GRIP);
            }
        }
        if self.decl.kind != ToolKind::Cavitron {
            self.plane_pass(sim, &pose.tip, TIP, &pose);
        }
        if let Some(shaft) = pose.shaft {
            self.plane_pass(sim, &shaft, SHAFT, &pose);
        }
        // Release what is no longer imposed, impose the rest.
        for c in &self.previous {
            let v = c.vertex;
            if self.next_role[v.idx()] == FREE {
                sim.release(v);
            }
            self.role[v.idx()] = FREE;
        }
        let mut touching = false;
        for c in &self.constraints {
            let v = c.vertex;
            let rest_m = sim.model().mesh().positions_m()[v.idx()];
            sim.prescribe(v, c.target_m - rest_m);
            self.role[v.idx()] = self.next_role[v.idx()];
            self.next_role[v.idx()] = FREE;
            touching |= self.role[v.idx()] == TIP;
        }
        self.armed = touching && jaw_opening > GRIP_BELOW;
        ContactReport {
            contact: !self.constraints.is_empty(),
            gripping: self.gripping,
            tets_removed: removed,
            constrained_vertices: self.constraints.len(),
        }
    }

    /// Frees every vertex the tool holds (the tool is withdrawn).
    pub fn release_all<S: Storage>(&mut self, sim: &mut Explicit<S>) {
        for c in self.constraints.drain(..) {
            sim.release(c.vertex);
            self.role[c.vertex.idx()] = FREE;
        }
        self.gripped.clear();
        self.gripping = false;
        self.armed = false;
    }

    /// The force on the tool and the contact stiffness after the step, from
    /// the vertices the last update imposed (see the module documentation).
    pub fn reaction<S: Storage>(&self, sim: &Explicit<S>) -> Reaction {
        let model = sim.model();
        let mut out = Reaction::NONE;
        for c in &self.constraints {
            let v = c.vertex;
            out.force_n += self
                .vertex_edges
                .elastic_force_n(model, v, |w| sim.displacement(w));
            let k = &model.vertex_tensors()[v.idx()];
            out.stiffness_n_per_m += match c.kind {
                ConstraintKind::Tip(n) | ConstraintKind::Shaft(n) => along(k, n),
                ConstraintKind::Grip => *k,
            };
        }
        out
    }

    fn push(&mut self, v: VertexId, kind: ConstraintKind, target_m: Vec3, role: u8) {
        self.next_role[v.idx()] = role;
        self.constraints.push(Constraint {
            vertex: v,
            kind,
            target_m,
        });
    }

    /// Rebuilds the list of live surface vertices.
    fn refresh_surface(&mut self, model: &ElasticModel) {
        for v in self.surface.drain(..) {
            self.on_surface[v.idx()] = false;
        }
        for tri in model.topology().surface_triangles(model.mesh()) {
            for v in tri {
                if !self.on_surface[v.idx()] {
                    self.on_surface[v.idx()] = true;
                    self.surface.push(v);
                }
            }
        }
    }

    /// Detects and projects the contact of one part (tip or shaft).
    fn plane_pass<S: Storage>(
        &mut self,
        sim: &Explicit<S>,
        segment: &Segment,
        role: u8,
        pose: &ToolPose,
    ) {
        let r = pose.radius_m;
        self.hits.clear();
        self.kept.clear();
        for &v in &self.surface {
            if self.excluded[v.idx()] || self.next_role[v.idx()] != FREE {
                continue;
            }
            let x = sim.position(v);
            if segment.might_touch(x, r) && segment.distance_m(x) < r {
                self.hits.push(v);
            } else if self.role[v.idx()] == role {
                self.kept.push(v);
            }
        }
        if self.hits.is_empty() && self.kept.is_empty() {
            return;
        }
        let n = self.mean_normal(sim).unwrap_or(-pose.direction);
        let (n, kind): (Vec3, fn(Vec3) -> ConstraintKind) = if role == TIP {
            (n, ConstraintKind::Tip)
        } else {
            let t = pose.direction;
            let proj = t.cross(n).cross(t);
            if proj.length() < MIN_SHAFT_SIN {
                return;
            }
            (proj.normalize(), ConstraintKind::Shaft)
        };
        let plane = Plane::tangent(segment, r, n);
        let model = sim.model();
        for i in 0..self.hits.len() {
            let v = self.hits[i];
            let target = plane.project(sim.position(v));
            self.push(v, kind(n), target, role);
        }
        for i in 0..self.kept.len() {
            let v = self.kept[i];
            let x = sim.position(v);
            let pushing = self
                .vertex_edges
                .elastic_force_n(model, v, |w| sim.displacement(w))
                .dot(n)
                > 0.0;
            if pushing
                && plane.footprint_distance_m(x, segment) <= r
                && plane.height_m(x) >= -KEEP_BELOW * r
            {
                self.push(v, kind(n), plane.project(x), role);
            }
        }
    }

    /// Mean outward normal (area-weighted, current positions) of the surface
    /// triangles touching the current hits and kept vertices.
    fn mean_normal<S: Storage>(&mut self, sim: &Explicit<S>) -> Option<Vec3> {
        for v in self.hits.iter().chain(&self.kept) {
            self.near[v.idx()] = true;
        }
        let model = sim.model();
        let mut sum = Vec3::ZERO;
        for [a, b, c] in model.topology().surface_triangles(model.mesh()) {
            if self.near[a.idx()] || self.near[b.idx()] || self.near[c.idx()] {
                let (pa, pb, pc) = (sim.position(a), sim.position(b), sim.position(c));
                sum += (pb - pa).cross(pc - pa);
            }
        }
        for v in self.hits.iter().chain(&self.kept) {
            self.near[v.idx()] = false;
        }
        sum.try_normalize()
    }

    /// The grasper's state: grip, let go, cut. Returns tetrahedra removed.
    fn grasp<S: Storage>(&mut self, sim: &mut Explicit<S>, pose: &ToolPose, jaw: Real) -> usize {
        if self.gripping && jaw > GRIP_BELOW {
            self.gripped.clear();
            self.gripping = false;
        } else if !self.gripping && jaw < GRIP_BELOW && self.armed {
            self.gripped.clear();
            for c in &self.previous {
                if matches!(c.kind, ConstraintKind::Tip(_)) {
                    self.gripped.push((c.vertex, sim.position(c.vertex)));
                }
            }
            self.gripping = !self.gripped.is_empty();
            self.grip_end_m = pose.end_m;
        }
        if !(self.gripping && jaw < CUT_BELOW) {
            return 0;
        }
        self.doomed.clear();
        for &(v, _) in &self.gripped {
            let range = self.tet_offsets[v.idx()] as usize..self.tet_offsets[v.idx() + 1] as usize;
            self.doomed.extend_from_slice(&self.vertex_tets[range]);
        }
        self.gripped.clear();
        self.gripping = false;
        self.remove_doomed(sim)
    }

    /// The cavitron: removes the live tetrahedra with a vertex within the
    /// radius of the tip. Returns how many.
    fn burn<S: Storage>(&mut self, sim: &mut Explicit<S>, pose: &ToolPose) -> usize {
        self.doomed.clear();
        let topo = sim.model().topology();
        for v in 0..sim.model().vertex_count() {
            let v = VertexId::from(v);
            let x = sim.position(v);
            if topo.vertex_tet_count(v) > 0
                && pose.tip.might_touch(x, pose.radius_m)
                && pose.tip.distance_m(x) < pose.radius_m
            {
                let range =
                    self.tet_offsets[v.idx()] as usize..self.tet_offsets[v.idx() + 1] as usize;
                self.doomed.extend_from_slice(&self.vertex_tets[range]);
            }
        }
        self.remove_doomed(sim)
    }

    fn remove_doomed<S: Storage>(&mut self, sim: &mut Explicit<S>) -> usize {
        let mut removed = 0;
        for &t in &self.doomed {
            // A tetrahedron may be listed once per doomed vertex.
            if sim.model().topology().is_alive(t) && sim.remove_tet(t).is_ok() {
                removed += 1;
            }
        }
        removed
    }
}
