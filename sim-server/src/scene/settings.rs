//! What a scene says about running it: the `[sim]` step and rate, the
//! `[contact]` law and its limits, and whether the chosen backend can run
//! the scene's material models.

use super::ranges::{self, KeyRange};
use super::report::{SceneReport, positive};
use super::spec::{
    BackendName, BoundName, DtPolicyName, MaterialModelName, PrecisionName, SceneSpec,
};
use super::{SceneError, SceneSource};
use crate::ids::TetId;
use crate::math::Real;
use crate::tensor_mass::{BoundMethod, DtPolicy, ElasticModel};
use toml::Spanned;

/// Simulation settings with defaults applied.
#[derive(Clone, Debug)]
pub struct SimSettings {
    /// Requested step (s); `None` = 90% of the stable step.
    pub dt_s: Option<Real>,
    /// Target rate (Hz) for real-time runs.
    pub rate_hz: Option<Real>,
    /// Worker threads.
    pub threads: usize,
    /// f32 (true) or f64 tensor storage.
    pub single_precision: bool,
    /// Refuse or sub-step.
    pub policy: DtPolicy,
    /// Which bound.
    pub bound: BoundMethod,
    /// Which backend (default tensor-mass).
    pub backend: BackendName,
    /// Multirate stepping (`[simulation] multirate`, tensor-mass only).
    pub multirate: bool,
}

/// The longest step a scene or `--dt-s` may ask for (s): longer, a live
/// run would sleep through its stop signal and its duration.
pub const MAX_DT_S: Real = 0.1;
/// The shortest (s): below it the integrators' coefficients (m / dt^2)
/// overflow long before any real time could be kept.
pub const MIN_DT_S: Real = 1e-6;

/// `dt_s` if it is a step a scene or `--dt-s` may ask for, else the
/// message naming `what` and the bounds.
pub fn check_step(what: &str, dt_s: Real) -> Result<Real, String> {
    if (MIN_DT_S..=MAX_DT_S).contains(&dt_s) {
        Ok(dt_s)
    } else {
        Err(format!(
            "{what} must be a step in seconds, at least {MIN_DT_S:e} and at most {MAX_DT_S}, got {dt_s}"
        ))
    }
}

/// Why a scene cannot run on the hybrid backend.
pub const HYBRID_NEEDS_SPLIT: &str = "the hybrid backend needs a [hybrid] section naming its tensor-mass (cuttable) part, e.g. [hybrid] select = { sphere_m = [x, y, z, r] }; the rest is precomputed";

