//! SVG parts written by a Python SVG library (svgwrite; `tests/data/svg/make.py`) and read
//! through usvg: each loads as its JSON twin (exact area, centroid and hole count from the
//! shapes' formulas), with curves flattened to the chord tolerance, units honoured and the
//! fill rule deciding holes; a file without units says so.

use std::path::{Path, PathBuf};
use std::process::Command;

use chladni_core::model::part::{ImportOptions, Part};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/integration/data/svg").join(name)
}

#[derive(serde::Deserialize)]
struct Twin {
    area_mm2: f64,
    centroid_mm: [f64; 2],
    holes: usize,
}

fn twin(name: &str) -> Twin {
    serde_json::from_str(&std::fs::read_to_string(data(&format!("{name}.json"))).unwrap()).unwrap()
}

fn load(name: &str, chord_mm: f64) -> (Part, Vec<String>) {
    let opt = ImportOptions { chord_mm, ..ImportOptions::default() };
    Part::load_with(&data(&format!("{name}.svg")), &opt).unwrap()
}

const FILES: [&str; 5] = ["circle-hole", "rounded-inch", "evenodd-pt", "css-ellipse", "unitless"];

#[test]
fn every_file_agrees_with_its_twin() {
    for name in FILES {
        let want = twin(name);
        for chord in [0.05, 0.005] {
            let (p, notes) = load(name, chord);
            assert_eq!(p.holes.len(), want.holes, "{name}: holes");
            // Vertices on the curve: the outline's chords cut area off, a hole's add it, each
            // by less than (its perimeter × the sagitta); all perimeters here < 400 mm.
            let a = p.area();
            assert!(
                (a - want.area_mm2).abs() <= 400.0 * chord,
                "{name} at {chord} mm: area {a} vs {}",
                want.area_mm2
            );
            let c = p.centroid();
            let d = (c[0] - want.centroid_mm[0]).hypot(c[1] - want.centroid_mm[1]);
            assert!(
                d < 20.0 * chord,
                "{name} at {chord} mm: centroid {c:?} vs {:?}",
                want.centroid_mm
            );
            assert_eq!(notes.iter().any(|n| n.contains("no physical size")), name == "unitless");
        }
    }
}

#[test]
fn a_finer_chord_tolerance_comes_closer() {
    let want = twin("circle-hole").area_mm2;
    let coarse = (load("circle-hole", 0.5).0.area() - want).abs();
    let fine = (load("circle-hole", 0.001).0.area() - want).abs();
    assert!(fine < coarse / 50.0, "coarse {coarse}, fine {fine}");
}

#[test]
fn analyze_reads_the_circle_hole_and_notes_missing_units() {
    let bin = env!("CARGO_BIN_EXE_chladni");
    let out = Command::new(bin)
        .args(["analyze", data("circle-hole.svg").to_str().unwrap(), "--field", "sign"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && text.contains("1 hole(s)"), "{text}");
    // The off-centre hole moves the rests off the plain rectangle's 90° and 270°.
    assert!(!text.contains(" 90.000000  stable"), "{text}");
    let out = Command::new(bin)
        .args(["analyze", data("unitless.svg").to_str().unwrap(), "--field", "sign"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && err.contains("no physical size"), "{err}");
}
