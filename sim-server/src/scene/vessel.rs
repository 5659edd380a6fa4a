//! `[[vessel]]`s: tetrahedra made transversally isotropic along a vessel
//! (the paper's figure 12: the fibre is the vessel's direction). A vessel
//! is given as exactly one of
//! - `points_m` (a polyline in the scene's frame) or `file` (a centreline
//!   exported with the organ: CSV, Slicer's `.fcsv`, legacy VTK lines; in
//!   the organ's units and placed as the organ is), with `radius_m`: every
//!   tetrahedron a segment crosses, or whose centroid is within the radius,
//!   takes the nearest segment's direction;
//! - `select` (the tetrahedra of a region, e.g. the physical tag
//!   `sim-server mesh` gives an inner vessel surface): each takes the
//!   region's local axis, the principal direction of the region's
//!   tetrahedra within three vessel radii of it (a tube is longest along its
//!   axis), the radius being 2 V / A of the region (a cylinder's).

use super::assign::{Defaults, too_many};
use super::materials::resolve;
use super::ranges;
use super::report::{SceneReport, positive};
use super::select::{Region, Tags, distance_to_segment, segment_crosses_tet};
use super::spec::SceneSpec;
use super::{SceneError, SceneSource};
use crate::ids::TetId;
use crate::material_map::TetMaterials;
use crate::math::{Real, Vec3};
use crate::mesh::TetMesh;
use crate::mesh::quality::face_key;
use crate::mesh::tetrahedralize::MM_DETECT_EXTENT;
use std::collections::HashMap;

/// Below this mean ratio of the first to the second principal extent, a
/// selected region is not a tube and its fibres are said to be unreliable.
const TUBE_ELONGATION: Real = 1.5;

/// The scene's `[[vessel]]`s, in order, after its regions.
pub(super) fn vessels(
    src: &SceneSource,
    spec: &SceneSpec,
    mesh: &TetMesh,
    physical: &Tags,
    defaults: &Defaults,
    mats: &mut TetMaterials,
    report: &mut SceneReport,
) -> Result<(), SceneError> {
    for (i, vessel) in spec.vessel.iter().enumerate() {
        let v = vessel.get_ref();
        let name = v
            .name
            .clone()
            .unwrap_or_else(|| format!("vessel {}", i + 1));
        let what = format!("[[vessel]] {name:?}");
        let fibres = match (&v.points_m, &v.file, &v.select) {
            (Some(p), None, None) => {
                let points: Vec<Vec3> = p.get_ref().iter().map(|q| Vec3::from_array(*q)).collect();
                let segments = segments(src, p.span(), &[points], &what)?;
                along_segments(src, v, &segments, mesh, &what, report)?
            }
            (None, Some(f), None) => {
                let lines = centreline(src, spec, v, f, &what, report)?;
                let segments = segments(src, f.span(), &lines, &what)?;
                along_segments(src, v, &segments, mesh, &what, report)?
            }
            (None, None, Some(sel)) => {
                if let Some(r) = &v.radius_m {
                    return Err(src.error(
                        r.span(),
                        format!("{what}: `radius_m` sizes a polyline; a selected region is its own extent"),
                    ));
                }
                let tets = Region::for_tets(src, sel)?.tets(mesh, physical);
                if tets.is_empty() {
                    return Err(src.error(sel.span(), format!("{what} selects no tetrahedron")));
                }
                let (fibres, elongation) = region_axes(mesh, &tets);
                if elongation < TUBE_ELONGATION {
                    report.warnings.push(format!(
                        "{what}: its tetrahedra do not form a tube (principal extents {elongation:.1}:1 around each, under {TUBE_ELONGATION}:1): the fibre directions are unreliable; give the centreline (`file`) instead"
                    ));
                }
                fibres
            }
            _ => {
                return Err(src.error(
                    vessel.span(),
                    format!("{what}: give exactly one of `points_m`, `file` (a centreline) or `select` (its tetrahedra)"),
                ));
            }
        };
        let keys = v.material_keys().over(defaults.keys);
        let material = resolve(src, &keys, true, vessel.span(), &what, report)?;
        let id = mats
            .add(material)
            .map_err(|_| too_many(src, vessel.span()))?;
        for &(t, dir) in &fibres {
            mats.assign(t, id).expect("tet in range");
            mats.set_fiber(t, dir)
                .map_err(|e| src.error(vessel.span(), format!("{what}: {e}")))?;
        }
        report.vessels.push((name, fibres.len()));
    }
    Ok(())
}

