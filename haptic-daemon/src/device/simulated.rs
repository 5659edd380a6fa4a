//! A simulated device: a hand modelled as a mass held by a spring and damper
//! to a scripted path (a CSV trajectory or a built-in slow poke), so that the
//! rendered forces push back on it like on a real hand. No hardware needed.

use super::{Device, DeviceError, DeviceSpecs, DeviceState, Trajectory};
use crate::math::V3;

/// Hand parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HandModel {
    /// Effective mass of hand and handle (kg).
    pub mass_kg: f64,
    /// Grip stiffness towards the intended path (N/m).
    pub stiffness_n_per_m: f64,
    /// Grip damping (N s/m).
    pub damping_n_s_per_m: f64,
}

impl Default for HandModel {
    /// A relaxed grip: 0.3 kg, 300 N/m, critically damped (about 19 N s/m).
    fn default() -> Self {
        let (m, k) = (0.3, 300.0);
        Self {
            mass_kg: m,
            stiffness_n_per_m: k,
            damping_n_s_per_m: 2.0 * (k * m).sqrt(),
        }
    }
}

/// The intended path of the hand.
#[derive(Clone, Debug, PartialEq)]
pub enum Path {
    /// A CSV trajectory.
    Trajectory(Trajectory),
    /// Moves along `direction` from `start_m` by `depth_m * (1 - cos(2 pi t / period_s)) / 2`.
    Poke {
        /// Rest point (m).
        start_m: V3,
        /// Unit direction.
        direction: V3,
        /// Peak excursion (m).
        depth_m: f64,
        /// Period (s).
        period_s: f64,
    },
}

/// The built-in poke's start: its tip's lowest point this far above the
/// organ's top (m).
const POKE_ABOVE_M: f64 = 0.003;
/// The built-in poke's depth below the organ's top: this fraction of the
/// organ's height, at most [`POKE_MAX_BELOW_M`].
const POKE_BELOW_OF_HEIGHT: f64 = 0.3;
/// The deepest the built-in poke presses below the organ's top (m).
const POKE_MAX_BELOW_M: f64 = 0.027;
/// The built-in poke's period (s).
const POKE_PERIOD_S: f64 = 4.0;

impl Path {
    /// The built-in poke when the scene is not known: straight down the z
    /// axis from z = 50 mm to 20 mm and back every 4 s (the embedded
    /// liver's top is at 47 mm).
    pub fn default_poke() -> Self {
        Path::Poke {
            start_m: [0.0, 0.0, 0.05],
            direction: [0.0, 0.0, -1.0],
            depth_m: 0.03,
            period_s: POKE_PERIOD_S,
        }
    }

    /// The built-in poke aimed at an organ whose rest bounding box is
    /// `min_m`..`max_m` (the simulation's `SceneInfo`) with a tool whose
    /// tip has radius `tip_radius_m` (the pose is the centre of its round
    /// end): straight down over the box's centre, from the tip's lowest
    /// point 3 mm clear of the box's top (so the contact's onset is seen)
    /// to the pose 30% of the box's height below the top (at most 27 mm),
    /// and back every 4 s. On the embedded liver this is
    /// [`Path::default_poke`] within 0.2 mm, started higher by the radius.
    /// `None` for a box that is not finite or not ordered.
    pub fn poke_over(min_m: V3, max_m: V3, tip_radius_m: f64) -> Option<Self> {
        let ordered =
            (0..3).all(|d| min_m[d].is_finite() && max_m[d].is_finite() && min_m[d] <= max_m[d]);
        if !ordered {
            return None;
        }
        // A radius the simulation would not send (NaN, negative, absurd)
        // is taken as a point tip.
        let radius = if tip_radius_m.is_finite() && (0.0..=0.1).contains(&tip_radius_m) {
            tip_radius_m
        } else {
            0.0
        };
        let height = max_m[2] - min_m[2];
        let below = (POKE_BELOW_OF_HEIGHT * height).min(POKE_MAX_BELOW_M);
        Some(Path::Poke {
            start_m: [
                0.5 * (min_m[0] + max_m[0]),
                0.5 * (min_m[1] + max_m[1]),
                max_m[2] + radius + POKE_ABOVE_M,
            ],
            direction: [0.0, 0.0, -1.0],
            depth_m: radius + POKE_ABOVE_M + below,
            period_s: POKE_PERIOD_S,
        })
    }

