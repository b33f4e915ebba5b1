//! Calibrating the settle speed from photos: a part's run simulated at a known speed on the
//! four-lines plate, rendered as timestamped photos by the vision generator, gives the speed
//! back through `chladni plate calibrate-speed --photos`; bad series are refused by name.

use crate::support;

use std::path::{Path, PathBuf};

use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::contact::Rim;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::integrate::SimParams;
use chladni_media::vision::synth::{Photo, Placed, render};
use support::cli::{chladni, ex, json, tmp};
use support::examples;

/// The speed the photos are rendered at (mm/s).
const TRUE_SPEED: f64 = 7.0;
/// Photo times (s): the part moves about 40 mm over them, still short of the node.
const TIMES: [f64; 5] = [0.0, 1.5, 3.0, 4.5, 6.0];

/// A 640 × 450 photo of the 300 × 200 plate (about 0.5 mm per pixel: the debug build locates
/// it quickly) with `placed` on it, in fairly even light (10 % fall-off: with a single part on
/// the plate, Otsu's threshold splits a stronger light gradient instead; docs/plate.md).
fn photo(part: &Part, placed: Vec<Placed>, seed: u64) -> Photo {
    let mut p = Photo::standard(vec![part.clone()], placed, seed);
    p.px = (640, 450);
    p.corners = p.corners.map(|c| [c[0] / 2.0, c[1] / 2.0]);
    p.blur_px = 0.6;
    p.light_falloff = 0.1;
    p
}

/// The pose after `t` s at TRUE_SPEED from `start`, with the plate's rim, as the fit models it.
fn pose_after(plate: &PlateModel, mode: usize, body: &Body, start: Pose, t: f64) -> Pose {
    let field = FieldModel::new(&plate.modes[mode], plate);
    let rim = Some(Rim::of(plate));
    let p = SimParams { speed: TRUE_SPEED, t_limit: t, run_to_limit: true, rim };
    if t == 0.0 { start } else { chladni_core::motion::integrate::run(body, &field, p, start).pose }
}

/// Renders the run as `dir/NAME(t)` photos.
fn render_series(dir: &Path, part: &Part, name: impl Fn(f64) -> String) {
    let plate = examples::plate("four-lines.toml");
    let mode = plate.modes.iter().position(|m| m.name == "vertical").unwrap();
    let body = Body::new(part);
    let start = Pose { x: 80.0, y: 110.0, theta: 0.6 };
    std::fs::create_dir_all(dir).unwrap();
    for (k, &t) in TIMES.iter().enumerate() {
        let q = pose_after(&plate, mode, &body, start, t);
        let placed = vec![Placed {
            part: 0,
            c: [q.x, q.y],
            theta_deg: q.theta.to_degrees(),
            flipped: false,
        }];
        render(&photo(part, placed, k as u64 + 1)).save(dir.join(name(t))).unwrap();
    }
}

fn calibrate(plate: &Path, dir: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "plate",
        "calibrate-speed",
        plate.to_str().unwrap(),
        "--mode",
        "vertical",
        "--photos",
        dir.to_str().unwrap(),
        "--json",
    ];
    args.extend_from_slice(extra);
    chladni(&args)
}

