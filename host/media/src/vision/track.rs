//! Parts followed from photo to photo (the camera loop's `locate`): each part is looked for
//! only near its last pose, in windows of the rectified plate, instead of rectifying,
//! flattening and segmenting the whole plate and searching every blob's orientation.
//!
//! Per part: the square window of half-side (its radius + [`SEARCH_MM`]) around its last
//! position, clipped to the plate, is first sampled at a quarter of the view's resolution and
//! thresholded with the [`Levels`] of the last full [`locate`](super::locate): the window's
//! median grey is the plate's level there (the plate is most of the window) and the threshold
//! that level times the learned share, where Otsu on the window itself would split noise in a
//! window of plate alone. The blob nearest the last position is the part's; the rectangle
//! around it is then sampled at full resolution on the full view's own pixel grid (its pixels
//! are the full view's) and thresholded the same way, unflattened: light varies little across
//! a window, and the edge fit reads its levels locally. A blob of the part's area is refined
//! by Gauss–Newton from its centroid at the last orientation and face; when that finds too
//! few edges (a large turn, a turned-over part), the blob is judged as the full locate judges
//! it (orientation search over a turn on both faces, erosion split of touching parts). A blob
//! that runs out of its window widens the window once. Anything else is named [`Lost`]: the
//! caller then runs the full locate.
//!
//! Limits: every part on the plate should be tracked (an untracked part of the same kind that
//! lies nearer a tracked part's last pose than the part itself is taken for it); the quick
//! refinement keeps the last face, so a part nearly its own mirror image that turns over
//! between photos may keep its old face (the full locate compares the faces).

use image::GrayImage;

use super::corners::Grid;
use super::fit::{self, Pose, View};
use super::{
    ACCEPT_SCORE, AREA_TOLERANCE, Blob, Ctx, Faces, Fit, Levels, LocateError, Located, MARGIN_PX,
    Outcome, Segmented, Template, Why, check_templates, classify, label, median_grey, not_dust,
};
use chladni_core::model::plate_file::is_plate_side;

/// How far (mm) beyond its own radius a part is looked for around its last position: a part
/// that moved farther may be lost (the window widens once for a blob that runs out of it).
pub const SEARCH_MM: f64 = 15.0;
/// A blob closer than this (px) to a window side inside the plate runs out of the window: the
/// edge fit reads grey profiles ±3 px across the outline, which must lie in the window.
const CUT_PX: u32 = 6;
/// The first look at a window is at 1/SCOUT of the view's resolution (each pixel sampled at
/// its block's centre): enough to find the blob, at a sixteenth of the sampling.
const SCOUT: u32 = 4;
/// The full-resolution window reaches this far (px) around the scouted blob: a scout pixel's
/// quantisation, a thin feature the scout may miss, and the edge fit's [`CUT_PX`].
const SCOUT_PAD_PX: u32 = 3 * SCOUT + CUT_PX;
/// A window narrower than this (px) holds no part.
const MIN_WINDOW_PX: f64 = 16.0;
/// The quick refinement must end this close (share of the part's radius) to its blob's
/// centroid: farther, it slid onto other edges.
const QUICK_DRIFT: f64 = 0.25;

/// A part's last known pose, where it is looked for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Near {
    /// Index of its part among the templates.
    pub kind: usize,
    /// Centroid x (mm from the plate's left edge).
    pub x_mm: f64,
    /// Centroid y (mm from the plate's bottom edge).
    pub y_mm: f64,
    /// Orientation (deg CCW).
    pub theta_deg: f64,
    /// Lies on its other face.
    pub flipped: bool,
    /// Whether its face was told apart (carried to a pose found on the same face).
    pub face_certain: bool,
}

impl From<&Located> for Near {
    fn from(l: &Located) -> Near {
        Near {
            kind: l.kind,
            x_mm: l.x_mm,
            y_mm: l.y_mm,
            theta_deg: l.theta_deg,
            flipped: l.flipped,
            face_certain: l.face_certain,
        }
    }
}

/// Why a part was not found near its last pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Lost {
    /// No blob of its size in its window: it moved farther than [`SEARCH_MM`], or left the
    /// plate.
    Gone,
    /// Its blob runs out of its window even widened once: it moved out of the window, or
    /// lies in a cluster too large for one.
    Cut,
    /// In contact with other parts and not told apart.
    Cluster,
    /// A blob of its area whose outline does not fit (hidden, damaged or another kind).
    Misfit,
    /// Less than a whole part: over the plate's edge, or partly hidden.
    Partial,
    /// Its pose is another tracked part's, whose last pose lay nearer it.
    Taken,
}