    /// This path, given in the scene, in the frame of a device that `map`
    /// places there: the built-in poke aims at the same scene points
    /// through the map; a trajectory is the device's own already
    /// (unchanged).
    pub fn in_device_frame(self, map: &super::WorkspaceMap) -> Self {
        match self {
            Path::Poke {
                start_m,
                direction,
                depth_m,
                period_s,
            } => Path::Poke {
                start_m: map.to_device(start_m),
                direction: map.direction_to_device(direction),
                depth_m: depth_m / map.scale,
                period_s,
            },
            t @ Path::Trajectory(_) => t,
        }
    }

    fn at(&self, t_s: f64) -> (V3, f64) {
        match self {
            Path::Trajectory(t) => t.sample(t_s),
            Path::Poke {
                start_m,
                direction,
                depth_m,
                period_s,
            } => {
                let s = depth_m * 0.5 * (1.0 - (std::f64::consts::TAU * t_s / period_s).cos());
                (std::array::from_fn(|d| start_m[d] + s * direction[d]), 1.0)
            }
        }
    }
}

/// The simulated device.
pub struct Simulated {
    hand: HandModel,
    path: Path,
    start_ns: Option<u64>,
    last_ns: u64,
    position_m: V3,
    velocity_m_s: V3,
    force_n: V3,
    gripper: f64,
    max_force_n: f64,
}

impl Simulated {
    /// A simulated device following `path` with `hand`, reporting `max_force_n`.
    pub fn new(path: Path, hand: HandModel, max_force_n: f64) -> Self {
        let (p0, jaw) = path.at(0.0);
        Self {
            hand,
            path,
            start_ns: None,
            last_ns: 0,
            position_m: p0,
            velocity_m_s: [0.0; 3],
            force_n: [0.0; 3],
            gripper: jaw,
            max_force_n,
        }
    }

    /// Advances the hand to `now_ns`: m a = k (target - x) - c v + F_rendered,
    /// semi-implicit Euler in steps of at most 0.5 ms (stable far beyond it).
    fn advance(&mut self, now_ns: u64) {
        let start = *self.start_ns.get_or_insert(now_ns);
        if self.last_ns == 0 {
            self.last_ns = now_ns;
        }
        let mut remaining = now_ns.saturating_sub(self.last_ns) as f64 * 1e-9;
        // A stalled caller (a debugger, SIGSTOP) must not make the hand jump.
        remaining = remaining.min(0.05);
        let h = &self.hand;
        while remaining > 0.0 {
            let dt = remaining.min(5e-4);
            remaining -= dt;
            let t_s = (self.last_ns.saturating_sub(start)) as f64 * 1e-9;
            let (target, jaw) = self.path.at(t_s);
            self.gripper = jaw;
            #[allow(clippy::needless_range_loop)] // three parallel arrays indexed together
            for d in 0..3 {
                let a = (h.stiffness_n_per_m * (target[d] - self.position_m[d])
                    - h.damping_n_s_per_m * self.velocity_m_s[d]
                    + self.force_n[d])
                    / h.mass_kg;
                self.velocity_m_s[d] += a * dt;
                self.position_m[d] += self.velocity_m_s[d] * dt;
            }
            self.last_ns += (dt * 1e9) as u64;
        }
        self.last_ns = now_ns;
    }
}

impl Device for Simulated {
    fn specs(&self) -> DeviceSpecs {
        DeviceSpecs {
            name: "simulated",
            max_force_n: self.max_force_n,
            max_stiffness_n_per_m: super::SIMULATED_MAX_STIFFNESS_N_PER_M,
            workspace_min_m: [-0.3; 3],
            workspace_max_m: [0.3; 3],
        }
    }

    fn enable(&mut self, now_ns: u64) -> Result<(), DeviceError> {
        self.start_ns = Some(now_ns);
        self.last_ns = now_ns;
        Ok(())
    }

    fn disable(&mut self) {
        self.force_n = [0.0; 3];
    }

    fn read(&mut self, now_ns: u64) -> Result<DeviceState, DeviceError> {
        self.advance(now_ns);
        Ok(DeviceState {
            position_m: self.position_m,
            velocity_m_s: self.velocity_m_s,
            gripper: self.gripper,
            buttons: 0,
        })
    }

