//! The contact problem around one tool, cut out of a step for a haptic
//! loop to solve again at every tick (SOFA's LCPForceFeedback idea,
//! Saupin, Duriez, Cotin 2008: a slow simulation sends its constraint
//! problem, the fast loop re-solves it for the newest tool pose).
//!
//! What a [`LocalContact`] holds, at the end of a step:
//!
//! - the tool's parts (capsules: segment and radius) and its position;
//! - the surface near the tool: the contact points of the penalty law
//!   (the same triangles, lattice and stiffnesses as the step's, but
//!   within a wider margin, so that the tool can slide onto them) and the
//!   positions of their triangles' vertices V;
//! - the tissue's compliance at V, W = (K^-1)_VV with the scene's fixed
//!   and prescribed vertices held (m/N, 3|V| x 3|V|): how the free tissue
//!   answers a force on those vertices, coupling through the whole organ
//!   included.
//!
//! A solver moving the tool by dx finds the vertices' motion delta with
//! `delta = W (f(x + delta, tool + dx) - f(x, tool))`, f the penalty
//! forces: the quasi-static, frictionless answer of a linear tissue to the
//! change of contact, exact for the linear model up to the tissue's
//! inertia and the points outside the margin (the haptic daemon's
//! `local-problem` extrapolator does it).

use crate::backend::Backend;
use crate::contact::instrument::Segment;
use crate::contact::penalty::field::{ContactField, PartSweep};
use crate::ids::VertexId;
use crate::math::{Real, Vec3};

/// One contact point of a [`LocalContact`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalPoint {
    /// Its triangle's vertices, as indices into [`LocalContact::vertices`].
    pub slots: [u16; 3],
    /// Barycentric weights (sum 1).
    pub weights: [Real; 3],
    /// The part it faces (index into [`LocalContact::parts`]).
    pub part: u8,
    /// Its spring stiffness k_p (N/m).
    pub stiffness_n_per_m: Real,
}

/// A tool part: a capsule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalPart {
    /// Its segment (m).
    pub segment: Segment,
    /// Its radius (m).
    pub radius_m: Real,
}

/// The contact problem around one tool after a step (see the module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LocalContact {
    /// The step it was taken after (counted by [`super::Tools`] from 1).
    pub step: u64,
    /// The tool's tip (proxy) position the step ended with (m).
    pub tool_position_m: Vec3,
    /// The tool's parts at the end of the step (tip, then shaft).
    pub parts: Vec<LocalPart>,
    /// The vertices of the points' triangles (mesh ids).
    pub vertices: Vec<u32>,
    /// Their positions at the end of the step (m).
    pub positions_m: Vec<Vec3>,
    /// The contact points within the margin.
    pub points: Vec<LocalPoint>,
    /// W = (K^-1)_VV (m/N), row-major, 3|V| x 3|V|, in the order of
    /// `vertices` (x, y, z of each).
    pub compliance_m_per_n: Vec<Real>,
    /// With [`super::LocalSpec::inertia`]: G = C_V^T M C_V, the lumped
    /// masses seen through the compliance's columns (row-major, the size of
    /// `compliance_m_per_n`; the tissue's mass condensed on V, Guyan, is
    /// W^-1 G W^-1); empty otherwise.
    pub column_mass: Vec<Real>,
    /// With [`super::LocalSpec::inertia`]: the vertices' velocities at the
    /// end of the step (m/s), taken with their positions.
    pub velocities_m_per_s: Vec<Vec3>,
    /// With [`super::LocalSpec::inertia`]: the mass-proportional damping
    /// (1/s).
    pub damping_per_s: Real,
}

impl LocalContact {
    /// Empties it (buffers kept).
    pub fn clear(&mut self) {
        self.parts.clear();
        self.vertices.clear();
        self.positions_m.clear();
        self.points.clear();
        self.compliance_m_per_n.clear();
        self.column_mass.clear();
        self.velocities_m_per_s.clear();
        self.damping_per_s = 0.0;
    }

    /// Takes the vertices' velocities and the tissue's mass-proportional
    /// damping from `sim` (with the positions: the same instant).
    pub(super) fn take_motion<B: Backend + ?Sized>(&mut self, sim: &B) {
        self.velocities_m_per_s.clear();
        self.velocities_m_per_s
            .extend(self.vertices.iter().map(|&v| sim.velocity(VertexId(v))));
        // As the tensor-mass integrator applies it: a scene's damping per
        // second, the same ratio at every vertex (the first one's taken).
        self.damping_per_s = self.vertices.first().map_or(0.0, |&v| {
            let m = sim.model().masses_kg()[v as usize];
            if m > 0.0 {
                sim.model().damping_kg_s()[v as usize] / m
            } else {
                0.0
            }
        });
    }

    /// Fills the points, parts and vertices from `field`, a field holding
    /// one tool's parts (standing still) and the points sampled around
    /// them; at most `max_vertices` vertices (the points nearest the tool
    /// first) and `max_points` points. `slot` is scratch indexed by vertex
    /// (`u32::MAX` on entry and on exit).
    pub(super) fn take_points(
        &mut self,
        field: &ContactField,
        position: impl Fn(u32) -> Vec3,
        max_vertices: usize,
        max_points: usize,
        slot: &mut [u32],
        order: &mut Vec<(Real, usize)>,
    ) {
        self.clear();
        self.parts
            .extend(field.parts().iter().map(|s: &PartSweep| LocalPart {
                segment: s.to,
                radius_m: s.radius_m,
            }));
        // Nearest first, so that a cap drops the far edge of the margin.
        order.clear();
        for (i, p) in field.points().iter().enumerate() {
            let x = (0..3).fold(Vec3::ZERO, |x, k| {
                x + position(p.vertices[k]) * p.weights[k]
            });
            let part = &field.parts()[p.part as usize];
            order.push((part.to.distance_m(x) - part.radius_m, i));
        }
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        for &(_, i) in order.iter() {
            if self.points.len() >= max_points {
                break;
            }
            let p = &field.points()[i];
            let new = p
                .vertices
                .iter()
                .filter(|v| slot[**v as usize] == u32::MAX)
                .count();
            if self.vertices.len() + new > max_vertices {
                continue;
            }
            let mut slots = [0u16; 3];
            for (k, &v) in p.vertices.iter().enumerate() {
                if slot[v as usize] == u32::MAX {
                    slot[v as usize] = self.vertices.len() as u32;
                    self.vertices.push(v);
                    self.positions_m.push(position(v));
                }
                slots[k] = slot[v as usize] as u16;
            }
            self.points.push(LocalPoint {
                slots,
                weights: p.weights,
                part: p.part as u8,
                stiffness_n_per_m: p.stiffness_n_per_m,
            });
        }
        for &v in &self.vertices {
            slot[v as usize] = u32::MAX;
        }
    }
}
