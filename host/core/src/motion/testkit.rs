//! Shared fixtures of the motion module's unit tests: a mode from TOML text, a plate around
//! it, a rectangle and a holed part.

use crate::model::field::Law;
use crate::model::part::Part;
use crate::model::plate::{Mode, PlateModel, parse_mode};
use crate::motion::body::Body;
use crate::motion::field::FieldModel;

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
pub(crate) fn holed_part() -> Part {
    Part::new(
        "h".into(),
        vec![[0.0, 0.0], [40.0, 0.0], [31.0, 16.0], [5.0, 26.0]],
        vec![vec![[10.0, 5.0], [14.0, 12.0], [20.0, 5.0]]],
    )
    .unwrap()
}

/// The pull of a law at 20 mm (a scale for force errors).
pub(crate) fn law_scale(law: Law) -> f64 {
    law.g(20.0).abs()
}

/// A uniform field of unit pull along `dir` over the whole plate (a sign-law line node far
/// beyond the plate in that direction).
pub fn uniform(dir: [f64; 2]) -> FieldModel {
    FieldModel::Line { xhat: dir, c: 1e3, law: Law::Sign, k: [1.0, 1.0] }
}

/// An irregular quadrilateral (no symmetry: its stable edges differ).
pub(crate) fn quad() -> Part {
    Part::new("q".into(), vec![[0.0, 0.0], [30.0, 0.0], [24.0, 14.0], [4.0, 20.0]], vec![]).unwrap()
}

/// Push alignment: the distance from the centroid to the wall (+x) when the part touches
/// it, d(θ) = max over vertices of their x; a part pushed against a fence descends d(θ)
/// from the orientation it arrives at to the local minimum (a stable edge).
pub(crate) fn predicted_rest(body: &Body, theta0: f64) -> f64 {
    let d = |th: f64| {
        let (s, c) = f64::sin_cos(th);
        body.rings[0].iter().map(|p| c * p[0] - s * p[1]).fold(f64::MIN, f64::max)
    };
    let (mut th, h) = (theta0, 1e-5);
    loop {
        let best = [th - h, th + h].into_iter().min_by(|a, b| d(*a).total_cmp(&d(*b)));
        match best {
            Some(b) if d(b) < d(th) - 1e-15 => th = b,
            _ => return th,
        }
    }
}

/// The repository's `examples/` folder.
fn examples() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples")
}

/// The three example plates' own solver modes (`examples/plates/*-6-modes.toml`).
pub(crate) fn solver_plates() -> Vec<PlateModel> {
    ["cantilever", "free", "hinged-rod"]
        .iter()
        .map(|n| PlateModel::load(&examples().join(format!("plates/{n}-6-modes.toml"))).unwrap())
        .collect()
}

/// The example parts and the ordinary ones in JSON (`examples/parts/`,
/// `examples/parts/ordinary/`), each face of a part that flips, sorted by file name.
pub(crate) fn example_parts() -> Vec<Part> {
    let mut files = Vec::new();
    for dir in ["parts", "parts/ordinary"] {
        for e in std::fs::read_dir(examples().join(dir)).unwrap() {
            let path = e.unwrap().path();
            if path.extension().is_some_and(|x| x == "json") {
                files.push(path);
            }
        }
    }
    files.sort();
    let mut parts = Vec::new();
    for f in files {
        let part = Part::load(&f).unwrap();
        if part.flips {
            parts.push(part.mirrored());
        }
        parts.push(part);
    }
    parts
}
