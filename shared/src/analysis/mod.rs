//! Part analysis: where a part comes to rest at a straight node, in integer arithmetic so that
//! the host and the controller get the same bits.
//!
//! - [`fx`]: Q31.32 fixed point and binary angles (sin/cos/sinc), deterministic on every target.
//! - [`geometry`]: polygon area, centroid, first and second moments, clipping by a line.
//! - [`field`]: straight-node force fields (sign, linear, sine; gain per side) and their exact
//!   integrals over polygon pieces.
//! - [`rest`]: balance offset, turn function t(θ), rest orientations (stable/unstable),
//!   alignment function a(θ).

pub mod field;
pub mod fx;
pub mod geometry;
pub mod rest;
