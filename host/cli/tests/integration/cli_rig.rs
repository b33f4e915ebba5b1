//! `chladni rig` against the QEMU controller (one boot): the rig follows the drive as a second
//! client (the parts move by the model for the drive time the controller's clock says, towards
//! the mode's node), its frames show the parts where `/truth` says (located within 0.5 mm and
//! 1°), each failure mode fails as named, Ctrl-C ends it with 0 and a lost link with 1.

use std::time::{Duration, SystemTime};

use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::contact::Rim;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::integrate::{SimParams, run};
use chladni_media::vision::synth::{Placed, pose_error};
use chladni_media::vision::{Template, locate};
use chladni_shared::drive::runner::{MANUAL_RAMP_MS, STOP_RAMP_MS};
use chladni_shared::icd::link::DriveState;
use chladni_shared::icd::plan::Level;
use chladni_shared::icd::units::Q15;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use serde_json::Value;

use crate::support;
use support::cli::{ex, keys, tmp};
use support::rig::{RigProcess, get, post};

/// Start poses of the triangle and the L-shape: apart, on either side of the vertical node at
/// x = 150 of the four-lines plate (its 60 Hz mode, amplitude 0.8).
const AT: [&str; 2] = ["100,60,20", "215,140,80"];

/// The drive time the manual drive's ramps (up and down, linear in amplitude) take off a run at
/// full amplitude, the speed going with the amplitude's square: 2/3 of their length.
const RAMPS_S: f64 = (MANUAL_RAMP_MS + STOP_RAMP_MS) as f64 / 1000.0 * 2.0 / 3.0;

/// The rig of these tests: the triangle and the L-shape at [`AT`] on the four-lines plate,
/// no bouncing noise, and `more`.
fn start(port: &str, more: &[&str]) -> RigProcess {
    let (plate, tri, ell) =
        (ex("plates/four-lines.toml"), ex("parts/triangle.json"), ex("parts/l-shape.json"));
    let mut args = vec!["--port", port, "--plate", &plate, "--part", &tri, "--part", &ell];
    args.extend(["--at", AT[0], "--at", AT[1], "--noise-mm", "0", "--noise-deg", "0"]);
    args.extend(more);
    RigProcess::start(&args)
}

const PATIENT: Duration = Duration::from_secs(120);

fn truth(rig: &RigProcess) -> Value {
    let a = get(&format!("{}/truth", rig.url), PATIENT).expect("an answer to /truth");
    assert_eq!(a.status, 200, "{}", String::from_utf8_lossy(&a.body));
    serde_json::from_slice(&a.body).unwrap()
}

fn unix_now() -> f64 {
    SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).unwrap().as_secs_f64()
}

fn parts() -> Vec<Part> {
    ["parts/triangle.json", "parts/l-shape.json"]
        .iter()
        .map(|p| Part::load(std::path::Path::new(&ex(p))).unwrap())
        .collect()
}

/// A frame of the state after the request: its time is after the request was sent, and the
/// parts located in it lie where `/truth` says, within 0.5 mm and 1°.
fn frame_matches_truth(rig: &RigProcess, size_mm: [f64; 2]) {
    let sent = unix_now();
    let a = get(&format!("{}/frame.png", rig.url), PATIENT).expect("a frame");
    let received = unix_now();
    assert_eq!((a.status, a.header("content-type")), (200, Some("image/png")));
    let time: f64 = a.header("x-frame-time").unwrap().parse().unwrap();
    assert!(sent <= time && time <= received, "{sent} {time} {received}");
    let t = truth(rig);
    let img = image::load_from_memory(&a.body).unwrap().to_luma8();
    let templates: Vec<Template> = parts().iter().map(Template::new).collect();
    let (report, _) = locate(&img, &templates, size_mm, None).unwrap();
    assert_eq!(report.parts.len(), 2, "{:?}", report.parts);
    for (k, p) in t["parts"].as_array().unwrap().iter().enumerate() {
        let f = |key: &str| p[key].as_f64().unwrap();
        let placed = Placed {
            part: k,
            c: [f("x_mm"), f("y_mm")],
            theta_deg: f("theta_deg"),
            flipped: false,
        };
        let (d, deg) = pose_error(&templates, &report.parts, &placed).expect("the part is found");
        eprintln!("part {k}: located within {d:.3} mm, {deg:.3}°");
        assert!(d < 0.5 && deg < 1.0, "{placed:?}: {d} mm {deg}° {:?}", report.parts);
    }
}

