//! `chladni plate learn` and `chladni steer` against the QEMU controller (one boot) and the
//! virtual rig (docs/steer.md, docs/rig.md): learning finds the true plate's node shifts and
//! speeds and predicts held-out bursts better than the given plate; a plan is made on the
//! learned plate; steering brings a part to a goal the true plate holds; a camera that fails
//! mid-run and Ctrl-C both end with the drive stopped and a named failure. At CI scale: the
//! free plate's 12 modes, 4 bursts per mode, one part steered; the full-size numbers (more
//! bursts, three and ten parts, 20 start/goal pairs) are the benches' (docs/evidence/steer.md).

use std::io::{BufRead, BufReader};
use std::process::Stdio;
use std::time::{Duration, Instant};

use chladni_core::model::plate::PlateModel;
use chladni_core::model::plate_file::PlateFile;
use chladni_core::model::pose::Pose;
use chladni_device::emulator::Emulator;
use chladni_shared::icd::link::DriveState;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use serde_json::Value;

use crate::support;
use support::cli::{chladni, command, ex, json, ok_json, tmp};
use support::rig::RigProcess;

/// How long the loops may take here (debug build, a loaded CI machine).
const LIMIT_S: &str = "600";
/// How long a frame may take (s): under a full machine's load QEMU and the rig's renders slow
/// down, and a frame after a burst took over 5 s, the command's default.
const CAMERA_S: &str = "30";

fn arg(p: &std::path::Path) -> String {
    p.display().to_string()
}

/// `chladni steer` of one triangle to `goal` on `rig`'s camera, with `more` arguments.
fn steer(
    port: &str,
    rig: &RigProcess,
    learned: &std::path::Path,
    tri: &str,
    goal: [&str; 3],
    more: &[&str],
) -> std::process::Output {
    let camera = format!("{}/frame.png", rig.url);
    let l = arg(learned);
    let args = ["steer", "--port", port, "--camera", &camera, "--plate", &l, "--part", tri];
    let wait = ["--camera-timeout-s", CAMERA_S, "--goal"];
    chladni(&[&args[..], &wait, &goal, more].concat())
}

/// The example 12-mode plate at 120 mm/s, the rig speed (a part crosses 100 mm in
/// 3–10 s), where the file says 20 mm/s: at 20 mm/s steering one part took 47–52 cycles of the
/// longest burst, 2.5 min of a debug CI run; at 120 mm/s 8–9 cycles (docs/evidence/steer.md).
fn fast_plate() -> String {
    let text = std::fs::read_to_string(ex("plates/free-12-modes.toml")).unwrap();
    let fast = text.replace("\nspeed_mm_s = 20.0\n", "\nspeed_mm_s = 120.0\n");
    assert_eq!(fast.matches("speed_mm_s = 120.0").count(), 12, "every mode at 120 mm/s");
    let path = tmp("steer", "given.toml");
    std::fs::write(&path, fast).unwrap();
    arg(&path)
}

/// The controller's drive is idle (stopped by whoever drove it).
fn drive_is_idle(emu: &Emulator) {
    let mut client = emu.connect("steer test").unwrap();
    let seen = support::emu::poll_until(&mut client, Duration::from_secs(10), |s| {
        s.state == DriveState::Idle
    });
    assert_eq!(seen.last().map(|s| s.state), Some(DriveState::Idle));
}

