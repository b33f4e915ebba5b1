//! # chladni-media
//!
//! What the `chladni` tool reads from and draws for people: parts located in photos
//! ([`vision`]), every figure ([`plot`]) and the JSON and CSV shapes of the data the commands
//! print ([`shapes`]).
#![forbid(unsafe_code)]

pub mod plot;
pub mod shapes;
pub mod vision;