pub(super) fn contact_config(
    src: &SceneSource,
    spec: &SceneSpec,
    report: &mut SceneReport,
) -> Result<crate::contact::ContactConfig, SceneError> {
    use crate::contact::{ContactConfig, ContactLaw};
    use crate::scene::spec::ContactLawName;
    let mut c = ContactConfig::default();
    let Some(section) = &spec.contact else {
        return Ok(c);
    };
    let s = section.get_ref();
    c.law = s.law.as_ref().map(|l| match l.get_ref() {
        ContactLawName::Penalty => ContactLaw::Penalty,
        ContactLawName::Projection => ContactLaw::Projection,
    });
    // Positive, then within its range ([`ranges`]).
    let mut pos = |v: &Option<toml::Spanned<Real>>, range: KeyRange, default: Real| {
        v.as_ref().map_or(Ok(default), |x| {
            positive(src, x, &format!("[contact] {}", range.key))?;
            range.check(src, x, "[contact]", report)
        })
    };
    c.stiffness_factor = pos(
        &s.stiffness_factor,
        ranges::STIFFNESS_FACTOR,
        c.stiffness_factor,
    )?;
    c.point_spacing = pos(&s.point_spacing, ranges::POINT_SPACING, c.point_spacing)?;
    c.max_tool_speed_m_s = pos(
        &s.max_tool_speed_m_s,
        ranges::MAX_TOOL_SPEED_M_S,
        c.max_tool_speed_m_s,
    )?;
    c.max_tool_accel_m_s2 = pos(
        &s.max_tool_accel_m_s2,
        ranges::MAX_TOOL_ACCEL_M_S2,
        c.max_tool_accel_m_s2,
    )?;
    c.entry_speed_m_s = pos(
        &s.entry_speed_m_s,
        ranges::ENTRY_SPEED_M_S,
        c.entry_speed_m_s,
    )?;
    if s.corotational_radius_m.is_some() {
        c.corotational_radius_m = Some(pos(
            &s.corotational_radius_m,
            ranges::COROTATIONAL_RADIUS_M,
            0.0,
        )?);
    }
    if let Some(springs) = &s.springs {
        c.implicit_springs = *springs.get_ref() == crate::scene::spec::SpringsName::Implicit;
    }
    // The penalty law's springs only: the projection law (asked for, or
    // the default off the tensor-mass backend) reads no factor.
    let backend = spec
        .simulation
        .as_ref()
        .and_then(|sim| sim.get_ref().backend.as_ref().map(|b| *b.get_ref()))
        .unwrap_or(BackendName::TensorMass);
    if let Some(r) = &s.corotational_radius_m
        && backend != BackendName::TensorMass
    {
        // The library's refusal, at the key's line.
        let refusal = crate::contact::ContactError::CorotationalRegionUnsupported {
            backend: backend.as_str(),
        };
        return Err(src.error(r.span(), refusal.to_string()));
    }
    let penalty = match c.law {
        Some(law) => law == ContactLaw::Penalty,
        None => backend == BackendName::TensorMass,
    };
    if penalty
        && c.implicit_springs
        && c.stiffness_factor > crate::contact::MAX_IMPLICIT_STIFFNESS_FACTOR
    {
        let span = s
            .stiffness_factor
            .as_ref()
            .map_or(section.span(), |x| x.span());
        // The library's refusal, at the key's line.
        let refusal = crate::contact::ContactError::TooStiffForImplicitSprings {
            value: c.stiffness_factor,
            max: crate::contact::MAX_IMPLICIT_STIFFNESS_FACTOR,
        };
        return Err(src.error(span, refusal.to_string()));
    }
    if let Some(d) = &s.damping_s_per_m {
        let x = *d.get_ref();
        if !(x.is_finite() && x >= 0.0) {
            return Err(src.error(
                d.span(),
                format!("[contact] damping_s_per_m must be a finite number >= 0, got {x}"),
            ));
        }
        c.damping_s_per_m = ranges::CONTACT_DAMPING_S_PER_M.check(src, d, "[contact]", report)?;
    }
    Ok(c)
}

/// A scene whose backend cannot run its material models is refused at the
/// first nonlinear `model` key, naming the backend's reason.
pub(super) fn backend_runs_models(
    src: &SceneSource,
    spec: &SceneSpec,
    model: &ElasticModel,
    backend: BackendName,
    hybrid_tets: Option<&[TetId]>,
) -> Result<(), SceneError> {
    let refusal = match backend {
        BackendName::TensorMass => return Ok(()),
        BackendName::Implicit => crate::backend::Implicit::check_model(model),
        BackendName::Precomputed => crate::backend::Precomputed::check_model(model),
        BackendName::Hybrid => {
            let mut in_tm = vec![false; model.mesh().tet_count()];
            for t in hybrid_tets.unwrap_or(&[]) {
                in_tm[t.idx()] = true;
            }
            crate::backend::Hybrid::check_model(model, |t| in_tm[t.idx()])
        }
    };
    let Err(e) = refusal else {
        return Ok(());
    };
    let nonlinear = |m: &Option<Spanned<MaterialModelName>>| {
        m.as_ref()
            .filter(|m| *m.get_ref() != MaterialModelName::Linear)
            .map(Spanned::span)
    };
    let span = nonlinear(&spec.material.get_ref().model)
        .or_else(|| {
            spec.region
                .iter()
                .find_map(|r| nonlinear(&r.get_ref().model))
        })
        .or_else(|| {
            spec.vessel
                .iter()
                .find_map(|v| nonlinear(&v.get_ref().model))
        })
        .unwrap_or(spec.material.span());
    Err(src.error(span, e.to_string()))
}