#[test]
fn learn_plan_steer_and_fail_on_the_virtual_rig() {
    let emu = support::emu::emulator_for("steer-loop", Duration::from_secs(1200));
    let port = emu.address();
    let (plate, tri) = (fast_plate(), ex("parts/triangle.json"));
    let true_file = tmp("steer", "true.toml");
    let learned = tmp("steer", "learned.toml");
    learns_the_true_plate(&port, &plate, &tri, &true_file, &learned);
    drive_is_idle(&emu);

    // A sensorless plan on the learned plate, as on any plate (the rectangle from a feed
    // strip along the left edge: on the free plate's modes no plan holds from everywhere).
    let (out, rect) = (arg(&tmp("steer", "plan.json")), ex("parts/rectangle.json"));
    let l = arg(&learned);
    let feed = ["--feed", "21", "21", "50", "179"];
    let planned = chladni(&[&["plan", &rect, "--plate", &l][..], &feed, &["--out", &out]].concat());
    assert!(planned.status.success(), "{}", String::from_utf8_lossy(&planned.stderr));

    steers_one_part(&port, &tri, &true_file, &learned);
    drive_is_idle(&emu);
    camera_failing_mid_run_stops_the_drive(&emu, &port, &tri, &learned);
    ctrl_c_stops_the_drive(&emu, &port, &tri, &learned);
}

