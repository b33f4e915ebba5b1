//! Parts in a photo of the plate (`chladni locate`, docs/plate.md "Parts in a photo"): each
//! part of the given kinds found, with its pose in the plate frame, the face it lies on and a
//! match score; blobs that are no single part named as clusters, partly hidden parts or
//! unknown.
//!
//! Pipeline: the plate's corners (given, or found from the plate's contrast, [`corners`]) →
//! the square-pixel rectified view → its uneven light divided out (`flat`) → Otsu threshold, the parts being the minority class (dark
//! parts on a light plate and light parts on a dark one both work) → 8-connected blobs with a
//! margin at the plate's edge → per blob: its area against each part's area, then for a
//! candidate part and face a coarse search of the orientation on the blob's mask and a
//! Gauss–Newton refinement on sub-pixel edges ([`fit`]). A blob of about two or more parts'
//! area is eroded until it falls apart and each piece fitted; a blob that cannot be explained
//! that way is reported as a cluster with its count, never as a guessed pose.
//!
//! Pose convention (docs/physics.md): centroid (x, y) mm from the plate's bottom-left corner,
//! θ counter-clockwise from the part as drawn, reported in [0°, 360°/m) for a part of
//! rotational symmetry order m. `flipped` = the part lies on its other face, whose θ = 0 is
//! [`Part::mirrored`]; a part with a mirror axis looks the same on both faces and is always
//! reported face up, at the equivalent turn.
//!
//! From photo to photo of a camera loop, [`track::track`] looks for each part only near its last
//! pose, with the [`Levels`] this pipeline learned.

use chladni_shared::icd::units::Given;
use image::{GrayImage, Luma};
use imageproc::contrast::otsu_level;
use imageproc::region_labelling::{Connectivity, connected_components};

use chladni_core::model::part::mirror::flip_turn_deg;
use chladni_core::model::part::{MAX_COORD_MM, Part};
use chladni_core::model::plate_file::is_plate_side;
use chladni_core::plate::photo::rectify::RectifyError;

pub mod corners;
pub mod fit;
mod flat;
pub mod plot;
pub mod series;
mod split;
pub mod synth;
#[cfg(test)]
mod tests;
pub mod track;
pub mod verify;

use fit::{Fitted, Sample, View};

/// A part must cover at least this many pixels in the rectified photo to be located.
pub(crate) const MIN_PART_PX: f64 = 200.0;
/// Blobs smaller than this (mm²) are dust, not reported.
pub(crate) const MIN_BLOB_MM2: f64 = 2.0;
/// Share of the outline whose edge must be found for a lone part's pose to be reported.
pub(crate) const ACCEPT_SCORE: f64 = 0.8;
/// The same for a part touching another (its contact edge is lost).
pub(crate) const ACCEPT_TOUCHING: f64 = 0.55;
/// A blob's area within this ratio of a part's counts as that part's.
pub(crate) const AREA_TOLERANCE: f64 = 0.15;
/// A chiral part's face is told when its better face's [`Fitted::quality`] beats the other
/// face's by at least this; closer, `face_certain` is false. Measured at 0.5 mm per pixel: the
/// example key's faces differ by 0.09, the example triangle's (its mirror image within 0.3 mm
/// of it turned) by 0.025; at 0.26 mm the triangle's by 0.1.
pub const FACE_MARGIN: f64 = 0.05;

/// The best fit of one part kind in a blob, over both faces.
#[derive(Debug, Clone, Copy)]
pub struct Fit {
    /// The better face's fit.
    pub f: Fitted,
    /// Whether that face is the flipped one.
    pub flipped: bool,
    /// The other face's best [`Fitted::quality`], for a part whose faces differ.
    pub other_face: Option<f64>,
}

