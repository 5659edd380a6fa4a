//! The viewer of a hapsim session: reads the scene (tools, rest shape,
//! fibres, uncut surface), mesh state, surface topology, force samples and
//! haptic telemetry from shared memory (no scene file: everything comes
//! from the session's streams) (it only subscribes, so
//! it never slows the simulation or the daemon), and draws them with
//! three-d, in a native window (cargo feature `window`) or into a PNG on a
//! surfaceless EGL context (`--snapshot`, no display needed).
//!
//! ```no_run
//! use viewer::camera::View;
//! use viewer::render::Layers;
//! use viewer::session::Session;
//! use viewer::snapshot::{SnapshotConfig, snapshot};
//! let name = shared::SessionName::new("default").unwrap();
//! let mut session = Session::join(&name).unwrap();
//! let cfg = SnapshotConfig {
//!     session: "default".into(),
//!     out: "liver.png".into(),
//!     size: (800, 600),
//!     view: View::Iso,
//!     layers: Layers::default(),
//!     wait_s: 10.0,
//! };
//! let report = snapshot(&mut session, &cfg).unwrap();
//! println!("{} triangles, {} made by cuts", report.triangles, report.cut_triangles);
//! ```
#![warn(missing_docs)]

pub mod camera;
pub mod colour;
pub mod controls;
pub mod drive;
pub mod egl;
pub mod overlay;
pub mod render;
pub mod scene_info;
pub mod session;
pub mod show;
pub mod snapshot;
pub mod streams;
#[cfg(feature = "window")]
pub mod window;
