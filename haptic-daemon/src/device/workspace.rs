//! A device's workspace placed in the scene: `scene = offset + scale R
//! device`, the force going back by the same rotation (`device = R^T
//! scene`), so the hand feels at a scene point what the tool meets there.
//!
//! A real device reports positions around its own origin (a 3D Systems
//! Touch about 16 x 12 x 7 cm, a Novint Falcon a 10 cm cube, a Haply
//! Inverse3 a sphere of about 20 cm); the scene's organ lies wherever its
//! mesh put it. [`WorkspaceMap`] moves (offset), turns (rotation: about
//! the device's x, then y, then z axis, in degrees) and scales the device's
//! motion onto the scene. A scale above 1 moves the tool further than the
//! hand: the same scene force is felt, over a shorter hand motion, so the
//! stiffness at the hand is the scene's times the scale, and the stiffness
//! the daemon may render in the scene is the device's limit over the scale
//! ([`Mapped::specs`]). The passivity observer sees scene positions: its
//! energies are the hand's times the scale, their signs the same.
//!
//! [`Mapped`] wraps any device; the identity map changes nothing (bit for
//! bit). Everything is fixed at start: no allocation, no lock per tick.

use super::{Device, DeviceError, DeviceSpecs, DeviceState};
use crate::math::{M3, V3, add, is_finite, mat_vec, scale};
use thiserror::Error;

/// Largest workspace scale: a hand moving 1 mm moves the tool 100 mm.
pub const MAX_SCALE: f64 = 100.0;
/// Smallest workspace scale.
pub const MIN_SCALE: f64 = 0.01;
/// Largest offset (m): the scene's frame within 100 m of the device's.
pub const MAX_OFFSET_M: f64 = 100.0;

/// A map that cannot be used.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum WorkspaceError {
    /// The scale is out of range or not finite.
    #[error("workspace scale must lie in {MIN_SCALE} ..= {MAX_SCALE}, got {0}")]
    Scale(f64),
    /// An offset component is out of range or not finite.
    #[error("workspace offset must be finite and within {MAX_OFFSET_M} m on each axis, got {0:?}")]
    Offset(V3),
    /// A rotation angle is not finite or beyond a turn.
    #[error("workspace rotation angles must be finite degrees within 360, got {0:?}")]
    Rotation(V3),
}

/// The device-to-scene map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorkspaceMap {
    /// Where the device's origin lies in the scene (m).
    pub offset_m: V3,
    /// Scene metres per device metre.
    pub scale: f64,
    /// Device axes to scene axes (orthonormal).
    pub rotation: M3,
}

impl Default for WorkspaceMap {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl WorkspaceMap {
    /// The device's frame is the scene's.
    pub const IDENTITY: Self = Self {
        offset_m: [0.0; 3],
        scale: 1.0,
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    };

    /// From an offset (m), a scale and rotations about the device's x, y
    /// and z axes (degrees, applied in that order), checked.
    pub fn new(offset_m: V3, scale: f64, rotate_deg: V3) -> Result<Self, WorkspaceError> {
        if !(scale.is_finite() && (MIN_SCALE..=MAX_SCALE).contains(&scale)) {
            return Err(WorkspaceError::Scale(scale));
        }
        if !offset_m
            .iter()
            .all(|x| x.is_finite() && x.abs() <= MAX_OFFSET_M)
        {
            return Err(WorkspaceError::Offset(offset_m));
        }
        if !rotate_deg.iter().all(|x| x.is_finite() && x.abs() <= 360.0) {
            return Err(WorkspaceError::Rotation(rotate_deg));
        }
        let [rx, ry, rz] = rotate_deg.map(f64::to_radians);
        let rot_x = [
            [1.0, 0.0, 0.0],
            [0.0, rx.cos(), -rx.sin()],
            [0.0, rx.sin(), rx.cos()],
        ];
        let rot_y = [
            [ry.cos(), 0.0, ry.sin()],
            [0.0, 1.0, 0.0],
            [-ry.sin(), 0.0, ry.cos()],
        ];
        let rot_z = [
            [rz.cos(), -rz.sin(), 0.0],
            [rz.sin(), rz.cos(), 0.0],
            [0.0, 0.0, 1.0],
        ];
        Ok(Self {
            offset_m,
            scale,
            rotation: mat_mul(&rot_z, &mat_mul(&rot_y, &rot_x)),
        })
    }

