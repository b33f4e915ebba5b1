//! Nodes made of coarse grains (the paper's urad lentils, ≈ 4 mm): a node is a band of
//! separate disks with gaps between them, which a threshold-and-skeleton pipeline breaks into
//! ragged pieces. Here the grain pixels themselves are the evidence:
//! 1. **Tracing.** Grain pixels are pooled into grain-sized cells; cells closer than 2.5
//!    grains are linked; the longest path through the minimum spanning tree of a linked
//!    group, averaged over 4 grains and simplified, follows one band (at a crossing it may
//!    turn into another: it is split at corners over 35° of a coarse outline); the cells
//!    within 3 grains leave the pool and the next path is traced.
//! 2. **Lines.** A traced piece is straight if it does not bow (parabola fit ≤ 1.25 grains;
//!    the wiggle between grains is random, a curve's bow systematic) and grains cover at
//!    least 60 % of its chord across the plate (a curve's tangent leaves its band). Its band
//!    (pixels within 1.5 grains) is refitted three times, dropping 4-grain stretches whose
//!    median offset leaves the line (a crossing node adds pixels to one side). Lines of the
//!    same direction (< 5°) and offset (< 3 grains), pieces of one band cut by a crossing, are
//!    merged; a line sharing a third of its pixels with a stronger one is dropped.
//! 3. **Curves** are traced again on the cells off the lines' bands, so no band remnant
//!    becomes a curve; every piece is a curve.
//! 4. Lines are refitted without their pixels near a curve (ends prolonged into the band).

use std::collections::{HashMap, HashSet, VecDeque};

use image::GrayImage;

use super::curves::{Curve, douglas_peucker};
use super::hough::{line_of, tls};
use super::{Found, Frame, Line, PhotoParams, clean, sand_mask};
use crate::plate::contour::distance_to;

/// Radius (grains) over which a band's traced path is averaged into its centre line.
const SMOOTH: f64 = 4.0;

/// Finds lines and curves made of grains `grain_px` pixels across.
pub fn find(img: &GrayImage, size_mm: [f64; 2], p: &PhotoParams, grain_px: f64) -> Found {
    let (mask, threshold, sand_is_dark) = sand_mask(img, p);
    let mask = clean(&mask, 1, 0);
    let frame = Frame::new(mask.w, mask.h, size_mm);
    let grain = grain_px * frame.pix;
    // One sample every quarter grain keeps ~12 points a grain.
    let stride = ((grain_px / 4.0).floor() as usize).max(1);
    let mut pts: Vec<[f64; 2]> = Vec::new();
    for y in (0..mask.h).step_by(stride) {
        for x in (0..mask.w).step_by(stride) {
            if mask.px[y * mask.w + x] {
                pts.push(frame.plate(y * mask.w + x));
            }
        }
    }
    let min_len = frame.min_length_mm(p);
    let pooled = cells(&pts, size_mm, grain);
    // Grain pixels sampled per grain (a disk a grain across, every `stride` pixels).
    let per_grain = std::f64::consts::PI * (0.5 * grain_px / stride as f64).powi(2);
    // 1. Lines: traced pieces that are straight and whose band crosses the plate.
    let mut lines = Vec::new();
    for piece in trace(&pooled, grain, min_len, p.max_lines) {
        if let Some(sel) = straight_fit(&piece, &pts, grain) {
            let band = band_pixels(&sel, &pts, grain);
            if chord_coverage(&band, size_mm, grain, per_grain) >= 0.6 {
                lines.push(band);
            }
        }
    }
    let lines = merge(lines, &pts, grain, size_mm);
    // 2. Curves: traced again without the lines' bands (3 grains each side, the band's
    //    stragglers included), so no remnant of a line band is taken for a curve.
    let fits: Vec<([f64; 2], [f64; 2])> = lines
        .iter()
        .map(|sel| {
            let (o, d, _) = tls(sel);
            (o, d)
        })
        .collect();
    let off_lines = |q: [f64; 2]| {
        fits.iter().all(|(o, d)| (-(q[0] - o[0]) * d[1] + (q[1] - o[1]) * d[0]).abs() > 3.0 * grain)
    };
    let rest: Vec<([f64; 2], usize)> = pooled.iter().copied().filter(|c| off_lines(c.0)).collect();
    let curves = trace(&rest, grain, min_len, p.max_lines);
    // 3. Lines refitted without the pixels where a curve crosses their band. The curves were
    //    traced without the bands, so they stop short of them: extend their ends into them.
    let reach: Vec<Vec<[f64; 2]>> = curves.iter().map(|c| extended(c, 5.0 * grain)).collect();
    let lines: Vec<Vec<[f64; 2]>> = lines
        .into_iter()
        .map(|sel| {
            let clear: Vec<[f64; 2]> =
                sel.iter().copied().filter(|q| distance_to(*q, &reach) > 2.0 * grain).collect();
            if clear.len() * 2 >= sel.len() { clear } else { sel }
        })
        .collect();
    let on_node = |q: &[f64; 2]| {
        lines.iter().any(|sel: &Vec<[f64; 2]>| sel.contains(q))
            || distance_to(*q, &curves) <= 1.5 * grain
    };
    let explained = pts.iter().filter(|q| on_node(q)).count();
    let centre = [size_mm[0] / 2.0, size_mm[1] / 2.0];
    Found {
        threshold,
        sand_is_dark,
        skeleton_pixels: pts.len(),
        unexplained_pixels: pts.len() - explained,
        lines: lines.iter().map(|sel| fit_line(sel, centre)).collect(),
        curves: curves.into_iter().map(|c| curve(c, &pts, grain)).collect(),
        size_mm,
        pixel_mm: frame.pix,
        sand_fraction: mask.count() as f64 / mask.px.len().max(1) as f64,
        coarse: true,
    }
}

