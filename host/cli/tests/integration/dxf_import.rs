//! DXF parts written by a real CAD library (ezdxf; `tests/data/dxf/make.py`): each loads as
//! its JSON twin (area, centroid, second moments, `chladni analyze` orientations), units
//! scale, layers select, and every refusal is its named error.

use std::path::{Path, PathBuf};
use std::process::Command;

use chladni_core::model::part::{DxfError, ImportOptions, Part, PartError};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/integration/data/dxf").join(name)
}

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/parts").join(name)
}

fn load(name: &str, layer: Option<&str>) -> Result<Part, PartError> {
    let opt = ImportOptions { layer: layer.map(str::to_string), ..ImportOptions::default() };
    Part::load_with(&data(name), &opt).map(|(p, _)| p)
}

/// Area, centroid and second moments about the centroid (Ixx, Iyy, Ixy) of the part.
fn moments(p: &Part) -> (f64, [f64; 2], [f64; 3]) {
    let (mut a, mut sx, mut sy, mut ixx, mut iyy, mut ixy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for ring in p.rings() {
        for i in 0..ring.len() {
            let ([x0, y0], [x1, y1]) = (ring[i], ring[(i + 1) % ring.len()]);
            let c = x0 * y1 - x1 * y0;
            a += c / 2.0;
            sx += (x0 + x1) * c / 6.0;
            sy += (y0 + y1) * c / 6.0;
            ixx += (y0 * y0 + y0 * y1 + y1 * y1) * c / 12.0;
            iyy += (x0 * x0 + x0 * x1 + x1 * x1) * c / 12.0;
            ixy += (x0 * y1 + 2.0 * x0 * y0 + 2.0 * x1 * y1 + x1 * y0) * c / 24.0;
        }
    }
    let (cx, cy) = (sx / a, sy / a);
    (a, [cx, cy], [ixx - a * cy * cy, iyy - a * cx * cx, ixy - a * cx * cy])
}

/// Same area, centroid and second moments within `rel` (relative) / `rel`·size (centroid).
fn assert_twins(dxf: &Part, twin: &Part, rel: f64) {
    let (a, c, i) = moments(dxf);
    let (b, d, j) = moments(twin);
    assert!((a - b).abs() <= rel * b, "area {a} vs {b}");
    let size = b.sqrt();
    assert!((c[0] - d[0]).hypot(c[1] - d[1]) <= rel * size, "centroid {c:?} vs {d:?}");
    let scale = j[0].abs().max(j[1].abs());
    for k in 0..3 {
        assert!((i[k] - j[k]).abs() <= rel * scale, "second moment {k}: {} vs {}", i[k], j[k]);
    }
}

/// `chladni analyze FILE --field sign --json`: stable and unstable orientations.
fn orientations(path: &Path, extra: &[&str]) -> (Vec<f64>, Vec<f64>) {
    let out = Command::new(env!("CARGO_BIN_EXE_chladni"))
        .args(["analyze", &path.display().to_string(), "--field", "sign", "--json"])
        .args(extra)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let list = |k: &str| -> Vec<f64> {
        let mut l: Vec<f64> =
            v[k].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        l.sort_by(f64::total_cmp);
        l
    };
    (list("stable_deg"), list("unstable_deg"))
}

/// Orientations equal within `tol` degrees (on the circle).
fn assert_same_rests(a: (Vec<f64>, Vec<f64>), b: (Vec<f64>, Vec<f64>), tol: f64) {
    let same = |x: &[f64], y: &[f64]| {
        x.len() == y.len()
            && x.iter().all(|u| {
                y.iter().any(|v| {
                    let d = (u - v).rem_euclid(360.0);
                    d.min(360.0 - d) <= tol
                })
            })
    };
    assert!(same(&a.0, &b.0) && same(&a.1, &b.1), "{a:?} vs {b:?}");
}

#[test]
fn each_part_is_its_json_twin() {
    let cases = [
        ("rectangle.dxf", example("rectangle.json"), 1e-12, 0.0),
        ("l-shape.dxf", example("l-shape.json"), 1e-12, 0.0),
        // Arcs: chords within 0.05 mm of the arc (inscribed, so the part is a little small)
        // against 1024 chords; the far arc weighs most in the second moments.
        ("hole-arc.dxf", data("hole-arc.json"), 4e-3, 0.05),
        ("arc-chain.dxf", data("hole-arc.json"), 4e-3, 0.05),
    ];
    for (file, twin, rel, deg_tol) in cases {
        let part = load(file, None).unwrap();
        let twin_part = Part::load(&twin).unwrap();
        assert_eq!(part.holes.len(), twin_part.holes.len(), "{file}");
        assert_twins(&part, &twin_part, rel);
        assert_same_rests(orientations(&data(file), &[]), orientations(&twin, &[]), deg_tol);
    }
}

#[test]
fn finer_chords_converge_on_the_twin() {
    let twin = moments(&Part::load(&data("hole-arc.json")).unwrap());
    let err = |chord: f64| {
        let opt = ImportOptions { layer: None, chord_mm: chord };
        let m = moments(&Part::load_with(&data("arc-chain.dxf"), &opt).unwrap().0);
        ((m.0 - twin.0) / twin.0).abs().max(((m.2[0] - twin.2[0]) / twin.2[0]).abs())
    };
    let (coarse, fine) = (err(0.05), err(0.005));
    // Sagitta error is linear in the tolerance.
    assert!(fine < coarse / 5.0 && fine < 5e-4, "{coarse} → {fine}");
}

#[test]
fn arcs_are_flattened_to_the_chord_tolerance() {
    for chord in [0.5, 0.05, 0.005] {
        let opt = ImportOptions { layer: None, chord_mm: chord };
        let (part, _) = Part::load_with(&data("hole-arc.dxf"), &opt).unwrap();
        // The hole is a circle of radius 6 at (25, 18): vertices on it, chord midpoints
        // within the tolerance of it.
        let hole = &part.holes[0];
        for i in 0..hole.len() {
            let (p, q) = (hole[i], hole[(i + 1) % hole.len()]);
            assert!(((p[0] - 25.0).hypot(p[1] - 18.0) - 6.0).abs() < 1e-9);
            let m = [(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0];
            let gap = 6.0 - (m[0] - 25.0).hypot(m[1] - 18.0);
            assert!(gap <= chord + 1e-12 && gap > 0.0, "chord {chord}: gap {gap}");
        }
        // Not needlessly fine either: the largest gap is more than a third of the tolerance.
        let p = (hole[0], hole[1]);
        let m = [(p.0[0] + p.1[0]) / 2.0, (p.0[1] + p.1[1]) / 2.0];
        assert!(6.0 - (m[0] - 25.0).hypot(m[1] - 18.0) > chord / 3.0, "chord {chord}");
    }
}

#[test]
fn inch_drawing_scales_by_25_4() {
    let part = load("inch.dxf", None).unwrap();
    let xs = part.outline.iter().map(|p| p[0]);
    let ys = part.outline.iter().map(|p| p[1]);
    let w = xs.clone().fold(f64::MIN, f64::max) - xs.fold(f64::MAX, f64::min);
    let h = ys.clone().fold(f64::MIN, f64::max) - ys.fold(f64::MAX, f64::min);
    assert!((w - 1.6 * 25.4).abs() < 1e-9 && (h - 0.4 * 25.4).abs() < 1e-9, "{w} × {h}");
    assert!((part.area() - 1.6 * 0.4 * 25.4 * 25.4).abs() < 1e-9);
}

#[test]
fn unitless_drawing_is_read_as_mm_with_a_note() {
    let (part, notes) = Part::load_with(&data("l-shape.dxf"), &ImportOptions::default()).unwrap();
    assert!((part.area() - Part::load(&example("l-shape.json")).unwrap().area()).abs() < 1e-9);
    assert!(notes.iter().any(|n| n.contains("no units") && n.contains("mm")), "{notes:?}");
}

#[test]
fn layer_option_picks_one_layer() {
    let part = load("layers.dxf", Some("PART")).unwrap();
    assert_twins(&part, &Part::load(&example("rectangle.json")).unwrap(), 1e-12);
    // Layer names are case-insensitive, as in CAD.
    let frame = load("layers.dxf", Some("fixture")).unwrap();
    assert!((frame.area() - 100.0 * 80.0).abs() < 1e-9);
    match load("layers.dxf", Some("NOPE")) {
        Err(PartError::Dxf(DxfError::EmptyLayer { layer, layers })) => {
            assert_eq!(layer.as_deref(), Some("NOPE"));
            assert_eq!(layers, ["PART", "FIXTURE"]);
        }
        other => panic!("{other:?}"),
    }
    // Without --layer: closed loops on two layers, refused naming both, their loops and the
    // option.
    let e = load("layers.dxf", None).unwrap_err();
    assert!(matches!(e, PartError::Dxf(DxfError::SeveralLayers { count: 2, .. })), "{e}");
    let m = e.to_string();
    assert!(
        m.contains("--layer")
            && m.contains("\"FIXTURE\" (1 closed loop(s))")
            && m.contains("\"PART\""),
        "{m}"
    );
    assert_same_rests(
        orientations(&data("layers.dxf"), &["--layer", "PART"]),
        orientations(&example("rectangle.json"), &[]),
        0.0,
    );
    let e = Part::load_with(
        &example("rectangle.json"),
        &ImportOptions { layer: Some("PART".into()), ..ImportOptions::default() },
    );
    assert!(matches!(e, Err(PartError::LayerNotDxf(_))));
}

#[test]
fn refusals_are_named_errors() {
    match load("open.dxf", None) {
        Err(PartError::Dxf(DxfError::OpenChain { entity, at })) => {
            assert_eq!((entity.kind, entity.layer.as_str()), ("LINE", "0"));
            assert!(!entity.handle.is_empty());
            // The loose end is one of the gap's two ends.
            let gap_end = |p: [f64; 2]| (at[0] - p[0]).hypot(at[1] - p[1]) < 1e-9;
            assert!(gap_end([0.0, 2.0]) || gap_end([0.0, 0.0]), "{at:?}");
        }
        other => panic!("{other:?}"),
    }
    match load("spline.dxf", None) {
        Err(PartError::Dxf(DxfError::Spline { entity, at })) => {
            assert_eq!(entity.kind, "SPLINE");
            assert_eq!(at, [0.0, 0.0]);
        }
        other => panic!("{other:?}"),
    }
    match load("disjoint.dxf", None) {
        Err(PartError::Dxf(DxfError::SeparateOutlines { count, loops })) => {
            assert_eq!(count, 2);
            assert_eq!(loops.matches("LWPOLYLINE #").count(), 2, "{loops}");
        }
        other => panic!("{other:?}"),
    }
    match load("miles.dxf", None) {
        Err(PartError::Dxf(DxfError::UnknownUnits { code, name })) => {
            assert_eq!((code, name.as_str()), (3, "Miles"));
        }
        other => panic!("{other:?}"),
    }
    // A polyline without vertices is part geometry with no length: said so, not "no part
    // geometry: layers with part geometry: 0".
    let hollow =
        std::env::temp_dir().join(format!("chladni-dxf-{}-hollow.dxf", std::process::id()));
    let text = "0\nSECTION\n2\nENTITIES\n0\nLWPOLYLINE\n8\n0\n90\n0\n0\nENDSEC\n0\nEOF\n";
    std::fs::write(&hollow, text).unwrap();
    let e = Part::load(&hollow);
    std::fs::remove_file(&hollow).unwrap();
    let m = e.unwrap_err().to_string();
    assert!(
        m.contains("entities on layer(s) 0 have no length") && !m.contains("layers with"),
        "{m}"
    );
    let garbage = std::env::temp_dir().join(format!("chladni-dxf-{}.dxf", std::process::id()));
    std::fs::write(&garbage, "not a drawing").unwrap();
    let e = Part::load(&garbage);
    std::fs::remove_file(&garbage).unwrap();
    assert!(matches!(e, Err(PartError::Dxf(DxfError::Read(_)))), "{e:?}");
}

#[test]
fn cli_names_the_entity_and_exits_2() {
    let out = Command::new(env!("CARGO_BIN_EXE_chladni"))
        .args(["analyze", &data("open.dxf").display().to_string(), "--field", "sign"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("open chain") && err.contains("LINE #") && err.contains("layer \"0\""),
        "{err}"
    );
}

fn load_notes(name: &str, layer: Option<&str>) -> Result<(Part, Vec<String>), PartError> {
    let opt = ImportOptions { layer: layer.map(str::to_string), ..ImportOptions::default() };
    Part::load_with(&data(name), &opt)
}

#[test]
fn cad_drawing_with_dimensions_centre_lines_and_text_reads_its_part() {
    let twin = Part::load(&data("hole-arc.json")).unwrap();
    let (part, notes) = load_notes("cad-dims.dxf", None).unwrap();
    assert_twins(&part, &twin, 2e-3);
    // One note names the ignored layers with their counts; the annotation is named by type.
    let ignored: Vec<&String> = notes.iter().filter(|n| n.contains("close no loop")).collect();
    assert_eq!(ignored.len(), 1, "{notes:?}");
    assert!(ignored[0].contains("\"CENTER\" (2 entities)"), "{notes:?}");
    let skipped =
        notes.iter().filter(|n| n.starts_with("skipped")).cloned().collect::<Vec<_>>().join("; ");
    for kind in ["3 DIMENSION", "1 TEXT", "1 MTEXT", "1 HATCH"] {
        assert!(skipped.contains(kind), "{kind}: {skipped}");
    }
}

#[test]
fn title_block_on_its_own_layer_needs_layer_and_says_so() {
    match load("cad-title.dxf", None) {
        Err(PartError::Dxf(e @ DxfError::SeveralLayers { .. })) => {
            let m = e.to_string();
            assert!(m.contains("\"PART\" (2 closed loop(s))") && m.contains("\"TITLE\""), "{m}");
            assert!(m.contains("--layer NAME"), "{m}");
        }
        other => panic!("{other:?}"),
    }
    let part = load("cad-title.dxf", Some("part")).unwrap();
    assert_twins(&part, &Part::load(&data("hole-arc.json")).unwrap(), 2e-3);
}

#[test]
fn inserted_blocks_are_exploded_with_their_placement() {
    // The same part drawn in place (flattened alike: a rigid placement commutes with it).
    let twin = load("hole-arc.dxf", None).unwrap();
    let turned = load("block.dxf", Some("PART")).unwrap();
    assert!((turned.area() - twin.area()).abs() < 1e-9 * twin.area(), "{}", turned.area());
    // The block's base point (25, 10) lands on (100, 50); the centroid turns by 30° about it.
    let [cx, cy] = twin.centroid();
    let (s, c) = 30f64.to_radians().sin_cos();
    let want =
        [100.0 + c * (cx - 25.0) - s * (cy - 10.0), 50.0 + s * (cx - 25.0) + c * (cy - 10.0)];
    let got = turned.centroid();
    assert!((got[0] - want[0]).hypot(got[1] - want[1]) < 1e-9, "{got:?} vs {want:?}");
    let big = load("block.dxf", Some("BIG")).unwrap();
    assert!((big.area() - 4.0 * twin.area()).abs() < 8e-3 * twin.area(), "{}", big.area());
    // Both inserts without --layer: closed loops on two layers.
    assert!(matches!(
        load("block.dxf", None),
        Err(PartError::Dxf(DxfError::SeveralLayers { count: 2, .. }))
    ));
}
