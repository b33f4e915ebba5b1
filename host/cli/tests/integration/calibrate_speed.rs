//! Calibrating a mode's settle speed: observations synthesised from the motion model at a
//! known μ (with seeded noise) give μ back, through the library and through
//! `chladni plate calibrate-speed`; bad files and undetermined fits are refused.

use std::path::PathBuf;

use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::integrate::SimParams;
use chladni_core::plate::calibrate::{self, CalPart, FitError, Measured, Observation};
use chladni_core::rng::Rng;

use crate::support;
use support::cli::{chladni, tmp_dir};
use support::examples;

const TRUE_SPEED: f64 = 14.2;

/// Time (s) until the centroid first comes within 1 mm of its rest, from a run at μ (no rim:
/// the starts below stay clear of it, where a run is the same with or without one)
/// (computed here from the model's trace, independently of the fit's own reading of it).
fn time_to_node(body: &Body, field: &FieldModel, mu: f64, start: Pose) -> f64 {
    let p = SimParams { speed: mu, t_limit: 1e9, run_to_limit: false, rim: None };
    let r = chladni_core::motion::integrate::run(body, field, p, start);
    assert!(r.rested);
    let d = |q: &Pose| (q.x - r.pose.x).hypot(q.y - r.pose.y);
    let k = r.trace.iter().position(|(_, q)| d(q) <= 1.0).unwrap();
    if k == 0 {
        return 0.0;
    }
    let ((ta, a), (tb, b)) = (r.trace[k - 1], r.trace[k]);
    ta + (d(&a) - 1.0) / (d(&a) - d(&b)) * (tb - ta)
}

/// Pose after `t` seconds at μ.
fn pose_after(body: &Body, field: &FieldModel, mu: f64, start: Pose, t: f64) -> Pose {
    chladni_core::motion::integrate::run(
        body,
        field,
        SimParams { speed: mu, t_limit: t, run_to_limit: true, rim: None },
        start,
    )
    .pose
}

/// Random starts on the four-lines plate's left half, away from the vertical node.
fn starts(rng: &mut Rng, n: usize) -> Vec<Pose> {
    (0..n)
        .map(|_| Pose {
            x: rng.range(30.0, 110.0),
            y: rng.range(40.0, 160.0),
            theta: rng.range(0.0, std::f64::consts::TAU),
        })
        .collect()
}

fn setup() -> (PlateModel, usize, Vec<Part>) {
    let plate = examples::plate("four-lines.toml");
    let mode = plate.modes.iter().position(|m| m.name == "vertical").unwrap();
    (plate, mode, vec![examples::part("triangle.json"), examples::part("plate-with-hole.json")])
}

/// Time observations at TRUE_SPEED with ±`noise` relative (uniform, seeded).
fn time_observations(noise: f64, seed: u64) -> (Vec<Observation>, Vec<f64>) {
    let (plate, mode, parts) = setup();
    let field = FieldModel::new(&plate.modes[mode], &plate);
    let mut rng = Rng::seeded(seed);
    let mut obs = Vec::new();
    let mut times = Vec::new();
    for (k, start) in starts(&mut rng, 12).into_iter().enumerate() {
        let part = k % parts.len();
        let t = time_to_node(&Body::new(&parts[part]), &field, TRUE_SPEED, start);
        let t = t * (1.0 + rng.range(-noise, noise));
        times.push(t);
        obs.push(Observation {
            line: k + 2,
            part,
            start,
            measured: Measured::TimeToNode { t_s: t },
        });
    }
    (obs, times)
}

#[test]
fn time_observations_give_the_speed_back_in_closed_form() {
    let (plate, mode, parts) = setup();
    let cal: Vec<CalPart> = parts.iter().map(CalPart::new).collect();
    // Exact observations: μ to the rounding of the integrator (scale invariance).
    let (obs, _) = time_observations(0.0, 3);
    let fit = calibrate::fit(&cal, &plate, mode, &obs, 1.0).unwrap();
    eprintln!("exact: {} mm/s, rms {:?} s", fit.speed_mm_s, fit.rms_time_s);
    assert_eq!(fit.method, "closed form");
    assert!((fit.speed_mm_s / TRUE_SPEED - 1.0).abs() < 1e-4, "{}", fit.speed_mm_s);
    // ±5 % stopwatch noise on 12 observations.
    let (obs, _) = time_observations(0.05, 4);
    let fit = calibrate::fit(&cal, &plate, mode, &obs, 1.0).unwrap();
    eprintln!("±5 %: {} mm/s, rms {:?} s", fit.speed_mm_s, fit.rms_time_s);
    assert!((fit.speed_mm_s / TRUE_SPEED - 1.0).abs() < 0.03, "{}", fit.speed_mm_s);
    assert_eq!(fit.residuals.len(), 12);
    assert!(fit.rms_time_s.unwrap() > 0.0 && fit.rms_pose_mm.is_none());
}