/// Grain pixels pooled into cells a grain wide: (centroid, count).
fn cells(pts: &[[f64; 2]], size_mm: [f64; 2], grain: f64) -> Vec<([f64; 2], usize)> {
    let nx = (size_mm[0] / grain).ceil() as usize + 1;
    let ny = (size_mm[1] / grain).ceil() as usize + 1;
    let mut sums = vec![(0.0f64, 0.0f64, 0usize); nx * ny];
    for q in pts {
        let c = ((q[1] / grain).max(0.0) as usize).min(ny - 1) * nx
            + ((q[0] / grain).max(0.0) as usize).min(nx - 1);
        sums[c] = (sums[c].0 + q[0], sums[c].1 + q[1], sums[c].2 + 1);
    }
    sums.into_iter()
        .filter(|s| s.2 > 0)
        .map(|(x, y, n)| ([x / n as f64, y / n as f64], n))
        .collect()
}

/// Band centre lines, split at corners: the pieces at least `min_len` long.
fn trace(cells: &[([f64; 2], usize)], grain: f64, min_len: f64, max: usize) -> Vec<Vec<[f64; 2]>> {
    let mut pool = cells.to_vec();
    let mut pieces = Vec::new();
    for _ in 0..2 * max {
        let Some(path) = longest_group_path(&pool, 2.5 * grain) else { break };
        let smooth: Vec<[f64; 2]> = path
            .iter()
            .map(|&i| {
                let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
                for (c, n) in &pool {
                    if dist(*c, pool[i].0) <= SMOOTH * grain {
                        let w = *n as f64;
                        (sx, sy, sw) = (sx + w * c[0], sy + w * c[1], sw + w);
                    }
                }
                [sx / sw, sy / sw]
            })
            .collect();
        let line = simplified(&smooth, 0.5 * grain);
        if length(&line) < min_len {
            // The longest path left is too short: so is every other.
            break;
        }
        // Corners are judged on a coarse outline (1.5 grains), which the wiggle of the band
        // between grains does not turn.
        let coarse = douglas_peucker(&smooth, 1.5 * grain);
        let mut start = 0;
        for w in coarse.windows(3) {
            if turn(smooth[w[0]], smooth[w[1]], smooth[w[2]]) > 35f64.to_radians() {
                pieces.push(simplified(&smooth[start..=w[1]], 0.5 * grain));
                start = w[1];
            }
        }
        pieces.push(simplified(&smooth[start..], 0.5 * grain));
        pieces.retain(|l| length(l) >= min_len);
        let near: Vec<bool> = pool
            .iter()
            .map(|(c, _)| distance_to(*c, std::slice::from_ref(&line)) <= 3.0 * grain)
            .collect();
        let mut k = 0;
        pool.retain(|_| {
            k += 1;
            !near[k - 1]
        });
    }
    pieces
}

