//! The penalty contact law: the field of contact points and their forces
//! (with its friction and linearly implicit springs, `field/`), and where
//! the points are sampled and kept across steps (`sampling/`).

pub mod field;
pub(super) mod sampling;
