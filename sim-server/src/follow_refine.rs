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

/// The scene a refined mesh is made from: everything a rebuild needs,
/// movable to a worker thread.
#[derive(Clone)]
pub struct Builder {
    src: SceneSource,
    spec: std::sync::Arc<SceneSpec>,
    scene: FollowScene,
}

/// A scene made again on a mesh refined round the tools, ready to take
/// the running one's place ([`Follower::install`]).
pub struct Rebuilt<S: Storage> {
    /// The new integrator and tools (their state not yet carried).
    pub prepared: Prepared<Explicit<S>>,
    /// How the running mesh's vertices map onto the new one's.
    pub transfer: VertexTransfer,
    /// The centres it was refined round (per tool).
    pub centres: Vec<Option<Vec3>>,
    /// Whether the refinement stopped at `refine_max_tets`.
    pub stopped_at_budget: bool,
    /// Wall time it took (s).
    pub wall_s: f64,
}

impl Builder {
    /// The scene made again with the cells round `centres` refined, for
    /// taking over from a running integrator on `running` (its mesh) at
    /// step `dt_s`.
    pub fn build<S: Storage>(
        &self,
        running: &crate::mesh::TetMesh,
        tools: usize,
        centres: Vec<Option<Vec3>>,
        dt_s: Real,
    ) -> Result<Rebuilt<S>, FollowError> {
        let started = std::time::Instant::now();
        let s = self.scene.settings;
        let around: Vec<RefineAround> = (centres.iter().flatten())
            .map(|c| RefineAround {
                centre_m: *c,
                radius_m: s.radius_m,
                cell_m: s.cell_m,
                max_tets: s.max_tets,
            })
            .collect();
        let scene = build_scene_around(&self.src, &self.spec, self.scene.base.clone(), &around)?;
        if scene.tools.len() != tools {
            return Err(FollowError::Tools {
                before: tools,
                now: scene.tools.len(),
            });
        }
        let stopped_at_budget = scene.report.refined.iter().any(|r| r.stopped_at_budget);
        let prepared = prepare::<S>(scene, Some(dt_s))?;
        let transfer = VertexTransfer::new(running, prepared.sim.model().mesh())?;
        Ok(Rebuilt {
            prepared,
            transfer,
            centres,
            stopped_at_budget,
            wall_s: started.elapsed().as_secs_f64(),
        })
    }
}

/// Puts `new` in the place of the running `sim` and `tools`, their state
/// carried across (displacements and velocities by rest position, the
/// tools' motion); returns the old ones.
fn swap<S: Storage>(
    sim: &mut Explicit<S>,
    tools: &mut crate::contact::Tools,
    new: Prepared<Explicit<S>>,
    transfer: &VertexTransfer,
) -> (Explicit<S>, crate::contact::Tools) {
    let Prepared {
        sim: mut next_sim,
        tools: mut next_tools,
        ..
    } = new;
    let u: Vec<Vec3> = (sim.displacements().iter())
        .map(|d| Vec3::from_array(*d))
        .collect();
    let v: Vec<Vec3> = (0..u.len())
        .map(|k| sim.velocity(VertexId::from(k)))
        .collect();
    next_sim.set_motion(&transfer.carry(&u), &transfer.carry(&v));
    next_tools.carry_from(tools, &transfer.new_of_old());
    (
        std::mem::replace(sim, next_sim),
        std::mem::replace(tools, next_tools),
    )
}

/// When the mesh should follow the tools: the material under each tip,
/// looked at every [`CHECK_EVERY_S`].
pub struct Follower {
    builder: Builder,
    /// Per tool, the centre (at rest) its sphere is refined round.
    centres: Vec<Option<Vec3>>,
    since_check_s: Real,
    report: FollowReport,
}

impl Follower {
    /// The refinement `scene` asks for (`None` when it asks for none),
    /// taking the mesh it refines from `scene`. `src` is the scene it was
    /// built from.
    pub fn new(src: &SceneSource, scene: &mut BuiltScene) -> Result<Option<Self>, SceneError> {
        let Some(follow) = scene.follow.take() else {
            return Ok(None);
        };
        Ok(Some(Self {
            builder: Builder {
                spec: std::sync::Arc::new(src.parse()?),
                src: src.clone(),
                scene: follow,
            },
            centres: vec![None; scene.tools.len()],
            since_check_s: Real::INFINITY,
            report: FollowReport {
                tets: scene.model.mesh().tet_count(),
                vertices: scene.model.vertex_count(),
                most_tets: scene.model.mesh().tet_count(),
                ..FollowReport::default()
            },
        }))
    }

