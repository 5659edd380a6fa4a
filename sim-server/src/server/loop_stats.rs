//! What the run loop measures of itself, one preallocated histogram per
//! duration ([`LoopHistogram`]: nothing allocated per step), and how it
//! goes into the run summary.

use super::RunSummary;
use sim_server::step_time::LoopHistogram;

/// The run loop's durations (ns).
#[derive(Default)]
pub(crate) struct LoopStats {
    /// The step after its pose (`step_us`).
    pub step: LoopHistogram,
    /// The same step's CPU time (`step_after_pose_cpu_us`).
    pub step_cpu: LoopHistogram,
    /// From the loop's wake-up to its force sample sent (`turnaround_us`).
    pub turnaround: LoopHistogram,
    /// The contact stiffness's hand-over after the sample (`hand_over_us`).
    pub hand_over: LoopHistogram,
    /// The rest of the step after its sample (`step_rest_us`).
    pub rest: LoopHistogram,
    /// From a new pose's device read to the loop's wake-up for it
    /// (`pose_wait_us`).
    pub pose_wait: LoopHistogram,
    /// The loop's CPU time per step, from one step's end to the next's
    /// (`step_cpu_us`).
    pub work_cpu: LoopHistogram,
    /// The loop's wall time per step's work, from its wake-up to the end
    /// of the next step's prediction (`step_work_us`).
    pub work: LoopHistogram,
    /// The first step on each mesh swapped in (`remesh_first_step_us`).
    pub first_after_swap: LoopHistogram,
    /// Whether the next step is the first on a mesh swapped in.
    pub swapped: bool,
}

impl LoopStats {
    /// The percentiles into `summary`'s `*_us` records.
    pub fn write_into(&self, summary: &mut RunSummary) {
        summary.step_us = self.step.percentiles_us();
        summary.step_cpu_us = self.work_cpu.percentiles_us();
        summary.step_after_pose_cpu_us = self.step_cpu.percentiles_us();
        summary.step_work_us = self.work.percentiles_us();
        summary.turnaround_us = self.turnaround.percentiles_us();
        summary.hand_over_us = self.hand_over.percentiles_us();
        summary.step_rest_us = self.rest.percentiles_us();
        summary.pose_wait_us = self.pose_wait.percentiles_us();
        summary.remesh_first_step_us = self.first_after_swap.percentiles_us();
    }
}
