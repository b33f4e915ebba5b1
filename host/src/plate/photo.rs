//! Chladni photo → node lines: straight lines, then curved nodes as polylines.
//!
//! Pipeline: box blur (merges sand-grain texture) minus a wide box blur (uneven lighting) →
//! Otsu threshold → sand = the minority class
//! (so light sand on a dark plate and dark sand on a light plate both work) → morphological
//! opening (drops stray grains) and closing (fills gaps) → Zhang–Suen skeleton → Hough
//! transform on the skeleton in plate coordinates → each peak refined by total least squares
//! over the skeleton pixels within a band, its pixels removed, repeat (a bowed candidate is a
//! piece of a curve and is skipped) → the skeleton pixels left over traced into chains,
//! simplified by Douglas–Peucker (submodule `curves`).
//!
//! The image must show exactly the plate, cropped to its edges and not rotated: image
//! columns map to x ∈ [0, W], rows to y ∈ [H, 0] (the top row is y = H).
//! A line is reported as `angle_deg` ∈ [0, 180) (its direction, CCW from the plate's +x) and
//! `offset_mm` = n̂ · (p − c), the signed distance from the plate centre c to the line, with
//! n̂ = (−sin α, cos α) the direction turned +90°.

use image::GrayImage;

use super::contour::Polyline;

mod coarse;
#[cfg(test)]
mod curve_tests;
mod curves;
pub mod rectify;
pub use curves::{Curve, douglas_peucker, turning};

/// Tuning of the pipeline.
#[derive(Debug, Clone)]
pub struct Params {
    /// Box blur radius as a fraction of the image's smaller side.
    pub blur: f64,
    /// Radius of the lighting-estimate blur, as a fraction of the smaller side.
    pub background: f64,
    /// Opening radius (pixels).
    pub open_px: usize,
    /// Closing radius (pixels).
    pub close_px: usize,
    /// Shortest line accepted, as a fraction of the plate's smaller side.
    pub min_length: f64,
    /// Half-width of the band (pixels) that collects a line's skeleton pixels.
    pub band_px: f64,
    /// Most lines looked for.
    pub max_lines: usize,
    /// Largest bow (pixels) of a line candidate's pixels about the fitted line; a bigger bow
    /// means a curved node, which is left for the curve tracer.
    pub max_sagitta_px: f64,
    /// Douglas–Peucker tolerance (pixels) when simplifying a curved node's pixel chain.
    pub simplify_px: f64,
    /// Side branches of the skeleton shorter than this (pixels) are sand lumps, not nodes.
    pub spur_px: usize,
    /// Tightest mean bend radius of a curved node, as a fraction of the plate's smaller side:
    /// chains that turn more per length (measured on the chain simplified at twice
    /// `simplify_px`) zig-zag through scattered grains.
    pub min_radius: f64,
    /// Grain diameter (pixels): above 2 px the grains (lentils) are found as bands of
    /// separate disks ([`coarse`]) instead of by threshold and skeleton.
    pub grain_px: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            blur: 0.006,
            background: 0.08,
            open_px: 1,
            close_px: 2,
            min_length: 0.25,
            band_px: 3.0,
            max_lines: 6,
            max_sagitta_px: 1.0,
            simplify_px: 1.5,
            spur_px: 10,
            min_radius: 0.1,
            grain_px: 0.0,
        }
    }
}

/// A straight node line found in a photo.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    /// Direction, degrees CCW from +x, in [0, 180).
    pub angle_deg: f64,
    /// Signed distance from the plate centre (mm), along n̂ = (−sin α, cos α).
    pub offset_mm: f64,
    /// Extent of the supporting skeleton pixels along the line (mm).
    pub length_mm: f64,
    /// RMS distance of those pixels from the line (mm).
    pub rms_mm: f64,
    /// Number of skeleton pixels on the line.
    pub pixels: usize,
    /// Ends of the stretch its pixels cover (plate coordinates, mm).
    pub ends_mm: [[f64; 2]; 2],
}

