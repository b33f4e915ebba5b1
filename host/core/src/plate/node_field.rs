//! A sampled mode shape from node curves alone: φ = signed distance to the nearest node.
//!
//! A grid node's field is f = −∇(K φ²), so φ only has to vanish on the nodes and grow away
//! from them; the distance does that with |∇φ| = 1 (the linear law's pull). The sign makes
//! the nodes zero *crossings*, as in a real mode shape, so contouring the grid gives the nodes
//! back: the nodes cut the plate into regions, and regions on the two sides of a node get
//! opposite signs (a 2-colouring). When no such colouring exists (a node ending inside the
//! plate, three regions meeting pairwise) φ is the unsigned distance, which still pulls parts
//! onto the nodes but has no zero crossings.

use std::collections::{HashMap, VecDeque};

use super::contour::{Polyline, segment_foot};
use crate::model::grid::Grid;

/// φ on a grid, and how its sign was found.
#[derive(Debug, Clone)]
pub struct NodeField {
    /// φ, normalised like the solver's grids (max |φ| = 1, the largest sample positive).
    pub grid: Grid,
    /// Whether φ changes sign across the nodes (false: unsigned distance).
    pub signed: bool,
    /// Regions the nodes cut the plate into.
    pub regions: usize,
    /// Why φ is unsigned, if it is.
    pub note: Option<String>,
}

/// Why no field could be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FieldError {
    /// Nothing to measure distance to.
    #[error("no node curves: nothing to build a grid node from")]
    NoNodes,
    /// Grid too small.
    #[error("the grid needs at least 2×2 samples, got {0}×{1}")]
    Size(usize, usize),
    /// Plate size not positive.
    #[error("plate size must be positive, got {0:?}")]
    Plate([f64; 2]),
}

/// Nearest point on any segment of `nodes` except polyline `skip`: (point, distance).
fn nearest_on(p: [f64; 2], nodes: &[Polyline], skip: Option<usize>) -> Option<([f64; 2], f64)> {
    nodes
        .iter()
        .enumerate()
        .filter(|&(k, _)| Some(k) != skip)
        .flat_map(|(_, l)| l.windows(2).map(|w| segment_foot(p, w[0], w[1])))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// Nearest point on the plate's edge.
fn nearest_edge(p: [f64; 2], size_mm: [f64; 2]) -> ([f64; 2], f64) {
    let [x, y] = [p[0].clamp(0.0, size_mm[0]), p[1].clamp(0.0, size_mm[1])];
    [[0.0, y], [size_mm[0], y], [x, 0.0], [x, size_mm[1]]]
        .into_iter()
        .map(|q| (q, (p[0] - q[0]).hypot(p[1] - q[1])))
        .fold(([0.0, 0.0], f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a })
}

/// Closes the gaps at open node ends: an end within `snap_mm` of the plate edge or of another
/// node gets the nearest such point appended; a polyline whose two ends are that close (and
/// that is long enough not to be a blob) is closed.
pub(crate) fn snap_ends(nodes: &[Polyline], size_mm: [f64; 2], snap_mm: f64) -> Vec<Polyline> {
    let target = |p: [f64; 2], k: usize| {
        let other = nearest_on(p, nodes, Some(k));
        let edge = nearest_edge(p, size_mm);
        let best = match other {
            Some(o) if o.1 < edge.1 => o,
            _ => edge,
        };
        (best.1 > 1e-9 && best.1 <= snap_mm).then_some(best.0)
    };
    nodes
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let mut l = l.clone();
            let (Some(&a), Some(&b)) = (l.first(), l.last()) else { return l };
            let gap = (a[0] - b[0]).hypot(a[1] - b[1]);
            let length = super::contour::total_length(std::slice::from_ref(&l));
            if l.len() < 2 || gap == 0.0 {
                return l;
            }
            if gap <= snap_mm && length > 4.0 * snap_mm {
                l.push(a);
                return l;
            }
            if let Some(q) = target(a, k) {
                l.insert(0, q);
            }
            if let Some(q) = target(b, k) {
                l.push(q);
            }
            l
        })
        .collect()
}

