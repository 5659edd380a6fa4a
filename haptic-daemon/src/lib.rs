//! The haptic daemon: reads the device, extrapolates the simulation's latest
//! force to the haptic rate, and commands the device safely.
//!
//! Per tick ([`daemon`]): the device sample must be plausible for a hand
//! ([`plausible`]), force samples must arrive at real rate ([`live`]), the
//! [`extrapolate`] local model is unilateral and capped at the device's
//! stiffness, and the [`safety`] filter clamps, slew-limits, ramps and keeps
//! the rendered environment passive. All of it pure, allocation-free and
//! with time passed in.
#![warn(missing_docs)]

pub mod daemon;
pub mod device;
pub mod extrapolate;
pub mod io;
pub mod live;
pub mod local_setup;
pub mod math;
pub mod plausible;
pub mod pose_history;
pub mod record;
pub mod rt;
pub mod safety;
pub mod slots;
pub mod transport;
