//! How parts move: the quasi-static motion of a part under a mode's field (field evaluation,
//! simulation of plans, the Monte Carlo check of a plan), and the paper's particle bouncing on a vibrating string.

pub mod montecarlo;
pub mod potential;
pub mod sim;
pub mod string;
