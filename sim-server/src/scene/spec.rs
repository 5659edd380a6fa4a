//! The scene file format (TOML), as typed structures. Unknown keys are
//! refused by serde (`deny_unknown_fields`) with their position; values that
//! need checking beyond their type keep their span (`Spanned`) so the
//! builder can name the line and column of a bad one.
//!
//! Key names follow the architecture page; extend, don't rename.

use serde::Deserialize;
use toml::Spanned;

/// A whole scene.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// `[mesh]`: a file or a generator.
    pub mesh: Spanned<MeshSpec>,
    /// `[material]`: the default material.
    pub material: Spanned<MaterialSpec>,
    /// `[[refine]]`: finer cells where tools work, applied in order to the
    /// mesh as loaded (before materials, constraints and tools).
    #[serde(default)]
    pub refine: Vec<Spanned<RefineSpec>>,
    /// `[[region]]`: material overrides on selections, applied in order.
    #[serde(default)]
    pub region: Vec<Spanned<RegionSpec>>,
    /// `[[vessel]]`: polylines whose tetrahedra become anisotropic along them.
    #[serde(default)]
    pub vessel: Vec<Spanned<VesselSpec>>,
    /// `[membrane]`: the surface capsule.
    pub membrane: Option<Spanned<MembraneSpec>>,
    /// `[[fixed]]`: vertices held at rest.
    #[serde(default)]
    pub fixed: Vec<Spanned<FixedSpec>>,
    /// `[[load]]`: displacements, forces or tractions.
    #[serde(default)]
    pub load: Vec<Spanned<LoadSpec>>,
    /// `[[tool]]`: laparoscopic tools.
    #[serde(default)]
    pub tool: Vec<Spanned<ToolSpec>>,
    /// `[simulation]`: backend, step and threads.
    pub simulation: Option<Spanned<SimulationSpec>>,
    /// `[contact]`: the tool-tissue contact law and its constants.
    pub contact: Option<Spanned<ContactSpec>>,
    /// `[hybrid]`: the split of the hybrid backend.
    pub hybrid: Option<Spanned<HybridSpec>>,
}

/// `[[refine]]`: the tetrahedra touching `select` bisected (longest edge
/// first, conforming) until their cells are no larger than `cell_m` (the
/// generators' measure: (6 V)^(1/3), the cube six such tetrahedra fill).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RefineSpec {
    /// A name for reports.
    pub name: Option<String>,
    /// Where: a box, a sphere (tetrahedra touching it) or a physical tag.
    pub select: Spanned<Selection>,
    /// The cell size wanted there (m), as a generator's `cell_m`: for a
    /// tool, no more than its radius.
    pub cell_m: Spanned<f64>,
    /// The most tetrahedra the whole mesh may have after this refinement
    /// (default 300,000): past it the refinement stops, conforming, and says so.
    pub max_tets: Option<Spanned<usize>>,
}

/// `[hybrid]`: the tetrahedra (by centroid, or by physical tag) that form the
/// hybrid backend's tensor-mass part, the one tools can cut; the rest is
/// precomputed. Read only by the hybrid backend.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HybridSpec {
    /// The tensor-mass (cuttable) region.
    pub select: Spanned<Selection>,
}

/// `[mesh]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshSpec {
    /// A mesh file (.msh, .vtk, .vtu, .mesh), relative to the scene file.
    pub file: Option<Spanned<String>>,
    /// Organ surfaces (STL, OBJ, PLY, OFF, VTK, VTP) to mesh at load with
    /// fTetWild (`sim-server mesh`), cached: one file or a list (the organ,
    /// then inner structures that become physical tags 2, 3, ...).
    pub surface: Option<Spanned<Surfaces>>,
    /// With `surface`: the ideal edge length (m).
    pub cell_m: Option<Spanned<f64>>,
    /// With `surface`: about this many tetrahedra.
    pub tets: Option<Spanned<usize>>,
    /// Rotates the organ about the origin (degrees about x, then y, then
    /// z, fixed axes), after `scale`/`units`, before `translate_m`.
    pub rotate_deg: Option<Spanned<[f64; 3]>>,
    /// Moves the organ (m), last: to place it under the tools' fulcrums.
    pub translate_m: Option<Spanned<[f64; 3]>>,
    /// A generated mesh.
    pub generate: Option<Spanned<GenerateSpec>>,
    /// Renumber vertices for memory locality (default true).
    pub reorder: Option<bool>,
    /// Multiplies the file's coordinates into metres (0.001 for a mesh in
    /// millimetres).
    pub scale: Option<Spanned<f64>>,
    /// The file's length unit, "m", "cm" or "mm" (another way to give
    /// `scale`).
    pub units: Option<Spanned<String>>,
}

