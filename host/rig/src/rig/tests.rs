//! The rig's physics against the motion model, on statuses as the controller reports them.

use super::*;
use crate::truth::Warp;
use chladni_core::model::plate_file::PlateFile;
use chladni_core::motion::integrate::{SimParams, run};
use chladni_media::vision::synth::pose_error;
use chladni_media::vision::{Template, locate};
use chladni_shared::icd::link::{DriveState, RunNumber};
use chladni_shared::icd::units::Q15;

/// A vertical node at x = 150 (60 Hz, amplitude 0.8) and a horizontal one at y = 120 (100 Hz,
/// faster), on a walled 300 × 200 mm plate.
const PLATE: &str = "[plate]\nname = \"t\"\nsize_mm = [300.0, 200.0]\n\
    [[mode]]\nname = \"vertical\"\nfreq_hz = 60.0\namplitude = 0.8\n\
    node = { kind = \"line\", angle_deg = 90.0 }\n\
    [[mode]]\nname = \"horizontal\"\nfreq_hz = 100.0\nspeed_mm_s = 15.0\n\
    node = { kind = \"line\", angle_deg = 0.0, offset_mm = 20.0 }\n";

fn plate() -> TruePlate {
    let file = PlateFile::parse(PLATE, "t").unwrap();
    TruePlate::from_file(file.clone(), &file).unwrap()
}

fn triangle() -> Part {
    Part::new("triangle".into(), vec![[0.0, 0.0], [30.0, 0.0], [8.0, 20.0]], vec![]).unwrap()
}

fn ell() -> Part {
    let outline =
        vec![[0.0, 0.0], [40.0, 0.0], [40.0, 12.0], [12.0, 12.0], [12.0, 30.0], [0.0, 30.0]];
    Part::new("ell".into(), outline, vec![]).unwrap()
}

fn rig(at: Vec<Pose>, noise: Noise, seed: u64) -> Rig {
    let kinds = vec![triangle(), ell()];
    let parts = (0..at.len()).map(|i| i % 2).collect();
    Rig::new(RigConfig { plate: plate(), kinds, parts, at: Some(at), seed, noise }).unwrap()
}

const QUIET: Noise = Noise { mm: 0.0, deg: 0.0 };

/// The statuses of a manual drive at `freq_mhz` and `amp` (Q15) started at sample 50 000 and
/// stopped after `drive` samples, polled every `every` samples until `end`.
fn polls(freq_mhz: u32, amp: u16, drive: u64, every: u64, end: u64) -> Vec<StatusReport> {
    let start = 50_000;
    (0..)
        .map(|k| start - 7 * every / 3 + k * every)
        .take_while(|&c| c <= end)
        .map(|clock| {
            let on = clock.saturating_sub(start).min(drive);
            let (state, run, freq_mhz, amplitude_q15) = if clock < start {
                (DriveState::Idle, 0, 0, 0)
            } else if on < drive {
                (DriveState::Running, 1, freq_mhz, amp)
            } else {
                (DriveState::Idle, 2, 0, 0)
            };
            StatusReport {
                state,
                run: RunNumber(run),
                clock,
                elapsed_samples: on,
                sample_rate: 50_000,
                freq_mhz,
                amplitude_q15,
                ..StatusReport::IDLE
            }
        })
        .collect()
}

fn follow(rig: &mut Rig, polls: &[StatusReport]) -> f64 {
    polls.windows(2).map(|w| rig.step(&w[0], &w[1]).iter().map(|s| s.seconds).sum::<f64>()).sum()
}

#[test]
fn a_part_driven_at_a_modes_frequency_ends_where_integrate_run_puts_it() {
    let start = Pose { x: 90.0, y: 70.0, theta: 0.4 };
    let amp = Q15::from_fraction(0.8).unwrap();
    for (every, seconds) in [(1000, 2.0), (733, 1.3)] {
        let mut rig = rig(vec![start], QUIET, 1);
        let drive = (seconds * 50_000.0) as u64;
        let driven =
            follow(&mut rig, &polls(60_000, amp.0, drive, every, 50_000 + drive + 5 * every));
        assert!((driven - seconds).abs() < 1e-12, "{driven}");
        let p = rig.plate().model.clone();
        let ratio = amp.to_fraction() / 0.8;
        let params = SimParams {
            speed: p.modes[0].speed_mm_s * ratio * ratio,
            t_limit: seconds,
            run_to_limit: true,
            rim: Some(Rim::of(&p)),
        };
        let want =
            run(&Body::new(&triangle()), &FieldModel::new(&p.modes[0], &p), params, start).pose;
        let got = rig.poses()[0];
        let d = (got.x - want.x).hypot(got.y - want.y);
        eprintln!("every {every}: {got:?} against {want:?}: {d:.2e} mm");
        assert!(d < 0.02 && (got.theta - want.theta).abs() < 1e-3, "{got:?} {want:?}");
        // It moved towards the node at x = 150, and far.
        assert!(want.x - start.x > 5.0 && (got.y - start.y).abs() < 1e-6);
        assert!((rig.truth().drive_s - seconds).abs() < 1e-12);
    }
}

