//! What the tool feels: the reaction of the tissue on it, the contact
//! stiffness d F / d (tool position), and the worker that computes the
//! stiffness off the step.

pub(crate) mod reaction;
pub(super) mod stiffness;
pub(super) mod worker;
