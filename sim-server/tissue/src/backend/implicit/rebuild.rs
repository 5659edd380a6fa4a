//! The background factor rebuild: one long-lived worker thread per backend
//! that factorises A off the stepping thread.
//!
//! Ownership. The stepping thread owns the factor in use and one
//! [`Snapshot`] (the arrays A is assembled from, allocated once at
//! construction). To ask for a factor it copies the model's arrays and the
//! held set into the snapshot (no allocation: the lengths never grow) and
//! moves the snapshot into the shared [`State`]'s `job` slot; the worker
//! takes it, factorises without holding the lock, and puts the snapshot back
//! with the new factor into `done`. At the start of a later step the stepping
//! thread takes `done`, swaps the factor in and moves the old one into
//! `retired`, which the worker drops (so freeing it costs the step nothing
//! either). At most one job is in flight. The lock is only ever held to move
//! these slots, and the stepping thread only `try_lock`s it: when the worker
//! happens to hold it, the step carries on and tries again next step, so a
//! step never waits for the worker.
//!
//! A factor is the inverse of A for the held set and tensors of its
//! snapshot; it records which rows that set left free, and the
//! preconditioner compares that with the current held set every time it is
//! applied ([`Factor::apply`]), so a factor that arrives after more holds,
//! releases or cuts is used exactly as a factor that has aged in place.
//!
//! Dropping the [`Rebuilder`] sets `shutdown`, wakes the worker (also past a
//! closed test gate) and joins it: a factorisation under way finishes first.

use super::factor::{Assembly, Factor};
use crate::ids::VertexId;
use crate::math::{Mat3, Real};
use crate::tensor_mass::ElasticModel;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, TryLockError, Weak};
use std::thread::JoinHandle;

/// A copy of what A is assembled from, for the worker.
pub(super) struct Snapshot {
    held: Vec<bool>,
    masses_kg: Vec<Real>,
    damping_kg_s: Vec<Real>,
    vertex_tensors: Vec<Mat3>,
    edges: Vec<[VertexId; 2]>,
    edge_tensors: Vec<Mat3>,
}

impl Snapshot {
    fn new(model: &ElasticModel) -> Self {
        let mut s = Self {
            held: Vec::new(),
            masses_kg: Vec::new(),
            damping_kg_s: Vec::new(),
            vertex_tensors: Vec::new(),
            edges: Vec::new(),
            edge_tensors: Vec::new(),
        };
        s.fill(model, &vec![false; model.vertex_count()]);
        s
    }

    /// Copies the model's arrays and `held`; allocates nothing once the
    /// buffers have these lengths (cuts zero tensors, they never add any).
    fn fill(&mut self, model: &ElasticModel, held: &[bool]) {
        fn copy<T: Copy>(to: &mut Vec<T>, from: &[T]) {
            to.clear();
            to.extend_from_slice(from);
        }
        copy(&mut self.held, held);
        copy(&mut self.masses_kg, model.masses_kg());
        copy(&mut self.damping_kg_s, model.damping_kg_s());
        copy(&mut self.vertex_tensors, model.vertex_tensors());
        copy(&mut self.edges, model.topology().edges());
        copy(&mut self.edge_tensors, model.edge_tensors());
    }

    fn assembly(&self) -> Assembly<'_> {
        Assembly {
            masses_kg: &self.masses_kg,
            damping_kg_s: &self.damping_kg_s,
            vertex_tensors: &self.vertex_tensors,
            edges: &self.edges,
            edge_tensors: &self.edge_tensors,
        }
    }
}

/// What the two threads hand each other.
struct State {
    /// Posted by the stepping thread, taken by the worker.
    job: Option<Snapshot>,
    /// The worker's answer (with the snapshot back, for reuse).
    done: Option<(Snapshot, Result<Factor, String>)>,
    /// A factor swapped out, for the worker to drop.
    retired: Option<Factor>,
    /// Test gate: while closed the worker holds a job without factorising.
    gate_closed: bool,
    shutdown: bool,
}

struct Shared {
    state: Mutex<State>,
    /// Wakes the worker: a job, a retired factor, the gate, shutdown.
    wake: Condvar,
    /// Wakes [`Rebuilder::wait`]: an answer is in `done`.
    answered: Condvar,
}

impl Shared {
    /// Blocking lock (the worker, drop, tests). The state stays consistent
    /// through a panic (slots are only moved), so poisoning is ignored.
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The stepping thread's lock: `None` when the worker holds it.
    fn try_lock(&self) -> Option<MutexGuard<'_, State>> {
        match self.state.try_lock() {
            Ok(g) => Some(g),
            Err(TryLockError::Poisoned(e)) => Some(e.into_inner()),
            Err(TryLockError::WouldBlock) => None,
        }
    }
}

/// A factor received from the worker.
pub(super) enum Received {
    /// Swapped in (the old one went to the worker to be dropped).
    Swapped,
    /// The factorisation failed (as inline, the reason is not kept); the
    /// old factor was retired as well.
    Failed,
}

/// The stepping thread's side of the worker.
pub(super) struct Rebuilder {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    /// Held by the worker thread while it runs (tests watch it end).
    alive: Weak<()>,
    /// The snapshot buffers when no job is in flight.
    spare: Option<Snapshot>,
}