/// Nearest node point of every grid point: (foot, distance).
fn nearest_all(nodes: &[Polyline], grid: &Grid) -> Vec<([f64; 2], f64)> {
    let mut out = Vec::with_capacity(grid.nx * grid.ny);
    for j in 0..grid.ny {
        for i in 0..grid.nx {
            let p = grid.point(i, j);
            let single = nodes.iter().filter(|l| l.len() == 1).map(|l| segment_foot(p, l[0], l[0]));
            let best = nearest_on(p, nodes, None)
                .into_iter()
                .chain(single)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap_or(([0.0, 0.0], f64::INFINITY));
            out.push(best);
        }
    }
    out
}

/// Labels the 4-connected components of the grid points off the nodes; returns (labels,
/// count).
fn regions(off: &[bool], nx: usize, ny: usize) -> (Vec<Option<usize>>, usize) {
    let mut label = vec![None; off.len()];
    let mut count = 0;
    for start in 0..off.len() {
        if !off[start] || label[start].is_some() {
            continue;
        }
        label[start] = Some(count);
        let mut queue = VecDeque::from([start]);
        while let Some(k) = queue.pop_front() {
            let (i, j) = (k % nx, k / nx);
            let steps =
                [(i > 0, k.wrapping_sub(1)), (i + 1 < nx, k + 1), (j > 0, k.wrapping_sub(nx))];
            for (ok, n) in steps.into_iter().chain([(j + 1 < ny, k + nx)]) {
                if ok && off[n] && label[n].is_none() {
                    label[n] = Some(count);
                    queue.push_back(n);
                }
            }
        }
        count += 1;
    }
    (label, count)
}

/// Sampling geometry shared by the steps: the grid, its node band and region labels.
struct Cells<'a> {
    grid: &'a Grid,
    /// Grid spacing (larger of x and y).
    step: f64,
    label: Vec<Option<usize>>,
}

impl Cells<'_> {
    /// First region met walking from `from` along `u` in quarter steps, up to 3 steps: the
    /// region on that side of the node `from` is on (or near). Short steps keep the walk from
    /// jumping past a second node close by, as near a crossing.
    fn probe(&self, from: [f64; 2], u: [f64; 2]) -> Option<usize> {
        let g = self.grid;
        let (dx, dy) = (g.size_mm[0] / (g.nx - 1) as f64, g.size_mm[1] / (g.ny - 1) as f64);
        (1..=12).find_map(|k| {
            let d = 0.25 * self.step * k as f64;
            let (x, y) = (from[0] + d * u[0], from[1] + d * u[1]);
            let i = (x / dx).round();
            let j = (y / dy).round();
            let inside = i >= 0.0 && j >= 0.0 && i < g.nx as f64 && j < g.ny as f64;
            if inside { self.label[j as usize * g.nx + i as usize] } else { None }
        })
    }

    /// How often probes on the two sides of the nodes hit each pair of regions (key sorted).
    fn sides(&self, nodes: &[Polyline]) -> HashMap<(usize, usize), usize> {
        let mut count = HashMap::new();
        for (k, w) in nodes.iter().enumerate().flat_map(|(k, l)| l.windows(2).map(move |w| (k, w)))
        {
            let (a, b) = (w[0], w[1]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            if len == 0.0 {
                continue;
            }
            let n = [-(b[1] - a[1]) / len, (b[0] - a[0]) / len];
            let samples = ((len / self.step) as usize).max(1);
            for s in 0..samples {
                let t = (s as f64 + 0.5) / samples as f64;
                let f = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                // Near another node (a crossing) a probe could pass it and meet a region
                // diagonally across; the sides are probed farther along the node instead.
                if nearest_on(f, nodes, Some(k)).is_some_and(|o| o.1 < 4.0 * self.step) {
                    continue;
                }
                if let (Some(p), Some(q)) = (self.probe(f, n), self.probe(f, [-n[0], -n[1]])) {
                    *count.entry((p.min(q), p.max(q))).or_insert(0) += 1;
                }
            }
        }
        count
    }
}

