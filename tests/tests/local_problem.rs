//! The contact problem the simulation sends to the haptic loop (the
//! `local-contact` stream and the `local-problem` extrapolator), checked
//! against the simulation itself: its compliance is the tissue's static
//! response at its vertices, and solved again for a moved tool it predicts
//! the force the simulation settles to there.

use haptic_daemon::extrapolate::ForceSample;
use haptic_daemon::extrapolate::local_problem::{LocalContactMsg, LocalProblem};
use shared::protocol::ForceMsg;
use sim_server::contact::{LocalContact, StiffnessSolves, ToolInput};
use sim_server::prelude::*;
use sim_server::prepare::{Prepared, prepare};
use sim_server::scene::{SceneSource, build_scene};
use sim_server::wire::{force_sample, local_contact_into, local_contact_msg, tool_flags};
use std::path::PathBuf;

/// A 40 x 20 x 20 mm block on 5 mm cells, fixed at the bottom, with a
/// 2.5 mm probe; damped so that it settles in a few hundred steps.
fn block() -> Prepared<Explicit<f64>> {
    let text = r#"
[mesh]
generate = { shape = "box", size_m = [0.04, 0.02, 0.02], cell_m = 0.005 }

[material]
young_pa = 5000.0
poisson = 0.45
density_kg_m3 = 1000.0
damping_per_s = 40.0

[[fixed]]
name = "bottom"
select = { box_m = [[-0.001, -0.001, -0.001], [0.041, 0.021, 0.0001]] }

[[tool]]
name = "probe"
kind = "grasper"
fulcrum_m = [0.02, 0.01, 0.15]
length_m = 0.3
radius_m = 0.0025
tip_length_m = 0.01
"#;
    let src = SceneSource {
        name: "<block>".into(),
        dir: PathBuf::from("."),
        text: text.into(),
    };
    let built = build_scene(&src, &src.parse().unwrap()).unwrap();
    let mut p = prepare::<f64>(built, Some(1e-3)).unwrap();
    p.tools.set_stiffness_solves(StiffnessSolves::Inline);
    p
}

/// `steps` steps with the tip at `tip`; the last force message.
fn hold(p: &mut Prepared<Explicit<f64>>, tip: Vec3, steps: usize) -> ForceMsg {
    let mut msg = ForceMsg::default();
    for k in 0..steps {
        let input = [Some(ToolInput {
            tip_m: tip,
            jaw_opening: 1.0,
        })];
        p.tools.update(&mut p.sim, &input);
        let flags = tool_flags(p.tools.step(&mut p.sim));
        msg = force_sample(ForceMsg::default(), &p.tools, &p.sim, k as u64 + 1, &flags);
        msg.seq = k as u64;
    }
    msg
}

const TOP_M: f64 = 0.02;

/// The probe's tip 2.5 mm into the top between vertices.
fn pressed() -> (Prepared<Explicit<f64>>, Vec3, ForceMsg) {
    let mut p = block();
    let at = Vec3::new(0.0185, 0.0085, TOP_M + 0.0025 - 0.0025);
    for k in 0..=100 {
        hold(&mut p, at + Vec3::Z * (0.005 * (1.0 - k as f64 / 100.0)), 1);
    }
    let msg = hold(&mut p, at, 600);
    (p, at, msg)
}

