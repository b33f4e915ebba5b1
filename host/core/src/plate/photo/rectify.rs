//! Perspective correction: a photo taken at an angle, with the plate's four corners marked,
//! becomes the cropped, square-on view the node finder expects.
//!
//! The plate is flat, so the photo is a projective image of it: a homography (8 unknowns)
//! fixed by the four corners, solved in f64 (imageproc's `Projection::from_control_points`
//! solves in f32). Each pixel of the rectified image is mapped back into the photo and sampled
//! bilinearly.

use image::{GrayImage, Luma};
use nalgebra::{SMatrix, SVector};

/// Why a photo cannot be rectified.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RectifyError {
    /// A corner lies outside the image.
    #[error(
        "corner {index} ({x:.1}, {y:.1}) px lies outside the {w}×{h} px image; give the pixel \
         positions of the plate's corners in the photo"
    )]
    OutsideImage {
        /// Corner index (0 = bottom-left of the plate, then counter-clockwise).
        index: usize,
        /// Column (px).
        x: f64,
        /// Row (px).
        y: f64,
        /// Image width (px).
        w: u32,
        /// Image height (px).
        h: u32,
    },
    /// The corners do not form a convex quadrilateral in the given order.
    #[error(
        "the corners {0:?} px do not form a convex quadrilateral in the order bottom-left, \
         bottom-right, top-right, top-left of the plate"
    )]
    NotConvex([[f64; 2]; 4]),
}

/// A plane projective map p ↦ (H·[p, 1]) / w, with h₃₃ = 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Homography([f64; 8]);

impl Homography {
    /// The map taking each `from[k]` to `to[k]`; `None` if the points are degenerate (three
    /// on a line).
    pub fn from_points(from: [[f64; 2]; 4], to: [[f64; 2]; 4]) -> Option<Homography> {
        // x = (h0 u + h1 v + h2)/(h6 u + h7 v + 1), y likewise with h3..h5: two linear
        // equations per point pair.
        let mut a = SMatrix::<f64, 8, 8>::zeros();
        let mut b = SVector::<f64, 8>::zeros();
        for (k, ([u, v], [x, y])) in from.into_iter().zip(to).enumerate() {
            let r = 2 * k;
            a.row_mut(r).copy_from_slice(&[u, v, 1.0, 0.0, 0.0, 0.0, -u * x, -v * x]);
            a.row_mut(r + 1).copy_from_slice(&[0.0, 0.0, 0.0, u, v, 1.0, -u * y, -v * y]);
            b[r] = x;
            b[r + 1] = y;
        }
        let h = a.lu().solve(&b)?;
        h.iter().all(|v| v.is_finite()).then(|| {
            let mut c = [0.0; 8];
            c.copy_from_slice(h.as_slice());
            Homography(c)
        })
    }

    /// Maps a point.
    // Inlined: the photo renderer and the locator map every pixel (see `geometry::inside`).
    #[inline]
    pub fn map(&self, [u, v]: [f64; 2]) -> [f64; 2] {
        let h = &self.0;
        let w = h[6] * u + h[7] * v + 1.0;
        [(h[0] * u + h[1] * v + h[2]) / w, (h[3] * u + h[4] * v + h[5]) / w]
    }
}

/// Bilinear sample of `img` at (x, y) in pixel-centre coordinates; `fill` outside.
fn sample(img: &GrayImage, [x, y]: [f64; 2], fill: u8) -> u8 {
    let (w, h) = (img.width() as f64, img.height() as f64);
    let (x, y) = (x - 0.5, y - 0.5);
    if !(x > -1.0 && y > -1.0 && x < w && y < h) {
        return fill;
    }
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |i: f64, j: f64| -> f64 {
        let i = i.clamp(0.0, w - 1.0) as u32;
        let j = j.clamp(0.0, h - 1.0) as u32;
        img.get_pixel(i, j)[0] as f64
    };
    let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1.0, y0) * fx;
    let bottom = at(x0, y0 + 1.0) * (1.0 - fx) + at(x0 + 1.0, y0 + 1.0) * fx;
    (top * (1.0 - fy) + bottom * fy).round() as u8
}

