//! From grey pixels to a one-pixel skeleton of the sand: a small box blur merges the grains, a
//! wide one estimates the plate's uneven lighting, Otsu thresholds their difference (the
//! minority class is the sand), opening drops stray grains and closing fills gaps (imageproc
//! does Otsu and the morphology), and Zhang–Suen thinning (which imageproc lacks) leaves the
//! skeleton.

use image::GrayImage;
use imageproc::distance_transform::Norm;

use super::{Mask, PhotoParams};

/// Separable box blur with radius `r`, the window shrinking at the edges, in f32. Kept by
/// hand: imageproc's `box_filter` rounds each pass down to 8 bits and replicates the edge pixels,
/// and with it a blank synthetic plate gave a spurious curve and the lentil arc came out whole in
/// 4 of 6 photos instead of 5 (`curve_tests`).
pub(crate) fn box_blur(img: &GrayImage, r: usize) -> Vec<f32> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let src: Vec<f32> = img.as_raw().iter().map(|&v| v as f32).collect();
    let pass = |src: &[f32], len: usize, count: usize, stride: usize, step: usize| -> Vec<f32> {
        let mut out = vec![0.0; src.len()];
        for line in 0..count {
            let base = line * stride;
            for k in 0..len {
                let lo = k.saturating_sub(r);
                let hi = (k + r).min(len - 1);
                let s: f32 = (lo..=hi).map(|m| src[base + m * step]).sum();
                out[base + k * step] = s / (hi - lo + 1) as f32;
            }
        }
        out
    };
    let horiz = pass(&src, w, h, w, 1);
    pass(&horiz, h, w, 1, w)
}

#[cfg(test)]
/// Otsu's threshold of 8-bit values: the t maximising the between-class variance of
/// {v ≤ t} and {v > t} (imageproc's `otsu_level`; its sums are u32, so the caller keeps
/// images under 16 MP: [`super::input::WORK_PIXELS`]).
pub(crate) fn otsu(values: &[u8]) -> u8 {
    let len = u32::try_from(values.len()).unwrap_or(u32::MAX);
    GrayImage::from_raw(len, 1, values.to_vec())
        .map_or(0, |img| imageproc::contrast::otsu_level(&img))
}

impl Mask {
    /// The mask as an 8-bit image (set = 255).
    pub(crate) fn to_image(&self) -> GrayImage {
        let raw = self.px.iter().map(|&b| if b { 255 } else { 0 }).collect();
        GrayImage::from_raw(self.w as u32, self.h as u32, raw).unwrap_or_default()
    }
    /// The non-zero pixels of an 8-bit image.
    pub(crate) fn from_image(img: &GrayImage) -> Mask {
        let px = img.as_raw().iter().map(|&v| v > 0).collect();
        Mask { w: img.width() as usize, h: img.height() as usize, px }
    }
}

/// Opening then closing with square structuring elements of radius `open` and `close`
/// (imageproc's L∞ morphology; pixels outside the image neither erode nor dilate).
pub fn clean(m: &Mask, open: usize, close: usize) -> Mask {
    let mut img = m.to_image();
    let radius = |r: usize| u8::try_from(r).unwrap_or(u8::MAX);
    if open > 0 {
        imageproc::morphology::open_mut(&mut img, Norm::LInf, radius(open));
    }
    if close > 0 {
        imageproc::morphology::close_mut(&mut img, Norm::LInf, radius(close));
    }
    Mask::from_image(&img)
}

/// Zhang–Suen thinning to a one-pixel-wide, 8-connected skeleton.
pub fn skeleton(m: &Mask) -> Mask {
    let mut m = m.clone();
    loop {
        let mut changed = false;
        for pass in 0..2 {
            let remove: Vec<usize> = (0..m.px.len()).filter(|&i| removable(&m, i, pass)).collect();
            changed |= !remove.is_empty();
            for i in remove {
                m.px[i] = false;
            }
        }
        if !changed {
            return m;
        }
    }
}

/// Whether Zhang–Suen's sub-iteration `pass` (0 or 1) deletes the set pixel `i`.
fn removable(m: &Mask, i: usize, pass: usize) -> bool {
    if !m.px[i] {
        return false;
    }
    let (x, y) = ((i % m.w) as isize, (i / m.w) as isize);
    // P2..P9 clockwise from north.
    let n = [
        m.get(x, y - 1),
        m.get(x + 1, y - 1),
        m.get(x + 1, y),
        m.get(x + 1, y + 1),
        m.get(x, y + 1),
        m.get(x - 1, y + 1),
        m.get(x - 1, y),
        m.get(x - 1, y - 1),
    ];
    let b = n.iter().filter(|&&v| v).count();
    let a = (0..8).filter(|&k| !n[k] && n[(k + 1) % 8]).count();
    let (p2, p4, p6, p8) = (n[0], n[2], n[4], n[6]);
    let cond = if pass == 0 { !(p4 && p6 && (p2 || p8)) } else { !(p2 && p8 && (p4 || p6)) };
    (2..=6).contains(&b) && a == 1 && cond
}

/// Sand mask of a photo: a small blur merges the grains, a large blur estimates the plate's
/// uneven lighting, Otsu thresholds their difference and the minority class is the sand.
/// Returns (mask, threshold, sand_is_dark).
pub(crate) fn sand_mask(img: &GrayImage, p: &PhotoParams) -> (Mask, u8, bool) {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let side = w.min(h) as f64;
    let small = box_blur(img, ((side * p.blur).round() as usize).max(1));
    let large = box_blur(img, ((side * p.background).round() as usize).max(2));
    let diff: Vec<u8> = small
        .iter()
        .zip(&large)
        .map(|(s, l)| (128.0 + s - l).round().clamp(0.0, 255.0) as u8)
        .collect();
    let diff = GrayImage::from_raw(img.width(), img.height(), diff).unwrap_or_default();
    let t = imageproc::contrast::otsu_level(&diff);
    let bright = diff.as_raw().iter().filter(|&&v| v > t).count();
    let sand_is_dark = bright * 2 > w * h;
    let px = diff.as_raw().iter().map(|&v| if sand_is_dark { v <= t } else { v > t }).collect();
    (Mask { w, h, px }, t, sand_is_dark)
}