#[test]
fn the_compliance_is_the_tissues_static_response_at_its_vertices() {
    let (mut p, _, _) = pressed();
    let mut lc = LocalContact::default();
    assert!(local_contact_into(&mut p.tools, &p.sim, 0, &mut lc));
    let nv = lc.vertices.len();
    assert!(nv >= 6 && !lc.points.is_empty(), "{nv} vertices");
    // Loads on V alone, solved statically with the bottom fixed: the
    // displacements at V are W times the loads.
    let model = p.sim.model();
    let mut fixed = Dirichlet::new(model.vertex_count());
    for (v, x) in model.mesh().positions_m().iter().enumerate() {
        if x.z < 1e-4 {
            fixed.fix(VertexId::from(v));
        }
    }
    let mut loads = vec![Vec3::ZERO; model.vertex_count()];
    let f: Vec<f64> = (0..3 * nv)
        .map(|i| ((i * 7919) % 13) as f64 * 0.01 - 0.06)
        .collect();
    for (k, &v) in lc.vertices.iter().enumerate() {
        loads[v as usize] = Vec3::new(f[3 * k], f[3 * k + 1], f[3 * k + 2]);
    }
    let u = solve_static(model, &fixed, &loads).unwrap().displacement_m;
    let n = 3 * nv;
    let w = &lc.compliance_m_per_n;
    let mut worst: f64 = 0.0;
    let mut size: f64 = 0.0;
    for (k, &v) in lc.vertices.iter().enumerate() {
        for r in 0..3 {
            let wf: f64 = (0..n).map(|c| w[(3 * k + r) * n + c] * f[c]).sum();
            worst = worst.max((wf - u[v as usize][r]).abs());
            size = size.max(u[v as usize][r].abs());
        }
    }
    assert!(size > 1e-6, "the loads move V: {size} m");
    assert!(
        worst <= 1e-9 * size.max(1e-3),
        "W f vs K^-1 f: {worst} m of {size}"
    );
    // Symmetric (a compliance).
    for i in 0..n {
        for j in 0..i {
            assert!((w[i * n + j] - w[j * n + i]).abs() <= 1e-12 * w[i * n + i].abs());
        }
    }
    // The column mass G = C^T M C: for loads f and g on V, f^T G g is the
    // kinetic-energy product of their static responses, u_f^T M u_g.
    let g_load: Vec<f64> = (0..n)
        .map(|i| ((i * 104_729) % 11) as f64 * 0.01 - 0.05)
        .collect();
    for (k, &v) in lc.vertices.iter().enumerate() {
        loads[v as usize] = Vec3::new(g_load[3 * k], g_load[3 * k + 1], g_load[3 * k + 2]);
    }
    let ug = solve_static(model, &fixed, &loads).unwrap().displacement_m;
    let m = model.masses_kg();
    let direct: f64 = (0..model.vertex_count())
        .map(|i| m[i] * u[i].dot(ug[i]))
        .sum();
    let gm = &lc.column_mass;
    assert_eq!(gm.len(), n * n, "the inertia is carried");
    let via_g: f64 = (0..n)
        .map(|i| f[i] * (0..n).map(|j| gm[i * n + j] * g_load[j]).sum::<f64>())
        .sum();
    assert!(direct.abs() > 0.0);
    assert!(
        (via_g - direct).abs() <= 1e-9 * direct.abs(),
        "f^T G g {via_g} vs u_f^T M u_g {direct}"
    );
    // The velocities are the vertices' own, the damping the scene's.
    for (k, &v) in lc.vertices.iter().enumerate() {
        assert_eq!(
            lc.velocities_m_per_s[k],
            p.sim.velocity(VertexId::from(v as usize))
        );
    }
    assert!(
        (lc.damping_per_s - 40.0).abs() < 1e-9,
        "{}",
        lc.damping_per_s
    );
}

