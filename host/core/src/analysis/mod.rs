//! Rest analysis of a part at a straight node: the f64 reference that the fixed-point core in
//! `chladni-shared` is checked against ([`reference`](mod@reference)), and the samples of an analysis that
//! `chladni analyze` prints and plots ([`samples`]).

pub mod reference;
pub mod samples;
