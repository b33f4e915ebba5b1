//! Poses found in synthetic photos against the poses drawn.

use super::synth::{Photo, Placed, random_poses, render};
use super::{Located, Report, Template, locate};
use crate::model::part::Part;

/// The test parts: an L and a right triangle (both chiral: their flipped face is another
/// shape) and a tab with a hole on its mirror axis (the same shape on both faces).
pub(crate) fn test_parts() -> Vec<Part> {
    let hole: Vec<[f64; 2]> = (0..12)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 12.0;
            [8.0 + 4.0 * a.cos(), 9.0 + 4.0 * a.sin()]
        })
        .collect();
    vec![
        Part::new(
            "ell".into(),
            vec![[0.0, 0.0], [40.0, 0.0], [40.0, 10.0], [12.0, 10.0], [12.0, 28.0], [0.0, 28.0]],
            vec![],
        )
        .unwrap(),
        Part::new("tri".into(), vec![[0.0, 0.0], [36.0, 0.0], [0.0, 22.0]], vec![]).unwrap(),
        Part::new(
            "tab".into(),
            vec![[0.0, 0.0], [30.0, 0.0], [30.0, 18.0], [0.0, 18.0]],
            vec![hole],
        )
        .unwrap(),
    ]
}

/// Errors (mm, deg) of the located part matching placed part `p`, folding the symmetry
/// period and a self-mirrored part's flip; `None` when no located part is within 5 mm or its
/// face is wrong.
pub(crate) fn pose_error(t: &[Template], found: &[Located], p: &Placed) -> Option<(f64, f64)> {
    let tm = &t[p.part];
    let (mut theta, mut flipped) = (p.theta_deg, p.flipped);
    if let (true, Some(turn)) = (flipped, tm.flip_turn_deg) {
        theta += turn;
        flipped = false;
    }
    let l = found.iter().filter(|l| l.kind == p.part).min_by(|a, b| {
        let d = |l: &&Located| (l.x_mm - p.c[0]).hypot(l.y_mm - p.c[1]);
        d(a).total_cmp(&d(b))
    })?;
    let dist = (l.x_mm - p.c[0]).hypot(l.y_mm - p.c[1]);
    if dist > 5.0 || l.flipped != flipped {
        return None;
    }
    let d = (l.theta_deg - theta).rem_euclid(tm.period_deg);
    Some((dist, d.min(tm.period_deg - d)))
}

fn run(photo: &Photo, corners: bool) -> (Vec<Template>, Report) {
    let t: Vec<Template> = photo.parts.iter().map(Template::new).collect();
    let img = render(photo);
    let (r, _) = locate(&img, &t, photo.size_mm, corners.then_some(photo.corners)).unwrap();
    (t, r)
}

fn check_all(photo: &Photo, corners: bool) -> Vec<(f64, f64)> {
    let (t, r) = run(photo, corners);
    let mut errs = Vec::new();
    for p in &photo.placed {
        let e = pose_error(&t, &r.parts, p);
        let Some((d, a)) = e else {
            panic!("seed {}: {p:?} not found right: {:?} {:?}", photo.seed, r.parts, r.unknown);
        };
        assert!(
            d <= 1.0 && a <= 1.0,
            "seed {}: {p:?}: {d:.3} mm {a:.3}° {:?}",
            photo.seed,
            r.parts
        );
        errs.push((d, a));
    }
    assert_eq!(r.parts.len(), photo.placed.len(), "{:?}", r.parts);
    assert!(r.unknown.is_empty(), "{:?}", r.unknown);
    errs
}

#[test]
fn lone_parts_on_both_faces_are_located_within_a_millimetre_and_a_degree() {
    let parts = test_parts();
    for seed in [1, 2] {
        let placed = random_poses(&parts, [300.0, 200.0], 7, 0, 6.0, seed);
        assert!(placed.len() >= 6);
        let errs = check_all(&Photo::standard(parts.clone(), placed, seed), false);
        let worst = errs.iter().fold((0.0f64, 0.0f64), |w, e| (w.0.max(e.0), w.1.max(e.1)));
        println!("seed {seed}: worst {:.3} mm {:.3}°", worst.0, worst.1);
    }
}

#[test]
fn light_parts_on_a_dark_plate_with_corners_given() {
    let parts = test_parts();
    let placed = random_poses(&parts, [300.0, 200.0], 6, 0, 6.0, 7);
    check_all(&Photo::standard(parts, placed, 7).light_on_dark(), true);
}

#[test]
fn touching_pairs_are_told_apart() {
    let parts = test_parts();
    let placed = random_poses(&parts, [300.0, 200.0], 4, 3, 8.0, 11);
    assert!(placed.len() >= 6, "{placed:?}");
    check_all(&Photo::standard(parts, placed, 11), false);
}