/// One tracked part.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum Seen {
    /// Found: the pose and fit as [`locate`](super::locate) reports them.
    Found(Located),
    /// Not found near its last pose.
    Lost {
        /// Part name.
        part: String,
        /// Why.
        why: Lost,
    },
}

/// What [`track`] found.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Tracked {
    /// One per last pose given, in their order.
    pub parts: Vec<Seen>,
    /// Pixel size of the rectified view (mm).
    pub pixel_mm: f64,
    /// Parts posed by the refinement from their last pose alone (no orientation search).
    pub quick: usize,
}

impl Tracked {
    /// Every part's pose, in the order given, or `None` when any is lost (then run the full
    /// [`locate`](super::locate)).
    pub fn all_found(&self) -> Option<Vec<Located>> {
        self.parts
            .iter()
            .map(|s| match s {
                Seen::Found(l) => Some(l.clone()),
                Seen::Lost { .. } => None,
            })
            .collect()
    }
}

/// Why the parts cannot be tracked in a photo.
#[derive(Debug, thiserror::Error)]
pub enum TrackError {
    /// The plate, its corners or a part is unusable (as for `locate`).
    #[error(transparent)]
    Locate(#[from] LocateError),
    /// A last pose names a part kind not given.
    #[error(
        "last pose {index} is of part kind {kind}, but {kinds} part kinds were given; pass the \
         templates the poses were located with"
    )]
    Kind {
        /// Index of the pose.
        index: usize,
        /// Its kind.
        kind: usize,
        /// Kinds given.
        kinds: usize,
    },
    /// A last pose that is no number.
    #[error(
        "last pose {index} is ({x}, {y}) mm at {theta}°, not a finite pose; pass the poses a \
         locate found"
    )]
    Pose {
        /// Index of the pose.
        index: usize,
        /// x (mm).
        x: f64,
        /// y (mm).
        y: f64,
        /// θ (deg).
        theta: f64,
    },
    /// Grey levels that no view has.
    #[error(
        "grey levels threshold {threshold}, contrast {contrast} (shares of the plate's grey) \
         must be finite and positive; take them from a full locate's report (`levels`)"
    )]
    Levels {
        /// Threshold share.
        threshold: f64,
        /// Contrast share.
        contrast: f64,
    },
}

impl TrackError {
    /// The error's name in `--json` output.
    pub fn name(&self) -> &'static str {
        match self {
            TrackError::Locate(e) => e.name(),
            TrackError::Kind { .. } => "bad_part_kind",
            TrackError::Pose { .. } => "bad_pose",
            TrackError::Levels { .. } => "bad_levels",
        }
    }
}

/// Finds again the parts whose last poses are `near` in `photo` of a `size_mm` plate whose
/// corners are `corners` (photo px, as [`locate`](super::locate) takes them), thresholding
/// with `levels` (a full locate's [`Report::levels`](super::Report::levels)).
pub fn track(
    photo: &GrayImage,
    templates: &[Template],
    size_mm: [f64; 2],
    corners: [[f64; 2]; 4],
    levels: &Levels,
    near: &[Near],
) -> Result<Tracked, TrackError> {
    if !size_mm.iter().all(|&v| is_plate_side(v)) {
        return Err(LocateError::Size(size_mm[0], size_mm[1]).into());
    }
    if templates.is_empty() {
        return Err(LocateError::NoParts.into());
    }
    check_input(templates.len(), levels, near)?;
    let grid = Grid::new(photo, corners, size_mm).map_err(LocateError::from)?;
    check_templates(templates, size_mm, grid.pix)?;
    let faces = Faces::of(templates, grid.pix);
    let plate = Plate { photo, grid: &grid, h_mm: size_mm[1], templates, faces: &faces, levels };
    let mut quick = 0;
    let mut parts: Vec<Seen> = near
        .iter()
        .map(|n| {
            let (seen, fast) = plate.track_one(&face_up(templates, n));
            quick += usize::from(fast);
            seen
        })
        .collect();
    resolve_shared(&mut parts, near, templates);
    Ok(Tracked { parts, pixel_mm: grid.pix, quick })
}

