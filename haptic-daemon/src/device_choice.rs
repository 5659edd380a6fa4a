//! The devices `haptic-daemon run` drives, a closed set made from the
//! `--device` argument, and the real-time loop run on the one chosen.

use anyhow::{Result, bail};
use haptic_daemon::daemon::{ChainConfig, RtLoop, Shared};
use haptic_daemon::device::{
    Device, HandModel, Haply, Mapped, Path, Plugin, Replay, Simulated, Trajectory, WorkspaceMap,
};
use haptic_daemon::extrapolate::Method;
use haptic_daemon::extrapolate::local_problem::LocalProblem;
use haptic_daemon::rt::Pacer;
use haptic_daemon::safety::{SafetyConfig, SafetyState};
use serde::Serialize;
use shared::loop_stats::LoopHistogram;
use shared::monotonic_ns;
use shared::protocol::ForceMsg;
use shared::source::Source;
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// Makes the device `spec` names, placed in the scene by `map`; the built-in
/// poke of `simulated` aims at `poke` (scene coordinates, see
/// [`Path::poke_over`]), or at the z axis without it; a trajectory file is
/// in the device's own frame.
pub(crate) fn make_device(
    spec: &str,
    max_force_n: f64,
    poke: Option<Path>,
    map: WorkspaceMap,
) -> Result<DeviceChoice> {
    let (kind, arg) = spec
        .split_once(':')
        .map_or((spec, None), |(k, a)| (k, Some(a)));
    let placed = |d| Mapped::new(d, map);
    match (kind, arg) {
        ("simulated", None) => {
            let path = poke
                .unwrap_or_else(Path::default_poke)
                .in_device_frame(&map);
            Ok(DeviceChoice::Simulated(placed(Simulated::new(
                path,
                HandModel::default(),
                max_force_n,
            ))))
        }
        ("simulated", Some(file)) => {
            let t = Trajectory::read(std::path::Path::new(file))?;
            Ok(DeviceChoice::Simulated(placed(Simulated::new(
                Path::Trajectory(t),
                HandModel::default(),
                max_force_n,
            ))))
        }
        ("replay", Some(file)) => {
            let t = Trajectory::read(std::path::Path::new(file))?;
            Ok(DeviceChoice::Replay(Mapped::new(
                Replay::new(t, max_force_n),
                map,
            )))
        }
        ("plugin", Some(rest)) => {
            // plugin:PATH[:ARGS]
            let (lib, plugin_args) = rest.split_once(':').unwrap_or((rest, ""));
            Ok(DeviceChoice::Plugin(Mapped::new(
                Plugin::load(std::path::Path::new(lib), plugin_args)?,
                map,
            )))
        }
        ("haply", url) => Ok(DeviceChoice::Haply(Mapped::new(
            Haply::connect(url.unwrap_or("ws://localhost:10001"))?,
            map,
        ))),
        _ => bail!(
            "unknown device {spec:?}: use simulated, simulated:FILE.csv, replay:FILE.csv or plugin:LIB.so[:ARGS]"
        ),
    }
}

/// The devices this binary knows, as a closed set (the loop is generic).
pub(crate) enum DeviceChoice {
    Simulated(Mapped<Simulated>),
    Replay(Mapped<Replay>),
    Plugin(Mapped<Plugin>),
    Haply(Mapped<Haply>),
}

impl DeviceChoice {
    pub(crate) fn specs(&self) -> haptic_daemon::device::DeviceSpecs {
        match self {
            DeviceChoice::Simulated(d) => d.specs(),
            DeviceChoice::Replay(d) => d.specs(),
            DeviceChoice::Plugin(d) => d.specs(),
            DeviceChoice::Haply(d) => d.specs(),
        }
    }

    /// Runs the real-time loop on this device until it stops (the loop is
    /// generic over the device: one instance per kind).
    pub(crate) fn run_loop(self, cfg: LoopConfig, sub: Source<ForceMsg>) -> Result<RtEnd> {
        match self {
            DeviceChoice::Simulated(d) => run_loop(d, cfg, sub),
            DeviceChoice::Replay(d) => run_loop(d, cfg, sub),
            DeviceChoice::Plugin(d) => run_loop(d, cfg, sub),
            DeviceChoice::Haply(d) => run_loop(d, cfg, sub),
        }
    }
}

/// The device's own limit for the simulated and replayed devices (N).
pub(crate) const SIMULATED_DEVICE_MAX_FORCE_N: f64 = 8.0;

/// What the real-time thread's loop is given, once (with the force source
/// it opens on its own thread).
pub(crate) struct LoopConfig {
    pub method: Method,
    pub safety: SafetyConfig,
    pub chain: ChainConfig,
    pub local: Option<triple_buffer::Output<LocalProblem>>,
    pub shared: Arc<Shared>,
    pub period_ns: u64,
    pub spin_ns: u64,
}

/// What the RT thread reports at its end.
pub(crate) struct RtEnd {
    pub ticks: u64,
    pub overruns: u64,
    /// `local-problem`: each tick's render time.
    pub render_us: Option<Lateness>,
}

/// The loop on the RT thread: ticks until stop, then ramps the force to zero
/// and disables the device. A panic inside is caught so the device is still
/// zeroed and disabled. Returns the ticks, overruns and render times.
pub(crate) fn run_loop<D: Device>(
    device: D,
    cfg: LoopConfig,
    sub: Source<ForceMsg>,
) -> Result<RtEnd> {
    let LoopConfig {
        method,
        safety,
        chain,
        local,
        shared,
        period_ns,
        spin_ns,
    } = cfg;
    let mut rt = RtLoop::with_chain(device, method, safety, chain, Some(sub), shared.clone());
    if let Some(local) = local {
        rt = rt.with_local_problems(local);
    }
    let start = monotonic_ns();
    rt.enable(start)?;
    let mut pacer = Pacer::new(period_ns, start).with_spin(spin_ns);
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut stopping = false;
        loop {
            let (deadline, lateness) = pacer.wait();
            if !stopping && shared.flags.stop.load(Ordering::Acquire) {
                rt.shutdown(deadline);
                stopping = true;
            }
            rt.tick(deadline.saturating_add(lateness.max(0) as u64), lateness);
            if stopping && matches!(rt.safety_state(), SafetyState::Stopped(_)) {
                break;
            }
        }
    }));
    rt.disable();
    if outcome.is_err() {
        bail!("the real-time loop panicked; the device was zeroed and disabled");
    }
    Ok(RtEnd {
        ticks: rt.ticks(),
        overruns: pacer.overruns(),
        render_us: rt.render_times().map(Lateness::of),
    })
}

/// Percentiles of a loop histogram (us), as the summaries write them.
#[derive(Serialize)]
pub(crate) struct Lateness {
    pub(crate) p50: f64,
    pub(crate) p99: f64,
    pub(crate) p999: f64,
    pub(crate) max: f64,
}

impl Lateness {
    pub(crate) fn of(h: &LoopHistogram) -> Self {
        Self {
            p50: h.quantile_us(0.5),
            p99: h.quantile_us(0.99),
            p999: h.quantile_us(0.999),
            max: h.max_us(),
        }
    }
}
