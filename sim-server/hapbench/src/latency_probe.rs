//! The baselines' publisher process (`hapbench probe`, hidden): a stamped
//! sample every millisecond on shared memory or, with `--zenoh`, on zenoh,
//! for `hapbench latency` to receive in the same run as the system.

use anyhow::Result;
use haptic_daemon::rt::Pacer;
use shared::protocol::{ForceMsg, PROTOCOL_VERSION};
use shared::{SessionName, monotonic_ns, services};

/// Flags of the hidden probe publisher (the baseline's other process).
#[derive(clap::Args)]
pub struct ProbeArgs {
    /// Session whose force stream the probe publishes on.
    #[arg(long)]
    pub session: String,
    /// Seconds.
    #[arg(long)]
    pub duration_s: f64,
    /// Publish on zenoh, listening here, instead of on shared memory.
    #[arg(long)]
    pub zenoh: Option<String>,
}

/// The baseline's publisher: a stamped sample every millisecond.
pub fn probe(args: &ProbeArgs) -> Result<()> {
    if let Some(endpoint) = &args.zenoh {
        return crate::latency_remote::probe(endpoint, args.duration_s);
    }
    let session = SessionName::new(&args.session)?;
    let node = services::node("hapbench-probe")?;
    let publisher = services::publisher(&services::force_service(&node, &session)?)?;
    every_ms(args.duration_s, |msg| {
        publisher.send_copy(msg).ok();
    });
    Ok(())
}

/// Calls `send` with a sample stamped now, every millisecond for
/// `duration_s` (the baselines' publishers).
pub fn every_ms(duration_s: f64, mut send: impl FnMut(ForceMsg)) {
    let mut pacer = Pacer::new(1_000_000, monotonic_ns());
    let end = monotonic_ns() + (duration_s * 1e9) as u64;
    let mut seq = 0;
    while monotonic_ns() < end {
        pacer.wait();
        send(ForceMsg {
            version: PROTOCOL_VERSION,
            seq,
            t_ns: monotonic_ns(),
            ..ForceMsg::default()
        });
        seq += 1;
    }
}