impl Rebuilder {
    /// Starts the worker for steps of `h`; `Err` if the thread cannot be
    /// created (the backend then rebuilds inline).
    pub fn new(model: &ElasticModel, h: Real) -> std::io::Result<Self> {
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                job: None,
                done: None,
                retired: None,
                gate_closed: false,
                shutdown: false,
            }),
            wake: Condvar::new(),
            answered: Condvar::new(),
        });
        let token = Arc::new(());
        let alive = Arc::downgrade(&token);
        let worker = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("implicit-factor".into())
            .spawn(move || {
                crate::background::lower_this_thread();
                let _token = token;
                work(&worker, h);
            })?;
        Ok(Self {
            shared,
            thread: Some(thread),
            alive,
            spare: Some(Snapshot::new(model)),
        })
    }

    /// A job has been posted and its answer not yet received.
    pub fn in_flight(&self) -> bool {
        self.spare.is_none()
    }

    /// Posts a job for the model's current tensors and `held`; `false` (try
    /// again next step) if one is in flight or the worker holds the lock.
    /// Never blocks, never allocates.
    pub fn request(&mut self, model: &ElasticModel, held: &[bool]) -> bool {
        if self.spare.is_none() {
            return false;
        }
        let Some(mut state) = self.shared.try_lock() else {
            return false;
        };
        if state.shutdown {
            return false;
        }
        let mut snapshot = self.spare.take().expect("checked above");
        // Copied under the lock: the worker is idle or dropping a retired
        // factor, and it never needs the lock while factorising.
        snapshot.fill(model, held);
        state.job = Some(snapshot);
        drop(state);
        self.shared.wake.notify_one();
        true
    }

    /// If the worker has answered, swaps its factor into `current` (the old
    /// one is handed to the worker to drop). Never blocks, never allocates.
    pub fn receive(&mut self, current: &mut Option<Factor>) -> Option<Received> {
        if self.spare.is_some() {
            return None;
        }
        let mut state = self.shared.try_lock()?;
        let (snapshot, result) = state.done.take()?;
        self.spare = Some(snapshot);
        let received = match result {
            Ok(factor) => {
                state.retired = current.replace(factor);
                Received::Swapped
            }
            Err(_) => {
                state.retired = current.take();
                Received::Failed
            }
        };
        drop(state);
        self.shared.wake.notify_one();
        Some(received)
    }

    /// Blocks until the job in flight (if any) has been answered; the answer
    /// is swapped in by the next step. Deadlocks if the gate is closed.
    pub fn wait(&self) {
        if self.spare.is_some() {
            return;
        }
        let mut state = self.shared.lock();
        while state.done.is_none() && !state.shutdown {
            state = self
                .shared
                .answered
                .wait(state)
                .unwrap_or_else(|e| e.into_inner());
        }
    }

    /// Closes or opens the test gate.
    pub fn gate(&self) -> RebuildGate {
        RebuildGate {
            shared: Arc::downgrade(&self.shared),
        }
    }

    /// Upgrades while the worker thread runs.
    pub fn alive(&self) -> Weak<()> {
        self.alive.clone()
    }
}

impl Drop for Rebuilder {
    fn drop(&mut self) {
        self.shared.lock().shutdown = true;
        self.shared.wake.notify_all();
        if let Some(thread) = self.thread.take() {
            // A panic in the worker has been reported already.
            let _ = thread.join();
        }
    }
}

/// The worker: waits for jobs and factorises them, until shutdown.
fn work(shared: &Shared, h: Real) {
    let mut state = shared.lock();
    loop {
        if let Some(old) = state.retired.take() {
            // Freed without the lock: the step may want it meanwhile.
            drop(state);
            drop(old);
            state = shared.lock();
            continue;
        }
        if state.shutdown {
            return;
        }
        if state.job.is_none() || state.gate_closed {
            state = shared.wake.wait(state).unwrap_or_else(|e| e.into_inner());
            continue;
        }
        let snapshot = state.job.take().expect("checked above");
        drop(state);
        // A panic inside faer must not leave the step waiting for an answer
        // for ever: it becomes a failed build (the backend goes to Jacobi).
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            Factor::new(&snapshot.assembly(), h, &snapshot.held)
        }))
        .unwrap_or_else(|_| Err("the factorisation panicked".into()));
        state = shared.lock();
        state.done = Some((snapshot, result));
        shared.answered.notify_all();
    }
}

/// A test handle on the worker's gate (see [`super::Implicit::rebuild_gate`]).
#[doc(hidden)]
#[derive(Clone)]
pub struct RebuildGate {
    shared: Weak<Shared>,
}

impl RebuildGate {
    /// While closed, a posted rebuild stays in flight without being worked on.
    pub fn close(&self) {
        if let Some(shared) = self.shared.upgrade() {
            shared.lock().gate_closed = true;
        }
    }

    /// Lets the worker factorise again.
    pub fn open(&self) {
        if let Some(shared) = self.shared.upgrade() {
            shared.lock().gate_closed = false;
            shared.wake.notify_all();
        }
    }
}