/// Turning angle (radians) at `b` of the path a → b → c.
fn turn(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let d = ((c[1] - b[1]).atan2(c[0] - b[0]) - (b[1] - a[1]).atan2(b[0] - a[0]))
        .rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

/// Douglas–Peucker simplification of `pts` at `tol`, as points.
fn simplified(pts: &[[f64; 2]], tol: f64) -> Vec<[f64; 2]> {
    douglas_peucker(pts, tol).into_iter().map(|i| pts[i]).collect()
}

/// The polyline with both ends prolonged by `by` along their last segments.
fn extended(l: &[[f64; 2]], by: f64) -> Vec<[f64; 2]> {
    let mut out = l.to_vec();
    let n = l.len();
    if n < 2 {
        return out;
    }
    let ext = |a: [f64; 2], b: [f64; 2]| {
        let d = dist(a, b).max(1e-9);
        [b[0] + (b[0] - a[0]) / d * by, b[1] + (b[1] - a[1]) / d * by]
    };
    out.insert(0, ext(l[1], l[0]));
    out.push(ext(l[n - 2], l[n - 1]));
    out
}

fn length(l: &[[f64; 2]]) -> f64 {
    l.windows(2).map(|w| dist(w[0], w[1])).sum()
}

/// Grain pixels within 1.5 grains of the line through `piece`, if the piece is straight
/// (every vertex within ¾ grain of that line).
fn straight_fit(piece: &[[f64; 2]], pts: &[[f64; 2]], grain: f64) -> Option<Vec<[f64; 2]>> {
    let (origin, dir, _) = tls(piece);
    let off = |q: &[f64; 2]| (-(q[0] - origin[0]) * dir[1] + (q[1] - origin[1]) * dir[0]).abs();
    // A band's centre line wiggles by a few millimetres between grains, randomly; a curve
    // bows systematically (the parabola fit of `sagitta` sees only that).
    if super::hough::sagitta(piece, origin, dir) > 1.25 * grain {
        return None;
    }
    // Pixels along the piece's extent only, so a crossing band beyond it does not count.
    let along = |q: &[f64; 2]| (q[0] - origin[0]) * dir[0] + (q[1] - origin[1]) * dir[1];
    let lo = piece.iter().map(along).fold(f64::INFINITY, f64::min) - grain;
    let hi = piece.iter().map(along).fold(f64::NEG_INFINITY, f64::max) + grain;
    Some(
        pts.iter()
            .filter(|q| off(q) <= 1.5 * grain && (lo..=hi).contains(&along(q)))
            .copied()
            .collect(),
    )
}

/// Fraction of the line's chord across the plate that grains cover (grain-long bins holding
/// a third of a grain or more). A straight node crosses the plate; the tangent of a short
/// curved piece leaves its band within a few grains.
fn chord_coverage(sel: &[[f64; 2]], size_mm: [f64; 2], grain: f64, per_grain: f64) -> f64 {
    let (origin, dir, _) = tls(sel);
    // Clip origin + t·dir to the plate (Liang–Barsky).
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..2 {
        if dir[k].abs() < 1e-12 {
            continue;
        }
        let (a, b) = ((0.0 - origin[k]) / dir[k], (size_mm[k] - origin[k]) / dir[k]);
        lo = lo.max(a.min(b));
        hi = hi.min(a.max(b));
    }
    if hi.is_nan() || lo.is_nan() || hi <= lo {
        return 0.0;
    }
    let n = ((hi - lo) / grain).ceil() as usize;
    let mut bins = vec![0.0f64; n.max(1)];
    for q in sel {
        let t = (q[0] - origin[0]) * dir[0] + (q[1] - origin[1]) * dir[1];
        if (lo..hi).contains(&t) {
            bins[(((t - lo) / grain) as usize).min(n.max(1) - 1)] += 1.0;
        }
    }
    bins.iter().filter(|&&c| c >= per_grain / 3.0).count() as f64 / bins.len() as f64
}

/// Merges lines (as their pixel sets) of about the same direction (< 5°) and offset (< 1.5
/// grains): one band cut into pieces by a crossing. Pieces of a lentil band fit to a few
/// degrees only; the merged line is refitted on all its pixels.
fn merge(
    mut sets: Vec<Vec<[f64; 2]>>,
    pts: &[[f64; 2]],
    grain: f64,
    size_mm: [f64; 2],
) -> Vec<Vec<[f64; 2]>> {
    let centre = [size_mm[0] / 2.0, size_mm[1] / 2.0];
    let mut merged = true;
    while merged {
        merged = false;
        'outer: for i in 0..sets.len() {
            for j in i + 1..sets.len() {
                let b = fit_line(&sets[j], centre);
                let (da, doff) = fit_line(&sets[i], centre).difference(b.angle_deg, b.offset_mm);
                if da < 5.0 && doff < 3.0 * grain {
                    let other = sets.swap_remove(j);
                    sets[i].extend(other);
                    sets[i] = band_pixels(&sets[i], pts, grain);
                    merged = true;
                    break 'outer;
                }
                // Two node lines share pixels only where they cross; sharing much more, the
                // weaker is a curve's tangent running along the stronger's band.
                let shared = sets[j].iter().filter(|q| sets[i].contains(q)).count();
                if shared * 3 > sets[i].len().min(sets[j].len()) {
                    let weaker = if sets[i].len() < sets[j].len() { i } else { j };
                    sets.swap_remove(weaker);
                    merged = true;
                    break 'outer;
                }
            }
        }
    }
    sets
}

