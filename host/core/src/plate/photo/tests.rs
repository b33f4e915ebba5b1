//! Straight-line accuracy on synthetic photos, and the pipeline's building blocks.

use super::sand::otsu;
use super::synth::{Scene, render};
use super::*;

fn scene(lines: Vec<(f64, f64)>, dark_sand: bool, seed: u64) -> Scene {
    Scene { dark_sand, ..Scene::standard(lines, vec![], seed) }
}

/// Angle difference modulo 180°, with the offset sign following the direction flip.
fn matches(found: &Line, (a, o): (f64, f64), size: [f64; 2]) -> Option<(f64, f64)> {
    let (da, doff) = found.difference(a, o);
    let doff = doff / size[0].min(size[1]);
    (da < 1.0 && doff < 0.01).then_some((da, doff))
}

fn recover(truth: Vec<(f64, f64)>, dark: bool, seed: u64) {
    let s = scene(truth.clone(), dark, seed);
    let found = find_lines(&render(&s), s.size_mm, &PhotoParams::default());
    assert_eq!(found.check_confidence(), Ok(()));
    assert_eq!(found.sand_is_dark, dark);
    assert_eq!(found.lines.len(), truth.len(), "{:?}", found.lines);
    for &t in &truth {
        let hit = found.lines.iter().find_map(|l| matches(l, t, s.size_mm));
        assert!(hit.is_some(), "line {t:?} not recovered: {:?}", found.lines);
        let (da, doff) = hit.unwrap_or_default();
        println!("line {t:?}: angle error {da:.3}°, offset error {:.3} % of plate", 100.0 * doff);
    }
}

#[test]
fn otsu_splits_two_levels() {
    let v: Vec<u8> =
        (0..100).map(|i| if i < 70 { 40 + (i % 5) as u8 } else { 200 - (i % 7) as u8 }).collect();
    let t = otsu(&v);
    assert!((44..194).contains(&t), "{t}");
}

#[test]
fn skeleton_of_a_bar_is_thin_and_long() {
    let (w, h) = (40, 15);
    let px = (0..w * h).map(|i| (5..10).contains(&(i / w)) && (3..37).contains(&(i % w))).collect();
    let sk = skeleton(&Mask { w, h, px });
    let rows: std::collections::BTreeSet<usize> =
        (0..w * h).filter(|&i| sk.px[i]).map(|i| i / w).collect();
    assert!(rows.len() <= 2, "{rows:?}");
    assert!(sk.count() >= 25, "{}", sk.count());
}

#[test]
fn recovers_an_off_centre_vertical_node() {
    recover(vec![(90.0, 40.0)], false, 1);
}

#[test]
fn recovers_an_oblique_node_with_dark_sand() {
    recover(vec![(27.0, -18.0)], true, 2);
}

#[test]
fn recovers_two_crossing_nodes() {
    recover(vec![(0.0, 12.0), (120.0, -25.0)], false, 3);
}

#[test]
fn png_round_trip_and_heavier_noise() {
    let mut s = scene(vec![(90.0, 0.0), (0.0, 0.0)], false, 5);
    s.noise = 40.0;
    s.stray = 0.05;
    let path =
        std::env::temp_dir().join(format!("chladni-synthetic-photo-{}.png", std::process::id()));
    render(&s).save(&path).unwrap();
    let img = image::open(&path).unwrap().to_luma8();
    std::fs::remove_file(&path).ok();
    let found = find_lines(&img, s.size_mm, &PhotoParams::default());
    assert_eq!(found.lines.len(), 2, "{:?}", found.lines);
    for t in [(90.0, 0.0), (0.0, 0.0)] {
        assert!(
            found.lines.iter().any(|l| matches(l, t, s.size_mm).is_some()),
            "{t:?}: {:?}",
            found.lines
        );
    }
}

#[test]
fn blank_plate_has_no_lines() {
    let mut s = scene(vec![], false, 4);
    s.density = 0.0;
    let found = find_lines(&render(&s), s.size_mm, &PhotoParams::default());
    assert!(found.lines.is_empty(), "{:?}", found.lines);
}

// Random noise thresholds into a maze whose "lines" are refused by the confidence check; the
// synthetic photos' nodes pass it.
#[test]
fn noise_is_refused_and_sand_on_nodes_is_trusted() {
    let mut rng = super::synth::Rng(42);
    let noise =
        image::GrayImage::from_fn(360, 240, |_, _| image::Luma([(rng.next_u64() >> 56) as u8]));
    let found = find_lines(&noise, [300.0, 200.0], &PhotoParams::default());
    assert!(!found.lines.is_empty(), "the Hough transform finds lines in noise");
    let err = found.check_confidence().unwrap_err();
    assert!(matches!(err, Unconfident::SandEverywhere(f) if f > 0.45), "{err}");
    for (truth, seed) in [(vec![(90.0, 40.0)], 1), (vec![(90.0, 40.0), (20.0, -30.0)], 7)] {
        let s = Scene::standard(truth, vec![], seed);
        let found = find_lines(&render(&s), s.size_mm, &PhotoParams::default());
        assert_eq!(found.check_confidence(), Ok(()), "{:?}", found.lines);
    }
}
