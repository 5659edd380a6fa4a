//! Replay of a recorded trajectory: the device position follows the CSV
//! exactly, whatever force is rendered (open loop), for repeatable runs.

use super::{Device, DeviceError, DeviceSpecs, DeviceState, Trajectory};
use crate::math::V3;

/// A device that replays a trajectory.
pub struct Replay {
    trajectory: Trajectory,
    start_ns: Option<u64>,
    last: Option<(u64, V3)>,
    max_force_n: f64,
}

impl Replay {
    /// Replays `trajectory`; `max_force_n` is the limit it reports (no hardware).
    pub fn new(trajectory: Trajectory, max_force_n: f64) -> Self {
        Self {
            trajectory,
            start_ns: None,
            last: None,
            max_force_n,
        }
    }
}

impl Device for Replay {
    fn specs(&self) -> DeviceSpecs {
        DeviceSpecs {
            name: "replay",
            max_force_n: self.max_force_n,
            max_stiffness_n_per_m: super::SIMULATED_MAX_STIFFNESS_N_PER_M,
            workspace_min_m: [-1.0; 3],
            workspace_max_m: [1.0; 3],
        }
    }

    fn enable(&mut self, now_ns: u64) -> Result<(), DeviceError> {
        self.start_ns = Some(now_ns);
        Ok(())
    }

    fn disable(&mut self) {}

    fn read(&mut self, now_ns: u64) -> Result<DeviceState, DeviceError> {
        let start = *self.start_ns.get_or_insert(now_ns);
        let t_s = now_ns.saturating_sub(start) as f64 * 1e-9;
        let (p, jaw) = self.trajectory.sample(t_s);
        let velocity = match self.last {
            Some((t0, p0)) if now_ns > t0 => {
                let dt = (now_ns - t0) as f64 * 1e-9;
                std::array::from_fn(|d| (p[d] - p0[d]) / dt)
            }
            _ => [0.0; 3],
        };
        self.last = Some((now_ns, p));
        Ok(DeviceState {
            position_m: p,
            velocity_m_s: velocity,
            gripper: jaw,
            buttons: 0,
        })
    }

    fn write_force(&mut self, _force_n: V3, _now_ns: u64) -> Result<(), DeviceError> {
        Ok(())
    }
}
