//! Where the contact stiffness is computed: in the step, or on a worker
//! thread with the step publishing the latest result.
//!
//! The stiffness needs, for each newly touched vertex, three sparse solves
//! with the tissue's factor (5-7 ms on the embedded liver, this VM) and,
//! every step, a dense solve of three times the touched vertices (a
//! millisecond or more for a grasper's bite): in the step they were the
//! live simulation's longest steps (its p99.9, 5-8 ms against a 0.25 ms
//! median). The live simulation therefore runs the solver on a worker
//! thread ([`StiffnessSolves::Worker`]): each step hands it a snapshot of
//! the active contact points when it is idle and publishes the newest
//! result, a few steps old (a hand-over every [`HAND_OVER_EVERY_S`] in
//! contact). The worker keeps its own copy of the
//! tissue model (made at start-up, not in a step), brought up to date
//! after cuts from the tetrahedra's alive flags (copying the model itself
//! took 1-3 ms of the step on the liver), and builds the new factor.
//! Offline benchmarks and tests compute it in the step
//! ([`StiffnessSolves::Inline`]): exact for every step and independent of
//! thread timing. The snapshot buffers travel to the worker and back, so
//! neither side allocates per step once warm.

use crate::contact::local::LocalContact;
use crate::contact::penalty::field::ContactField;
use crate::contact::response::stiffness::{Snapshot, Solver};
use crate::ids::{TetId, VertexId};
use crate::math::{Mat3, Real};
use crate::tensor_mass::ElasticModel;
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};

/// In contact, the worker gets a new snapshot at most this often
/// (simulated s; and at once when a contact starts): each hand-over wakes
/// it, and on this VM waking a thread on the other core cost the stepping
/// thread 7% of its time when it happened every 1 ms step. K changes
/// slowly against the force, which every sample carries.
pub const HAND_OVER_EVERY_S: Real = 4e-3;

/// Where the contact stiffness is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StiffnessSolves {
    /// In the step: exact every step, deterministic (offline benchmarks,
    /// tests), at the price of long steps when a tool reaches new tissue.
    Inline,
    /// On a worker thread, the newest result published (the live
    /// simulation: no long step).
    Worker,
}

/// A snapshot to solve, with the tetrahedra's alive flags when a cut
/// changed them (else empty).
struct Job {
    snap: Snapshot,
    tools: usize,
    alive: Vec<bool>,
    /// A contact problem whose compliance to fill in.
    local: Option<Box<LocalContact>>,
}

/// A solved snapshot: its buffers back, and the stiffness per tool.
struct Done {
    snap: Snapshot,
    alive: Vec<bool>,
    stiffness: Vec<Mat3>,
    local: Option<Box<LocalContact>>,
}

/// The worker's channel ends.
struct Link {
    jobs: Sender<Job>,
    done: Receiver<Done>,
    /// A job is out.
    busy: bool,
    /// The model's `topology_changes` the worker has.
    sent_topology: u64,
    /// Simulated time since the last hand-over (s).
    waited_s: Real,
    /// Whether the last snapshot handed over had points in contact.
    touching: bool,
}

/// The contact stiffness of a scene's tools (see the module docs).
pub struct ContactStiffness {
    mode: StiffnessSolves,
    /// Inline: the solver. Worker: it until the worker starts (it moves
    /// there).
    solver: Option<Solver>,
    link: Option<Link>,
    /// The spare snapshot (filled and sent, or solved inline).
    snap: Snapshot,
    /// The spare alive-flags buffer.
    alive: Vec<bool>,
    /// Worker: the worker's copy of the model, until it starts.
    copy: Option<Box<ElasticModel>>,
    /// Per tool: the newest stiffness.
    newest: Vec<Mat3>,
    exact: bool,
    /// The scene's held vertices (to build a solver again).
    held: Vec<VertexId>,
    /// The newest contact problem with its compliance, not yet taken.
    local_ready: Option<Box<LocalContact>>,
    /// A contact problem's buffers to fill next.
    local_spare: Option<Box<LocalContact>>,
}

impl ContactStiffness {
    /// For `model` with `held` vertices fixed (the scene's fixed and
    /// prescribed ones); factorises K now unless the mesh is too large.
    /// Computed on a worker thread unless set otherwise
    /// ([`ContactStiffness::set_solves`]).
    pub fn new(model: &ElasticModel, held: &[VertexId]) -> Self {
        let solver = Solver::new(model, held);
        Self {
            mode: StiffnessSolves::Worker,
            exact: solver.exact(),
            solver: Some(solver),
            link: None,
            snap: Snapshot::default(),
            alive: Vec::new(),
            copy: Some(Box::new(model.clone())),
            newest: Vec::new(),
            held: held.to_vec(),
            local_ready: None,
            local_spare: None,
        }
    }

