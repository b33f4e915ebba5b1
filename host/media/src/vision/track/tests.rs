//! Tracked poses against the full locate's on synthetic photos of parts moved between frames.

use super::*;
use crate::vision::synth::{Photo, Placed, nudge, pose_error, random_poses, render, sample_parts};
use crate::vision::{Report, locate};
use chladni_core::plate::photo::synth::Rng;

const SIZE: [f64; 2] = [300.0, 200.0];

/// The full locate of `photo` (corners given).
fn full(photo: &Photo, t: &[Template]) -> Report {
    locate(&render(photo), t, photo.size_mm, Some(photo.corners)).unwrap().0
}

/// Position (mm) and orientation (deg, folded by the period) differences of two poses of one
/// part kind, or `None` for different kinds or faces.
fn differ(t: &[Template], a: &Located, b: &Located) -> Option<(f64, f64)> {
    if a.kind != b.kind || a.flipped != b.flipped {
        return None;
    }
    let p = t[a.kind].period_deg;
    let d = (a.theta_deg - b.theta_deg).rem_euclid(p);
    Some(((a.x_mm - b.x_mm).hypot(a.y_mm - b.y_mm), d.min(p - d)))
}

/// The full locate's part nearest `l`.
fn counterpart<'r>(r: &'r Report, l: &Located) -> &'r Located {
    let d = |o: &&Located| (o.x_mm - l.x_mm).hypot(o.y_mm - l.y_mm);
    r.parts.iter().min_by(|a, b| d(a).total_cmp(&d(b))).unwrap()
}

/// One frame of the loop: the parts `last` located in full, then moved to `now` and tracked
/// from the first locate's poses and levels. Returns the tracked result, the full locate of
/// the second photo and the templates.
fn frame(photo: &Photo, now: Vec<Placed>) -> (Tracked, Report, Vec<Template>) {
    let t: Vec<Template> = photo.parts.iter().map(Template::new).collect();
    let before = full(photo, &t);
    assert_eq!(before.parts.len(), photo.placed.len(), "{:?}", before.unknown);
    let near: Vec<Near> = before.parts.iter().map(Near::from).collect();
    let next = Photo { placed: now, ..photo.clone() };
    let img = render(&next);
    let tracked = track(&img, &t, SIZE, photo.corners, &before.levels, &near).unwrap();
    let (after, _) = locate(&img, &t, SIZE, Some(photo.corners)).unwrap();
    (tracked, after, t)
}

/// Parts moved by up to 10 mm and 20° (and, every other seed, by up to 1 mm and 2°, the quick
/// refinement's case; one part turned over, the search's): every part found, at the full
/// locate's pose within 0.05 mm and 0.05°, on both polarities and under 45 % light fall-off.
#[test]
fn moved_parts_are_tracked_to_the_full_locates_pose() {
    let parts = sample_parts();
    let mut worst = (0.0f64, 0.0f64);
    for seed in 0..4u64 {
        let last = random_poses(&parts, SIZE, 3, 0, 25.0, 100 + seed);
        let small = seed % 2 == 1;
        let step = if small { (1.0, 2.0) } else { (10.0, 20.0) };
        let mut now = nudge(&parts, &last, SIZE, step, 4.0, seed);
        // One part turned over: its last face no longer fits, the full search finds it.
        let turned = seed == 0;
        let chiral = |p: &&mut Placed| Template::new(&parts[p.part]).mirrored.is_some();
        if let Some(p) = now.iter_mut().filter(|_| turned).find(chiral) {
            p.flipped = !p.flipped;
        }
        let mut photo = Photo::standard(parts.clone(), last, 100 + seed);
        match seed {
            2 => photo = photo.light_on_dark(),
            3 => photo.light_falloff = 0.45,
            _ => {}
        }
        let (tracked, after, t) = frame(&photo, now.clone());
        let found = tracked.all_found().unwrap_or_else(|| panic!("seed {seed}: {tracked:?}"));
        println!("seed {seed}: {} of {} by the refinement alone", tracked.quick, found.len());
        for l in &found {
            let (d, a) = differ(&t, l, counterpart(&after, l)).expect("the same part and face");
            println!("seed {seed} {}: {d:.4} mm {a:.4}° score {:.3}", l.part, l.score);
            assert!(d <= 0.05 && a <= 0.05, "seed {seed}: {l:?} vs {:?}", counterpart(&after, l));
            worst = (worst.0.max(d), worst.1.max(a));
        }
        for q in &now {
            let e = pose_error(&t, &found, q);
            assert!(e.is_some_and(|(d, a)| d < 1.0 && a < 1.0), "seed {seed}: {q:?} {found:?}");
        }
        if small {
            assert_eq!(tracked.quick, found.len(), "seed {seed}: small moves need no search");
        }
        if turned {
            assert!(tracked.quick < found.len(), "seed {seed}: the turned part was searched");
        }
    }
    println!("tracked vs full locate: worst {:.4} mm {:.4}°", worst.0, worst.1);
}