/// Why a photo cannot be searched.
#[derive(Debug, thiserror::Error)]
pub enum LocateError {
    /// No part kind given.
    #[error("no part given; name the parts to look for with --part P.json")]
    NoParts,
    /// A bad plate size.
    #[error(
        "--size-mm {} {}: the plate's width and height must be finite, positive and at most \
         {MAX_COORD_MM} (mm)",
        Given(*.0),
        Given(*.1)
    )]
    Size(f64, f64),
    /// The plate cannot be found automatically.
    #[error(
        "no plate found in the photo: {0}; photograph the plate against a background of clearly \
         different brightness, or give its corners with --corners X0 Y0 X1 Y1 X2 Y2 X3 Y3"
    )]
    NoPlate(String),
    /// The given corners are unusable.
    #[error("--corners: {0}")]
    Corners(#[from] RectifyError),
    /// A part that cannot lie on this plate.
    #[error(
        "part {part}: {across:.1} mm across does not fit on the {w} × {h} mm plate; is this the \
         right part file (in mm)?"
    )]
    PartTooLarge {
        /// Part name.
        part: String,
        /// Its diameter (mm).
        across: f64,
        /// Plate width.
        w: f64,
        /// Plate height.
        h: f64,
    },
    /// A part too small to see at the photo's resolution.
    #[error(
        "part {part}: {px:.0} px in this photo ({pix:.2} mm per pixel), under the {MIN_PART_PX} px \
         a part needs to be located; photograph the plate closer or at a higher resolution"
    )]
    PartTooSmall {
        /// Part name.
        part: String,
        /// Its area in pixels.
        px: f64,
        /// Pixel size (mm).
        pix: f64,
    },
    /// Blobs were found, but none is any given part, alone or in a cluster.
    #[error(
        "none of the {blobs} blobs on the plate ({areas} mm²) matches a given part ({parts}); \
         is it the right part file, in mm?"
    )]
    NothingMatches {
        /// Blob count.
        blobs: usize,
        /// Their areas, listed.
        areas: String,
        /// The parts and their areas.
        parts: String,
    },
}

impl LocateError {
    /// The error's name in `--json` output.
    pub fn name(&self) -> &'static str {
        match self {
            LocateError::NoParts => "no_parts",
            LocateError::Size(..) => "bad_size",
            LocateError::NoPlate(_) => "no_plate",
            LocateError::Corners(RectifyError::OutsideImage { .. }) => "corners_outside_image",
            LocateError::Corners(RectifyError::NotConvex(_)) => "corners_not_convex",
            LocateError::PartTooLarge { .. } => "part_too_large",
            LocateError::PartTooSmall { .. } => "part_too_small",
            LocateError::NothingMatches { .. } => "nothing_matches",
        }
    }
}

/// A part kind to look for.
#[derive(Debug, Clone)]
pub struct Template {
    /// The part as drawn (face up).
    pub part: Part,
    /// Its mirror image, when it has no mirror axis (the flipped face looks different).
    pub mirrored: Option<Part>,
    /// Orientations equal modulo this (deg): 360°/m for symmetry order m.
    pub period_deg: f64,
    /// The flipped face is the face up turned by this (deg), for parts with a mirror axis.
    pub flip_turn_deg: Option<f64>,
    /// Area (mm²).
    pub area_mm2: f64,
    /// Largest distance of a vertex from the centroid (mm).
    pub radius_mm: f64,
}

impl Template {
    /// Prepares a part.
    pub fn new(part: &Part) -> Template {
        let m = chladni_core::planner::symmetry_order(part).max(1);
        let turn = flip_turn_deg(part);
        let c = part.centroid();
        let radius_mm =
            part.outline.iter().map(|p| (p[0] - c[0]).hypot(p[1] - c[1])).fold(0.0, f64::max);
        Template {
            part: part.clone(),
            mirrored: turn.is_none().then(|| part.mirrored()),
            period_deg: 360.0 / f64::from(m),
            flip_turn_deg: turn,
            area_mm2: part.area(),
            radius_mm,
        }
    }
}

/// A part found.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Located {
    /// Part name.
    pub part: String,
    /// Centroid x (mm from the plate's left edge).
    pub x_mm: f64,
    /// Centroid y (mm from the plate's bottom edge).
    pub y_mm: f64,
    /// Orientation (deg CCW), in [0, period).
    pub theta_deg: f64,
    /// Lies on its other face (the better-fitting face; see `face_certain`).
    pub flipped: bool,
    /// Whether the photo tells the faces apart: false when both faces' outlines fit within
    /// [`FACE_MARGIN`] of each other's quality (a part nearly its own mirror image at this pixel size);
    /// then `flipped` is a guess that `verify` does not take as a pose.
    pub face_certain: bool,
    /// Share of its outline whose edge was found on the photo (0–1).
    pub score: f64,
    /// RMS distance of those edges from the fitted outline (px).
    pub rms_px: f64,
    /// Touches another part (its pose rests on fewer edges).
    pub touching: bool,
    /// Index of its part among those given.
    #[serde(skip)]
    pub kind: usize,
}