    /// Where it is computed from now on (a worker already started keeps
    /// the solver: then this has no effect).
    pub fn set_solves(&mut self, mode: StiffnessSolves) {
        if self.link.is_none() {
            self.mode = mode;
            if mode == StiffnessSolves::Inline {
                self.copy = None;
            }
        }
    }

    /// Whether K_eff uses the tissue's full compliance (else the diagonal
    /// blocks only).
    pub fn exact(&self) -> bool {
        self.exact
    }

    /// Where it is being computed now: `Worker` once the worker thread
    /// runs (it starts at the first step), else `Inline`.
    pub fn solves(&self) -> StiffnessSolves {
        if self.link.is_some() {
            StiffnessSolves::Worker
        } else {
            StiffnessSolves::Inline
        }
    }

    /// Takes in the step's contact (`field`, `tools` tools) on `model`,
    /// `dt_s` after the previous one. With `local`, a contact problem is
    /// made alongside the stiffness: `local` fills its points (false: none
    /// now) when a snapshot is solved, and the solver adds the compliance
    /// ([`ContactStiffness::take_local`] gives it when done).
    pub fn update(
        &mut self,
        model: &ElasticModel,
        field: &ContactField,
        tools: usize,
        dt_s: Real,
        local: Option<&mut dyn FnMut(&mut LocalContact) -> bool>,
    ) {
        self.newest.resize(tools, Mat3::ZERO);
        if self.mode == StiffnessSolves::Worker && self.link.is_none() {
            self.start(model);
        }
        if self.link.is_none() {
            // Inline (or no worker could be started).
            if let Some(solver) = &mut self.solver {
                self.snap.fill(field);
                for (t, k) in self.newest.iter_mut().enumerate() {
                    *k = solver.stiffness(model, &self.snap, t);
                }
                if let Some(make) = local {
                    let mut lc = self.local_spare.take().unwrap_or_default();
                    let solved = make(&mut lc) && solver.solve_local(model, &mut lc);
                    if solved {
                        keep_local(&mut self.local_ready, &mut self.local_spare, lc);
                    } else {
                        self.local_spare = Some(lc);
                    }
                }
            }
            return;
        }
        if self.receive().is_err() {
            // The worker died (a panic in the solver): keep the last
            // stiffness rather than take the step down; later ones in the
            // step.
            self.link = None;
            self.mode = StiffnessSolves::Inline;
            self.solver = Some(Solver::new(model, &self.held));
            return;
        }
        let Some(link) = &mut self.link else {
            return;
        };
        link.waited_s += dt_s;
        let touching = field.penetrations_m().iter().any(|d| *d > 0.0);
        if !touching {
            // No contact: no stiffness, and nothing for the worker.
            self.newest.fill(Mat3::ZERO);
        }
        // A contact problem is wanted near the surface too (the tool
        // approaching): then a hand-over at the same pace in contact or not.
        let due = touching != link.touching
            || ((touching || local.is_some()) && link.waited_s >= HAND_OVER_EVERY_S);
        if !link.busy && due {
            link.waited_s = 0.0;
            link.touching = touching;
            self.snap.fill(field);
            let topology = model.topology_changes();
            self.alive.clear();
            if topology != link.sent_topology {
                self.alive.extend_from_slice(model.topology().alive());
            }
            link.sent_topology = topology;
            let local = local.and_then(|make| {
                let mut lc = self.local_spare.take().unwrap_or_default();
                if make(&mut lc) {
                    Some(lc)
                } else {
                    self.local_spare = Some(lc);
                    None
                }
            });
            let job = Job {
                snap: std::mem::take(&mut self.snap),
                tools,
                alive: std::mem::take(&mut self.alive),
                local,
            };
            link.busy = link.jobs.send(job).is_ok();
        }
    }

    /// Adds the tissue's compliance at the problem's vertices to `lc`
    /// (and, with its velocities taken, the column mass: see
    /// [`LocalContact`]) now; false when there is none to give: the solver
    /// runs on the worker thread, or the mesh is too large for a factor.
    pub fn solve_local(&mut self, model: &ElasticModel, lc: &mut LocalContact) -> bool {
        match (&self.link, &mut self.solver) {
            (None, Some(solver)) => solver.solve_local(model, lc),
            _ => false,
        }
    }

