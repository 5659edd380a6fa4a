//! The contact field's laws: zero force at zero gap and linear inside, a
//! smooth onset, damping that never pulls, friction's two limits.

use super::fixtures::{add_point, whole_step};
use super::*;

fn field(tip_z: Real) -> (ContactField, Vec<Vec3>) {
    let rest = vec![
        Vec3::new(-0.01, -0.01, 0.0),
        Vec3::new(0.01, -0.01, 0.0),
        Vec3::new(0.0, 0.01, 0.0),
    ];
    let mut f = ContactField::new(1, 0.0);
    let seg = Segment {
        a_m: Vec3::new(0.0, 0.0, tip_z + 0.01),
        b_m: Vec3::new(0.0, 0.0, tip_z),
    };
    add_point(
        &mut f,
        (seg, seg),
        true,
        0.002,
        ([0, 1, 2], [0.25, 0.25, 0.5]),
        100.0,
    );
    (f, rest)
}

#[test]
fn force_is_zero_at_zero_gap_and_grows_linearly_inside() {
    // The point is at (0, 0, 0); the tip end at height z: gap = z - r.
    let d0 = ONSET_OF_RADIUS * 0.002;
    for (z, expect) in [
        (0.0021, 0.0),
        (0.002, 0.0),
        (0.002 - d0 / 2.0, 100.0 * d0 / 8.0),
        (0.0015, 100.0 * (0.0005 - d0 / 2.0)),
        (0.001, 100.0 * (0.001 - d0 / 2.0)),
    ] {
        let (mut f, rest) = field(z);
        let u = vec![[0.0; 3]; 3];
        let mut out = vec![[0.0; 3]; 3];
        f.static_forces(&rest, &u, &mut out);
        let tool = f.force_n(0);
        assert!((tool.z - expect).abs() < 1e-12, "z {z}: {tool}");
        // The tissue gets the opposite, spread by the weights.
        let sum: Real = out.iter().map(|o| o[2]).sum();
        assert!((sum + tool.z).abs() < 1e-12);
        assert!((out[2][2] + 0.5 * tool.z).abs() < 1e-12);
    }
}

#[test]
fn the_spring_is_smooth_at_the_onset() {
    let r = 0.002;
    let d0 = ONSET_OF_RADIUS * r;
    let (f, s) = spring(100.0, d0, r);
    assert!((f - 100.0 * d0 / 2.0).abs() < 1e-15 && (s - 100.0).abs() < 1e-12);
    // The slope is the derivative of the force, on both sides.
    for d in [0.3 * d0, d0 * 0.999, d0 * 1.001, 3.0 * d0] {
        let h = 1e-9;
        let fd = (spring(100.0, d + h, r).0 - spring(100.0, d - h, r).0) / (2.0 * h);
        assert!((fd - spring(100.0, d, r).1).abs() < 1e-4, "{d}");
    }
}

#[test]
fn the_spring_is_the_derivative_of_its_energy() {
    let r = 0.002;
    let d0 = ONSET_OF_RADIUS * r;
    assert_eq!(spring_energy(100.0, 0.0, r), 0.0);
    assert_eq!(spring_energy(100.0, -1e-3, r), 0.0);
    for d in [0.3 * d0, d0 * 0.999, d0 * 1.001, 3.0 * d0, 0.5 * r] {
        let h = 1e-10;
        let fd = (spring_energy(100.0, d + h, r) - spring_energy(100.0, d - h, r)) / (2.0 * h);
        let f = spring(100.0, d, r).0;
        assert!((fd - f).abs() < 1e-6 * f.max(1e-6), "{d}: {fd} against {f}");
    }
    // The field sums it over the points in contact.
    let (mut f, rest) = field(0.0015);
    let u = vec![[0.0; 3]; 3];
    let mut out = vec![[0.0; 3]; 3];
    f.static_forces(&rest, &u, &mut out);
    let e = f.spring_energy_j();
    assert!(
        (e - spring_energy(100.0, 0.0005, 0.002)).abs() < 1e-15,
        "{e}"
    );
}

