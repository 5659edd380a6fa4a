//! The haptic daemon: reads the device, extrapolates the simulation's latest
//! force to the haptic rate, and commands the device safely.
#![warn(missing_docs)]

pub mod daemon;
pub mod device;
pub mod extrapolate;
pub mod io;
pub mod math;
pub mod record;
pub mod rt;
pub mod safety;
pub mod slots;
