//! Plates.

pub mod file;
pub mod solver;