/// The pose the motion model gives a part driven `seconds` under `mode` of the true plate.
fn model(plate: &PlateModel, mode: usize, part: &Part, start: Pose, seconds: f64) -> Pose {
    let m = &plate.modes[mode];
    let ratio = Q15::from_fraction(0.8).unwrap().to_fraction() / m.amplitude;
    let p = SimParams {
        speed: m.speed_mm_s * ratio * ratio,
        t_limit: seconds,
        run_to_limit: true,
        rim: Some(Rim::of(plate)),
    };
    run(&Body::new(part), &FieldModel::new(m, plate), p, start).pose
}

fn start_pose(at: &str) -> Pose {
    let v: Vec<f64> = at.split(',').map(|v| v.parse().unwrap()).collect();
    Pose { x: v[0], y: v[1], theta: v[2].to_radians() }
}

#[test]
fn the_rig_moves_parts_as_the_controller_drives_and_fails_as_asked() {
    let mut emu = support::emu::emulator("cli-rig");
    let port = emu.address();
    let written = tmp("rig", "true.toml");
    let w = written.display().to_string();
    let more = ["--speed-factor", "1.5", "--seed", "3", "--write-true-plate", &w];
    let rig = start(&port, &more);
    assert_eq!(keys(&rig.listening), ["parts", "true_plate", "url"]);
    assert_eq!(rig.listening["parts"], 2);
    let modes = rig.listening["true_plate"]["modes"].as_array().unwrap();
    assert_eq!(modes.len(), 4);
    assert!(modes.iter().all(|m| m["speed_factor"] == 1.5), "{modes:?}");
    let plate = PlateModel::load(&written).unwrap();
    assert_eq!(plate.modes[0].speed_mm_s, 15.0, "10 mm/s × 1.5");
    // The true node moved 4–8 mm (the default warp) from x = 150.
    let node_x = 150.0 + plate.modes[0].shift_mm[0];
    let shift = plate.modes[0].shift_mm[0].hypot(plate.modes[0].shift_mm[1]);
    assert!((4.0 - 1e-3..=8.0 + 1e-3).contains(&shift), "{:?}", plate.modes[0]);
    frame_matches_truth(&rig, plate.size_mm);

    // 1 s of drive at the vertical node's 60 Hz and its amplitude, then a stop.
    let mut client = emu.connect("rig test").unwrap();
    let amp = Q15::from_fraction(0.8).unwrap();
    let run = client.drive(60_000, Level::Drive(amp.0)).unwrap();
    support::emu::poll_until(&mut client, PATIENT, |s| s.run == run && s.elapsed_samples >= 50_000);
    client.stop().unwrap();
    let seen = support::emu::poll_until(&mut client, PATIENT, |s| s.state == DriveState::Idle);
    let last = seen.last().unwrap();
    let seconds = last.elapsed_samples as f64 / f64::from(last.sample_rate);
    let t = truth(&rig);
    // The rig's time base is the controller's clock: every sample of the drive counted.
    assert!((t["drive_s"].as_f64().unwrap() - seconds).abs() < 1e-9, "{t} against {seconds} s");
    for (k, part) in parts().iter().enumerate() {
        let start = start_pose(AT[k]);
        let want = model(&plate, 0, part, start, seconds - RAMPS_S);
        let p = &t["parts"][k];
        let (x, y) = (p["x_mm"].as_f64().unwrap(), p["y_mm"].as_f64().unwrap());
        let d = (x - want.x).hypot(y - want.y);
        eprintln!(
            "part {k}: ({x:.3}, {y:.3}) against the model's ({:.3}, {:.3}): {d:.3} mm",
            want.x, want.y
        );
        // Within one poll (20 ms) of drive at 15 mm/s: the rig sees each ramp at two polls.
        assert!(d < 0.3, "part {k}: {p} against {want:?}");
        // Towards the true node, by more than 10 mm.
        assert!((want.x - node_x).abs() < (start.x - node_x).abs() - 10.0, "{want:?}");
    }
    frame_matches_truth(&rig, plate.size_mm);

    picks(&rig);

    fail_modes(&port);

    // Ctrl-C: exit 0.
    let _ = kill(Pid::from_raw(rig.child.id() as i32), Signal::SIGINT);
    let (code, out, err) = rig.wait();
    assert_eq!((code, out.as_str()), (Some(0), ""), "{err}");

    // The controller gone: exit 1, named.
    let rig = start(&port, &[]);
    emu.kill();
    let (code, out, err) = rig.wait();
    assert_eq!(code, Some(1), "{err}");
    let lost = format!("the controller link at {port} was lost");
    assert!(err.contains(&lost), "{err}");
    let failure: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(failure["error"], "failed");
    assert!(failure["message"].as_str().unwrap().contains(&lost), "{out}");
}

