//! # chladni (host library)
//!
//! Everything the `chladni` command does, as a library the CLI and the end-to-end tests share.
//! The CLI (`src/cli/`) only parses arguments, calls this library and renders the result.
//! - [`model`]: the files: parts (JSON, SVG, DXF), plates and their modes (TOML), plans (JSON).
//! - [`analysis`]: rest analysis of a part at a straight node (the f64 reference).
//! - [`motion`]: quasi-static part motion under a mode's field; the particle on a string.
//! - [`plate`]: the plate mode solver, node lines, node fields, Chladni photos.
//! - [`planner`]: sensorless plan synthesis (step maps, BFS over orientation sets; feed-region
//!   plans by tracking simulated poses, [`planner::feed`]).
//! - [`plot`]: figures of analyses, plans, traces and plate modes.
//! - [`controller`]: the link client, the QEMU emulator, firmware builds.
//! - [`demo`]: `chladni demo`, the main job end to end (plan, figures, Monte Carlo, the
//!   plan stored and run on the controller under telemetry, a summary).
//! - [`cell`]: the controller served to a cell: one link owner for Modbus TCP and HTTP.
//! - [`output`]: output files written atomically, never over one of the command's inputs.
//! - [`rng`]: the one seeded pseudo-random generator.
//! - [`vision`]: parts in a photo of the plate: poses, faces, clusters (`chladni locate`).
//! - [`shapes`]: the JSON and CSV shapes of the data the commands print for research.
#![forbid(unsafe_code)]

pub mod analysis;
pub mod cell;
pub mod controller;
pub mod demo;
pub mod model;
pub mod motion;
pub mod output;
pub mod planner;
pub mod plate;
pub mod plot;
pub mod rng;
pub mod shapes;
pub mod vision;
