//! The penalty contact law: the field of contact points and their forces,
//! friction, the linearly implicit springs, and where the points are
//! sampled and kept across steps.

pub mod field;
pub mod friction;
pub mod implicit;
pub(super) mod sampling;
pub(super) mod selection;