fn check_input(kinds: usize, levels: &Levels, near: &[Near]) -> Result<(), TrackError> {
    let (threshold, contrast) = (levels.threshold, levels.contrast);
    if !(threshold.is_finite() && threshold > 0.0 && contrast.is_finite() && contrast > 0.0) {
        return Err(TrackError::Levels { threshold, contrast });
    }
    for (index, n) in near.iter().enumerate() {
        if n.kind >= kinds {
            return Err(TrackError::Kind { index, kind: n.kind, kinds });
        }
        if ![n.x_mm, n.y_mm, n.theta_deg].iter().all(|v| v.is_finite()) {
            let (x, y, theta) = (n.x_mm, n.y_mm, n.theta_deg);
            return Err(TrackError::Pose { index, x, y, theta });
        }
    }
    Ok(())
}

/// `n` with a part that has a mirror axis on its up face (where `locate` reports it).
fn face_up(templates: &[Template], n: &Near) -> Near {
    match (n.flipped, templates[n.kind].flip_turn_deg) {
        (true, Some(turn)) => Near { theta_deg: n.theta_deg + turn, flipped: false, ..*n },
        _ => *n,
    }
}

/// Two tracked parts of one kind found at one pose: the one whose last pose lay farther from
/// it is [`Lost::Taken`].
fn resolve_shared(parts: &mut [Seen], near: &[Near], templates: &[Template]) {
    let pos = |s: &Seen| match s {
        Seen::Found(l) => Some((l.kind, [l.x_mm, l.y_mm])),
        Seen::Lost { .. } => None,
    };
    let mut taken = Vec::new();
    for i in 0..parts.len() {
        for j in i + 1..parts.len() {
            let (Some((ki, a)), Some((kj, b))) = (pos(&parts[i]), pos(&parts[j])) else {
                continue;
            };
            if ki != kj || (a[0] - b[0]).hypot(a[1] - b[1]) >= 0.5 * templates[ki].radius_mm {
                continue;
            }
            let from = |n: &Near| (n.x_mm - a[0]).hypot(n.y_mm - a[1]);
            taken.push(if from(&near[i]) <= from(&near[j]) { j } else { i });
        }
    }
    for k in taken {
        let part = templates[near[k].kind].part.name.clone();
        parts[k] = Seen::Lost { part, why: Lost::Taken };
    }
}

/// The photo and what every window shares.
struct Plate<'a> {
    photo: &'a GrayImage,
    grid: &'a Grid,
    h_mm: f64,
    templates: &'a [Template],
    faces: &'a [Faces],
    levels: &'a Levels,
}

/// A window of the rectified view (px): left, top, width, height.
#[derive(Debug, Clone, Copy)]
struct Window {
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
}

/// What a scout found: the full-resolution window, the plate's grey level, the blob's
/// centroid (px).
type Scouted = (Window, f64, [f64; 2]);

/// A window's view and blobs, at full resolution.
struct WindowView {
    img: GrayImage,
    seg: Segmented,
    /// Plate position (mm) of the window's bottom-left corner: the view's frame is the
    /// window's, as if it were a plate of its own.
    origin: [f64; 2],
    h_mm: f64,
}

/// The sides (left, top, right, bottom) of a `w` × `h` view, of which `edge` are the plate's
/// edge, that `bbox` comes within `gap` px of elsewhere: where a blob runs out of the view.
fn cut(bbox: [u32; 4], (w, h): (u32, u32), edge: [bool; 4], gap: u32) -> [bool; 4] {
    let [x0, y0, x1, y1] = bbox;
    let near = [x0 < gap, y0 < gap, x1 + gap >= w, y1 + gap >= h];
    [0, 1, 2, 3].map(|k| near[k] && !edge[k])
}