    /// What makes the meshes.
    pub fn builder(&self) -> &Builder {
        &self.builder
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

    /// After a step of `dt_s`: the centres the mesh should be refined round
    /// now, when they differ from the running mesh's (at most every
    /// [`CHECK_EVERY_S`]; `None` while a grip or a cut holds the mesh).
    pub fn due<B: crate::backend::Backend>(
        &mut self,
        sim: &B,
        tools: &crate::contact::Tools,
        dt_s: Real,
    ) -> Option<Vec<Option<Vec3>>> {
        self.since_check_s += dt_s;
        if self.since_check_s < CHECK_EVERY_S {
            return None;
        }
        self.since_check_s = 0.0;
        let wanted = self.wanted(sim, tools);
        if !self.moved(&wanted) {
            return None;
        }
        if let Some(why) = tools.pins_the_mesh() {
            self.report.pinned.get_or_insert(why);
            return None;
        }
        Some(wanted)
    }

    /// Puts `rebuilt` in the place of the running `sim` and `tools`, their
    /// state carried across (displacements and velocities by rest
    /// position, the tools' motion), and records it; returns the old ones.
    pub fn install<S: Storage>(
        &mut self,
        rebuilt: Rebuilt<S>,
        sim: &mut Explicit<S>,
        tools: &mut crate::contact::Tools,
    ) -> (Explicit<S>, crate::contact::Tools) {
        let started = std::time::Instant::now();
        let Rebuilt {
            prepared,
            transfer,
            centres,
            stopped_at_budget,
            wall_s,
        } = rebuilt;
        let old = swap(sim, tools, prepared, &transfer);
        let wall_s = wall_s + started.elapsed().as_secs_f64();
        let r = &mut self.report;
        r.rebuilds += 1;
        r.tets = sim.model().mesh().tet_count();
        r.vertices = sim.model().vertex_count();
        r.most_tets = r.most_tets.max(r.tets);
        r.spheres = centres.iter().flatten().count();
        r.stopped_at_budget |= stopped_at_budget;
        r.rebuild_wall_s += wall_s;
        r.longest_rebuild_wall_s = r.longest_rebuild_wall_s.max(wall_s);
        self.centres = centres;
        old
    }

    /// Per tool, the material point under its tip taken back to rest, if
    /// the tip is within the radius of the tissue.
    fn wanted<B: crate::backend::Backend>(
        &self,
        sim: &B,
        tools: &crate::contact::Tools,
    ) -> Vec<Option<Vec3>> {
        let rest = sim.model().mesh().positions_m();
        let u = sim.displacements();
        let r2 = self.builder.scene.settings.radius_m.powi(2);
        (0..self.centres.len())
            .map(|i| {
                let tip = tools.tool(i).pose()?.end_m;
                let (v, d2) = (rest.iter().zip(u))
                    .map(|(x, d)| (*x + Vec3::from_array(*d)).distance_squared(tip))
                    .enumerate()
                    .min_by(|a, b| a.1.total_cmp(&b.1))?;
                (d2 <= r2).then(|| tip - Vec3::from_array(u[v]))
            })
            .collect()
    }

    fn moved(&self, wanted: &[Option<Vec3>]) -> bool {
        let step = MOVE_FRACTION * self.builder.scene.settings.radius_m;
        (self.centres.iter().zip(wanted)).any(|(c, w)| match (c, w) {
            (None, None) => false,
            (Some(c), Some(w)) => c.distance(*w) > step,
            _ => true,
        })
    }
}

/// The refinement that follows a scene's tools, made between two steps on
/// the calling thread (offline: `hapbench extrapolation`, the examples;
/// deterministic).
pub struct FollowRefine {
    follower: Follower,
}

impl FollowRefine {
    /// The refinement `scene` asks for (`None` when it asks for none),
    /// taking the mesh it refines from `scene`. `src` is the scene it was
    /// built from.
    pub fn new(src: &SceneSource, scene: &mut BuiltScene) -> Result<Option<Self>, SceneError> {
        Ok(Follower::new(src, scene)?.map(|follower| Self { follower }))
    }

    /// Per tool, the centre (in the mesh at rest, m) its cells are refined
    /// round now; `None` for a tool away from the tissue.
    pub fn centres(&self) -> &[Option<Vec3>] {
        self.follower.centres()
    }

    /// What it has done so far.
    pub fn report(&self) -> &FollowReport {
        self.follower.report()
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
        let Some(centres) = self.follower.due(&p.sim, &p.tools, dt_s) else {
            return Ok(false);
        };
        let mut rebuilt = (self.follower.builder).build::<S>(
            p.sim.model().mesh(),
            p.tools.len(),
            centres,
            p.dt_s,
        )?;
        configure(&mut rebuilt.prepared);
        p.original_vertex_ids
            .clone_from(&rebuilt.prepared.original_vertex_ids);
        drop(self.follower.install(rebuilt, &mut p.sim, &mut p.tools));
        Ok(true)
    }
}
