//! # chladni-shared
//!
//! The `no_std` core of Chladni, shared bit for bit by the host tool (`chladni`) and the
//! controller firmware. If something can be computed without touching a register, it lives
//! here and is tested on the host; the same test vectors also run on Cortex-M in QEMU.
//!
//! Modules:
//! - [`fx`]: Q31.32 fixed point and binary angles (sin/cos/sinc), deterministic on every target.
//! - [`geometry`]: polygon area, centroid, first and second moments, clipping by a line.
//! - [`field`]: straight-node force fields (sign, linear, sine; gain per side) and their
//!   exact integrals over polygon pieces.
//! - [`rest`]: balance offset, turn function t(θ), rest orientations (stable/unstable),
//!   alignment function a(θ).
//! - [`link`]: the wire protocol (postcard messages in COBS frames), versioned, with typed errors.
//! - [`dds`]: the drive's sine synthesis (phase accumulator, interpolated table, DAC codes).
//! - [`plan`]: drive plans and their validation against device limits.
//! - [`runner`]: the plan runner filling sample blocks, step boundaries exact to the sample.
//! - [`plant`]: a simulated shaker + plate (resonant second-order system) for the QEMU board.
//! - [`vectors`]: deterministic test vectors whose digests must match on host and target.
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod dds;
pub mod field;
pub mod fx;
pub mod geometry;
pub mod link;
pub mod plan;
pub mod plant;
pub mod rest;
pub mod runner;
pub mod vectors;