/// `surface = "organ.stl"` or `surface = ["organ.stl", "tumour.stl"]`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub enum Surfaces {
    /// One surface.
    One(String),
    /// The organ, then inner structures.
    Many(Vec<String>),
}

impl Surfaces {
    /// The files in order.
    pub fn files(&self) -> Vec<&str> {
        match self {
            Surfaces::One(s) => vec![s.as_str()],
            Surfaces::Many(v) => v.iter().map(String::as_str).collect(),
        }
    }
}

/// The generators.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum ShapeKind {
    /// A box split into cubes.
    Box,
    /// An ellipsoid.
    Ellipsoid,
    /// The liver-like organ.
    Liver,
}

/// Lattice of the implicit-shape generators.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum LatticeKind {
    /// Cubes split into 6 tetrahedra.
    Cubic,
    /// Body-centred cubic tetrahedra (better shaped).
    Bcc,
}

/// `generate = { shape = ..., ... }`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GenerateSpec {
    /// Which shape.
    pub shape: ShapeKind,
    /// Box sides (m).
    pub size_m: Option<Spanned<[f64; 3]>>,
    /// Box minimum corner (m), default the origin.
    pub origin_m: Option<[f64; 3]>,
    /// Ellipsoid radii (m).
    pub radii_m: Option<Spanned<[f64; 3]>>,
    /// Ellipsoid centre (m), default the origin.
    pub center_m: Option<[f64; 3]>,
    /// Cell edge (m).
    pub cell_m: Option<Spanned<f64>>,
    /// Box only: target tetrahedron count instead of a cell edge.
    pub tets: Option<Spanned<usize>>,
    /// Lattice for ellipsoid and liver (default bcc).
    pub lattice: Option<LatticeKind>,
}

/// One of the anisotropic energy terms.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum TermName {
    /// Stretch along the fibre.
    Stretch,
    /// Cross-stretch.
    Cross,
    /// Shear.
    Shear,
}

/// Strain models (`model = ...` in a material table).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum MaterialModelName {
    /// The paper's linearised strain.
    Linear,
    /// St Venant-Kirchhoff (Green-Lagrange strain).
    Stvk,
    /// Corotational (linear in each element's rotated frame).
    Corotational,
}

