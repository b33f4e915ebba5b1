//! Plates: the plate file, the Kirchhoff-plate mode solver, node lines (contours of φ = 0),
//! Chladni photos to node lines, and plots.

pub mod contour;
pub mod file;
pub mod model;
pub mod modes_file;
pub mod node_field;
pub mod photo;
pub mod plot;
pub mod solver;
