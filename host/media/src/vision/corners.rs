//! The plate's four corners in a photo where the plate contrasts with its surroundings, and
//! the square-pixel rectified view of the plate.
//!
//! Otsu splits the photo; the plate is the largest region of either class that does not touch
//! the photo's border (the surroundings do). Its outer contour's convex hull, simplified by
//! Douglas–Peucker until four vertices are left, gives rough corners. That much runs on the
//! photo shrunk to at most `ROUGH_SIDE_PX` on its long side (block means): the rough corners
//! need only be good to a few pixels, and the labelling and contour passes cost in proportion
//! to the pixels. Each side is then fitted at full resolution (total least squares) to
//! sub-pixel edge crossings measured across it, over a window wide enough for the shrunk
//! view's error, and the corners are the intersections of neighbouring sides. Corners come out in the order the rest of the
//! photo code uses: the plate's bottom-left, bottom-right, top-right, top-left, taking the
//! photo's bottom as the plate's bottom.

use image::{GrayImage, Luma};
use imageproc::contours::{BorderType, find_contours};
use imageproc::contrast::otsu_level;
use imageproc::geometry::{approximate_polygon_dp, convex_hull};
use imageproc::point::Point;
use imageproc::region_labelling::{Connectivity, connected_components};

use super::LocateError;
use chladni_core::plate::photo::rectify::{Homography, RectifyError, check_corners, warp};

/// Least share of the photo the plate must cover to be found.
const MIN_PLATE_SHARE: f64 = 0.05;
/// The rough corners are found on the photo shrunk to at most this long side (px).
const ROUGH_SIDE_PX: u32 = 400;

/// `img` shrunk by the whole factor `k` (each pixel the mean of a k × k block; the last
/// partial blocks dropped).
fn shrink(img: &GrayImage, k: u32) -> GrayImage {
    if k <= 1 {
        return img.clone();
    }
    let (w, h) = (img.width() / k, img.height() / k);
    let mut sums = vec![0u32; w as usize];
    let mut out = GrayImage::new(w, h);
    for by in 0..h {
        sums.fill(0);
        for y in by * k..(by + 1) * k {
            for (bx, s) in sums.iter_mut().enumerate() {
                let x0 = bx as u32 * k;
                *s += (x0..x0 + k).map(|x| u32::from(img.get_pixel(x, y)[0])).sum::<u32>();
            }
        }
        for (bx, s) in sums.iter().enumerate() {
            out.put_pixel(bx as u32, by, Luma([(s / (k * k)) as u8]));
        }
    }
    out
}

/// The plate region: the label image's largest component of one Otsu class off the border.
fn plate_mask(img: &GrayImage) -> Result<GrayImage, LocateError> {
    let t = otsu_level(img);
    let (w, h) = img.dimensions();
    let mut best: Option<(usize, GrayImage)> = None;
    for light in [true, false] {
        let mask = GrayImage::from_fn(w, h, |x, y| {
            Luma([if (img.get_pixel(x, y)[0] > t) == light { 255 } else { 0 }])
        });
        let labels = connected_components(&mask, Connectivity::Four, Luma([0u8]));
        let n = labels.pixels().map(|p| p[0]).max().unwrap_or(0) as usize;
        let mut area = vec![0usize; n + 1];
        let mut border = vec![false; n + 1];
        for (x, y, p) in labels.enumerate_pixels() {
            let l = p[0] as usize;
            area[l] += 1;
            border[l] |= x == 0 || y == 0 || x + 1 == w || y + 1 == h;
        }
        let pick = (1..=n).filter(|&l| !border[l]).max_by_key(|&l| area[l]);
        if let Some(l) = pick.filter(|&l| best.as_ref().is_none_or(|b| area[l] > b.0)) {
            let only = GrayImage::from_fn(w, h, |x, y| {
                Luma([if labels.get_pixel(x, y)[0] as usize == l { 255 } else { 0 }])
            });
            best = Some((area[l], only));
        }
    }
    match best {
        Some((area, mask)) if area as f64 >= MIN_PLATE_SHARE * f64::from(w * h) => Ok(mask),
        _ => Err(LocateError::NoPlate(format!(
            "no region of even grey, clear of the photo's border, covers {:.0} % of it",
            100.0 * MIN_PLATE_SHARE
        ))),
    }
}

