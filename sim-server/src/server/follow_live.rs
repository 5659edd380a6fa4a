//! The refinement that follows the tools in the live loop (`[contact]
//! refine_radius_m`, `sim_server::follow_refine`): the loop looks where the
//! tools touch after each step, a worker thread makes the refined scene
//! (tens to a couple of hundred milliseconds on the liver, far longer than
//! a step), and the loop swaps it in at a step boundary, the state carried
//! across; the old integrator and tools go back to the worker to be
//! dropped (joining the old contact-stiffness worker is not the loop's
//! business). The worker runs under SCHED_IDLE, on whatever a core has
//! left after the loop and the haptic thread. One rebuild is in flight at a time; the tools keep moving
//! meanwhile within the refined sphere (a rebuild is asked when the
//! material under a tip has moved a quarter of the radius).

use sim_server::backend::Backend;
use sim_server::contact::Tools;
use sim_server::follow_refine::{Builder, FollowError, FollowReport, Follower, Rebuilt};
use sim_server::math::{Real, Vec3};
use sim_server::mesh::TetMesh;
use sim_server::prepare::Prepared;
use sim_server::tensor_mass::{Explicit, Storage};
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};

/// A mesh refinement that follows the tools of a running `B`.
pub trait LiveRemesh<B: Backend> {
    /// After a step of `dt_s`: a finished mesh swapped in (returns true),
    /// or a new one asked of the worker when the tools have moved.
    fn after_step(&mut self, sim: &mut B, tools: &mut Tools, dt_s: Real) -> bool;
    /// What it has done.
    fn report(&self) -> FollowReport;
}

enum Job<S: Storage> {
    Build {
        running: TetMesh,
        tools: usize,
        centres: Vec<Option<Vec3>>,
        dt_s: Real,
    },
    Drop(Box<(Explicit<S>, Tools)>),
}

/// [`LiveRemesh`] for the tensor-mass integrator, with its worker thread.
pub struct LiveFollow<S: Storage> {
    follower: Follower,
    jobs: Option<Sender<Job<S>>>,
    done: Receiver<Result<Rebuilt<S>, FollowError>>,
    worker: Option<std::thread::JoinHandle<()>>,
    in_flight: bool,
    /// A rebuild failed (said once): the mesh stays as it is.
    failed: bool,
}

impl<S: Storage> LiveFollow<S> {
    /// Starts the worker for `follower`.
    pub fn start(follower: Follower) -> std::io::Result<Self> {
        let (jobs, inbox) = channel::<Job<S>>();
        let (outbox, done) = channel();
        let builder: Builder = follower.builder().clone();
        let worker = std::thread::Builder::new()
            .name("follow-refine".into())
            .spawn(move || {
                // Best effort: at normal priority it only competes more.
                let _ = shared::rt::background();
                // The build's parallel parts (the elements' step bounds)
                // would otherwise run on rayon's global pool, whose threads
                // are at normal priority and took the loop's core.
                let pool = idle_pool().ok();
                while let Ok(job) = inbox.recv() {
                    match job {
                        Job::Build {
                            running,
                            tools,
                            centres,
                            dt_s,
                        } => {
                            let build = || builder.build::<S>(&running, tools, centres, dt_s);
                            let r = match &pool {
                                Some(pool) => pool.install(build),
                                None => build(),
                            };
                            if outbox.send(r).is_err() {
                                return;
                            }
                        }
                        Job::Drop(old) => drop(old),
                    }
                }
            })?;
        Ok(Self {
            follower,
            jobs: Some(jobs),
            done,
            worker: Some(worker),
            in_flight: false,
            failed: false,
        })
    }

    fn send(&mut self, job: Job<S>) {
        if let Some(j) = &self.jobs
            && j.send(job).is_err()
        {
            self.fail("the worker thread has gone");
        }
    }

    fn fail(&mut self, why: impl std::fmt::Display) {
        if !self.failed {
            eprintln!(
                "sim-server: the mesh cannot follow the tools any more ({why}); it stays as it is"
            );
        }
        self.failed = true;
    }
}

/// The worker's own rayon pool: one thread, under SCHED_IDLE (best
/// effort, as [`shared::rt::background`]), so that the parallel parts of a
/// build (`ElasticModel::element_lambdas`, 12 x 12 eigenproblems for every
/// element) run where the worker itself runs and not on the global pool's
/// threads at normal priority, which competed with the stepping loop for
/// its core (the step's p99 on the refined liver).
fn idle_pool() -> Result<rayon::ThreadPool, rayon::ThreadPoolBuildError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .thread_name(|_| "follow-refine-pool".into())
        .start_handler(|_| {
            let _ = shared::rt::background();
        })
        .build()
}

impl<S: Storage> LiveRemesh<Explicit<S>> for LiveFollow<S> {
    fn after_step(&mut self, sim: &mut Explicit<S>, tools: &mut Tools, dt_s: Real) -> bool {
        let mut swapped = false;
        match self.done.try_recv() {
            Ok(Ok(rebuilt)) => {
                self.in_flight = false;
                if tools.pins_the_mesh().is_some() {
                    // A grip or a cut since it was asked: it is of a mesh
                    // that no longer runs.
                    let Prepared { sim, tools, .. } = rebuilt.prepared;
                    self.send(Job::Drop(Box::new((sim, tools))));
                } else {
                    let old = self.follower.install(rebuilt, sim, tools);
                    self.send(Job::Drop(Box::new(old)));
                    swapped = true;
                }
            }
            Ok(Err(e)) => {
                self.in_flight = false;
                self.fail(e);
            }
            Err(TryRecvError::Empty) => {}
            Err(TryRecvError::Disconnected) => {
                if self.in_flight {
                    self.in_flight = false;
                    self.fail("the worker thread has gone");
                }
            }
        }
        if !self.in_flight
            && !self.failed
            && let Some(centres) = self.follower.due(sim, tools, dt_s)
        {
            self.in_flight = true;
            self.send(Job::Build {
                running: sim.model().mesh().clone(),
                tools: tools.len(),
                centres,
                dt_s: sim.dt_s(),
            });
        }
        swapped
    }

    fn report(&self) -> FollowReport {
        self.follower.report().clone()
    }
}

impl<S: Storage> Drop for LiveFollow<S> {
    fn drop(&mut self) {
        // Closing the jobs ends the worker once it has finished its job.
        self.jobs = None;
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::idle_pool;
    use rayon::prelude::*;

    /// Parallel work installed in the worker's pool stays on its one
    /// thread, and that thread is under SCHED_IDLE (which any thread may
    /// lower itself to on Linux).
    #[test]
    fn builds_run_on_one_idle_thread() {
        let pool = idle_pool().expect("a one-thread pool");
        let (threads, indices, policy) = pool.install(|| {
            let indices: Vec<Option<usize>> = (0..64)
                .into_par_iter()
                .map(|_| rayon::current_thread_index())
                .collect();
            // SAFETY: pid 0 = the calling thread; no pointers.
            let policy = unsafe { libc::sched_getscheduler(0) };
            (rayon::current_num_threads(), indices, policy)
        });
        assert_eq!(threads, 1);
        assert!(indices.iter().all(|i| *i == Some(0)), "{indices:?}");
        assert_eq!(policy, libc::SCHED_IDLE);
    }
}
