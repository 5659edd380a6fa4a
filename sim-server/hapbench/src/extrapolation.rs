//! `hapbench extrapolation` (paper 5.2 with numbers): offline and
//! deterministic. The hand follows a trajectory; the simulation runs at the
//! simulation rate (a sample for the pose at t_j is delivered one period
//! later, stamped then, as a real-time simulation would send it) while the
//! haptic loop, at the haptic rate, renders each extrapolator from the
//! samples it has. The ground truth is the same simulation stepped at the
//! haptic rate with the pose of each tick, without delay.
//!
//! Per method: RMS and max force error against the truth, the 99th
//! percentile of the per-tick force change (what the hand feels as
//! roughness), and the net work the rendered force does on the hand
//! (sum of F . dp; positive means the rendering injected energy: an active,
//! potentially unstable device).

use anyhow::{Context, Result};
use haptic_daemon::device::Trajectory;
use haptic_daemon::extrapolate::{Extrapolator, ForceSample, Method};
use indicatif::ProgressBar;
use serde::Serialize;
use shared::protocol::ForceMsg;
use shared::protocol::MAX_TOOLS;
use sim_server::contact::{StiffnessSolves, ToolInput};
use sim_server::follow_refine::{FollowRefine, FollowReport};
use sim_server::math::Vec3;
use sim_server::prepare::{Prepared, prepare};
use sim_server::scene::spec::BackendName;
use sim_server::scene::{SceneSource, build_scene};
use sim_server::tensor_mass::Explicit;
use sim_server::wire::{force_sample, tool_flags};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::local_render::LocalRender;
use crate::phases::{Phase, away_from_snaps, classify, dropouts, near_snaps, rms_by_phase};
use crate::plot::{Axes, Series, chart};
use crate::progress::bar;

/// The default hand path (tool 0).
const PRESS_SLIDE_CSV: &str = include_str!("../../../tests/data/press-slide.csv");

/// Flags of `hapbench extrapolation`.
#[derive(clap::Args)]
pub struct Args {
    /// Scene (default: the embedded liver).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Hand path for tool 0, CSV `t_s,x_m,y_m,z_m[,jaw]` (default: press
    /// and slide on the liver, tests/data/press-slide.csv).
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    /// Simulation rate (Hz).
    #[arg(long, default_value_t = 60.0)]
    pub sim_rate: f64,
    /// Haptic rate (Hz).
    #[arg(long, default_value_t = 1000.0)]
    pub haptic_rate: f64,
    /// A transport delay (ms) added to every sample and contact problem
    /// on its way to the haptic loop (a network between the simulation
    /// and the daemon): each arrives this much later than the period after
    /// its pose.
    #[arg(long, default_value_t = 0.0)]
    pub delay_ms: f64,
    /// Write the results here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write SVG plots here.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Write the per-tick series here (CSV: time, hand position, the
    /// truth's force, then each method's force).
    #[arg(long)]
    pub series: Option<PathBuf>,
    /// Write the simulation's samples here as the haptic loop receives
    /// them (CSV: delivery time, pose time and position, force, contact
    /// flag, contact stiffness), to try an extrapolator offline against
    /// `--series`'s truth.
    #[arg(long)]
    pub samples: Option<PathBuf>,
}

/// One method's figures.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MethodResult {
    /// RMS of |F - F_truth| over the ticks (N).
    pub rms_error_n: f64,
    /// Max of |F - F_truth| (N).
    pub max_error_n: f64,
    /// 99th percentile of |F(t) - F(t - tick)| (N).
    pub p99_jump_n: f64,
    /// Work of the rendered force on the hand, sum of F . dp (J).
    pub net_energy_j: f64,
    /// RMS of |F - F_truth| per phase of the path (N).
    pub rms_error_by_phase_n: BTreeMap<&'static str, f64>,
    /// RMS of |F - F_truth| over the ticks away from the truth's snaps
    /// (N; see `phases::near_snaps`).
    pub rms_error_away_from_snaps_n: f64,
    /// The share of the squared error in the ticks near a snap (0 to 1).
    pub snap_error_share: f64,
    /// Ticks rendered as exactly 0 N while the newest sample delivered said
    /// contact with a force and the truth has one (above
    /// [`CONTACT_FORCE_N`]): a dropout the simulation did not have (a hand
    /// leaving the tissue faster than the samples is not one).
    pub zero_in_contact_ticks: usize,
}