#[test]
fn pose_observations_give_the_speed_back_by_a_1d_search() {
    let (plate, mode, parts) = setup();
    let field = FieldModel::new(&plate.modes[mode], &plate);
    let cal: Vec<CalPart> = parts.iter().map(CalPart::new).collect();
    let mut rng = Rng::seeded(11);
    let mut obs = Vec::new();
    for (k, start) in starts(&mut rng, 8).into_iter().enumerate() {
        let part = k % parts.len();
        // Observed while still moving: a quarter of the way to the node's time.
        let body = Body::new(&parts[part]);
        let t = 0.25 * time_to_node(&body, &field, TRUE_SPEED, start);
        let q = pose_after(&body, &field, TRUE_SPEED, start, t);
        let mut noisy = |v: f64, a: f64| v + rng.range(-a, a);
        let measured = Measured::PoseAfter {
            t_s: t,
            x_mm: noisy(q.x, 0.3),
            y_mm: noisy(q.y, 0.3),
            theta_deg: Some(noisy(q.theta.to_degrees(), 1.0)),
        };
        obs.push(Observation { line: k + 2, part, start, measured });
    }
    let fit = calibrate::fit(&cal, &plate, mode, &obs, 1.0).unwrap();
    eprintln!("poses ±0.3 mm, ±1°: {} mm/s, rms {:?} mm", fit.speed_mm_s, fit.rms_pose_mm);
    assert_eq!(fit.method, "1-D search");
    assert!((fit.speed_mm_s / TRUE_SPEED - 1.0).abs() < 0.03, "{}", fit.speed_mm_s);
    // Mixed with the time observations: still μ.
    let (times, _) = time_observations(0.02, 5);
    let all: Vec<Observation> = obs.iter().cloned().chain(times).collect();
    let fit = calibrate::fit(&cal, &plate, mode, &all, 1.0).unwrap();
    assert!((fit.speed_mm_s / TRUE_SPEED - 1.0).abs() < 0.03, "{}", fit.speed_mm_s);
    assert!(fit.rms_time_s.is_some() && fit.rms_pose_mm.is_some());
}

#[test]
fn observations_that_do_not_move_are_refused() {
    let (plate, mode, parts) = setup();
    let field = FieldModel::new(&plate.modes[mode], &plate);
    let cal: Vec<CalPart> = parts.iter().map(CalPart::new).collect();
    // Start where the part comes to rest: nothing depends on μ.
    let body = Body::new(&parts[0]);
    let p = SimParams { speed: 10.0, t_limit: 1e9, run_to_limit: false, rim: None };
    let rest = chladni_core::motion::integrate::run(
        &body,
        &field,
        p,
        Pose { x: 80.0, y: 100.0, theta: 0.5 },
    )
    .pose;
    let still = [
        Observation { line: 2, part: 0, start: rest, measured: Measured::TimeToNode { t_s: 3.0 } },
        Observation {
            line: 3,
            part: 0,
            start: rest,
            measured: Measured::PoseAfter { t_s: 5.0, x_mm: rest.x, y_mm: rest.y, theta_deg: None },
        },
    ];
    let e = calibrate::fit(&cal, &plate, mode, &still, 1.0).unwrap_err();
    assert!(matches!(e, FitError::Undetermined(_)), "{e}");
    // A pose observed long after the part came to rest does not fix μ either.
    let start = Pose { x: 60.0, y: 100.0, theta: 0.5 };
    let end = chladni_core::motion::integrate::run(&body, &field, p, start).pose;
    let late = [Observation {
        line: 2,
        part: 0,
        start,
        measured: Measured::PoseAfter { t_s: 1e4, x_mm: end.x, y_mm: end.y, theta_deg: None },
    }];
    let e = calibrate::fit(&cal, &plate, mode, &late, 1.0).unwrap_err();
    assert!(matches!(e, FitError::Undetermined(_) | FitError::AtBound { .. }), "{e}");
    assert!(matches!(calibrate::fit(&cal, &plate, mode, &[], 1.0), Err(FitError::Empty)));
}

