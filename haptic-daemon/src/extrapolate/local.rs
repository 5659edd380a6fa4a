//! The local model made safe to render: unilateral (it never pulls the
//! hand into the tissue) and with its stiffness capped at what the device
//! renders stably.
//!
//! The simulation's local model `F = F_n + K (P_n - P)` is a linearisation
//! about the latest sample. Linear means bilateral: as the tool withdraws
//! past the surface, `K (P_n - P)` keeps growing the other way and the force
//! pulls the hand back into the tissue, which no tissue does. And `K` is
//! whatever the contact law computed, which may be far stiffer than the
//! device can render without buzzing (a Touch renders about 400 N/m).
//!
//! # Unilateral projection ([`unilateral`])
//!
//! The sample's force points out of the tissue, so when `|F_n|` exceeds
//! [`MIN_NORMAL_FORCE_N`] its direction is the contact normal
//! `n = F_n / |F_n|`. The model force `F` is split into its normal part
//! `f = F.n` and its tangential part `F_t = F - f n` (which comes from `K`
//! only: `F_n` has none). Then
//!
//! - `f >= |F_n|` (pressing further in): `F` unchanged;
//! - `0 < f < |F_n|` (withdrawing from `P_n`): the normal part follows the
//!   model and the tangential part is scaled by `f / |F_n|`, the fraction of
//!   the sample's load that remains (shear needs load to act on);
//! - `f <= 0` (the tool has left the surface the model predicts): zero.
//!
//! So `F.n >= 0` always, the force is continuous in `P` (at `f = |F_n|` the
//! scale is 1, at `f = 0` everything is 0) and goes to exactly zero on
//! release. With no usable normal (`|F_n| <= MIN_NORMAL_FORCE_N`) the
//! direction of "out" is unknown, so the model is not applied and `F_n`
//! (below 1 mN) is held until the next sample.
//!
//! # Stiffness cap ([`cap_stiffness`])
//!
//! `K` is scaled down, direction kept, so that its spectral norm (the
//! largest gain `|K d| / |d|`, the largest eigenvalue of a symmetric `K`)
//! is at most the device's `max_stiffness_n_per_m`.

use crate::math::{
    M3, V3, ZERO, add, dot, is_finite, mat_vec, norm, positive_part, scale, spectral_norm, sub,
};

/// Below this sample force (N) its direction is not trusted as the contact
/// normal: 1 mN, under the force resolution of any haptic device (~10 mN).
pub const MIN_NORMAL_FORCE_N: f64 = 1e-3;

/// `k` scaled so that its spectral norm is at most `max_n_per_m` (N/m);
/// `k` itself when already below, or when the cap is not a positive number
/// (infinite: no cap). A non-finite `k` is returned unchanged (the caller
/// falls back to the constant force).
pub fn cap_stiffness(k: &M3, max_n_per_m: f64) -> M3 {
    if !(max_n_per_m > 0.0 && max_n_per_m < f64::INFINITY) {
        return *k;
    }
    let s = spectral_norm(k);
    if !(s > max_n_per_m && s.is_finite()) {
        return *k;
    }
    let c = max_n_per_m / s;
    std::array::from_fn(|i| scale(k[i], c))
}

/// The model force `f_model_n` made unilateral about the sample force
/// `f_sample_n` (see the module documentation). Finite in, finite out; a
/// non-finite model force is returned as it is, for the caller's fallback.
pub fn unilateral(f_model_n: V3, f_sample_n: V3) -> V3 {
    if !is_finite(f_model_n) {
        return f_model_n;
    }
    let load = norm(f_sample_n);
    if !(load > MIN_NORMAL_FORCE_N && load.is_finite()) {
        return f_sample_n;
    }
    let n = scale(f_sample_n, 1.0 / load);
    let f = dot(f_model_n, n);
    if f.is_nan() || f <= 0.0 {
        return ZERO;
    }
    if f >= load {
        return f_model_n;
    }
    let tangential = sub(f_model_n, scale(n, f));
    add(scale(n, f), scale(tangential, f / load))
}

/// The local model `F_n + K_c (P_n - P)` with `K_c` the positive part of the
/// stiffness ([`positive_part`]) capped at `max_stiffness_n_per_m`, made
/// unilateral.
pub fn local_model_unilateral(
    f_last_n: V3,
    k_n_per_m: &M3,
    max_stiffness_n_per_m: f64,
    p_last_m: V3,
    p_m: V3,
) -> V3 {
    let k = cap_stiffness(&positive_part(k_n_per_m), max_stiffness_n_per_m);
    let model = add(f_last_n, mat_vec(&k, sub(p_last_m, p_m)));
    unilateral(model, f_last_n)
}

