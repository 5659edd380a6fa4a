//! The refinement that follows the tools (`[contact] refine_radius_m`):
//! the cells within a radius of where each tool touches are bisected down
//! to the tool's radius while it is there, and coarsened back when it has
//! gone, so the tissue under a narrow instrument is fine enough for it and
//! the rest of the organ keeps its cells (issue 44; the space-adaptive
//! idea of Debunne, Desbrun, Cani and Barr 2001, "Dynamic real-time
//! deformations using space and time adaptive sampling", on the
//! longest-edge bisection of `tissue::mesh::refine`).
//!
//! Why this design: every refined mesh is made again from the scene's
//! mesh before refinement (the `BaseMesh`) for the spheres where the tools
//! are now, not by bisecting and merging the mesh in place. Bisection
//! breaks ties by position, so two refinements agree wherever both
//! spheres reach: under a tool that has moved a little, the new mesh has
//! the same elements as the old (`tissue::mesh::transfer` tests it), and
//! coarsening is nothing more than not refining there any more (no
//! history of splits to undo, as red-green closures or a split tree would
//! need). The new mesh then is one ordinary scene (materials, vessels'
//! fibres, fixed and loaded vertices, tools), built by the same code as at
//! start; the state moves across by rest position (`VertexTransfer`:
//! displacements and velocities, exact for fields linear on the old
//! elements, the shared vertices' values kept bit for bit), and the tools
//! keep their motion (`Tools::carry_from`).
//!
//! When: the material point under each tool (its tip's nearest vertex,
//! taken back to rest) is checked every [`CHECK_EVERY_S`] of simulated
//! time; the mesh is made again when one has moved more than a quarter of
//! the radius from the centre it was refined round, or a tool came within
//! the radius of the tissue or left it. So a tool always works at least
//! three quarters of the radius inside the refined cells. While a tool
//! grips or has cut, the mesh stays as it is (their state is on one mesh's
//! vertices and elements) and the report says so once.

use crate::contact::ContactError;
use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::mesh::transfer::{TransferError, VertexTransfer};
use crate::prepare::{PrepareError, Prepared, prepare};
use crate::scene::refine::{FollowScene, RefineAround};
use crate::scene::spec::SceneSpec;
use crate::scene::{BuiltScene, SceneError, SceneSource, build_scene_around};
use crate::tensor_mass::{Explicit, ExplicitError, Storage};
use thiserror::Error;

/// Simulated time between two looks at where the tools are (s).
pub const CHECK_EVERY_S: Real = 0.005;

/// How far (as a fraction of the radius) the material under a tool moves
/// from the centre it was refined round before the mesh follows it.
pub const MOVE_FRACTION: Real = 0.25;

