//! Node lines: the contours φ = 0 of a sampled mode shape, by marching squares, joined into
//! polylines (plate coordinates, mm).

use std::collections::HashMap;

use crate::model::grid::Grid;

/// A node line: a polyline in plate coordinates (mm); closed if first == last.
pub type Polyline = Vec<[f64; 2]>;

/// Grid edge: (0 = along x, 1 = along y, i, j) starting at grid point (i, j).
type EdgeId = (u8, usize, usize);

/// Contours φ = 0 of `grid`. Samples with φ ≥ 0 count as positive, so a contour that runs
/// exactly through samples (a hinge line, say) is traced once, on the negative side's edge.
pub fn node_lines(grid: &Grid) -> Vec<Polyline> {
    let crossing = |e: EdgeId| -> [f64; 2] {
        let (a, b) = match e.0 {
            0 => ((e.1, e.2), (e.1 + 1, e.2)),
            _ => ((e.1, e.2), (e.1, e.2 + 1)),
        };
        let (va, vb) = (grid.at(a.0, a.1), grid.at(b.0, b.1));
        let t = if va == vb { 0.5 } else { va / (va - vb) };
        let (pa, pb) = (grid.point(a.0, a.1), grid.point(b.0, b.1));
        [pa[0] + t * (pb[0] - pa[0]), pa[1] + t * (pb[1] - pa[1])]
    };
    let segments = cell_segments(grid);
    // Join segments that share an edge crossing.
    let mut at: HashMap<EdgeId, Vec<usize>> = HashMap::new();
    for (k, s) in segments.iter().enumerate() {
        for e in s {
            at.entry(*e).or_default().push(k);
        }
    }
    let mut used = vec![false; segments.len()];
    let mut lines = Vec::new();
    let next = |e: EdgeId, from: usize, used: &[bool]| -> Option<usize> {
        at.get(&e)?.iter().copied().find(|&k| k != from && !used[k])
    };
    for start in 0..segments.len() {
        if used[start] {
            continue;
        }
        used[start] = true;
        // Walk forward from the segment's second end, then backward from its first.
        let mut chain: Vec<EdgeId> = vec![segments[start][0], segments[start][1]];
        for dir in 0..2 {
            let mut cur = start;
            loop {
                let end = *chain.last().unwrap_or(&segments[start][1]);
                match next(end, cur, &used) {
                    Some(k) => {
                        used[k] = true;
                        let other =
                            if segments[k][0] == end { segments[k][1] } else { segments[k][0] };
                        chain.push(other);
                        cur = k;
                    }
                    None => break,
                }
            }
            if dir == 0 {
                chain.reverse();
            }
        }
        lines.push(chain.into_iter().map(crossing).collect());
    }
    lines
}

/// The node lines of `lines` that have a length: an isolated zero of the mode shape (the
/// hinged-rod plate's rod point, where w = 0 is imposed) traces as a one-point polyline, which
/// is no line to count (the hinged-rod plate's first mode read "2 lines" and drew one).
pub fn line_count(lines: &[Polyline]) -> usize {
    lines.iter().filter(|l| total_length(std::slice::from_ref(*l)) > 0.0).count()
}

/// Marching squares: the zero crossings of φ in each grid cell joined in pairs (a saddle cell,
/// all four edges cut, is split by the sign at its centre).
fn cell_segments(grid: &Grid) -> Vec<[EdgeId; 2]> {
    let pos = |i: usize, j: usize| grid.at(i, j) >= 0.0;
    let mut segments: Vec<[EdgeId; 2]> = Vec::new();
    for j in 0..grid.ny - 1 {
        for i in 0..grid.nx - 1 {
            let (p00, p10, p11, p01) = (pos(i, j), pos(i + 1, j), pos(i + 1, j + 1), pos(i, j + 1));
            let bottom = (0, i, j);
            let right = (1, i + 1, j);
            let top = (0, i, j + 1);
            let left = (1, i, j);
            let mut cut = Vec::with_capacity(4);
            if p00 != p10 {
                cut.push(bottom);
            }
            if p10 != p11 {
                cut.push(right);
            }
            if p11 != p01 {
                cut.push(top);
            }
            if p01 != p00 {
                cut.push(left);
            }
            match cut.len() {
                2 => segments.push([cut[0], cut[1]]),
                4 => {
                    let centre = grid.at(i, j)
                        + grid.at(i + 1, j)
                        + grid.at(i + 1, j + 1)
                        + grid.at(i, j + 1);
                    if (centre >= 0.0) == p00 {
                        segments.push([bottom, right]);
                        segments.push([left, top]);
                    } else {
                        segments.push([bottom, left]);
                        segments.push([right, top]);
                    }
                }
                _ => {}
            }
        }
    }
    segments
}