    fn write_force(&mut self, force_n: V3, _now_ns: u64) -> Result<(), DeviceError> {
        if force_n.iter().any(|f| !f.is_finite()) {
            return Err(DeviceError::NonFinite("force command"));
        }
        self.force_n = force_n;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poke() -> Path {
        Path::Poke {
            start_m: [0.0, 0.0, 0.1],
            direction: [0.0, 0.0, -1.0],
            depth_m: 0.02,
            period_s: 2.0,
        }
    }

    #[test]
    fn the_built_in_poke_aims_at_the_organ_it_is_given() {
        // The embedded liver's rest box (`sim-server check`): the poke of
        // an unknown scene, within 0.2 mm.
        let liver = Path::poke_over([-0.1100, -0.0750, -0.0432], [0.1104, 0.0750, 0.0470], 0.0);
        let (
            Some(Path::Poke {
                start_m, depth_m, ..
            }),
            Path::Poke {
                start_m: s0,
                depth_m: d0,
                ..
            },
        ) = (liver, Path::default_poke())
        else {
            panic!("pokes");
        };
        for d in 0..3 {
            assert!((start_m[d] - s0[d]).abs() < 2e-4, "{start_m:?} vs {s0:?}");
        }
        assert!((depth_m - d0).abs() < 2e-4, "{depth_m} vs {d0}");
        // hapbench's 60 x 40 x 20 mm probe box: over its centre (which the
        // unknown-scene poke at x = y = 0 only grazed at a corner), from
        // 3 mm above its top to 6 mm into it.
        let Some(b) = Path::poke_over([0.0; 3], [0.06, 0.04, 0.02], 0.0) else {
            panic!("a box");
        };
        let (top, bottom) = (b.at(0.0).0, b.at(2.0).0);
        assert!((top[0] - 0.03).abs() < 1e-12 && (top[1] - 0.02).abs() < 1e-12);
        assert!((top[2] - 0.023).abs() < 1e-12, "{top:?}");
        assert!((bottom[2] - 0.014).abs() < 1e-12, "{bottom:?}");
        // With the box's 2.5 mm probe: its round end starts 3 mm clear of
        // the top (it touched at once before) and presses as deep.
        let Some(b) = Path::poke_over([0.0; 3], [0.06, 0.04, 0.02], 0.0025) else {
            panic!("a box");
        };
        let (top, bottom) = (b.at(0.0).0, b.at(2.0).0);
        assert!((top[2] - 0.0025 - 0.023).abs() < 1e-12, "{top:?}");
        assert!((bottom[2] - 0.014).abs() < 1e-12, "{bottom:?}");
        // Not a box: no aim; an absurd radius: a point tip.
        assert!(Path::poke_over([0.0; 3], [f64::NAN, 1.0, 1.0], 0.0).is_none());
        assert!(Path::poke_over([0.0, 0.0, 1.0], [1.0, 1.0, 0.0], 0.0).is_none());
        let Some(b) = Path::poke_over([0.0; 3], [0.06, 0.04, 0.02], f64::NAN) else {
            panic!("a box");
        };
        assert!((b.at(0.0).0[2] - 0.023).abs() < 1e-12);
    }

    #[test]
    fn the_hand_follows_its_path_and_yields_to_force() {
        let mut dev = Simulated::new(poke(), HandModel::default(), 5.0);
        dev.enable(1_000_000_000).unwrap();
        let mut t = 1_000_000_000u64;
        for _ in 0..1000 {
            t += 1_000_000;
            dev.read(t).unwrap();
        }
        // After 1 s (half a period) the path is at its deepest: z = 0.08.
        let z_free = dev.read(t).unwrap().position_m[2];
        assert!((z_free - 0.08).abs() < 2e-3, "{z_free}");
        // A constant 1 N upward force holds the hand 1/300 m higher at rest.
        let mut held = Simulated::new(poke(), HandModel::default(), 5.0);
        held.enable(1_000_000_000).unwrap();
        held.write_force([0.0, 0.0, 1.0], 0).unwrap();
        let mut t = 1_000_000_000u64;
        for _ in 0..1000 {
            t += 1_000_000;
            held.read(t).unwrap();
        }
        let z_held = held.read(t).unwrap().position_m[2];
        assert!(
            (z_held - z_free - 1.0 / 300.0).abs() < 5e-4,
            "{z_held} vs {z_free}"
        );
        assert!(held.write_force([f64::NAN, 0.0, 0.0], t).is_err());
    }
}
