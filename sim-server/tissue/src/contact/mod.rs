//! Tool contact on the tensor-mass simulation (paper 4.1-4.3): detection
//! between a posed tool and the deformed surface, projection of the collided
//! vertices on contact planes (frictionless sliding), gripping, cutting by
//! the jaws and by the cavitron, and the reaction force and contact
//! stiffness the haptic device renders.
//!
//! [`Tools`] holds every tool of a scene. Each simulation step:
//! `tools.update(&mut sim, &inputs)` (detect and impose),
//! `sim.step()`, then `tools.reaction(i, &sim)` (what tool `i` feels).
//!
//! # Where things are
//! From the top down (each layer imports only those below it; the
//! `module_graph` system test checks it):
//! - [`tools`](Tools): the scene's tools together, set up and stepped
//!   (with the contact problems made for the daemon, `tools/local_problems.rs`).
//! - `tool/`: one tool's contact state ([`ToolContact`]), the proxy that
//!   follows the pose, the claims on vertices, the approach and the tip
//!   held outside.
//! - `response/`: what the tool feels (the reaction, the contact stiffness
//!   and its worker).
//! - `local.rs`: the contact problem around one tool, for the daemon.
//! - [`penalty`]: the penalty law (`field/` with its friction and implicit
//!   springs; `sampling/`: where the points are sampled and kept).
//! - `surface/`: the tissue's surface as the tools meet it (the index of its
//!   triangles, where a point crosses it, live faces, adjacency).
//! - `instrument/`: what a tool is (its declaration, friction coefficients,
//!   pose and segments).
//! - `follow_region.rs`: the corotational region following the tools;
//!   `config.rs`: the law and its constants.
//!
//! # Rules (and where they simplify the paper)
//! - **Geometry.** The shaft runs from the fulcrum through the tip; the tip
//!   is its last `tip_length_m`, the rest inside the fulcrum is the shaft;
//!   both are capsules of radius `radius_m`. A tip further than `length_m`
//!   from the fulcrum is pulled back to `length_m`.
//! - **Detection.** A live, unclaimed surface vertex (at its current
//!   position) collides with the tip if it is closer than `radius_m` to the
//!   tip segment, with the shaft likewise; the tip takes precedence. The
//!   paper used OpenGL picking; here a parry3d BVH over the surface vertices
//!   ([`SurfaceIndex`], shared by all tools, refitted incrementally each
//!   step and updated in place after a cut) gives the candidates near each
//!   segment, then the exact point-segment distance decides.
//! - **Two tools.** A vertex is held by at most one tool per step
//!   ([`Tools`]): grips first, then tips and shafts in declaration order;
//!   a tool lets go of a vertex only if no tool holds it in the new step.
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
//! - **Reserved vertices** (those the scene fixes or prescribes): no tool
//!   ever prescribes nor releases them ([`Tools::reserve`]).
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

mod config;
mod follow_region;
mod instrument;
mod local;
pub mod penalty;
pub(crate) mod response;
pub(crate) mod surface;
mod tool;
mod tools;

pub use config::{ContactConfig, ContactLaw, MAX_IMPLICIT_STIFFNESS_FACTOR};
pub use follow_region::RegionStats;
pub use instrument::{Friction, Plane, Segment, ToolDecl, ToolKind, ToolPose};
pub use local::{LocalContact, LocalPart, LocalPoint};
pub use penalty::field::ContactField;
pub use response::reaction::Reaction;
pub use response::stiffness::MAX_FACTOR_VERTICES;
pub use response::worker::{ContactStiffness, StiffnessSolves};
pub use surface::index::SurfaceIndex;
pub use tool::ToolContact;
pub use tool::proxy::Proxy;
pub use tools::{ContactError, LocalSpec, ToolInput, Tools};

use crate::ids::VertexId;
use crate::math::{Real, Vec3};

/// Jaw opening below which jaws that touched tissue open grip it.
pub const GRIP_BELOW: Real = 0.5;
/// Jaw opening below which gripping jaws cut what they hold.
pub const CUT_BELOW: Real = 0.1;

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
    /// The tool tried to cut and the backend refused: why (the precomputed
    /// backend cannot cut; the hybrid cuts only its tensor-mass part).
    pub cut_refused: Option<&'static str>,
    /// The tissue's surface stopped the tip short of the pose asked (the
    /// penalty law's proxy is held outside the tissue; see
    /// `surface_crossing`).
    pub held_outside: bool,
    /// The simulated tool is not where the hand asked and does not follow
    /// it one for one: it is coming in slowly near the tissue (after a
    /// let-go, a jump) or held outside it. Its force is the tool's where
    /// it is; extrapolating it by the hand's motion would render contact
    /// the simulation does not have.
    pub catching_up: bool,
}
