//! `chladni verify` end to end: a simulated run's end poses (`simulate --poses`) rendered as
//! photos (the synthetic camera of `vision::synth`) and checked against the plan give
//! `simulate`'s success rate, trial by trial; a photo with a part turned wrong exits 1 naming
//! it; every bad input is refused by name (exit 2).

use crate::support;

use std::path::{Path, PathBuf};

use chladni_core::model::angle::signed_diff;
use chladni_core::model::part::Part;
use chladni_media::vision::Template;
use chladni_media::vision::synth::{Photo, Placed, render};
use serde_json::Value;
use support::cli::{chladni, ex, json, tmp};

fn scratch(name: &str) -> PathBuf {
    tmp("verify", name)
}

/// The part: the example key, whose two faces differ clearly at the photos' 0.5 mm per pixel
/// (the example triangle's mirror image is within 0.3 mm of it turned: at this resolution its
/// face is a coin toss).
const PART: &str = "parts/key.svg";
/// Its plan on the example plate.
const PLAN: &str = "plans/key-four-lines.json";
const PLATE: &str = "plates/four-lines.toml";

/// The example key plan cut to its last step (the vertical node at 60 Hz): it predicts
/// 91.0°, and keys that arrive the other way round end at 271.0°, so some trials miss.
fn one_step_plan() -> PathBuf {
    let text = std::fs::read_to_string(ex(PLAN)).unwrap();
    let mut plan: Value = serde_json::from_str(&text).unwrap();
    let last = plan["steps"].as_array().unwrap().last().cloned().unwrap();
    plan["steps"] = Value::Array(vec![last]);
    plan["final_position_mm"] = Value::Null;
    plan.as_object_mut().unwrap().remove("reachable_deg");
    let path = scratch("one-step.json");
    std::fs::write(&path, plan.to_string()).unwrap();
    path
}

/// A 640 × 450 photo of the 300 × 200 mm plate (0.5 mm per pixel), the standard camera's view
/// halved: a quarter of the pixels to render and search in a debug build.
fn photo(parts: &[Part], placed: Vec<Placed>, seed: u64) -> Photo {
    let mut p = Photo::standard(parts.to_vec(), placed, seed);
    p.px = (640, 450);
    p.corners = p.corners.map(|c| [c[0] / 2.0, c[1] / 2.0]);
    p.blur_px = 0.5;
    p
}

/// `--corners` of [`photo`]: given, as a camera fixed over the plate would have them measured
/// once (finding them is `chladni locate`'s test, and the costliest step in a debug build).
fn corners() -> Vec<String> {
    photo(&[], vec![], 0).corners.iter().flatten().map(|v| v.to_string()).collect()
}

fn verify_args<'a>(photo: &'a str, plan: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec!["verify", photo, "--plan", plan];
    a.extend_from_slice(&["--plate", "PLATE", "--part", "PART"]);
    a.extend_from_slice(extra);
    a
}

/// Runs `verify` with the example plate and part, the photo's corners given.
fn verify(photo: &Path, plan: &Path, extra: &[&str]) -> std::process::Output {
    let (plate, part) = (ex(PLATE), ex(PART));
    let (p, pl) = (photo.display().to_string(), plan.display().to_string());
    let corners = corners();
    let mut extra = extra.to_vec();
    extra.push("--corners");
    extra.extend(corners.iter().map(String::as_str));
    let args: Vec<&str> = verify_args(&p, &pl, &extra)
        .into_iter()
        .map(|a| match a {
            "PLATE" => plate.as_str(),
            "PART" => part.as_str(),
            a => a,
        })
        .collect();
    chladni(&args)
}

/// Trials grouped so that no two in one photo lie closer than `gap` mm (their centroids).
fn groups(ends: &[(usize, Placed)], gap: f64) -> Vec<Vec<(usize, Placed)>> {
    let mut out: Vec<Vec<(usize, Placed)>> = Vec::new();
    for e in ends {
        let fits = |g: &Vec<(usize, Placed)>| {
            g.iter().all(|(_, o)| (o.c[0] - e.1.c[0]).hypot(o.c[1] - e.1.c[1]) > gap)
        };
        match out.iter_mut().find(|g| fits(g)) {
            Some(g) => g.push(e.clone()),
            None => out.push(vec![e.clone()]),
        }
    }
    out
}

