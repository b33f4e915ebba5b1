//! Photos for the cell's photo check (`POST /api/verify`): the example key on the example
//! plate after the example key plan, one key where the plan puts it and one turned and
//! elsewhere, rendered by the synthetic camera (`vision::synth`) at 640 × 450 px.
#![allow(dead_code)]

use chladni_core::model::part::Part;
use chladni_media::vision::synth::{Photo, Placed, render};

/// The plan, part and plate the photos are checked against (`examples/…`).
pub const PLAN: &str = "plans/key-four-lines.json";
/// The part.
pub const PART: &str = "parts/key.svg";
/// The plate.
pub const PLATE: &str = "plates/four-lines.toml";

/// The camera: the standard synthetic view halved (0.5 mm per pixel).
fn camera(placed: Vec<Placed>) -> Photo {
    let part = Part::load(&super::examples::root().join("examples").join(PART)).unwrap();
    let mut p = Photo::standard(vec![part], placed, 11);
    p.px = (640, 450);
    p.corners = p.corners.map(|c| [c[0] / 2.0, c[1] / 2.0]);
    p.blur_px = 0.5;
    p
}

/// The camera's plate corners, as `--verify-corners` takes them.
pub fn corners() -> Vec<String> {
    camera(vec![]).corners.iter().flatten().map(|v| v.to_string()).collect()
}

/// Two keys: one at the plan's predicted pose (as planned), one turned 109° and 90 mm away
/// (off): found 2, oriented 1.
pub fn one_good_one_off() -> image::GrayImage {
    let good = Placed { part: 0, c: [150.101, 117.396], theta_deg: 90.9557, flipped: false };
    let off = Placed { c: [70.0, 60.0], theta_deg: 200.0, ..good.clone() };
    render(&camera(vec![good, off]))
}

/// `serve`'s arguments for checking these photos.
pub fn serve_args() -> Vec<String> {
    let ex = |p: &str| super::examples::root().join("examples").join(p).display().to_string();
    let mut a = vec!["--verify-plan".to_string(), ex(PLAN), "--verify-part".into(), ex(PART)];
    a.extend(["--verify-plate".to_string(), ex(PLATE), "--verify-corners".into()]);
    a.extend(corners());
    a
}