/// What a blob that is not a located part is.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Why {
    /// Its area and shape match no given part.
    Unmatched,
    /// Several parts in contact that could not be told apart.
    Cluster,
    /// Less than a whole part: partly hidden, or over the plate's edge.
    Partial,
    /// A part's area, but its outline does not fit the blob (hidden, damaged or another kind).
    Misfit,
}

/// A blob on the plate that is not a located part.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Unknown {
    /// What it is.
    pub why: Why,
    /// The part it most likely is or holds.
    pub part: Option<String>,
    /// For a cluster: how many parts its area holds.
    pub count: Option<usize>,
    /// Area (mm²).
    pub area_mm2: f64,
    /// Centroid x (mm).
    pub x_mm: f64,
    /// Centroid y (mm).
    pub y_mm: f64,
}

/// Everything found in a photo.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    /// Parts found, bottom to top then left to right.
    pub parts: Vec<Located>,
    /// Blobs that are not a located part.
    pub unknown: Vec<Unknown>,
    /// The plate's corners in the photo (px; bottom-left, bottom-right, top-right, top-left).
    pub corners: [[f64; 2]; 4],
    /// Whether the corners were found in the photo (not given).
    pub corners_found: bool,
    /// Pixel size of the rectified view (mm).
    pub pixel_mm: f64,
    /// Whether the parts are darker than the plate.
    pub parts_dark: bool,
    /// The view's grey levels, for [`track`](track::track) on the next photos.
    #[serde(skip)]
    pub levels: Levels,
}

/// A connected region of part-class pixels.
#[derive(Debug, Clone)]
pub(crate) struct Blob {
    pub label: u32,
    pub area_px: usize,
    /// Centroid (continuous px).
    pub centroid_px: [f64; 2],
    /// Bounding box (px): x0, y0, x1, y1 inclusive.
    pub bbox: [u32; 4],
    /// Reaches the margin at the plate's edge.
    pub at_edge: bool,
}

/// Pixels at the plate's edge left out of the blobs (the surroundings bleed in there).
pub(crate) const MARGIN_PX: u32 = 2;

/// The grey levels of a rectified, flattened view, as shares of its plate's level (the view's
/// median grey: the plate is most of it). Light multiplies plate and parts alike, so the
/// shares hold across the plate and from frame to frame while the levels themselves follow the
/// light: [`track`](track::track) thresholds its windows with them, where Otsu on a window
/// that is mostly part, or all plate, would split whatever is there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Levels {
    /// Whether the parts are darker than the plate.
    pub parts_dark: bool,
    /// The part/plate threshold (greys above it are the lighter class).
    pub threshold: f64,
    /// The mean grey difference between part and plate pixels.
    pub contrast: f64,
}

/// A view's part-class blobs, their label image (row-major), the parts' polarity and the
/// part/plate contrast (grey levels).
pub(crate) struct Segmented {
    pub labels: Vec<u32>,
    pub blobs: Vec<Blob>,
    pub parts_dark: bool,
    pub contrast: f64,
}

/// Whether pixel (`x`, `y`) of a `w` × `h` view lies inside `margin` (px at the left, top,
/// right and bottom).
fn inner(x: u32, y: u32, (w, h): (u32, u32), m: [u32; 4]) -> bool {
    x >= m[0] && y >= m[1] && x + m[2] < w && y + m[3] < h
}

/// The median grey of `img` inside `margin` (left, top, right, bottom px).
pub(crate) fn median_grey(img: &GrayImage, margin: [u32; 4]) -> f64 {
    let mut hist = [0usize; 256];
    let dim = img.dimensions();
    for (_, _, p) in img.enumerate_pixels().filter(|(x, y, _)| inner(*x, *y, dim, margin)) {
        hist[usize::from(p[0])] += 1;
    }
    let half = hist.iter().sum::<usize>().div_ceil(2);
    let mut seen = 0;
    for (g, n) in hist.iter().enumerate() {
        seen += n;
        if seen >= half && seen > 0 {
            return g as f64;
        }
    }
    0.0
}

