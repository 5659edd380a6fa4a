//! Where and when a measurement was made, written into every benchmark's
//! JSON (`sim-server bench`, `hapbench ...`) under `provenance`, so that a
//! results page rendered from it (`hapbench report`) names the date, the
//! commit and the machine, as the project's measurements must: these
//! machines are shared and noisy, and a figure without its machine is not
//! a claim.
//!
//! ```
//! let p = sim_server::provenance::Provenance::collect();
//! assert!(p.date_utc.ends_with('Z') && p.machine.cores >= 1);
//! let v = sim_server::provenance::stamp(serde_json::json!({ "steps_per_s": 1.0 }));
//! assert!(v["provenance"]["commit"].is_string());
//! ```

use serde::{Deserialize, Serialize};
use std::path::Path;
use std::process::Command;
use thiserror::Error;

/// The machine a measurement ran on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Machine {
    /// `HAPSIM_MACHINE` when set (a lab's own name for it), else the host
    /// name.
    pub name: String,
    /// The CPU model (`/proc/cpuinfo`'s `model name`; "unknown" elsewhere).
    pub cpu: String,
    /// Logical CPUs this process may use.
    pub cores: usize,
    /// Physical memory (GiB; 0 where unknown).
    pub memory_gib: f64,
    /// The operating system and kernel.
    pub os: String,
}

/// When, from which source, on which machine, by which command.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// UTC, RFC 3339, to the second.
    pub date_utc: String,
    /// The source's git commit (12 hex digits, `+dirty` with uncommitted
    /// changes to tracked files), or `unknown` outside a checkout.
    pub commit: String,
    /// The machine.
    pub machine: Machine,
    /// The command line that measured.
    pub command: String,
}

impl Provenance {
    /// This moment, this checkout, this machine, this process's command.
    /// Cold: reads a few files and runs `git` twice.
    pub fn collect() -> Self {
        Self {
            date_utc: humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string(),
            commit: commit(),
            machine: Machine::this(),
            command: std::env::args().collect::<Vec<_>>().join(" "),
        }
    }
}

impl Machine {
    /// The machine this process runs on.
    pub fn this() -> Self {
        let read = |p: &str| std::fs::read_to_string(p).unwrap_or_default();
        let cpu = (read("/proc/cpuinfo").lines())
            .find_map(|l| l.strip_prefix("model name")?.split(':').nth(1))
            .map_or_else(|| "unknown".to_string(), |s| s.trim().to_string());
        let memory_gib = (read("/proc/meminfo").lines())
            .find_map(|l| l.strip_prefix("MemTotal:"))
            .and_then(|s| s.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
            .map_or(0.0, |kib| kib / (1024.0 * 1024.0));
        let os_name = (read("/etc/os-release").lines())
            .find_map(|l| l.strip_prefix("PRETTY_NAME="))
            .map_or_else(
                || std::env::consts::OS.to_string(),
                |s| s.trim_matches('"').to_string(),
            );
        let kernel = read("/proc/sys/kernel/osrelease").trim().to_string();
        let name = std::env::var("HAPSIM_MACHINE")
            .ok()
            .filter(|s| !s.trim().is_empty())
            .unwrap_or_else(|| read("/proc/sys/kernel/hostname").trim().to_string());
        Self {
            name,
            cpu,
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            memory_gib: (memory_gib * 10.0).round() / 10.0,
            os: if kernel.is_empty() {
                os_name
            } else {
                format!("{os_name}, Linux {kernel}")
            },
        }
    }

    /// One line: "2 x Intel Xeon ..., 23.5 GiB, Ubuntu ... (name)".
    pub fn line(&self) -> String {
        format!(
            "{} x {}, {:.1} GiB, {} ({})",
            self.cores, self.cpu, self.memory_gib, self.os, self.name
        )
    }
}

/// The git commit of the current directory's checkout.
fn commit() -> String {
    let git = |args: &[&str]| {
        Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(c) if !c.is_empty() => {
            let dirty = git(&["status", "--porcelain", "--untracked-files=no"])
                .is_some_and(|s| !s.is_empty());
            if dirty { format!("{c}+dirty") } else { c }
        }
        _ => "unknown".to_string(),
    }
}

/// `value` (a JSON object) with this run's `provenance` added; any other
/// value is wrapped as `{"results": value, "provenance": ...}`.
pub fn stamp(value: serde_json::Value) -> serde_json::Value {
    let p = serde_json::to_value(Provenance::collect()).unwrap_or_default();
    match value {
        serde_json::Value::Object(mut m) => {
            m.insert("provenance".to_string(), p);
            serde_json::Value::Object(m)
        }
        other => serde_json::json!({ "results": other, "provenance": p }),
    }
}

/// Why a stamped report could not be written.
#[derive(Debug, Error)]
pub enum WriteError {
    /// The report did not serialise (the reason in the message, not a
    /// separate cause, so that it is said once).
    #[error("cannot serialise the report: {0}")]
    Serialise(serde_json::Error),
    /// The file could not be written.
    #[error("cannot write {path}: {reason}")]
    Io {
        /// The file.
        path: String,
        /// The system's reason.
        reason: std::io::Error,
    },
}

/// Writes `report` to `path` as pretty JSON with its provenance.
pub fn write_stamped(path: &Path, report: &impl Serialize) -> Result<(), WriteError> {
    let value = serde_json::to_value(report).map_err(WriteError::Serialise)?;
    let text = serde_json::to_string_pretty(&stamp(value)).map_err(WriteError::Serialise)?;
    std::fs::write(path, text + "\n").map_err(|reason| WriteError::Io {
        path: path.display().to_string(),
        reason,
    })
}