/// Colours regions so that regions on the two sides of a node differ; Err names the clash.
/// Side pairs seen only once are ignored: a probe near a crossing can land past another node.
fn two_colour(n: usize, sides: &HashMap<(usize, usize), usize>) -> Result<Vec<bool>, String> {
    let mut adj = vec![Vec::new(); n];
    for (&(a, b), &c) in sides {
        if c < 2 {
            continue;
        }
        if a == b {
            return Err(format!("a node has region {a} on both sides (it ends inside the plate)"));
        }
        adj[a].push(b);
        adj[b].push(a);
    }
    let mut colour: Vec<Option<bool>> = vec![None; n];
    for start in 0..n {
        if colour[start].is_some() {
            continue;
        }
        colour[start] = Some(true);
        let mut queue = VecDeque::from([start]);
        while let Some(r) = queue.pop_front() {
            let c = colour[r].unwrap_or(true);
            for &s in &adj[r] {
                match colour[s] {
                    None => {
                        colour[s] = Some(!c);
                        queue.push_back(s);
                    }
                    Some(cs) if cs == c => {
                        return Err(format!(
                            "regions {r} and {s} border each other across a node and \
                             through a chain of an odd number of nodes (not 2-colourable)"
                        ));
                    }
                    Some(_) => {}
                }
            }
        }
    }
    Ok(colour.into_iter().map(|c| c.unwrap_or(true)).collect())
}

