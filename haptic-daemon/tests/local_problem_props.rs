//! Property tests of the `local-problem` solver as the RT thread uses it:
//! problems of any size within the wire's capacity, set up one after the
//! other in the same buffers (as the triple buffer reuses them), then
//! rendered for tool positions near and far: never a panic, and the force
//! is finite or the solver declines (the caller then falls back).

use haptic_daemon::extrapolate::ForceSample;
use haptic_daemon::extrapolate::local_problem::{
    Capsule, LocalContactMsg, LocalProblem, MAX_POINTS, MAX_VERTICES, Point,
};
use proptest::prelude::*;

/// A problem message: `nv` vertices within 2 cm, `np` points on random
/// triangles of them, a capsule near them, W diagonal-dominant (positive
/// definite) with random couplings.
#[derive(Clone, Debug)]
struct Problem {
    positions: Vec<[f64; 3]>,
    points: Vec<([u16; 3], [f64; 2], f64)>,
    capsule: ([f64; 3], [f64; 3], f64),
    couplings: Vec<f64>,
}

fn problem() -> impl Strategy<Value = Problem> {
    (1usize..=MAX_VERTICES, 1usize..=64).prop_flat_map(|(nv, np)| {
        let v = (nv - 1) as u16;
        (
            proptest::collection::vec([-0.02f64..0.02, -0.02f64..0.02, -0.005f64..0.005], nv),
            proptest::collection::vec(
                (
                    [0..=v, 0..=v, 0..=v],
                    [0.0f64..0.5, 0.0f64..0.5],
                    1.0f64..2000.0,
                ),
                np,
            ),
            (
                [-0.01f64..0.01, -0.01f64..0.01, -0.002f64..0.01],
                [-0.01f64..0.01, -0.01f64..0.01, 0.0f64..0.05],
                0.0005f64..0.01,
            ),
            proptest::collection::vec(-1.0f64..1.0, nv * 3),
        )
            .prop_map(|(positions, points, capsule, couplings)| Problem {
                positions,
                points,
                capsule,
                couplings,
            })
    })
}

fn to_wire(p: &Problem, seq: u64, msg: &mut LocalContactMsg) {
    let nv = p.positions.len();
    msg.seq = seq;
    msg.t_ns = seq * 1_000_000;
    msg.tool_position_m = p.capsule.0;
    msg.part_count = 1;
    msg.parts[0] = Capsule {
        a_m: p.capsule.0,
        b_m: p.capsule.1,
        radius_m: p.capsule.2,
        onset_m: 0.02 * p.capsule.2,
    };
    msg.vertex_count = nv as u32;
    msg.positions_m[..nv].copy_from_slice(&p.positions);
    msg.point_count = p.points.len() as u32;
    for (o, (slots, [a, b], k)) in msg.points.iter_mut().zip(&p.points) {
        *o = Point {
            weights: [1.0 - a - b, *a, *b],
            stiffness_n_per_m: *k,
            slots: *slots,
            part: 0,
        };
    }
    let n = 3 * nv;
    // W = 1e-3 (I + 0.3 c c^T / |c|^2): positive definite.
    let c = &p.couplings;
    let c2: f64 = c.iter().map(|x| x * x).sum::<f64>().max(1e-12);
    for i in 0..n {
        for j in 0..n {
            let d = if i == j { 1.0 } else { 0.0 };
            msg.compliance_m_per_n[i * n + j] = 1e-3 * (d + 0.3 * c[i] * c[j] / c2);
        }
    }
    // Every other problem with inertia: G = m W W (a mass m at each
    // coordinate once condensed), the vertices moving.
    msg.inertia = (seq % 2) as u32;
    let w = msg.compliance_m_per_n;
    for i in 0..n {
        for j in 0..n {
            msg.column_mass[i * n + j] =
                0.01 * (0..n).map(|k| w[i * n + k] * w[k * n + j]).sum::<f64>();
        }
    }
    for (v, x) in msg.velocities_m_per_s[..nv].iter_mut().zip(c.chunks(3)) {
        *v = [0.01 * x[0], 0.01 * x[1], 0.01 * x[2]];
    }
    msg.damping_per_s = 5.0;
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn problems_in_reused_buffers_never_panic_and_stay_finite(
        problems in proptest::collection::vec(problem(), 1..5),
        moves in proptest::collection::vec([-0.01f64..0.01, -0.01f64..0.01, -0.01f64..0.01], 1..6),
    ) {
        let mut lp = LocalProblem::new();
        let mut msg = Box::<LocalContactMsg>::default();
        const { assert!(MAX_POINTS >= 64) };
        for (k, p) in problems.iter().enumerate() {
            to_wire(p, k as u64 + 1, &mut msg);
            prop_assert!(lp.set_from_wire(&msg).is_ok());
            let inertial = lp.set_inertia_from_wire(&msg, 0.03, 1e-3);
            prop_assert_eq!(inertial, Ok(msg.inertia == 1 && lp.is_ready()));
            let latest = ForceSample {
                t_ns: msg.t_ns,
                seq: msg.seq,
                position_m: msg.tool_position_m,
                force_n: [0.0, 0.0, 0.1],
                stiffness_n_per_m: [[100.0, 0.0, 0.0], [0.0, 100.0, 0.0], [0.0, 0.0, 100.0]],
                in_contact: k % 2 == 0,
                catching_up: false,
            };
            for (i, m) in moves.iter().enumerate() {
                let tool = [
                    msg.tool_position_m[0] + m[0],
                    msg.tool_position_m[1] + m[1],
                    msg.tool_position_m[2] + m[2],
                ];
                if let Some(f) = lp.render(&latest, msg.t_ns + (i as u64 + 1) * 1_000_000, tool, 3000.0) {
                    prop_assert!(f.iter().all(|x| x.is_finite()), "{f:?}");
                }
            }
        }
    }
}