#[test]
fn photos_of_a_run_at_7_mm_s_give_the_speed_back_and_write_the_plate() {
    let part = examples::part("l-shape.json");
    let dir = tmp("calphoto", "series");
    render_series(&dir, &part, |t| format!("run_{:05.0}ms.png", t * 1000.0));
    std::fs::write(dir.join("notes.txt"), "not a photo: ignored").unwrap();
    let plate = tmp("calphoto", "plate.toml");
    std::fs::copy(ex("plates/four-lines.toml"), &plate).unwrap();
    let out = calibrate(&plate, &dir, &["--part", &ex("parts/l-shape.json")]);
    let v = json(&out);
    assert!(out.status.success(), "{v}");
    let mu = v["speed_mm_s"].as_f64().unwrap();
    eprintln!("photos: {mu} mm/s (true {TRUE_SPEED}), rms {} mm", v["rms_pose_mm"]);
    assert!((mu / TRUE_SPEED - 1.0).abs() < 0.02, "{v}");
    assert!(v["rms_pose_mm"].as_f64().unwrap() < 0.5, "{v}");
    assert_eq!(v["method"], "1-D search");
    assert_eq!(v["photos"].as_array().unwrap().len(), TIMES.len());
    assert_eq!(v["residuals"].as_array().unwrap().len(), TIMES.len() - 1);
    assert_eq!(v["photos"][4]["t_s"], 6.0);
    let written = PlateModel::parse(&std::fs::read_to_string(&plate).unwrap(), "p").unwrap();
    assert_eq!(written.modes[0].speed_mm_s, mu);
    // The same photos with the corners given and the seconds form of the names.
    let dir2 = tmp("calphoto", "series2");
    std::fs::create_dir_all(&dir2).unwrap();
    for (k, &t) in TIMES.iter().enumerate() {
        let from = dir.join(format!("run_{:05.0}ms.png", t * 1000.0));
        std::fs::copy(from, dir2.join(format!("cam{k}_t{t:07.3}.png"))).unwrap();
    }
    let corners: Vec<String> =
        photo(&part, vec![], 0).corners.iter().flatten().map(|c| c.to_string()).collect();
    let tri = ex("parts/l-shape.json");
    let mut extra = vec!["--part", tri.as_str(), "--dry-run", "--corners"];
    extra.extend(corners.iter().map(String::as_str));
    let out = calibrate(&plate, &dir2, &extra);
    let v2 = json(&out);
    assert!(out.status.success(), "{v2}");
    assert!((v2["speed_mm_s"].as_f64().unwrap() / TRUE_SPEED - 1.0).abs() < 0.02, "{v2}");
    for d in [dir, dir2] {
        std::fs::remove_dir_all(d).unwrap();
    }
}

/// The error name of a failed run (exit 2), and that its message names `needle`.
fn refused(out: &std::process::Output, needle: &str) -> String {
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let v = json(out);
    let msg = v["message"].as_str().unwrap();
    assert!(msg.contains(needle), "{msg} should name {needle}");
    v["error"].as_str().unwrap().to_string()
}

#[test]
fn bad_photo_series_are_refused_by_name() {
    let part = examples::part("l-shape.json");
    let plate = ex("plates/four-lines.toml");
    let plate = Path::new(&plate);
    let tri = ex("parts/l-shape.json");
    let args = ["--part", tri.as_str(), "--dry-run"];
    let dir = tmp("calphoto", "bad");
    std::fs::create_dir_all(&dir).unwrap();
    assert_eq!(refused(&calibrate(plate, &dir, &args), "no photos"), "no_photos");
    let one = dir.join("t001.000.png");
    let at = |x: f64| vec![Placed { part: 0, c: [x, 100.0], theta_deg: 10.0, flipped: false }];
    render(&photo(&part, at(80.0), 1)).save(&one).unwrap();
    assert_eq!(refused(&calibrate(plate, &dir, &args), "at least 2"), "too_few_photos");
    let noname = dir.join("shot.png");
    std::fs::copy(&one, &noname).unwrap();
    assert_eq!(refused(&calibrate(plate, &dir, &args), "shot.png"), "unreadable_time");
    std::fs::remove_file(&noname).unwrap();
    let empty: PathBuf = dir.join("t002.000.png");
    render(&photo(&part, vec![], 2)).save(&empty).unwrap();
    assert_eq!(refused(&calibrate(plate, &dir, &args), "t002.000.png"), "part_not_found");
    let mut two = at(80.0);
    two.extend(at(200.0));
    render(&photo(&part, two, 3)).save(&empty).unwrap();
    assert_eq!(refused(&calibrate(plate, &dir, &args), "t002.000.png"), "several_parts");
    let mut flipped = at(90.0);
    flipped[0].flipped = true;
    render(&photo(&part, flipped, 4)).save(&empty).unwrap();
    assert_eq!(refused(&calibrate(plate, &dir, &args), "t002.000.png"), "face_changed");
    std::fs::write(&empty, b"not a png").unwrap();
    assert_eq!(refused(&calibrate(plate, &dir, &args), "t002.000.png"), "not_a_photo");
    // Two parts, or the CSV and the photos at once: refused before any photo is read.
    let hole = ex("parts/plate-with-hole.json");
    let out = calibrate(plate, &dir, &["--part", &tri, "--part", &hole]);
    assert_eq!(refused(&out, "exactly one --part"), "bad_input");
    let out = calibrate(plate, &dir, &["--part", &tri, "--observations", "x.csv"]);
    assert_eq!(out.status.code(), Some(2));
    std::fs::remove_dir_all(dir).unwrap();
}
