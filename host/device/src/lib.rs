//! # chladni-device
//!
//! The controller seen from the host: the link client, the QEMU emulator that runs the
//! firmware as a controller (behind a proxy that lets several clients share its serial
//! socket), building firmware images, flashing the board (probe-rs), the serial ports of this
//! machine, and the JSON shapes of what the controller commands print.

#![forbid(unsafe_code)]

pub mod client;
pub mod config_keys;
pub mod emulator;
pub mod firmware;
pub mod flash;
pub mod json;
pub mod ports;
pub mod proxy;
pub mod sweep;