impl Plate<'_> {
    /// The pose of one part near `n`, and whether the quick refinement found it.
    fn track_one(&self, n: &Near) -> (Seen, bool) {
        let t = &self.templates[n.kind];
        let lost = |why| (Seen::Lost { part: t.part.name.clone(), why }, false);
        let pix = self.grid.pix;
        let at = [n.x_mm / pix, (self.h_mm - n.y_mm) / pix];
        let Some(win) = self.around(at, (t.radius_mm + SEARCH_MM) / pix) else {
            return lost(Lost::Gone);
        };
        let (mut win, plate, seen_at) = match self.scout(win, at, t) {
            Ok(found) => found,
            Err(why) => return lost(why),
        };
        for widened in [false, true] {
            let Some(v) = self.view(win, plate) else { return lost(Lost::Gone) };
            let local = [seen_at[0] - f64::from(win.x0), seen_at[1] - f64::from(win.y0)];
            let Some(b) = nearest(&v.seg.blobs, local, t, pix) else { return lost(Lost::Gone) };
            let out = cut(b.bbox, (win.w, win.h), self.plate_sides(win), CUT_PX);
            if !out.iter().any(|&c| c) {
                return self.pose(&v, b, n);
            }
            if widened {
                break;
            }
            win = self.grow(win, out, self.widest_px());
        }
        lost(Lost::Cut)
    }

    /// The largest part's diameter (px): how far a window widens on a side a blob runs out of.
    fn widest_px(&self) -> u32 {
        let r = self.templates.iter().map(|t| t.radius_mm).fold(0.0, f64::max);
        (2.0 * r / self.grid.pix).ceil() as u32
    }

    /// A look over `win` at 1/[`SCOUT`] resolution for the blob nearest `at` (px) of about
    /// part `t`'s size or more: the full-resolution window around it, the plate's grey level
    /// there (the median of the wide window, which is mostly plate) and the blob's centroid
    /// (px).
    fn scout(&self, win: Window, at: [f64; 2], t: &Template) -> Result<Scouted, Lost> {
        let mut win = win;
        for widened in [false, true] {
            let dims = (win.w / SCOUT, win.h / SCOUT);
            let img = self.grid.window(self.photo, [win.x0, win.y0, dims.0, dims.1], SCOUT);
            let img = img.ok_or(Lost::Gone)?;
            let edge = self.plate_sides(win);
            let plate = median_grey(&img, edge.map(u32::from));
            let seg = self.segment(&img, plate, edge.map(u32::from));
            let s = f64::from(SCOUT);
            let local = [(at[0] - f64::from(win.x0)) / s, (at[1] - f64::from(win.y0)) / s];
            let b = nearest(&seg.blobs, local, t, self.grid.pix * s).ok_or(Lost::Gone)?;
            let out = cut(b.bbox, dims, edge, 1);
            if !out.iter().any(|&c| c) {
                let c = [0, 1].map(|k| f64::from([win.x0, win.y0][k]) + b.centroid_px[k] * s);
                let [x0, y0, x1, y1] = b.bbox.map(|v| v * SCOUT);
                let (x0, y0) = (win.x0 + x0, win.y0 + y0);
                let (x1, y1) = (win.x0 + x1 + SCOUT, win.y0 + y1 + SCOUT);
                let pad = SCOUT_PAD_PX;
                let (x0, y0) = (x0.saturating_sub(pad), y0.saturating_sub(pad));
                let (x1, y1) = ((x1 + pad).min(self.grid.w), (y1 + pad).min(self.grid.h));
                return Ok((Window { x0, y0, w: x1 - x0, h: y1 - y0 }, plate, c));
            }
            if !widened {
                win = self.grow(win, out, self.widest_px());
            }
        }
        Err(Lost::Cut)
    }

    /// The window of half-side `r` px around `c` (px), clipped to the plate.
    fn around(&self, c: [f64; 2], r: f64) -> Option<Window> {
        let (gw, gh) = (f64::from(self.grid.w), f64::from(self.grid.h));
        let x0 = (c[0] - r).floor().clamp(0.0, gw);
        let y0 = (c[1] - r).floor().clamp(0.0, gh);
        let x1 = (c[0] + r).ceil().clamp(0.0, gw);
        let y1 = (c[1] + r).ceil().clamp(0.0, gh);
        let win = Window { x0: x0 as u32, y0: y0 as u32, w: (x1 - x0) as u32, h: (y1 - y0) as u32 };
        (x1 - x0 >= MIN_WINDOW_PX && y1 - y0 >= MIN_WINDOW_PX).then_some(win)
    }

    /// Which of `win`'s sides (left, top, right, bottom) are the plate's edge.
    fn plate_sides(&self, win: Window) -> [bool; 4] {
        [win.x0 == 0, win.y0 == 0, win.x0 + win.w >= self.grid.w, win.y0 + win.h >= self.grid.h]
    }

    /// `win` widened by `by` px on its `cut` sides, clipped to the plate.
    fn grow(&self, win: Window, cut: [bool; 4], by: u32) -> Window {
        let d = |k: usize| if cut[k] { by } else { 0 };
        let (x0, y0) = (win.x0.saturating_sub(d(0)), win.y0.saturating_sub(d(1)));
        let x1 = (win.x0 + win.w).saturating_add(d(2)).min(self.grid.w);
        let y1 = (win.y0 + win.h).saturating_add(d(3)).min(self.grid.h);
        Window { x0, y0, w: x1 - x0, h: y1 - y0 }
    }

    /// The blobs of `img`, whose plate's grey level is `plate`, thresholded at the learned
    /// share of it, `margin` px left out at the plate's edges.
    fn segment(&self, img: &GrayImage, plate: f64, margin: [u32; 4]) -> Segmented {
        let l = self.levels;
        let t = (l.threshold * plate).round().clamp(0.0, 255.0) as u8;
        label(img, t, l.parts_dark, l.contrast * plate, margin)
    }

    /// The full-resolution view of `win`, whose plate's grey level is `plate`. Not flattened:
    /// light varies little across a window, and the edge fit reads levels locally.
    fn view(&self, win: Window, plate: f64) -> Option<WindowView> {
        let img = self.grid.window(self.photo, [win.x0, win.y0, win.w, win.h], 1)?;
        let margin = self.plate_sides(win).map(|e| if e { MARGIN_PX } else { 0 });
        let seg = self.segment(&img, plate, margin);
        let pix = self.grid.pix;
        let bottom = self.h_mm - f64::from(win.y0 + win.h) * pix;
        let origin = [f64::from(win.x0) * pix, bottom];
        Some(WindowView { img, seg, origin, h_mm: f64::from(win.h) * pix })
    }

    /// The part of `n`'s kind in blob `b`: the quick refinement, else the full locate's
    /// judgement of the blob; and whether the quick one found it.
    fn pose(&self, v: &WindowView, b: &Blob, n: &Near) -> (Seen, bool) {
        let view = View {
            img: &v.img,
            labels: &v.seg.labels,
            pix: self.grid.pix,
            h_mm: v.h_mm,
            pol: if v.seg.parts_dark { -1.0 } else { 1.0 },
            contrast: v.seg.contrast,
            evaluated: Default::default(),
        };
        let ctx = Ctx { view, templates: self.templates, faces: self.faces };
        let back = |mut l: Located| {
            l.x_mm += v.origin[0];
            l.y_mm += v.origin[1];
            Seen::Found(l)
        };
        if let Some(l) = quick(&ctx, b, n) {
            return (back(l), true);
        }
        let local = [n.x_mm - v.origin[0], n.y_mm - v.origin[1]];
        let part = self.templates[n.kind].part.name.clone();
        let why = match classify(&ctx, b) {
            Outcome::Parts(found) => {
                let mine = found.into_iter().filter(|l| l.kind == n.kind).min_by(|a, c| {
                    let d = |l: &Located| (l.x_mm - local[0]).hypot(l.y_mm - local[1]);
                    d(a).total_cmp(&d(c))
                });
                if let Some(l) = mine {
                    return (back(l), false);
                }
                Lost::Gone
            }
            Outcome::Other(u) => match u.why {
                Why::Cluster => Lost::Cluster,
                Why::Misfit => Lost::Misfit,
                Why::Partial => Lost::Partial,
                Why::Unmatched => Lost::Gone,
            },
        };
        (Seen::Lost { part, why }, false)
    }
}

