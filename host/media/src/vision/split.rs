//! Touching parts: a blob of about two or more parts' area is eroded step by step until it
//! falls into pieces; each piece seeds a fit of each part kind (a shift search absorbs the
//! piece's offset from the part's centroid), which must find most of that part's outline.
//! The pieces are accepted only together: each fits, no two are the same part, and their
//! areas add up to the blob's.

use image::{GrayImage, Luma};
use imageproc::distance_transform::Norm;
use imageproc::morphology::erode;
use imageproc::region_labelling::{Connectivity, connected_components};

use super::{ACCEPT_TOUCHING, AREA_TOLERANCE, Blob, Ctx, Located};

/// Most pieces a blob is split into.
const MAX_PIECES: usize = 6;

/// The blob's mask in its bounding box (1 px of border).
fn blob_mask(ctx: &Ctx, b: &Blob) -> (GrayImage, [u32; 2]) {
    let w = ctx.view.img.width() as usize;
    let [x0, y0, x1, y1] = b.bbox;
    let (ox, oy) = (x0.saturating_sub(1), y0.saturating_sub(1));
    let (bw, bh) = (x1 - ox + 3, y1 - oy + 3);
    let m = GrayImage::from_fn(bw, bh, |x, y| {
        let (gx, gy) = ((ox + x) as usize, (oy + y) as usize);
        let on = gx < w
            && gy * w + gx < ctx.view.labels.len()
            && ctx.view.labels[gy * w + gx] == b.label;
        Luma([if on { 255 } else { 0 }])
    });
    (m, [ox, oy])
}

/// Centroids (px, whole image) of the pieces of `mask` eroded by `k`, with at least `min_px`
/// pixels each.
fn pieces(mask: &GrayImage, k: u8, min_px: f64, off: [u32; 2]) -> Vec<[f64; 2]> {
    let e = erode(mask, Norm::LInf, k);
    let labels = connected_components(&e, Connectivity::Eight, Luma([0u8]));
    let n = labels.pixels().map(|p| p[0]).max().unwrap_or(0) as usize;
    let mut acc = vec![(0usize, 0.0, 0.0); n + 1];
    for (x, y, p) in labels.enumerate_pixels() {
        let a = &mut acc[p[0] as usize];
        a.0 += 1;
        a.1 += f64::from(x + off[0]) + 0.5;
        a.2 += f64::from(y + off[1]) + 0.5;
    }
    acc.iter()
        .skip(1)
        .filter(|a| a.0 as f64 >= min_px)
        .map(|a| [a.1 / a.0 as f64, a.2 / a.0 as f64])
        .collect()
}

/// The parts of a blob of touching parts, or `None` when they cannot be told apart.
pub(super) fn split(ctx: &Ctx, b: &Blob) -> Option<Vec<Located>> {
    let (mask, off) = blob_mask(ctx, b);
    let pix2 = ctx.view.pix * ctx.view.pix;
    let smallest = ctx.templates.iter().map(|t| t.area_mm2).fold(f64::MAX, f64::min) / pix2;
    let largest_r = ctx.templates.iter().map(|t| t.radius_mm).fold(0.0, f64::max) / ctx.view.pix;
    let mut k = 2u8;
    while f64::from(k) < 0.5 * largest_r && k < 40 {
        let seeds = pieces(&mask, k, 0.05 * smallest, off);
        let fits = (2..=MAX_PIECES).contains(&seeds.len());
        if let Some(found) = fits.then(|| fit_pieces(ctx, b, &seeds, i32::from(k) + 4)).flatten() {
            return Some(found);
        }
        if seeds.len() > MAX_PIECES {
            return None;
        }
        k = k.saturating_add(2);
    }
    None
}

/// Fits a part at each seed; all must fit and their areas add up to the blob's.
fn fit_pieces(ctx: &Ctx, b: &Blob, seeds: &[[f64; 2]], shift_px: i32) -> Option<Vec<Located>> {
    let mut out: Vec<Located> = Vec::new();
    let mut area = 0.0;
    for &s in seeds {
        let centre = ctx.mm(s);
        let best = (0..ctx.templates.len())
            .filter_map(|k| ctx.fit(k, b.label, centre, shift_px).map(|f| (k, f)))
            .max_by(|a, c| a.1.f.score.total_cmp(&c.1.f.score))?;
        let (k, fit) = best;
        if fit.f.score < ACCEPT_TOUCHING {
            return None;
        }
        let l = ctx.located(k, &fit, true);
        let r = ctx.templates[k].radius_mm;
        if out.iter().any(|o| (o.x_mm - l.x_mm).hypot(o.y_mm - l.y_mm) < 0.5 * r) {
            return None;
        }
        area += ctx.templates[k].area_mm2;
        out.push(l);
    }
    let blob_mm2 = b.area_px as f64 * ctx.view.pix * ctx.view.pix;
    ((area / blob_mm2 - 1.0).abs() <= AREA_TOLERANCE).then_some(out)
}

/// The part kind and count whose multiple best explains a blob's area ratios `r`.
pub(super) fn cluster_count(r: &[f64]) -> (usize, usize) {
    let mut best = (0usize, 2usize, f64::MAX);
    for (k, &x) in r.iter().enumerate() {
        let n = x.round().max(2.0);
        let err = (x / n - 1.0).abs();
        if err < best.2 {
            best = (k, n as usize, err);
        }
    }
    (best.0, best.1)
}