#[test]
fn parts_apart_move_each_as_alone_and_parts_that_meet_push_each_other() {
    // Apart: each where integrate::run puts it alone.
    let start =
        vec![Pose { x: 90.0, y: 70.0, theta: 0.4 }, Pose { x: 220.0, y: 140.0, theta: 2.0 }];
    let mut r = rig(start.clone(), QUIET, 1);
    follow(&mut r, &polls(100_000, Q15::FULL.0, 75_000, 1000, 140_000));
    let p = r.plate().model.clone();
    let params =
        SimParams { speed: 15.0, t_limit: 1.5, run_to_limit: true, rim: Some(Rim::of(&p)) };
    let field = FieldModel::new(&p.modes[1], &p);
    for (i, part) in [triangle(), ell()].iter().enumerate() {
        let want = run(&Body::new(part), &field, params, start[i]).pose;
        let got = r.poses()[i];
        assert!((got.x - want.x).hypot(got.y - want.y) < 0.02, "{got:?} {want:?}");
        // Towards the node at y = 100 + 20.
        assert!((want.y - 120.0).abs() < (start[i].y - 120.0).abs() - 5.0, "{want:?}");
    }
    // Two parts on either side of the node, in line: they meet there and hold each other off.
    let start =
        vec![Pose { x: 150.0, y: 80.0, theta: 0.0 }, Pose { x: 152.0, y: 160.0, theta: 0.0 }];
    let mut r = rig(start, QUIET, 1);
    follow(&mut r, &polls(100_000, Q15::FULL.0, 250_000, 1000, 320_000));
    let q = r.poses();
    let meet = shape::contacts(&r.pieces[0], q[0], &r.pieces[1], q[1], 0.5);
    assert!(!meet.is_empty(), "{q:?}");
    assert!(shape::overlap(&r.pieces[0], q[0], &r.pieces[1], q[1]) < 0.01, "{q:?}");
    assert!(q[0].y > 95.0 && q[1].y < 145.0, "{q:?}");
}

#[test]
fn idle_time_moves_nothing_even_with_noise() {
    let start =
        vec![Pose { x: 90.0, y: 70.0, theta: 0.4 }, Pose { x: 220.0, y: 140.0, theta: 2.0 }];
    let mut r = rig(start.clone(), DEFAULT_NOISE, 3);
    // Driven for 0 samples: polls at idle only (a stop at the first sample).
    let driven = follow(&mut r, &polls(60_000, Q15::FULL.0, 0, 1000, 500_000));
    assert_eq!(driven, 0.0);
    assert_eq!(r.poses(), start.as_slice());
}

#[test]
fn an_unknown_frequency_moves_parts_only_by_the_noise() {
    let start = Pose { x: 90.0, y: 70.0, theta: 0.4 };
    // 75 Hz is no mode (60 Hz ± 0.5 Hz, 100 Hz ± 0.5 Hz): quiet, nothing moves.
    let mut quiet = rig(vec![start], QUIET, 1);
    let driven = follow(&mut quiet, &polls(75_000, Q15::FULL.0, 100_000, 1000, 200_000));
    assert!((driven - 2.0).abs() < 1e-12);
    assert_eq!(quiet.poses(), [start]);
    assert_eq!(quiet.truth().drive_s, 0.0);
    // With noise: a random walk of σ = 0.15 mm·√2 per axis and 0.5°·√2 over 2 s, over seeds.
    let (mut sxx, mut sth) = (0.0, 0.0);
    let n = 200;
    for seed in 0..n {
        let mut noisy = rig(vec![start], DEFAULT_NOISE, seed);
        follow(&mut noisy, &polls(75_000, Q15::FULL.0, 100_000, 1000, 200_000));
        let q = noisy.poses()[0];
        sxx += (q.x - start.x).powi(2) + (q.y - start.y).powi(2);
        sth += (q.theta - start.theta).to_degrees().powi(2);
    }
    let (rms_mm, rms_deg) = ((sxx / (2 * n) as f64).sqrt(), (sth / n as f64).sqrt());
    let (want_mm, want_deg) = (0.15 * 2f64.sqrt(), 0.5 * 2f64.sqrt());
    assert!((rms_mm / want_mm - 1.0).abs() < 0.15, "{rms_mm} mm against {want_mm}");
    assert!((rms_deg / want_deg - 1.0).abs() < 0.15, "{rms_deg}° against {want_deg}");
}

