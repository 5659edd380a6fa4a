//! `hapbench stability`: the extremes, each reported as `stable`,
//! `refused` (with the message the user would get) or `diverged-detected`
//! (non-finite or runaway displacements caught before any force left),
//! never a NaN force out. A 4 x 2 x 2 cm block, fixed at x = 0, pulled at
//! the free end and pressed by a hook from above.

use anyhow::{Context, Result};
use serde::Serialize;
use shared::protocol::MAX_TOOLS;
use sim_server::contact::ToolInput;
use sim_server::math::Vec3;
use sim_server::prepare::prepare;
use sim_server::scene::{SceneSource, build_scene};
use sim_server::tensor_mass::element_bound;
use std::path::PathBuf;

use crate::plot::{Axes, Scale, Series, chart};
use crate::progress::bar;
use indicatif::ProgressBar;

/// Flags of `hapbench stability`.
#[derive(clap::Args)]
pub struct Args {
    /// Simulated seconds per case.
    #[arg(long, default_value_t = 0.5)]
    pub duration_s: f64,
    /// Write the results here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write SVG plots (stable step and displacement per family) here.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// Cases in a run (for the progress bar).
const CASES: usize = 33;

/// One chart per family of cases: the stable step bound and the largest
/// displacement against the pushed value (on a log axis for the wide
/// ranges), each case simulated for `duration_s`.
fn plot(dir: &std::path::Path, cases: &[Case], duration_s: f64) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    for (family, log) in [
        ("poisson", false),
        ("anisotropy_mu_ratio", true),
        ("membrane_alpha_over_young", true),
        ("sliver_thickness_m", true),
        ("sliver_damping_per_s", true),
    ] {
        let of: Vec<&Case> = cases.iter().filter(|c| c.case == family).collect();
        let pts = |f: &dyn Fn(&Case) -> f64| -> Vec<(f64, f64)> {
            of.iter()
                .filter(|c| c.outcome == "stable")
                .map(|c| (c.value, f(c)))
                .collect()
        };
        let (lo, hi) = of
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), c| {
                (lo.min(c.value), hi.max(c.value))
            });
        // A margin of 5% of the range each side, in the axis's own terms.
        let (x0, x1, scale) = if log {
            let m = (hi / lo).powf(0.05);
            (lo / m, hi * m, Scale::Log10)
        } else {
            (lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo), Scale::Linear)
        };
        // One unit per chart: the stable step, then the largest displacement.
        let bound = Series::markers("stable step", pts(&|c| c.dt_bound_s * 1e6));
        let moved = Series::markers("max |u|", pts(&|c| c.max_displacement_m * 1e3));
        let unstable = of.iter().filter(|c| c.outcome != "stable").count();
        for (what, series, unit) in [
            ("bound", bound, "element bound on the step (us)"),
            ("displacement", moved, "largest displacement (mm)"),
        ] {
            let svg = chart(
                &format!(
                    "Stable cases: {family}, {} of {} cases, {duration_s} s each",
                    of.len() - unstable,
                    of.len()
                ),
                family,
                unit,
                x0,
                x1,
                &[series],
                Axes {
                    x: scale,
                    y: Scale::Linear,
                },
            );
            let path = dir.join(format!("stability-{family}-{what}.svg"));
            std::fs::write(&path, svg)
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
    }
    Ok(())
}

/// One case's outcome.
#[derive(Clone, Debug, Serialize)]
pub struct Case {
    /// What is pushed to the extreme.
    pub case: &'static str,
    /// Its value.
    pub value: f64,
    /// `stable`, `refused` or `diverged-detected`.
    pub outcome: &'static str,
    /// The refusal or detection message.
    pub message: String,
    /// The stable step bound (s).
    pub dt_bound_s: f64,
    /// The step used (s).
    pub dt_s: f64,
    /// Sub-steps per step.
    pub substeps: usize,
    /// Largest displacement seen (m).
    pub max_displacement_m: f64,
    /// Largest displacement at the end of the run (m): where the scene
    /// settles, without the dynamic overshoot.
    pub final_displacement_m: f64,
    /// Largest force on the tool (N); always finite.
    pub max_force_n: f64,
}

/// Simulated time the tool is held at its path's first pose before the
/// path starts (s): the proxy travels from the fulcrum (10 cm) at 1 m/s.
const LEAD_IN_S: f64 = 0.25;

/// How the hook moves: (tip at time t).
type Path = Box<dyn Fn(f64) -> [f64; 3]>;

/// A small pull at the free end (the sliver plates go without it: a thin
/// cantilever's deflection grows with 1/thickness^3, which is physics, not
/// instability).
const PULL: &str = r#"
[[load]]
name = "pull"
select = { box_m = [[0.0399, -0.001, -0.001], [0.041, 0.021, 0.021]] }
force_n = [0.0, 0.0, -0.01]
"#;

const BLOCK: &str = r#"
[mesh]
generate = { shape = "box", size_m = [0.04, 0.02, 0.02], cell_m = 0.004 }