/// How far the ground truth can be trusted: the same simulation with each
/// step split into twice as many integrator sub-steps.
#[derive(Serialize)]
struct TruthCheck {
    /// Sub-steps per haptic tick of the truth and of the check.
    substeps: [usize; 2],
    /// The truth's wall time a tick (us; this machine, this run, the
    /// refinement's rebuilds included).
    truth_wall_us_per_tick: f64,
    /// RMS of |F_truth - F_check| over the ticks (N).
    rms_difference_n: f64,
}

/// What the refinement that follows the tool did in one run.
#[derive(Serialize)]
struct Refinement {
    /// Meshes made after the first.
    rebuilds: u64,
    /// The most tetrahedra a mesh had, and the scene's own.
    most_tets: usize,
    /// Whether a mesh stopped at `refine_max_tets`.
    stopped_at_budget: bool,
    /// Why the mesh stayed once when it should have followed.
    pinned: Option<&'static str>,
    /// Wall time making meshes again, in all and the longest (s; this
    /// machine, this run).
    rebuild_wall_s: [f64; 2],
}

impl From<FollowReport> for Refinement {
    fn from(r: FollowReport) -> Self {
        Self {
            rebuilds: r.rebuilds,
            most_tets: r.most_tets,
            stopped_at_budget: r.stopped_at_budget,
            pinned: r.pinned,
            rebuild_wall_s: [r.rebuild_wall_s, r.longest_rebuild_wall_s],
        }
    }
}

#[derive(Serialize)]
struct Report {
    scene: String,
    trajectory: String,
    sim_rate_hz: f64,
    haptic_rate_hz: f64,
    /// `--delay-ms`.
    delay_ms: f64,
    duration_s: f64,
    ticks: usize,
    truth: MethodResult,
    truth_max_force_n: f64,
    truth_check: TruthCheck,
    /// Zero-force ticks of the truth with force within 50 ms on both sides.
    truth_dropout_ticks: usize,
    /// Ticks within a snap of the truth's force or 67 ms after one.
    truth_snap_ticks: usize,
    /// Ticks per phase.
    phase_ticks: BTreeMap<&'static str, usize>,
    methods: BTreeMap<&'static str, MethodResult>,
    /// With `[contact] refine_radius_m`: what the refinement that follows
    /// the tool did in the truth's run and in the simulation's.
    refinement: Option<[Refinement; 2]>,
    /// `local-problem`: wall time of one tick's render (us) over the
    /// ticks it solved, p50 / p99 / max (this machine, this run).
    local_problem_render_us: [f64; 3],
    /// `local-problem`: wall time of a problem's set-up with its catch-up
    /// (us), p50 / p99 / max: the daemon's set-up thread's work.
    local_problem_setup_us: [f64; 3],
}

fn scene_source(path: Option<&Path>) -> Result<SceneSource> {
    Ok(match path {
        Some(p) => SceneSource::read(p)?,
        None => SceneSource::embedded(),
    })
}

/// Tool 0's sample after a step, as the daemon would receive it (its
/// time and counter are set when it is delivered).
pub(crate) type Sample = ForceSample;

/// The scene built and checked for this bench: a tool, the tensor-mass
/// backend. Run once before the truth, so that a scene it cannot measure
/// is refused as such, not as a failure of the ground truth.
fn checked_scene(src: &SceneSource) -> Result<sim_server::scene::BuiltScene> {
    let scene = build_scene(src, &src.parse()?)?;
    anyhow::ensure!(
        !scene.tools.is_empty(),
        "the scene {} has no [[tool]]",
        src.name
    );
    // The truth and its check are explicit sub-steps (the check halves
    // them): a scene on another backend would be measured on a backend it
    // did not ask for, so it is refused rather than silently swapped.
    anyhow::ensure!(
        scene.settings.backend == BackendName::TensorMass,
        "{}: `[simulation] backend = \"{}\"`: hapbench extrapolation measures against the tensor-mass backend's haptic-rate truth (its check halves the explicit sub-steps); run it with `backend = \"tensor-mass\"`, or compare backends with `hapbench tradeoff`",
        src.name,
        scene.settings.backend.as_str()
    );
    Ok(scene)
}

