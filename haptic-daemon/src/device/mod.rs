//! Haptic devices behind one trait. The daemon is generic over it (no `dyn`
//! in the loop); the command line picks one implementation at start.
//!
//! Contract for implementations used on the real-time thread: `read` and
//! `write_force` must not allocate, lock, or block; any I/O a device needs
//! happens on its own thread or in non-blocking calls.

mod haply;
mod plugin;
mod replay;
mod simulated;
mod trajectory;
mod workspace;
mod workspace_file;

pub use haply::{Haply, HaplyError, INVERSE3_MAX_FORCE_N, force_command, parse_state};
pub use plugin::{ABI_VERSION, Plugin, PluginError};
pub use replay::Replay;
pub use simulated::{HandModel, Path, Simulated};
pub use trajectory::{Trajectory, TrajectoryError};
pub use workspace::{Mapped, WorkspaceError, WorkspaceMap};
pub use workspace_file::{WorkspaceFileError, WorkspaceSpec};

use crate::math::V3;
use thiserror::Error;

/// Largest stiffness a 3D Systems Touch (Phantom Omni class) renders
/// stably (N/m). Its data sheet gives 1-2.3 N/mm per axis for the device's
/// own servo loop; behind a simulation, extrapolation and a 1 kHz loop,
/// about 400 N/m renders without buzz.
pub const TOUCH_MAX_STIFFNESS_N_PER_M: f64 = 400.0;
/// Largest stiffness a Novint Falcon renders stably (N/m), about 3 N/mm,
/// under the same conditions.
pub const FALCON_MAX_STIFFNESS_N_PER_M: f64 = 3000.0;
/// Largest stiffness a Force Dimension omega.x renders stably (N/m), about
/// 5 N/mm under the same conditions (its closed-loop stiffness on its own
/// controller is higher).
pub const OMEGA_MAX_STIFFNESS_N_PER_M: f64 = 5000.0;
/// The simulated and replayed devices' stiffness limit (N/m): a Falcon-class
/// device, the middle of the range above, so that what runs on them would
/// also run on common hardware.
pub const SIMULATED_MAX_STIFFNESS_N_PER_M: f64 = FALCON_MAX_STIFFNESS_N_PER_M;

/// The stiffness limit of a named device class (`touch`, `falcon`, `omega`;
/// N/m), for the command line.
pub fn max_stiffness_preset(name: &str) -> Option<f64> {
    match name {
        "touch" => Some(TOUCH_MAX_STIFFNESS_N_PER_M),
        "falcon" => Some(FALCON_MAX_STIFFNESS_N_PER_M),
        "omega" => Some(OMEGA_MAX_STIFFNESS_N_PER_M),
        _ => None,
    }
}

/// What a device can do, from its specifications.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeviceSpecs {
    /// Name for reports.
    pub name: &'static str,
    /// Largest force it may be commanded (N).
    pub max_force_n: f64,
    /// Largest stiffness it renders stably (N/m); the local model's
    /// stiffness is capped at it.
    pub max_stiffness_n_per_m: f64,
    /// Workspace bounds (m).
    pub workspace_min_m: V3,
    /// Workspace bounds (m).
    pub workspace_max_m: V3,
}

/// One reading of the device.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DeviceState {
    /// Handle position (m).
    pub position_m: V3,
    /// Handle velocity (m/s).
    pub velocity_m_s: V3,
    /// Gripper / jaw opening, 0 closed .. 1 open.
    pub gripper: f64,
    /// Button bits.
    pub buttons: u32,
}

/// A device failure.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DeviceError {
    /// The device reported a non-finite value.
    #[error("the device reported a non-finite {0}")]
    NonFinite(&'static str),
    /// The device is gone.
    #[error("the device is disconnected: {0}")]
    Disconnected(String),
}

/// A haptic device.
pub trait Device {
    /// Its specifications.
    fn specs(&self) -> DeviceSpecs;
    /// Enables force output (after the daemon has set up everything else).
    fn enable(&mut self, now_ns: u64) -> Result<(), DeviceError>;
    /// Commands zero force and disables output (every exit path calls it).
    fn disable(&mut self);
    /// Reads position, velocity, gripper and buttons at `now_ns`.
    fn read(&mut self, now_ns: u64) -> Result<DeviceState, DeviceError>;
    /// Commands a force (N); the daemon has already made it safe.
    fn write_force(&mut self, force_n: V3, now_ns: u64) -> Result<(), DeviceError>;
}
