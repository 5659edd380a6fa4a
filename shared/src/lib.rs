//! What crosses a process boundary between the sim-server, the haptic daemon
//! and the viewer: session naming and the clock every payload is stamped with.
//!
//! [`protocol`] holds the payloads (`#[repr(C)]`, fixed size, versioned),
//! documented field by field in `docs/protocol.md`.
//!
//! ```
//! use shared::{monotonic_ns, SessionName};
//! let session = SessionName::new("trainee-3").unwrap();
//! assert_eq!(session.service("force"), "hapsim/trainee-3/force");
//! let t0 = monotonic_ns();
//! assert!(monotonic_ns() >= t0);
//! ```
#![warn(missing_docs)]

pub mod alloc_count;
mod clock;
pub mod ipc_root;
pub mod loop_stats;
pub mod protocol;
pub mod reaper;
pub mod remote;
pub mod rt;
pub mod services;
mod session;
pub mod source;

pub use clock::{NS_PER_S, monotonic_ns, thread_cpu_ns};
pub use session::{SessionName, SessionNameError};
