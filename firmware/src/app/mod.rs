//! The application, board-independent: it only sees the link as an async byte stream.
#![deny(unsafe_code)]

pub mod drive;
pub mod link;
