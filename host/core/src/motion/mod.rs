//! How parts move: the quasi-static motion of a part under a mode's field (the part
//! [`body`], the [`field`] models, the [`integrate`]r, plan [`steps`]), the Monte Carlo check of a plan, and the paper's particle
//! bouncing on a vibrating string.

pub mod body;
pub mod bulk;
pub mod contact;
pub mod field;
pub mod integrate;
pub mod many;
pub mod montecarlo;
pub mod potential;
pub mod shape;
pub mod steps;
pub mod string;
#[cfg(test)]
mod testkit;