#[test]
fn damping_never_pulls() {
    let (mut f, rest) = field(0.0015);
    f.damping_s_per_m = 10.0;
    let u = vec![[0.0; 3]; 3];
    // The tissue moves away from the tool fast (down, u_prev above u):
    // the penetration shrinks, the factor would be negative; it is
    // clamped to zero, not a pull.
    let up = vec![[0.0, 0.0, 0.01]; 3];
    let mut out = vec![[0.0; 3]; 3];
    f.zero(&mut out);
    let at = SubStep {
        h_s: 1e-3,
        step_s: 1e-3,
        s: 1.0,
        masses_kg: &[1.0; 3],
    };
    f.add_forces(&rest, &u, &up, at, &mut out);
    assert!(f.force_n(0).z >= 0.0);
    assert_eq!(f.force_n(0).z, 0.0);
}

#[test]
fn friction_holds_to_the_static_limit_then_drags_at_the_dynamic_one() {
    // A shaft lying along x, 0.5 mm into a point below it, sliding
    // along its own axis: the normal and depth stay as they are, only
    // the friction changes.
    let rest = vec![
        Vec3::new(-0.01, -0.01, 0.0),
        Vec3::new(0.01, -0.01, 0.0),
        Vec3::new(0.0, 0.01, 0.0),
    ];
    let mu = Friction {
        static_coefficient: 0.5,
        dynamic_coefficient: 0.3,
    };
    let mut f = ContactField::new(1, 0.0).with_friction(&[mu]);
    let seg = |x: Real| Segment {
        a_m: Vec3::new(x - 0.02, 0.0, 0.0015),
        b_m: Vec3::new(x + 0.02, 0.0, 0.0015),
    };
    let u = vec![[0.0; 3]; 3];
    let mut out = vec![[0.0; 3]; 3];
    let normal = spring(100.0, 0.0005, 0.002).0;
    let mut x = 0.0;
    let mut forces = Vec::new();
    let step_m = 0.00005;
    for k in 0..16 {
        // Ten steps forward, then back.
        let dx = if k < 10 { step_m } else { -step_m };
        f.clear();
        let sweep = (seg(x), seg(x + dx));
        add_point(
            &mut f,
            sweep,
            false,
            0.002,
            ([0, 1, 2], [0.25, 0.25, 0.5]),
            100.0,
        );
        x += dx;
        f.zero(&mut out);
        f.add_forces(&rest, &u, &u, whole_step(1e-3), &mut out);
        let tool = f.force_n(0);
        assert!((tool.z - normal).abs() < 1e-12, "{tool}");
        // The tissue gets the opposite.
        let sum = out.iter().fold(Vec3::ZERO, |s, o| s + Vec3::from_array(*o));
        assert!((sum + tool).length() < 1e-12);
        forces.push(tool.x);
    }
    // Sticking: 100 N/m x 0.05 mm more each step against the motion,
    // up to mu_s f (0.5 x 0.0479 N: 4 steps hold, the 5th slips).
    for (k, fx) in forces[..4].iter().enumerate() {
        assert!(
            (fx + 100.0 * step_m * (k + 1) as Real).abs() < 1e-12,
            "{k}: {fx}"
        );
    }
    for fx in &forces[4..10] {
        assert!((fx + 0.3 * normal).abs() < 1e-12, "sliding: {fx}");
    }
    // Back: it sticks at once and unloads elastically.
    assert!((forces[10] - (-0.3 * normal + 100.0 * step_m)).abs() < 1e-12);
    // The stiffness seen by the local model: tangential k_p while it
    // sticks.
    let h = f.spring_hessians()[0];
    assert!((h.x_axis.x - 100.0).abs() < 1e-9 && (h.z_axis.z - 100.0).abs() < 1e-9);
    // A static evaluation reads the state without moving it.
    let before = f.force_n(0);
    for _ in 0..2 {
        f.static_forces(&rest, &u, &mut out);
        assert!((f.force_n(0).x - before.x).abs() < 1e-15);
    }
}