/// All grain pixels within 1.5 grains of the line fitted to `sel`, along its whole length,
/// refitted twice (each fit centres the band better).
fn band_pixels(sel: &[[f64; 2]], pts: &[[f64; 2]], grain: f64) -> Vec<[f64; 2]> {
    let mut sel = sel.to_vec();
    for _ in 0..3 {
        let (origin, dir, _) = tls(&sel);
        let band: Vec<[f64; 2]> = pts
            .iter()
            .filter(|q| {
                (-(q[0] - origin[0]) * dir[1] + (q[1] - origin[1]) * dir[0]).abs() <= 1.5 * grain
            })
            .copied()
            .collect();
        sel = without_crossings(&band, origin, dir, grain);
    }
    sel
}

/// The band's pixels without the stretches where another node crosses it: the band is cut
/// into 4-grain bins along the line; each bin's median offset should lie on a straight line,
/// and bins off it by more than 2.5 median absolute deviations (at least half a grain) — a
/// crossing node adds pixels to one side — are dropped.
fn without_crossings(
    band: &[[f64; 2]],
    origin: [f64; 2],
    dir: [f64; 2],
    grain: f64,
) -> Vec<[f64; 2]> {
    let se = |q: &[f64; 2]| {
        let (dx, dy) = (q[0] - origin[0], q[1] - origin[1]);
        (dx * dir[0] + dy * dir[1], -dx * dir[1] + dy * dir[0])
    };
    let bin_len = 4.0 * grain;
    let mut bins: HashMap<i64, Vec<(f64, f64)>> = HashMap::new();
    for q in band {
        let (s, e) = se(q);
        bins.entry((s / bin_len).floor() as i64).or_default().push((s, e));
    }
    let mut med: Vec<(i64, f64, f64)> = bins
        .iter()
        .filter(|(_, v)| v.len() >= 3)
        .map(|(&k, v)| {
            let mut e: Vec<f64> = v.iter().map(|p| p.1).collect();
            e.sort_by(f64::total_cmp);
            (k, v.iter().map(|p| p.0).sum::<f64>() / v.len() as f64, e[e.len() / 2])
        })
        .collect();
    if med.len() < 3 {
        return band.to_vec();
    }
    // Straight line e = a + b s through the bin medians, then residuals.
    let fit = |m: &[(i64, f64, f64)]| {
        let n = m.len() as f64;
        let (ms, me) =
            (m.iter().map(|v| v.1).sum::<f64>() / n, m.iter().map(|v| v.2).sum::<f64>() / n);
        let sss: f64 = m.iter().map(|v| (v.1 - ms).powi(2)).sum();
        let b = if sss > 0.0 {
            m.iter().map(|v| (v.1 - ms) * (v.2 - me)).sum::<f64>() / sss
        } else {
            0.0
        };
        (me - b * ms, b)
    };
    let (a, b) = fit(&med);
    let mut res: Vec<f64> = med.iter().map(|v| (v.2 - a - b * v.1).abs()).collect();
    let mut sorted = res.clone();
    sorted.sort_by(f64::total_cmp);
    let limit = (2.5 * 1.4826 * sorted[sorted.len() / 2]).max(0.5 * grain);
    let mut k = 0;
    med.retain(|_| {
        k += 1;
        res[k - 1] <= limit
    });
    res.clear();
    let keep: HashSet<i64> = med.iter().map(|v| v.0).collect();
    band.iter().copied().filter(|q| keep.contains(&((se(q).0 / bin_len).floor() as i64))).collect()
}