    /// Whether it changes nothing.
    pub fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }

    /// A device position in the scene (m).
    pub fn to_scene(&self, device_m: V3) -> V3 {
        if self.is_identity() {
            return device_m;
        }
        add(
            self.offset_m,
            scale(mat_vec(&self.rotation, device_m), self.scale),
        )
    }

    /// A scene position in the device's frame (m): the inverse of
    /// [`WorkspaceMap::to_scene`].
    pub fn to_device(&self, scene_m: V3) -> V3 {
        if self.is_identity() {
            return scene_m;
        }
        let d = std::array::from_fn(|i| scene_m[i] - self.offset_m[i]);
        scale(mat_vec(&transpose(&self.rotation), d), 1.0 / self.scale)
    }

    /// A device velocity in the scene (m/s).
    pub fn velocity_to_scene(&self, device_m_s: V3) -> V3 {
        if self.is_identity() {
            return device_m_s;
        }
        scale(mat_vec(&self.rotation, device_m_s), self.scale)
    }

    /// A scene direction in the device's frame (unit length kept).
    pub fn direction_to_device(&self, scene: V3) -> V3 {
        mat_vec(&transpose(&self.rotation), scene)
    }

    /// The scene's force on the tool as the device renders it (N): the
    /// same force, turned back into the device's axes.
    pub fn force_to_device(&self, scene_n: V3) -> V3 {
        if self.is_identity() {
            return scene_n;
        }
        mat_vec(&transpose(&self.rotation), scene_n)
    }

    /// A stiffness in the scene felt at the hand (N/m): times the scale.
    pub fn stiffness_at_hand(&self, scene_n_per_m: f64) -> f64 {
        scene_n_per_m * self.scale
    }
}