#[test]
fn cli_fits_writes_the_plate_file_and_refuses_bad_csv() {
    let plate_path = tmp_dir("cal").join("plate.toml");
    let original =
        std::fs::read_to_string(examples::root().join("examples/plates/four-lines.toml")).unwrap();
    std::fs::write(&plate_path, &original).unwrap();
    std::fs::copy(
        examples::root().join("examples/parts/triangle.json"),
        tmp_dir("cal").join("triangle.json"),
    )
    .unwrap();
    let (obs, times) = time_observations(0.03, 8);
    let mut csv =
        String::from("part,x_mm,y_mm,theta_deg,t_s,end_x_mm,end_y_mm,end_theta_deg\n# stopwatch\n");
    let names = ["triangle.json", "plate with hole"];
    for (o, t) in obs.iter().zip(&times) {
        let s = o.start;
        csv += &format!("{},{},{},{},{t}\n", names[o.part], s.x, s.y, s.theta.to_degrees());
    }
    let csv_path = tmp_dir("cal").join("obs.csv");
    std::fs::write(&csv_path, &csv).unwrap();
    let hole = examples::root().join("examples/parts/plate-with-hole.json");
    let run = |csv: &PathBuf, extra: &[&str]| {
        let mut args = vec![
            "plate",
            "calibrate-speed",
            plate_path.to_str().unwrap(),
            "--mode",
            "vertical",
            "--observations",
            csv.to_str().unwrap(),
            "--part",
            hole.to_str().unwrap(),
            "--json",
        ];
        args.extend_from_slice(extra);
        chladni(&args)
    };
    let out = run(&csv_path, &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let mu = v["speed_mm_s"].as_f64().unwrap();
    eprintln!("CLI: {mu} mm/s, rms {} s", v["rms_time_s"]);
    assert!((mu / TRUE_SPEED - 1.0).abs() < 0.03, "{v}");
    assert_eq!(v["previous_speed_mm_s"], 10.0);
    assert_eq!(v["residuals"].as_array().unwrap().len(), obs.len());
    // The file: the vertical mode's speed set, everything else as it was.
    let now = std::fs::read_to_string(&plate_path).unwrap();
    let edited = PlateModel::parse(&now, "p").unwrap();
    assert_eq!(edited.modes[0].speed_mm_s, mu);
    assert_eq!(edited.modes[2].speed_mm_s, 15.0);
    let added = format!(
        "node = {{ kind = \"line\", angle_deg = 90.0, offset_mm = 0.0 }}\nspeed_mm_s = {mu}\n"
    );
    let want = original.replacen(
        "node = { kind = \"line\", angle_deg = 90.0, offset_mm = 0.0 }\n",
        &added,
        1,
    );
    assert_eq!(now, want);
    // --dry-run leaves it.
    std::fs::write(&plate_path, &original).unwrap();
    let out = run(&csv_path, &["--dry-run"]);
    assert!(out.status.success());
    assert_eq!(std::fs::read_to_string(&plate_path).unwrap(), original);
    // Bad CSV: exit 2, line and column named, JSON error object.
    let bad = tmp_dir("cal").join("bad.csv");
    std::fs::write(&bad, csv.replacen(",", ",x", 3).replace(&format!("{}", times[0]), "soon"))
        .unwrap();
    let out = run(&bad, &[]);
    assert_eq!(out.status.code(), Some(2));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["error"], "bad_input");
    let msg = v["message"].as_str().unwrap();
    assert!(msg.contains("line 1, column 2: header `xx_mm`"), "{msg}");
    std::fs::write(&bad, csv.replace(&format!("{}\n", times[1]), "soon\n")).unwrap();
    let out = run(&bad, &[]);
    let msg = String::from_utf8_lossy(&out.stderr);
    assert!(msg.contains("line 4, column 5 (t_s): `soon` is not a number"), "{msg}");
    assert_eq!(std::fs::read_to_string(&plate_path).unwrap(), original);
    let out = chladni(&[
        "plate",
        "calibrate-speed",
        plate_path.to_str().unwrap(),
        "--mode",
        "nope",
        "--observations",
        csv_path.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("\"vertical\""));
}
