//! Shared fixtures of the motion module's unit tests: a mode from TOML text, a plate around
//! it, a rectangle and a holed part.

use crate::model::part::Part;
use crate::model::plate::{Law, Mode, PlateModel, parse_mode};

/// A mode parsed from plate-file TOML on a 300 × 200 mm plate.
pub fn mode(toml_text: &str) -> Mode {
    let t: toml::Table = toml::from_str(toml_text).unwrap();
    parse_mode(1, &t, [300.0, 200.0]).unwrap()
}

/// A 300 × 200 mm plate with that one mode.
pub fn plate(m: &Mode) -> PlateModel {
    PlateModel {
        name: "t".into(),
        size_mm: [300.0, 200.0],
        modes: vec![m.clone()],
        edge: crate::model::plate::Edge::Wall,
        friction: crate::model::plate::DEFAULT_FRICTION,
    }
}

/// A 40 × 10 mm rectangle.
pub fn rect() -> Part {
    Part::new("r".into(), vec![[0.0, 0.0], [40.0, 0.0], [40.0, 10.0], [0.0, 10.0]], vec![]).unwrap()
}

/// An irregular quadrilateral with a triangular hole: wrench accuracy tests.
pub fn holed_part() -> Part {
    Part::new(
        "h".into(),
        vec![[0.0, 0.0], [40.0, 0.0], [31.0, 16.0], [5.0, 26.0]],
        vec![vec![[10.0, 5.0], [14.0, 12.0], [20.0, 5.0]]],
    )
    .unwrap()
}

/// The pull of a law at 20 mm (a scale for force errors).
pub fn law_scale(law: Law) -> f64 {
    law.g(20.0).abs()
}
