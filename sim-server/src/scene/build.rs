//! Building a scene: the mesh, per-tetrahedron materials (default, regions,
//! vessels), the membrane, constraints, loads, tools and settings. Only what
//! the scene declares is built.

use super::materials::resolve;
use super::mesh_load::{LoadedMesh, load_mesh};
use super::select::{Region, distance_to_segment, segment_crosses_tet};
use super::settings::{backend_runs_models, contact_config, settings};
use super::spec::{BackendName, MembraneModelName, SceneSpec};
use super::{SceneError, SceneSource};
use crate::contact::Friction;
use crate::ids::{TetId, VertexId};
use crate::material_map::TetMaterials;
use crate::math::{Real, Vec3};
use crate::membrane::MembraneModel;

use crate::tensor_mass::{BoundMethod, DtPolicy, ElasticModel};
use serde::Serialize;
use toml::Spanned;

pub use crate::contact::ToolDecl;

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
}

/// What the scene made, for `check` and logs.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SceneReport {
    /// Where the mesh came from.
    pub mesh_source: String,
    /// Importer and builder warnings.
    pub warnings: Vec<String>,
    /// (name, tetrahedra, material) per region, in order.
    pub regions: Vec<(String, usize, String)>,
    /// (name, tetrahedra made anisotropic) per vessel.
    pub vessels: Vec<(String, usize)>,
    /// Tetrahedra with an anisotropic material.
    pub anisotropic_tets: usize,
    /// The default material.
    pub default_material: String,
    /// Membrane: alpha and model, if any.
    pub membrane: Option<(Real, String)>,
    /// Vertices held fixed.
    pub fixed_vertices: usize,
    /// Vertices with an imposed displacement.
    pub prescribed_vertices: usize,
    /// Vertices carrying a force.
    pub loaded_vertices: usize,
    /// Tetrahedra of the hybrid's tensor-mass part, when `[hybrid]` is given.
    pub hybrid_tets: Option<usize>,
}

/// A built scene.
pub struct BuiltScene {
    /// The model (mesh, materials, tensors, membrane).
    pub model: ElasticModel,
    /// Fixed vertices.
    pub fixed: Vec<VertexId>,
    /// Imposed displacements (m).
    pub prescribed: Vec<(VertexId, Vec3)>,
    /// Per-vertex forces (N); empty when the scene has no force or traction load.
    pub loads_n: Vec<Vec3>,
    /// Declared tools.
    pub tools: Vec<ToolDecl>,
    /// The hybrid's tensor-mass (cuttable) part, when `[hybrid]` is given.
    pub hybrid_tets: Option<Vec<TetId>>,
    /// Settings.
    pub settings: SimSettings,
    /// Contact law and constants.
    pub contact: crate::contact::ContactConfig,
    /// Summary.
    pub report: SceneReport,
    /// Each vertex's index in the mesh as read or generated, when the
    /// scene renumbered the vertices (RCM, `[mesh] reorder`): outputs write
    /// it as the `original_id` point array. `None`: the file's order kept.
    pub original_vertex_ids: Option<Vec<u32>>,
}

fn describe(m: &crate::material::Material) -> String {
    let l = m.lame();
    let mut s = format!(
        "{}, E {:.4} kPa, nu {:.3}, rho {:.0} kg/m3, damping {:.3} /s",
        m.model().name(),
        l.young_pa() / 1e3,
        l.poisson(),
        m.density_kg_m3(),
        m.damping_per_s()
    );
    if let crate::material::Elasticity::Transverse(t) = m.elasticity() {
        let e = t.engineering();
        s += &format!(
            ", transversally isotropic: delta_lambda {:.4} kPa, delta_mu {:.4} kPa, E_fibre {:.4} kPa, G_fibre {:.4} kPa, terms {}",
            t.delta_lambda_pa() / 1e3,
            t.delta_mu_pa() / 1e3,
            e.young_fiber_pa / 1e3,
            e.shear_fiber_pa / 1e3,
            t.terms()
        );
    }
    s
}

pub(super) fn positive(
    src: &SceneSource,
    v: &toml::Spanned<Real>,
    what: &str,
) -> Result<Real, SceneError> {
    let x = *v.get_ref();
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(src.error(
            v.span(),
            format!("{what} must be a positive finite number, got {x}"),
        ))
    }
}

/// `friction_static` / `friction_dynamic` of a `[[tool]]`: either alone
/// sets both; each is checked at its own line.
fn tool_friction(
    src: &SceneSource,
    t: &super::spec::ToolSpec,
    what: &str,
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
    let friction = Friction {
        static_coefficient: s.or(d).unwrap_or(0.0),
        dynamic_coefficient: d.or(s).unwrap_or(0.0),
    };
    match (friction.check(), &t.friction_dynamic) {
        (Err(why), Some(d)) => Err(src.error(d.span(), format!("{what} {why}"))),
        _ => Ok(friction),
    }
}

