//! What a tool is, before it touches anything: its declaration (kind,
//! fulcrum, shaft and tip, friction coefficients) and where it is (the
//! pose, its tip and shaft segments). The lowest layer of `contact`: the
//! surface queries, the penalty law and the tool's contact state all read
//! it, and it reads none of them.

mod decl;
mod geometry;

pub use decl::{Friction, ToolDecl, ToolKind};
pub use geometry::{Plane, Segment, ToolPose};
