//! Setting up a scene's tools: the contact constants checked, the law
//! chosen for the backend (penalty where it integrates contact, the
//! paper's projection otherwise), and the state they share (one surface
//! index, the claims on vertices, the contact field, the point sampler and
//! the contact stiffness's solver). A part of [`super`], which owns them.

use super::local_problems::LocalScratch;
use super::{ContactError, Tools};
use crate::backend::Backend;
use crate::contact::ContactReport;
use crate::contact::ToolDecl;
use crate::contact::config::{ContactConfig, ContactLaw, MAX_IMPLICIT_STIFFNESS_FACTOR};
use crate::contact::penalty::field::ContactField;
use crate::contact::penalty::sampling::Sampler;
use crate::contact::response::worker::ContactStiffness;
use crate::contact::surface::adjacency::Adjacency;
use crate::contact::surface::crossing::Crossing;
use crate::contact::surface::index::SurfaceIndex;
use crate::contact::tool::ToolContact;
use crate::contact::tool::claims::Claims;
use crate::contact::tool::proxy::Proxy;
use crate::ids::VertexId;
use crate::math::{Mat3, Real};
use crate::tensor_mass::ElasticModel;

impl Tools {
    /// The tools `decls` over `model` with the paper's projection law,
    /// touching nothing.
    pub fn new(decls: &[ToolDecl], model: &ElasticModel) -> Self {
        Self::build(
            decls,
            model,
            ContactLaw::Projection,
            &ContactConfig::default(),
        )
    }

    /// The tools `decls` on `sim` as `config` says: the penalty law
    /// (unless the scene asks for projection or the backend cannot
    /// integrate it), with `sim`'s stable step made to include the contact
    /// springs (more sub-steps). The scene holds `held` (fixed or
    /// prescribed): no tool takes them ([`Tools::reserve`]), and the
    /// contact stiffness sees them fixed.
    pub fn with_config<B: Backend + ?Sized>(
        decls: &[ToolDecl],
        sim: &mut B,
        config: &ContactConfig,
        held: &[VertexId],
    ) -> Result<Self, ContactError> {
        for (key, value) in [
            ("stiffness_factor", config.stiffness_factor),
            ("point_spacing", config.point_spacing),
            ("max_tool_speed_m_s", config.max_tool_speed_m_s),
            ("max_tool_accel_m_s2", config.max_tool_accel_m_s2),
            ("entry_speed_m_s", config.entry_speed_m_s),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(ContactError::BadConstant {
                    key,
                    value,
                    range: "positive",
                });
            }
        }
        if !(config.damping_s_per_m.is_finite() && config.damping_s_per_m >= 0.0) {
            return Err(ContactError::BadConstant {
                key: "damping_s_per_m",
                value: config.damping_s_per_m,
                range: "zero or positive",
            });
        }
        for d in decls {
            d.friction
                .check()
                .map_err(|why| ContactError::BadFriction {
                    tool: d.name.clone(),
                    why,
                })?;
        }
        let caps = sim.capabilities();
        let law = match config.law {
            Some(ContactLaw::Penalty) if !caps.integrates_contact => {
                return Err(ContactError::PenaltyUnsupported { backend: caps.name });
            }
            Some(law) => law,
            // Every backend that can integrate the penalty law takes it:
            // on the static backend (precomputed) it is a Newton solve a
            // step, several times the projection law's cost, but the
            // projection law over-states the force on fine meshes and
            // misses the organ between vertices on coarse ones (docs/design/contact.md,
            // the two laws against an analytic indentation); `law = "projection"` keeps the cheap one.
            None if caps.integrates_contact && !decls.is_empty() => ContactLaw::Penalty,
            None => ContactLaw::Projection,
        };
        // The penalty law's springs only (the projection law reads no factor).
        if law == ContactLaw::Penalty
            && config.implicit_springs
            && config.stiffness_factor > MAX_IMPLICIT_STIFFNESS_FACTOR
        {
            return Err(ContactError::TooStiffForImplicitSprings {
                value: config.stiffness_factor,
                max: MAX_IMPLICIT_STIFFNESS_FACTOR,
            });
        }
        if let Some(d) = decls.iter().find(|d| d.friction.is_active()) {
            if law == ContactLaw::Projection {
                return Err(ContactError::FrictionUnsupported {
                    tool: d.name.clone(),
                    backend: caps.name,
                });
            }
            if !caps.dynamic {
                return Err(ContactError::FrictionStatic {
                    tool: d.name.clone(),
                    backend: caps.name,
                });
            }
        }
        let mut tools = Self::build(decls, sim.model(), law, config);
        if law == ContactLaw::Penalty {
            let sampler = Sampler::new(sim.model(), config.stiffness_factor, config.point_spacing);

            tools.crossing = Some(Crossing::new(
                sim.model(),
                sampler.max_edge_m(),
                config.point_spacing,
            ));
            tools.sampler = Some(sampler);
            tools.stiffness = Some(ContactStiffness::new(sim.model(), held));
        }
        if let Some(r) = config.corotational_radius_m {
            if !(r.is_finite() && r > 0.0) {
                return Err(ContactError::BadConstant {
                    key: "corotational_radius_m",
                    value: r,
                    range: "positive",
                });
            }
            if !caps.corotational_region {
                return Err(ContactError::CorotationalRegionUnsupported { backend: caps.name });
            }
            tools.follow = Some(crate::contact::follow_region::FollowRegion::new(
                r,
                decls.len(),
                sim.model(),
            ));
        }
        for v in held {
            tools.reserve(*v);
        }
        Ok(tools)
    }

    fn build(
        decls: &[ToolDecl],
        model: &ElasticModel,
        law: ContactLaw,
        config: &ContactConfig,
    ) -> Self {
        let tools: Vec<ToolContact> = decls
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let proxy = Proxy::new(
                    config.max_tool_speed_m_s,
                    config.max_tool_accel_m_s2,
                    config.entry_speed_m_s,
                );
                ToolContact::new(d, i, model, law, proxy)
            })
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
            law,
            field: ContactField::new(decls.len(), config.damping_s_per_m)
                .with_friction(&decls.iter().map(|d| d.friction).collect::<Vec<_>>())
                .with_implicit_springs(config.implicit_springs),
            sampler: None,
            crossing: None,
            stiffness: None,
            last_inputs: vec![None; decls.len()],
            stiffness_n_per_m: vec![Mat3::ZERO; decls.len()],
            mark: vec![false; model.vertex_count()],
            spring_n_per_m: vec![0.0; model.vertex_count()],
            sprung: Vec::new(),
            local: LocalScratch {
                field: ContactField::new(decls.len(), 0.0),
                ..Default::default()
            },
            steps: 0,
            deferred_hand_over: false,
            hand_over_due_s: 0.0,
            follow: None,
        }
    }
}
