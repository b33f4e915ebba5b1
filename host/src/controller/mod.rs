//! The controller seen from the host: the link client, the QEMU emulator that runs the
//! firmware as a controller (behind a proxy that lets several clients share its serial
//! socket), building firmware images, and flashing the board (probe-rs).

pub mod client;
pub mod config_keys;
pub mod emulator;
pub mod firmware;
pub mod flash;
pub mod json;
pub mod proxy;
pub mod sweep;