/// Rough corners: the hull of the plate's outer contour, simplified to four vertices.
fn rough_corners(mask: &GrayImage) -> Result<[[f64; 2]; 4], LocateError> {
    let contours = find_contours::<i32>(mask);
    let outer = contours
        .into_iter()
        .filter(|c| c.border_type == BorderType::Outer)
        .max_by_key(|c| c.points.len())
        .ok_or_else(|| LocateError::NoPlate("the plate region has no contour".into()))?;
    let hull = convex_hull(outer.points);
    let per: f64 = (0..hull.len())
        .map(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
            f64::from(a.x - b.x).hypot(f64::from(a.y - b.y))
        })
        .sum();
    let mut eps = 0.005 * per;
    let mut poly: Vec<Point<i32>> = hull.clone();
    while poly.len() > 4 && eps < 0.1 * per {
        poly = approximate_polygon_dp(&hull, eps, true);
        eps *= 1.3;
    }
    if poly.len() != 4 {
        return Err(LocateError::NoPlate(format!(
            "the plate region's outline has {} corners, not 4; give --corners",
            poly.len()
        )));
    }
    let pts: Vec<[f64; 2]> =
        poly.iter().map(|p| [f64::from(p.x) + 0.5, f64::from(p.y) + 0.5]).collect();
    let cx = pts.iter().map(|p| p[0]).sum::<f64>() / 4.0;
    let cy = pts.iter().map(|p| p[1]).sum::<f64>() / 4.0;
    // Math angle with the photo's y flipped: bottom-left ≈ −135°, then counter-clockwise.
    let mut sorted = pts.clone();
    sorted.sort_by(|a, b| {
        let ang = |p: &[f64; 2]| (cy - p[1]).atan2(p[0] - cx);
        ang(a).total_cmp(&ang(b))
    });
    Ok([sorted[0], sorted[1], sorted[2], sorted[3]])
}

