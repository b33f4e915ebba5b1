//! The pose of one part in a blob: a coarse search over the orientation (and, for a piece of a
//! cluster, a few pixels of shift) of the part's outline against the blob's mask, then
//! Gauss–Newton on sub-pixel edge crossings measured along the outline's normals.
//!
//! An edge crossing is where the grey level, sampled bilinearly along the normal, passes the
//! middle of the levels found just inside and just outside the part: that point does not move
//! under a symmetric blur, and the local levels follow uneven lighting. A sample whose two
//! levels barely differ (the contact with another part, a shadow) gives no crossing and drops
//! out of the fit.

use std::cell::Cell;

use image::GrayImage;
use nalgebra::{Matrix3, Vector3};

use chladni_core::model::part::Part;

/// Half-length (px) of the grey profile read along a normal.
const PROFILE_PX: f64 = 3.0;
/// Step (px) along the profile.
const STEP_PX: f64 = 0.5;
/// Least level difference across an edge, as a fraction of the photo's part/plate contrast.
const MIN_EDGE_CONTRAST: f64 = 0.35;
/// An edge sample within this distance (px) of the fitted outline counts for the score.
pub const INLIER_PX: f64 = 0.75;
/// The mask score's inside and outside points lie this far (px) either side of the outline.
const MASK_PX: f64 = 1.5;

/// A point on a part's boundary (mm, relative to the centroid) and its outward normal.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// Position.
    pub p: [f64; 2],
    /// Unit normal pointing out of the material.
    pub n: [f64; 2],
}

/// The boundary of one face of a part, sampled about every `step_mm` (corners skipped: their
/// normal is not defined).
pub fn samples(part: &Part, step_mm: f64) -> Vec<Sample> {
    let c = part.centroid();
    let mut out = Vec::new();
    for ring in part.rings() {
        for k in 0..ring.len() {
            let (a, b) = (ring[k], ring[(k + 1) % ring.len()]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let len = dx.hypot(dy);
            // Outline CCW, holes CW: (dy, −dx) points out of the material on both.
            let n = [dy / len, -dx / len];
            let count = (len / step_mm).floor() as usize;
            let before = out.len();
            for i in 0..count {
                let t = (i as f64 + 0.5) / count as f64;
                if t * len < 1.5 * step_mm || (1.0 - t) * len < 1.5 * step_mm {
                    continue;
                }
                out.push(Sample { p: [a[0] + t * dx - c[0], a[1] + t * dy - c[1]], n });
            }
            // An edge a few steps long (a polygonised hole at a coarse pixel) keeps its
            // midpoint: skipped whole, a small hole vanishes from the fit, and a part that only
            // its hole tells from its half turn (the tab) could be posed 180° off.
            if out.len() == before && count >= 1 {
                out.push(Sample { p: [a[0] + 0.5 * dx - c[0], a[1] + 0.5 * dy - c[1]], n });
            }
        }
    }
    out
}

/// The rectified plate image as the fit sees it.
pub struct View<'a> {
    /// Rectified photo, square pixels, top row = the plate's top edge.
    pub img: &'a GrayImage,
    /// Blob labels (row-major, as the image).
    pub labels: &'a [u32],
    /// Pixel size (mm).
    pub pix: f64,
    /// Plate height (mm).
    pub h_mm: f64,
    /// +1 when parts are lighter than the plate, −1 when darker.
    pub pol: f64,
    /// Mean grey difference between part and plate pixels.
    pub contrast: f64,
    /// Outline samples the coarse search has scored on the mask (a work count, for tests).
    pub evaluated: Cell<u64>,
}

/// A pose: centroid (mm, plate frame) and orientation (rad, CCW).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Centroid.
    pub c: [f64; 2],
    /// Orientation.
    pub theta: f64,
}

/// A refined pose and how well the outline sits on the photo's edges.
#[derive(Debug, Clone, Copy)]
pub struct Fitted {
    /// The pose.
    pub pose: Pose,
    /// Fraction of the outline samples with an edge within [`INLIER_PX`].
    pub score: f64,
    /// RMS distance (px) of those edges from the outline.
    pub rms_px: f64,
}

impl Fitted {
    /// How well the outline sits on the edges, 0–1: the score, discounted by the inliers'
    /// RMS distance as a share of [`INLIER_PX`] squared. Two faces that both find every edge
    /// still differ here by how close their edges lie.
    pub fn quality(&self) -> f64 {
        self.score * (1.0 - (self.rms_px / INLIER_PX).powi(2))
    }
}

