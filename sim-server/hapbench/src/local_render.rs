//! `local-problem` as `hapbench extrapolation` renders it: the problems
//! through the wire as the server sends them, set up as the daemon's set-up
//! thread does, rendered at the haptic ticks as its RT thread does.

use haptic_daemon::extrapolate::local_problem::{LocalContactMsg, LocalProblem};
use haptic_daemon::extrapolate::{Extrapolator, ForceSample, Method};
use haptic_daemon::local_setup::{MAX_CATCH_UP, catch_up};
use haptic_daemon::pose_history::PoseHistory;
use sim_server::contact::LocalContact;
use sim_server::wire::{LOCAL_EVERY_S, local_contact_into, local_contact_msg};

/// `local-problem` rendered while the simulation runs (its problems are
/// too large to keep for the whole path): after step j, the ticks in the
/// window in which sample j is the newest delivered one. Twice: as the
/// daemon renders it by default (with the tissue's inertia the problem
/// carries) and with `--quasi-static` (`local-problem-quasi-static`).
pub(crate) struct LocalRender<'a> {
    lp: LocalProblem,
    quasi: LocalProblem,
    lc: LocalContact,
    msg: Box<LocalContactMsg>,
    fallback: Extrapolator,
    hand: &'a [[f64; 3]],
    haptic_s: f64,
    sim_s: f64,
    /// Transport delay of samples and problems (s).
    delay_s: f64,
    pub(crate) rendered: Vec<[f64; 3]>,
    pub(crate) quasi_rendered: Vec<[f64; 3]>,
    /// Wall time of each tick's render with inertia (ns), what the RT
    /// thread pays.
    pub(crate) render_ns: Vec<u64>,
    /// Wall time of each problem's set-up with its catch-up (ns), what the
    /// daemon's set-up thread pays.
    pub(crate) setup_ns: Vec<u64>,
    /// Simulated time of the last problem taken (s).
    last_problem_s: Option<f64>,
    /// The hand's positions at the ticks rendered so far, as the daemon's
    /// RT thread records them, and scratch to read them back.
    history: PoseHistory,
    poses: Vec<(u64, [f64; 3])>,
}

impl<'a> LocalRender<'a> {
    pub(crate) fn new(
        hand: &'a [[f64; 3]],
        haptic_s: f64,
        sim_s: f64,
        delay_s: f64,
        ticks: usize,
    ) -> Self {
        Self {
            lp: LocalProblem::new(),
            quasi: LocalProblem::new(),
            lc: LocalContact::default(),
            msg: Box::default(),
            fallback: Extrapolator::new(Method::LocalProblem),
            hand,
            haptic_s,
            sim_s,
            delay_s,
            rendered: Vec::with_capacity(ticks),
            quasi_rendered: Vec::with_capacity(ticks),
            render_ns: Vec::with_capacity(ticks),
            setup_ns: Vec::new(),
            last_problem_s: None,
            history: PoseHistory::default(),
            poses: Vec::with_capacity(MAX_CATCH_UP),
        }
    }

    /// After step `j` (its sample `sample`): the problem through the wire
    /// as the server sends it, set up as the daemon's set-up thread does,
    /// then the ticks until the next delivery.
    pub(crate) fn after_step<B: sim_server::backend::Backend>(
        &mut self,
        j: usize,
        sample: &ForceSample,
        tools: &mut sim_server::contact::Tools,
        sim: &B,
    ) {
        let ns = |t: f64| (t * 1e9).round() as u64;
        let delivered = ForceSample {
            t_ns: ns((j + 1) as f64 * self.sim_s),
            seq: j as u64,
            ..*sample
        };
        // The problems and the samples they render from are stamped with
        // the time of their state, as the live server stamps a problem:
        // the pose's time (here a period before delivery).
        let stated = ForceSample {
            t_ns: ns(j as f64 * self.sim_s),
            ..delivered
        };
        // At the server's pace: a problem at most every LOCAL_EVERY_S (a
        // newer sample is rendered from the last one), none when the
        // server would have none.
        let t_s = j as f64 * self.sim_s;
        if self
            .last_problem_s
            .is_some_and(|last| t_s - last < LOCAL_EVERY_S - 1e-9)
        {
        } else if local_contact_into(tools, sim, 0, &mut self.lc) {
            self.last_problem_s = Some(t_s);
            local_contact_msg(&self.lc, 0, j as u64, stated.t_ns, &mut self.msg);
            if self.quasi.set_from_wire(&self.msg).is_err() {
                self.quasi.clear();
            }
            // Set up as the daemon's set-up thread does: stepped through
            // the hand's positions since the problem's state (the ticks
            // rendered so far), the first render going on from there.
            let t0 = std::time::Instant::now();
            let ok = self.lp.set_from_wire(&self.msg).is_ok()
                && catch_up(
                    &mut self.lp,
                    &self.msg,
                    &self.history,
                    self.haptic_s,
                    &mut self.poses,
                )
                .is_ok();
            self.setup_ns.push(t0.elapsed().as_nanos() as u64);
            if !ok {
                self.lp.clear();
            }
        } else {
            self.lp.clear();
            self.quasi.clear();
        }
        // Ticks before the first delivery render nothing.
        while self.rendered.len() < self.hand.len()
            && (self.rendered.len() as f64) * self.haptic_s
                < (j + 1) as f64 * self.sim_s + self.delay_s - 1e-12
        {
            let k = self.rendered.len();
            self.history
                .push(ns(k as f64 * self.haptic_s), self.hand[k]);
            self.rendered.push([0.0; 3]);
            self.quasi_rendered.push([0.0; 3]);
        }
        self.fallback.push(&delivered);
        let end = (j + 2) as f64 * self.sim_s + self.delay_s - 1e-12;
        while self.rendered.len() < self.hand.len()
            && (self.rendered.len() as f64) * self.haptic_s < end
        {
            let k = self.rendered.len();
            let (p, now) = (self.hand[k], ns(k as f64 * self.haptic_s));
            self.history.push(now, p);
            let t0 = std::time::Instant::now();
            let f = self
                .lp
                .render(&stated, now, p, f64::INFINITY)
                .unwrap_or_else(|| self.fallback.force(now, p));
            self.render_ns.push(t0.elapsed().as_nanos() as u64);
            self.rendered.push(f);
            let f = self
                .quasi
                .render(&stated, now, p, f64::INFINITY)
                .unwrap_or_else(|| self.fallback.force(now, p));
            self.quasi_rendered.push(f);
        }
    }
}