#[test]
fn a_mode_is_driven_within_half_a_percent_or_half_a_hertz() {
    let r = rig(vec![Pose { x: 90.0, y: 70.0, theta: 0.0 }], QUIET, 1);
    assert_eq!(r.mode_at(60.0), Some(0));
    assert_eq!(r.mode_at(60.49), Some(0));
    assert_eq!(r.mode_at(59.4), None);
    assert_eq!(r.mode_at(100.5), Some(1));
    assert_eq!(r.mode_at(80.0), None);
}

#[test]
fn random_drops_are_reproducible_and_apart_and_bad_start_poses_are_named() {
    let config = |at, seed| RigConfig {
        plate: plate(),
        kinds: vec![triangle(), ell()],
        parts: vec![0, 1, 0, 1, 0, 1],
        at,
        seed,
        noise: QUIET,
    };
    let a = Rig::new(config(None, 4)).unwrap();
    assert_eq!(a.poses(), Rig::new(config(None, 4)).unwrap().poses());
    assert_ne!(a.poses(), Rig::new(config(None, 5)).unwrap().poses());
    for i in 0..6 {
        for j in 0..i {
            assert_eq!(shape::overlap(&a.pieces[i], a.poses[i], &a.pieces[j], a.poses[j]), 0.0);
        }
    }
    let q = |x, y| Pose { x, y, theta: 0.0 };
    let e = Rig::new(config(Some(vec![q(50.0, 50.0)]), 1)).unwrap_err();
    assert!(e.to_string().contains("--at gives 1 poses for 6 parts"), "{e}");
    let two = |at| RigConfig { parts: vec![0, 1], ..config(Some(at), 1) };
    let e = Rig::new(two(vec![q(50.0, 50.0), q(55.0, 52.0)])).unwrap_err();
    assert!(e.to_string().contains("parts 1 and 2: the parts overlap"), "{e}");
    let e = Rig::new(two(vec![q(50.0, 50.0), q(295.0, 100.0)])).unwrap_err();
    assert!(e.to_string().contains("part 2 (295, 100, 0°): the part reaches over"), "{e}");
    let e = Rig::new(RigConfig { parts: vec![], ..config(None, 1) }).unwrap_err();
    assert!(matches!(e, RigError::NoParts), "{e}");
    let e = Rig::new(RigConfig { parts: vec![0, 2], ..config(None, 1) }).unwrap_err();
    assert!(e.to_string().contains("part 2 is of kind 2, but only 2 kinds"), "{e}");
}

#[test]
fn a_warped_plate_moves_parts_by_its_own_speed() {
    let given = PlateFile::parse(PLATE, "t").unwrap();
    let warp = Warp { shift_mm: [0.0, 0.0], speed_factor: [2.0, 2.0] };
    let fast = TruePlate::warped(&given, &warp, 1).unwrap();
    let kinds = vec![triangle()];
    let at = Some(vec![Pose { x: 90.0, y: 70.0, theta: 0.4 }]);
    let config = |plate| RigConfig {
        plate,
        kinds: kinds.clone(),
        parts: vec![0],
        at: at.clone(),
        seed: 1,
        noise: QUIET,
    };
    let (mut slow, mut fast) =
        (Rig::new(config(plate())).unwrap(), Rig::new(config(fast)).unwrap());
    // 1 s on the fast plate is 2 s on the given one (μ scales time only).
    follow(&mut fast, &polls(60_000, Q15::FULL.0, 50_000, 1000, 120_000));
    follow(&mut slow, &polls(60_000, Q15::FULL.0, 100_000, 1000, 170_000));
    let (a, b) = (fast.poses()[0], slow.poses()[0]);
    assert!((a.x - b.x).hypot(a.y - b.y) < 0.02, "{a:?} {b:?}");
}