[[fixed]]
name = "wall"
select = { box_m = [[-0.001, -0.001, -0.001], [0.0001, 0.021, 0.021]] }

[[tool]]
name = "hook"
kind = "hook"
fulcrum_m = [0.03, 0.01, 0.12]
length_m = 0.3
radius_m = 0.003
tip_length_m = 0.01
"#;

fn material(nu: f64, extra: &str) -> String {
    format!(
        "\n[material]\nyoung_pa = 5000.0\npoisson = {nu}\ndensity_kg_m3 = 1000.0\ndamping_per_s = 5.0\n{extra}\n"
    )
}

/// Presses 3 mm into the top over 0.1 s, then holds.
fn press(t: f64) -> [f64; 3] {
    [0.03, 0.01, 0.02 + 0.003 - 0.006 * (t / 0.1).min(1.0)]
}

fn run_case(
    progress: &ProgressBar,
    case: &'static str,
    value: f64,
    scene: &str,
    dt_factor: Option<f64>,
    path: Path,
    duration_s: f64,
) -> Case {
    progress.inc(1);
    let mut out = Case {
        case,
        value,
        outcome: "stable",
        message: String::new(),
        dt_bound_s: f64::NAN,
        dt_s: f64::NAN,
        substeps: 0,
        max_displacement_m: 0.0,
        final_displacement_m: 0.0,
        max_force_n: 0.0,
    };
    let src = SceneSource {
        name: format!("<{case} = {value}>"),
        dir: PathBuf::from("."),
        text: scene.to_string(),
    };
    let built = match src.parse().and_then(|spec| build_scene(&src, &spec)) {
        Ok(b) => b,
        Err(e) => {
            out.outcome = "refused";
            out.message = e.to_string();
            return out;
        }
    };
    let bound = element_bound(&built.model).dt_max_s;
    out.dt_bound_s = bound;
    let dt = dt_factor.map_or(0.001, |f| f * bound);
    let mut p = match prepare::<f64>(built, Some(dt)) {
        Ok(p) => p,
        Err(e) => {
            out.outcome = "refused";
            out.message = e.to_string();
            return out;
        }
    };
    out.dt_s = dt;
    out.substeps = p.sim.substeps();
    let steps = (duration_s / dt).ceil() as usize;
    let mut inputs = [None; MAX_TOOLS];
    // The simulated tool comes in from its fulcrum no faster than a hand
    // (the contact's proxy): hold the path's first pose until it is there.
    let lead_in = (LEAD_IN_S / dt).ceil() as usize;
    for k in 0..lead_in + steps {
        let t = k.saturating_sub(lead_in) as f64 * dt;
        inputs[0] = Some(ToolInput {
            tip_m: Vec3::from_array(path(t)),
            jaw_opening: 1.0,
        });
        p.tools.update(&mut p.sim, &inputs);
        p.tools.step(&mut p.sim);
        let u_max = p
            .sim
            .displacements()
            .iter()
            .map(|u| u[0].hypot(u[1]).hypot(u[2]))
            .fold(0.0, f64::max);
        // Runaway: a displacement larger than the block itself many times over.
        if !u_max.is_finite() || u_max > 1.0 {
            out.outcome = "diverged-detected";
            out.message = format!(
                "displacements {} at step {k}: the force would be zeroed",
                if u_max.is_finite() {
                    "ran away"
                } else {
                    "became non-finite"
                }
            );
            return out;
        }
        out.max_displacement_m = out.max_displacement_m.max(u_max);
        out.final_displacement_m = u_max;
        let f = p.tools.reaction(0, &p.sim).force_n.length();
        out.max_force_n = out.max_force_n.max(f);
    }
    out
}

