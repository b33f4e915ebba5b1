//! Straight nodes: a Hough transform of the skeleton pixels in plate coordinates, each peak
//! refined by total least squares over the pixels within a band, its pixels removed, and the
//! next peak taken; a candidate that bows is a piece of a curved node and is left for the
//! curve tracer.

use super::{Frame, Line, Mask, PhotoParams};

/// Total-least-squares line through points: (centroid, unit direction, rms distance).
pub(super) fn tls(pts: &[[f64; 2]]) -> ([f64; 2], [f64; 2], f64) {
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

/// The Hough accumulator's geometry: 360 directions (0.5° bins) and 1-pixel offset bins in
/// plate coordinates relative to the centre.
struct Accumulator {
    trig: Vec<(f64, f64)>,
    rho_max: f64,
    n_rho: usize,
    pix: f64,
}

impl Accumulator {
    fn new(frame: &Frame) -> Accumulator {
        let n_theta = 360usize;
        let rho_max = 0.5 * frame.size_mm[0].hypot(frame.size_mm[1]);
        let n_rho = (2.0 * rho_max / frame.pix).ceil() as usize + 1;
        let trig = (0..n_theta)
            .map(|k| {
                let a = std::f64::consts::PI * k as f64 / n_theta as f64;
                (a.sin(), a.cos())
            })
            .collect();
        Accumulator { trig, rho_max, n_rho, pix: frame.pix }
    }

    /// The strongest line through `pts`: (votes, origin, unit direction).
    fn peak(&self, pts: &[[f64; 2]]) -> (usize, [f64; 2], [f64; 2]) {
        let (n_theta, n_rho, pix) = (self.trig.len(), self.n_rho, self.pix);
        // Hough: line at direction α has normal n̂ = (−sin α, cos α), offset ρ = n̂·p.
        let mut acc = vec![0u32; n_theta * n_rho];
        for q in pts {
            for (k, &(s, c)) in self.trig.iter().enumerate() {
                let rho = -s * q[0] + c * q[1];
                let r = ((rho + self.rho_max) / pix).round() as usize;
                acc[k * n_rho + r.min(n_rho - 1)] += 1;
            }
        }
        let (best, &votes) = acc.iter().enumerate().max_by_key(|&(_, v)| *v).unwrap_or((0, &0));
        let a = std::f64::consts::PI * (best / n_rho) as f64 / n_theta as f64;
        let rho = (best % n_rho) as f64 * pix - self.rho_max;
        (votes as usize, [-a.sin() * rho, a.cos() * rho], [a.cos(), a.sin()])
    }
}

/// Total least squares over the points within `band` of a line, three times: (inlier
/// indices, origin, direction, rms).
fn refine(
    pts: &[[f64; 2]],
    mut origin: [f64; 2],
    mut dir: [f64; 2],
    band: f64,
) -> (Vec<usize>, [f64; 2], [f64; 2], f64) {
    let mut inliers: Vec<usize> = Vec::new();
    let mut rms = 0.0;
    for _ in 0..3 {
        inliers = (0..pts.len())
            .filter(|&i| {
                (-(pts[i][0] - origin[0]) * dir[1] + (pts[i][1] - origin[1]) * dir[0]).abs() <= band
            })
            .collect();
        if inliers.len() < 2 {
            break;
        }
        let sel: Vec<[f64; 2]> = inliers.iter().map(|&i| pts[i]).collect();
        (origin, dir, rms) = tls(&sel);
    }
    (inliers, origin, dir, rms)
}

/// Hough + total least squares on the skeleton: the straight lines, and the skeleton with
/// their pixels removed. imageproc's `hough::detect_lines` is not used: it votes in whole
/// degrees on pixel coordinates and returns no vote counts, while this search needs the
/// strongest peak's votes (the stopping rule), 0.5° bins in plate coordinates (pixels need not
/// be square) and a fresh vote after each line's pixels are removed.
pub(super) fn straight_lines(sk: &Mask, frame: &Frame, p: &PhotoParams) -> (Vec<Line>, Mask) {
    let centre = [frame.size_mm[0] / 2.0, frame.size_mm[1] / 2.0];
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
    let acc = Accumulator::new(frame);
    let min_pixels = (frame.min_length_mm(p) / frame.pix) as usize;
    let band = p.band_px * frame.pix;
    let mut lines = Vec::new();
    // Curved candidates are dropped from the vote without ending the search; the cap keeps
    // the loop finite however many there are.
    let mut tries = 0;
    while lines.len() < p.max_lines && tries < 4 * p.max_lines && pts.len() >= min_pixels.max(2) {
        tries += 1;
        let (votes, origin, dir) = acc.peak(&pts);
        if votes < min_pixels {
            break;
        }
        let (inliers, origin, dir, rms) = refine(&pts, origin, dir, band);
        if inliers.len() < min_pixels {
            break;
        }
        let sel: Vec<[f64; 2]> = inliers.iter().map(|&i| pts[i]).collect();
        let straight = sagitta(&sel, origin, dir) <= p.max_sagitta_px * frame.pix;
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
pub(super) fn sagitta(pts: &[[f64; 2]], origin: [f64; 2], dir: [f64; 2]) -> f64 {
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
pub(super) fn line_of(
    sel: &[[f64; 2]],
    origin: [f64; 2],
    dir: [f64; 2],
    rms: f64,
    centre: [f64; 2],
) -> Line {
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