/// Total length (mm) of a set of polylines.
pub fn total_length(lines: &[Polyline]) -> f64 {
    lines
        .iter()
        .flat_map(|l| l.windows(2))
        .map(|w| ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt())
        .sum()
}

pub(crate) use crate::model::geometry::segment_foot;

/// Distance from `p` to the nearest of `lines` (∞ if there are none); a one-point polyline
/// counts as that point.
pub(crate) fn distance_to(p: [f64; 2], lines: &[Polyline]) -> f64 {
    lines
        .iter()
        .flat_map(|l| {
            let segs = l.windows(2).map(move |w| segment_foot(p, w[0], w[1]).1);
            let single = (l.len() == 1).then(|| (p[0] - l[0][0]).hypot(p[1] - l[0][1]));
            segs.chain(single)
        })
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hinged-rod example's first mode: its node is the hinge line, plus the rod point (an
    /// isolated zero), which `plate modes` counted as a second line.
    #[test]
    fn hinged_rod_first_mode_is_one_line() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/plates/hinged-rod-solver.toml");
        let file = crate::model::plate_file::PlateFile::load(&path).unwrap();
        let plate = file.plate.mechanics().unwrap();
        let sol = crate::plate::solver::solve(&plate, 1, crate::plate::solver::DEFAULT_TERMS);
        let (nx, ny) = crate::plate::solver::grid_dims(121, plate.size_mm);
        let lines = node_lines(&sol.sample(0, nx, ny));
        let ends: Vec<_> = lines.iter().map(|l| (l[0], l[l.len() - 1])).collect();
        assert_eq!(line_count(&lines), 1, "{ends:?}");
        assert!((total_length(&lines) - 200.0).abs() < 1.0);
    }

    fn grid(nx: usize, ny: usize, f: impl Fn(f64, f64) -> f64) -> Grid {
        let size_mm = [100.0, 50.0];
        let mut values = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                values
                    .push(f(i as f64 * 100.0 / (nx - 1) as f64, j as f64 * 50.0 / (ny - 1) as f64));
            }
        }
        Grid { nx, ny, size_mm, values }
    }

    #[test]
    fn straight_node_is_one_polyline_at_the_right_place() {
        let g = grid(41, 21, |x, _| x - 30.3);
        let lines = node_lines(&g);
        assert_eq!(lines.len(), 1);
        assert!(lines[0].iter().all(|p| (p[0] - 30.3).abs() < 1e-9));
        assert!((total_length(&lines) - 50.0).abs() < 1e-9);
    }

    #[test]
    fn circle_is_one_closed_polyline() {
        let g = grid(81, 41, |x, y| (x - 50.0).hypot(y - 25.0) - 15.0);
        let lines = node_lines(&g);
        assert_eq!(lines.len(), 1);
        let l = &lines[0];
        assert_eq!(l.first(), l.last());
        let len = total_length(&lines);
        assert!((len - 2.0 * std::f64::consts::PI * 15.0).abs() < 0.5, "length {len}");
        // Every contour point lies on the circle; the centre is 15 mm from it.
        assert!(l.iter().all(|p| ((p[0] - 50.0).hypot(p[1] - 25.0) - 15.0).abs() < 0.1));
        assert!((distance_to([50.0, 25.0], &lines) - 15.0).abs() < 0.1);
        assert_eq!(distance_to([0.0, 0.0], &[]), f64::INFINITY);
        assert_eq!(segment_foot([3.0, 4.0], [0.0, 0.0], [0.0, 0.0]), ([0.0, 0.0], 5.0));
    }

    #[test]
    fn crossing_nodes_give_four_arms_or_two_lines() {
        let g = grid(41, 41, |x, y| (x - 50.3) * (y - 25.2));
        let lines = node_lines(&g);
        let len = total_length(&lines);
        assert!((len - 150.0).abs() < 2.0, "length {len}");
        assert!(lines.len() == 2 || lines.len() == 4, "{} lines", lines.len());
    }
}
