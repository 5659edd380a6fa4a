//! Drawing one frame with three-d, the same for the window and snapshots:
//! the organ surface smooth-shaded (cut faces in a paler colour, as their
//! own mesh so the crease between capsule and cut stays sharp), the tools
//! (shaft, tip coloured by contact state), optional fibre directions and
//! force vectors, and the text overlay. With [`ColourBy::Displacement`] the
//! organ is coloured by how far each vertex moved (viridis, see
//! [`crate::colour`]) and a colour bar gives the range; force arrows are
//! drawn over everything (the tip is inside the dent it makes) at a fixed
//! length per newton, printed in the overlay.

use crate::colour::ColourBy;
use crate::overlay::Image;
use crate::scene_info::Fibre;
use three_d::*;

/// Background colour (linear RGBA).
pub const BACKGROUND: [f32; 4] = [0.08, 0.09, 0.11, 1.0];
/// The organ's capsule.
pub const CAPSULE: Srgba = Srgba::new(160, 62, 52, 255);
/// Faces made by cuts (exposed parenchyma).
pub const CUT: Srgba = Srgba::new(236, 170, 120, 255);
const SHAFT: Srgba = Srgba::new(170, 175, 185, 255);
const TIP_FREE: Srgba = Srgba::new(120, 160, 220, 255);
const TIP_CONTACT: Srgba = Srgba::new(240, 210, 60, 255);
const TIP_GRIP: Srgba = Srgba::new(80, 210, 110, 255);
const TIP_CUT: Srgba = Srgba::new(240, 60, 200, 255);
const FORCE: Srgba = Srgba::new(60, 230, 230, 255);
const FIBRE: Srgba = Srgba::new(250, 250, 250, 255);
/// The default force arrow length per newton (mm/N).
pub const FORCE_MM_PER_N: f32 = 20.0;

/// The tip colour of a tool in `flags`' state, and the state's name.
pub fn tip_state(flags: u32) -> (Srgba, &'static str) {
    match flags {
        f if f & shared::protocol::CUTTING != 0 => (TIP_CUT, "cutting"),
        f if f & shared::protocol::GRIPPING != 0 => (TIP_GRIP, "gripping"),
        f if f & shared::protocol::CONTACT != 0 => (TIP_CONTACT, "in contact"),
        _ => (TIP_FREE, "free"),
    }
}

/// A force arrow's length (m) for a force of `force_n` newtons at
/// `mm_per_n`; zero below one tool radius (no arrow is drawn then).
pub fn arrow_length_m(force_n: f32, mm_per_n: f32, radius_m: f32) -> f32 {
    let len = force_n * mm_per_n * 1e-3;
    if len.is_finite() && len > radius_m {
        len
    } else {
        0.0
    }
}

/// A tool as drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolShape {
    /// Where the shaft enters (m).
    pub fulcrum_m: Vec3,
    /// The tool end (m).
    pub end_m: Vec3,
    /// Shaft radius (m).
    pub radius_m: f32,
    /// `CONTACT | GRIPPING | CUTTING` bits.
    pub flags: u32,
    /// Force of the tissue on the tool (N).
    pub force_n: Vec3,
}

/// A clipping plane across one axis: what lies beyond it (on the axis's
/// positive side) is not drawn, so the inside (vessels, fibres) shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clip {
    /// 0, 1 or 2: x, y or z.
    pub axis: usize,
    /// Where across the organ's bounding box along the axis, 0 to 1.
    pub fraction: f32,
}

impl Clip {
    /// The plane's coordinate (m) for bounds `lo..hi`.
    pub fn at_m(&self, lo: Vec3, hi: Vec3) -> f32 {
        lo[self.axis] + self.fraction * (hi[self.axis] - lo[self.axis])
    }

    /// Whether `p` is kept by a plane at `at_m`.
    pub fn keeps(&self, at_m: f32, p: [f32; 3]) -> bool {
        p[self.axis] <= at_m
    }
}

impl std::str::FromStr for Clip {
    type Err = String;
    /// `x`, `y` or `z`, optionally `:FRACTION` (default 0.5): `y:0.4`.
    fn from_str(s: &str) -> Result<Self, String> {
        let (axis, fraction) = s.split_once(':').unwrap_or((s, "0.5"));
        let axis = match axis.trim() {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            other => {
                return Err(format!(
                    "{other:?} is not an axis: use x, y or z, optionally :FRACTION (y:0.5)"
                ));
            }
        };
        let fraction: f32 = fraction
            .trim()
            .parse()
            .ok()
            .filter(|f: &f32| (0.0..=1.0).contains(f))
            .ok_or_else(|| {
                format!("{fraction:?} is not a fraction of the organ between 0 and 1")
            })?;
        Ok(Self { axis, fraction })
    }
}

