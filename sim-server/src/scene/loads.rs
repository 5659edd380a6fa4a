//! The scene's `[[load]]`s: prescribed displacements (`displacement_m`, or a
//! rigid `rotate` of the selection) and forces (`force_n` shared by the
//! selected vertices, `traction_pa` over the surface triangles they close).

use super::ranges::{self, KeyRange};
use super::report::SceneReport;
use super::select::{Region, Tags};
use super::spec::SceneSpec;
use super::{SceneError, SceneSource};
use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::tensor_mass::ElasticModel;

/// The scene's loads on `model`: each prescribed vertex with its
/// displacement (m), and the force on every vertex (N; empty when the scene
/// loads none).
pub(super) type Loads = (Vec<(VertexId, Vec3)>, Vec<Vec3>);

/// The `[[load]]`s of `spec` on `model`, each checked at its own line.
pub(super) fn loads(
    src: &SceneSource,
    spec: &SceneSpec,
    model: &ElasticModel,
    physical: &Tags,
    report: &mut SceneReport,
) -> Result<Loads, SceneError> {
    let mesh = model.mesh();
    let n = mesh.vertex_count();
    let mut prescribed = Vec::new();
    let mut loads_n: Vec<Vec3> = Vec::new();
    for load in &spec.load {
        let l = load.get_ref();
        let given = l.displacement_m.is_some() as u8
            + l.force_n.is_some() as u8
            + l.traction_pa.is_some() as u8
            + l.rotate.is_some() as u8;
        if given != 1 {
            return Err(src.error(
                load.span(),
                "[[load]] needs exactly one of displacement_m, force_n, traction_pa, rotate",
            ));
        }
        let vs = Region::new(src, &l.select)?.vertices(mesh, physical);
        if vs.is_empty() {
            return Err(src.error(l.select.span(), "[[load]] selects no vertex"));
        }
        // Finite, and its length within the key's range.
        let mut vector = |v: &toml::Spanned<[Real; 3]>, range: KeyRange| {
            let x = Vec3::from_array(*v.get_ref());
            if !x.is_finite() {
                return Err(src.error(v.span(), "load values must be finite"));
            }
            let range = KeyRange {
                key: match range.key {
                    "force_n" => "force_n (its length)",
                    "traction_pa" => "traction_pa (its length)",
                    _ => "displacement_m (its length)",
                },
                ..range
            };
            range.check_at(src, v.span(), x.length(), "[[load]]", report)?;
            Ok(x)
        };
        if let Some(d) = &l.displacement_m {
            let d = vector(d, ranges::LOAD_DISPLACEMENT_M)?;
            prescribed.extend(vs.iter().map(|v| (*v, d)));
            continue;
        }
        if let Some(r) = &l.rotate {
            let (turn, origin) = rotation(src, r.get_ref())?;
            ranges::LOAD_ANGLE_DEG.check(src, &r.get_ref().angle_deg, "[[load]] rotate", report)?;
            let p = mesh.positions_m();
            prescribed.extend(vs.iter().map(|v| {
                let x = p[v.idx()];
                (*v, turn * (x - origin) + origin - x)
            }));
            continue;
        }
        if loads_n.is_empty() {
            loads_n = vec![Vec3::ZERO; n];
        }
        if let Some(f) = &l.force_n {
            let each = vector(f, ranges::LOAD_FORCE_N)? / vs.len() as Real;
            for v in &vs {
                loads_n[v.idx()] += each;
            }
        } else if let Some(t) = &l.traction_pa {
            let t = vector(t, ranges::LOAD_TRACTION_PA)?;
            let mut selected = vec![false; n];
            for v in &vs {
                selected[v.idx()] = true;
            }
            let p = mesh.positions_m();
            let mut faces = 0;
            for [a, b, c] in model.topology().surface_triangles(mesh) {
                if selected[a.idx()] && selected[b.idx()] && selected[c.idx()] {
                    let area = 0.5
                        * (p[b.idx()] - p[a.idx()])
                            .cross(p[c.idx()] - p[a.idx()])
                            .length();
                    for v in [a, b, c] {
                        loads_n[v.idx()] += t * (area / 3.0);
                    }
                    faces += 1;
                }
            }
            if faces == 0 {
                return Err(src.error(l.select.span(), "[[load]] traction_pa: no surface triangle has all three vertices in the selection"));
            }
        }
    }
    Ok((prescribed, loads_n))
}

/// The rotation and the point it turns about of a `rotate` load.
fn rotation(
    src: &SceneSource,
    r: &super::spec::RotateSpec,
) -> Result<(crate::math::Mat3, Vec3), SceneError> {
    let axis = Vec3::from_array(*r.axis.get_ref());
    let length = axis.length();
    if !(length.is_finite() && length > 0.0) {
        return Err(src.error(
            r.axis.span(),
            "[[load]] rotate axis must be a finite non-zero vector",
        ));
    }
    let origin = Vec3::from_array(*r.origin_m.get_ref());
    if !origin.is_finite() {
        return Err(src.error(r.origin_m.span(), "[[load]] rotate origin_m must be finite"));
    }
    let angle = *r.angle_deg.get_ref();
    if !angle.is_finite() {
        return Err(src.error(
            r.angle_deg.span(),
            "[[load]] rotate angle_deg must be finite",
        ));
    }
    Ok((
        crate::math::Mat3::from_axis_angle(axis / length, angle.to_radians()),
        origin,
    ))
}
