//! The files a user writes and the tool reads and writes: parts (JSON, SVG), plates (TOML:
//! material, size and the menu of modes), plans (JSON, the same plan the controller runs);
//! speed observations (CSV, [`observations`]) and in-place plate edits ([`plate_edit`]);
//! angles on a circle ([`angle`]), the field law of a node ([`field`]) and the polygon helpers every room uses ([`geometry`]);
//! a mode sampled on a grid ([`grid`]), a part's pose on the plate ([`pose`]) and the top level of
//! the JSON files ([`json_top`]).

pub mod angle;
pub mod feed_region;
pub mod field;
pub mod geometry;
pub mod grid;
pub mod json_top;
pub mod modes_file;
pub mod observations;
pub mod part;
pub mod plan_file;
pub mod plate;
pub mod plate_edit;
pub mod plate_file;
pub mod pose;
