//! # chladni-core
//!
//! The physics and the planning of the Chladni feeder, with no terminal, network, serial or
//! plotting crate: what `chladni` computes, as a library the other host crates build on.
//! - [`model`]: the files: parts (JSON, SVG, DXF), plates and their modes (TOML), plans (JSON).
//! - [`analysis`]: rest analysis of a part at a straight node (the f64 reference).
//! - [`motion`]: quasi-static part motion under a mode's field; the particle on a string.
//! - [`planner`]: sensorless plan synthesis (step maps, BFS over orientation sets; feed-region
//!   plans by tracking simulated poses, [`planner::feed`]).
//! - [`plate`]: the plate mode solver, node lines, node fields, Chladni photos, suggestions.
//! - [`output`]: output files written atomically, never over one of the command's inputs.
//! - [`progress`]: what long work reports as it goes; the caller draws it.
//! - [`rng`]: the one seeded pseudo-random generator.
//! - [`steer`]: closed-loop steering: the plate as learned from bursts, the command of a cycle.
#![forbid(unsafe_code)]

pub mod analysis;
pub mod model;
pub mod motion;
pub mod output;
pub mod planner;
pub mod plate;
pub mod progress;
pub mod rng;
pub mod steer;
