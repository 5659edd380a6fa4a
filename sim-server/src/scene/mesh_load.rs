//! A scene's `[mesh]`: read from a file (with its physical tags) or
//! generated, scaled to metres as `scale` or `units` asks, and renumbered
//! for the kernel (RCM) with each vertex's original index kept.

use super::report::{SceneReport, positive};
use super::select::Tags;
use super::spec::{LatticeKind, SceneSpec, ShapeKind};
use super::{SceneError, SceneSource};
use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::mesh::{BoxSpec, CellSize, TetMesh, io, rcm_order, shapes};

/// The factor `[mesh] scale` or `units` asks for (`None`: metres as read).
fn mesh_scale(src: &SceneSource, m: &super::spec::MeshSpec) -> Result<Option<Real>, SceneError> {
    match (&m.scale, &m.units) {
        (Some(_), Some(u)) => Err(src.error(u.span(), "give `scale` or `units`, not both")),
        (Some(s), None) => {
            positive(src, s, "scale")?;
            // Its usual range is its accepted one: no warning to keep.
            let mut none = SceneReport::default();
            super::ranges::MESH_SCALE
                .check(src, s, "[mesh]", &mut none)
                .map(Some)
        }
        (None, Some(u)) => match u.get_ref().as_str() {
            "m" => Ok(None),
            "cm" => Ok(Some(0.01)),
            "mm" => Ok(Some(0.001)),
            other => Err(src.error(
                u.span(),
                format!("units must be \"m\", \"cm\" or \"mm\", got {other:?}"),
            )),
        },
        (None, None) => Ok(None),
    }
}

/// The `[mesh]` placement as a rotation then a shift: `rotate_deg` (x,
/// then y, then z, fixed axes) and `translate_m`; `None` when neither is
/// given. Centreline files of the same segmentation are placed by it too.
pub(super) fn placement(
    src: &SceneSource,
    m: &super::spec::MeshSpec,
) -> Result<Option<(glam::DMat3, Vec3)>, SceneError> {
    if m.rotate_deg.is_none() && m.translate_m.is_none() {
        return Ok(None);
    }
    let finite = |s: &toml::Spanned<[f64; 3]>, what: &str| {
        if s.get_ref().iter().all(|x| x.is_finite()) {
            Ok(*s.get_ref())
        } else {
            Err(src.error(s.span(), format!("`{what}` must be three finite numbers")))
        }
    };
    let r = m
        .rotate_deg
        .as_ref()
        .map(|s| finite(s, "rotate_deg"))
        .transpose()?
        .unwrap_or([0.0; 3]);
    let t = m
        .translate_m
        .as_ref()
        .map(|s| finite(s, "translate_m"))
        .transpose()?
        .unwrap_or([0.0; 3]);
    if let Some(s) = &m.translate_m
        && t.iter().any(|x| x.abs() > MAX_BODY_M)
    {
        return Err(src.error(
            s.span(),
            format!("`translate_m` moves the organ more than {MAX_BODY_M} m"),
        ));
    }
    let rot = glam::DMat3::from_rotation_z(r[2].to_radians())
        * glam::DMat3::from_rotation_y(r[1].to_radians())
        * glam::DMat3::from_rotation_x(r[0].to_radians());
    Ok(Some((rot, Vec3::from_array(t))))
}

/// `mesh` placed by [`placement`] (a rotation keeps every tetrahedron's
/// orientation, so the mesh stays valid).
fn placed(
    src: &SceneSource,
    m: &super::spec::MeshSpec,
    mesh: TetMesh,
) -> Result<TetMesh, SceneError> {
    let Some((rot, shift)) = placement(src, m)? else {
        return Ok(mesh);
    };
    let span = m
        .rotate_deg
        .as_ref()
        .or(m.translate_m.as_ref())
        .map(|s| s.span())
        .unwrap_or_default();
    TetMesh::new(
        mesh.positions_m()
            .iter()
            .map(|p| rot * *p + shift)
            .collect(),
        mesh.tets().iter().map(|t| t.map(|v| v.0)).collect(),
    )
    .map_err(|e| src.error(span, e.to_string()))
}