/// Bilinear grey level at a continuous photo position.
fn grey(img: &GrayImage, [x, y]: [f64; 2]) -> f64 {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let (x, y) = (x - 0.5, y - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |i: i64, j: i64| {
        f64::from(img.get_pixel(i.clamp(0, w - 1) as u32, j.clamp(0, h - 1) as u32)[0])
    };
    let (i, j) = (x0 as i64, y0 as i64);
    let top = at(i, j) * (1.0 - fx) + at(i + 1, j) * fx;
    top * (1.0 - fy) + (at(i, j + 1) * (1.0 - fx) + at(i + 1, j + 1) * fx) * fy
}

/// A side's line (point, unit direction) fitted to edge crossings between corners `a` and `b`,
/// `out` pointing away from the plate, searched within `reach` px of the rough side.
fn fit_side(
    img: &GrayImage,
    a: [f64; 2],
    b: [f64; 2],
    out: [f64; 2],
    reach: f64,
) -> Option<([f64; 2], [f64; 2])> {
    let len = (b[0] - a[0]).hypot(b[1] - a[1]);
    let mut pts = Vec::new();
    let n = (len / 3.0) as usize;
    let steps = (4.0 * reach).round() as usize;
    let at = |k: usize| -reach + 0.5 * k as f64;
    for i in 0..n {
        let t = 0.1 + 0.8 * i as f64 / n.max(1) as f64;
        let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
        let v: Vec<f64> = (0..=steps)
            .map(|k| grey(img, [p[0] + at(k) * out[0], p[1] + at(k) * out[1]]))
            .collect();
        let (inside, outside) =
            ((v[0] + v[1] + v[2]) / 3.0, (v[steps - 2] + v[steps - 1] + v[steps]) / 3.0);
        if (inside - outside).abs() < 10.0 {
            continue;
        }
        let mid = 0.5 * (inside + outside);
        let sg = (inside - outside).signum();
        let cross = (0..steps)
            .filter(|&k| (v[k] - mid) * sg > 0.0 && (v[k + 1] - mid) * sg <= 0.0)
            .map(|k| at(k) + 0.5 * (v[k] - mid) / (v[k] - v[k + 1]))
            .min_by(|x, y| x.abs().total_cmp(&y.abs()));
        if let Some(s) = cross {
            pts.push([p[0] + s * out[0], p[1] + s * out[1]]);
        }
    }
    let mut line = tls(&pts)?;
    // One pass of outlier rejection: a part lying over the edge bends a few crossings.
    let keep: Vec<[f64; 2]> = pts.into_iter().filter(|p| dist(&line, *p) < 1.0).collect();
    if keep.len() >= 4 {
        line = tls(&keep)?;
    }
    Some(line)
}

fn dist((c, d): &([f64; 2], [f64; 2]), p: [f64; 2]) -> f64 {
    ((p[0] - c[0]) * d[1] - (p[1] - c[1]) * d[0]).abs()
}

/// Total least squares line through `pts`: (centroid, unit direction).
fn tls(pts: &[[f64; 2]]) -> Option<([f64; 2], [f64; 2])> {
    if pts.len() < 4 {
        return None;
    }
    let n = pts.len() as f64;
    let c = [pts.iter().map(|p| p[0]).sum::<f64>() / n, pts.iter().map(|p| p[1]).sum::<f64>() / n];
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for p in pts {
        let (x, y) = (p[0] - c[0], p[1] - c[1]);
        sxx += x * x;
        syy += y * y;
        sxy += x * y;
    }
    let a = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    Some((c, [a.cos(), a.sin()]))
}

fn intersect((p, d): ([f64; 2], [f64; 2]), (q, e): ([f64; 2], [f64; 2])) -> Option<[f64; 2]> {
    let den = d[0] * e[1] - d[1] * e[0];
    if den.abs() < 1e-9 {
        return None;
    }
    let t = ((q[0] - p[0]) * e[1] - (q[1] - p[1]) * e[0]) / den;
    Some([p[0] + t * d[0], p[1] + t * d[1]])
}

/// The plate's corners (photo pixels, x right, y down; bottom-left, bottom-right, top-right,
/// top-left), found from the plate's contrast with its surroundings.
pub(crate) fn find_corners(img: &GrayImage) -> Result<[[f64; 2]; 4], LocateError> {
    let k = img.width().max(img.height()).div_ceil(ROUGH_SIDE_PX).max(1);
    let small = rough_corners(&plate_mask(&shrink(img, k))?)?;
    // Shrunk pixel i spans photo pixels [k·i, k·(i + 1)): continuous positions scale by k.
    let rough = small.map(|p| [p[0] * f64::from(k), p[1] * f64::from(k)]);
    // The rough sides may be a shrunk pixel or two off: the window covers that, and is the
    // full-resolution search's ±5 px when nothing was shrunk.
    let reach = 5.0 + 2.0 * f64::from(k - 1);
    let cx = rough.iter().map(|p| p[0]).sum::<f64>() / 4.0;
    let cy = rough.iter().map(|p| p[1]).sum::<f64>() / 4.0;
    let mut sides = Vec::with_capacity(4);
    for k in 0..4 {
        let (a, b) = (rough[k], rough[(k + 1) % 4]);
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let mut out = [(b[1] - a[1]) / len, -(b[0] - a[0]) / len];
        let mid = [0.5 * (a[0] + b[0]) - cx, 0.5 * (a[1] + b[1]) - cy];
        if out[0] * mid[0] + out[1] * mid[1] < 0.0 {
            out = [-out[0], -out[1]];
        }
        let side = fit_side(img, a, b, out, reach)
            .ok_or_else(|| LocateError::NoPlate(format!("plate side {k} shows no clear edge")))?;
        sides.push(side);
    }
    let mut c = [[0.0; 2]; 4];
    for k in 0..4 {
        // Corner k joins side k−1 (ending at it) and side k (starting from it).
        c[k] = intersect(sides[(k + 3) % 4], sides[k])
            .ok_or_else(|| LocateError::NoPlate("two plate sides are parallel".into()))?;
    }
    Ok(c)
}

/// The square-pixel grid of the rectified plate: the map from its pixels to the photo's, its
/// size (px) and its pixel size (mm). The full view and a tracker's windows share it, so a
/// window's pixels are the full view's pixels.
pub(crate) struct Grid {
    /// Rectified pixel position (continuous, top row = the plate's top edge) → photo position.
    pub hom: Homography,
    /// Width (px).
    pub w: u32,
    /// Height (px).
    pub h: u32,
    /// Pixel size (mm).
    pub pix: f64,
}

impl Grid {
    /// The plate (`size_mm`) whose corners sit at `corners` in `img`, with square pixels as
    /// fine as the photo's finest view of the plate.
    pub fn new(
        img: &GrayImage,
        corners: [[f64; 2]; 4],
        size_mm: [f64; 2],
    ) -> Result<Grid, RectifyError> {
        check_corners(img.width(), img.height(), &corners)?;
        let len = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
        let [bl, br, tr, tl] = corners;
        let along_x = len(bl, br).max(len(tl, tr));
        let along_y = len(bl, tl).max(len(br, tr));
        let pix = (size_mm[0] / along_x).min(size_mm[1] / along_y);
        let (w, h) = (size_mm[0] / pix, size_mm[1] / pix);
        let out = [[0.0, h], [w, h], [w, 0.0], [0.0, 0.0]];
        let hom = Homography::from_points(out, corners).ok_or(RectifyError::NotConvex(corners))?;
        let (wi, hi) = (w.round().max(2.0) as u32, h.round().max(2.0) as u32);
        // Pixel size from the rounded image, so that the image spans the plate exactly.
        let pix = 0.5 * (size_mm[0] / f64::from(wi) + size_mm[1] / f64::from(hi));
        let out = [
            [0.0, f64::from(hi)],
            [f64::from(wi), f64::from(hi)],
            [f64::from(wi), 0.0],
            [0.0, 0.0],
        ];
        let hom = Homography::from_points(out, corners).unwrap_or(hom);
        Ok(Grid { hom, w: wi, h: hi, pix })
    }

    /// The part of the rectified view whose top-left pixel is (`x0`, `y0`), `w` × `h` pixels
    /// of `scale` × `scale` view pixels each, sampled from `img` at each one's centre: at
    /// scale 1, the full view's own pixels.
    pub fn window(
        &self,
        img: &GrayImage,
        [x0, y0, w, h]: [u32; 4],
        scale: u32,
    ) -> Option<GrayImage> {
        let s = f64::from(scale);
        let (x0, y0) = (f64::from(x0), f64::from(y0));
        let (fw, fh) = (f64::from(w), f64::from(h));
        let (x1, y1) = (x0 + fw * s, y0 + fh * s);
        let from = [[0.0, 0.0], [fw, 0.0], [fw, fh], [0.0, fh]];
        let to = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]].map(|p| self.hom.map(p));
        // The same projective map on a shifted, scaled domain: four points fix it.
        let hom = Homography::from_points(from, to)?;
        Some(warp(img, &hom, w, h, 0))
    }
}

/// The square-on view of the plate (`size_mm`) whose corners sit at `corners` in the photo,
/// with square pixels as fine as the photo's finest view of the plate: (image, mm per pixel).
pub(crate) fn rectify_square(
    img: &GrayImage,
    corners: [[f64; 2]; 4],
    size_mm: [f64; 2],
) -> Result<(GrayImage, f64), RectifyError> {
    let g = Grid::new(img, corners, size_mm)?;
    Ok((warp(img, &g.hom, g.w, g.h, 0), g.pix))
}
