//! Plates: the Kirchhoff-plate mode solver and its sampled mode shapes, node lines (contours of
//! φ = 0), the signed-distance field of a set of nodes, Chladni photos to node lines, and the
//! calibration of a mode's settle speed from observed parts ([`calibrate`]).

pub mod calibrate;
pub mod contour;
pub mod node_field;
pub mod photo;
pub mod solver;