pub(super) fn settings(src: &SceneSource, spec: &SceneSpec) -> Result<SimSettings, SceneError> {
    let mut s = SimSettings {
        dt_s: None,
        rate_hz: None,
        threads: 1,
        single_precision: true,
        policy: DtPolicy::Substep,
        bound: BoundMethod::Element,
        backend: BackendName::TensorMass,
        multirate: false,
    };
    let Some(sim) = &spec.simulation else {
        return Ok(s);
    };
    let sim = sim.get_ref();
    if let Some(b) = &sim.backend {
        if *b.get_ref() == BackendName::Hybrid && spec.hybrid.is_none() {
            return Err(src.error(b.span(), HYBRID_NEEDS_SPLIT));
        }
        s.backend = *b.get_ref();
    }
    s.dt_s = sim
        .dt_s
        .as_ref()
        .map(|d| {
            // The bounds `--dt-s` has.
            check_step("[simulation] dt_s", positive(src, d, "[simulation] dt_s")?)
                .map_err(|e| src.error(d.span(), e))
        })
        .transpose()?;
    s.rate_hz = sim
        .rate_hz
        .as_ref()
        .map(|r| match positive(src, r, "[simulation] rate_hz")? {
            // One step of the rate within the step's bounds.
            hz if (1.0 / MAX_DT_S..=1.0 / MIN_DT_S).contains(&hz) => Ok(hz),
            hz => Err(src.error(
                r.span(),
                format!(
                    "[simulation] rate_hz must be at least {} and at most {:e} (a step of {MAX_DT_S} s to {MIN_DT_S:e} s), got {hz}",
                    1.0 / MAX_DT_S,
                    1.0 / MIN_DT_S
                ),
            )),
        })
        .transpose()?;
    // The rate sets the step where the scene gives none (dt_s wins).
    if s.dt_s.is_none() {
        s.dt_s = s.rate_hz.map(|hz| 1.0 / hz);
    }
    if let Some(t) = &sim.threads {
        let most = crate::tensor_mass::explicit::MAX_THREADS;
        if *t.get_ref() == 0 || *t.get_ref() > most {
            return Err(src.error(
                t.span(),
                format!(
                    "[simulation] threads must be at least 1 and at most {most}, got {}",
                    t.get_ref()
                ),
            ));
        }
        s.threads = *t.get_ref();
    }
    s.single_precision = sim.precision.unwrap_or(PrecisionName::F32) == PrecisionName::F32;
    s.policy = match sim.dt_policy.unwrap_or(DtPolicyName::Substep) {
        DtPolicyName::Refuse => DtPolicy::Refuse,
        DtPolicyName::Substep => DtPolicy::Substep,
        DtPolicyName::Unchecked => DtPolicy::Unchecked,
    };
    s.bound = match sim.bound.unwrap_or(BoundName::Element) {
        BoundName::Element => BoundMethod::Element,
        BoundName::PowerIteration => BoundMethod::PowerIteration,
    };
    if let Some(m) = &sim.multirate {
        s.multirate = *m.get_ref();
        if s.multirate && s.backend != BackendName::TensorMass {
            return Err(src.error(
                m.span(),
                "[simulation] multirate sub-steps the explicit tensor-mass step; the other backends do not step explicitly: remove it or use backend = \"tensor-mass\"",
            ));
        }
        if s.multirate && s.policy == DtPolicy::Unchecked {
            return Err(src.error(
                m.span(),
                crate::tensor_mass::MultirateError::Unchecked.to_string(),
            ));
        }
    }
    Ok(s)
}