/// Otsu-thresholded blobs of the rectified view, and its levels.
fn segment(img: &GrayImage) -> (Segmented, Levels) {
    let t = otsu_level(img);
    let m = [MARGIN_PX; 4];
    let dim = img.dimensions();
    let (mut n_hi, mut n_lo, mut s_hi, mut s_lo) = (0usize, 0usize, 0.0, 0.0);
    for (_, _, p) in img.enumerate_pixels().filter(|(x, y, _)| inner(*x, *y, dim, m)) {
        if p[0] > t {
            n_hi += 1;
            s_hi += f64::from(p[0]);
        } else {
            n_lo += 1;
            s_lo += f64::from(p[0]);
        }
    }
    let parts_dark = n_lo < n_hi;
    let contrast = (s_hi / n_hi.max(1) as f64 - s_lo / n_lo.max(1) as f64).abs();
    let plate = median_grey(img, m).max(1.0);
    let levels = Levels { parts_dark, threshold: f64::from(t) / plate, contrast: contrast / plate };
    (label(img, t, parts_dark, contrast, m), levels)
}

/// The 8-connected blobs of the pixels of `img` on the parts' side of `t`, leaving out
/// `margin` px at the left, top, right and bottom (the plate's edge, where the surroundings
/// bleed in; a blob reaching it is `at_edge`; a side with no margin is no plate edge).
pub(crate) fn label(
    img: &GrayImage,
    t: u8,
    parts_dark: bool,
    contrast: f64,
    m: [u32; 4],
) -> Segmented {
    let (w, h) = img.dimensions();
    let mask = GrayImage::from_fn(w, h, |x, y| {
        let part = (img.get_pixel(x, y)[0] > t) != parts_dark;
        Luma([if part && inner(x, y, (w, h), m) { 255 } else { 0 }])
    });
    let labels = connected_components(&mask, Connectivity::Eight, Luma([0u8]));
    let n = labels.pixels().map(|p| p[0]).max().unwrap_or(0) as usize;
    let mut acc = vec![(0usize, 0.0f64, 0.0f64, [u32::MAX, u32::MAX, 0, 0], false); n + 1];
    let edge = |x: u32, y: u32| {
        (m[0] > 0 && x <= m[0])
            || (m[1] > 0 && y <= m[1])
            || (m[2] > 0 && x + m[2] + 1 >= w)
            || (m[3] > 0 && y + m[3] + 1 >= h)
    };
    for (x, y, p) in labels.enumerate_pixels() {
        let a = &mut acc[p[0] as usize];
        a.0 += 1;
        a.1 += f64::from(x) + 0.5;
        a.2 += f64::from(y) + 0.5;
        a.3 = [a.3[0].min(x), a.3[1].min(y), a.3[2].max(x), a.3[3].max(y)];
        a.4 |= edge(x, y);
    }
    let blobs = (1..=n)
        .filter(|&l| acc[l].0 > 0)
        .map(|l| {
            let a = &acc[l];
            Blob {
                label: l as u32,
                area_px: a.0,
                centroid_px: [a.1 / a.0 as f64, a.2 / a.0 as f64],
                bbox: a.3,
                at_edge: a.4,
            }
        })
        .collect();
    Segmented { labels: labels.into_raw(), blobs, parts_dark, contrast }
}

/// The two faces of a template as outline samples at the photo's pixel size.
pub(crate) struct Faces {
    pub up: Vec<Sample>,
    pub flipped: Option<Vec<Sample>>,
}

impl Faces {
    /// Each template's faces, sampled every 1.5 px of `pix` mm.
    pub fn of(templates: &[Template], pix: f64) -> Vec<Faces> {
        let step = 1.5 * pix;
        templates
            .iter()
            .map(|t| Faces {
                up: fit::samples(&t.part, step),
                flipped: t.mirrored.as_ref().map(|m| fit::samples(m, step)),
            })
            .collect()
    }
}

/// The search context: the view, the templates and their samples.
pub(crate) struct Ctx<'a> {
    pub view: View<'a>,
    pub templates: &'a [Template],
    pub faces: &'a [Faces],
}