    /// Takes in the worker's finished job, if any; an error when the
    /// worker died.
    fn receive(&mut self) -> Result<(), TryRecvError> {
        let Some(link) = &mut self.link else {
            return Ok(());
        };
        match link.done.try_recv() {
            Ok(done) => {
                self.snap = done.snap;
                self.alive = done.alive;
                for (k, d) in self.newest.iter_mut().zip(done.stiffness) {
                    *k = d;
                }
                link.busy = false;
                if let Some(lc) = done.local {
                    if lc.compliance_m_per_n.is_empty() {
                        self.local_spare = Some(lc);
                    } else {
                        keep_local(&mut self.local_ready, &mut self.local_spare, lc);
                    }
                }
                Ok(())
            }
            Err(TryRecvError::Empty) => Ok(()),
            Err(e) => Err(e),
        }
    }

    /// The newest contact problem with its compliance (see
    /// [`ContactStiffness::update`]), once; give its buffers back with
    /// [`ContactStiffness::recycle_local`].
    /// Between steps too: a job the worker finished since the step is
    /// taken in (a dead worker is seen by the next step).
    pub fn take_local(&mut self) -> Option<Box<LocalContact>> {
        let _ = self.receive();
        self.local_ready.take()
    }

    /// Buffers for the next contact problem.
    pub fn recycle_local(&mut self, lc: Box<LocalContact>) {
        self.local_spare = Some(lc);
    }

    /// The newest stiffness of tool `tool` (N/m).
    pub fn stiffness(&self, tool: usize) -> Mat3 {
        self.newest.get(tool).copied().unwrap_or(Mat3::ZERO)
    }

    /// Starts the worker with the solver and a copy of `model`; stays
    /// inline if the thread cannot start.
    fn start(&mut self, model: &ElasticModel) {
        let Some(mut solver) = self.solver.take() else {
            return;
        };
        // The copy made at start-up, or (switched back from inline) one
        // made now, once.
        let mut own = self.copy.take().unwrap_or_else(|| Box::new(model.clone()));
        let (jobs, inbox) = channel::<Job>();
        let (outbox, done) = channel::<Done>();
        let mut results = Vec::new();
        let spawned = std::thread::Builder::new()
            .name("contact-stiffness".into())
            .spawn(move || {
                crate::background::lower_this_thread();
                while let Ok(job) = inbox.recv() {
                    follow_cuts(&mut own, &job.alive);
                    results.clear();
                    for t in 0..job.tools {
                        results.push(solver.stiffness(&own, &job.snap, t));
                    }
                    let mut local = job.local;
                    if let Some(lc) = local.as_deref_mut()
                        && !solver.solve_local(&own, lc)
                    {
                        lc.compliance_m_per_n.clear();
                    }
                    let reply = Done {
                        snap: job.snap,
                        alive: job.alive,
                        stiffness: std::mem::take(&mut results),
                        local,
                    };
                    if outbox.send(reply).is_err() {
                        return;
                    }
                }
            });
        match spawned {
            Ok(_) => {
                self.link = Some(Link {
                    jobs,
                    done,
                    busy: false,
                    // The copy was made at start-up: the first job
                    // brings it up to date.
                    sent_topology: u64::MAX,
                    waited_s: 0.0,
                    touching: false,
                });
            }
            Err(_) => {
                // The closure (and the solver in it) is gone: build one
                // and stay inline.
                self.mode = StiffnessSolves::Inline;
                self.solver = Some(Solver::new(model, &self.held));
            }
        }
    }
}

/// Keeps `lc` as the newest problem in `ready` (an older one not taken
/// becomes the `spare`).
fn keep_local(
    ready: &mut Option<Box<LocalContact>>,
    spare: &mut Option<Box<LocalContact>>,
    lc: Box<LocalContact>,
) {
    if let Some(old) = ready.replace(lc) {
        *spare = Some(old);
    }
}

/// Removes from (restores to) `own` the tetrahedra `alive` says are dead
/// (alive); nothing when `alive` is empty (no cut since the last job).
fn follow_cuts(own: &mut ElasticModel, alive: &[bool]) {
    for (t, &a) in alive.iter().enumerate() {
        let id = TetId::from(t);
        match (own.topology().is_alive(id), a) {
            (true, false) => {
                let _ = own.remove_tet(id);
            }
            (false, true) => {
                let _ = own.restore_tet(id);
            }
            _ => {}
        }
    }
}