#[test]
fn a_frame_shows_the_parts_where_the_truth_says() {
    let at = vec![Pose { x: 90.0, y: 70.0, theta: 0.4 }, Pose { x: 220.0, y: 140.0, theta: 2.0 }];
    let r = rig(at, QUIET, 1);
    let camera = r.camera();
    let img = camera.photo(r.placed(), 11);
    let templates: Vec<Template> = camera.kinds.iter().map(Template::new).collect();
    let (report, _) = locate(&img, &templates, camera.size_mm, None).unwrap();
    assert_eq!(report.parts.len(), 2, "{:?}", report.parts);
    for p in r.placed() {
        let (d, a) = pose_error(&templates, &report.parts, &p).unwrap();
        assert!(d < 0.5 && a < 1.0, "{p:?}: {d} mm {a}°");
    }
    // Frames differ in their noise, not in what they show.
    let (a, b) = (r.render(1, Format::Png).unwrap(), r.render(2, Format::Png).unwrap());
    assert_ne!(a, b);
    assert!(a.starts_with(b"\x89PNG"));
    assert!(r.render(1, Format::Jpeg).unwrap().starts_with(&[0xff, 0xd8]));
}

#[test]
fn a_shifted_mode_moves_parts_as_the_unshifted_one_moves_them_shifted() {
    let file = PlateFile::parse(PLATE, "t").unwrap();
    let mut moved = file.clone();
    moved.mode[0].shift_mm = Some([6.0, -3.0]);
    let moved = TruePlate::from_file(moved, &file).unwrap();
    let start = Pose { x: 90.0, y: 70.0, theta: 0.4 };
    let config = |plate, at: Pose| RigConfig {
        plate,
        kinds: vec![triangle()],
        parts: vec![0],
        at: Some(vec![at]),
        seed: 1,
        noise: QUIET,
    };
    let mut a = Rig::new(config(plate(), start)).unwrap();
    let mut b = Rig::new(config(moved, Pose { x: 96.0, y: 67.0, ..start })).unwrap();
    for r in [&mut a, &mut b] {
        follow(r, &polls(60_000, Q15::FULL.0, 400_000, 1000, 460_000));
    }
    let (p, q) = (a.poses()[0], b.poses()[0]);
    assert!(p.x > 140.0, "it reached the node: {p:?}");
    assert!((q.x - p.x - 6.0).abs() < 0.02 && (q.y - p.y + 3.0).abs() < 1e-9, "{p:?} {q:?}");
    assert_eq!(b.truth().modes[0].shift_mm, [6.0, -3.0]);
}

#[test]
fn a_pick_removes_the_part_nearest_within_the_radius_and_nothing_elsewhere() {
    let q = |x, y| Pose { x, y, theta: 0.0 };
    let mut r = rig(vec![q(60.0, 50.0), q(100.0, 60.0), q(220.0, 150.0)], QUIET, 1);
    assert_eq!(r.pick(160.0, 100.0, 20.0), None, "no centroid within 20 mm");
    assert_eq!(r.truth().parts.len(), 3);
    // Both of the first two within 40 mm of (80, 55): the nearer, the ell at (100, 60), goes.
    let picked = r.pick(85.0, 57.0, 40.0).unwrap();
    assert_eq!((picked.part.as_str(), picked.x_mm, picked.y_mm), ("ell", 100.0, 60.0));
    let t = r.truth();
    let left: Vec<(&str, f64)> = t.parts.iter().map(|p| (p.part.as_str(), p.x_mm)).collect();
    assert_eq!(left, [("triangle", 60.0), ("triangle", 220.0)]);
    assert_eq!(r.placed().len(), 2);
    // The rest still move as driven: the vertical node at x = 150 pulls both towards it.
    let before = r.poses().to_vec();
    follow(&mut r, &polls(60_000, Q15::from_fraction(0.8).unwrap().0, 100_000, 1_000, 160_000));
    let after = r.poses().to_vec();
    assert!((after[0].x - 150.0).abs() < (before[0].x - 150.0).abs() - 1.0, "{after:?}");
    assert!((after[1].x - 150.0).abs() < (before[1].x - 150.0).abs() - 1.0, "{after:?}");
    // A part exactly at the radius is picked; beyond it not.
    assert!(r.pick(after[0].x + 5.0, after[0].y, 5.0 - 1e-9).is_none());
    assert!(r.pick(after[0].x + 5.0, after[0].y, 5.0 + 1e-9).is_some());
    assert_eq!(r.truth().parts.len(), 1);
}
