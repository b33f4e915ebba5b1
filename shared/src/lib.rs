//! # chladni-shared
//!
//! The `no_std` core of Chladni, shared bit for bit by the host tool (`chladni`) and the
//! controller firmware. If something can be computed without touching a register, it lives
//! here and is tested on the host; the same test vectors also run on Cortex-M in QEMU.
//!
//! Rooms:
//! - [`icd`]: the wire contract: link framing and messages, drive plans and device limits,
//!   and the unit conversions (Hz ↔ mHz, amplitude ↔ Q15, fixed point and angles ↔ `f64`).
//! - [`drive`]: the drive signal: sine synthesis, the plan runner, the simulated plant.
//! - [`analysis`]: rest orientations of a part at a node: fixed point, polygon geometry,
//!   force fields, the rest analysis.
//! - [`vectors`]: deterministic test vectors whose digests must match on host and target.
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod analysis;
pub mod drive;
pub mod icd;
pub mod vectors;
