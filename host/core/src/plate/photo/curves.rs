//! Curved nodes: the skeleton pixels the straight lines leave over, traced into 8-connected
//! chains split at junctions and ends, with short side branches pruned, each simplified by
//! Douglas–Peucker into a polyline.

use std::collections::{HashMap, HashSet};

use super::{Frame, Mask, PhotoParams};
use crate::plate::contour::{Polyline, segment_foot, total_length};

/// A curved node found in a photo.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    /// Simplified polyline (plate coordinates, mm; closed if first == last).
    pub points: Polyline,
    /// Length of the polyline (mm).
    pub length_mm: f64,
    /// RMS distance of the chain's pixels from the polyline (mm).
    pub rms_mm: f64,
    /// Skeleton pixels in the chain.
    pub pixels: usize,
}

/// 8-neighbour offsets.
const N8: [(isize, isize); 8] =
    [(0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1)];

/// Curves among the skeleton pixels `rest` (the skeleton minus the straight lines' pixels).
pub(super) fn trace(rest: &Mask, frame: &Frame, p: &PhotoParams) -> Vec<Curve> {
    let mut m = rest.clone();
    thin_corners(&mut m);
    prune_spurs(&mut m, p.spur_px);
    let min_len = frame.min_length_mm(p);
    let tol = p.simplify_px * frame.pix;
    let max_turn = 1.0 / (p.min_radius * frame.size_mm[0].min(frame.size_mm[1]));
    let mut curves: Vec<Curve> = chains(&m)
        .into_iter()
        .filter_map(|c| {
            let pts: Polyline = c.iter().map(|&i| frame.plate(i)).collect();
            (total_length(std::slice::from_ref(&pts)) >= min_len).then(|| curve_of(&pts, tol))
        })
        .filter(|c| {
            // Measured on a coarser simplification: pixel steps add turning to any chain.
            let coarse: Polyline =
                douglas_peucker(&c.points, 2.0 * tol).into_iter().map(|k| c.points[k]).collect();
            turning(&coarse) <= max_turn * c.length_mm
        })
        .collect();
    curves.sort_by(|a, b| b.length_mm.total_cmp(&a.length_mm));
    curves
}

fn neighbours(m: &Mask, i: usize) -> impl Iterator<Item = usize> + '_ {
    let (x, y) = ((i % m.w) as isize, (i / m.w) as isize);
    N8.iter()
        .filter(move |&&(dx, dy)| m.get(x + dx, y + dy))
        .map(move |&(dx, dy)| (y + dy) as usize * m.w + (x + dx) as usize)
}

fn degrees(m: &Mask) -> Vec<usize> {
    (0..m.px.len()).map(|i| if m.px[i] { neighbours(m, i).count() } else { 0 }).collect()
}

/// Removes pixels whose neighbours stay connected without them (the corner of a staircase
/// step, the middle of a pixel triangle at a bend): then a pixel inside a curve has exactly
/// two neighbours and only real junctions split chains. Ends (one neighbour) and pixels
/// that join separate neighbours (lines, junctions) stay.
fn thin_corners(m: &mut Mask) {
    for i in 0..m.px.len() {
        if !m.px[i] {
            continue;
        }
        let (x, y) = ((i % m.w) as isize, (i / m.w) as isize);
        let ring: Vec<(isize, isize)> =
            N8.iter().copied().filter(|&(dx, dy)| m.get(x + dx, y + dy)).collect();
        if ring.len() >= 2 && connected(&ring) {
            m.px[i] = false;
        }
    }
}

/// Whether pixels at the given offsets form one 8-connected group.
fn connected(ring: &[(isize, isize)]) -> bool {
    let mut seen = vec![false; ring.len()];
    seen[0] = true;
    let mut stack = vec![0];
    while let Some(a) = stack.pop() {
        for b in 0..ring.len() {
            let near = (ring[a].0 - ring[b].0).abs() <= 1 && (ring[a].1 - ring[b].1).abs() <= 1;
            if !seen[b] && near {
                seen[b] = true;
                stack.push(b);
            }
        }
    }
    seen.iter().all(|&s| s)
}

/// Deletes side branches shorter than `max_px` (an end pixel joined to a junction): sand
/// lumps leave them on the skeleton, and each would split its curve in two. A junction keeps
/// two branches: its long ones first, then its longest spurs, so the true end of a curve that
/// forks near its end is shortened, not lost.
fn prune_spurs(m: &mut Mask, max_px: usize) {
    for _ in 0..4 {
        let deg = degrees(m);
        let all = chains(m);
        // Per junction pixel: its long branches, and its spurs as (length, chain index).
        let mut at: HashMap<usize, (usize, Vec<(usize, usize)>)> = HashMap::new();
        for (k, c) in all.iter().enumerate() {
            let (a, b) = (c[0], c[c.len() - 1]);
            let spur = c.len() < max_px && (deg[a] == 1 || deg[b] == 1);
            for j in [a, b].into_iter().filter(|&j| deg[j] >= 3) {
                let e = at.entry(j).or_default();
                if spur {
                    e.1.push((c.len(), k));
                } else {
                    e.0 += 1;
                }
            }
        }
        let mut removed = false;
        for (long, mut spurs) in at.into_values() {
            spurs.sort_by_key(|s| std::cmp::Reverse(s.0));
            for &(_, k) in spurs.iter().skip(2usize.saturating_sub(long)) {
                for &i in &all[k] {
                    if deg[i] <= 2 {
                        m.px[i] = false;
                        removed = true;
                    }
                }
            }
        }
        if !removed {
            return;
        }
        thin_corners(m);
    }
}