/// The tetrahedra of a `surface` key: the cached mesh of these surfaces
/// and options, made by fTetWild when not cached yet (said in the report).
fn meshed_surface(
    src: &SceneSource,
    m: &super::spec::MeshSpec,
    surface: &toml::Spanned<super::spec::Surfaces>,
    report: &mut SceneReport,
) -> Result<std::path::PathBuf, SceneError> {
    use crate::mesh::tetrahedralize::{
        MeshRequest, Size, Units, cache_dir, cache_key, tetrahedralize,
    };
    let at = surface.span();
    let files: Vec<std::path::PathBuf> = surface
        .get_ref()
        .files()
        .iter()
        .map(|f| src.dir.join(f))
        .collect();
    let size = match (&m.cell_m, &m.tets) {
        (Some(c), None) => Size::CellM(positive(src, c, "cell_m")?),
        (None, Some(n)) => Size::Tets(*n.get_ref()),
        _ => {
            return Err(src.error(
                at,
                "`surface` needs exactly one of `cell_m`, `tets` at [mesh]",
            ));
        }
    };
    let units = match mesh_scale(src, m)? {
        None if m.units.is_some() => Some(Units::M),
        None => None,
        Some(s) if (s - 1e-3).abs() < 1e-12 => Some(Units::Mm),
        Some(_) => {
            return Err(src.error(
                at.clone(),
                "a `surface` takes `units = \"mm\"` or `\"m\"` (or none: millimetres are detected), not `scale` or cm",
            ));
        }
    };
    let Some(dir) = cache_dir().map(|d| d.join("meshes")) else {
        return Err(src.error(at, "no cache directory (neither XDG_CACHE_HOME nor HOME is set) for the meshed surface: mesh it with `sim-server mesh` and give `file`"));
    };
    let mut req = MeshRequest::new(files, size, std::path::PathBuf::new());
    req.units = units;
    let key = cache_key(&req).map_err(|e| src.error(at.clone(), e.to_string()))?;
    let path = dir.join(format!("{key:016x}.msh"));
    if path.is_file() {
        report.mesh_source = format!(
            "{} (meshed surface, cached: {})",
            req.surfaces[0].display(),
            path.display()
        );
        return Ok(path);
    }
    std::fs::create_dir_all(&dir)
        .map_err(|e| src.error(at.clone(), format!("cannot create {}: {e}", dir.display())))?;
    // Written beside, renamed into place: a run stopped mid-way leaves no
    // half mesh under the key.
    let partial = dir.join(format!("{key:016x}.{}.partial.msh", std::process::id()));
    req.out = partial.clone();
    let made = tetrahedralize(&req).map_err(|e| src.error(at.clone(), e.to_string()))?;
    std::fs::rename(&partial, &path)
        .map_err(|e| src.error(at, format!("cannot write {}: {e}", path.display())))?;
    for s in &made.inputs {
        for h in &s.holes {
            report.warnings.push(format!(
                "{}: a hole ({} boundary vertices) around ({:.4}, {:.4}, {:.4}) m; fTetWild meshed across it",
                s.path, h.edges, h.centre[0], h.centre[1], h.centre[2]
            ));
        }
        if s.nonmanifold_edges > 0 {
            report.warnings.push(format!(
                "{}: {} non-manifold edges (sim-server mesh lists them)",
                s.path, s.nonmanifold_edges
            ));
        }
    }
    report.mesh_source = format!(
        "{} (meshed by fTetWild in {:.1} s: {} tetrahedra; cached: {})",
        req.surfaces[0].display(),
        made.seconds,
        made.tets,
        path.display()
    );
    Ok(path)
}

/// `mesh` with every coordinate multiplied by `s`.
/// A body more than this across (m) is refused: not an organ in metres.
const MAX_BODY_M: Real = 10.0;

/// A mesh file's body checked for its units: refused, with the `[mesh]
/// scale` to set, when it is more than [`MAX_BODY_M`] across (a liver
/// read in millimetres is 1400 m wide and would run, untouchable); said as
/// a warning (here, so that `run` says it as `check` does) when its edges
/// are not plausibly metres.
fn plausible_units(
    src: &SceneSource,
    at: std::ops::Range<usize>,
    mesh: &TetMesh,
    report: &mut SceneReport,
) -> Result<(), SceneError> {
    let extent = crate::mesh::extent::Extent::of(mesh);
    let size = extent.max_m - extent.min_m;
    let across = size.max_element();
    let warning = extent.units_warning();
    if across > MAX_BODY_M {
        let fix = warning.unwrap_or_else(|| "set [mesh] scale to what makes it metres".into());
        return Err(src.error(
            at,
            format!(
                "the body is {across:.1} m across, more than {MAX_BODY_M} m: not an organ in metres; {fix}"
            ),
        ));
    }
    report.warnings.extend(warning);
    Ok(())
}