/// What to show.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Layers {
    /// Fibre directions.
    pub fibres: bool,
    /// Force vectors at the tool ends.
    pub forces: bool,
    /// The text overlay.
    pub overlay: bool,
    /// What the organ's colour shows.
    pub colour_by: ColourBy,
    /// Force arrow length per newton (mm/N).
    pub force_mm_per_n: f32,
    /// A clipping plane (None: the whole organ).
    pub clip: Option<Clip>,
}

impl Default for Layers {
    fn default() -> Self {
        Self {
            fibres: false,
            forces: true,
            overlay: true,
            colour_by: ColourBy::Tissue,
            force_mm_per_n: FORCE_MM_PER_N,
            clip: None,
        }
    }
}

type Solid = Gm<Mesh, PhysicalMaterial>;

/// The GPU side of a frame; update what changed, then [`Renderer::draw`].
pub struct Renderer {
    context: Context,
    capsule: Option<Solid>,
    cut: Option<Solid>,
    tools: Vec<Solid>,
    arrows: Vec<Solid>,
    fibres: Option<Solid>,
    overlay: Option<Gm<Rectangle, ColorMaterial>>,
    overlay_size: (f32, f32),
    bar: Option<Gm<Rectangle, ColorMaterial>>,
    bar_size: (f32, f32),
    clip: Option<(Clip, f32)>,
    key: DirectionalLight,
    fill: DirectionalLight,
    ambient: AmbientLight,
}

fn solid(context: &Context, mesh: &CpuMesh, color: Srgba) -> Solid {
    Gm::new(
        Mesh::new(context, mesh),
        PhysicalMaterial::new_opaque(
            context,
            &CpuMaterial {
                albedo: color,
                roughness: 0.55,
                metallic: 0.0,
                ..Default::default()
            },
        ),
    )
}

/// An sRGB channel as a linear one (both 8-bit).
fn srgb_to_linear(c: u8) -> u8 {
    let v = f32::from(c) / 255.0;
    let l = if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    };
    (l * 255.0).round() as u8
}

/// A unit-radius cylinder along x from 0 to 1, placed from `a` to `b`.
fn placed(mut mesh: CpuMesh, a: Vec3, b: Vec3, radius: f32) -> Option<CpuMesh> {
    let d = b - a;
    let len = d.magnitude();
    if len.is_nan() || len <= 1e-9 {
        return None;
    }
    let m = Mat4::from_translation(a)
        * rotation_matrix_from_dir_to_dir(vec3(1.0, 0.0, 0.0), d / len)
        * Mat4::from_nonuniform_scale(len, radius, radius);
    mesh.transform(m).ok()?;
    Some(mesh)
}

/// Concatenates meshes that have positions and indices only.
fn merge(parts: impl IntoIterator<Item = CpuMesh>) -> CpuMesh {
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for part in parts {
        let base = positions.len() as u32;
        let p = part.positions.to_f32();
        let count = p.len() as u32;
        positions.extend(p);
        match part.indices.into_u32() {
            Some(ix) => indices.extend(ix.into_iter().map(|i| i + base)),
            None => indices.extend(base..base + count),
        }
    }
    let mut mesh = CpuMesh {
        positions: Positions::F32(positions),
        indices: Indices::U32(indices),
        ..Default::default()
    };
    mesh.compute_normals();
    mesh
}

impl Renderer {
    /// A renderer on `context` with nothing to draw yet.
    pub fn new(context: &Context) -> Self {
        Self {
            context: context.clone(),
            capsule: None,
            cut: None,
            tools: Vec::new(),
            arrows: Vec::new(),
            fibres: None,
            overlay: None,
            overlay_size: (0.0, 0.0),
            bar: None,
            bar_size: (0.0, 0.0),
            clip: None,
            // Travelling directions, set for the views from +y (in front):
            // the key from above and behind the organ, the fill from the
            // camera's side, so that tissue is never lit to the cut colour.
            key: DirectionalLight::new(context, 2.2, Srgba::WHITE, vec3(-0.4, 0.5, -1.0)),
            fill: DirectionalLight::new(context, 0.8, Srgba::WHITE, vec3(0.6, -0.4, 0.3)),
            ambient: AmbientLight::new(context, 0.35, Srgba::WHITE),
        }
    }