/// Three triangles on a plate whose nodes lie 4–8 mm from the given ones, speeds ×0.4–×2.5:
/// `plate learn` finds the modes' shifts within 2 mm (median; a mode whose nodes run along the
/// shift barely shows it) and every speed within 30 %, and predicts its held-out bursts better
/// on the learned plate than on the given one.
fn learns_the_true_plate(
    port: &str,
    plate: &str,
    tri: &str,
    true_file: &std::path::Path,
    learned: &std::path::Path,
) {
    let t = arg(true_file);
    let rig = RigProcess::start(&[
        "--port",
        port,
        "--plate",
        plate,
        "--part",
        tri,
        "--count",
        "3",
        "--seed",
        "4",
        "--at",
        "90,60,10",
        "--at",
        "200,70,100",
        "--at",
        "150,150,200",
        "--warp-mm",
        "4..8",
        "--speed-factor",
        "0.5..2",
        "--write-true-plate",
        &t,
    ]);
    let camera = format!("{}/frame.png", rig.url);
    let l = arg(learned);
    let out = chladni(&[
        "plate",
        "learn",
        "--port",
        port,
        "--camera",
        &camera,
        "--plate",
        plate,
        "--part",
        tri,
        "--part",
        tri,
        "--part",
        tri,
        "--bursts-per-mode",
        "4",
        "--out",
        &l,
        "--json",
        "--time-limit-s",
        LIMIT_S,
        "--camera-timeout-s",
        CAMERA_S,
    ]);
    let v = ok_json(&out);
    eprintln!("learn: {v}");
    assert_eq!(v["timed_out"], false, "{v}");
    let (truth, got) = (PlateModel::load(true_file).unwrap(), PlateModel::load(learned).unwrap());
    let given = PlateModel::load(std::path::Path::new(plate)).unwrap();
    let mut shift_off = Vec::new();
    for ((t, g), m) in truth.modes.iter().zip(&got.modes).zip(&given.modes) {
        let off = (t.shift_mm[0] - g.shift_mm[0]).hypot(t.shift_mm[1] - g.shift_mm[1]);
        let ratio = g.speed_mm_s / t.speed_mm_s;
        eprintln!("{}: shift off by {off:.2} mm, speed ×{ratio:.3} of the truth", m.name);
        assert!((ratio - 1.0).abs() < 0.3, "{}: speed ×{ratio} of the truth", m.name);
        shift_off.push(off);
    }
    shift_off.sort_by(f64::total_cmp);
    assert!(shift_off[shift_off.len() / 2] < 2.0, "shifts off by {shift_off:?} mm");
    let (before, after): (f64, f64) = v["modes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| (m["before_mm"].as_f64().unwrap(), m["after_mm"].as_f64().unwrap()))
        .fold((0.0, 0.0), |a, m| (a.0 + m.0, a.1 + m.1));
    assert!(after < 0.5 * before, "held-out error {after} mm after, {before} mm before");
    let file = PlateFile::load(learned).unwrap();
    assert_eq!(file.learned.map(|l| l.mode.len()), Some(12));
}

/// One triangle across the plate to a goal pose, within 2 mm and 3°.
fn steers_one_part(port: &str, tri: &str, true_file: &std::path::Path, learned: &std::path::Path) {
    let goal = Pose { x: 200.0, y: 120.0, theta: 30f64.to_radians() };
    let rig = RigProcess::start(&[
        "--port",
        port,
        "--true-plate",
        &arg(true_file),
        "--plate",
        &arg(learned),
        "--part",
        tri,
        "--at",
        "90,150,40",
    ]);
    let log = tmp("steer", "one.jsonl");
    let (gx, gy, gt) = (
        format!("{:.3}", goal.x),
        format!("{:.3}", goal.y),
        format!("{:.3}", goal.theta.to_degrees()),
    );
    let more = ["--json", "--log", &arg(&log), "--time-limit-s", LIMIT_S];
    let out = steer(port, &rig, learned, tri, [&gx, &gy, &gt], &more);
    let v = json(&out);
    eprintln!("steer: {v}");
    assert_eq!((out.status.code(), &v["reached"]), (Some(0), &Value::Bool(true)), "{v}");
    let p = &v["parts"][0];
    assert!(p["error_mm"].as_f64().unwrap() <= 2.0 && p["error_deg"].as_f64().unwrap() <= 3.0);
    let lines = std::fs::read_to_string(&log).unwrap();
    let cycles = v["cycles"].as_u64().unwrap() as usize;
    assert_eq!(lines.lines().count(), cycles + 1, "one line per cycle and one for the end");
    let first: Value = serde_json::from_str(lines.lines().next().unwrap()).unwrap();
    assert!(first["command"]["driven_s"].as_f64().unwrap() > 0.0, "{first}");
}

/// A camera that starts sending garbage after 3 frames: the loop ends, named, drive idle.
fn camera_failing_mid_run_stops_the_drive(
    emu: &Emulator,
    port: &str,
    tri: &str,
    learned: &std::path::Path,
) {
    let rig = RigProcess::start(&[
        "--port",
        port,
        "--plate",
        &arg(learned),
        "--part",
        tri,
        "--at",
        "90,150,40",
        "--fail-after-frames",
        "3",
        "--fail-mode",
        "garbage",
    ]);
    let out = steer(port, &rig, learned, tri, ["220", "50", "0"], &["--json"]);
    let v = json(&out);
    assert_eq!((out.status.code(), v["error"].as_str()), (Some(1), Some("not_an_image")), "{v}");
    assert!(v["message"].as_str().unwrap().contains("the drive was stopped"), "{v}");
    drive_is_idle(emu);
}

/// Ctrl-C in the middle of steering: exit 130, named, the drive idle.
fn ctrl_c_stops_the_drive(emu: &Emulator, port: &str, tri: &str, learned: &std::path::Path) {
    let rig = RigProcess::start(&["--port", port, "--plate", &arg(learned), "--part", tri]);
    let log = tmp("steer", "interrupted.jsonl");
    let mut child = command()
        .args(["steer", "--port", port, "--camera", &format!("{}/frame.png", rig.url)])
        .args(["--plate", &arg(learned), "--part", tri, "--goal", "220", "50", "0", "--json"])
        .args(["--log", &arg(&log)])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Wait for the first cycle's line: steering has started.
    let started = Instant::now();
    while std::fs::read_to_string(&log).map_or(true, |t| t.lines().count() < 1) {
        assert!(started.elapsed() < Duration::from_secs(120), "no cycle logged");
        std::thread::sleep(Duration::from_millis(50));
    }
    kill(Pid::from_raw(child.id() as i32), Signal::SIGINT).unwrap();
    let status = child.wait().unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
    let v: Value = serde_json::from_str(&line).unwrap();
    assert_eq!((status.code(), v["error"].as_str()), (Some(130), Some("interrupted")), "{v}");
    drive_is_idle(emu);
}
