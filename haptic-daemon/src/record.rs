//! `haptic-daemon record`: a lossless recorder of a session's streams. The
//! simulation's force samples (one CSV row per tool per step) and the
//! daemon's telemetry (one row per haptic tick, the `--record` columns),
//! with every sequence gap counted, flushed every 200 ms and on SIGTERM or
//! SIGINT, so a stop loses nothing already received.
//!
//! The force stream keeps up to [`shared::services::FORCE_BUFFER_MAX`]
//! samples per subscriber; the recorder asks for all of them (the daemon
//! asks for a few), so a recorder scheduled out for up to a second at 1 kHz
//! still loses nothing.

use crate::io::{RECORD_HEADER, write_row};
use crate::transport::{Transport, TransportError};
use serde::Serialize;
use shared::SessionName;
use shared::monotonic_ns;
use shared::protocol::{ForceMsg, MAX_TOOLS, PROTOCOL_VERSION};
use shared::services;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// The force CSV's header.
pub const FORCE_HEADER: &str =
    "t_ns,seq,sim_time_ns,tool,pos_x_m,pos_y_m,pos_z_m,force_x_n,force_y_n,force_z_n,flags";
const FLUSH_EVERY_NS: u64 = 200_000_000;

/// Why recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// Shared memory or zenoh.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// A file.
    #[error("{file}: {reason}")]
    File {
        /// The file.
        file: PathBuf,
        /// The OS error.
        reason: std::io::Error,
    },
}

/// What to record.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordConfig {
    /// The session.
    pub session: SessionName,
    /// Force samples CSV.
    pub forces: Option<PathBuf>,
    /// Telemetry CSV.
    pub telemetry: Option<PathBuf>,
    /// Stop after this long (s); otherwise at the stop flag.
    pub duration_s: Option<f64>,
}

/// Counts sequence gaps in one stream.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct SeqTracker {
    /// Messages seen.
    pub received: u64,
    /// Places where numbers were skipped.
    pub gaps: u64,
    /// Numbers skipped in all.
    pub lost: u64,
    /// Times the numbering started again (a publisher restarted).
    pub restarts: u64,
    #[serde(skip)]
    next: Option<u64>,
}

impl SeqTracker {
    /// Notes message number `seq`.
    pub fn see(&mut self, seq: u64) {
        match self.next {
            Some(n) if seq > n => {
                self.gaps += 1;
                self.lost += seq - n;
            }
            Some(n) if seq < n => self.restarts += 1,
            _ => {}
        }
        self.received += 1;
        self.next = Some(seq + 1);
    }
}

/// What was recorded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct RecordSummary {
    /// Force samples.
    pub forces: SeqTracker,
    /// Telemetry ticks.
    pub telemetry: SeqTracker,
}

fn create(path: &Path, header: &str) -> Result<BufWriter<File>, RecordError> {
    let err = |source| RecordError::File {
        file: path.to_path_buf(),
        reason: source,
    };
    let mut w = BufWriter::new(File::create(path).map_err(err)?);
    writeln!(w, "{header}").map_err(err)?;
    Ok(w)
}

fn finish(w: &mut Option<BufWriter<File>>, path: &Option<PathBuf>) -> Result<(), RecordError> {
    if let (Some(w), Some(p)) = (w.as_mut(), path) {
        let err = |source| RecordError::File {
            file: p.clone(),
            reason: source,
        };
        w.flush().map_err(err)?;
        w.get_ref().sync_data().map_err(err)?;
    }
    Ok(())
}

fn force_rows(w: &mut impl Write, m: &ForceMsg) -> std::io::Result<()> {
    for (i, t) in m.tools[..(m.tool_count as usize).min(MAX_TOOLS)]
        .iter()
        .enumerate()
    {
        writeln!(
            w,
            "{},{},{},{},{},{},{},{},{},{},{}",
            m.t_ns,
            m.seq,
            m.sim_time_ns,
            i,
            t.position_m[0],
            t.position_m[1],
            t.position_m[2],
            t.force_n[0],
            t.force_n[1],
            t.force_n[2],
            t.flags
        )?;
    }
    Ok(())
}

/// Records until `stop` is set or the duration ends; always flushes.
/// `transport`: shared memory, or zenoh through a bridge.
pub fn record(
    cfg: &RecordConfig,
    transport: &Transport,
    stop: &Arc<AtomicBool>,
) -> Result<RecordSummary, RecordError> {
    let (mut forces, _n1) =
        transport.force_source("hapsim-recorder", &cfg.session, services::FORCE_BUFFER_MAX)?;
    let (mut telemetry, _n2) = transport.telemetry_source("hapsim-recorder-t", &cfg.session)?;
    let mut force_out = cfg
        .forces
        .as_deref()
        .map(|p| create(p, FORCE_HEADER))
        .transpose()?;
    let mut tele_out = cfg
        .telemetry
        .as_deref()
        .map(|p| create(p, RECORD_HEADER))
        .transpose()?;
    let mut summary = RecordSummary::default();
    let start = monotonic_ns();
    let mut flushed = start;
    let file_err = |p: &Option<PathBuf>| {
        let file = p.clone().unwrap_or_default();
        move |source| RecordError::File {
            file,
            reason: source,
        }
    };
    loop {
        let now = monotonic_ns();
        let done = stop.load(Ordering::Relaxed)
            || cfg
                .duration_s
                .is_some_and(|d| (now - start) as f64 * 1e-9 >= d);
        while let Some(s) = forces.pop() {
            if s.version != PROTOCOL_VERSION {
                continue;
            }
            summary.forces.see(s.seq);
            if let Some(w) = force_out.as_mut() {
                force_rows(w, &s).map_err(file_err(&cfg.forces))?;
            }
        }
        while let Some(b) = telemetry.pop() {
            if b.version != PROTOCOL_VERSION {
                continue;
            }
            for t in &b.ticks[..(b.count as usize).min(b.ticks.len())] {
                summary.telemetry.see(t.seq);
                if let Some(w) = tele_out.as_mut() {
                    write_row(w, t).map_err(file_err(&cfg.telemetry))?;
                }
            }
        }
        if done {
            break;
        }
        if now - flushed > FLUSH_EVERY_NS {
            for (w, p) in [
                (&mut force_out, &cfg.forces),
                (&mut tele_out, &cfg.telemetry),
            ] {
                if let Some(w) = w.as_mut() {
                    w.flush().map_err(file_err(p))?;
                }
            }
            flushed = now;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    finish(&mut force_out, &cfg.forces)?;
    finish(&mut tele_out, &cfg.telemetry)?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::SeqTracker;

    #[test]
    fn gaps_losses_and_restarts_are_counted() {
        let mut s = SeqTracker::default();
        for seq in [0, 1, 2, 5, 6, 9, 0, 1] {
            s.see(seq);
        }
        assert_eq!((s.received, s.gaps, s.lost, s.restarts), (8, 2, 4, 1));
    }
}