/// The polylines' segments, each of finite non-zero length.
fn segments(
    src: &SceneSource,
    span: std::ops::Range<usize>,
    lines: &[Vec<Vec3>],
    what: &str,
) -> Result<Vec<[Vec3; 2]>, SceneError> {
    // A segment's length must itself be finite and non-zero (points of
    // 1e300 m are finite, their distance is not).
    let usable = |w: &[Vec3]| {
        let len = (w[1] - w[0]).length();
        len.is_finite() && len > 0.0
    };
    if lines
        .iter()
        .any(|l| l.len() < 2 || l.iter().any(|p| !p.is_finite()) || !l.windows(2).all(usable))
    {
        return Err(src.error(
            span,
            format!("{what}: the polyline needs at least two distinct finite points per segment, each segment of finite length"),
        ));
    }
    Ok(lines
        .iter()
        .flat_map(|l| l.windows(2).map(|w| [w[0], w[1]]))
        .collect())
}

/// The tetrahedra a segment crosses or whose centroid lies within
/// `radius_m`, each with the nearest such segment's direction.
fn along_segments(
    src: &SceneSource,
    v: &super::spec::VesselSpec,
    segments: &[[Vec3; 2]],
    mesh: &TetMesh,
    what: &str,
    report: &mut SceneReport,
) -> Result<Vec<(TetId, Vec3)>, SceneError> {
    let Some(r) = &v.radius_m else {
        return Err(src.error(
            v.points_m
                .as_ref()
                .map(|p| p.span())
                .or(v.file.as_ref().map(|f| f.span()))
                .unwrap_or_default(),
            format!("{what}: a polyline needs `radius_m`"),
        ));
    };
    let radius = positive(src, r, &format!("{what} radius_m"))?;
    ranges::VESSEL_RADIUS_M.check(src, r, what, report)?;
    let mut out = Vec::new();
    for t in (0..mesh.tet_count()).map(TetId::from) {
        let p = mesh.tet_points(t);
        let centroid = (p[0] + p[1] + p[2] + p[3]) / 4.0;
        let best = segments
            .iter()
            .filter(|w| {
                segment_crosses_tet(w[0], w[1], p)
                    || distance_to_segment(centroid, w[0], w[1]) <= radius
            })
            .min_by(|a, b| {
                distance_to_segment(centroid, a[0], a[1])
                    .total_cmp(&distance_to_segment(centroid, b[0], b[1]))
            });
        if let Some(w) = best {
            out.push((t, w[1] - w[0]));
        }
    }
    if out.is_empty() {
        let span = v
            .points_m
            .as_ref()
            .map(|p| p.span())
            .or(v.file.as_ref().map(|f| f.span()))
            .unwrap_or_default();
        let hint = if v.file.is_some() {
            " (are its units and placement the organ's? `units`, `[mesh] rotate_deg`/`translate_m`)"
        } else {
            ""
        };
        return Err(src.error(span, format!("{what} crosses no tetrahedron{hint}")));
    }
    Ok(out)
}

/// A centreline file's polylines in the scene's frame: scaled to metres
/// (the vessel's `units`, else the `[mesh]`'s, else millimetres when the
/// points span more than 5 "m") and placed as the organ is.
fn centreline(
    src: &SceneSource,
    spec: &SceneSpec,
    v: &super::spec::VesselSpec,
    file: &toml::Spanned<String>,
    what: &str,
    report: &mut SceneReport,
) -> Result<Vec<Vec<Vec3>>, SceneError> {
    let path = src.dir.join(file.get_ref());
    let mut lines =
        super::centreline::read_polylines(&path).map_err(|e| src.error(file.span(), e))?;
    let m = spec.mesh.get_ref();
    let factor = |u: &toml::Spanned<String>| match u.get_ref().as_str() {
        "m" => Ok(1.0),
        "cm" => Ok(0.01),
        "mm" => Ok(0.001),
        other => Err(src.error(
            u.span(),
            format!("units must be \"m\", \"cm\" or \"mm\", got {other:?}"),
        )),
    };
    let scale = match (&v.units, &m.units, &m.scale) {
        (Some(u), _, _) | (None, Some(u), _) => factor(u)?,
        (None, None, Some(s)) => *s.get_ref(),
        (None, None, None) => {
            let (lo, hi) = lines.iter().flatten().fold(
                (Vec3::splat(Real::INFINITY), Vec3::splat(Real::NEG_INFINITY)),
                |(lo, hi), p| (lo.min(*p), hi.max(*p)),
            );
            if (hi - lo).max_element() > MM_DETECT_EXTENT {
                report.warnings.push(format!(
                    "{what}: {} spans more than {MM_DETECT_EXTENT} \"m\": read as millimetres (set `units` to say)",
                    file.get_ref()
                ));
                1e-3
            } else {
                1.0
            }
        }
    };
    let place = super::mesh_load::placement(src, m)?;
    for p in lines.iter_mut().flatten() {
        *p *= scale;
        if let Some((rot, shift)) = place {
            *p = rot * *p + shift;
        }
    }
    Ok(lines)
}