/// Generates a table type holding the material keys (shared by
/// `[material]`, `[[region]]` and `[[vessel]]`) plus its own keys. serde's
/// `flatten` cannot be combined with `deny_unknown_fields`, hence a macro.
macro_rules! with_material_keys {
    ($(#[$doc:meta])* $name:ident { $($(#[$fdoc:meta])* $field:ident : $ty:ty,)* }) => {
        $(#[$doc])*
        #[derive(Debug, Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct $name {
            $($(#[$fdoc])* pub $field: $ty,)*
            /// Young's modulus (Pa); for anisotropic materials, of the transverse plane.
            pub young_pa: Option<Spanned<f64>>,
            /// Poisson's ratio (of the transverse plane when anisotropic).
            pub poisson: Option<Spanned<f64>>,
            /// Density (kg/m^3).
            pub density_kg_m3: Option<Spanned<f64>>,
            /// Mass-proportional damping (1/s).
            pub damping_per_s: Option<Spanned<f64>>,
            /// lambda_L - lambda_T (Pa), the paper's parameter.
            pub delta_lambda_pa: Option<Spanned<f64>>,
            /// mu_L - mu_T (Pa), the paper's parameter.
            pub delta_mu_pa: Option<Spanned<f64>>,
            /// Young's modulus along the fibre (Pa), engineering form.
            pub young_fiber_pa: Option<Spanned<f64>>,
            /// Shear modulus in planes containing the fibre (Pa), engineering form.
            pub shear_fiber_pa: Option<Spanned<f64>>,
            /// Enabled anisotropic terms (default all three).
            pub terms: Option<Spanned<Vec<TermName>>>,
            /// Strain model (default linear).
            pub model: Option<Spanned<MaterialModelName>>,
        }

        impl $name {
            /// The material keys of this table.
            pub fn material_keys(&self) -> MaterialKeys<'_> {
                MaterialKeys {
                    young_pa: self.young_pa.as_ref(),
                    poisson: self.poisson.as_ref(),
                    density_kg_m3: self.density_kg_m3.as_ref(),
                    damping_per_s: self.damping_per_s.as_ref(),
                    delta_lambda_pa: self.delta_lambda_pa.as_ref(),
                    delta_mu_pa: self.delta_mu_pa.as_ref(),
                    young_fiber_pa: self.young_fiber_pa.as_ref(),
                    shear_fiber_pa: self.shear_fiber_pa.as_ref(),
                    terms: self.terms.as_ref(),
                    model: self.model.as_ref(),
                }
            }
        }
    };
}

/// The material keys of one table, by reference with their spans.
#[derive(Clone, Copy, Debug, Default)]
pub struct MaterialKeys<'a> {
    /// `young_pa`.
    pub young_pa: Option<&'a Spanned<f64>>,
    /// `poisson`.
    pub poisson: Option<&'a Spanned<f64>>,
    /// `density_kg_m3`.
    pub density_kg_m3: Option<&'a Spanned<f64>>,
    /// `damping_per_s`.
    pub damping_per_s: Option<&'a Spanned<f64>>,
    /// `delta_lambda_pa`.
    pub delta_lambda_pa: Option<&'a Spanned<f64>>,
    /// `delta_mu_pa`.
    pub delta_mu_pa: Option<&'a Spanned<f64>>,
    /// `young_fiber_pa`.
    pub young_fiber_pa: Option<&'a Spanned<f64>>,
    /// `shear_fiber_pa`.
    pub shear_fiber_pa: Option<&'a Spanned<f64>>,
    /// `terms`.
    pub terms: Option<&'a Spanned<Vec<TermName>>>,
    /// `model`.
    pub model: Option<&'a Spanned<MaterialModelName>>,
}

impl<'a> MaterialKeys<'a> {
    /// These keys over `base`: each key from `self` if given, else from `base`.
    pub fn over(self, base: MaterialKeys<'a>) -> MaterialKeys<'a> {
        MaterialKeys {
            young_pa: self.young_pa.or(base.young_pa),
            poisson: self.poisson.or(base.poisson),
            density_kg_m3: self.density_kg_m3.or(base.density_kg_m3),
            damping_per_s: self.damping_per_s.or(base.damping_per_s),
            delta_lambda_pa: self.delta_lambda_pa.or(base.delta_lambda_pa),
            delta_mu_pa: self.delta_mu_pa.or(base.delta_mu_pa),
            young_fiber_pa: self.young_fiber_pa.or(base.young_fiber_pa),
            shear_fiber_pa: self.shear_fiber_pa.or(base.shear_fiber_pa),
            terms: self.terms.or(base.terms),
            model: self.model.or(base.model),
        }
    }

    /// Whether any anisotropic key is given.
    pub fn any_anisotropic(&self) -> bool {
        self.delta_lambda_pa.is_some()
            || self.delta_mu_pa.is_some()
            || self.young_fiber_pa.is_some()
            || self.shear_fiber_pa.is_some()
    }
}

with_material_keys!(
    /// `[material]`: every key required except the anisotropic ones.
    MaterialSpec {
        /// Fibre direction for an anisotropic default material.
        fiber: Option<Spanned<[f64; 3]>>,
    }
);

with_material_keys!(
    /// `[[region]]`: a selection and material overrides.
    RegionSpec {
        /// A name for reports.
        name: Option<String>,
        /// Which tetrahedra (by centroid, or by physical tag).
        select: Spanned<Selection>,
        /// Fibre direction (makes the region transversally isotropic).
        fiber: Option<Spanned<[f64; 3]>>,
    }
);

with_material_keys!(
    /// `[[vessel]]`: tetrahedra made transversally isotropic along a
    /// vessel, given as exactly one of a polyline (`points_m`), a
    /// centreline file (`file`) or a region (`select`, e.g. the physical
    /// tag `sim-server mesh` gives an inner surface).
    VesselSpec {
        /// A name for reports.
        name: Option<String>,
        /// The polyline's points (m, the scene's frame), at least two.
        points_m: Option<Spanned<Vec<[f64; 3]>>>,
        /// A centreline file (.csv, .fcsv, .txt, .vtk), relative to the
        /// scene, in the organ's frame: placed by `[mesh] rotate_deg` and
        /// `translate_m` as the organ is.
        file: Option<Spanned<String>>,
        /// The file's units, "m", "cm" or "mm" (default: `[mesh] units`,
        /// else millimetres when it spans more than 5 "m").
        units: Option<Spanned<String>>,
        /// The vessel's tetrahedra; each fibre along the region's local axis.
        select: Option<Spanned<Selection>>,
        /// Radius (m) around a polyline's segments.
        radius_m: Option<Spanned<f64>>,
    }
);

/// A selection: exactly one of the keys.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Selection {
    /// Axis-aligned box [[x0, y0, z0], [x1, y1, z1]] (m).
    pub box_m: Option<[[f64; 3]; 2]>,
    /// Sphere [cx, cy, cz, r] (m).
    pub sphere_m: Option<[f64; 4]>,
    /// A physical tag of the imported mesh's tetrahedra.
    pub physical: Option<i32>,
    /// A physical tag of the imported mesh's surface triangles (a Gmsh
    /// physical surface, a medit triangle reference): its vertices.
    pub surface_physical: Option<i32>,
}

/// Membrane model names.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum MembraneModelName {
    /// Linearised springs folded into the tensors (no per-step cost).
    Linear,
    /// Paper eq 29 every step.
    Nonlinear,
}

