//! What the tool feels, the reaction physics in one place: the elastic
//! force -(K U)_v the tissue exerts at a vertex (from the model's f64
//! tensors on that vertex's row only), the force on a tool (the penalty
//! field's force on its parts plus that elastic force at every vertex it
//! constrains), and the contact stiffness beside it.

use crate::backend::Backend;
use crate::contact::surface::adjacency::Adjacency;
use crate::contact::{Constraint, ConstraintKind};
use crate::ids::VertexId;
use crate::math::{Mat3, Vec3, outer};
use crate::tensor_mass::ElasticModel;
use crate::tensor_mass::large_strain::VertexForce;

/// Force and stiffness one tool feels after a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reaction {
    /// Force the tissue exerts on the tool (N): the sum over the constrained
    /// vertices of their elastic forces F_i = -(K U)_i (plus the nonlinear
    /// elements' part in a nonlinear model). A tool pressing into
    /// tissue is pushed back out of it.
    pub force_n: Vec3,
    /// Contact stiffness (N/m), symmetric positive semidefinite: how the
    /// force on the tool grows when the tool moves by dx is about
    /// `-stiffness * dx` (see [`crate::contact`] for the approximation).
    pub stiffness_n_per_m: Mat3,
}

impl Reaction {
    /// No contact.
    pub const NONE: Self = Self {
        force_n: Vec3::ZERO,
        stiffness_n_per_m: Mat3::ZERO,
    };

    /// The stiffness as rows (`[row][column]`), as the force sample carries it.
    pub fn stiffness_rows(&self) -> [[f64; 3]; 3] {
        self.stiffness_n_per_m.transpose().to_cols_array_2d()
    }
}

/// The stiffness K_vv restricted to the direction `n`: n (n^T K n) n^T.
fn along(k: &Mat3, n: Vec3) -> Mat3 {
    outer(n, n) * n.dot(*k * n)
}

/// The elastic force -(K U)_v (N) at vertex `v`, given displacements: the
/// vertex tensor and the tensors of the edges around it (`adj`).
pub(crate) fn elastic_force_n(
    adj: &Adjacency,
    model: &ElasticModel,
    v: VertexId,
    displacement: impl Fn(VertexId) -> Vec3,
) -> Vec3 {
    let mut ku = model.vertex_tensors()[v.idx()] * displacement(v);
    let edges = model.topology().edges();
    let tensors = model.edge_tensors();
    for e in adj.edges_of(v) {
        let [a, b] = edges[e.idx()];
        let k = tensors[e.idx()];
        // Stored as K_ab with a < b; row b uses K_ba = K_ab^T.
        ku += if a == v {
            k * displacement(b)
        } else {
            k.transpose() * displacement(a)
        };
    }
    -ku
}

/// The whole elastic force at vertex `v` (N): the linear -(K U)_v plus, in
/// a nonlinear model, the nonlinear pass's correction there (or its whole
/// force, when the step keeps no linear tensors). The pass saw the state at
/// the start of the last sub-step.
pub(crate) fn vertex_force_n<B: Backend + ?Sized>(sim: &B, adj: &Adjacency, v: VertexId) -> Vec3 {
    match sim.nonlinear_force_n(v) {
        Some(VertexForce::Whole(f)) => f,
        Some(VertexForce::Correction(c)) => {
            elastic_force_n(adj, sim.model(), v, |w| sim.displacement(w)) + c
        }
        None => elastic_force_n(adj, sim.model(), v, |w| sim.displacement(w)),
    }
}

