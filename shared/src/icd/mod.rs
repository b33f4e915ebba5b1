//! The wire contract between the host and the controller (interface control document): what
//! both sides must agree on, bit for bit.
//!
//! - [`link`]: framing (postcard messages in COBS frames, versioned) and the messages
//!   (requests, responses, the drive's status and refusals, typed errors).
//! - [`plan`]: drive plans ([`plan::Plan`], [`plan::Step`]), the device's limits
//!   ([`plan::DeviceLimits`]) and the validation of plans and setpoints against them.
//! - [`units`]: the one conversion for each pair of units: Hz ↔ mHz ([`units::MilliHz`]),
//!   amplitude ↔ Q15 ([`units::Q15`]), fixed point and binary angles ↔ `f64`.

pub mod link;
pub mod plan;
pub mod units;