/// Runs every case.
pub fn run(args: &Args) -> Result<()> {
    anyhow::ensure!(
        args.duration_s.is_finite() && args.duration_s > 0.0,
        "--duration-s must be positive"
    );
    let d = args.duration_s;
    let progress = bar(CASES, "stability");
    let mut cases = Vec::new();
    let base =
        |nu: f64, extra: &str, sim: &str| format!("{BLOCK}{PULL}{}{sim}", material(nu, extra));
    for nu in [0.3, 0.45, 0.49, 0.499] {
        cases.push(run_case(
            &progress,
            "poisson",
            nu,
            &base(nu, "", ""),
            None,
            Box::new(press),
            d,
        ));
    }
    // Anisotropy: the paper's delta_mu (the fibre terms' shear modulus) at
    // `ratio - 1` times mu, delta_lambda 0 (a large delta_lambda alone is
    // refused as not positive definite, with the admissible range).
    let mu = 5000.0 / 2.8;
    for ratio in [1.0, 3.0, 10.0, 30.0, 100.0] {
        let extra = format!(
            "fiber = [1.0, 0.0, 0.0]\ndelta_lambda_pa = 0.0\ndelta_mu_pa = {}",
            (ratio - 1.0) * mu
        );
        cases.push(run_case(
            &progress,
            "anisotropy_mu_ratio",
            ratio,
            &base(0.4, &extra, ""),
            None,
            Box::new(press),
            d,
        ));
    }
    cases.push(run_case(
        &progress,
        "anisotropy_delta_lambda_over_lambda",
        2.0,
        &base(
            0.4,
            &format!(
                "fiber = [1.0, 0.0, 0.0]\ndelta_lambda_pa = {}\ndelta_mu_pa = 0.0",
                2.0 * 5000.0 * 0.4 / (1.4 * 0.2)
            ),
            "",
        ),
        None,
        Box::new(press),
        d,
    ));
    for factor in [1.0, 10.0, 100.0, 1000.0] {
        let sim = format!("\n[membrane]\nalpha = {}\n", 5000.0 * factor);
        cases.push(run_case(
            &progress,
            "membrane_alpha_over_young",
            factor,
            &base(0.4, "", &sim),
            None,
            Box::new(press),
            d,
        ));
    }
    for (policy, factors) in [
        ("unchecked", [0.5, 0.9, 1.1, 1.5]),
        ("refuse", [0.5, 0.9, 1.1, 1.5]),
        ("substep", [0.5, 0.9, 1.1, 1.5]),
    ] {
        for f in factors {
            let sim = format!("\n[simulation]\ndt_policy = \"{policy}\"\n");
            let name = match policy {
                "unchecked" => "dt_over_bound_unchecked",
                "refuse" => "dt_over_bound_refuse",
                _ => "dt_over_bound_substep",
            };
            cases.push(run_case(
                &progress,
                name,
                f,
                &base(0.4, "", &sim),
                Some(f),
                Box::new(press),
                d,
            ));
        }
    }
    // Slivers: a cell edge so short in z that the elements are flat; then
    // the thinnest under more mass damping (the scene's 5 /s, 20 /s, 80 /s),
    // to tell the plate's own dynamics from the contact's.
    let sliver = |h: f64, damping: f64| {
        let scene = format!("{BLOCK}{}", material(0.4, ""))
            .replace(
                "size_m = [0.04, 0.02, 0.02], cell_m = 0.004",
                &format!("size_m = [0.04, 0.02, {h}], cell_m = 0.004"),
            )
            .replace(
                "damping_per_s = 5.0",
                &format!("damping_per_s = {damping:?}"),
            );
        let on_top = move |t: f64| {
            let [x, y, z] = press(t);
            [x, y, z - 0.02 + h]
        };
        (scene, on_top)
    };
    for h in [0.004, 0.001, 0.0002] {
        let (scene, on_top) = sliver(h, 5.0);
        cases.push(run_case(
            &progress,
            "sliver_thickness_m",
            h,
            &scene,
            None,
            Box::new(on_top),
            d,
        ));
    }
    for damping in [20.0, 80.0] {
        let (scene, on_top) = sliver(0.0002, damping);
        cases.push(run_case(
            &progress,
            "sliver_damping_per_s",
            damping,
            &scene,
            None,
            Box::new(on_top),
            d,
        ));
    }
    cases.push(run_case(
        &progress,
        "tool_depth_m",
        0.05,
        &base(0.4, "", ""),
        None,
        // Down from the top to 50 mm below it (through the 20 mm block)
        // in 0.25 s, a fast hand (0.2 m/s): the tool follows a moving hand
        // at its pace, where it would only creep towards a hand standing
        // that deep from the start (the proxy's entry speed).
        Box::new(|t| [0.03, 0.01, 0.02 + 0.003 - 0.053 * (t / 0.25).min(1.0)]),
        d,
    ));
    cases.push(run_case(
        &progress,
        "tool_speed_m_s",
        2.0,
        &base(0.4, "", ""),
        None,
        Box::new(|t| [0.03 - 2.0 * (t - 0.05).max(0.0), 0.01, 0.018]),
        d,
    ));
    progress.finish_and_clear();
    println!(
        "{:<28} {:>9} {:<18} {:>11} {:>9} {:>10} {:>10} {:>9}",
        "case", "value", "outcome", "bound us", "substeps", "max u mm", "final u mm", "max F N"
    );
    for c in &cases {
        println!(
            "{:<28} {:>9} {:<18} {:>11.2} {:>9} {:>10.3} {:>10.3} {:>9.3}{}",
            c.case,
            c.value,
            c.outcome,
            c.dt_bound_s * 1e6,
            c.substeps,
            c.max_displacement_m * 1e3,
            c.final_displacement_m * 1e3,
            c.max_force_n,
            if c.message.is_empty() {
                String::new()
            } else {
                format!("  ({})", c.message)
            }
        );
    }
    if let Some(dir) = &args.plot {
        plot(dir, &cases, args.duration_s)?;
    }
    if let Some(path) = &args.json {
        sim_server::provenance::write_stamped(path, &serde_json::json!({ "cases": cases }))?;
    }
    Ok(())
}
