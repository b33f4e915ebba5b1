//! Cameras against a real HTTP server on 127.0.0.1 and real folders, with frames rendered by
//! [`crate::vision::synth`].

mod dir_tests;
mod http_tests;

use std::io::Cursor;
use std::time::{Duration, SystemTime};

use image::{GrayImage, ImageFormat};

use super::{CameraError, CameraOptions, Frame};
use chladni_media::vision::synth::{Photo, Placed, render, sample_parts};

/// A small photo of one part (96 × 64 px), different noise for each seed.
fn photo(seed: u64) -> GrayImage {
    let parts = sample_parts().into_iter().take(1).collect();
    let placed = vec![Placed { part: 0, c: [150.0, 100.0], theta_deg: 30.0, flipped: false }];
    let mut p = Photo::standard(parts, placed, seed);
    p.px = (96, 64);
    p.corners = [[5.0, 60.0], [91.0, 61.0], [88.0, 6.0], [8.0, 5.0]];
    render(&p)
}

/// The photo encoded as PNG or JPEG.
fn encoded(img: &GrayImage, format: ImageFormat) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, format).expect("encoding a small grey image");
    out.into_inner()
}

/// Options with a short timeout, for the failing cases.
fn quick(timeout_ms: u64) -> CameraOptions {
    CameraOptions {
        timeout: Duration::from_millis(timeout_ms),
        max_age: Duration::from_millis(10),
        ..CameraOptions::default()
    }
}

/// The error, with its name and message checked for the value it must name.
fn failed(r: Result<Frame, CameraError>, name: &str, names: &str) -> CameraError {
    let e = match r {
        Ok(f) => panic!("expected {name}, got a frame taken {:?}", f.taken),
        Err(e) => e,
    };
    assert_eq!(e.name(), name, "{e}");
    assert!(e.to_string().contains(names), "{e:?} does not name {names}");
    e
}

/// Unix seconds as the X-Frame-Time header writes them.
fn stamp(t: SystemTime) -> String {
    let d = t.duration_since(SystemTime::UNIX_EPOCH).expect("after 1970");
    format!("{}.{:06}", d.as_secs(), d.subsec_micros())
}

/// The time a stamp written by [`stamp`] stands for.
fn from_stamp(s: &str) -> SystemTime {
    SystemTime::UNIX_EPOCH + Duration::from_secs_f64(s.parse().expect("a stamp"))
}