/// The local model along the contact normal only, `F_n + n k_n n.(P_n -
/// P)` with `n = F_n / |F_n|` and `k_n = n^T K_c n` (`K_c` capped), made
/// unilateral: a virtual plane through the sample's contact, the
/// intermediate representation of Adachi et al. (1995) and Mark et al.
/// (1996) with the simulation's normal stiffness. With no usable normal,
/// `F_n`.
pub fn local_normal_unilateral(
    f_last_n: V3,
    k_n_per_m: &M3,
    max_stiffness_n_per_m: f64,
    p_last_m: V3,
    p_m: V3,
) -> V3 {
    let load = norm(f_last_n);
    if !(load > MIN_NORMAL_FORCE_N && load.is_finite()) {
        return f_last_n;
    }
    let n = scale(f_last_n, 1.0 / load);
    let k = cap_stiffness(k_n_per_m, max_stiffness_n_per_m);
    let k_n = dot(n, mat_vec(&k, n)).max(0.0);
    let model = add(f_last_n, scale(n, k_n * dot(n, sub(p_last_m, p_m))));
    unilateral(model, f_last_n)
}

#[cfg(test)]
mod tests {
    use super::*;

    const K300: M3 = [[300.0, 0.0, 0.0], [0.0, 300.0, 0.0], [0.0, 0.0, 300.0]];

    fn close(a: V3, b: V3) -> bool {
        (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12)
    }

    #[test]
    fn pressing_in_is_the_plain_model() {
        // Surface normal +z, 1 N at z = 0; pressing 2 mm deeper adds 0.6 N.
        let f = local_model_unilateral([0.0, 0.0, 1.0], &K300, 1e4, ZERO, [0.0, 0.0, -0.002]);
        assert!(close(f, [0.0, 0.0, 1.6]), "{f:?}");
        // Sliding sideways while pressing: the shear of K passes.
        let f = local_model_unilateral([0.0, 0.0, 1.0], &K300, 1e4, ZERO, [0.001, 0.0, -0.001]);
        assert!(close(f, [-0.3, 0.0, 1.3]), "{f:?}");
    }

    #[test]
    fn a_withdrawal_gives_exactly_zero_never_a_pull() {
        // 1 N at 300 N/m: released 3.33 mm above the sample position.
        for dz in [0.0034, 0.004, 0.01, 0.1, 1.0] {
            let f = local_model_unilateral([0.0, 0.0, 1.0], &K300, 1e4, ZERO, [0.0, 0.0, dz]);
            assert_eq!(f, ZERO, "dz {dz}");
        }
        // Withdrawing diagonally: never a component into the tissue.
        for k in 0..200 {
            let p = [0.001 * (k as f64 - 100.0) / 10.0, 0.002, 0.0001 * k as f64];
            let f = local_model_unilateral([0.0, 0.0, 1.0], &K300, 1e4, ZERO, p);
            assert!(f[2] >= 0.0, "{p:?}: {f:?}");
        }
        // Not along an axis: the normal is F_n's direction.
        let fs = [0.0, 0.6, 0.8];
        let f = local_model_unilateral(fs, &K300, 1e4, ZERO, [0.0, 0.02, 0.02]);
        assert_eq!(f, ZERO);
    }

