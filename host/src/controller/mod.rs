//! The controller seen from the host: the link client, the QEMU emulator that runs the
//! firmware as a controller, and building firmware images.

pub mod client;
pub mod emulator;
pub mod firmware;
pub mod units;