/// The blob nearest `at` (window px) that is at least a quarter of part `t`.
fn nearest<'b>(blobs: &'b [Blob], at: [f64; 2], t: &Template, pix: f64) -> Option<&'b Blob> {
    let quarter = 0.25 * t.area_mm2 / (pix * pix);
    let d = |b: &Blob| (b.centroid_px[0] - at[0]).hypot(b.centroid_px[1] - at[1]);
    blobs
        .iter()
        .filter(|b| not_dust(b, pix) && b.area_px as f64 >= quarter)
        .min_by(|a, b| d(a).total_cmp(&d(b)))
}

/// Part `n.kind` on its last face refined from blob `b`'s centroid at its last orientation,
/// if the blob is one such part and the fit finds its outline's edges as `locate` requires.
fn quick(ctx: &Ctx, b: &Blob, n: &Near) -> Option<Located> {
    let t = &ctx.templates[n.kind];
    let pix = ctx.view.pix;
    let area = b.area_px as f64 * pix * pix;
    if b.at_edge || (area / t.area_mm2 - 1.0).abs() > AREA_TOLERANCE {
        return None;
    }
    let faces = &ctx.faces[n.kind];
    let s = if n.flipped { faces.flipped.as_ref()? } else { &faces.up };
    let c = ctx.mm(b.centroid_px);
    let f = fit::refine(&ctx.view, s, Pose { c, theta: n.theta_deg.to_radians() });
    let drift = (f.pose.c[0] - c[0]).hypot(f.pose.c[1] - c[1]);
    if f.score < ACCEPT_SCORE || drift > QUICK_DRIFT * t.radius_mm {
        return None;
    }
    let mut l = ctx.located(n.kind, &Fit { f, flipped: n.flipped, other_face: None }, false);
    l.face_certain = n.face_certain;
    Some(l)
}

#[cfg(test)]
mod tests;
