//! The tissue's surface as the tools meet it: the bounding-volume index of
//! its triangles, where a moving point first crosses it, the live faces
//! around a set of vertices, and what each vertex touches.

pub(crate) mod adjacency;
pub(super) mod crossing;
pub(super) mod faces;
pub(super) mod index;