fn unit(src: &SceneSource, v: &toml::Spanned<[Real; 3]>, what: &str) -> Result<Vec3, SceneError> {
    let a = Vec3::from_array(*v.get_ref());
    // Scaled by its largest component first: the length of [1e300, 0, 0]
    // overflows and that of [1e-300, 0, 0] underflows, yet both have a
    // direction (found by the scene fuzz test: the first normalised to 0).
    let largest = a.abs().max_element();
    match (a / largest).try_normalize() {
        Some(n) if a.is_finite() && largest > 0.0 => Ok(n),
        _ => Err(src.error(v.span(), format!("{what} must be a finite non-zero vector"))),
    }
}

/// Builds everything `spec` declares.
pub fn build_scene(src: &SceneSource, spec: &SceneSpec) -> Result<BuiltScene, SceneError> {
    let mut report = SceneReport::default();
    let LoadedMesh {
        mesh,
        physical,
        original_ids: original_vertex_ids,
    } = load_mesh(src, spec, &mut report)?;
    let n_tets = mesh.tet_count();

    // Materials: default, then regions in order, then vessels.
    let default_keys = spec.material.get_ref().material_keys();
    let default_fiber = spec
        .material
        .get_ref()
        .fiber
        .as_ref()
        .map(|f| unit(src, f, "[material] fiber"))
        .transpose()?;
    let default = resolve(
        src,
        &default_keys,
        default_fiber.is_some(),
        spec.material.span(),
        "[material]",
    )?;
    report.default_material = describe(&default);
    let mut mats = TetMaterials::uniform(default, n_tets);
    if let Some(f) = default_fiber {
        for t in 0..n_tets {
            mats.set_fiber(TetId::from(t), f)
                .expect("valid tet and fibre");
        }
    }
    let too_many = |span| src.error(span, "too many distinct materials (at most 65535)");
    for (i, region) in spec.region.iter().enumerate() {
        let r = region.get_ref();
        let name = r
            .name
            .clone()
            .unwrap_or_else(|| format!("region {}", i + 1));
        let what = format!("[[region]] {name:?}");
        let fiber = match &r.fiber {
            Some(f) => Some(unit(src, f, &format!("{what} fiber"))?),
            None => default_fiber,
        };
        let keys = r.material_keys().over(default_keys);
        let material = resolve(src, &keys, fiber.is_some(), region.span(), &what)?;
        let tets = Region::for_tets(src, &r.select)?.tets(&mesh, &physical);
        if tets.is_empty() {
            return Err(src.error(r.select.span(), format!("{what} selects no tetrahedron")));
        }
        let id = mats.add(material).map_err(|_| too_many(region.span()))?;
        for &t in &tets {
            mats.assign(t, id).expect("tet in range");
            if let Some(f) = fiber {
                mats.set_fiber(t, f).expect("unit fibre");
            }
        }
        report.regions.push((name, tets.len(), describe(&material)));
    }
    for (i, vessel) in spec.vessel.iter().enumerate() {
        let v = vessel.get_ref();
        let name = v
            .name
            .clone()
            .unwrap_or_else(|| format!("vessel {}", i + 1));
        let what = format!("[[vessel]] {name:?}");
        let points: Vec<Vec3> = v
            .points_m
            .get_ref()
            .iter()
            .map(|p| Vec3::from_array(*p))
            .collect();
        // A segment's length must itself be finite and non-zero (points of
        // 1e300 m are finite, their distance is not).
        let usable = |w: &[Vec3]| {
            let len = (w[1] - w[0]).length();
            len.is_finite() && len > 0.0
        };
        if points.len() < 2
            || points.iter().any(|p| !p.is_finite())
            || !points.windows(2).all(usable)
        {
            return Err(src.error(
                v.points_m.span(),
                format!(
                    "{what}: points_m needs at least two distinct finite points per segment, each segment of finite length"
                ),
            ));
        }
        let radius = positive(src, &v.radius_m, &format!("{what} radius_m"))?;
        let keys = v.material_keys().over(default_keys);
        let material = resolve(src, &keys, true, vessel.span(), &what)?;
        let id = mats.add(material).map_err(|_| too_many(vessel.span()))?;
        let mut count = 0;
        for t in (0..n_tets).map(TetId::from) {
            let p = mesh.tet_points(t);
            let centroid = (p[0] + p[1] + p[2] + p[3]) / 4.0;
            // The closest crossing segment gives the direction.
            let best = points
                .windows(2)
                .filter(|w| {
                    segment_crosses_tet(w[0], w[1], p)
                        || distance_to_segment(centroid, w[0], w[1]) <= radius
                })
                .min_by(|a, b| {
                    distance_to_segment(centroid, a[0], a[1])
                        .total_cmp(&distance_to_segment(centroid, b[0], b[1]))
                });
            if let Some(w) = best {
                mats.assign(t, id).expect("tet in range");
                mats.set_fiber(t, w[1] - w[0])
                    .map_err(|e| src.error(v.points_m.span(), format!("{what}: points_m: {e}")))?;
                count += 1;
            }
        }
        if count == 0 {
            return Err(src.error(v.points_m.span(), format!("{what} crosses no tetrahedron")));
        }
        report.vessels.push((name, count));
    }
    report.anisotropic_tets = (0..n_tets)
        .filter(|&t| mats.material(TetId::from(t)).is_anisotropic())
        .count();
    let mut model = ElasticModel::new(mesh, mats).map_err(|e| {
        // A mesh that overlaps itself is the mesh's fault, not the material's.
        let span = match e {
            crate::tensor_mass::ModelError::OversharedFace(_) => spec.mesh.span(),
            _ => spec.material.span(),
        };
        src.error(span, e.to_string())
    })?;

    if let Some(m) = &spec.membrane {
        let alpha = *m.get_ref().alpha.get_ref();
        let kind = match m.get_ref().model.unwrap_or(MembraneModelName::Linear) {
            MembraneModelName::Linear => MembraneModel::Linear,
            MembraneModelName::Nonlinear => MembraneModel::Nonlinear,
        };
        if !(alpha.is_finite() && alpha > 0.0) {
            return Err(src.error(
                m.get_ref().alpha.span(),
                format!("[membrane] alpha must be a positive finite number (N/m^2), got {alpha}"),
            ));
        }
        model = model.with_membrane(alpha, kind).expect("alpha checked");
        report.membrane = Some((alpha, format!("{kind:?}").to_lowercase()));
    }

    let mesh = model.mesh();
    let n = mesh.vertex_count();
    let mut fixed = Vec::new();
    for f in &spec.fixed {
        let vs = Region::new(src, &f.get_ref().select)?.vertices(mesh, &physical);
        if vs.is_empty() {
            return Err(src.error(f.get_ref().select.span(), "[[fixed]] selects no vertex"));
        }
        fixed.extend(vs);
    }
    fixed.sort_unstable();
    fixed.dedup();
    let hybrid_tets = match &spec.hybrid {
        Some(h) => {
            let select = &h.get_ref().select;
            let tets = Region::for_tets(src, select)?.tets(mesh, &physical);
            if tets.is_empty() || tets.len() == mesh.tet_count() {
                return Err(src.error(
                    select.span(),
                    format!(
                        "[hybrid] select picks {} of {} tetrahedra; the tensor-mass part and the precomputed rest must both be non-empty",
                        tets.len(),
                        mesh.tet_count()
                    ),
                ));
            }
            report.hybrid_tets = Some(tets.len());
            Some(tets)
        }
        None => None,
    };
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
        let vs = Region::new(src, &l.select)?.vertices(mesh, &physical);
        if vs.is_empty() {
            return Err(src.error(l.select.span(), "[[load]] selects no vertex"));
        }
        let vector = |v: &toml::Spanned<[Real; 3]>| {
            let x = Vec3::from_array(*v.get_ref());
            if x.is_finite() {
                Ok(x)
            } else {
                Err(src.error(v.span(), "load values must be finite"))
            }
        };
        if let Some(d) = &l.displacement_m {
            let d = vector(d)?;
            prescribed.extend(vs.iter().map(|v| (*v, d)));
            continue;
        }
        if let Some(r) = &l.rotate {
            let (turn, origin) = rotation(src, r.get_ref())?;
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
            let each = vector(f)? / vs.len() as Real;
            for v in &vs {
                loads_n[v.idx()] += each;
            }
        } else if let Some(t) = &l.traction_pa {
            let t = vector(t)?;
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
    // A vertex both fixed and prescribed is an error in the scene.
    if let Some((v, _)) = prescribed
        .iter()
        .find(|(v, _)| fixed.binary_search(v).is_ok())
    {
        let span = spec.load.first().map_or(spec.mesh.span(), |l| l.span());
        return Err(src.error(
            span,
            format!("vertex {} is both fixed and given a displacement", v.0),
        ));
    }
    report.fixed_vertices = fixed.len();
    report.prescribed_vertices = prescribed.len();
    report.loaded_vertices = loads_n.iter().filter(|f| **f != Vec3::ZERO).count();

    let mut tools: Vec<ToolDecl> = Vec::new();
    for tool in &spec.tool {
        let t = tool.get_ref();
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
        if tip > length {
            return Err(src.error(
                t.tip_length_m.span(),
                format!("{what}: tip_length_m ({tip}) exceeds length_m ({length})"),
            ));
        }
        let friction = tool_friction(src, t, &what)?;
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
    let settings = settings(src, spec)?;
    backend_runs_models(src, spec, &model, settings.backend, hybrid_tets.as_deref())?;
    let contact = contact_config(src, spec)?;
    Ok(BuiltScene {
        contact,
        model,
        fixed,
        prescribed,
        loads_n,
        tools,
        hybrid_tets,
        settings,
        report,
        original_vertex_ids,
    })
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
