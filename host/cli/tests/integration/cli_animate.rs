//! `chladni simulate --animate run.gif`: the GIF decodes (with the `image` crate) into the
//! expected number of frames of the expected size, the parts move between the first and the
//! last frame, and bad uses are refused before any simulation.

use image::AnimationDecoder;
use image::codecs::gif::GifDecoder;

use crate::support;
use support::cli::{chladni, repo, tmp};

const PART: &str = "examples/parts/triangle.json";
const PLATE: &str = "examples/plates/four-lines.toml";
const PLAN: &str = "examples/plans/triangle-four-lines.json";

#[test]
fn the_animation_decodes_into_moving_frames_of_the_plate_size() {
    let gif = tmp("animate", "run.gif");
    let (part, plate, plan) = (repo(PART), repo(PLATE), repo(PLAN));
    let out = chladni(&[
        "simulate",
        &part,
        "--plate",
        &plate,
        "--plan",
        &plan,
        "--trials",
        "6",
        "--animate",
        gif.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let n = chladni_media::plot::animate::MAX_FRAMES;
    assert!(stdout.contains(&format!("({n} frames)")), "{stdout}");

    let file = std::io::BufReader::new(std::fs::File::open(&gif).unwrap());
    let frames = GifDecoder::new(file).unwrap().into_frames().collect_frames().unwrap();
    assert_eq!(frames.len(), n);
    let model = chladni_core::model::plate::PlateModel::load(std::path::Path::new(&plate)).unwrap();
    let (w, h) = chladni_media::plot::animate::frame_size(&model);
    for f in &frames {
        assert_eq!(f.buffer().dimensions(), (w, h));
    }
    // The parts move (and the clock and step change): first and last frames differ widely.
    let (a, b) = (frames[0].buffer(), frames[n - 1].buffer());
    let changed = a.pixels().zip(b.pixels()).filter(|(p, q)| p != q).count();
    assert!(changed > 500, "only {changed} pixels differ between the first and last frame");
    // The last frame is held longer than the others.
    let ms = |i: usize| frames[i].delay().numer_denom_ms();
    assert!(ms(n - 1).0 / ms(n - 1).1 > ms(0).0 / ms(0).1);
}

#[test]
fn animate_refuses_other_formats_and_two_faces_before_simulating() {
    let (part, plate, plan) = (repo(PART), repo(PLATE), repo(PLAN));
    let base = ["simulate", &part, "--plate", &plate, "--plan", &plan];
    let png = tmp("animate", "run.png");
    let mut args = base.to_vec();
    args.extend(["--animate", png.to_str().unwrap()]);
    let out = chladni(&args);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--animate file must end in .gif"), "{err}");
    assert!(!png.exists());

    let gif = tmp("animate", "faces.gif");
    let mut args = base.to_vec();
    args.extend(["--both-faces", "--animate", gif.to_str().unwrap()]);
    let out = chladni(&args);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--animate draws one part on one face"), "{err}");
    assert!(!gif.exists());
}