/// `[membrane]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MembraneSpec {
    /// k = alpha * h (N/m^2).
    pub alpha: Spanned<f64>,
    /// Spring model (default linear).
    pub model: Option<MembraneModelName>,
}

/// `[[fixed]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixedSpec {
    /// A name for reports.
    pub name: Option<String>,
    /// Which vertices.
    pub select: Spanned<Selection>,
}

/// `[[load]]`: exactly one of the load keys.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSpec {
    /// A name for reports.
    pub name: Option<String>,
    /// Which vertices (tractions: the surface triangles with all three vertices selected).
    pub select: Spanned<Selection>,
    /// Prescribed displacement (m), like a fixed set moved.
    pub displacement_m: Option<Spanned<[f64; 3]>>,
    /// Total force (N) spread equally over the selected vertices.
    pub force_n: Option<Spanned<[f64; 3]>>,
    /// Traction (Pa) on the selected surface.
    pub traction_pa: Option<Spanned<[f64; 3]>>,
    /// A rigid rotation of the selection, imposed as displacements.
    pub rotate: Option<Spanned<RotateSpec>>,
}

/// `rotate = { axis = [x, y, z], origin_m = [x, y, z], angle_deg = A }`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RotateSpec {
    /// Rotation axis (any length but zero).
    pub axis: Spanned<[f64; 3]>,
    /// A point on the axis (m).
    pub origin_m: Spanned<[f64; 3]>,
    /// Angle (degrees, right hand about the axis).
    pub angle_deg: Spanned<f64>,
}

/// Tool kinds (the contact code's own enum, read by name: `grasper`, `hook`, `cavitron`).
pub use crate::contact::ToolKind;

/// `[[tool]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ToolSpec {
    /// Unique name.
    pub name: Spanned<String>,
    /// Kind.
    pub kind: ToolKind,
    /// Insertion point (m).
    pub fulcrum_m: Spanned<[f64; 3]>,
    /// Shaft length (m).
    pub length_m: Spanned<f64>,
    /// Shaft radius (m).
    pub radius_m: Spanned<f64>,
    /// Tip segment length (m).
    pub tip_length_m: Spanned<f64>,
    /// Static Coulomb coefficient of its sliding contact (default: the
    /// dynamic one, else 0: frictionless).
    pub friction_static: Option<Spanned<f64>>,
    /// Dynamic Coulomb coefficient (default: the static one).
    pub friction_dynamic: Option<Spanned<f64>>,
}

/// Contact laws by name.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum ContactLawName {
    /// Compliant Hunt-Crossley contact on points of the surface triangles.
    Penalty,
    /// The paper's: touched vertices projected on a plane tangent to the tool.
    Projection,
}