fn scaled(mesh: &TetMesh, s: Real) -> Result<TetMesh, crate::mesh::MeshError> {
    TetMesh::new(
        mesh.positions_m().iter().map(|p| *p * s).collect(),
        mesh.tets().iter().map(|t| t.map(|v| v.0)).collect(),
    )
}

/// A scene's mesh, renumbered, with what it said about itself.
pub(super) struct LoadedMesh {
    pub mesh: TetMesh,
    /// Physical tags of tetrahedra and surface triangles.
    pub physical: Tags,
    /// Per vertex, its index before renumbering (`None`: not renumbered).
    pub original_ids: Option<Vec<u32>>,
}

/// The mesh as read, generated or meshed and placed, before any
/// refinement: what a refinement that follows the tools refines again each
/// time they move (kept in the built scene only when it asks for one).
#[derive(Clone, Debug)]
pub struct BaseMesh {
    pub(super) mesh: TetMesh,
    pub(super) physical: Tags,
}

impl BaseMesh {
    /// The mesh (m).
    pub fn mesh(&self) -> &TetMesh {
        &self.mesh
    }
}

/// The scene's mesh as read, generated or meshed, and placed.
pub(super) fn load_base(
    src: &SceneSource,
    spec: &SceneSpec,
    report: &mut SceneReport,
) -> Result<BaseMesh, SceneError> {
    let m = spec.mesh.get_ref();
    if m.surface.is_none()
        && let Some(k) = m
            .cell_m
            .as_ref()
            .map(|c| c.span())
            .or(m.tets.as_ref().map(|t| t.span()))
    {
        return Err(src.error(
            k,
            "`cell_m` and `tets` at [mesh] size a `surface`; a generated mesh takes them inside `generate`",
        ));
    }
    let (mesh, physical) = match (&m.file, &m.generate) {
        (None, None) if m.surface.is_some() => {
            let surface = m.surface.as_ref().expect("checked");
            let path = meshed_surface(src, m, surface, report)?;
            let imported =
                io::read_mesh(&path).map_err(|e| src.error(surface.span(), e.to_string()))?;
            report.warnings.extend(imported.warnings);
            plausible_units(src, surface.span(), &imported.mesh, report)?;
            let tags = Tags {
                tets: imported.tet_physical,
                surface: Vec::new(),
            };
            (imported.mesh, tags)
        }
        (Some(file), None) if m.surface.is_none() => {
            let path = src.dir.join(file.get_ref());
            let imported =
                io::read_mesh(&path).map_err(|e| src.error(file.span(), e.to_string()))?;
            report.mesh_source = path.display().to_string();
            report.warnings.extend(imported.warnings);
            let mesh = match mesh_scale(src, m)? {
                Some(s) => {
                    scaled(&imported.mesh, s).map_err(|e| src.error(file.span(), e.to_string()))?
                }
                None => imported.mesh,
            };
            plausible_units(src, file.span(), &mesh, report)?;
            let tags = Tags {
                tets: imported.tet_physical,
                surface: imported
                    .surface_physical
                    .into_iter()
                    .map(|(t, tag)| (t.map(VertexId), tag))
                    .collect(),
            };
            (mesh, tags)
        }
        (None, Some(g)) if m.surface.is_none() && (m.scale.is_some() || m.units.is_some()) => {
            return Err(src.error(
                g.span(),
                "`scale` and `units` convert a mesh file; a generated mesh is given in metres",
            ));
        }
        (None, Some(g)) if m.surface.is_none() => {
            let gen_span = g.span();
            let g = g.get_ref();
            let cell = g
                .cell_m
                .as_ref()
                .map(|c| positive(src, c, "cell_m"))
                .transpose()?;
            let need_cell =
                || cell.ok_or_else(|| src.error(gen_span.clone(), "this generator needs `cell_m`"));
            let lattice = match g.lattice.unwrap_or(LatticeKind::Bcc) {
                LatticeKind::Bcc => shapes::Lattice::BodyCentred,
                LatticeKind::Cubic => shapes::Lattice::Cubic,
            };
            let fail = |e: crate::mesh::GenerateError| src.error(gen_span.clone(), e.to_string());
            // A key of another shape was ignored without a word (a box
            // given center_m was built at the origin).
            let (name, keys) = match g.shape {
                ShapeKind::Box => ("box", "size_m, origin_m, and cell_m or tets"),
                ShapeKind::Ellipsoid => ("ellipsoid", "radii_m, center_m, cell_m, lattice"),
                ShapeKind::Liver => ("liver", "cell_m, lattice"),
            };
            let given = [
                ("size_m", g.size_m.is_some(), ShapeKind::Box),
                ("origin_m", g.origin_m.is_some(), ShapeKind::Box),
                ("tets", g.tets.is_some(), ShapeKind::Box),
                ("radii_m", g.radii_m.is_some(), ShapeKind::Ellipsoid),
                ("center_m", g.center_m.is_some(), ShapeKind::Ellipsoid),
            ];
            if let Some((key, ..)) = given.iter().find(|(_, set, of)| *set && *of != g.shape) {
                return Err(src.error(
                    gen_span,
                    format!("`{key}` does not apply to shape \"{name}\" (its keys: {keys})"),
                ));
            }
            if g.shape == ShapeKind::Box && g.lattice.is_some() {
                return Err(src.error(
                    gen_span,
                    format!(
                        "`lattice` does not apply to shape \"box\" (its keys: {keys}): the box is cut into cubes of six tetrahedra"
                    ),
                ));
            }
            if let Some(t) = &g.tets
                && *t.get_ref() == 0
            {
                return Err(src.error(t.span(), "`tets` must be at least 1"));
            }
            let mesh = match g.shape {
                ShapeKind::Box => {
                    let size = g.size_m.as_ref().ok_or_else(|| {
                        src.error(gen_span.clone(), "shape \"box\" needs `size_m`")
                    })?;
                    let cells = match (cell, &g.tets) {
                        (Some(h), None) => CellSize::EdgeM(h),
                        (None, Some(n)) => CellSize::TargetTets(*n.get_ref()),
                        _ => {
                            return Err(src.error(
                                gen_span.clone(),
                                "shape \"box\" needs exactly one of `cell_m`, `tets`",
                            ));
                        }
                    };
                    let spec = BoxSpec {
                        origin_m: Vec3::from_array(g.origin_m.unwrap_or([0.0; 3])),
                        size_m: Vec3::from_array(*size.get_ref()),
                        cells,
                    };
                    spec.generate()
                        .map_err(|e| src.error(size.span(), e.to_string()))?
                }
                ShapeKind::Ellipsoid => {
                    let radii = g.radii_m.as_ref().ok_or_else(|| {
                        src.error(gen_span.clone(), "shape \"ellipsoid\" needs `radii_m`")
                    })?;
                    let centre = Vec3::from_array(g.center_m.unwrap_or([0.0; 3]));
                    shapes::ellipsoid(
                        centre,
                        Vec3::from_array(*radii.get_ref()),
                        need_cell()?,
                        lattice,
                    )
                    .map_err(fail)?
                }
                ShapeKind::Liver => shapes::liver(need_cell()?, lattice).map_err(fail)?,
            };
            report.mesh_source = format!("generated {:?}", g.shape).to_lowercase();
            let n = mesh.tet_count();
            let tags = Tags {
                tets: vec![0; n],
                surface: Vec::new(),
            };
            (mesh, tags)
        }
        _ => {
            return Err(src.error(
                spec.mesh.span(),
                "[mesh] needs exactly one of `file`, `generate`, `surface`",
            ));
        }
    };
    let mesh = placed(src, m, mesh)?;
    Ok(BaseMesh { mesh, physical })
}

