//! The command-line flags of the daemon's checks (`haptic-daemon run`):
//! pose plausibility, live force samples, the local model's stiffness cap
//! and the passivity observer/controller.

use anyhow::{Context, Result, bail};
use haptic_daemon::daemon::ChainConfig;
use haptic_daemon::device::max_stiffness_preset;
use haptic_daemon::live::{DEFAULT_MAX_RATE, DEFAULT_SLACK_NS, LiveConfig};
use haptic_daemon::plausible::{
    DEFAULT_MAX_ACCEL_M_S2, DEFAULT_MAX_REJECT_RUN_NS, DEFAULT_MAX_SPEED_M_S, DEFAULT_TOLERANCE_M,
    PlausibleConfig,
};
use haptic_daemon::safety::PassivityConfig;
use haptic_daemon::safety::passivity::{DEFAULT_MAX_DAMPING_N_S_PER_M, DEFAULT_TOLERANCE_J};

/// The checks' flags.
#[derive(clap::Args)]
pub struct ChainArgs {
    /// Cap on the stiffness the local model renders (N/m, or touch = 400,
    /// falcon = 3000, omega = 5000); at most the device's own (simulated and
    /// replay 3000, haply 2500, a plugin what it reports). Default: the
    /// device's.
    #[arg(long)]
    max_stiffness_n_per_m: Option<String>,
    /// Device samples faster than this are rejected (m/s; a surgeon's hand
    /// peaks around 1-2 m/s).
    #[arg(long, default_value_t = DEFAULT_MAX_SPEED_M_S)]
    max_speed_m_s: f64,
    /// Device samples accelerating harder than this are rejected (m/s^2).
    #[arg(long, default_value_t = DEFAULT_MAX_ACCEL_M_S2)]
    max_accel_m_s2: f64,
    /// Slack on the speed and acceleration bounds (m; sensor noise and
    /// sample-timing jitter).
    #[arg(long, default_value_t = DEFAULT_TOLERANCE_M)]
    pose_tolerance_m: f64,
    /// After rejecting device samples for this long, take the device's pose
    /// as the new reference and ramp the force in (ms).
    #[arg(long, default_value_t = DEFAULT_MAX_REJECT_RUN_NS as f64 / 1e6)]
    max_reject_run_ms: f64,
    /// Force samples whose simulated time runs faster than this times wall
    /// time are not rendered (a simulation fast-forwarding after a stall).
    #[arg(long, default_value_t = DEFAULT_MAX_RATE)]
    max_sim_rate: f64,
    /// Simulated time a stream may run ahead, on top of one simulation step,
    /// before it counts as fast (ms).
    #[arg(long, default_value_t = DEFAULT_SLACK_NS as f64 / 1e6)]
    sim_slack_ms: f64,
    /// Turn the passivity observer/controller off.
    #[arg(long)]
    no_passivity: bool,
    /// Energy the rendered environment may generate before the passivity
    /// controller damps (J).
    #[arg(long, default_value_t = DEFAULT_TOLERANCE_J)]
    passivity_tolerance_j: f64,
    /// Largest damping the passivity controller adds (N s/m).
    #[arg(long, default_value_t = DEFAULT_MAX_DAMPING_N_S_PER_M)]
    max_damping_n_s_per_m: f64,
}

impl ChainArgs {
    /// The daemon's checks from the command line, validated; the stiffness cap
    /// at most the device's `device_max_stiffness_n_per_m`.
    pub fn config(&self, device_max_stiffness_n_per_m: f64) -> Result<ChainConfig> {
        let args = self;
        let max_stiffness_n_per_m = match args.max_stiffness_n_per_m.as_deref() {
            None => None,
            Some(v) => {
                let k = match max_stiffness_preset(v) {
                    Some(k) => k,
                    None => v.parse::<f64>().with_context(|| {
                        format!(
                            "--max-stiffness-n-per-m {v:?}: give N/m or one of touch, falcon, omega"
                        )
                    })?,
                };
                if k > device_max_stiffness_n_per_m {
                    bail!(
                        "--max-stiffness-n-per-m {k} N/m exceeds the device's limit of {device_max_stiffness_n_per_m} N/m"
                    );
                }
                Some(k)
            }
        };
        let chain = ChainConfig {
            plausible: PlausibleConfig {
                max_speed_m_s: args.max_speed_m_s,
                max_accel_m_s2: args.max_accel_m_s2,
                tolerance_m: args.pose_tolerance_m,
                max_reject_run_ns: ms_to_ns("max-reject-run-ms", args.max_reject_run_ms)?,
            },
            live: LiveConfig {
                max_rate: args.max_sim_rate,
                slack_ns: ms_to_ns("sim-slack-ms", args.sim_slack_ms)?,
                ..LiveConfig::default()
            },
            passivity: PassivityConfig {
                enabled: !args.no_passivity,
                tolerance_j: args.passivity_tolerance_j,
                max_damping_n_s_per_m: args.max_damping_n_s_per_m,
            },
            max_stiffness_n_per_m,
        };
        chain.validate()?;
        Ok(chain)
    }
}

/// Milliseconds from the command line as nanoseconds (a positive finite
/// number).
fn ms_to_ns(flag: &str, ms: f64) -> Result<u64> {
    if !(ms.is_finite() && ms > 0.0 && ms < 1e9) {
        bail!("--{flag} must be a positive number of milliseconds, got {ms}");
    }
    Ok((ms * 1e6).round().max(1.0) as u64)
}
