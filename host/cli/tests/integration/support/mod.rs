//! The one support module of the host's integration tests: example files, CLI runs, the
//! emulated controller, ELF fixtures. A test file includes it with `mod support;` and uses what
//! it needs.
#![allow(dead_code)]

pub mod cli;
pub mod elf;
pub mod examples;
/// The emulated controller and plans for it: the end-to-end tests' support, shared.
pub use chladni_e2e as emu;
pub mod photos;
pub mod rig;
