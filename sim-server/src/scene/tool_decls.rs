//! The scene's `[[tool]]`s: at most the protocol's four, unique names, a fulcrum outside the organ, a
//! positive length, radius and tip no longer than the tool, friction.

use super::ranges;
use super::report::{SceneReport, positive};
use super::spec::SceneSpec;
use super::{SceneError, SceneSource};
use crate::contact::{Friction, ToolDecl};
use crate::math::{Real, Vec3};
use crate::tensor_mass::ElasticModel;
use shared::protocol::MAX_TOOLS;
use toml::Spanned;

/// The `[[tool]]`s of `spec` around `model`, each checked at its own line.
pub(super) fn tool_decls(
    src: &SceneSource,
    spec: &SceneSpec,
    model: &ElasticModel,
    report: &mut SceneReport,
) -> Result<Vec<ToolDecl>, SceneError> {
    let mut tools: Vec<ToolDecl> = Vec::new();
    for (k, tool) in spec.tool.iter().enumerate() {
        let t = tool.get_ref();
        if k == MAX_TOOLS {
            // The protocol carries MAX_TOOLS poses and forces: a fifth tool
            // would be declared and never moved or felt.
            return Err(src.error(
                tool.span(),
                format!(
                    "a scene has at most {MAX_TOOLS} [[tool]]s (the poses and force samples carry {MAX_TOOLS}), this is tool {}",
                    k + 1
                ),
            ));
        }
        let name = t.name.get_ref().clone();
        if name.is_empty() || tools.iter().any(|x| x.name == name) {
            return Err(src.error(
                t.name.span(),
                format!("tool names must be unique and non-empty: {name:?}"),
            ));
        }
        let what = format!("[[tool]] {name:?}");
        let fulcrum = Vec3::from_array(*t.fulcrum_m.get_ref());
        if !fulcrum.is_finite() {
            return Err(src.error(
                t.fulcrum_m.span(),
                format!("{what} fulcrum_m must be finite"),
            ));
        }
        if let Some(tet) = containing_tet(model.mesh(), fulcrum) {
            return Err(src.error(
                t.fulcrum_m.span(),
                format!(
                    "{what} fulcrum_m {:?} is inside the organ (tetrahedron {}): the fulcrum is where the tool enters the body, outside the tissue, and the simulated tool comes in from it",
                    fulcrum.to_array(),
                    tet
                ),
            ));
        }
        let length = positive(src, &t.length_m, &format!("{what} length_m"))?;
        let radius = positive(src, &t.radius_m, &format!("{what} radius_m"))?;
        let tip = positive(src, &t.tip_length_m, &format!("{what} tip_length_m"))?;
        ranges::TOOL_LENGTH_M.check(src, &t.length_m, &what, report)?;
        ranges::TOOL_RADIUS_M.check(src, &t.radius_m, &what, report)?;
        ranges::TOOL_TIP_LENGTH_M.check(src, &t.tip_length_m, &what, report)?;
        if tip > length {
            return Err(src.error(
                t.tip_length_m.span(),
                format!("{what}: tip_length_m ({tip}) exceeds length_m ({length})"),
            ));
        }
        let friction = tool_friction(src, t, &what, report)?;
        // A tool whose tip cannot reach the organ is declared, moved and
        // never felt: a run gave 0 contact steps and no word.
        if let Some(nearest) = nearest_distance_m(model.mesh(), fulcrum)
            && nearest > length + radius
        {
            let (line, column) = src.line_col(t.fulcrum_m.span().start);
            report.warnings.push(format!(
                "{}:{line}:{column}: {what} cannot reach the organ: its tip reaches {:.1} mm from fulcrum_m (length_m {:.1} mm, radius {:.1} mm), the organ's nearest vertex is {:.1} mm from it; move fulcrum_m closer or lengthen length_m",
                src.name,
                (length + radius) * 1e3,
                length * 1e3,
                radius * 1e3,
                nearest * 1e3
            ));
        }
        tools.push(ToolDecl {
            name,
            kind: t.kind,
            fulcrum_m: fulcrum.to_array(),
            length_m: length,
            radius_m: radius,
            tip_length_m: tip,
            friction,
        });
    }
    Ok(tools)
}

/// `friction_static` / `friction_dynamic` of a `[[tool]]`: either alone
/// sets both; each is checked at its own line.
fn tool_friction(
    src: &SceneSource,
    t: &super::spec::ToolSpec,
    what: &str,
    report: &mut SceneReport,
) -> Result<Friction, SceneError> {
    let coefficient = |v: Option<&Spanned<Real>>, key: &str| match v {
        None => Ok(None),
        Some(v) if v.get_ref().is_finite() && *v.get_ref() >= 0.0 => Ok(Some(*v.get_ref())),
        Some(v) => Err(src.error(
            v.span(),
            format!(
                "{what} {key} must be a finite number >= 0, got {}",
                v.get_ref()
            ),
        )),
    };
    let s = coefficient(t.friction_static.as_ref(), "friction_static")?;
    let d = coefficient(t.friction_dynamic.as_ref(), "friction_dynamic")?;
    for (v, key) in [
        (&t.friction_static, "friction_static"),
        (&t.friction_dynamic, "friction_dynamic"),
    ] {
        if let Some(v) = v {
            let range = ranges::KeyRange {
                key,
                ..ranges::FRICTION
            };
            range.check(src, v, what, report)?;
        }
    }
    let friction = Friction {
        static_coefficient: s.or(d).unwrap_or(0.0),
        dynamic_coefficient: d.or(s).unwrap_or(0.0),
    };
    match (friction.check(), &t.friction_dynamic) {
        (Err(why), Some(d)) => Err(src.error(d.span(), format!("{what} {why}"))),
        _ => Ok(friction),
    }
}

/// The distance from `p` to the nearest vertex of `mesh` that a
/// tetrahedron uses (m), if it has one.
fn nearest_distance_m(mesh: &crate::mesh::TetMesh, p: Vec3) -> Option<Real> {
    let x = mesh.positions_m();
    (mesh.tets().iter().flatten())
        .map(|v| x[v.idx()].distance(p))
        .min_by(Real::total_cmp)
}

/// The first tetrahedron of `mesh` containing `p` (all four barycentric
/// coordinates, signed volumes with `p` in place of a vertex over the
/// tetrahedron's, at least -1e-9), if any.
fn containing_tet(mesh: &crate::mesh::TetMesh, p: Vec3) -> Option<usize> {
    let x = mesh.positions_m();
    let vol = |a: Vec3, b: Vec3, c: Vec3, d: Vec3| (b - a).cross(c - a).dot(d - a);
    mesh.tets().iter().position(|t| {
        let [a, b, c, d] = t.map(|v| x[v.idx()]);
        let v = vol(a, b, c, d);
        if v == 0.0 {
            return false;
        }
        [
            vol(p, b, c, d),
            vol(a, p, c, d),
            vol(a, b, p, d),
            vol(a, b, c, p),
        ]
        .iter()
        .all(|w| w / v >= -1e-9)
    })
}