    /// The organ surface: `triangles` over `positions_m`, split by
    /// `is_cut`; the capsule in `colours` (one per vertex) when given.
    /// Clipped by [`Renderer::set_clip`]'s plane; returns the triangles
    /// drawn.
    pub fn set_surface(
        &mut self,
        positions_m: &[[f32; 3]],
        triangles: &[[u32; 3]],
        is_cut: impl Fn([u32; 3]) -> bool,
        colours: Option<&[[u8; 3]]>,
    ) -> usize {
        let clip = self.clip;
        let kept = |t: &[u32; 3]| {
            clip.is_none_or(|(c, at)| {
                t.iter()
                    .any(|&v| positions_m.get(v as usize).is_some_and(|p| c.keeps(at, *p)))
            })
        };
        let positions: Vec<Vec3> = positions_m.iter().map(|p| vec3(p[0], p[1], p[2])).collect();
        let build = |want_cut: bool| -> Option<CpuMesh> {
            let indices: Vec<u32> = triangles
                .iter()
                .filter(|t| kept(t) && is_cut(**t) == want_cut)
                .flatten()
                .copied()
                .collect();
            if indices.is_empty() {
                return None;
            }
            let mut mesh = CpuMesh {
                positions: Positions::F32(positions.clone()),
                indices: Indices::U32(indices),
                ..Default::default()
            };
            mesh.compute_normals();
            Some(mesh)
        };
        let field = colours.filter(|c| c.len() == positions.len());
        self.capsule = build(false).map(|mut m| match field {
            Some(c) => {
                m.colors = Some(
                    c.iter()
                        .map(|c| Srgba::new(c[0], c[1], c[2], 255))
                        .collect(),
                );
                solid(&self.context, &m, Srgba::WHITE)
            }
            None => solid(&self.context, &m, CAPSULE),
        });
        // Cut faces keep their colour: where the tissue was opened stays
        // visible whatever the capsule shows.
        self.cut = build(true).map(|m| solid(&self.context, &m, CUT));
        triangles.iter().filter(|t| kept(t)).count()
    }

    /// The colour bar (drawn in the bottom-right corner); `None` removes it.
    pub fn set_colour_bar(&mut self, image: Option<&Image>) {
        self.bar = image.and_then(|i| self.panel(i));
        self.bar_size = image.map_or((0.0, 0.0), |i| (i.width as f32, i.height as f32));
    }

    /// The tools (and their force vectors, `mm_per_n` long per newton, when
    /// `forces`).
    pub fn set_tools(&mut self, tools: &[ToolShape], forces: bool, mm_per_n: f32) {
        self.tools.clear();
        self.arrows.clear();
        for t in tools {
            let tip_len = (t.radius_m * 4.0).min((t.end_m - t.fulcrum_m).magnitude());
            let dir = (t.end_m - t.fulcrum_m).normalize();
            let tip_start = t.end_m - dir * tip_len;
            if let Some(m) = placed(CpuMesh::cylinder(16), t.fulcrum_m, tip_start, t.radius_m) {
                self.tools.push(solid(&self.context, &m, SHAFT));
            }
            let (color, _) = tip_state(t.flags);
            let mut ball = CpuMesh::sphere(12);
            if ball
                .transform(Mat4::from_translation(t.end_m) * Mat4::from_scale(t.radius_m))
                .is_ok()
            {
                let tip = placed(CpuMesh::cylinder(16), tip_start, t.end_m, t.radius_m);
                self.tools.push(solid(
                    &self.context,
                    &merge(tip.into_iter().chain([ball])),
                    color,
                ));
            }
            let len = arrow_length_m(t.force_n.magnitude(), mm_per_n, t.radius_m);
            if forces && len > 0.0 {
                let mut arrow = CpuMesh::arrow(0.8, 0.5, 12);
                // Thick enough to see beside the shaft it often runs along.
                let thick = (1.6 * t.radius_m).max(0.06 * len);
                let m = Mat4::from_translation(t.end_m)
                    * rotation_matrix_from_dir_to_dir(vec3(1.0, 0.0, 0.0), t.force_n.normalize())
                    * Mat4::from_nonuniform_scale(len, thick, thick);
                if arrow.transform(m).is_ok() {
                    let mut a = solid(&self.context, &arrow, FORCE);
                    // Over everything: the tip sits inside its own dent.
                    a.material.render_states.depth_test = DepthTest::Always;
                    self.arrows.push(a);
                }
            }
        }
    }

    /// The clipping plane for the surface and fibres set next (None: none).
    pub fn set_clip(&mut self, clip: Option<(Clip, f32)>) {
        self.clip = clip;
    }