impl Ctx<'_> {
    /// The best fit of template `k` (either face) in blob `label` near `centre`, searching
    /// shifts within `shift_px`: the fit, its face and the other face's best score (`None`
    /// for a part with a mirror axis, fitted on one face).
    pub fn fit(&self, k: usize, label: u32, centre: [f64; 2], shift_px: i32) -> Option<Fit> {
        let t = &self.templates[k];
        let period = t.period_deg.to_radians();
        let faces = [(Some(&self.faces[k].up), false), (self.faces[k].flipped.as_ref(), true)];
        let mut best: [Option<Fitted>; 2] = [None, None];
        for (s, flipped) in faces {
            let Some(s) = s else { continue };
            let slot = &mut best[usize::from(flipped)];
            for (_, start) in fit::coarse(&self.view, s, centre, label, period, shift_px) {
                let f = fit::refine(&self.view, s, start);
                if slot.as_ref().is_none_or(|b| f.score > b.score) {
                    *slot = Some(f);
                }
            }
        }
        match best {
            [Some(up), Some(down)] => {
                // The faces are compared by quality, not score alone: a near-mirror part's two
                // faces can find every edge (score 1) and differ only in how close they lie.
                let flipped = down.quality() > up.quality();
                let (f, other) = if flipped { (down, up) } else { (up, down) };
                Some(Fit { f, flipped, other_face: Some(other.quality()) })
            }
            [Some(f), None] => Some(Fit { f, flipped: false, other_face: None }),
            [None, Some(f)] => Some(Fit { f, flipped: true, other_face: None }),
            [None, None] => None,
        }
    }

    /// The located part for fit `f` of template `k`.
    pub fn located(&self, k: usize, fit: &Fit, touching: bool) -> Located {
        let (t, f) = (&self.templates[k], &fit.f);
        let theta = f.pose.theta.to_degrees().rem_euclid(t.period_deg);
        // Both faces fitting about as well: the photo cannot tell them apart (a part nearly
        // its own mirror image at this pixel size); the better one is reported, marked.
        let face_certain = fit.other_face.is_none_or(|o| f.quality() - o >= FACE_MARGIN);
        Located {
            part: t.part.name.clone(),
            x_mm: f.pose.c[0],
            y_mm: f.pose.c[1],
            theta_deg: if t.period_deg - theta < 1e-9 { 0.0 } else { theta },
            flipped: fit.flipped,
            face_certain,
            score: f.score,
            rms_px: f.rms_px,
            touching,
            kind: k,
        }
    }

    /// Plate position (mm) of a continuous pixel position.
    pub fn mm(&self, p: [f64; 2]) -> [f64; 2] {
        [p[0] * self.view.pix, self.view.h_mm - p[1] * self.view.pix]
    }
}

/// What one blob is.
pub(crate) enum Outcome {
    Parts(Vec<Located>),
    Other(Unknown),
}

/// Area ratio of the blob to each template.
fn ratios(ctx: &Ctx, b: &Blob) -> Vec<f64> {
    let a = b.area_px as f64 * ctx.view.pix * ctx.view.pix;
    ctx.templates.iter().map(|t| a / t.area_mm2).collect()
}

/// Decides what blob `b` is.
pub(crate) fn classify(ctx: &Ctx, b: &Blob) -> Outcome {
    let r = ratios(ctx, b);
    let centre = ctx.mm(b.centroid_px);
    let area_mm2 = b.area_px as f64 * ctx.view.pix * ctx.view.pix;
    let unknown = |why, part: Option<usize>, count| {
        Outcome::Other(Unknown {
            why,
            part: part.map(|k| ctx.templates[k].part.name.clone()),
            count,
            area_mm2,
            x_mm: centre[0],
            y_mm: centre[1],
        })
    };
    let nearest = (0..r.len()).min_by(|&a, &c| (r[a].ln().abs()).total_cmp(&r[c].ln().abs()));
    let single: Vec<usize> =
        (0..r.len()).filter(|&k| (r[k] - 1.0).abs() <= AREA_TOLERANCE).collect();
    if b.at_edge {
        return unknown(Why::Partial, nearest, None);
    }
    let mut misfit = None;
    for &k in &single {
        if let Some(fit) = ctx.fit(k, b.label, centre, 0) {
            if fit.f.score >= ACCEPT_SCORE {
                return Outcome::Parts(vec![ctx.located(k, &fit, false)]);
            }
            misfit = Some(k);
        }
    }
    // Two small parts can have one large part's area: a misfit may still be a pair.
    if r.iter().any(|&x| x >= 2.0 - 2.0 * AREA_TOLERANCE) {
        if let Some(parts) = split::split(ctx, b) {
            return Outcome::Parts(parts);
        }
        if misfit.is_none() {
            let (k, count) = split::cluster_count(&r);
            return unknown(Why::Cluster, Some(k), Some(count));
        }
    }
    if let Some(k) = misfit {
        return unknown(Why::Misfit, Some(k), None);
    }
    if r.iter().any(|&x| (0.25..1.0).contains(&x)) {
        let k = (0..r.len()).filter(|&k| r[k] < 1.0).max_by(|&a, &c| r[a].total_cmp(&r[c]));
        return unknown(Why::Partial, k, None);
    }
    unknown(Why::Unmatched, None, None)
}