/// One run of the simulation over the path.
struct Run {
    /// Tool 0's sample after each step.
    samples: Vec<Sample>,
    /// The most sub-steps a step used.
    most_substeps: usize,
    /// What the refinement that follows the tool did, if the scene has one.
    refinement: Option<FollowReport>,
    /// Wall time of the steps (s; this machine, this run).
    wall_s: f64,
}

/// Tool 0's force (and contact state) for each pose the loop gives, the
/// simulation stepped `dt_s` after each, in `substep_factor` times the
/// sub-steps stability needs; and the most sub-steps a step used.
fn simulate(
    src: &SceneSource,
    dt_s: f64,
    substep_factor: usize,
    poses: impl Iterator<Item = ([f64; 3], f64)>,
    steps: usize,
    bar: &ProgressBar,
    mut local: Option<&mut LocalRender>,
) -> Result<Run> {
    let mut scene = checked_scene(src)?;
    // `[contact] refine_radius_m`: the mesh follows the tool, made again
    // between two steps (offline, so the truth stays deterministic).
    let mut refinement = FollowRefine::new(src, &mut scene)?;
    let mut p = prepare::<f64>(scene, Some(dt_s))?;
    let configure = |p: &mut Prepared<Explicit<f64>>| {
        p.sim.set_substep_factor(substep_factor);
        // Offline: the stiffness of every sample exact, and the results
        // independent of thread timing.
        p.tools.set_stiffness_solves(StiffnessSolves::Inline);
    };
    configure(&mut p);
    let started = std::time::Instant::now();
    let mut out = Vec::with_capacity(steps);
    // The contact springs add sub-steps while the tool touches.
    let mut most_substeps = p.sim.substeps();
    let mut inputs = [None; MAX_TOOLS];
    for (tip, jaw) in poses.take(steps) {
        inputs[0] = Some(ToolInput {
            tip_m: Vec3::from_array(tip),
            jaw_opening: jaw,
        });
        p.tools.update(&mut p.sim, &inputs);
        let flags = tool_flags(p.tools.step(&mut p.sim));
        most_substeps = most_substeps.max(p.sim.substeps());
        // The live server's path: the reactions into a force message, and
        // the daemon's conversion out of it.
        let msg = force_sample(ForceMsg::default(), &p.tools, &p.sim, 1, &flags);
        let sample = ForceSample::from_wire(&msg, 0).context("the scene has no tool 0")?;
        anyhow::ensure!(
            sample.is_finite(),
            "the simulation diverged at step {}",
            out.len()
        );
        out.push(sample);
        if let Some(l) = local.as_deref_mut() {
            l.after_step(out.len() - 1, &sample, &mut p.tools, &p.sim);
        }
        if let Some(r) = &mut refinement {
            r.follow(&mut p, dt_s, configure)?;
        }
        bar.inc(1);
    }
    Ok(Run {
        samples: out,
        most_substeps,
        refinement: refinement.map(|r| r.report().clone()),
        wall_s: started.elapsed().as_secs_f64(),
    })
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn figures(
    rendered: &[[f64; 3]],
    truth: &[[f64; 3]],
    hand: &[[f64; 3]],
    phases: &[Phase],
    snaps: &[bool],
) -> MethodResult {
    let n = rendered.len().max(1);
    let err: Vec<f64> = rendered
        .iter()
        .zip(truth)
        .map(|(a, b)| norm(sub(*a, *b)))
        .collect();
    let mut jumps: Vec<f64> = rendered.windows(2).map(|w| norm(sub(w[1], w[0]))).collect();
    let p99 = crate::latency::stats(&mut jumps).p99;
    let energy: f64 = rendered
        .iter()
        .zip(hand.windows(2))
        .map(|(f, w)| {
            let d = sub(w[1], w[0]);
            f[0] * d[0] + f[1] * d[1] + f[2] * d[2]
        })
        .sum();
    let (rms_error_away_from_snaps_n, snap_error_share) = away_from_snaps(&err, snaps);
    MethodResult {
        rms_error_away_from_snaps_n,
        snap_error_share,
        rms_error_n: (err.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt(),
        max_error_n: err.iter().copied().fold(0.0, f64::max),
        p99_jump_n: p99,
        net_energy_j: energy,
        rms_error_by_phase_n: rms_by_phase(&err, phases),
        zero_in_contact_ticks: 0,
    }
}

/// A force the hand feels as contact (N): a tenth of a common device's
/// force resolution above nothing.
const CONTACT_FORCE_N: f64 = 0.02;

/// Whether sample `j` has reached the haptic loop at `t_s`: the sample for
/// the pose at `j s` is delivered one period later, plus the transport
/// delay (the rule every method's render and the counts below share).
fn delivered(j: usize, t_s: f64, s: f64, delay_s: f64) -> bool {
    (j + 1) as f64 * s + delay_s <= t_s + 1e-12
}

/// [`MethodResult::zero_in_contact_ticks`] of `rendered` (tick `k` at
/// `k h`, samples as [`delivered`]).
fn zero_in_contact(
    rendered: &[[f64; 3]],
    truth: &[[f64; 3]],
    samples: &[ForceSample],
    h: f64,
    s: f64,
    delay_s: f64,
) -> usize {
    let mut next = 0;
    let mut zeros = 0;
    for (k, f) in rendered.iter().enumerate() {
        let t = k as f64 * h;
        while next < samples.len() && delivered(next, t, s, delay_s) {
            next += 1;
        }
        let newest = next.checked_sub(1).map(|j| &samples[j]);
        if *f == [0.0; 3]
            && truth.get(k).is_some_and(|t| norm(*t) > CONTACT_FORCE_N)
            && newest.is_some_and(|x| x.in_contact && norm(x.force_n) > 0.0)
        {
            zeros += 1;
        }
    }
    zeros
}

/// The per-tick CSV of `--series`.
fn write_series(
    path: &Path,
    h: f64,
    hand: &[[f64; 3]],
    truth: &[[f64; 3]],
    methods: &[(&str, Vec<[f64; 3]>)],
) -> Result<()> {
    use std::fmt::Write as _;
    let mut s = String::from("t_s,x_m,y_m,z_m,truth_fx_n,truth_fy_n,truth_fz_n");
    for (name, _) in methods {
        write!(s, ",{name}_fx_n,{name}_fy_n,{name}_fz_n")?;
    }
    s.push('\n');
    for (k, f) in truth.iter().enumerate() {
        let p = hand[k];
        write!(
            s,
            "{:.4},{},{},{},{},{},{}",
            k as f64 * h,
            p[0],
            p[1],
            p[2],
            f[0],
            f[1],
            f[2]
        )?;
        for (_, r) in methods {
            let r = r[k];
            write!(s, ",{},{},{}", r[0], r[1], r[2])?;
        }
        s.push('\n');
    }
    std::fs::write(path, s).with_context(|| format!("cannot write {}", path.display()))
}

/// The samples of `--samples`, as the haptic loop receives them: one line
/// per simulation step, CSV `delivered_s,pose_s,x_m,y_m,z_m,fx_n,fy_n,fz_n,
/// in_contact,k00..k22` (the contact stiffness row by row, N/m, dF = -K dP).
fn write_samples(path: &Path, period_s: f64, delay_s: f64, samples: &[Sample]) -> Result<()> {
    use std::fmt::Write as _;
    let mut o = String::from("delivered_s,pose_s,x_m,y_m,z_m,fx_n,fy_n,fz_n,in_contact");
    for i in 0..3 {
        for j in 0..3 {
            write!(o, ",k{i}{j}_n_per_m")?;
        }
    }
    o.push('\n');
    for (j, x) in samples.iter().enumerate() {
        let pose_s = j as f64 * period_s;
        let (p, f) = (x.position_m, x.force_n);
        write!(
            o,
            "{},{pose_s},{},{},{},{},{},{},{}",
            pose_s + period_s + delay_s,
            p[0],
            p[1],
            p[2],
            f[0],
            f[1],
            f[2],
            u8::from(x.in_contact)
        )?;
        for v in x.stiffness_n_per_m.iter().flatten() {
            write!(o, ",{v}")?;
        }
        o.push('\n');
    }
    std::fs::write(path, o).with_context(|| format!("cannot write {}", path.display()))
}

/// The highest haptic rate simulated (Hz): `haptic-daemon run --rate`'s.
const MAX_HAPTIC_RATE_HZ: f64 = 10_000.0;

/// The longest trajectory simulated (s): an hour at 10 kHz is 36 million
/// ticks, kept for every method.
const MAX_DURATION_S: f64 = 3600.0;

/// Runs the benchmark.
pub fn run(args: &Args) -> Result<()> {
    // The simulation's step is its period: within the scenes' bounds on
    // a step, and no faster than the haptic loop (it was told "use dt_s
    // <= 2 s" at 0.01 Hz, and about --haptic-rate at 1e9 Hz).
    use sim_server::scene::MAX_DT_S;
    anyhow::ensure!(
        args.sim_rate.is_finite()
            && args.sim_rate >= 1.0 / MAX_DT_S
            && args.sim_rate <= args.haptic_rate,
        "--sim-rate must be at least {} Hz (a step of at most {MAX_DT_S} s) and at most the haptic rate ({} Hz), got {}",
        1.0 / MAX_DT_S,
        args.haptic_rate,
        args.sim_rate
    );
    anyhow::ensure!(
        args.haptic_rate.is_finite()
            && args.haptic_rate >= args.sim_rate
            && args.haptic_rate <= MAX_HAPTIC_RATE_HZ,
        "--haptic-rate must be at least the simulation rate and at most {MAX_HAPTIC_RATE_HZ} Hz (the daemon's range)"
    );
    anyhow::ensure!(
        args.delay_ms.is_finite() && (0.0..=1000.0).contains(&args.delay_ms),
        "--delay-ms must be between 0 and 1000"
    );
    let src = scene_source(args.scene.as_deref())?;
    let (traj, traj_name) = match &args.trajectory {
        Some(p) => (Trajectory::read(p)?, p.display().to_string()),
        None => (
            Trajectory::parse("press-slide.csv", PRESS_SLIDE_CSV)?,
            "press-slide.csv (built in)".into(),
        ),
    };
    let duration = traj.duration_s();
    println!(
        "run: scene {}{}, trajectory {traj_name} ({duration:.2} s), simulation {} Hz{}, haptic {} Hz{}, delay {} ms",
        src.name,
        if args.scene.is_none() {
            " (default)"
        } else {
            ""
        },
        args.sim_rate,
        if args.sim_rate == 60.0 {
            " (default)"
        } else {
            ""
        },
        args.haptic_rate,
        if args.haptic_rate == 1000.0 {
            " (default)"
        } else {
            ""
        },
        args.delay_ms
    );
    // Every tick of the truth, each method and the series is kept: a
    // trajectory of days would ask for more memory than any machine has.
    anyhow::ensure!(
        duration <= MAX_DURATION_S,
        "the trajectory lasts {duration} s; at most {MAX_DURATION_S} s are simulated tick by tick"
    );
    let (h, s) = (1.0 / args.haptic_rate, 1.0 / args.sim_rate);
    let ticks = (duration / h).floor() as usize;
    let sim_steps = (duration / s).ceil() as usize + 1;
    checked_scene(&src)?;
    let b = bar(ticks, "truth");
    let haptic_poses = || (0..).map(|k| traj.sample(k as f64 * h));
    let Run {
        samples: truth,
        most_substeps: truth_substeps,
        refinement: truth_refinement,
        wall_s: truth_wall_s,
    } = simulate(&src, h, 1, haptic_poses(), ticks, &b, None).context("ground truth")?;
    b.finish();
    let b = bar(ticks, "truth, twice the sub-steps");
    let Run {
        samples: check,
        most_substeps: check_substeps,
        ..
    } = simulate(&src, h, 2, haptic_poses(), ticks, &b, None)
        .context("ground truth with twice the sub-steps")?;
    b.finish();
    let hand: Vec<[f64; 3]> = (0..=ticks).map(|k| traj.sample(k as f64 * h).0).collect();
    let delay_s = args.delay_ms * 1e-3;
    let mut local = LocalRender::new(&hand[..ticks], h, s, delay_s, ticks);
    let b = bar(sim_steps, "simulation");
    let Run {
        samples,
        refinement: sample_refinement,
        ..
    } = simulate(
        &src,
        s,
        1,
        (0..).map(|j| traj.sample(j as f64 * s)),
        sim_steps,
        &b,
        Some(&mut local),
    )
    .context("simulation at the simulation rate")?;
    b.finish();

    if let Some(path) = &args.samples {
        write_samples(path, s, delay_s, &samples)?;
    }
    let truth_f: Vec<[f64; 3]> = truth.iter().map(|t| t.force_n).collect();
    let check_f: Vec<[f64; 3]> = check.iter().map(|t| t.force_n).collect();
    let phases = classify(&truth_f, &hand, h);
    let snaps = near_snaps(&truth_f, h);
    let ns = |t: f64| (t * 1e9).round() as u64;
    let mut methods = BTreeMap::new();
    let mut rendered_all = Vec::new();
    // Every extrapolator but `local-problem` from the samples alone; that
    // one was rendered during the simulation.
    local.rendered.resize(ticks, [0.0; 3]);
    let render_us = percentiles_us(std::mem::take(&mut local.render_ns));
    let setup_us = percentiles_us(std::mem::take(&mut local.setup_ns));
    let mut local_rendered = Some(std::mem::take(&mut local.rendered));
    {
        let mut rendered = std::mem::take(&mut local.quasi_rendered);
        rendered.resize(ticks, [0.0; 3]);
        methods.insert(
            "local-problem-quasi-static",
            MethodResult {
                zero_in_contact_ticks: zero_in_contact(
                    &rendered, &truth_f, &samples, h, s, delay_s,
                ),
                ..figures(&rendered, &truth_f, &hand, &phases, &snaps)
            },
        );
        rendered_all.push(("local-problem-quasi-static", rendered));
    }
    for method in Method::ALL {
        if method == Method::LocalProblem
            && let Some(rendered) = local_rendered.take()
        {
            methods.insert(
                method.name(),
                MethodResult {
                    zero_in_contact_ticks: zero_in_contact(
                        &rendered, &truth_f, &samples, h, s, delay_s,
                    ),
                    ..figures(&rendered, &truth_f, &hand, &phases, &snaps)
                },
            );
            rendered_all.push((method.name(), rendered));
            continue;
        }
        let mut ex = Extrapolator::new(method);
        let mut next = 0;
        let mut rendered = Vec::with_capacity(ticks);
        for (k, p) in hand.iter().take(ticks).enumerate() {
            let t = k as f64 * h;
            // Sample j (pose at j s) is delivered one simulation period
            // later, plus the transport delay.
            while next < samples.len() && delivered(next, t, s, delay_s) {
                ex.push(&ForceSample {
                    t_ns: ns((next + 1) as f64 * s),
                    seq: next as u64,
                    ..samples[next]
                });
                next += 1;
            }
            rendered.push(ex.force(ns(t), *p));
        }
        methods.insert(
            method.name(),
            MethodResult {
                zero_in_contact_ticks: zero_in_contact(
                    &rendered, &truth_f, &samples, h, s, delay_s,
                ),
                ..figures(&rendered, &truth_f, &hand, &phases, &snaps)
            },
        );
        rendered_all.push((method.name(), rendered));
    }
    let report = Report {
        scene: src.name.clone(),
        trajectory: traj_name,
        sim_rate_hz: args.sim_rate,
        haptic_rate_hz: args.haptic_rate,
        delay_ms: args.delay_ms,
        duration_s: duration,
        ticks,
        truth: figures(&truth_f, &truth_f, &hand, &phases, &snaps),
        truth_max_force_n: truth_f.iter().map(|f| norm(*f)).fold(0.0, f64::max),
        truth_check: TruthCheck {
            substeps: [truth_substeps, check_substeps],
            truth_wall_us_per_tick: truth_wall_s * 1e6 / ticks.max(1) as f64,
            rms_difference_n: figures(&check_f, &truth_f, &hand, &phases, &snaps).rms_error_n,
        },
        truth_dropout_ticks: dropouts(&truth_f, h),
        truth_snap_ticks: snaps.iter().filter(|n| **n).count(),
        refinement: truth_refinement
            .zip(sample_refinement)
            .map(|(a, b)| [a.into(), b.into()]),
        local_problem_render_us: render_us,
        local_problem_setup_us: setup_us,
        phase_ticks: phases.iter().fold(BTreeMap::new(), |mut m, p| {
            *m.entry(p.name()).or_insert(0) += 1;
            m
        }),
        methods,
    };
    println!(
        "{:<24} {:>12} {:>12} {:>12} {:>14} {:>16} {:>10}",
        "method",
        "rms err N",
        "max err N",
        "p99 jump N",
        "net energy mJ",
        "away snaps N",
        "0N in cont"
    );
    for (name, m) in std::iter::once(("truth (haptic rate)", &report.truth))
        .chain(report.methods.iter().map(|(k, v)| (*k, v)))
    {
        println!(
            "{name:<24} {:>12.4} {:>12.4} {:>12.4} {:>14.3} {:>16.4} {:>10}",
            m.rms_error_n,
            m.max_error_n,
            m.p99_jump_n,
            m.net_energy_j * 1e3,
            m.rms_error_away_from_snaps_n,
            m.zero_in_contact_ticks
        );
    }
    let names: Vec<&str> = report.phase_ticks.keys().copied().collect();
    print!("\nrms error by phase (N)  ");
    for n in &names {
        print!(" {:>9}", format!("{n}:{}", report.phase_ticks[n]));
    }
    println!();
    for (name, m) in report.methods.iter() {
        print!("{name:<24}");
        for n in &names {
            print!(
                " {:>9.4}",
                m.rms_error_by_phase_n.get(n).copied().unwrap_or(0.0)
            );
        }
        println!();
    }
    println!(
        "\nlocal-problem: a tick's render {:.1} us p50, {:.1} us p99, {:.1} us max; a problem's set-up with its catch-up {:.0} / {:.0} / {:.0} us",
        report.local_problem_render_us[0],
        report.local_problem_render_us[1],
        report.local_problem_render_us[2],
        report.local_problem_setup_us[0],
        report.local_problem_setup_us[1],
        report.local_problem_setup_us[2]
    );
    println!(
        "\ntruth: max |F| {:.3} N, {} dropout ticks, {} ticks near snaps; {} vs {} sub-steps per tick differ by {:.4} N RMS; {:.0} us of wall time a tick",
        report.truth_max_force_n,
        report.truth_dropout_ticks,
        report.truth_snap_ticks,
        report.truth_check.substeps[0],
        report.truth_check.substeps[1],
        report.truth_check.rms_difference_n,
        report.truth_check.truth_wall_us_per_tick
    );
    if let Some([t, s]) = &report.refinement {
        println!(
            "refinement round the tool: the truth made {} meshes (at most {} tetrahedra; {:.2} s of wall time, the longest {:.1} ms), the simulation {} (at most {}){}{}",
            t.rebuilds,
            t.most_tets,
            t.rebuild_wall_s[0],
            t.rebuild_wall_s[1] * 1e3,
            s.rebuilds,
            s.most_tets,
            if t.stopped_at_budget || s.stopped_at_budget {
                "; stopped at refine_max_tets"
            } else {
                ""
            },
            t.pinned
                .or(s.pinned)
                .map_or(String::new(), |w| format!("; held while {w}"))
        );
    }
    if let Some(path) = &args.json {
        sim_server::provenance::write_stamped(path, &report)?;
    }
    if let Some(path) = &args.series {
        write_series(path, h, &hand, &truth_f, &rendered_all)?;
    }
    if let Some(dir) = &args.plot {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let curve = |f: &[[f64; 3]]| -> Vec<(f64, f64)> {
            f.iter()
                .enumerate()
                .map(|(k, v)| (k as f64 * h, norm(*v)))
                .collect()
        };
        let mut series = vec![Series::line("truth", curve(&truth_f))];
        for (name, r) in &rendered_all {
            series.push(Series::line(name, curve(r)));
        }
        let title = format!(
            "|F| on tool 0: {}, {}, simulation {} Hz, haptic {} Hz{}",
            src.name,
            Path::new(&report.trajectory)
                .file_name()
                .map_or(report.trajectory.clone(), |n| n
                    .to_string_lossy()
                    .into_owned()),
            args.sim_rate,
            args.haptic_rate,
            if args.delay_ms > 0.0 {
                format!(", delay {} ms", args.delay_ms)
            } else {
                String::new()
            }
        );
        for (file, x0, x1) in [
            ("extrapolation.svg", 0.0, duration),
            ("extrapolation-zoom.svg", 1.0, 2.0),
        ] {
            let svg = chart(
                &title,
                "time (s)",
                "|F| (N)",
                x0,
                x1.min(duration),
                &series,
                Axes::default(),
            );
            let path = dir.join(file);
            std::fs::write(&path, svg)
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
    }
    Ok(())
}

/// p50, p99 and the largest of durations (ns) in microseconds (zeros when
/// there are none).
fn percentiles_us(mut t: Vec<u64>) -> [f64; 3] {
    t.sort_unstable();
    let q = |f: f64| {
        t.get(((t.len() as f64 - 1.0) * f) as usize)
            .map_or(0.0, |x| *x as f64 * 1e-3)
    };
    [q(0.5), q(0.99), q(1.0)]
}
