//! The application, board-independent: it only sees the link as an async byte stream and the
//! drive output as a [`drive::SampleOutput`]. It builds and unit-tests on the host too.
#![deny(unsafe_code)]

pub mod drive;
pub mod link;
pub mod store;
pub mod watchdog;

#[cfg(all(test, not(target_os = "none")))]
mod tests;