/// Renders the `w`×`h` image whose pixel centre p shows `img` at `h_out_to_in.map(p)`. Kept by
/// hand: with imageproc's projective `warp_into` (f32 map, each bilinear row rounded to 8 bits)
/// the oblique-photo test's worst angle error grew from 0.13° to 0.15° (offset 0.14 → 0.12 mm).
pub fn warp(img: &GrayImage, h_out_to_in: &Homography, w: u32, h: u32, fill: u8) -> GrayImage {
    GrayImage::from_fn(w, h, |i, j| {
        Luma([sample(img, h_out_to_in.map([i as f64 + 0.5, j as f64 + 0.5]), fill)])
    })
}

/// The square-on view of the plate whose corners sit at `corners` (pixel positions in the
/// photo, x right, y down: the plate's bottom-left, bottom-right, top-right and top-left
/// corners, i.e. plate (0, 0), (W, 0), (W, H), (0, H)). The result is as many pixels wide and
/// high as the longer of the plate's opposite edges in the photo.
pub fn rectify(img: &GrayImage, corners: [[f64; 2]; 4]) -> Result<GrayImage, RectifyError> {
    check_corners(img.width(), img.height(), &corners)?;
    let len = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    let [bl, br, tr, tl] = corners;
    let w = len(bl, br).max(len(tl, tr)).round().max(2.0);
    let h = len(bl, tl).max(len(br, tr)).round().max(2.0);
    // Rectified image: top row = the plate's top edge (y = H).
    let out = [[0.0, h], [w, h], [w, 0.0], [0.0, 0.0]];
    let hom = Homography::from_points(out, corners).ok_or(RectifyError::NotConvex(corners))?;
    let mut grey: Vec<u8> = img.as_raw().clone();
    grey.sort_unstable();
    let fill = grey.get(grey.len() / 2).copied().unwrap_or(0);
    Ok(warp(img, &hom, w as u32, h as u32, fill))
}

/// Corners usable for a `w`×`h` px photo: each inside it (within a pixel) and the four a
/// convex quadrilateral in the given order.
pub fn check_corners(w: u32, h: u32, corners: &[[f64; 2]; 4]) -> Result<(), RectifyError> {
    for (index, &[x, y]) in corners.iter().enumerate() {
        if !(x >= -1.0 && y >= -1.0 && x <= w as f64 + 1.0 && y <= h as f64 + 1.0) {
            return Err(RectifyError::OutsideImage { index, x, y, w, h });
        }
    }
    if !convex(corners) {
        return Err(RectifyError::NotConvex(*corners));
    }
    Ok(())
}