fn mat_mul(a: &M3, b: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn transpose(a: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

/// A device seen through a [`WorkspaceMap`].
pub struct Mapped<D: Device> {
    inner: D,
    map: WorkspaceMap,
}

impl<D: Device> Mapped<D> {
    /// `inner` placed in the scene by `map`.
    pub fn new(inner: D, map: WorkspaceMap) -> Self {
        Self { inner, map }
    }

    /// The map.
    pub fn map(&self) -> &WorkspaceMap {
        &self.map
    }
}

impl<D: Device> Device for Mapped<D> {
    /// The device's specifications in the scene: its workspace box mapped
    /// (the box round the mapped corners), the stiffness it renders stably
    /// divided by the scale (a scene stiffness K is felt as K times the
    /// scale); the force limit is the device's.
    fn specs(&self) -> DeviceSpecs {
        let s = self.inner.specs();
        if self.map.is_identity() {
            return s;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for c in 0..8 {
            let corner = std::array::from_fn(|i| {
                if c >> i & 1 == 0 {
                    s.workspace_min_m[i]
                } else {
                    s.workspace_max_m[i]
                }
            });
            let p = self.map.to_scene(corner);
            for i in 0..3 {
                lo[i] = lo[i].min(p[i]);
                hi[i] = hi[i].max(p[i]);
            }
        }
        DeviceSpecs {
            max_stiffness_n_per_m: s.max_stiffness_n_per_m / self.map.scale,
            workspace_min_m: lo,
            workspace_max_m: hi,
            ..s
        }
    }

    fn enable(&mut self, now_ns: u64) -> Result<(), DeviceError> {
        self.inner.enable(now_ns)
    }

    fn disable(&mut self) {
        self.inner.disable();
    }

    fn read(&mut self, now_ns: u64) -> Result<DeviceState, DeviceError> {
        let s = self.inner.read(now_ns)?;
        // A non-finite reading stays non-finite (the daemon rejects it).
        if !(is_finite(s.position_m) && is_finite(s.velocity_m_s)) {
            return Ok(s);
        }
        Ok(DeviceState {
            position_m: self.map.to_scene(s.position_m),
            velocity_m_s: self.map.velocity_to_scene(s.velocity_m_s),
            ..s
        })
    }

    fn write_force(&mut self, force_n: V3, now_ns: u64) -> Result<(), DeviceError> {
        self.inner
            .write_force(self.map.force_to_device(force_n), now_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{norm, sub};

    #[test]
    fn a_map_and_its_inverse_agree_and_forces_keep_their_size() {
        let m = WorkspaceMap::new([0.01, -0.02, 0.05], 2.5, [10.0, -35.0, 90.0]).unwrap();
        let r = m.rotation;
        // Orthonormal, a proper rotation.
        for i in 0..3 {
            for j in 0..3 {
                let d: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                assert!((d - f64::from(u8::from(i == j))).abs() < 1e-12);
            }
        }
        let p = [0.03, -0.01, 0.02];
        let back = m.to_device(m.to_scene(p));
        assert!(norm(sub(back, p)) < 1e-15, "{back:?}");
        // A device step dx moves the scene point scale * |dx|.
        let q = m.to_scene([0.031, -0.01, 0.02]);
        assert!((norm(sub(q, m.to_scene(p))) - 2.5e-3).abs() < 1e-12);
        let f = [1.0, -2.0, 0.5];
        assert!((norm(m.force_to_device(f)) - norm(f)).abs() < 1e-12);
        // The force turns back by R^T: F_scene . R dx = F_device . dx.
        let dx = [0.3, 0.1, -0.2];
        let w_scene: f64 = (0..3).map(|i| f[i] * mat_vec(&r, dx)[i]).sum();
        let w_device: f64 = (0..3).map(|i| m.force_to_device(f)[i] * dx[i]).sum();
        assert!((w_scene - w_device).abs() < 1e-12);
        assert_eq!(m.stiffness_at_hand(400.0), 1000.0);
    }

    #[test]
    fn a_quarter_turn_about_z_sends_device_x_to_scene_y() {
        let m = WorkspaceMap::new([0.0; 3], 1.0, [0.0, 0.0, 90.0]).unwrap();
        let p = m.to_scene([1.0, 0.0, 0.0]);
        assert!(norm(sub(p, [0.0, 1.0, 0.0])) < 1e-12, "{p:?}");
        let m = WorkspaceMap::new([0.0; 3], 1.0, [90.0, 0.0, 0.0]).unwrap();
        let p = m.to_scene([0.0, 1.0, 0.0]);
        assert!(norm(sub(p, [0.0, 0.0, 1.0])) < 1e-12, "{p:?}");
    }

    #[test]
    fn bad_maps_are_refused_and_the_identity_is_exact() {
        assert_eq!(
            WorkspaceMap::new([0.0; 3], 0.0, [0.0; 3]),
            Err(WorkspaceError::Scale(0.0))
        );
        assert!(WorkspaceMap::new([0.0; 3], f64::NAN, [0.0; 3]).is_err());
        assert!(WorkspaceMap::new([1e3, 0.0, 0.0], 1.0, [0.0; 3]).is_err());
        assert!(WorkspaceMap::new([0.0; 3], 1.0, [f64::INFINITY, 0.0, 0.0]).is_err());
        let id = WorkspaceMap::new([0.0; 3], 1.0, [0.0; 3]).unwrap();
        assert!(id.is_identity());
        let p = [0.1234567, -9.87e-3, 3.3];
        assert_eq!(id.to_scene(p), p);
        assert_eq!(id.force_to_device(p), p);
    }
}
