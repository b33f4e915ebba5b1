//! `chladni locate` on synthetic 1280 × 900 photos of a 300 × 200 mm plate (docs/plate.md,
//! "Parts in a photo"): first the accuracy over many seeded photos (both faces, both
//! polarities, touching pairs), printed as a table of the error distribution, at the full
//! 1280 × 900 px (≈ 0.26 mm per pixel) and at half that (640 × 450, ≈ 0.52 mm); then
//! criterion's time per photo (corners found automatically, seven parts, one touching pair);
//! then the camera loop's case: three parts (one of each kind) located in full with the corners
//! given, against `track` from their poses in the photo before.

use chladni_media::vision::synth::{Photo, Placed, pose_error, random_poses, render, sample_parts};
use chladni_media::vision::track::{Near, track};
use chladni_media::vision::{Template, locate};
use criterion::{Criterion, criterion_group, criterion_main};

/// Photos in the accuracy sweep.
const PHOTOS: u64 = 24;

fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// The accuracy sweep on photos scaled by `scale` (1 = 1280 × 900 px).
fn accuracy(scale: f64) {
    let parts = sample_parts();
    let t: Vec<Template> = parts.iter().map(Template::new).collect();
    let (mut pos, mut ang) = (Vec::new(), Vec::new());
    let (mut missed, mut wrong_face, mut total, mut uncertain) = (0, 0, 0, 0);
    for seed in 0..PHOTOS {
        let placed = random_poses(&parts, [300.0, 200.0], 6, (seed % 3) as usize, 6.0, seed);
        let mut photo = Photo::standard(parts.clone(), placed.clone(), seed);
        photo.px = ((1280.0 * scale) as u32, (900.0 * scale) as u32);
        photo.corners = photo.corners.map(|c| [c[0] * scale, c[1] * scale]);
        photo.blur_px *= scale.sqrt();
        if seed % 2 == 1 {
            photo = photo.light_on_dark();
        }
        let img = render(&photo);
        let found = locate(&img, &t, photo.size_mm, None).map(|r| r.0.parts).unwrap_or_default();
        uncertain += found.iter().filter(|l| !l.face_certain).count();
        for p in &placed {
            total += 1;
            match pose_error(&t, &found, p) {
                Some((d, a)) => {
                    pos.push(d);
                    ang.push(a);
                }
                None if found
                    .iter()
                    .any(|l| (l.x_mm - p.c[0]).hypot(l.y_mm - p.c[1]) < 5.0 && l.face_certain) =>
                {
                    wrong_face += 1
                }
                // Marked uncertain: no pose claimed (counted in `uncertain`).
                None if found.iter().any(|l| (l.x_mm - p.c[0]).hypot(l.y_mm - p.c[1]) < 5.0) => {}
                None => missed += 1,
            }
        }
    }
    println!(
        "locate accuracy at {}x{} px: {PHOTOS} photos, {total} parts, {missed} not located, \
         {wrong_face} on the wrong face, {uncertain} faces uncertain",
        (1280.0 * scale) as u32,
        (900.0 * scale) as u32
    );
    println!("| error | median | p90 | p99 | max |");
    println!("|---|---|---|---|---|");
    for (name, v) in [("position (mm)", &mut pos), ("orientation (°)", &mut ang)] {
        let q: Vec<String> =
            [0.5, 0.9, 0.99, 1.0].iter().map(|&q| format!("{:.3}", quantile(v, q))).collect();
        println!("| {name} | {} |", q.join(" | "));
    }
}

fn bench(c: &mut Criterion) {
    accuracy(1.0);
    accuracy(0.5);
    let parts = sample_parts();
    let t: Vec<Template> = parts.iter().map(Template::new).collect();
    let placed = random_poses(&parts, [300.0, 200.0], 6, 1, 6.0, 3);
    let photo = Photo::standard(parts, placed, 3);
    let img = render(&photo);
    let mut g = c.benchmark_group("locate");
    g.sample_size(20);
    g.bench_function("1280x900_auto_corners", |b| {
        b.iter(|| locate(&img, &t, photo.size_mm, None).unwrap())
    });
    g.bench_function("1280x900_corners_given", |b| {
        b.iter(|| locate(&img, &t, photo.size_mm, Some(photo.corners)).unwrap())
    });
    g.finish();
}

/// `last` moved by `d_mm` (each part in its own direction) and turned by ±`d_deg`; `over`:
/// every part turned over too.
fn moved(last: &[Placed], d_mm: f64, d_deg: f64, over: bool) -> Vec<Placed> {
    let turn = |k: usize| if k.is_multiple_of(2) { d_deg } else { -d_deg };
    let dir = |k: usize| 2.0 * k as f64 + 0.5;
    last.iter()
        .enumerate()
        .map(|(k, p)| Placed {
            c: [p.c[0] + d_mm * dir(k).cos(), p.c[1] + d_mm * dir(k).sin()],
            theta_deg: p.theta_deg + turn(k),
            flipped: p.flipped != over,
            ..p.clone()
        })
        .collect()
}

/// Full locate against `track` for three parts at 1280 × 900: moved as in one loop cycle
/// (2 mm, 3°), as far as the quick refinement reaches (10 mm, 20°), and turned over (every
/// part searched as the full locate searches a blob: the worst case short of a lost part).
fn loop_cycle(c: &mut Criterion) {
    let parts = sample_parts();
    let t: Vec<Template> = parts.iter().map(Template::new).collect();
    let last = vec![
        Placed { part: 0, c: [70.0, 60.0], theta_deg: 30.0, flipped: false },
        Placed { part: 1, c: [160.0, 140.0], theta_deg: 100.0, flipped: true },
        Placed { part: 2, c: [240.0, 70.0], theta_deg: 200.0, flipped: false },
    ];
    let photo = Photo::standard(parts.clone(), last.clone(), 5);
    let (size, corners) = (photo.size_mm, photo.corners);
    let (before, _) = locate(&render(&photo), &t, size, Some(corners)).unwrap();
    let near: Vec<Near> = before.parts.iter().map(Near::from).collect();
    let mut g = c.benchmark_group("locate");
    g.sample_size(20);
    let cases = [
        ("2mm_3deg", 2.0, 3.0, false),
        ("10mm_20deg", 10.0, 20.0, false),
        ("2mm_3deg_turned_over", 2.0, 3.0, true),
    ];
    for (name, d_mm, d_deg, over) in cases {
        let img = render(&Photo { placed: moved(&last, d_mm, d_deg, over), ..photo.clone() });
        let r = track(&img, &t, size, corners, &before.levels, &near).unwrap();
        assert!(r.all_found().is_some(), "{:?}", r.parts);
        println!("track {name}: {} of 3 parts by the refinement alone", r.quick);
        if name == "2mm_3deg" {
            g.bench_function("3_parts_full_corners_given", |b| {
                b.iter(|| locate(&img, &t, size, Some(corners)).unwrap())
            });
        }
        g.bench_function(format!("3_parts_track_{name}"), |b| {
            b.iter(|| track(&img, &t, size, corners, &before.levels, &near).unwrap())
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().without_plots();
    targets = bench, loop_cycle
}
criterion_main!(benches);