/// Three parts apart; the tab moved 90 mm (out of its window), the L 35 mm (its blob runs out
/// of its window): the tab is lost, never posed elsewhere; the L found where it is (the
/// window widened) or lost; the triangle, unmoved, found.
#[test]
fn a_part_moved_beyond_its_window_is_lost_not_misplaced() {
    let parts = sample_parts();
    let last = vec![
        Placed { part: 0, c: [60.0, 60.0], theta_deg: 30.0, flipped: false },
        Placed { part: 1, c: [150.0, 150.0], theta_deg: 100.0, flipped: true },
        Placed { part: 2, c: [240.0, 50.0], theta_deg: 200.0, flipped: false },
    ];
    let mut now = last.clone();
    now[0].c[0] += 35.0;
    now[2].c[1] += 90.0;
    let photo = Photo::standard(parts.clone(), last, 41);
    let (tracked, _, t) = frame(&photo, now.clone());
    println!("{:?}", tracked.parts);
    let by_kind = |k: usize| {
        tracked.parts.iter().find(|s| match s {
            Seen::Found(l) => l.kind == k,
            Seen::Lost { part, .. } => *part == t[k].part.name,
        })
    };
    assert!(
        matches!(by_kind(2), Some(Seen::Lost { why: Lost::Gone, .. })),
        "the tab left its window: {:?}",
        by_kind(2)
    );
    match by_kind(0) {
        Some(Seen::Found(l)) => {
            let e = pose_error(&t, std::slice::from_ref(l), &now[0]);
            assert!(e.is_some_and(|(d, a)| d < 1.0 && a < 1.0), "{l:?}");
        }
        Some(Seen::Lost { .. }) => {}
        None => panic!("the L is missing: {:?}", tracked.parts),
    }
    let Some(Seen::Found(tri)) = by_kind(1) else { panic!("{:?}", tracked.parts) };
    assert!(pose_error(&t, std::slice::from_ref(tri), &now[1]).is_some_and(|e| e.0 < 1.0));
}

/// Parts in contact (each with a last pose a few mm and degrees off): split as the full locate
/// splits them, each at the full locate's pose and marked touching, or named lost for the
/// caller's full locate; never a wrong pose.
#[test]
fn touching_parts_are_split_or_reported() {
    let parts = sample_parts();
    let (mut split, mut reported) = (0, 0);
    for seed in [11u64, 12, 13] {
        let now = random_poses(&parts, SIZE, 2, 1, 8.0, seed);
        assert_eq!(now.len(), 3, "seed {seed}: a touching pair");
        let photo = Photo::standard(parts.clone(), now.clone(), seed);
        let t: Vec<Template> = parts.iter().map(Template::new).collect();
        let r = full(&photo, &t);
        let mut rng = Rng(seed);
        let mut off = |m: f64| m * (2.0 * rng.uniform() - 1.0);
        // Last poses a few mm and degrees off (the tracker puts a tab's flipped face up).
        let near: Vec<Near> = now
            .iter()
            .map(|p| Near {
                kind: p.part,
                x_mm: p.c[0] + off(2.0),
                y_mm: p.c[1] + off(2.0),
                theta_deg: p.theta_deg + off(6.0),
                flipped: p.flipped,
                face_certain: true,
            })
            .collect();
        let img = render(&photo);
        let tracked = track(&img, &t, SIZE, photo.corners, &r.levels, &near).unwrap();
        for (s, p) in tracked.parts.iter().zip(&now) {
            println!("seed {seed}: {s:?}");
            match s {
                Seen::Found(l) => {
                    let (d, a) = differ(&t, l, counterpart(&r, l)).expect("same part and face");
                    assert!(d <= 0.05 && a <= 0.05, "seed {seed}: {l:?} vs {:?}", r.parts);
                    assert!(pose_error(&t, std::slice::from_ref(l), p).is_some());
                    split += usize::from(l.touching);
                }
                Seen::Lost { why, .. } => {
                    assert!(matches!(why, Lost::Cut | Lost::Cluster), "seed {seed}: {why:?}");
                    reported += 1;
                }
            }
        }
    }
    println!("touching parts: {split} split and posed, {reported} reported lost");
    assert!(split >= 2, "at least one pair split: {split} posed, {reported} lost");
}

/// Bad input is named: a kind not given, a pose that is no number, levels no view has.
#[test]
fn bad_input_is_named() {
    let parts = sample_parts();
    let t: Vec<Template> = parts.iter().map(Template::new).collect();
    let photo = Photo::standard(parts, vec![], 1);
    let img = GrayImage::new(1280, 900);
    let levels = Levels { parts_dark: true, threshold: 0.6, contrast: 0.7 };
    let n = Near {
        kind: 5,
        x_mm: 10.0,
        y_mm: 10.0,
        theta_deg: 0.0,
        flipped: false,
        face_certain: true,
    };
    let e = track(&img, &t, SIZE, photo.corners, &levels, &[n]).unwrap_err();
    assert_eq!(e.name(), "bad_part_kind", "{e}");
    let nan = Near { kind: 0, x_mm: f64::NAN, ..n };
    let e = track(&img, &t, SIZE, photo.corners, &levels, &[nan]).unwrap_err();
    assert_eq!(e.name(), "bad_pose", "{e}");
    let flat = Levels { contrast: 0.0, ..levels };
    let e = track(&img, &t, SIZE, photo.corners, &flat, &[]).unwrap_err();
    assert!(e.to_string().contains("full locate"), "{e}");
    let mut crossed = photo.corners;
    crossed.swap(1, 2);
    let e = track(&img, &t, SIZE, crossed, &levels, &[]).unwrap_err();
    assert_eq!(e.name(), "corners_not_convex", "{e}");
    // A pose off the plate has no window: lost, not an error.
    let off = Near { kind: 0, x_mm: -500.0, ..n };
    let r = track(&img, &t, SIZE, photo.corners, &levels, &[off]).unwrap();
    assert!(matches!(r.parts[0], Seen::Lost { why: Lost::Gone, .. }), "{r:?}");
}
