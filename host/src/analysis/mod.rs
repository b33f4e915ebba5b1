//! Rest analysis of a part at a straight node: the f64 reference that the fixed-point core in
//! `chladni-shared` is checked against.

pub mod reference;