/// Why the mesh could not follow the tools.
#[derive(Debug, Error)]
pub enum FollowError {
    /// The scene did not build on the refined mesh.
    #[error("the mesh refined round the tools: {0}")]
    Scene(#[from] SceneError),
    /// The integrator or the tools refused the refined mesh.
    #[error("the mesh refined round the tools: {0}")]
    Prepare(#[from] PrepareError<ExplicitError>),
    /// The state could not be carried to the refined mesh.
    #[error("the mesh refined round the tools: {0}")]
    Transfer(#[from] TransferError),
    /// The refined scene's tools are not the scene's.
    #[error("the mesh refined round the tools has {now} tools, not {before}")]
    Tools {
        /// Tools before.
        before: usize,
        /// Tools after.
        now: usize,
    },
}

impl From<ContactError> for FollowError {
    fn from(e: ContactError) -> Self {
        Self::Prepare(PrepareError::Contact(e))
    }
}

/// What the refinement that follows the tools has done.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FollowReport {
    /// Meshes made (not counting the first).
    pub rebuilds: u64,
    /// The mesh's tetrahedra now.
    pub tets: usize,
    /// Its vertices now.
    pub vertices: usize,
    /// The most tetrahedra a mesh has had.
    pub most_tets: usize,
    /// Spheres refined now (tools within the radius of the tissue).
    pub spheres: usize,
    /// Whether a refinement stopped at `refine_max_tets`.
    pub stopped_at_budget: bool,
    /// Why the mesh stayed once when it should have followed (a grip, a cut).
    pub pinned: Option<&'static str>,
    /// Wall time spent making meshes again, in all and the longest (s;
    /// this machine, this run: the scene built on the refined mesh, the
    /// integrator set up, the state carried).
    pub rebuild_wall_s: f64,
    /// The longest of them (s).
    pub longest_rebuild_wall_s: f64,
}

/// The refinement that follows a scene's tools, between steps.
pub struct FollowRefine {
    src: SceneSource,
    spec: SceneSpec,
    scene: FollowScene,
    /// Per tool, the centre (at rest) its sphere is refined round.
    centres: Vec<Option<Vec3>>,
    since_check_s: Real,
    report: FollowReport,
}

impl FollowRefine {
    /// The refinement `scene` asks for (`None` when it asks for none),
    /// taking the mesh it refines from `scene`. `src` is the scene it was
    /// built from.
    pub fn new(src: &SceneSource, scene: &mut BuiltScene) -> Result<Option<Self>, SceneError> {
        let Some(follow) = scene.follow.take() else {
            return Ok(None);
        };
        Ok(Some(Self {
            spec: src.parse()?,
            src: src.clone(),
            centres: vec![None; scene.tools.len()],
            since_check_s: Real::INFINITY,
            report: FollowReport {
                tets: scene.model.mesh().tet_count(),
                vertices: scene.model.vertex_count(),
                most_tets: scene.model.mesh().tet_count(),
                ..FollowReport::default()
            },
            scene: follow,
        }))
    }

    /// Per tool, the centre (in the mesh at rest, m) its cells are refined
    /// round now; `None` for a tool away from the tissue.
    pub fn centres(&self) -> &[Option<Vec3>] {
        &self.centres
    }

    /// What it has done so far.
    pub fn report(&self) -> &FollowReport {
        &self.report
    }

    /// After a step of `dt_s`: where the tools touch now, and if that has
    /// moved, `p` made again on a mesh refined there with its state
    /// carried over; `configure` is then applied to the new `p` (what the
    /// caller set on the old one: sub-step factor, stiffness solves, ...).
    /// Returns whether the mesh changed.
    pub fn follow<S: Storage>(
        &mut self,
        p: &mut Prepared<Explicit<S>>,
        dt_s: Real,
        configure: impl FnOnce(&mut Prepared<Explicit<S>>),
    ) -> Result<bool, FollowError> {
        self.since_check_s += dt_s;
        if self.since_check_s < CHECK_EVERY_S {
            return Ok(false);
        }
        self.since_check_s = 0.0;
        let wanted = self.wanted(p);
        if !self.moved(&wanted) {
            return Ok(false);
        }
        if let Some(why) = p.tools.pins_the_mesh() {
            self.report.pinned.get_or_insert(why);
            return Ok(false);
        }
        self.rebuild(p, wanted, configure)?;
        Ok(true)
    }

    /// Per tool, the material point under its tip taken back to rest, if
    /// the tip is within the radius of the tissue.
    fn wanted<S: Storage>(&self, p: &Prepared<Explicit<S>>) -> Vec<Option<Vec3>> {
        let rest = p.sim.model().mesh().positions_m();
        let u = p.sim.displacements();
        let r2 = self.scene.settings.radius_m.powi(2);
        (0..self.centres.len())
            .map(|i| {
                let tip = p.tools.tool(i).pose()?.end_m;
                let (v, d2) = (rest.iter().zip(u))
                    .map(|(x, d)| (*x + Vec3::from_array(*d)).distance_squared(tip))
                    .enumerate()
                    .min_by(|a, b| a.1.total_cmp(&b.1))?;
                (d2 <= r2).then(|| tip - Vec3::from_array(u[v]))
            })
            .collect()
    }

    fn moved(&self, wanted: &[Option<Vec3>]) -> bool {
        let step = MOVE_FRACTION * self.scene.settings.radius_m;
        (self.centres.iter().zip(wanted)).any(|(c, w)| match (c, w) {
            (None, None) => false,
            (Some(c), Some(w)) => c.distance(*w) > step,
            _ => true,
        })
    }

    fn rebuild<S: Storage>(
        &mut self,
        p: &mut Prepared<Explicit<S>>,
        wanted: Vec<Option<Vec3>>,
        configure: impl FnOnce(&mut Prepared<Explicit<S>>),
    ) -> Result<(), FollowError> {
        let started = std::time::Instant::now();
        let s = self.scene.settings;
        let around: Vec<RefineAround> = (wanted.iter().flatten())
            .map(|c| RefineAround {
                centre_m: *c,
                radius_m: s.radius_m,
                cell_m: s.cell_m,
                max_tets: s.max_tets,
            })
            .collect();
        let mut scene =
            build_scene_around(&self.src, &self.spec, self.scene.base.clone(), &around)?;
        if scene.tools.len() != p.tools.len() {
            return Err(FollowError::Tools {
                before: p.tools.len(),
                now: scene.tools.len(),
            });
        }
        self.report.stopped_at_budget |= scene.report.refined.iter().any(|r| r.stopped_at_budget);
        scene.follow = None;
        let mut next = prepare::<S>(scene, Some(p.dt_s))?;
        configure(&mut next);
        let transfer = VertexTransfer::new(p.sim.model().mesh(), next.sim.model().mesh())?;
        let u: Vec<Vec3> = (p.sim.displacements().iter())
            .map(|d| Vec3::from_array(*d))
            .collect();
        let v: Vec<Vec3> = (0..u.len())
            .map(|k| p.sim.velocity(VertexId::from(k)))
            .collect();
        next.sim
            .set_motion(&transfer.carry(&u), &transfer.carry(&v));
        next.tools.carry_from(&p.tools, &transfer.new_of_old());
        *p = next;
        self.centres = wanted;
        self.report.rebuilds += 1;
        self.report.tets = p.sim.model().mesh().tet_count();
        self.report.vertices = p.sim.model().vertex_count();
        self.report.most_tets = self.report.most_tets.max(self.report.tets);
        self.report.spheres = around.len();
        let wall_s = started.elapsed().as_secs_f64();
        self.report.rebuild_wall_s += wall_s;
        self.report.longest_rebuild_wall_s = self.report.longest_rebuild_wall_s.max(wall_s);
        Ok(())
    }
}
