//! The step-time statistics of a run: the loop's durations in
//! [`LoopHistogram`]s (shared with the haptic daemon; preallocated, nothing
//! per sample), summarised as [`StepPercentiles`] (`step_us` and the other
//! `*_us` records of the run summary).

pub use shared::loop_stats::{LoopHistogram, PercentilesUs as StepPercentiles};
