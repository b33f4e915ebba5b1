//! Flat-field correction of the rectified view before it is thresholded: uneven light (a lamp
//! to one side, vignetting) makes the plate's own grey level drift across the photo by more
//! than a small part's contrast covers pixels, and Otsu then splits the drift, not part from
//! plate. The plate's background is fitted by a quadratic surface in (x, y) to a grid of
//! samples, robustly (samples farther than 3 robust σ from the fit, the parts among them, are
//! dropped and the surface refitted), and the view is divided by it: light multiplies what
//! the plate and the parts reflect, so dividing it out leaves both at their own levels.
//!
//! The plate is the majority of the view (the threshold relies on that too), so the robust fit
//! settles on it whichever polarity the parts have. The division moves no edge the fit could
//! see: the surface varies over the whole plate, an edge over a pixel.

use image::{GrayImage, Luma};
use nalgebra::{SMatrix, SVector};

/// Grid step (px) of the samples the surface is fitted to.
const STEP_PX: u32 = 6;
/// Robust refits after the first.
const PASSES: usize = 4;
/// Samples within this many robust σ of the surface are background.
const KEEP_SIGMA: f64 = 3.0;
/// …and always within this many grey levels (the noise of an evenly lit plate).
const KEEP_FLOOR: f64 = 4.0;

/// Terms of the surface at normalised position (u, v) ∈ [−1, 1]².
fn terms(u: f64, v: f64) -> SVector<f64, 6> {
    SVector::<f64, 6>::from([1.0, u, v, u * u, u * v, v * v])
}

/// The least-squares surface through the samples `(terms, grey)` whose flag is set.
fn fit(samples: &[(SVector<f64, 6>, f64)], keep: &[bool]) -> Option<SVector<f64, 6>> {
    let mut a = SMatrix::<f64, 6, 6>::zeros();
    let mut b = SVector::<f64, 6>::zeros();
    for ((t, g), _) in samples.iter().zip(keep).filter(|(_, k)| **k) {
        a += t * t.transpose();
        b += t * *g;
    }
    a.lu().solve(&b)
}

/// The median of `v` (reordered).
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// The background surface of `img` inside a margin of `margin` px: coefficients of [`terms`].
fn background(img: &GrayImage, margin: u32) -> Option<SVector<f64, 6>> {
    let (w, h) = img.dimensions();
    let norm = |x: u32, y: u32| {
        let u = 2.0 * (f64::from(x) + 0.5) / f64::from(w) - 1.0;
        (u, 2.0 * (f64::from(y) + 0.5) / f64::from(h) - 1.0)
    };
    let mut samples = Vec::new();
    for y in (margin..h.saturating_sub(margin)).step_by(STEP_PX as usize) {
        for x in (margin..w.saturating_sub(margin)).step_by(STEP_PX as usize) {
            let (u, v) = norm(x, y);
            samples.push((terms(u, v), f64::from(img.get_pixel(x, y)[0])));
        }
    }
    if samples.len() < 24 {
        return None;
    }
    let mut keep = vec![true; samples.len()];
    let mut c = fit(&samples, &keep)?;
    for _ in 0..PASSES {
        let r: Vec<f64> = samples.iter().map(|(t, g)| g - c.dot(t)).collect();
        let mut dev: Vec<f64> = r.clone();
        let mid = median(&mut dev);
        let mut abs: Vec<f64> = r.iter().map(|x| (x - mid).abs()).collect();
        let sigma = 1.4826 * median(&mut abs);
        let limit = (KEEP_SIGMA * sigma).max(KEEP_FLOOR);
        keep = r.iter().map(|x| (x - mid).abs() <= limit).collect();
        c = fit(&samples, &keep)?;
    }
    Some(c)
}

/// `img` with its background divided out (rescaled to the background's mean level), or a copy
/// when no background can be fitted (a view too small to sample).
pub fn flatten(img: &GrayImage, margin: u32) -> GrayImage {
    let Some(c) = background(img, margin) else { return img.clone() };
    let (w, h) = img.dimensions();
    // The mean of the surface over the view: the constant term plus the squares' means (1/3).
    let level = c[0] + (c[3] + c[5]) / 3.0;
    if level.partial_cmp(&1.0) != Some(std::cmp::Ordering::Greater) {
        return img.clone();
    }
    let mut out = GrayImage::new(w, h);
    for y in 0..h {
        let v = 2.0 * (f64::from(y) + 0.5) / f64::from(h) - 1.0;
        for x in 0..w {
            let u = 2.0 * (f64::from(x) + 0.5) / f64::from(w) - 1.0;
            let bg = c.dot(&terms(u, v)).max(0.05 * level);
            let g = f64::from(img.get_pixel(x, y)[0]) * level / bg;
            out.put_pixel(x, y, Luma([g.round().clamp(0.0, 255.0) as u8]));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plate whose light falls 40 % across, with a dark square on it: after the correction
    /// the plate is level to a grey level and the square keeps its contrast.
    #[test]
    fn a_light_gradient_is_divided_out_and_the_part_kept() {
        let light =
            |x: u32, y: u32| 1.0 - 0.4 * (0.6 * f64::from(x) / 400.0 + 0.4 * f64::from(y) / 300.0);
        let part = |x: u32, y: u32| (250..290).contains(&x) && (100..130).contains(&y);
        let img = GrayImage::from_fn(400, 300, |x, y| {
            let r = if part(x, y) { 55.0 } else { 205.0 };
            Luma([(r * light(x, y)).round() as u8])
        });
        let flat = flatten(&img, 2);
        let plate: Vec<u8> =
            flat.enumerate_pixels().filter(|(x, y, _)| !part(*x, *y)).map(|p| p.2[0]).collect();
        let (lo, hi) = (plate.iter().min().unwrap(), plate.iter().max().unwrap());
        assert!(hi - lo <= 2, "plate {lo}..{hi}");
        let inside = flat.get_pixel(270, 115)[0];
        let ratio = f64::from(inside) / f64::from(plate[0]);
        assert!((ratio - 55.0 / 205.0).abs() < 0.02, "{inside} / {}", plate[0]);
    }
}
