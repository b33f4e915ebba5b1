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
mod hough;
pub mod input;
pub mod job;
pub mod rectify;
mod sand;
pub mod synth;
#[cfg(test)]
mod tests;

pub(crate) use curves::Curve;
pub use curves::turning;
pub use input::PhotoError;
pub(crate) use sand::sand_mask;
pub use sand::{clean, skeleton};

/// Tuning of the pipeline.
#[derive(Debug, Clone)]
pub struct PhotoParams {
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
    /// separate disks (`coarse`) instead of by threshold and skeleton.
    pub grain_px: f64,
}

impl Default for PhotoParams {
    fn default() -> Self {
        PhotoParams {
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
    /// Fraction of the photo's pixels classed as sand (or grains).
    pub sand_fraction: f64,
    /// Whether the nodes were found from coarse grains ([`PhotoParams::grain_px`]).
    pub coarse: bool,
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
    pub(crate) fn get(&self, x: isize, y: isize) -> bool {
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
    fn min_length_mm(&self, p: &PhotoParams) -> f64 {
        p.min_length * self.size_mm[0].min(self.size_mm[1])
    }
}

/// Finds straight node lines, then curved nodes (as polylines) among the skeleton pixels left
/// over, in a photo of the plate (`size_mm` = [W, H]).
pub fn find_lines(img: &GrayImage, size_mm: [f64; 2], p: &PhotoParams) -> Found {
    if p.grain_px > 2.0 {
        return coarse::find(img, size_mm, p, p.grain_px);
    }
    let (mask, threshold, sand_is_dark) = sand_mask(img, p);
    let sk = skeleton(&clean(&mask, p.open_px, p.close_px));
    let frame = Frame::new(sk.w, sk.h, size_mm);
    let (lines, rest) = hough::straight_lines(&sk, &frame, p);
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
        sand_fraction: mask.count() as f64 / mask.px.len().max(1) as f64,
        coarse: false,
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

/// Most of the plate that sand may cover: Otsu splits any picture in two, and on a Chladni
/// photo the sand (the minority class) is a band along the nodes (the synthetic photos: 6–25 %),
/// while noise or texture splits about evenly (random noise: 50 %).
pub(crate) const MAX_SAND_FRACTION: f64 = 0.4;
/// Largest RMS distance (pixels) of a line's skeleton pixels from it: a node's skeleton lies
/// within a pixel of its line (synthetic photos: 0.7–0.9 px), while pixels scattered evenly over
/// the ±3 px band a line collects have an RMS of 3/√3 ≈ 1.7 px (random noise: 1.5–1.6 px).
pub(crate) const MAX_LINE_RMS_PX: f64 = 1.2;
/// Least skeleton pixels per pixel of a line's length: a node's skeleton is continuous
/// (synthetic photos: 1.0–1.1), a line through a maze of noise is not (0.6–0.9).
pub(crate) const MIN_LINE_COVERAGE: f64 = 0.9;

/// Nodes found, but not convincingly: the measure that failed, with its value and bound.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Unconfident {
    /// The thresholded "sand" covers too much of the plate to be sand on nodes.
    #[error(
        "no confident node found: the \"sand\" covers {:.0} % of the plate (a Chladni figure's \
         sand is a band along the nodes, at most {:.0} %), so the picture is likely noise or \
         texture; photograph the plate square-on with the sand in clear contrast",
        100.0 * .0,
        100.0 * MAX_SAND_FRACTION
    )]
    SandEverywhere(f64),
    /// A line's pixels are scattered about it or sparse along it.
    #[error(
        "no confident node found: line {index} (angle {angle_deg:.1}°) has its skeleton pixels \
         {rms_px:.2} px RMS off it (at most {max_rms:.1}) and {coverage:.2} per pixel of its length \
         (at least {min_cov:.1}), so it is likely noise; photograph the plate square-on with the \
         sand in clear contrast",
        max_rms = MAX_LINE_RMS_PX,
        min_cov = MIN_LINE_COVERAGE
    )]
    ScatteredLine {
        /// Line number (from 1).
        index: usize,
        /// Its direction.
        angle_deg: f64,
        /// RMS distance of its pixels (px).
        rms_px: f64,
        /// Skeleton pixels per pixel of its length.
        coverage: f64,
    },
}

impl Found {
    /// `Err` when nodes were found but do not look like sand on nodes (see [`Unconfident`]); a
    /// plate with no node found passes (there is nothing to distrust). Lines of coarse grains
    /// are not scored (their pixels are grains, not a skeleton).
    pub fn check_confidence(&self) -> Result<(), Unconfident> {
        if self.lines.is_empty() && self.curves.is_empty() {
            return Ok(());
        }
        if self.sand_fraction > MAX_SAND_FRACTION {
            return Err(Unconfident::SandEverywhere(self.sand_fraction));
        }
        for (k, l) in self.lines.iter().enumerate().filter(|_| !self.coarse) {
            let rms_px = l.rms_mm / self.pixel_mm;
            let coverage = l.pixels as f64 * self.pixel_mm / l.length_mm.max(self.pixel_mm);
            if rms_px > MAX_LINE_RMS_PX || coverage < MIN_LINE_COVERAGE {
                let angle_deg = l.angle_deg;
                return Err(Unconfident::ScatteredLine {
                    index: k + 1,
                    angle_deg,
                    rms_px,
                    coverage,
                });
            }
        }
        Ok(())
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
