//! The wire contract between the host and the controller (interface control document): what
//! both sides must agree on, bit for bit.
//!
//! - [`frame`]: framing: postcard messages with a CRC in COBS frames, versioned, with a
//!   client session and request id.
//! - [`link`]: the messages: each request paired with its response type, the drive's status,
//!   typed refusals, telemetry.
//! - [`store`]: the plan store as the link sees it: slots, chunked uploads, summaries,
//!   configuration, plan CRCs.
//! - [`plan`]: drive plans ([`plan::Plan`], [`plan::Step`]), the device's limits
//!   ([`plan::DeviceLimits`]) and the validation of plans and setpoints against them.
//! - [`sense`]: sensing and control: drive levels (open or closed loop), measurements, faults
//!   with their causes, the monitors' thresholds, reset causes.
//! - [`units`]: the one conversion for each pair of units: Hz ↔ mHz ([`units::MilliHz`]),
//!   amplitude ↔ Q15 ([`units::Q15`]), fixed point and binary angles ↔ `f64`.

#[cfg(test)]
mod doc_examples;
pub mod frame;
pub mod link;
pub mod plan;
pub mod sense;
pub mod store;
pub mod units;
#[cfg(test)]
mod wire_pins;