impl View<'_> {
    /// Continuous pixel coordinates (pixel i spans [i, i + 1)) of plate point `q` (mm).
    pub(crate) fn to_px(&self, q: [f64; 2]) -> [f64; 2] {
        [q[0] / self.pix, (self.h_mm - q[1]) / self.pix]
    }

    fn label_at(&self, q: [f64; 2]) -> u32 {
        let [x, y] = self.to_px(q);
        let (w, h) = (self.img.width() as f64, self.img.height() as f64);
        if !(x >= 0.0 && y >= 0.0 && x < w && y < h) {
            return 0;
        }
        self.labels[y as usize * self.img.width() as usize + x as usize]
    }

    /// Bilinear grey level at plate point `q`.
    fn grey(&self, q: [f64; 2]) -> f64 {
        let [x, y] = self.to_px(q);
        let (w, h) = (self.img.width() as i64, self.img.height() as i64);
        let (x, y) = (x - 0.5, y - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let at = |i: i64, j: i64| -> f64 {
            let (i, j) = (i.clamp(0, w - 1) as u32, j.clamp(0, h - 1) as u32);
            f64::from(self.img.get_pixel(i, j)[0])
        };
        // Far off the image (a diverging refinement) reads the border, without overflow.
        let (i, j) = ((x0 as i64).clamp(-1, w), (y0 as i64).clamp(-1, h));
        let top = at(i, j) * (1.0 - fx) + at(i + 1, j) * fx;
        let bottom = at(i, j + 1) * (1.0 - fx) + at(i + 1, j + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// Signed distance (mm, along `n`) from `q` to the edge crossing nearest it, if the grey
    /// profile there has one with enough contrast.
    pub(crate) fn edge_offset(&self, q: [f64; 2], n: [f64; 2]) -> Option<f64> {
        let steps = (2.0 * PROFILE_PX / STEP_PX) as usize;
        let mut v = [0.0f64; 16];
        let v = &mut v[..=steps.min(15)];
        for (i, g) in v.iter_mut().enumerate() {
            let t = (i as f64 * STEP_PX - PROFILE_PX) * self.pix;
            *g = self.grey([q[0] + t * n[0], q[1] + t * n[1]]);
        }
        let k = v.len();
        let inside = 0.5 * (v[0] + v[1]);
        let outside = 0.5 * (v[k - 1] + v[k - 2]);
        if (inside - outside) * self.pol < MIN_EDGE_CONTRAST * self.contrast {
            return None;
        }
        let mid = 0.5 * (inside + outside);
        let s = |i: usize| (v[i] - mid) * self.pol;
        (0..k - 1)
            .filter(|&i| s(i) > 0.0 && s(i + 1) <= 0.0)
            .map(|i| {
                let t = i as f64 * STEP_PX + STEP_PX * s(i) / (s(i) - s(i + 1));
                (t - PROFILE_PX) * self.pix
            })
            .min_by(|a, b| a.abs().total_cmp(&b.abs()))
    }

    /// Fraction of samples whose inside point lies in blob `label` and outside point not, at
    /// `pose` (the coarse measure, on the mask), the points `d_px` either side of the outline.
    fn mask_score(&self, s: &[Sample], pose: Pose, label: u32, d_px: f64) -> f64 {
        self.evaluated.set(self.evaluated.get() + s.len() as u64);
        let (sn, cs) = pose.theta.sin_cos();
        let d = d_px * self.pix;
        let hits = s
            .iter()
            .filter(|smp| {
                let p = [cs * smp.p[0] - sn * smp.p[1], sn * smp.p[0] + cs * smp.p[1]];
                let n = [cs * smp.n[0] - sn * smp.n[1], sn * smp.n[0] + cs * smp.n[1]];
                let q = [pose.c[0] + p[0], pose.c[1] + p[1]];
                self.label_at([q[0] - d * n[0], q[1] - d * n[1]]) == label
                    && self.label_at([q[0] + d * n[0], q[1] + d * n[1]]) != label
            })
            .count();
        hits as f64 / s.len().max(1) as f64
    }
}

/// Orientation step (deg) of the coarse search's wide pass.
const WIDE_STEP_DEG: f64 = 6.0;
/// Shift step (px) of the wide pass.
const WIDE_SHIFT_PX: i32 = 4;
/// Outline samples the wide pass scores.
const WIDE_SAMPLES: usize = 48;
/// Outline samples the fine pass scores.
const FINE_SAMPLES: usize = 96;
/// Wide-pass candidates the fine pass looks around.
const WIDE_KEEP: usize = 4;
/// Candidates returned, and how far apart their orientations must be (deg).
const CANDIDATES: usize = 3;
const CANDIDATE_GAP_DEG: f64 = 10.0;

/// Every `len / n`-th sample: about `n` of them spread around the outline.
fn thin(s: &[Sample], n: usize) -> Vec<Sample> {
    s.iter().step_by((s.len() / n).max(1)).copied().collect()
}

/// The best `keep` of `all` (score, pose), best first, orientations at least `gap` (rad)
/// apart modulo `period`.
fn distinct(mut all: Vec<(f64, Pose)>, keep: usize, gap: f64, period: f64) -> Vec<(f64, Pose)> {
    all.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut out: Vec<(f64, Pose)> = Vec::new();
    for cand in all {
        let far = out.iter().all(|o| {
            let d = (o.1.theta - cand.1.theta).rem_euclid(period);
            d.min(period - d) >= gap
        });
        if far && out.len() < keep {
            out.push(cand);
        }
    }
    out
}

/// The best poses of the outline `s` in blob `label` around `centre` with shifts within
/// `shift_px`: up to three candidates at least 10° apart, best first, for [`refine`].
///
/// Coarse to fine, so that a cluster's piece (whose seed lies pixels off the part's centroid)
/// costs little more than a lone part: a wide pass over one symmetry period `period` (rad) at
/// 6° and shifts at 4 px, scoring 48 samples with a ±3 px tolerance (as wide as its grid, so
/// that a pose between grid points still scores); then around the best four, a fine pass at
/// 2° and 2 px (the old single pass's grid) on 96 samples at ±1.5 px. The work counted in
/// [`View::evaluated`] drops about 20× against the single pass for a cluster's piece.
pub fn coarse(
    view: &View,
    s: &[Sample],
    centre: [f64; 2],
    label: u32,
    period: f64,
    shift_px: i32,
) -> Vec<(f64, Pose)> {
    let (wide, fine) = (thin(s, WIDE_SAMPLES), thin(s, FINE_SAMPLES));
    let step = WIDE_STEP_DEG.to_radians();
    let n = (period / step).round().max(1.0) as usize;
    let reach = shift_px / WIDE_SHIFT_PX;
    let at = |c: [f64; 2], dx: i32, dy: i32| {
        [c[0] + f64::from(dx) * view.pix, c[1] + f64::from(dy) * view.pix]
    };
    let mut all = Vec::with_capacity(n);
    for i in 0..n {
        let theta = i as f64 * period / n as f64;
        let mut best = (f64::MIN, Pose { c: centre, theta });
        for dy in -reach..=reach {
            for dx in -reach..=reach {
                let pose = Pose { c: at(centre, dx * WIDE_SHIFT_PX, dy * WIDE_SHIFT_PX), theta };
                let sc = view.mask_score(&wide, pose, label, 2.0 * MASK_PX);
                if sc > best.0 {
                    best = (sc, pose);
                }
            }
        }
        all.push(best);
    }
    let gap = 2.0 * step;
    let mut fine_all = Vec::new();
    for (_, seed) in distinct(all, WIDE_KEEP, gap, period) {
        let near = if shift_px > 0 { WIDE_SHIFT_PX / 2 } else { 0 };
        let mut best = (f64::MIN, seed);
        for k in -2..=2 {
            let theta = seed.theta + f64::from(k) * 2f64.to_radians();
            for dy in (-near..=near).step_by(2) {
                for dx in (-near..=near).step_by(2) {
                    let pose = Pose { c: at(seed.c, dx, dy), theta };
                    let sc = view.mask_score(&fine, pose, label, MASK_PX);
                    if sc > best.0 {
                        best = (sc, pose);
                    }
                }
            }
        }
        fine_all.push(best);
    }
    distinct(fine_all, CANDIDATES, CANDIDATE_GAP_DEG.to_radians(), period)
}

/// Edge offsets (mm) of every sample at `pose`, with each sample's rotated position and normal.
fn measure(view: &View, s: &[Sample], pose: Pose) -> Vec<([f64; 2], [f64; 2], Option<f64>)> {
    let (sn, cs) = pose.theta.sin_cos();
    s.iter()
        .map(|smp| {
            let p = [cs * smp.p[0] - sn * smp.p[1], sn * smp.p[0] + cs * smp.p[1]];
            let n = [cs * smp.n[0] - sn * smp.n[1], sn * smp.n[0] + cs * smp.n[1]];
            (p, n, view.edge_offset([pose.c[0] + p[0], pose.c[1] + p[1]], n))
        })
        .collect()
}

/// Gauss–Newton on the edge offsets from `start`: each sample pulls the outline along its
/// normal onto its edge crossing (Huber weights beyond 1 px, so a stray edge cannot drag it).
pub fn refine(view: &View, s: &[Sample], start: Pose) -> Fitted {
    let mut pose = start;
    for _ in 0..10 {
        let mut a = Matrix3::<f64>::zeros();
        let mut b = Vector3::<f64>::zeros();
        for (p, n, d) in measure(view, s, pose) {
            let Some(d) = d else { continue };
            let j = Vector3::new(n[0], n[1], n[0] * -p[1] + n[1] * p[0]);
            let w = (view.pix / d.abs().max(1e-12)).min(1.0);
            a += w * j * j.transpose();
            b += w * d * j;
        }
        let Some(x) = a.lu().solve(&b) else { break };
        // A step this large comes from too few edges to pin the pose: it is lost, stop.
        if !x.iter().all(|v| v.is_finite()) || x[0].hypot(x[1]) > 20.0 * view.pix {
            break;
        }
        pose.c[0] += x[0];
        pose.c[1] += x[1];
        pose.theta += x[2];
        let moved_px = (x[0].hypot(x[1]) + x[2].abs() * 20.0) / view.pix;
        if moved_px < 1e-3 {
            break;
        }
    }
    let m = measure(view, s, pose);
    let inl: Vec<f64> = m
        .iter()
        .filter_map(|x| x.2)
        .map(|d| d / view.pix)
        .filter(|d| d.abs() <= INLIER_PX)
        .collect();
    let rms_px = (inl.iter().map(|d| d * d).sum::<f64>() / inl.len().max(1) as f64).sqrt();
    Fitted { pose, score: inl.len() as f64 / s.len().max(1) as f64, rms_px }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::plot::placed;
    use crate::vision::synth::sample_parts;
    use chladni_core::model::part::inside;

    /// A 260 × 200 px view (0.26 mm/px) of the L at `pose`: dark on light, edges anti-aliased
    /// 4 × 4, labelled 1 inside.
    fn scene(pose: Pose) -> (GrayImage, Vec<u32>, f64, f64) {
        let (pix, h_mm) = (0.26, 200.0 * 0.26);
        let l = &sample_parts()[0];
        let rings = placed(l, pose.c, pose.theta.to_degrees());
        let cover = |x: u32, y: u32| {
            let hits = (0..16)
                .filter(|k| {
                    let u = (f64::from(x) + (f64::from(k % 4) + 0.5) / 4.0) * pix;
                    let v = h_mm - (f64::from(y) + (f64::from(k / 4) + 0.5) / 4.0) * pix;
                    inside([u, v], &rings[0])
                })
                .count();
            hits as f64 / 16.0
        };
        let img = GrayImage::from_fn(260, 200, |x, y| {
            image::Luma([(200.0 - 150.0 * cover(x, y)).round() as u8])
        });
        let labels = img.pixels().map(|p| u32::from(p[0] < 125)).collect();
        (img, labels, pix, h_mm)
    }

    /// A cluster piece's search (±14 px of shift, as `split` asks at its 10 px erosion) finds
    /// the pose from a seed 5 px off, scoring a small share of the samples the single 2°/2 px
    /// pass over every shift scored (its 180 × 15² × 96).
    #[test]
    fn the_coarse_search_finds_an_offset_part_with_a_twentieth_of_the_work() {
        let truth = Pose { c: [33.0, 26.0], theta: 137f64.to_radians() };
        let (img, labels, pix, h_mm) = scene(truth);
        let view = View {
            img: &img,
            labels: &labels,
            pix,
            h_mm,
            pol: -1.0,
            contrast: 150.0,
            evaluated: Cell::new(0),
        };
        let s = samples(&sample_parts()[0], 1.5 * pix);
        let seed = [truth.c[0] + 5.0 * pix, truth.c[1] - 4.0 * pix];
        let cands = coarse(&view, &s, seed, 1, std::f64::consts::TAU, 14);
        let single_pass = 180 * 15 * 15 * 96;
        let work = view.evaluated.get();
        println!("coarse search: {work} mask samples (the single pass: {single_pass})");
        assert!(work * 15 < single_pass, "{work}");
        let best = cands
            .iter()
            .map(|c| refine(&view, &s, c.1))
            .max_by(|a, b| a.score.total_cmp(&b.score))
            .unwrap();
        let d = (best.pose.c[0] - truth.c[0]).hypot(best.pose.c[1] - truth.c[1]);
        let a = chladni_core::model::angle::wrap_deg((best.pose.theta - truth.theta).to_degrees());
        assert!(best.score > 0.9 && d < 0.05 && a.min(360.0 - a) < 0.1, "{best:?}");
    }
}