/// Everything the pipeline found.
#[derive(Debug, Clone)]
pub struct Found {
    /// Otsu threshold (0–255) on the lighting-corrected image (128 = local background).
    pub threshold: u8,
    /// Whether the sand is darker than the plate.
    pub sand_is_dark: bool,
    /// Skeleton pixel count.
    pub skeleton_pixels: usize,
    /// Skeleton pixels on no reported line or curve (debris, short bits, side branches).
    pub unexplained_pixels: usize,
    /// Lines, strongest first.
    pub lines: Vec<Line>,
    /// Curved nodes (skeleton chains off the lines), longest first.
    pub curves: Vec<Curve>,
    /// Plate size (mm).
    pub size_mm: [f64; 2],
    /// Mean pixel size (mm).
    pub pixel_mm: f64,
}

/// Binary image: `true` = set.
#[derive(Debug, Clone, PartialEq)]
pub struct Mask {
    /// Width.
    pub w: usize,
    /// Height.
    pub h: usize,
    /// Row-major pixels.
    pub px: Vec<bool>,
}

impl Mask {
    fn get(&self, x: isize, y: isize) -> bool {
        x >= 0
            && y >= 0
            && (x as usize) < self.w
            && (y as usize) < self.h
            && self.px[y as usize * self.w + x as usize]
    }
    /// Number of set pixels.
    pub fn count(&self) -> usize {
        self.px.iter().filter(|&&b| b).count()
    }
}

/// Separable box blur with radius `r` (edges clamp).
pub fn box_blur(img: &GrayImage, r: usize) -> Vec<f32> {
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

/// Otsu's threshold of 8-bit values: the t maximising the between-class variance of
/// {v ≤ t} and {v > t}.
pub fn otsu(values: &[u8]) -> u8 {
    let mut hist = [0u64; 256];
    for &v in values {
        hist[v as usize] += 1;
    }
    let total = values.len() as f64;
    let sum_all: f64 = hist.iter().enumerate().map(|(i, &c)| i as f64 * c as f64).sum();
    let (mut w0, mut sum0, mut best, mut best_t) = (0.0, 0.0, -1.0, 0u8);
    for (t, &c) in hist.iter().enumerate() {
        w0 += c as f64;
        sum0 += t as f64 * c as f64;
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let m0 = sum0 / w0;
        let m1 = (sum_all - sum0) / w1;
        let between = w0 * w1 * (m0 - m1) * (m0 - m1);
        if between > best {
            best = between;
            best_t = t as u8;
        }
    }
    best_t
}

fn morph(m: &Mask, r: usize, dilate: bool) -> Mask {
    let r = r as isize;
    let mut out = m.clone();
    for y in 0..m.h as isize {
        for x in 0..m.w as isize {
            let mut hit = !dilate;
            'n: for dy in -r..=r {
                for dx in -r..=r {
                    let inside = x + dx >= 0
                        && y + dy >= 0
                        && ((x + dx) as usize) < m.w
                        && ((y + dy) as usize) < m.h;
                    if !inside {
                        continue;
                    }
                    let v = m.get(x + dx, y + dy);
                    if dilate && v {
                        hit = true;
                        break 'n;
                    }
                    if !dilate && !v {
                        hit = false;
                        break 'n;
                    }
                }
            }
            out.px[y as usize * m.w + x as usize] = hit;
        }
    }
    out
}

/// Opening (erode, dilate) then closing (dilate, erode) with square structuring elements.
pub fn clean(m: &Mask, open: usize, close: usize) -> Mask {
    let mut m = m.clone();
    if open > 0 {
        m = morph(&morph(&m, open, false), open, true);
    }
    if close > 0 {
        m = morph(&morph(&m, close, true), close, false);
    }
    m
}