/// `[contact]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSpec {
    /// The law (default: penalty on tensor-mass and precomputed, which
    /// can run it; projection on implicit and hybrid).
    pub law: Option<Spanned<ContactLawName>>,
    /// Penalty springs relative to the tissue's own vertex stiffness (default 64).
    pub stiffness_factor: Option<Spanned<f64>>,
    /// Hunt-Crossley damping alpha (s/m, default 3; 0 for none).
    pub damping_s_per_m: Option<Spanned<f64>>,
    /// Contact point spacing as a fraction of the tool radius (default 0.5).
    pub point_spacing: Option<Spanned<f64>>,
    /// Speed limit of the simulated tool following the device (m/s, default 1).
    pub max_tool_speed_m_s: Option<Spanned<f64>>,
    /// Acceleration limit of the simulated tool (m/s^2, default 100).
    pub max_tool_accel_m_s2: Option<Spanned<f64>>,
    /// Near the tissue, how much faster than the hand the simulated tool
    /// may move when it catches up (m/s, default 0.02).
    pub entry_speed_m_s: Option<Spanned<f64>>,
    /// The linear tetrahedra within this distance of a tool's tip are
    /// corotational, the region following the tools (m; tensor-mass only).
    pub corotational_radius_m: Option<Spanned<f64>>,
    /// The tetrahedra within this distance of where a tool touches are
    /// refined while it is there and coarsened back when it leaves (m;
    /// tensor-mass only).
    pub refine_radius_m: Option<Spanned<f64>>,
    /// The cell size there (m; default: the smallest tool radius).
    pub refine_cell_m: Option<Spanned<f64>>,
    /// The most tetrahedra the refined mesh may have (default 300,000).
    pub refine_max_tets: Option<Spanned<usize>>,
    /// How the penalty springs are integrated (default: implicit).
    pub springs: Option<Spanned<SpringsName>>,
}

/// How the penalty springs are integrated, by name.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum SpringsName {
    /// At every sub-step with the tissue's forces (they size the sub-steps).
    Explicit,
    /// Linearly implicit at the end of each sub-step (they do not limit it).
    Implicit,
}

/// Backends by name.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum BackendName {
    /// Explicit tensor-mass.
    TensorMass,
    /// Precomputed (Cotin): static unit responses.
    Precomputed,
    /// Hybrid: a precomputed part joined to a cuttable tensor-mass part.
    Hybrid,
    /// Implicit backward Euler.
    Implicit,
}

impl BackendName {
    /// The name as scenes and `--backend` spell it (and the backend's own
    /// `Capabilities::name`).
    pub fn as_str(self) -> &'static str {
        match self {
            BackendName::TensorMass => "tensor-mass",
            BackendName::Precomputed => "precomputed",
            BackendName::Hybrid => "hybrid",
            BackendName::Implicit => "implicit",
        }
    }
}

/// Kernel precision names.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum PrecisionName {
    /// f32 tensor storage.
    F32,
    /// f64 tensor storage.
    F64,
}

/// dt policy names.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum DtPolicyName {
    /// Refuse a dt above the bound.
    Refuse,
    /// Sub-step.
    Substep,
    /// Use the step as given, even above the bound (stability experiments:
    /// a divergence is detected and the forces zeroed).
    Unchecked,
}

/// Bound names.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum BoundName {
    /// Irons' element bound.
    Element,
    /// Power iteration.
    PowerIteration,
}

/// `[simulation]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSpec {
    /// Backend (default tensor-mass).
    pub backend: Option<Spanned<BackendName>>,
    /// Step (s); default 90% of the stable step.
    pub dt_s: Option<Spanned<f64>>,
    /// Target simulation rate (Hz) for real-time runs.
    pub rate_hz: Option<Spanned<f64>>,
    /// Worker threads (default 1).
    pub threads: Option<Spanned<usize>>,
    /// Kernel storage precision (default f32).
    pub precision: Option<PrecisionName>,
    /// What to do when dt exceeds the bound (default substep).
    pub dt_policy: Option<DtPolicyName>,
    /// Which bound to enforce (default element).
    pub bound: Option<BoundName>,
    /// Sub-step only the vertices whose elements need a short step, the
    /// rest at a longer one (default false; tensor-mass backend only).
    pub multirate: Option<Spanned<bool>>,
}