    #[test]
    fn continuous_at_the_release_point() {
        // With shear coupling: K maps a z withdrawal into an x force too
        // (symmetric positive definite, as a contact stiffness is: the
        // model renders only the positive part).
        let k = [[300.0, 0.0, 100.0], [0.0, 300.0, 0.0], [100.0, 0.0, 300.0]];
        let fs = [0.0, 0.0, 1.0];
        let release = 1.0 / 300.0;
        let mut prev = local_model_unilateral(fs, &k, 1e4, ZERO, ZERO);
        let steps = 10_000;
        let mut max_jump = 0.0f64;
        for i in 1..=steps {
            let z = 2.0 * release * i as f64 / steps as f64;
            let f = local_model_unilateral(fs, &k, 1e4, ZERO, [0.0, 0.0, z]);
            max_jump = max_jump.max(norm(sub(f, prev)));
            assert!(f[2] >= 0.0);
            prev = f;
        }
        // Step 0.67 um at ~316 N/m (|K e_z|): a continuous force moves
        // < 1 mN a step.
        assert!(max_jump < 1e-3, "{max_jump}");
        // Just below the release point: tiny; at and beyond it: zero.
        let f = local_model_unilateral(fs, &k, 1e4, ZERO, [0.0, 0.0, release * 0.999]);
        assert!(norm(f) < 2e-3, "{f:?}");
        let f = local_model_unilateral(fs, &k, 1e4, ZERO, [0.0, 0.0, release * 1.001]);
        assert_eq!(f, ZERO);
        // Half-way out: normal 0.5 N, the shear halved (-100 * z * 0.5).
        let f = local_model_unilateral(fs, &k, 1e4, ZERO, [0.0, 0.0, release / 2.0]);
        assert!(close(f, [-100.0 * release / 2.0 * 0.5, 0.0, 0.5]), "{f:?}");
    }

    #[test]
    fn a_negative_stiffness_is_never_rendered() {
        // An unstable contact (K_yy < 0): moving sideways along y, the raw
        // model would push the hand further along y (energy in); only the
        // positive part is rendered.
        let k = [[300.0, 0.0, 0.0], [0.0, -80.0, 0.0], [0.0, 0.0, 300.0]];
        let f = local_model_unilateral([0.0, 0.0, 1.0], &k, 1e4, ZERO, [0.0, 0.001, 0.0]);
        assert!(close(f, [0.0, 0.0, 1.0]), "{f:?}");
    }

    #[test]
    fn a_stiff_k_is_capped() {
        let stiff = [[5000.0, 0.0, 0.0], [0.0, 5000.0, 0.0], [0.0, 0.0, 20_000.0]];
        let c = cap_stiffness(&stiff, 400.0);
        assert!((spectral_norm(&c) - 400.0).abs() < 1e-9);
        // Direction kept: the z axis stays 4 times the others.
        assert!((c[2][2] / c[0][0] - 4.0).abs() < 1e-12);
        // Below the cap, or no cap: unchanged.
        assert_eq!(cap_stiffness(&K300, 400.0), K300);
        assert_eq!(cap_stiffness(&stiff, f64::INFINITY), stiff);
        assert_eq!(cap_stiffness(&stiff, f64::NAN), stiff);
        // Pressing 1 mm into a 20 kN/m contact capped at 400 N/m: 0.4 N more.
        let f = local_model_unilateral([0.0, 0.0, 1.0], &stiff, 400.0, ZERO, [0.0, 0.0, -0.001]);
        assert!(close(f, [0.0, 0.0, 1.4]), "{f:?}");
    }

    #[test]
    fn the_normal_model_ignores_sliding_and_follows_the_normal() {
        let k = [
            [300.0, 50.0, 100.0],
            [50.0, 300.0, 0.0],
            [100.0, 0.0, 200.0],
        ];
        let fs = [0.0, 0.0, 1.0];
        // Sliding 5 mm along the surface: unchanged.
        let f = local_normal_unilateral(fs, &k, 1e4, ZERO, [0.005, -0.003, 0.0]);
        assert!(close(f, fs), "{f:?}");
        // Pressing 1 mm: k_n = K_zz = 200 N/m, along n only.
        let f = local_normal_unilateral(fs, &k, 1e4, ZERO, [0.002, 0.0, -0.001]);
        assert!(close(f, [0.0, 0.0, 1.2]), "{f:?}");
        // Withdrawing past 5 mm: released, exactly zero.
        let f = local_normal_unilateral(fs, &k, 1e4, ZERO, [0.0, 0.0, 0.0051]);
        assert_eq!(f, ZERO);
        // A tilted normal: the force stays along it.
        let fs = [0.0, 0.6, 0.8];
        let f = local_normal_unilateral(fs, &K300, 1e4, ZERO, [0.0, -0.0006, -0.0008]);
        assert!(close(f, [0.0, 0.6 * 1.3, 0.8 * 1.3]), "{f:?}");
    }

    #[test]
    fn no_usable_normal_holds_the_sample() {
        let f = local_model_unilateral([0.0, 0.0, 1e-4], &K300, 1e4, ZERO, [0.0, 0.0, -0.01]);
        assert_eq!(f, [0.0, 0.0, 1e-4]);
        assert_eq!(unilateral([1.0, 2.0, 3.0], ZERO), ZERO);
    }
}