/// One tool's reaction after a step: `penalty` (the penalty field's force
/// on the tool and the contact stiffness computed for it), if the tool
/// uses that law, plus, at every vertex it constrains, the elastic force
/// there and the vertex's own stiffness (along the contact normal for
/// the tip and shaft, whole for a grip).
pub(crate) fn tool_reaction<B: Backend + ?Sized>(
    sim: &B,
    adj: &Adjacency,
    constraints: &[Constraint],
    penalty: Option<(Vec3, Mat3)>,
) -> Reaction {
    let model = sim.model();
    let mut out = Reaction::NONE;
    if let Some((force_n, stiffness_n_per_m)) = penalty {
        out.force_n = force_n;
        out.stiffness_n_per_m = stiffness_n_per_m;
    }
    for c in constraints {
        let v = c.vertex;
        out.force_n += vertex_force_n(sim, adj, v);
        let k = &model.vertex_tensors()[v.idx()];
        out.stiffness_n_per_m += match c.kind {
            ConstraintKind::Tip(n) | ConstraintKind::Shaft(n) => along(k, n),
            ConstraintKind::Grip => *k,
        };
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Elasticity, Isotropic, Material, MaterialModel};
    use crate::material_map::TetMaterials;
    use crate::math::Real;
    use crate::mesh::{BoxSpec, CellSize};
    use crate::static_newton::{NewtonConfig, solve_static_nonlinear};
    use crate::static_solve::Dirichlet;
    use crate::tensor_mass::{Explicit, ExplicitConfig, Storage};

    /// A 2 x 1 x 1 cm StVK block, with a linear capsule membrane if
    /// `capsule`.
    fn block(capsule: bool) -> ElasticModel {
        let mesh = BoxSpec::new(Vec3::new(0.02, 0.01, 0.01), CellSize::EdgeM(0.005))
            .generate()
            .unwrap();
        let iso = Isotropic::from_young_poisson(4500.0, 0.4).unwrap();
        let material = Material::new(Elasticity::Isotropic(iso), 1000.0, 0.0)
            .unwrap()
            .with_model(MaterialModel::Stvk);
        let model = ElasticModel::new(
            mesh.clone(),
            TetMaterials::uniform(material, mesh.tet_count()),
        )
        .unwrap();
        if capsule {
            model
                .with_membrane(5000.0, crate::membrane::MembraneModel::Linear)
                .unwrap()
        } else {
            model
        }
    }

    /// The force the held vertices feel from a StVK block stretched by 30%
    /// of its length (one end fixed, the other held where a tool holds it):
    /// at the static StVK equilibrium, the sum of [`vertex_force_n`] over
    /// the held end is minus the support force the nonlinear static solver
    /// reports there, with the step's whole forces (beside a kernel with
    /// no tensors, or the capsule's alone) and with its corrections (beside
    /// the linear tensors), with and without a linear capsule membrane, in
    /// f64 and f32; the linear force alone is far off.
    #[test]
    fn a_held_end_feels_the_nonlinear_force() {
        fn check<S: Storage>(capsule: bool, whole: bool, tol: Real) {
            let model = block(capsule);
            let n = model.vertex_count();
            let p = model.mesh().positions_m().to_vec();
            let mut bc = Dirichlet::new(n);
            let stretch = Vec3::new(0.006, 0.001, -0.001);
            let held: Vec<VertexId> = (0..n as u32)
                .map(VertexId)
                .filter(|v| p[v.idx()].x > 0.02 - 1e-9)
                .collect();
            for (v, x) in p.iter().enumerate() {
                if x.x < 1e-9 {
                    bc.fix(VertexId(v as u32));
                }
            }
            for v in &held {
                bc.prescribe(*v, stretch);
            }
            let statics =
                solve_static_nonlinear(&model, &bc, &vec![Vec3::ZERO; n], NewtonConfig::default())
                    .unwrap()
                    .solution;
            let support: Vec3 = held.iter().map(|v| statics.force_n[v.idx()]).sum();
            let adj = Adjacency::new(&model);
            let config = ExplicitConfig::new(1e-5);
            let mut sim = if whole {
                Explicit::<S>::new(model, config).unwrap()
            } else {
                Explicit::<S>::with_linear_tensors(model, config).unwrap()
            };
            assert_eq!(sim.kernel().is_elastic(), !whole);
            for (v, x) in p.iter().enumerate() {
                if x.x < 1e-9 {
                    sim.fix(VertexId(v as u32));
                }
            }
            for v in &held {
                sim.prescribe(*v, stretch);
            }
            sim.set_state(&statics.displacement_m, &statics.displacement_m);
            sim.step();
            // The pass saw the equilibrium at the start of the step; the
            // free vertices barely moved in 10 us.
            let felt: Vec3 = held.iter().map(|v| vertex_force_n(&sim, &adj, *v)).sum();
            let linear: Vec3 = held
                .iter()
                .map(|v| {
                    elastic_force_n(&adj, sim.model(), *v, |w| {
                        Vec3::from(statics.displacement_m[w.idx()])
                    })
                })
                .sum();
            let scale = support.length();
            assert!(
                (felt + support).length() <= tol * scale,
                "capsule {capsule}, whole {whole}: felt {felt} against support {support}"
            );
            assert!(
                (linear + support).length() > 0.05 * scale,
                "the stretch is nonlinear enough to tell: linear {linear}, support {support}"
            );
        }
        for capsule in [false, true] {
            for whole in [false, true] {
                check::<f64>(capsule, whole, 1e-6);
                check::<f32>(capsule, whole, 1e-4);
            }
        }
    }
}