/// Pixel chains of a thin mask: from every end or junction pixel along each of its
/// neighbours to the next end or junction, then closed loops (which have neither).
fn chains(m: &Mask) -> Vec<Vec<usize>> {
    let deg = degrees(m);
    let key = |a: usize, b: usize| (a.min(b), a.max(b));
    let walk = |start: usize, first: usize, used: &mut HashSet<(usize, usize)>| {
        let mut chain = vec![start, first];
        used.insert(key(start, first));
        let (mut prev, mut cur) = (start, first);
        while deg[cur] == 2 && cur != start {
            let Some(next) =
                neighbours(m, cur).find(|&q| q != prev && !used.contains(&key(cur, q)))
            else {
                break;
            };
            used.insert(key(cur, next));
            chain.push(next);
            (prev, cur) = (cur, next);
        }
        chain
    };
    let mut used = HashSet::new();
    let mut out = Vec::new();
    for i in (0..m.px.len()).filter(|&i| m.px[i] && deg[i] != 2) {
        let firsts: Vec<usize> = neighbours(m, i).collect();
        for q in firsts {
            if !used.contains(&key(i, q)) {
                out.push(walk(i, q, &mut used));
            }
        }
    }
    let mut on_chain = vec![false; m.px.len()];
    for &i in out.iter().flatten() {
        on_chain[i] = true;
    }
    for i in 0..m.px.len() {
        if m.px[i]
            && deg[i] == 2
            && !on_chain[i]
            && let Some(q) = neighbours(m, i).next()
        {
            let c = walk(i, q, &mut used);
            for &j in &c {
                on_chain[j] = true;
            }
            out.push(c);
        }
    }
    out
}

/// Indices of the points Douglas–Peucker keeps at tolerance `tol`: both ends, then, span by
/// span, the point farthest from the span's chord while it is farther than `tol`. A closed
/// chain (first == last) has a zero-length chord, so its first split is the farthest point.
pub(crate) fn douglas_peucker(pts: &[[f64; 2]], tol: f64) -> Vec<usize> {
    if pts.len() < 3 {
        return (0..pts.len()).collect();
    }
    let mut keep = vec![false; pts.len()];
    keep[0] = true;
    keep[pts.len() - 1] = true;
    let mut stack = vec![(0, pts.len() - 1)];
    while let Some((a, b)) = stack.pop() {
        let far = (a + 1..b)
            .map(|k| (k, segment_foot(pts[k], pts[a], pts[b]).1))
            .max_by(|x, y| x.1.total_cmp(&y.1));
        if let Some((k, d)) = far
            && d > tol
        {
            keep[k] = true;
            stack.push((a, k));
            stack.push((k, b));
        }
    }
    (0..pts.len()).filter(|&k| keep[k]).collect()
}

/// Total absolute turning angle (radians) along a polyline: a node bends gently (a circle of
/// radius R turns 1/R per mm), a chain through scattered grains zig-zags.
pub fn turning(points: &[[f64; 2]]) -> f64 {
    points
        .windows(3)
        .map(|w| {
            let a = (w[1][1] - w[0][1]).atan2(w[1][0] - w[0][0]);
            let b = (w[2][1] - w[1][1]).atan2(w[2][0] - w[1][0]);
            let d = (b - a).rem_euclid(std::f64::consts::TAU);
            d.min(std::f64::consts::TAU - d)
        })
        .sum()
}

/// Simplifies a pixel chain (plate coordinates) into a curve.
fn curve_of(pts: &[[f64; 2]], tol: f64) -> Curve {
    let keep = douglas_peucker(pts, tol);
    let points: Polyline = keep.iter().map(|&k| pts[k]).collect();
    // Each pixel against the segment that replaced it.
    let sq: f64 = keep
        .windows(2)
        .flat_map(|w| (w[0]..w[1]).map(move |k| (k, w[0], w[1])))
        .map(|(k, a, b)| segment_foot(pts[k], pts[a], pts[b]).1.powi(2))
        .sum();
    let closed = pts.len() > 2 && pts.first() == pts.last();
    let pixels = pts.len() - usize::from(closed);
    Curve {
        length_mm: total_length(std::slice::from_ref(&points)),
        rms_mm: (sq / (pts.len() - 1).max(1) as f64).sqrt(),
        pixels,
        points,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(w: usize, h: usize, set: impl Fn(usize, usize) -> bool) -> Mask {
        Mask { w, h, px: (0..w * h).map(|i| set(i % w, i / w)).collect() }
    }

    #[test]
    fn staircase_is_one_chain_and_a_spur_is_pruned() {
        // A 4-connected staircase (every step has a corner pixel) plus a 3-pixel spur.
        let m = mask(30, 30, |x, y| {
            ((x == y || x == y + 1) && x < 28) || (x + y == 20 && (11..15).contains(&x))
        });
        let mut t = m.clone();
        thin_corners(&mut t);
        prune_spurs(&mut t, 10);
        let c = chains(&t);
        assert_eq!(c.len(), 1, "{c:?}");
        assert!(c[0].len() >= 20, "{}", c[0].len());
    }

    #[test]
    fn ring_is_one_closed_chain() {
        let m = mask(40, 40, |x, y| {
            let r = (x as f64 - 20.0).hypot(y as f64 - 20.0);
            (r - 12.0).abs() < 0.5
        });
        let mut t = m.clone();
        thin_corners(&mut t);
        let c = chains(&t);
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].first(), c[0].last());
    }

    #[test]
    fn douglas_peucker_keeps_corners_only() {
        let pts: Vec<[f64; 2]> = (0..=20)
            .map(|k| if k <= 10 { [k as f64, 0.0] } else { [10.0, (k - 10) as f64] })
            .collect();
        assert_eq!(douglas_peucker(&pts, 0.5), vec![0, 10, 20]);
    }
}