/// Zhang–Suen thinning to a one-pixel-wide, 8-connected skeleton.
pub fn skeleton(m: &Mask) -> Mask {
    let mut m = m.clone();
    loop {
        let mut changed = false;
        for pass in 0..2 {
            let mut remove = Vec::new();
            for y in 0..m.h as isize {
                for x in 0..m.w as isize {
                    if !m.get(x, y) {
                        continue;
                    }
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
                    let cond = if pass == 0 {
                        !(p4 && p6 && (p2 || p8))
                    } else {
                        !(p2 && p8 && (p4 || p6))
                    };
                    if (2..=6).contains(&b) && a == 1 && cond {
                        remove.push(y as usize * m.w + x as usize);
                    }
                }
            }
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

/// Sand mask of a photo: a small blur merges the grains, a large blur estimates the plate's
/// uneven lighting, Otsu thresholds their difference and the minority class is the sand.
/// Returns (mask, threshold, sand_is_dark).
pub fn sand_mask(img: &GrayImage, p: &Params) -> (Mask, u8, bool) {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let side = w.min(h) as f64;
    let small = box_blur(img, ((side * p.blur).round() as usize).max(1));
    let large = box_blur(img, ((side * p.background).round() as usize).max(2));
    let diff: Vec<u8> = small
        .iter()
        .zip(&large)
        .map(|(s, l)| (128.0 + s - l).round().clamp(0.0, 255.0) as u8)
        .collect();
    let t = otsu(&diff);
    let bright = diff.iter().filter(|&&v| v > t).count();
    let sand_is_dark = bright * 2 > diff.len();
    let px = diff.iter().map(|&v| if sand_is_dark { v <= t } else { v > t }).collect();
    (Mask { w, h, px }, t, sand_is_dark)
}

/// Total-least-squares line through points: (centroid, unit direction, rms distance).
fn tls(pts: &[[f64; 2]]) -> ([f64; 2], [f64; 2], f64) {
    let n = pts.len() as f64;
    let cx = pts.iter().map(|p| p[0]).sum::<f64>() / n;
    let cy = pts.iter().map(|p| p[1]).sum::<f64>() / n;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in pts {
        let (dx, dy) = (p[0] - cx, p[1] - cy);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    // Principal axis of the 2×2 scatter matrix.
    let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let d = [theta.cos(), theta.sin()];
    let rms = (pts.iter().map(|p| (-(p[0] - cx) * d[1] + (p[1] - cy) * d[0]).powi(2)).sum::<f64>()
        / n)
        .sqrt();
    ([cx, cy], d, rms)
}

/// Pixel ↔ plate geometry of an image covering the plate exactly.
#[derive(Debug, Clone, Copy)]
struct Frame {
    w: usize,
    h: usize,
    size_mm: [f64; 2],
    /// Mean pixel size (mm).
    pix: f64,
}

impl Frame {
    fn new(w: usize, h: usize, size_mm: [f64; 2]) -> Frame {
        let pix = 0.5 * (size_mm[0] / w as f64 + size_mm[1] / h as f64);
        Frame { w, h, size_mm, pix }
    }
    /// Plate coordinates (mm, origin at the bottom-left corner) of pixel `i`'s centre.
    fn plate(&self, i: usize) -> [f64; 2] {
        let (x, y) = ((i % self.w) as f64 + 0.5, (i / self.w) as f64 + 0.5);
        [x * self.size_mm[0] / self.w as f64, self.size_mm[1] - y * self.size_mm[1] / self.h as f64]
    }
    /// Shortest node accepted (mm).
    fn min_length_mm(&self, p: &Params) -> f64 {
        p.min_length * self.size_mm[0].min(self.size_mm[1])
    }
}

/// Finds straight node lines, then curved nodes (as polylines) among the skeleton pixels left
/// over, in a photo of the plate (`size_mm` = [W, H]).
pub fn find_lines(img: &GrayImage, size_mm: [f64; 2], p: &Params) -> Found {
    if p.grain_px > 2.0 {
        return coarse::find(img, size_mm, p, p.grain_px);
    }
    let (mask, threshold, sand_is_dark) = sand_mask(img, p);
    let sk = skeleton(&clean(&mask, p.open_px, p.close_px));
    let frame = Frame::new(sk.w, sk.h, size_mm);
    let (lines, rest) = straight_lines(&sk, &frame, p);
    let curves = curves::trace(&rest, &frame, p);
    let on_curves: usize = curves.iter().map(|c| c.pixels).sum();
    Found {
        threshold,
        sand_is_dark,
        skeleton_pixels: sk.count(),
        unexplained_pixels: rest.count().saturating_sub(on_curves),
        lines,
        curves,
        size_mm,
        pixel_mm: frame.pix,
    }
}

/// Hough + total least squares on the skeleton: the straight lines, and the skeleton with
/// their pixels removed.
fn straight_lines(sk: &Mask, frame: &Frame, p: &Params) -> (Vec<Line>, Mask) {
    let size_mm = frame.size_mm;
    let pix = frame.pix;
    let centre = [size_mm[0] / 2.0, size_mm[1] / 2.0];
    // Skeleton points in plate coordinates relative to the centre, with their pixel index.
    let mut ids: Vec<usize> = (0..sk.px.len()).filter(|&i| sk.px[i]).collect();
    let mut pts: Vec<[f64; 2]> = ids
        .iter()
        .map(|&i| {
            let q = frame.plate(i);
            [q[0] - centre[0], q[1] - centre[1]]
        })
        .collect();
    let mut rest = sk.clone();
    let n_theta = 360usize;
    let rho_max = 0.5 * size_mm[0].hypot(size_mm[1]);
    let n_rho = (2.0 * rho_max / pix).ceil() as usize + 1;
    let trig: Vec<(f64, f64)> = (0..n_theta)
        .map(|k| {
            let a = std::f64::consts::PI * k as f64 / n_theta as f64;
            (a.sin(), a.cos())
        })
        .collect();
    let min_pixels = (frame.min_length_mm(p) / pix) as usize;
    let band = p.band_px * pix;
    let mut lines = Vec::new();
    // Curved candidates are dropped from the vote without ending the search; the cap keeps
    // the loop finite however many there are.
    let mut tries = 0;
    while lines.len() < p.max_lines && tries < 4 * p.max_lines && pts.len() >= min_pixels.max(2) {
        tries += 1;
        // Hough: line at direction α has normal n̂ = (−sin α, cos α), offset ρ = n̂·p.
        let mut acc = vec![0u32; n_theta * n_rho];
        for q in &pts {
            for (k, &(s, c)) in trig.iter().enumerate() {
                let rho = -s * q[0] + c * q[1];
                let r = ((rho + rho_max) / pix).round() as usize;
                acc[k * n_rho + r.min(n_rho - 1)] += 1;
            }
        }
        let (best, &votes) = acc.iter().enumerate().max_by_key(|&(_, v)| *v).unwrap_or((0, &0));
        if (votes as usize) < min_pixels {
            break;
        }
        let a = std::f64::consts::PI * (best / n_rho) as f64 / n_theta as f64;
        let rho = (best % n_rho) as f64 * pix - rho_max;
        let (mut origin, mut dir) = ([-a.sin() * rho, a.cos() * rho], [a.cos(), a.sin()]);
        let mut inliers: Vec<usize> = Vec::new();
        let mut rms = 0.0;
        for _ in 0..3 {
            inliers = (0..pts.len())
                .filter(|&i| {
                    (-(pts[i][0] - origin[0]) * dir[1] + (pts[i][1] - origin[1]) * dir[0]).abs()
                        <= band
                })
                .collect();
            if inliers.len() < 2 {
                break;
            }
            let sel: Vec<[f64; 2]> = inliers.iter().map(|&i| pts[i]).collect();
            (origin, dir, rms) = tls(&sel);
        }
        if inliers.len() < min_pixels {
            break;
        }
        let sel: Vec<[f64; 2]> = inliers.iter().map(|&i| pts[i]).collect();
        let straight = sagitta(&sel, origin, dir) <= p.max_sagitta_px * pix;
        if straight {
            lines.push(line_of(&sel, origin, dir, rms, centre));
        }
        let mut keep = vec![true; pts.len()];
        for &i in &inliers {
            keep[i] = false;
            if straight {
                rest.px[ids[i]] = false;
            }
        }
        let mut k = 0;
        pts.retain(|_| {
            k += 1;
            keep[k - 1]
        });
        let mut k = 0;
        ids.retain(|_| {
            k += 1;
            keep[k - 1]
        });
    }
    (lines, rest)
}

/// Bow of points about a fitted line: the least-squares parabola e = a + b·s + c·s² of their
/// offsets e against their positions s along the line, evaluated as |c|·(L/2)² over their
/// extent L. A tangent band of a curved node has a bow of a pixel or more, a straight node
/// only its pixel noise.
fn sagitta(pts: &[[f64; 2]], origin: [f64; 2], dir: [f64; 2]) -> f64 {
    let se: Vec<(f64, f64)> = pts
        .iter()
        .map(|q| {
            let (dx, dy) = (q[0] - origin[0], q[1] - origin[1]);
            (dx * dir[0] + dy * dir[1], -dx * dir[1] + dy * dir[0])
        })
        .collect();
    let lo = se.iter().map(|v| v.0).fold(f64::MAX, f64::min);
    let hi = se.iter().map(|v| v.0).fold(f64::MIN, f64::max);
    let half = 0.5 * (hi - lo);
    if half <= 0.0 {
        return 0.0;
    }
    // Fit in u = (s − mid)/half ∈ [−1, 1] for conditioning; then the bow is |c_u|.
    let mid = 0.5 * (hi + lo);
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut r = nalgebra::Vector3::<f64>::zeros();
    for &(s, e) in &se {
        let u = (s - mid) / half;
        let b = nalgebra::Vector3::new(1.0, u, u * u);
        m += b * b.transpose();
        r += b * e;
    }
    m.lu().solve(&r).map_or(0.0, |c| c[2].abs())
}

/// The reported line of a fit (centre-relative `origin`, unit `dir`) and its pixels.
fn line_of(sel: &[[f64; 2]], origin: [f64; 2], dir: [f64; 2], rms: f64, centre: [f64; 2]) -> Line {
    let proj: Vec<f64> = sel.iter().map(|q| q[0] * dir[0] + q[1] * dir[1]).collect();
    let lo = proj.iter().copied().fold(f64::MAX, f64::min);
    let hi = proj.iter().copied().fold(f64::MIN, f64::max);
    let o = origin[0] * dir[0] + origin[1] * dir[1];
    let end = |t: f64| {
        [origin[0] + (t - o) * dir[0] + centre[0], origin[1] + (t - o) * dir[1] + centre[1]]
    };
    let mut alpha = dir[1].atan2(dir[0]).to_degrees();
    if alpha < 0.0 {
        alpha += 180.0;
    }
    if alpha >= 180.0 {
        alpha -= 180.0;
    }
    let ar = alpha.to_radians();
    let offset = -ar.sin() * origin[0] + ar.cos() * origin[1];
    Line {
        angle_deg: alpha,
        offset_mm: offset,
        length_mm: hi - lo,
        rms_mm: rms,
        pixels: sel.len(),
        ends_mm: [end(lo), end(hi)],
    }
}

/// Default gap closed by [`Found::nodes`], as a fraction of the plate's smaller side.
pub const DEFAULT_SNAP: f64 = 0.1;

impl Line {
    /// Angle (degrees) and offset (mm) differences, both absolute, to the line
    /// (`angle_deg`, `offset_mm`) in the same convention. A line's direction is only defined
    /// modulo 180°, and turning it by 180° reverses the normal its offset is measured along,
    /// so the angle difference is folded into [−90°, 90°] and the offset flipped with it.
    pub fn difference(&self, angle_deg: f64, offset_mm: f64) -> (f64, f64) {
        let mut da = self.angle_deg - angle_deg;
        let mut off = self.offset_mm;
        while da > 90.0 {
            da -= 180.0;
            off = -off;
        }
        while da < -90.0 {
            da += 180.0;
            off = -off;
        }
        (da.abs(), (off - offset_mm).abs())
    }
}

impl Found {
    /// Node geometry as polylines (plate coordinates, mm): each line as the segment its pixels
    /// cover, each curve as found; an open end within `snap` (fraction of the plate's smaller
    /// side) of the plate edge or of another node is joined to its nearest point there. Line
    /// bands, the image border and thin patches of sand leave such gaps, and a real node never
    /// ends inside the plate.
    pub fn nodes(&self, snap: f64) -> Vec<Polyline> {
        let raw: Vec<Polyline> = self
            .lines
            .iter()
            .map(|l| l.ends_mm.to_vec())
            .chain(self.curves.iter().map(|c| c.points.clone()))
            .collect();
        super::node_field::snap_ends(
            &raw,
            self.size_mm,
            snap * self.size_mm[0].min(self.size_mm[1]),
        )
    }
}

/// The photo at half brightness with `nodes` (plate coordinates, mm) drawn over it in white,
/// 2 px wide: for checking a result by eye (grey, so the PNG stays small).
pub fn overlay(img: &GrayImage, nodes: &[Polyline], size_mm: [f64; 2]) -> GrayImage {
    let (w, h) = img.dimensions();
    let mut out = GrayImage::from_fn(w, h, |x, y| image::Luma([img.get_pixel(x, y)[0] / 2]));
    let (sx, sy) = (w as f64 / size_mm[0], h as f64 / size_mm[1]);
    for seg in nodes.iter().flat_map(|l| l.windows(2)) {
        let (a, b) = (
            [seg[0][0] * sx, (size_mm[1] - seg[0][1]) * sy],
            [seg[1][0] * sx, (size_mm[1] - seg[1][1]) * sy],
        );
        let n = ((b[0] - a[0]).hypot(b[1] - a[1]) * 2.0).ceil() as usize + 1;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let (x, y) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
            for (dx, dy) in [(0.0, 0.0), (0.5, 0.0), (-0.5, 0.0), (0.0, 0.5), (0.0, -0.5)] {
                let (px, py) = ((x + dx).floor(), (y + dy).floor());
                if px >= 0.0 && py >= 0.0 && px < w as f64 && py < h as f64 {
                    out.put_pixel(px as u32, py as u32, image::Luma([255]));
                }
            }
        }
    }
    out
}

/// Synthetic Chladni photos for tests and docs: sand grains scattered around known node lines
/// and curves on a plate with uneven lighting and sensor noise.
pub mod synth {
    use image::{GrayImage, Luma};

    use crate::plate::contour::{Polyline, distance_to};

    /// Small deterministic PRNG (SplitMix64).
    #[derive(Debug, Clone)]
    pub struct Rng(pub u64);
    impl Rng {
        /// Next 64 random bits.
        pub fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        /// Uniform in [0, 1).
        pub fn uniform(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// What to draw.
    #[derive(Debug, Clone)]
    pub struct Scene {
        /// Image size (pixels).
        pub px: (u32, u32),
        /// Plate size (mm).
        pub size_mm: [f64; 2],
        /// Node lines (angle_deg, offset_mm) in the convention of [`super::Line`].
        pub lines: Vec<(f64, f64)>,
        /// Curved nodes: polylines in plate coordinates (mm, origin at the bottom-left corner).
        pub curves: Vec<Polyline>,
        /// Width (1σ, mm) of the sand band around a node.
        pub sand_sigma_mm: f64,
        /// Peak grain density on a node (grains per pixel).
        pub density: f64,
        /// Density of stray grains elsewhere.
        pub stray: f64,
        /// Pixel noise amplitude (grey levels).
        pub noise: f64,
        /// Dark sand on a light plate instead of light sand on a dark plate.
        pub dark_sand: bool,
        /// Seed.
        pub seed: u64,
        /// Grain diameter (mm): 0 draws single-pixel grains (sand); lentils are ~4 mm disks,
        /// scattered so that they cover the same fraction of the plate.
        pub grain_mm: f64,
    }

    impl Scene {
        /// The tests' standard photo: 360×240 px of a 300×200 mm plate, light sand in a
        /// 3 mm band (σ) around the nodes, 2 % stray grains, ±25 grey levels of noise.
        pub fn standard(lines: Vec<(f64, f64)>, curves: Vec<Polyline>, seed: u64) -> Scene {
            Scene {
                px: (360, 240),
                size_mm: [300.0, 200.0],
                lines,
                curves,
                sand_sigma_mm: 3.0,
                density: 0.6,
                stray: 0.02,
                noise: 25.0,
                dark_sand: false,
                seed,
                grain_mm: 0.0,
            }
        }

        /// The tests' lentil photo: 720×480 px of the 300×200 mm plate, 4 mm lentils (10 px)
        /// with 80 % coverage on the node, bands σ = 5 mm wide, 1 % stray lentils.
        pub fn lentils(lines: Vec<(f64, f64)>, curves: Vec<Polyline>, seed: u64) -> Scene {
            Scene {
                px: (720, 480),
                grain_mm: 4.0,
                sand_sigma_mm: 5.0,
                density: 0.8,
                stray: 0.01,
                ..Scene::standard(lines, curves, seed)
            }
        }
    }

    /// Fraction of the plate covered by grains at distance `d` (mm) from the nearest node.
    fn coverage(s: &Scene, d: f64) -> f64 {
        s.density * (-0.5 * (d / s.sand_sigma_mm).powi(2)).exp() + s.stray
    }

    /// Distance (mm) from plate point (x, y) (origin at the centre) to the nearest node.
    fn node_distance(s: &Scene, x: f64, y: f64) -> f64 {
        s.lines
            .iter()
            .map(|&(a, o)| {
                let a = a.to_radians();
                (-a.sin() * x + a.cos() * y - o).abs()
            })
            .fold(f64::MAX, f64::min)
            .min(distance_to([x + s.size_mm[0] / 2.0, y + s.size_mm[1] / 2.0], &s.curves))
    }

    /// Lentils: disks of `grain_mm` whose centres fall with the density that covers the
    /// same fraction of the plate as single-pixel sand would (`None` for sand).
    fn lentil_mask(s: &Scene, rng: &mut Rng) -> Option<Vec<bool>> {
        if s.grain_mm <= 0.0 {
            return None;
        }
        let (w, h) = (s.px.0 as i64, s.px.1 as i64);
        let (sx, sy) = (s.size_mm[0] / w as f64, s.size_mm[1] / h as f64);
        let r = 0.5 * s.grain_mm;
        let disk_px = std::f64::consts::PI * r * r / (sx * sy);
        let (rx, ry) = ((r / sx).ceil() as i64, (r / sy).ceil() as i64);
        let mut mask = vec![false; (w * h) as usize];
        for row in 0..h {
            for col in 0..w {
                let x = (col as f64 + 0.5) * sx - s.size_mm[0] / 2.0;
                let y = s.size_mm[1] / 2.0 - (row as f64 + 0.5) * sy;
                if rng.uniform() >= coverage(s, node_distance(s, x, y)) / disk_px {
                    continue;
                }
                for j in (row - ry).max(0)..(row + ry + 1).min(h) {
                    for i in (col - rx).max(0)..(col + rx + 1).min(w) {
                        if ((i - col) as f64 * sx).hypot((j - row) as f64 * sy) <= r {
                            mask[(j * w + i) as usize] = true;
                        }
                    }
                }
            }
        }
        Some(mask)
    }

    /// Renders the scene.
    pub fn render(s: &Scene) -> GrayImage {
        let mut rng = Rng(s.seed);
        let (w, h) = s.px;
        let (sx, sy) = (s.size_mm[0] / w as f64, s.size_mm[1] / h as f64);
        let lentils = lentil_mask(s, &mut rng);
        let mut img = GrayImage::new(w, h);
        for row in 0..h {
            for col in 0..w {
                let x = (col as f64 + 0.5) * sx - s.size_mm[0] / 2.0;
                let y = s.size_mm[1] / 2.0 - (row as f64 + 0.5) * sy;
                // Lighting gradient across the plate plus noise.
                let light = 70.0 + 30.0 * (col as f64 / w as f64) - 15.0 * (row as f64 / h as f64);
                let noise = s.noise * (rng.uniform() + rng.uniform() + rng.uniform() - 1.5);
                let grain = match &lentils {
                    Some(m) => m[(row * w + col) as usize],
                    None => rng.uniform() < coverage(s, node_distance(s, x, y)),
                };
                let v = match (grain, s.dark_sand) {
                    (false, false) => light + noise,
                    (true, false) => 190.0 + 40.0 * rng.uniform() + noise,
                    (false, true) => 255.0 - light + noise,
                    (true, true) => 40.0 + 30.0 * rng.uniform() + noise,
                };
                img.put_pixel(col, row, Luma([v.round().clamp(0.0, 255.0) as u8]));
            }
        }
        img
    }

    /// Circle arc about `centre` (mm) of radius `r` from `from_deg` to `to_deg` (CCW), as `n`
    /// segments.
    pub fn arc(centre: [f64; 2], r: f64, from_deg: f64, to_deg: f64, n: usize) -> Polyline {
        (0..=n)
            .map(|k| {
                let a = (from_deg + (to_deg - from_deg) * k as f64 / n as f64).to_radians();
                [centre[0] + r * a.cos(), centre[1] + r * a.sin()]
            })
            .collect()
    }

    /// Branch c + R(α)·(a cosh t, b sinh t), t ∈ [−t_max, t_max], as `n` segments (the
    /// hyperbola node of plate/model.rs).
    pub fn hyperbola(
        centre: [f64; 2],
        angle_deg: f64,
        ab: [f64; 2],
        t_max: f64,
        n: usize,
    ) -> Polyline {
        let (s, c) = angle_deg.to_radians().sin_cos();
        (0..=n)
            .map(|k| {
                let t = -t_max + 2.0 * t_max * k as f64 / n as f64;
                let (u, v) = (ab[0] * t.cosh(), ab[1] * t.sinh());
                [centre[0] + c * u - s * v, centre[1] + s * u + c * v]
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
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
        let found = find_lines(&render(&s), s.size_mm, &Params::default());
        assert_eq!(found.sand_is_dark, dark);
        assert_eq!(found.lines.len(), truth.len(), "{:?}", found.lines);
        for &t in &truth {
            let hit = found.lines.iter().find_map(|l| matches(l, t, s.size_mm));
            assert!(hit.is_some(), "line {t:?} not recovered: {:?}", found.lines);
            let (da, doff) = hit.unwrap_or_default();
            println!(
                "line {t:?}: angle error {da:.3}°, offset error {:.3} % of plate",
                100.0 * doff
            );
        }
    }

    #[test]
    fn otsu_splits_two_levels() {
        let v: Vec<u8> = (0..100)
            .map(|i| if i < 70 { 40 + (i % 5) as u8 } else { 200 - (i % 7) as u8 })
            .collect();
        let t = otsu(&v);
        assert!((44..194).contains(&t), "{t}");
    }

    #[test]
    fn skeleton_of_a_bar_is_thin_and_long() {
        let (w, h) = (40, 15);
        let px =
            (0..w * h).map(|i| (5..10).contains(&(i / w)) && (3..37).contains(&(i % w))).collect();
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
        let path = std::env::temp_dir()
            .join(format!("chladni-synthetic-photo-{}.png", std::process::id()));
        render(&s).save(&path).unwrap();
        let img = image::open(&path).unwrap().to_luma8();
        std::fs::remove_file(&path).ok();
        let found = find_lines(&img, s.size_mm, &Params::default());
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
        let found = find_lines(&render(&s), s.size_mm, &Params::default());
        assert!(found.lines.is_empty(), "{:?}", found.lines);
    }
}
