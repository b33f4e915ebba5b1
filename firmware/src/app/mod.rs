//! The application, board-independent: it only sees the link as an async byte stream, the
//! drive output as a [`drive::SampleOutput`] and the accelerometer as an async I2C bus
//! ([`sense`]); a USB board's link is [`usb`]'s packet stream. It builds and unit-tests on the host too.
#![deny(unsafe_code)]

pub mod drive;
pub mod link;
pub mod sense;
pub mod store;
pub mod usb;
pub mod watchdog;

#[cfg(all(test, not(target_os = "none")))]
mod tests;