#[test]
fn photos_of_a_simulated_runs_end_poses_give_simulates_success_rate() {
    let plan = one_step_plan();
    let sim = chladni(&[
        "simulate",
        &ex(PART),
        "--plate",
        &ex(PLATE),
        "--plan",
        &plan.display().to_string(),
        "--trials",
        "8",
        "--json",
        "--poses",
    ]);
    assert!(sim.status.success(), "{}", String::from_utf8_lossy(&sim.stderr));
    let sim = json(&sim);
    let rate = sim["success_rate"].as_f64().unwrap();
    assert!(rate > 0.0 && rate < 1.0, "the test needs hits and misses: {rate}");
    let target = sim["final_orientation_deg"].as_f64().unwrap();
    let ends: Vec<(usize, Placed)> = (sim["poses"].as_array().unwrap().iter().enumerate())
        .map(|(i, p)| {
            let e = &p["end"];
            let c = [e["x_mm"].as_f64().unwrap(), e["y_mm"].as_f64().unwrap()];
            (i, Placed { part: 0, c, theta_deg: e["theta_deg"].as_f64().unwrap(), flipped: false })
        })
        .collect();
    let part = Part::load(Path::new(&ex(PART))).unwrap();
    let gap = 2.0 * Template::new(&part).radius_mm + 4.0;
    let (mut found, mut oriented) = (0, 0);
    for (k, group) in groups(&ends, gap).into_iter().enumerate() {
        let placed: Vec<Placed> = group.iter().map(|g| g.1.clone()).collect();
        let path = scratch(&format!("end-{k}.png"));
        render(&photo(std::slice::from_ref(&part), placed, 40 + k as u64)).save(&path).unwrap();
        let out = verify(&path, &plan, &["--json"]);
        let v = json(&out);
        let parts = v["parts"].as_array().unwrap();
        assert_eq!(parts.len(), group.len(), "{v}");
        let mut all_hit = true;
        for (trial, p) in &group {
            let hit = signed_diff(p.theta_deg, target, 360.0).abs() <= 5.0;
            all_hit &= hit;
            let seen = (parts.iter())
                .find(|l| {
                    (l["x_mm"].as_f64().unwrap() - p.c[0])
                        .hypot(l["y_mm"].as_f64().unwrap() - p.c[1])
                        < 1.0
                })
                .unwrap_or_else(|| panic!("trial {trial} at {:?} not found: {v}", p.c));
            assert_eq!(seen["ok"].as_bool(), Some(hit), "trial {trial}: {seen}");
            if !hit {
                let reason = seen["reason"].as_str().unwrap();
                assert!(reason.starts_with("key: θ"), "{reason}");
                assert_eq!(seen["miss"], "orientation");
            }
        }
        assert_eq!(out.status.code(), Some(if all_hit { 0 } else { 1 }), "{v}");
        found += v["found"].as_u64().unwrap();
        oriented += v["oriented"].as_u64().unwrap();
        let _ = std::fs::remove_file(path);
    }
    assert_eq!(found, ends.len() as u64);
    assert_eq!(oriented as f64 / found as f64, rate, "verify {oriented}/{found}, simulate {rate}");
}

#[test]
fn a_part_turned_wrong_exits_1_naming_it_and_the_plot_is_written() {
    let plan = one_step_plan();
    let part = Part::load(Path::new(&ex(PART))).unwrap();
    let good = Placed { part: 0, c: [150.0, 55.0], theta_deg: 91.0, flipped: false };
    let wrong = Placed { c: [150.0, 145.0], theta_deg: 131.0, ..good.clone() };
    let path = scratch("turned.png");
    render(&photo(std::slice::from_ref(&part), vec![good, wrong], 7)).save(&path).unwrap();
    let plot = scratch("turned-plot.png");
    let out = verify(&path, &plan, &["--plot", plot.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{text}\n{}", String::from_utf8_lossy(&out.stderr));
    let off: Vec<&str> = text.lines().filter(|l| l.contains("OFF")).collect();
    assert_eq!(off.len(), 1, "{text}");
    assert!(off[0].contains("key: θ") && off[0].contains("40.0° from the planned 91.0°"), "{text}");
    assert!(text.contains("1 of 2 parts as planned (50.0 %"), "{text}");
    let fig = image::open(&plot).unwrap().to_rgb8();
    // Red outline (off) and green outline (as planned) both drawn.
    let count = |rgb: [u8; 3]| fig.pixels().filter(|p| p.0 == rgb).count();
    assert!(count([230, 30, 30]) > 100 && count([0, 200, 60]) > 100, "outlines missing");
    for f in [path, plot] {
        let _ = std::fs::remove_file(f);
    }
}

fn refused(out: &std::process::Output, name: &str, words: &str) {
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let v = json(out);
    assert_eq!(v["error"], name, "{v}");
    assert!(v["message"].as_str().unwrap().contains(words), "{v}");
}

#[test]
fn bad_input_is_refused_by_name() {
    let plan = one_step_plan();
    let text = scratch("not-a-photo.png");
    std::fs::write(&text, "hello").unwrap();
    refused(&verify(&text, &plan, &["--json"]), "not_a_photo", "cannot read image");
    let write = |name: &str, v: Value| {
        let p = scratch(name);
        std::fs::write(&p, v.to_string()).unwrap();
        p
    };
    let base: Value = serde_json::from_str(&std::fs::read_to_string(&plan).unwrap()).unwrap();
    let mut other_plate = base.clone();
    other_plate["steps"][0]["freq_hz"] = 77.0.into();
    let p = write("77hz.json", other_plate);
    refused(&verify(&text, &p, &["--json"]), "plan_plate_mismatch", "77");
    let mut nothing = base.clone();
    nothing["final_orientation_deg"] = Value::Null;
    let p = write("nothing.json", nothing);
    refused(&verify(&text, &p, &["--json"]), "no_prediction", "nothing to check");
    let two = ["--json", "--part", &ex("parts/rectangle.json")];
    refused(&verify(&text, &plan, &two), "plan_parts_mismatch", "1 part(s)");
    let swapped = ["--json", "--size-mm", "200", "300"];
    refused(&verify(&text, &plan, &swapped), "size_mismatch", "300 × 200 mm");
    refused(&verify(&text, &plan, &["--json", "--tol-deg", "0"]), "bad_tolerance", "--tol-deg 0");
    let bad_plan = scratch("bad-plan.json");
    std::fs::write(&bad_plan, "{").unwrap();
    refused(&verify(&text, &bad_plan, &["--json"]), "bad_plan", "bad-plan.json");
    let _ = std::fs::remove_file(text);
}
