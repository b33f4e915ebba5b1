//! Plates: the Kirchhoff-plate mode solver (with point supports) and its sampled mode shapes,
//! the forced response of a plate driven at one point ([`drive`]), the search for drive points
//! and clamps that give a plan ([`suggest`]), node lines (contours of φ = 0), the
//! signed-distance field of a set of nodes, Chladni photos to node lines, and the calibration
//! of a mode's settle speed from observed parts ([`calibrate`]); the forced rocking of a
//! hinged-rod plate ([`rocking`]).

pub mod calibrate;
pub mod contour;
pub mod drive;
pub mod node_field;
pub mod photo;
pub mod rocking;
pub mod solver;
pub mod suggest;
