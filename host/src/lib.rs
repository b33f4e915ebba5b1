//! # chladni (host library)
//!
//! Everything the `chladni` command does, as a library the CLI and the end-to-end tests share:
//! - [`device`]: the client for the controller's link (serial port or QEMU's TCP socket).
//! - [`emulator`]: builds the QEMU firmware and runs it as a controller on a TCP port.
//! - [`firmware`]: locates and builds firmware images.
//! - [`flash`]: checks a board image and writes it through a debug probe (probe-rs).
//! - [`plate`]: plate files, the plate mode solver, node lines, Chladni photos.
//! - [`physics`]: the particle-on-a-string model of the paper's Appendix.
//! - [`part`]: planar parts: JSON/SVG import and validation.
//! - [`reference`]: the f64 reference implementation of the rest analysis.
//! - [`plot`]: part, turn-function and alignment-function plots.
//! - [`plan_file`]: the plan JSON file ⇄ the device plan.
//! - [`plan_plot`]: plan and motion-trace figures.
//! - [`planner`]: sensorless plan synthesis (step maps, BFS over orientation sets; feed-region
//!   plans by tracking simulated poses, [`planner::feed`]).
//! - [`sim`]: quasi-static part motion under a mode's field.

pub mod device;
pub mod emulator;
pub mod firmware;
pub mod flash;
pub mod part;
pub mod physics;
pub mod plan_file;
pub mod plan_plot;
pub mod planner;
pub mod plate;
pub mod plot;
pub mod reference;
pub mod sim;