/// Checks the parts against the plate and the photo's resolution.
pub(crate) fn check_templates(
    t: &[Template],
    size_mm: [f64; 2],
    pix: f64,
) -> Result<(), LocateError> {
    if t.is_empty() {
        return Err(LocateError::NoParts);
    }
    for t in t {
        let across = 2.0 * t.radius_mm;
        if across > size_mm[0].hypot(size_mm[1]) {
            let (w, h) = (size_mm[0], size_mm[1]);
            return Err(LocateError::PartTooLarge { part: t.part.name.clone(), across, w, h });
        }
        let px = t.area_mm2 / (pix * pix);
        if px < MIN_PART_PX {
            return Err(LocateError::PartTooSmall { part: t.part.name.clone(), px, pix });
        }
    }
    Ok(())
}

/// Finds the parts of the kinds `templates` in `photo` of a `size_mm` plate whose corners are
/// `corners` (photo px, as [`chladni_core::plate::photo::rectify::rectify`] takes them) or, when
/// `None`, found from the plate's contrast. Returns the report and the rectified view.
pub fn locate(
    photo: &GrayImage,
    templates: &[Template],
    size_mm: [f64; 2],
    corners: Option<[[f64; 2]; 4]>,
) -> Result<(Report, GrayImage), LocateError> {
    if !size_mm.iter().all(|&v| is_plate_side(v)) {
        return Err(LocateError::Size(size_mm[0], size_mm[1]));
    }
    if templates.is_empty() {
        return Err(LocateError::NoParts);
    }
    let (corners, corners_found) = match corners {
        Some(c) => (c, false),
        None => (corners::find_corners(photo)?, true),
    };
    let (img, pix) = corners::rectify_square(photo, corners, size_mm)?;
    check_templates(templates, size_mm, pix)?;
    let flat = flat::flatten(&img, MARGIN_PX);
    let (seg, levels) = segment(&flat);
    let faces = Faces::of(templates, pix);
    let view = View {
        img: &flat,
        labels: &seg.labels,
        pix,
        h_mm: size_mm[1],
        pol: if seg.parts_dark { -1.0 } else { 1.0 },
        contrast: seg.contrast,
        evaluated: Default::default(),
    };
    let ctx = Ctx { view, templates, faces: &faces };
    let (mut parts, mut unknown) = (Vec::new(), Vec::new());
    for b in seg.blobs.iter().filter(|b| not_dust(b, pix)) {
        match classify(&ctx, b) {
            Outcome::Parts(p) => parts.extend(p),
            Outcome::Other(u) => unknown.push(u),
        }
    }
    if parts.is_empty() && !unknown.is_empty() && unknown.iter().all(|u| u.why == Why::Unmatched) {
        return Err(nothing_matches(&unknown, templates));
    }
    parts.sort_by(|a, b| {
        (a.y_mm, a.x_mm).partial_cmp(&(b.y_mm, b.x_mm)).unwrap_or(std::cmp::Ordering::Equal)
    });
    let parts_dark = seg.parts_dark;
    let report =
        Report { parts, unknown, corners, corners_found, pixel_mm: pix, parts_dark, levels };
    Ok((report, img))
}

/// Whether blob `b` is big enough to be anything but dust at `pix` mm per pixel.
pub(crate) fn not_dust(b: &Blob, pix: f64) -> bool {
    b.area_px as f64 >= (MIN_BLOB_MM2 / (pix * pix)).max(20.0)
}

fn nothing_matches(unknown: &[Unknown], templates: &[Template]) -> LocateError {
    let areas: Vec<String> = unknown.iter().take(8).map(|u| format!("{:.0}", u.area_mm2)).collect();
    let parts: Vec<String> =
        templates.iter().map(|t| format!("{} {:.0} mm²", t.part.name, t.area_mm2)).collect();
    LocateError::NothingMatches {
        blobs: unknown.len(),
        areas: areas.join(", "),
        parts: parts.join(", "),
    }
}
