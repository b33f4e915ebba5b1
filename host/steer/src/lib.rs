//! The feeder with a camera (docs/steer.md): the controller drives one plate mode in short
//! bursts, a camera shows where the parts went, and the loop learns what each mode really does
//! (`chladni plate learn`) or steers parts to goal poses (`chladni steer`).
//!
//! [`session`] is the one place that touches the hardware: a burst on the controller, a frame
//! taken after the drive settled, the parts located in it; every exit path stops the drive.
//! The decisions (predict, choose, fit) are `chladni_core::steer`'s, pure and tested without
//! a camera; this crate runs them against the real thing.
#![forbid(unsafe_code)]

pub mod camera;
pub mod error;
pub mod learn;
pub mod parts;
pub mod session;
pub mod steer;

pub use error::LoopError;
