//! `chladni plate from-photo` end to end: synthetic Chladni photos (one curved, one straight,
//! at two drive frequencies) calibrate a plate file mode by mode, and the planner reads it.

use std::path::{Path, PathBuf};
use std::process::Output;

use chladni_core::model::plate::{Node, PlateModel};
use chladni_core::plate::photo::synth::{Scene, arc, render};

use crate::support;
use support::cli::{chladni, tmp};

/// The standard synthetic photo (360×240 px, 300×200 mm plate) of the given nodes, as PNG.
fn photo(name: &str, lines: Vec<(f64, f64)>, curves: Vec<Vec<[f64; 2]>>) -> PathBuf {
    let img = render(&Scene::standard(lines, curves, 11));
    let path = tmp("photo", name);
    img.save(&path).unwrap();
    path
}

fn from_photo(img: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["plate", "from-photo", img.to_str().unwrap(), "--size-mm", "300", "200"];
    args.extend_from_slice(extra);
    chladni(&args)
}

#[test]
fn two_photos_calibrate_a_plate_file_that_the_planner_reads() {
    let plate = tmp("photo", "plate.toml");
    // 120 Hz: a quarter circle about the corner (0, 0), edge to edge.
    let curved = photo("curved.png", vec![], vec![arc([0.0, 0.0], 130.0, 0.0, 90.0, 90)]);
    let out =
        from_photo(&curved, &["--freq-hz", "120", "--json", "--out", plate.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["curves"].as_array().unwrap().len(), 1, "{v}");
    assert_eq!(v["grid"]["signed"], true, "{v}");
    // 60 Hz: one straight node across the plate, appended.
    let straight = photo("straight.png", vec![(0.0, 20.0)], vec![]);
    let out =
        from_photo(&straight, &["--freq-hz", "60", "--append", "--out", plate.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    let model = PlateModel::load(&plate).unwrap();
    assert_eq!(
        model.name,
        "from photo chladni-photo-".to_string() + &format!("{}-curved", std::process::id())
    );
    assert_eq!(model.size_mm, [300.0, 200.0]);
    let names: Vec<&str> = model.modes.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["photo 120 Hz nodes", "photo 60 Hz line"]);
    assert!(matches!(model.modes[0].node, Node::Grid(_)));
    match model.modes[1].node {
        Node::Line { angle_deg, offset_mm } => {
            assert!(angle_deg.min(180.0 - angle_deg) < 1.0, "{angle_deg}");
            // Near 180° the same line has its normal, and so its offset, reversed.
            let offset = if angle_deg > 90.0 { -offset_mm } else { offset_mm };
            assert!((offset - 20.0).abs() < 2.0, "{angle_deg}° {offset_mm}");
        }
        ref n => panic!("expected a line, got {n:?}"),
    }
    // The planner takes the calibrated plate: the rectangle lies along the straight node.
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/parts/rectangle.json");
    let out = chladni(&["plan", root, "--plate", plate.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let p: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(p["steps"].as_array().unwrap().len(), 1, "{p}");

    // Appending a photo of another plate size is refused and names both sizes.
    let out = chladni(&[
        "plate",
        "from-photo",
        straight.to_str().unwrap(),
        "--size-mm",
        "330",
        "220",
        "--freq-hz",
        "90",
        "--append",
        "--out",
        plate.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("is a 300 × 200 mm plate, the photo is 330 × 220 mm; give --size-mm 300 200"),
        "{err}"
    );
    for f in [plate, curved, straight] {
        let _ = std::fs::remove_file(f);
    }
}

#[test]
fn bad_arguments_exit_2_with_the_value() {
    let img = photo("bad.png", vec![(90.0, 0.0)], vec![]);
    let out = from_photo(&img, &["--grid", "2", "--as-grid", "--json"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--grid must be in 3..=401, got 2"));
    let out = chladni(&["plate", "from-photo", "/nonexistent.png", "--size-mm", "300", "200"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot read image /nonexistent.png"));
    let out = from_photo(&img, &["--append"]);
    assert_eq!(out.status.code(), Some(2), "--append needs --out");
    // A photo with no sand on nodes: exit 1, and no empty plate file left behind.
    let blank = photo("blank.png", vec![], vec![]);
    let plate = tmp("photo", "blank.toml");
    let out = from_photo(&blank, &["--freq-hz", "60", "--out", plate.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no node found in"));
    assert!(!plate.exists());
    for f in [img, blank] {
        let _ = std::fs::remove_file(f);
    }
}

// A photo taken at an angle: with the plate's corners marked, the straight node is found as
// drawn; a corner outside the image is refused with its value.
#[test]
fn oblique_photo_is_rectified_by_its_corners() {
    use chladni_core::plate::photo::rectify::{Homography, warp};
    let square = photo("square.png", vec![(90.0, 40.0)], vec![]);
    let plate = image::open(&square).unwrap().to_luma8();
    let corners = [[38.0, 352.0], [452.0, 372.0], [405.0, 58.0], [88.0, 44.0]];
    let to_plate =
        Homography::from_points(corners, [[0.0, 240.0], [360.0, 240.0], [360.0, 0.0], [0.0, 0.0]])
            .unwrap();
    let oblique = tmp("photo", "oblique.png");
    warp(&plate, &to_plate, 500, 420, 90).save(&oblique).unwrap();
    let flat: Vec<String> = corners.iter().flatten().map(|v| v.to_string()).collect();
    let rectified = tmp("photo", "rectified.png");
    let mut args = vec!["--json", "--save-rectified", rectified.to_str().unwrap(), "--corners"];
    args.extend(flat.iter().map(String::as_str));
    let out = from_photo(&oblique, &args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let lines = v["lines"].as_array().unwrap();
    assert_eq!(lines.len(), 1, "{v}");
    assert!((lines[0]["angle_deg"].as_f64().unwrap() - 90.0).abs() < 1.0, "{v}");
    assert!((lines[0]["offset_mm"].as_f64().unwrap() - 40.0).abs() < 2.0, "{v}");
    let saved = image::open(&rectified).unwrap();
    assert!(saved.width() > 350 && saved.height() > 280, "{}×{}", saved.width(), saved.height());

    let mut bad = flat.clone();
    bad[2] = "900".into();
    let mut args = vec!["--corners"];
    args.extend(bad.iter().map(String::as_str));
    let out = from_photo(&oblique, &args);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--corners: corner 1 (900.0, 372.0) px lies outside the 500×420 px image"),
        "{err}"
    );
    for f in [square, oblique, rectified] {
        let _ = std::fs::remove_file(f);
    }
}

// The paper's lentils: with --grain-mm the nodes are found as bands of separate grains; a
// grain size over a tenth of the plate is refused.
#[test]
fn lentil_photo_with_grain_size() {
    let img = render(&Scene::lentils(vec![(90.0, 40.0), (20.0, -30.0)], vec![], 2));
    let path = tmp("photo", "lentils.png");
    img.save(&path).unwrap();
    let out = from_photo(&path, &["--grain-mm", "4", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let mut angles: Vec<f64> =
        v["lines"].as_array().unwrap().iter().map(|l| l["angle_deg"].as_f64().unwrap()).collect();
    angles.sort_by(f64::total_cmp);
    assert_eq!(angles.len(), 2, "{v}");
    assert!((angles[0] - 20.0).abs() < 2.5 && (angles[1] - 90.0).abs() < 2.5, "{angles:?}");
    let out = from_photo(&path, &["--grain-mm", "25"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--grain-mm must be in [0, 20.0)") && err.contains("got 25"), "{err}");
    let _ = std::fs::remove_file(path);
}

/// A PNG of `w`×`h` px whose pixels are random grey levels.
fn noise_png(name: &str, w: u32, h: u32) -> PathBuf {
    let mut rng = chladni_core::plate::photo::synth::Rng(42);
    let img = image::GrayImage::from_fn(w, h, |_, _| image::Luma([(rng.next_u64() >> 56) as u8]));
    let path = tmp("photo", name);
    img.save(&path).unwrap();
    path
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

// A huge PNG (a few hundred kB, 20 000 × 20 000 px) is refused from its header, at once.
#[test]
fn huge_image_is_refused_before_decoding() {
    let path = tmp("photo", "huge.png");
    let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    let mut enc = png::Encoder::new(file, 20_000, 20_000);
    enc.set_color(png::ColorType::Grayscale);
    let mut w = enc.write_header().unwrap().into_stream_writer().unwrap();
    let row = vec![0u8; 20_000];
    // Only the first rows: the header alone must stop it (the file is cut short).
    for _ in 0..10 {
        std::io::Write::write_all(&mut w, &row).unwrap();
    }
    drop(w);
    let t = std::time::Instant::now();
    let out = from_photo(&path, &[]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(t.elapsed().as_secs() < 5, "{:?}", t.elapsed());
    let err = stderr(&out);
    assert!(err.contains("is 20000×20000 px (400 MP), over the limit of 50 MP"), "{err}");
    assert!(err.contains("scale it down"), "{err}");
    let _ = std::fs::remove_file(path);
}

// Random noise has no nodes: whatever lines the Hough transform finds in it explain little of
// the skeleton, so the photo is refused (exit 1) and nothing is written.
#[test]
fn random_noise_is_not_a_chladni_figure() {
    let path = noise_png("noise.png", 360, 240);
    let plate = tmp("photo", "noise.toml");
    let out = from_photo(&path, &["--freq-hz", "60", "--out", plate.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stdout));
    let err = stderr(&out);
    assert!(err.contains("no confident node found"), "{err}");
    assert!(err.contains("%"), "{err}");
    assert!(!plate.exists());
    let _ = std::fs::remove_file(path);
}

// --size-mm 200 300 for a 300 × 200 px photo: the aspect ratios contradict, the swap is named;
// with --corners (a rectified view) the photo's own shape does not matter.
#[test]
fn size_contradicting_the_photo_is_refused() {
    let img = photo("aspect.png", vec![(90.0, 40.0)], vec![]);
    let out = chladni(&["plate", "from-photo", img.to_str().unwrap(), "--size-mm", "200", "300"]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.contains("--size-mm 200 300 has aspect ratio W/H = 0.667, but the 360×240 px photo"),
        "{err}"
    );
    assert!(err.contains("has 1.500; did you mean --size-mm 300 200?"), "{err}");
    // Within the tolerance (a loosely cropped photo) it runs.
    let out = chladni(&["plate", "from-photo", img.to_str().unwrap(), "--size-mm", "310", "200"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let _ = std::fs::remove_file(img);
}

// --freq-hz outside the drive's range is refused before any work; --out needs a frequency.
#[test]
fn frequency_is_checked_before_work_and_needed_for_a_plate_file() {
    let img = photo("freq.png", vec![(90.0, 40.0)], vec![]);
    let plate = tmp("photo", "freq.toml");
    let out = from_photo(&img, &["--freq-hz", "1e9", "--out", plate.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.contains("--freq-hz: frequency 1e9 Hz is outside the drive's range 1..=2000 Hz"),
        "{err}"
    );
    assert!(!plate.exists());
    let out = from_photo(&img, &["--out", plate.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--out needs --freq-hz"), "{}", stderr(&out));
    assert!(!plate.exists());
    let _ = std::fs::remove_file(img);
}

// The format comes from the content: a PNG named .jpg is read as the PNG it is.
#[test]
fn png_named_jpg_is_read_by_its_content() {
    let png = photo("named.png", vec![(90.0, 40.0)], vec![]);
    let jpg = tmp("photo", "named.jpg");
    std::fs::rename(&png, &jpg).unwrap();
    let out = from_photo(&jpg, &["--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["lines"].as_array().unwrap().len(), 1, "{v}");
    let _ = std::fs::remove_file(jpg);
}

/// A photo with two node lines is one mode (one `lines` entry), a line photo appended at the
/// same frequency merges into it, and the plan made on the plate holds in simulation.
#[test]
fn multi_line_photo_is_one_mode_that_plans_and_simulates_as_planned() {
    let plate = tmp("photo", "lines.toml");
    let plate_s = plate.to_str().unwrap();
    // 60 Hz: vertical lines at x = 80 and x = 190 mm (offset along n̂ = (−1, 0) from x = 150).
    let two = photo("two-lines.png", vec![(90.0, 70.0), (90.0, -40.0)], vec![]);
    let out = from_photo(&two, &["--freq-hz", "60", "--out", plate_s]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let model = PlateModel::load(&plate).unwrap();
    assert_eq!(model.modes.len(), 1);
    assert_eq!(
        model.modes[0].name,
        "photo 60 Hz 2 lines",
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(matches!(&model.modes[0].node, Node::Lines(l) if l.len() == 2));
    // 80 Hz: a horizontal line, appended as a second mode.
    let horizontal = photo("horizontal.png", vec![(0.0, 0.0)], vec![]);
    let out = from_photo(&horizontal, &["--freq-hz", "80", "--append", "--out", plate_s]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    let part = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/parts/rectangle.json");
    let plan = tmp("photo", "lines-plan.json");
    let out =
        chladni(&["plan", part, "--plate", plate_s, "--json", "--out", plan.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let p: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let freqs: Vec<f64> =
        p["steps"].as_array().unwrap().iter().map(|s| s["freq_hz"].as_f64().unwrap()).collect();
    assert!(freqs.windows(2).all(|w| w[0] != w[1]), "{freqs:?}");
    let out = chladni(&[
        "simulate",
        part,
        "--plate",
        plate_s,
        "--plan",
        plan.to_str().unwrap(),
        "--trials",
        "60",
        "--json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // The plan claims every start ends at its final orientation.
    assert_eq!(s["success_rate"].as_f64(), Some(1.0), "{s}");

    // A third line at 60 Hz merges into the 60 Hz mode, and says so.
    let third = photo("third.png", vec![(0.0, 60.0)], vec![]);
    let out = from_photo(&third, &["--freq-hz", "60", "--append", "--out", plate_s]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        stderr(&out).contains("merged into [[mode]] 1 (photo 60 Hz 2 lines)"),
        "{}",
        stderr(&out)
    );
    let model = PlateModel::load(&plate).unwrap();
    assert_eq!(model.modes.len(), 2);
    assert!(matches!(&model.modes[0].node, Node::Lines(l) if l.len() == 3));
    // A grid entry at 60 Hz cannot merge with lines: refused, the file unchanged.
    let before = std::fs::read_to_string(&plate).unwrap();
    let out = from_photo(&third, &["--freq-hz", "60", "--as-grid", "--append", "--out", plate_s]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("already at 60 Hz"), "{}", stderr(&out));
    assert_eq!(std::fs::read_to_string(&plate).unwrap(), before);
    for f in [plate, plan, two, horizontal, third] {
        let _ = std::fs::remove_file(f);
    }
}