/// The robot: a pick at a part's centroid removes it after the pick time (2 s by default); one
/// where no part lies says so; bad bodies are named.
fn picks(rig: &RigProcess) {
    let url = format!("{}/pick", rig.url);
    let before = truth(rig);
    let first = &before["parts"][0];
    let (x, y) = (first["x_mm"].as_f64().unwrap(), first["y_mm"].as_f64().unwrap());
    let asked = std::time::Instant::now();
    let body = format!(r#"{{"x_mm": {}, "y_mm": {}, "radius_mm": 5}}"#, x + 2.0, y - 1.0);
    let a = post(&url, body.as_bytes(), PATIENT).expect("an answer to /pick");
    assert!(asked.elapsed() >= Duration::from_secs(2), "{:?}", asked.elapsed());
    assert_eq!(a.status, 200, "{}", String::from_utf8_lossy(&a.body));
    let picked: Value = serde_json::from_slice(&a.body).unwrap();
    assert_eq!(keys(&picked), ["pick_time_s", "picked"]);
    assert_eq!(
        (&picked["picked"]["part"], picked["pick_time_s"].as_f64()),
        (&first["part"], Some(2.0))
    );
    let after = truth(rig);
    assert_eq!(after["parts"].as_array().unwrap(), &before["parts"].as_array().unwrap()[1..]);
    // Where the picked part was, nothing is left to pick.
    let a = post(&url, body.as_bytes(), PATIENT).unwrap();
    assert_eq!(a.status, 404, "{}", String::from_utf8_lossy(&a.body));
    let e: Value = serde_json::from_slice(&a.body).unwrap();
    assert_eq!(e["error"], "no_part", "{e}");
    assert!(e["message"].as_str().unwrap().contains("within 5 mm of"), "{e}");
    for (bad, name, says) in [
        (r#"{"x_mm": 1, "y_mm": 2}"#, "bad_json", "radius_mm"),
        (r#"{"x_mm": 1, "y_mm": 2, "radius_mm": 5, "z_mm": 0}"#, "bad_json", "z_mm"),
        (r#"{"x_mm": 1, "y_mm": 2, "radius_mm": -5}"#, "bad_value", "radius_mm = -5"),
        ("not json", "bad_json", "x_mm"),
    ] {
        let a = post(&url, bad.as_bytes(), PATIENT).unwrap();
        let e: Value = serde_json::from_slice(&a.body).unwrap();
        assert_eq!((a.status, e["error"].as_str()), (400, Some(name)), "{bad}: {e}");
        assert!(e["message"].as_str().unwrap().contains(says), "{bad}: {e}");
    }
    let huge =
        format!(r#"{{"x_mm": 1, "y_mm": 2, "radius_mm": 5, "pad": "{}"}}"#, "x".repeat(4000));
    assert_eq!(post(&url, huge.as_bytes(), PATIENT).unwrap().status, 413);
    assert_eq!(get(&url, PATIENT).unwrap().status, 405, "GET /pick");
}

/// Each failure mode after one good frame.
fn fail_modes(port: &str) {
    for mode in ["garbage", "frozen", "status500", "hang"] {
        let rig = start(port, &["--fail-after-frames", "1", "--fail-mode", mode]);
        let frame = format!("{}/frame.png", rig.url);
        let first = get(&frame, PATIENT).expect("the first frame");
        assert_eq!(first.status, 200);
        assert!(image::load_from_memory(&first.body).is_ok());
        let wait = if mode == "hang" { Duration::from_secs(3) } else { PATIENT };
        let next = get(&frame, wait);
        match mode {
            "garbage" => {
                let a = next.unwrap();
                assert_eq!((a.status, a.header("content-type")), (200, Some("image/png")));
                assert!(image::load_from_memory(&a.body).is_err());
            }
            "frozen" => {
                for a in [next.unwrap(), get(&frame, PATIENT).unwrap()] {
                    assert_eq!(a.status, 200);
                    assert_eq!(a.body, first.body, "a frozen camera sends the same bytes");
                }
            }
            "status500" => assert_eq!(next.unwrap().status, 500),
            _ => assert!(next.is_none(), "a hanging camera answered"),
        }
        // The truth is still served.
        assert_eq!(truth(&rig)["parts"].as_array().unwrap().len(), 2, "{mode}");
    }
}