#[test]
fn solved_for_a_moved_tool_the_problem_predicts_the_settled_force() {
    let (mut p, at, msg_a) = pressed();
    let mut lc = LocalContact::default();
    assert!(local_contact_into(&mut p.tools, &p.sim, 0, &mut lc));
    let mut wire = Box::<LocalContactMsg>::default();
    local_contact_msg(&lc, 0, msg_a.seq, msg_a.t_ns, &mut wire);
    let mut lp = LocalProblem::new();
    lp.set_from_wire(&wire).unwrap();
    let sample = ForceSample::from_wire(&msg_a, 0).unwrap();
    assert!(sample.in_contact && sample.force_n[2] > 0.05, "{sample:?}");
    // At the sample's own pose the problem renders the sample.
    let same = lp
        .render(&sample, sample.t_ns, sample.position_m, f64::INFINITY)
        .unwrap();
    assert!((0..3).all(|i| (same[i] - sample.force_n[i]).abs() < 1e-12));
    // 0.6 mm deeper and 1 mm aside, slowly, then settled.
    let b = at + Vec3::new(0.001, 0.0, -0.0006);
    for k in 1..=200 {
        hold(&mut p, at.lerp(b, k as f64 / 200.0), 1);
    }
    let settled = ForceSample::from_wire(&hold(&mut p, b, 600), 0).unwrap();
    let predicted = lp
        .render(&sample, sample.t_ns, b.to_array(), f64::INFINITY)
        .unwrap();
    let err: f64 = (0..3)
        .map(|i| (predicted[i] - settled.force_n[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    let change: f64 = (0..3)
        .map(|i| (settled.force_n[i] - sample.force_n[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    eprintln!(
        "sample {:?} -> settled {:?}, predicted {predicted:?}: error {err:.5} N of a {change:.4} N change",
        sample.force_n, settled.force_n
    );
    assert!(change > 0.02, "the move changes the force: {change} N");
    assert!(err < 0.1 * change, "error {err} N of a {change} N change");
    // Withdrawn above the surface: nothing.
    let free = lp
        .render(
            &sample,
            sample.t_ns,
            (at + Vec3::Z * 0.01).to_array(),
            f64::INFINITY,
        )
        .unwrap();
    assert_eq!(free, [0.0; 3]);
}

/// The real processes: `sim-server run` on the box scene and
/// `haptic-daemon run --extrapolation local-problem` with the simulated
/// hand palpating it. The simulation publishes contact problems once the
/// daemon subscribes, the daemon sets them up and renders from them.
#[test]
fn the_daemon_renders_the_problems_the_simulation_sends() {
    let (d, sim_json, _) = palpate_the_box("localproblem", &[], 4);
    let num = |k: &str| d[k].as_f64().unwrap_or_else(|| panic!("{k}: {d}"));
    // One every 8 ms or more while the probe is near the surface on an
    // idle machine (about 250 in these 4 s); the stiffness worker that
    // adds the compliance runs at low priority, so a loaded machine (the
    // test suite in parallel) gets far fewer (42 seen).
    assert!(num("local_problems") >= 5.0, "{d}");
    assert_eq!(num("local_problems_refused"), 0.0, "{d}");
    // By default with the tissue's inertia the simulation sends.
    assert_eq!(num("local_problems_inertial"), num("local_problems"), "{d}");
    // The palpation's force (about 0.5 N at 6 mm), within the limit.
    let max = num("max_force_n");
    assert!(max > 0.1 && max <= num("force_limit_n"), "{d}");
    // The simulation's side: as many published, none dropped.
    let published = sim_json["local_problems"].as_u64().expect("local_problems");
    assert!(published >= num("local_problems") as u64, "{sim_json}");
    assert_eq!(sim_json["local_problems_dropped"], 0, "{sim_json}");
}

/// A 30 Hz simulation (`--dt-s`): each problem is caught up through the
/// ~33 ms of hand positions since its pose before the RT thread renders
/// it; the rendered force stays within the limit and takes energy from
/// the hand over the palpation (passive).
#[test]
fn a_slow_simulations_problems_are_caught_up_and_render_passively() {
    let (d, _, record) = palpate_the_box("localslow", &["--dt-s", "0.0333333"], 5);
    let num = |k: &str| d[k].as_f64().unwrap_or_else(|| panic!("{k}: {d}"));
    assert!(num("local_problems") >= 3.0, "{d}");
    assert_eq!(num("local_problems_refused"), 0.0, "{d}");
    assert_eq!(num("local_problems_inertial"), num("local_problems"), "{d}");
    let max = num("max_force_n");
    assert!(max > 0.1 && max <= num("force_limit_n"), "{d}");
    // Net work on the hand from the record: sum F . dx over the ticks.
    let text = std::fs::read_to_string(&record).expect("record");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (px, fx) = (col("pos_x_m"), col("force_x_n"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| {
            l.split(',')
                .map(|x| x.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    let work: f64 = rows
        .windows(2)
        .map(|w| {
            (0..3)
                .map(|c| w[0][fx + c] * (w[1][px + c] - w[0][px + c]))
                .sum::<f64>()
        })
        .sum();
    assert!(rows.len() > 3000, "{} ticks recorded", rows.len());
    assert!(
        work.is_finite() && work <= 0.0,
        "{work} J put into the hand"
    );
}

/// Runs `sim-server run` on the box (with `sim_args`) and the daemon with
/// the simulated hand on the palpation for `secs` s, recording; the
/// daemon's and the simulation's JSON and the record's path.
fn palpate_the_box(
    name: &str,
    sim_args: &[&str],
    secs: u32,
) -> (serde_json::Value, serde_json::Value, PathBuf) {
    use std::process::Stdio;
    use std::time::Duration;
    use system_tests::{
        Peer, binary, daemon_run, finish, read_json, scratch_dir, wait_bounded, wait_for,
    };
    let session = format!("{name}{}", std::process::id());
    let dir = scratch_dir(name);
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
    let mut sim = std::process::Command::new(binary("sim-server"))
        .args([
            "run",
            "--quiet",
            "--session",
            &session,
            "--duration-s",
            "60",
        ])
        .args(sim_args)
        .arg("--scene")
        .arg(data.join("box-probe.toml"))
        .arg("--json")
        .arg(dir.join("sim.json"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start sim-server");
    wait_for(&session, Peer::Simulation);
    let (json, record) = (dir.join("daemon.json"), dir.join("record.csv"));
    let daemon = daemon_run(&session)
        .arg("--device")
        .arg(format!(
            "simulated:{}",
            data.join("box-palpate.csv").display()
        ))
        .args(["--extrapolation", "local-problem", "--duration-s"])
        .arg(secs.to_string())
        .arg("--json")
        .arg(&json)
        .arg("--record")
        .arg(&record)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start haptic-daemon");
    finish(daemon, Duration::from_secs(30), "haptic-daemon");
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(sim.id() as libc::pid_t, libc::SIGTERM) };
    wait_bounded(&mut sim, Duration::from_secs(10), "sim-server");
    let d = read_json(&json);
    assert_eq!(d["extrapolation"], "local-problem", "{d}");
    (d, read_json(&dir.join("sim.json")), record)
}