/// `base` refined as the scene's `[[refine]]` and then `around` (where the
/// tools are) ask, and renumbered unless `[mesh] reorder = false`.
pub(super) fn finish_mesh(
    src: &SceneSource,
    spec: &SceneSpec,
    base: BaseMesh,
    around: &[super::refine::RefineAround],
    report: &mut SceneReport,
) -> Result<LoadedMesh, SceneError> {
    let m = spec.mesh.get_ref();
    let BaseMesh { mesh, physical } = base;
    // (Reoriented tetrahedra were named by the reader's warning, once; a
    // generated mesh has none.)
    let (mesh, physical) = super::refine::refine_mesh(src, spec, mesh, physical, report)?;
    let (mesh, physical) = super::refine::refine_around(src, spec, mesh, physical, around, report)?;
    if !m.reorder.unwrap_or(true) {
        return Ok(LoadedMesh {
            mesh,
            physical,
            original_ids: None,
        });
    }
    let order = rcm_order(&mesh);
    let new_of_old = crate::mesh::new_of_old(&order, mesh.vertex_count());
    let mut physical = physical;
    for (tri, _) in &mut physical.surface {
        *tri = tri.map(|v| VertexId(new_of_old[v.idx()]));
    }
    Ok(LoadedMesh {
        mesh: mesh.permuted(&order),
        physical,
        original_ids: Some(order.iter().map(|v| v.0).collect()),
    })
}