/// The reported line through pixels (plate coordinates).
fn fit_line(sel: &[[f64; 2]], centre: [f64; 2]) -> Line {
    let rel: Vec<[f64; 2]> = sel.iter().map(|q| [q[0] - centre[0], q[1] - centre[1]]).collect();
    let (origin, dir, rms) = tls(&rel);
    line_of(&rel, origin, dir, rms, centre)
}

/// A traced piece as a reported curve: rms of the grain pixels within 1.5 grains of it.
fn curve(points: Vec<[f64; 2]>, pts: &[[f64; 2]], grain: f64) -> Curve {
    let one = std::slice::from_ref(&points);
    let near: Vec<f64> =
        pts.iter().map(|q| distance_to(*q, one)).filter(|d| *d <= 1.5 * grain).collect();
    let rms = (near.iter().map(|d| d * d).sum::<f64>() / near.len().max(1) as f64).sqrt();
    Curve { length_mm: length(&points), points, rms_mm: rms, pixels: near.len() }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Among the groups of `cells` linked by steps ≤ `link`, the longest path through a group's
/// minimum spanning tree (cell indices, in order); `None` if there are no cells.
fn longest_group_path(cells: &[([f64; 2], usize)], link: f64) -> Option<Vec<usize>> {
    let n = cells.len();
    let mut group = vec![usize::MAX; n];
    let mut best: Option<(f64, Vec<usize>)> = None;
    for s in 0..n {
        if group[s] != usize::MAX {
            continue;
        }
        // The group of s: breadth-first over links.
        group[s] = s;
        let mut members = vec![s];
        let mut k = 0;
        while k < members.len() {
            let u = members[k];
            k += 1;
            for v in 0..n {
                if group[v] == usize::MAX && dist(cells[u].0, cells[v].0) <= link {
                    group[v] = s;
                    members.push(v);
                }
            }
        }
        let tree = spanning_tree(cells, &members);
        let (a, _) = farthest(&tree, 0);
        let (len, path) = farthest(&tree, a).1;
        if best.as_ref().is_none_or(|b| len > b.0) {
            best = Some((len, path.into_iter().map(|i| members[i]).collect()));
        }
    }
    best.map(|b| b.1)
}

/// Minimum spanning tree (Prim) of `members`, as adjacency lists over their positions.
fn spanning_tree(cells: &[([f64; 2], usize)], members: &[usize]) -> Vec<Vec<(usize, f64)>> {
    let m = members.len();
    let at = |i: usize| cells[members[i]].0;
    let mut adj = vec![Vec::new(); m];
    let mut best = vec![(f64::INFINITY, usize::MAX); m];
    let mut done = vec![false; m];
    best[0].0 = 0.0;
    for _ in 0..m {
        let Some(u) = (0..m).filter(|&i| !done[i]).min_by(|&a, &b| best[a].0.total_cmp(&best[b].0))
        else {
            break;
        };
        done[u] = true;
        let (d, p) = best[u];
        if p != usize::MAX {
            adj[u].push((p, d));
            adj[p].push((u, d));
        }
        for v in 0..m {
            let d = dist(at(u), at(v));
            if !done[v] && d < best[v].0 {
                best[v] = (d, u);
            }
        }
    }
    adj
}

/// The tree node farthest from `from` along the tree: (node, (distance, path from it back to
/// `from`)).
fn farthest(adj: &[Vec<(usize, f64)>], from: usize) -> (usize, (f64, Vec<usize>)) {
    let n = adj.len();
    let mut d = vec![f64::INFINITY; n];
    let mut prev = vec![usize::MAX; n];
    d[from] = 0.0;
    let mut queue = VecDeque::from([from]);
    while let Some(u) = queue.pop_front() {
        for &(v, w) in &adj[u] {
            if d[v].is_infinite() {
                d[v] = d[u] + w;
                prev[v] = u;
                queue.push_back(v);
            }
        }
    }
    let end =
        (0..n).filter(|&i| d[i].is_finite()).max_by(|&a, &b| d[a].total_cmp(&d[b])).unwrap_or(from);
    let mut path = vec![end];
    let mut u = end;
    while prev[u] != usize::MAX {
        u = prev[u];
        path.push(u);
    }
    (end, (d[end], path))
}