    /// Fibre directions as thin rods (built once per scene), those beyond
    /// the clipping plane left out; returns how many are drawn.
    pub fn set_fibres(&mut self, fibres: &[Fibre], rod_radius_m: f32) -> usize {
        let clip = self.clip;
        let shown: Vec<&Fibre> = fibres
            .iter()
            .filter(|(c, _)| clip.is_none_or(|(k, at)| k.keeps(at, *c)))
            .collect();
        let count = shown.len();
        let rods = shown.into_iter().filter_map(|(c, d)| {
            let (c, d) = (Vec3::from(*c), Vec3::from(*d));
            placed(CpuMesh::cylinder(3), c - d * 0.5, c + d * 0.5, rod_radius_m)
        });
        let mesh = merge(rods);
        self.fibres = (mesh.vertex_count() > 0).then(|| solid(&self.context, &mesh, FIBRE));
        count
    }

    /// The overlay panel (drawn in the top-left corner).
    pub fn set_overlay(&mut self, image: &Image) {
        self.overlay = self.panel(image);
        self.overlay_size = (image.width as f32, image.height as f32);
    }

    /// A screen-space panel showing `image` pixel for pixel.
    fn panel(&self, image: &Image) -> Option<Gm<Rectangle, ColorMaterial>> {
        if image.pixels.is_empty() {
            return None;
        }
        // The framebuffer encodes what is drawn as sRGB and an 8-bit texture
        // is read as linear: decoding the panel's sRGB pixels first makes
        // the picture hold them as given (a colour bar's colours exactly the
        // map's, the organ's colours being the same map's as sRGB).
        let decoded: Vec<[u8; 4]> = image
            .pixels
            .iter()
            .map(|p| {
                [
                    srgb_to_linear(p[0]),
                    srgb_to_linear(p[1]),
                    srgb_to_linear(p[2]),
                    p[3],
                ]
            })
            .collect();
        let texture = CpuTexture {
            data: TextureData::RgbaU8(decoded),
            width: image.width as u32,
            height: image.height as u32,
            min_filter: Interpolation::Nearest,
            mag_filter: Interpolation::Nearest,
            mipmap: None,
            ..Default::default()
        };
        let material = ColorMaterial {
            color: Srgba::WHITE,
            texture: Some(Texture2DRef::from_cpu_texture(&self.context, &texture)),
            is_transparent: true,
            render_states: RenderStates {
                blend: Blend::TRANSPARENCY,
                depth_test: DepthTest::Always,
                write_mask: WriteMask::COLOR,
                ..Default::default()
            },
        };
        let (w, h) = (image.width as f32, image.height as f32);
        let rect = Rectangle::new(&self.context, vec2(w / 2.0, h / 2.0), degrees(0.0), w, h);
        Some(Gm::new(rect, material))
    }

    /// Clears `target` and draws everything with `camera`.
    pub fn draw(&mut self, target: &RenderTarget, camera: &Camera, layers: &Layers) {
        let [r, g, b, a] = BACKGROUND;
        target.clear(ClearState::color_and_depth(r, g, b, a, 1.0));
        let mut objects: Vec<&dyn Object> = Vec::new();
        objects.extend(self.capsule.iter().map(|o| o as &dyn Object));
        objects.extend(self.cut.iter().map(|o| o as &dyn Object));
        objects.extend(self.tools.iter().map(|o| o as &dyn Object));
        if layers.fibres {
            objects.extend(self.fibres.iter().map(|o| o as &dyn Object));
        }
        target.render(camera, objects, &[&self.key, &self.fill, &self.ambient]);
        if layers.forces {
            target.render(
                camera,
                self.arrows.iter().map(|o| o as &dyn Object),
                &[&self.key, &self.fill, &self.ambient],
            );
        }
        let vp = camera.viewport();
        if layers.overlay
            && let Some(panel) = &mut self.overlay
        {
            let (w, h) = self.overlay_size;
            panel
                .geometry
                .set_center(vec2(w / 2.0 + 8.0, vp.height as f32 - h / 2.0 - 8.0));
            target.render(Camera::new_2d(vp), [&*panel], &[]);
        }
        // The colour bar is part of the picture's meaning: shown even
        // without the text overlay.
        if let Some(bar) = &mut self.bar {
            let (w, h) = self.bar_size;
            bar.geometry
                .set_center(vec2(vp.width as f32 - w / 2.0 - 8.0, h / 2.0 + 8.0));
            target.render(Camera::new_2d(vp), [&*bar], &[]);
        }
    }
}