/// Each of `tets` with the local axis of the region they form, and the
/// mean elongation (first to second principal extent) around them.
fn region_axes(mesh: &TetMesh, tets: &[TetId]) -> (Vec<(TetId, Vec3)>, Real) {
    let centroid = |t: TetId| {
        let p = mesh.tet_points(t);
        (p[0] + p[1] + p[2] + p[3]) / 4.0
    };
    // The region's boundary area: faces of one region tetrahedron only.
    let mut faces: HashMap<[u32; 3], u8> = HashMap::with_capacity(tets.len() * 3);
    for &t in tets {
        let tet = mesh.tets()[t.idx()].map(|v| v.0);
        for k in 0..4 {
            *faces.entry(face_key(&tet, k)).or_default() += 1;
        }
    }
    let pos = mesh.positions_m();
    let area: Real = faces
        .iter()
        .filter(|(_, n)| **n == 1)
        .map(|(k, _)| {
            let [a, b, c] = k.map(|v| pos[v as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .sum();
    let volume: Real = tets.iter().map(|&t| mesh.tet_volume_m3(t)).sum();
    let cell = {
        let mut c: Vec<Real> = tets
            .iter()
            .map(|&t| (6.0 * mesh.tet_volume_m3(t)).cbrt())
            .collect();
        c.sort_by(Real::total_cmp);
        c[c.len() / 2]
    };
    let radius = if area > 0.0 {
        2.0 * volume / area
    } else {
        cell
    };
    // Three radii: a ball that wide inside a tube is 3.5 times longer
    // (in its standard deviation) along the axis than across.
    let reach = (3.0 * radius).max(1.5 * cell);
    let points: Vec<(Vec3, Real)> = tets
        .iter()
        .map(|&t| (centroid(t), mesh.tet_volume_m3(t)))
        .collect();
    // A grid of `reach` cells: each tetrahedron looks at 27 cells.
    let key = |p: Vec3| (p / reach).floor().as_i64vec3().to_array();
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (i, (p, _)) in points.iter().enumerate() {
        grid.entry(key(*p)).or_default().push(i);
    }
    let whole = principal(points.iter().copied());
    // The weighted centroids within `r` (a multiple of `reach`) of `c`.
    let near = |c: Vec3, r: Real| {
        let k = key(c);
        let span = (r / reach).ceil() as i64;
        let grid = &grid;
        let points = &points;
        (-span..=span)
            .flat_map(move |x| {
                (-span..=span)
                    .flat_map(move |y| (-span..=span).map(move |z| [k[0] + x, k[1] + y, k[2] + z]))
            })
            .filter_map(move |cell| grid.get(&cell))
            .flatten()
            .map(move |&j| points[j])
            .filter(move |(p, _)| (*p - c).length() <= r)
    };
    let mut elongation_sum = 0.0;
    let out = tets
        .iter()
        .zip(&points)
        .map(|(&t, (c, _))| {
            // Near a vessel's end the ball holds a stub as wide as long:
            // twice and four times as far, the one most elongated.
            let mut pick: Option<(Vec3, Real)> = None;
            for f in [1.0, 2.0, 4.0] {
                let a = principal(near(*c, f * reach));
                if a.1.is_finite() && pick.is_none_or(|p| a.1 > p.1) {
                    pick = Some(a);
                }
                if a.1.is_finite() && a.1 >= 1.5 {
                    break;
                }
            }
            let (axis, ratio) = pick.unwrap_or(whole);
            elongation_sum += ratio.min(100.0);
            (t, axis)
        })
        .collect();
    (out, elongation_sum / tets.len() as Real)
}

/// The principal axis of weighted points and the ratio of the first to the
/// second principal extent (infinite for fewer than three points).
fn principal(points: impl Iterator<Item = (Vec3, Real)>) -> (Vec3, Real) {
    let pts: Vec<(Vec3, Real)> = points.collect();
    let w: Real = pts.iter().map(|(_, w)| w).sum();
    if pts.len() < 3 || w.is_nan() || w <= 0.0 {
        return (Vec3::X, Real::INFINITY);
    }
    let mean = pts.iter().map(|(p, w)| *p * *w).sum::<Vec3>() / w;
    let mut c = nalgebra::Matrix3::<Real>::zeros();
    for (p, wi) in &pts {
        let d = *p - mean;
        let d = nalgebra::Vector3::new(d.x, d.y, d.z);
        c += d * d.transpose() * *wi;
    }
    let e = nalgebra::SymmetricEigen::new(c);
    let mut order = [0usize, 1, 2];
    order.sort_by(|a, b| e.eigenvalues[*b].total_cmp(&e.eigenvalues[*a]));
    let v = e.eigenvectors.column(order[0]);
    let ratio = (e.eigenvalues[order[0]] / e.eigenvalues[order[1]].max(Real::MIN_POSITIVE)).sqrt();
    (Vec3::new(v[0], v[1], v[2]), ratio)
}
