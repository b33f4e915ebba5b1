//! The example parts and plates of the source tree, and plates written inline, for the
//! planner's integration tests. Each test binary compiles this module and uses part of it.
#![allow(dead_code)]

use std::path::Path;

use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::plate_file::PlateFile;

/// The workspace root.
pub fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

/// `examples/parts/NAME`.
pub fn part(name: &str) -> Part {
    Part::load(&root().join("examples/parts").join(name)).unwrap()
}

/// `examples/plates/NAME`.
pub fn plate(name: &str) -> PlateModel {
    PlateModel::load(&root().join("examples/plates").join(name)).unwrap()
}

/// A 300 × 200 mm plate with the `[[mode]]` entries `modes`.
pub fn plate_text(modes: &str) -> PlateModel {
    let text = format!("[plate]\nname = \"t\"\nsize_mm = [300.0, 200.0]\n{modes}");
    PlateModel::from_file(&PlateFile::parse(&text, "t").unwrap()).unwrap()
}

/// A 300 × 200 mm plate of grid modes whose nodes are straight lines through the centre at
/// `angles` (deg): φ = the signed distance from the line (a linear field, which the grid
/// fields' Catmull–Rom interpolant and its resampling keep exactly) on 41 × 41 samples, gain
/// 1 on the φ < 0 side and `gain_right` on the other.
pub fn line_grid_plate(angles: &[f64], gain_right: f64) -> PlateModel {
    use chladni_core::model::grid::Grid;
    use chladni_core::model::plate::{Mode, Node};
    let mut plate = plate_text(
        "[[mode]]\nfreq_hz = 60.0\nspeed_mm_s = 30.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n",
    );
    let template = plate.modes[0].clone();
    let (n, size) = (41, [300.0, 200.0]);
    plate.modes = angles
        .iter()
        .enumerate()
        .map(|(k, &a)| {
            let (s, c) = a.to_radians().sin_cos();
            let values = (0..n)
                .flat_map(|j| {
                    (0..n).map(move |i| {
                        let x = i as f64 * size[0] / (n - 1) as f64 - size[0] / 2.0;
                        let y = j as f64 * size[1] / (n - 1) as f64 - size[1] / 2.0;
                        (c * y - s * x) / 200.0
                    })
                })
                .collect();
            Mode {
                name: format!("line {a}"),
                freq_hz: 60.0 + 10.0 * k as f64,
                gain_right,
                node: Node::Grid(Grid { nx: n, ny: n, size_mm: size, values }),
                ..template.clone()
            }
        })
        .collect();
    plate
}

/// The text of `examples/plates/NAME` split at its `[[mode]]` entries: what comes before the
/// first (the `[plate]` table) and each entry from its `[[mode]]` line, to write plate files
/// made of the examples' modes.
pub fn plate_entries(name: &str) -> (String, Vec<String>) {
    let text = std::fs::read_to_string(root().join("examples/plates").join(name)).unwrap();
    let mut pieces = text.split("\n[[mode]]");
    let head = pieces.next().unwrap_or_default().to_string() + "\n";
    (head, pieces.map(|e| format!("[[mode]]{e}\n")).collect())
}