/// Consecutive edges all turn the same way (and none is degenerate).
fn convex(c: &[[f64; 2]; 4]) -> bool {
    let turns: Vec<f64> = (0..4)
        .map(|k| {
            let (a, b, d) = (c[k], c[(k + 1) % 4], c[(k + 2) % 4]);
            (b[0] - a[0]) * (d[1] - b[1]) - (b[1] - a[1]) * (d[0] - b[0])
        })
        .collect();
    turns.iter().all(|&t| t > 1e-9) || turns.iter().all(|&t| t < -1e-9)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plate::photo::synth::{Scene, render};
    use crate::plate::photo::{PhotoParams, find_lines};

    #[test]
    fn homography_maps_the_four_points_and_inverts() {
        let a = [[0.0, 0.0], [10.0, 0.0], [10.0, 5.0], [0.0, 5.0]];
        let b = [[3.0, 40.0], [52.0, 47.0], [44.0, 4.0], [9.0, 11.0]];
        let h = Homography::from_points(a, b).unwrap();
        let back = Homography::from_points(b, a).unwrap();
        for (p, q) in a.iter().zip(&b) {
            let m = h.map(*p);
            assert!((m[0] - q[0]).abs() < 1e-9 && (m[1] - q[1]).abs() < 1e-9, "{m:?} {q:?}");
        }
        let p = [3.7, 2.2];
        let r = back.map(h.map(p));
        assert!((r[0] - p[0]).abs() < 1e-9 && (r[1] - p[1]).abs() < 1e-9, "{r:?}");
        // Three points on a line fix no homography.
        let line = [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [0.0, 5.0]];
        assert_eq!(Homography::from_points(line, b), None);
    }

    #[test]
    fn bad_corners_are_named() {
        let img = GrayImage::new(100, 80);
        let ok = [[5.0, 70.0], [90.0, 75.0], [95.0, 5.0], [10.0, 10.0]];
        assert!(rectify(&img, ok).is_ok());
        let outside = [[5.0, 70.0], [190.0, 75.0], [95.0, 5.0], [10.0, 10.0]];
        assert!(matches!(rectify(&img, outside), Err(RectifyError::OutsideImage { index: 1, .. })));
        let crossed = [[5.0, 70.0], [95.0, 5.0], [90.0, 75.0], [10.0, 10.0]];
        let err = rectify(&img, crossed).unwrap_err();
        assert!(err.to_string().contains("do not form a convex quadrilateral"), "{err}");
    }

    /// The synthetic plate photo seen at an angle: the plate fills the quadrilateral
    /// `corners` of a `w`×`h` frame on a mid-grey, noisy background.
    fn oblique(plate: &GrayImage, corners: [[f64; 2]; 4], w: u32, h: u32) -> GrayImage {
        let (pw, ph) = (plate.width() as f64, plate.height() as f64);
        let square = [[0.0, ph], [pw, ph], [pw, 0.0], [0.0, 0.0]];
        let to_plate = Homography::from_points(corners, square).unwrap();
        let mut img = warp(plate, &to_plate, w, h, 90);
        for (k, p) in img.pixels_mut().enumerate() {
            // Background texture the node finder must not see (it is cropped away).
            p[0] = p[0].saturating_add(((k * 7919) % 23) as u8);
        }
        img
    }

    // Lines recovered from a photo taken obliquely (keystone ≈ 25 %, 5° roll) after
    // rectification by the four marked corners, against the lines drawn on the plate.
    #[test]
    fn oblique_photo_rectified_by_its_corners_gives_the_drawn_lines() {
        let truth = [(90.0, 40.0), (20.0, -30.0)];
        let plate = render(&Scene::standard(truth.to_vec(), vec![], 5));
        let corners = [[38.0, 352.0], [452.0, 372.0], [405.0, 58.0], [88.0, 44.0]];
        let photo = oblique(&plate, corners, 500, 420);
        // Unrectified, the lines come out wrong (the keystone bends the plate's geometry).
        let skewed = find_lines(&photo, [300.0, 200.0], &PhotoParams::default());
        let rect = rectify(&photo, corners).unwrap();
        let found = find_lines(&rect, [300.0, 200.0], &PhotoParams::default());
        assert_eq!(found.lines.len(), 2, "{:?}", found.lines);
        let mut worst = (0.0f64, 0.0f64);
        for (a, o) in truth {
            let l = found
                .lines
                .iter()
                .min_by(|p, q| {
                    let d = |l: &&crate::plate::photo::Line| {
                        (l.angle_deg - a).abs().min(180.0 - (l.angle_deg - a).abs())
                    };
                    d(p).total_cmp(&d(q))
                })
                .unwrap();
            worst.0 = worst.0.max((l.angle_deg - a).abs());
            worst.1 = worst.1.max((l.offset_mm - o).abs());
        }
        println!("rectified: worst angle error {:.2}°, offset error {:.2} mm", worst.0, worst.1);
        assert!(worst.0 < 1.0 && worst.1 < 2.0, "{worst:?} {:?}", found.lines);
        let skew_ok = truth.iter().all(|&(a, o)| {
            skewed
                .lines
                .iter()
                .any(|l| (l.angle_deg - a).abs() < 1.0 && (l.offset_mm - o).abs() < 2.0)
        });
        assert!(!skew_ok, "without rectification the lines should be off: {:?}", skewed.lines);
    }
}