/// φ = distance to the nearest of `nodes` (plate coordinates, mm), signed by a 2-colouring
/// of the regions they cut the plate into, on an `nx × ny` grid over the plate.
pub fn node_field(
    nodes: &[Polyline],
    size_mm: [f64; 2],
    nx: usize,
    ny: usize,
) -> Result<NodeField, FieldError> {
    if nx < 2 || ny < 2 {
        return Err(FieldError::Size(nx, ny));
    }
    if !size_mm.iter().all(|v| v.is_finite() && *v > 0.0) {
        return Err(FieldError::Plate(size_mm));
    }
    if nodes.iter().all(|l| l.is_empty()) {
        return Err(FieldError::NoNodes);
    }
    let mut grid = Grid { nx, ny, size_mm, values: vec![0.0; nx * ny] };
    let near = nearest_all(nodes, &grid);
    let step = (size_mm[0] / (nx - 1) as f64).max(size_mm[1] / (ny - 1) as f64);
    // Points closer than `band` to a node are on it. Any segment joining two 4-neighbours
    // that crosses a node has an end within step/2 of it, so a band wider than that keeps
    // the regions on the two sides apart.
    let band = 0.6 * step;
    let off: Vec<bool> = near.iter().map(|n| n.1 >= band).collect();
    let (label, count) = regions(&off, nx, ny);
    let cells = Cells { grid: &grid, step, label };
    let colours = two_colour(count, &cells.sides(nodes));
    let values: Vec<f64> = (0..nx * ny)
        .map(|k| {
            let (foot, d) = near[k];
            let Ok(colour) = &colours else { return d };
            let region = cells.label[k].or_else(|| {
                // On a node's band: the region on this point's side of its nearest node.
                let p = grid.point(k % nx, k / nx);
                let u = (d > 0.0).then(|| [(p[0] - foot[0]) / d, (p[1] - foot[1]) / d]);
                u.and_then(|u| cells.probe(p, u))
            });
            if region.is_some_and(|r| !colour[r]) { -d } else { d }
        })
        .collect();
    let peak = values.iter().copied().fold(0.0f64, |m, v| if v.abs() > m.abs() { v } else { m });
    if peak == 0.0 || !peak.is_finite() {
        return Err(FieldError::NoNodes);
    }
    grid.values = values.into_iter().map(|v| v / peak).collect();
    Ok(NodeField { grid, signed: colours.is_ok(), regions: count, note: colours.err() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plate::contour::{distance_to, node_lines};

    const SIZE: [f64; 2] = [300.0, 200.0];

    fn circle(c: [f64; 2], r: f64) -> Polyline {
        (0..=120)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 120.0;
                [c[0] + r * a.cos(), c[1] + r * a.sin()]
            })
            .collect()
    }

    /// Worst distance from the grid's zero set to `truth`, and from `truth` to the zero set.
    fn zero_set_error(field: &NodeField, truth: &[Polyline]) -> (f64, f64) {
        let zero = node_lines(&field.grid);
        let worst = |a: &[Polyline], b: &[Polyline]| {
            a.iter().flatten().map(|&p| distance_to(p, b)).fold(0.0, f64::max)
        };
        (worst(&zero, truth), worst(truth, &zero))
    }

    #[test]
    fn circle_and_crossing_lines_are_signed_and_their_zero_set_is_the_nodes() {
        let nodes = vec![circle([150.0, 100.0], 50.0)];
        let f = node_field(&nodes, SIZE, 61, 41).unwrap();
        assert!(f.signed && f.regions == 2, "{:?}", f.note);
        // Inside and outside differ in sign; |φ| is the distance, normalised.
        let (inside, outside) = (f.grid.at(30, 20), f.grid.at(0, 0));
        assert!(inside * outside < 0.0);
        let peak = f.grid.values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!((peak - 1.0).abs() < 1e-12);
        let far = 150.0f64.hypot(100.0) - 50.0;
        // (The 120-gon's sides sit up to 0.02 mm inside the circle.)
        assert!((outside.abs() - 1.0).abs() < 1e-9 && (inside.abs() - 50.0 / far).abs() < 1e-3);
        let (e1, e2) = zero_set_error(&f, &nodes);
        assert!(e1 < 0.3 && e2 < 0.3, "{e1} {e2}");

        let cross = vec![vec![[0.0, 80.0], [300.0, 130.0]], vec![[120.0, 0.0], [180.0, 200.0]]];
        let f = node_field(&cross, SIZE, 61, 41).unwrap();
        assert!(f.signed && f.regions == 4, "{:?}", f.note);
        let (e1, e2) = zero_set_error(&f, &cross);
        println!("crossing lines: zero set → nodes {e1:.2} mm, nodes → zero set {e2:.2} mm");
        assert!(e1 < 2.5 && e2 < 5.0, "{e1} {e2}");
    }

    #[test]
    fn a_node_ending_inside_the_plate_gives_the_unsigned_distance() {
        let nodes = vec![vec![[50.0, 100.0], [200.0, 100.0]]];
        let f = node_field(&nodes, SIZE, 31, 21).unwrap();
        assert!(!f.signed && f.regions == 1);
        assert!(f.note.as_deref().is_some_and(|n| n.contains("both sides")), "{:?}", f.note);
        assert!(f.grid.values.iter().all(|&v| v >= 0.0));
        // Snapping ends within 60 mm of the edge joins it to both sides: now it separates.
        let snapped = snap_ends(&nodes, SIZE, 60.0);
        assert_eq!(snapped[0].first(), Some(&[0.0, 100.0]));
        assert_eq!(snapped[0].last(), Some(&[200.0, 100.0]));
        let snapped = snap_ends(&nodes, SIZE, 100.0);
        assert_eq!(snapped[0].last(), Some(&[300.0, 100.0]));
        assert!(node_field(&snapped, SIZE, 31, 21).unwrap().signed);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let nodes = vec![circle([150.0, 100.0], 50.0)];
        assert_eq!(node_field(&[], SIZE, 31, 21).unwrap_err(), FieldError::NoNodes);
        assert_eq!(node_field(&[vec![]], SIZE, 31, 21).unwrap_err(), FieldError::NoNodes);
        assert_eq!(node_field(&nodes, SIZE, 1, 21).unwrap_err(), FieldError::Size(1, 21));
        let bad = [f64::NAN, 200.0];
        assert!(matches!(node_field(&nodes, bad, 31, 21), Err(FieldError::Plate(_))));
    }
}
