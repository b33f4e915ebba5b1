//! The one support module of the host's integration tests: example files, CLI runs, ELF fixtures.
//! A test file includes it with `mod support;` and uses what it needs.
#![allow(dead_code)]

pub mod cli;
pub mod elf;
pub mod examples;
pub mod photos;
