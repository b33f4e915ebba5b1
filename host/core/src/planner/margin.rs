//! Margins from evidence (docs/plan.md, "Margins from evidence"): how far a step keeps the
//! orientations it acts on from the basin boundaries of its map, per part × mode.
//!
//! A basin boundary of a grid mode's map is only as good as the sampled mode shape it was
//! simulated on. The evidence: the map's runs made again on the mode's grid resampled to half
//! its resolution ([`coarse_grid`]), from the start orientations around each of its basin
//! boundaries ([`windowed_spread`]: a few runs per boundary, not a second map), and how far
//! the boundaries moved ([`boundary_spread`]). The margin a step must keep is that spread (at
//! least [`MIN_MARGIN_DEG`]); a map whose boundaries move farther than [`MAX_MARGIN_DEG`](super::mode_margin::MAX_MARGIN_DEG), or
//! are not found again near their place, is not resolved on its grid and gets that cap.
//! Halving the resolution moves a boundary more than the mode's own grid does (the
//! Catmull–Rom interpolant's error falls with the cube of the spacing), so the spread
//! overstates the grid's own part of the error rather than understating it.
//!
//! Maps without a grid (straight nodes, hyperbolas) have no resampling evidence; they keep
//! `--margin-deg`'s default ([`super::PlanOptions::margin_deg`], 3°), and the planner's dynamic
//! check simulates every straight-node transition of a plan anyway. `--margin-deg D` given by
//! the user overrides every mode.

use super::cluster::{CLUSTER_DEG, Clusters};
use super::maps::{
    StepMap, map_run, map_starts, map_thetas, outside_reach, rest_sets, sampled_map,
    simulate_starts,
};
use super::mode_margin::{MIN_MARGIN_DEG, MarginSource, ModeMargin};
use super::options::PlanOptions;
use super::symmetry::body_symmetry_order;
use crate::model::angle::cdist;
use crate::model::angle::wrap_deg;
use crate::model::grid::Grid;
use crate::model::plate::{Mode, Node, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::contact::Rim;
use crate::motion::field::grid_eval;

/// How far the basin boundaries `a` and `b` (deg, modulo 360°) lie apart: the largest distance
/// of a boundary of either set from the other set's nearest (the symmetric Hausdorff distance
/// on the circle). 0 when both are empty; infinite when only one is.
pub fn boundary_spread(a: &[f64], b: &[f64]) -> f64 {
    let far = |x: &[f64], y: &[f64]| {
        x.iter()
            .map(|&p| y.iter().map(|&q| cdist(p, q, 360.0)).fold(f64::INFINITY, f64::min))
            .fold(0.0, f64::max)
    };
    match (a.is_empty(), b.is_empty()) {
        (true, true) => 0.0,
        (true, false) | (false, true) => f64::INFINITY,
        _ => far(a, b).max(far(b, a)),
    }
}

/// The grid resampled to about half its resolution ((n − 1)/2 + 1 samples a side, at least 4)
/// through the grid fields' own Catmull–Rom interpolant, normalised as the solver writes it.
pub fn coarse_grid(g: &Grid) -> Grid {
    let half = |n: usize| ((n - 1) / 2 + 1).max(4).min(n);
    resample(g, half(g.nx), half(g.ny))
}

/// `g` sampled at `nx` × `ny` points over the same plate, normalised (max |φ| = 1, the
/// largest-magnitude sample positive).
pub fn resample(g: &Grid, nx: usize, ny: usize) -> Grid {
    let (nx, ny) = (nx.max(2), ny.max(2));
    let mut values = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let p = [
                i as f64 * g.size_mm[0] / (nx - 1) as f64,
                j as f64 * g.size_mm[1] / (ny - 1) as f64,
            ];
            values.push(grid_eval(g, p).0);
        }
    }
    let big = values.iter().copied().fold(0.0f64, |m, v| if v.abs() > m.abs() { v } else { m });
    if big != 0.0 {
        values.iter_mut().for_each(|v| *v /= big);
    }
    Grid { nx, ny, size_mm: g.size_mm, values }
}

/// Start orientations simulated on either side of each basin boundary for the evidence
/// ([`windowed_spread`]): a boundary that moved farther is not found near its old place.
pub const WINDOW_STEPS: usize = 2;

/// The evidence margin of a grid mode's map `base` (made with `n` start orientations and
/// `period`): its boundaries found again on the coarse grid ([`windowed_spread`]). A map
/// without boundaries needs none ([`MarginSource::NoBoundaries`]). `None` for a mode without
/// a grid.
pub fn grid_margin(
    body: &Body,
    mode: &Mode,
    plate: &PlateModel,
    n: usize,
    period: f64,
    base: &StepMap,
) -> Option<ModeMargin> {
    let Node::Grid(g) = &mode.node else { return None };
    if base.boundaries.is_empty() {
        return Some(ModeMargin { deg: MIN_MARGIN_DEG, source: MarginSource::NoBoundaries });
    }
    let coarse = coarse_grid(g);
    let dims = [coarse.nx, coarse.ny];
    let other = Mode { node: Node::Grid(coarse), ..mode.clone() };
    let spread = windowed_spread(body, &other, plate, n, period, base);
    Some(ModeMargin::from_spread(spread, [g.nx, g.ny], dims))
}

/// The indices of a simulated map's `n` start orientations within [`WINDOW_STEPS`] of each of
/// its `boundaries` (each lies half a step after a start orientation, [`map_thetas`]), sorted.
fn window(boundaries: &[f64], n: usize) -> Vec<usize> {
    let step = 360.0 / n as f64;
    let k = WINDOW_STEPS as isize;
    let mut idx = std::collections::BTreeSet::new();
    for &b in boundaries {
        let i = (b / step - 0.8).round() as isize;
        for d in -k..=k + 1 {
            idx.insert((i + d).rem_euclid(n as isize) as usize);
        }
    }
    idx.into_iter().collect()
}

/// How far the basin boundaries of `map` (made with `n` start orientations) move under
/// `mode` (the resampled field): the map's runs (its start points, [`map_starts`], the same
/// settings, `maps::map_run`) from only the start orientations around each base boundary
/// (`window`); the boundaries found there (where neighbouring orientations' sets of rests
/// differ, or a run does not come to rest) against `base` ([`boundary_spread`]; infinite when
/// none is found). The start points the map left out (a run outside the mode's reach,
/// [`StepMap::dead_starts`]) are left out, and so is one with a windowed run outside it. The cost: 2·[`WINDOW_STEPS`] + 2 orientations per boundary (per
/// 360°/m for a part of symmetry order m) instead of the map's `n` (n/m).
pub fn windowed_spread(
    body: &Body,
    mode: &Mode,
    plate: &PlateModel,
    n: usize,
    period: f64,
    map: &StepMap,
) -> f64 {
    let base = &map.boundaries;
    // A part of symmetry order m started at θ + 360°/m is the run from θ turned (as in
    // [`sampled_map`]): only the windows' orientations below 360°/m are simulated, and the
    // boundaries found there repeat every 360°/m.
    let m = body_symmetry_order(body) as usize;
    let m = if m > 1 && n.is_multiple_of(m) { m } else { 1 };
    let distinct = n / m;
    let mut idx: Vec<usize> = window(base, n).into_iter().map(|i| i % distinct).collect();
    idx.sort_unstable();
    idx.dedup();
    let thetas = map_thetas(n);
    let (field, p) = map_run(body, mode, plate);
    let rim = Rim::of(plate);
    // Only the start points the map kept are run (the others are left out whatever their
    // runs give), and a point is dropped, its runs called off, as soon as one of its windowed
    // runs ends outside the mode's reach (`maps::simulate_starts`): the same answer as
    // running them all, without paying for runs that creep where the pull vanishes.
    let live: Vec<[f64; 2]> = map_starts(body, mode, plate)
        .into_iter()
        .enumerate()
        .filter(|(point, _)| !map.dead_points.contains(point))
        .map(|(_, s)| s)
        .collect();
    let (idx_ref, thetas_ref) = (&idx, &thetas);
    let poses: Vec<(usize, Pose)> = live
        .iter()
        .enumerate()
        .flat_map(|(j, s)| {
            idx_ref.iter().map(move |&i| {
                let theta = thetas_ref[i].to_radians();
                (j, rim.project(body, Pose { x: s[0], y: s[1], theta }))
            })
        })
        .collect();
    let ends = simulate_starts(body, mode, plate, &field, p, &poses, live.len());
    // Ends are labelled by the map's own rests (the nearest within the clustering tolerance),
    // so that the windowed runs and the map tell rests apart alike; other ends are clustered
    // as new rests.
    let mut clusters = Clusters::new(period, CLUSTER_DEG);
    let mut label = |theta: f64| {
        let near = map.stable.iter().enumerate().map(|(k, &s)| (k, cdist(s, theta, period)));
        match near.min_by(|a, b| a.1.total_cmp(&b.1)) {
            Some((k, d)) if d <= CLUSTER_DEG => k,
            _ => map.stable.len() + clusters.label(theta),
        }
    };
    let labels: Vec<Vec<Option<usize>>> = ends
        .chunks(idx.len().max(1))
        .filter_map(|runs| runs.iter().copied().collect::<Option<Vec<(Pose, bool)>>>())
        .filter(|runs| !runs.iter().any(|r| outside_reach(body, mode, plate, r.0)))
        .map(|runs| runs.iter().map(|(q, ok)| ok.then(|| label(q.theta.to_degrees()))).collect())
        .collect();
    let combined = rest_sets(&labels, idx.len());
    let mut found = Vec::new();
    for k in 0..idx.len() {
        let next = (k + 1) % idx.len();
        if idx[next] != (idx[k] + 1) % distinct {
            continue;
        }
        if combined[k].is_none() || combined[k] != combined[next] {
            let b = thetas[idx[k]] + 180.0 / n as f64;
            found.extend((0..m).map(|t| wrap_deg(b + t as f64 * 360.0 / m as f64)));
        }
    }
    boundary_spread(base, &found)
}

/// A curved or grid mode's simulated map ([`sampled_map`]); with [`PlanOptions::margin_auto`],
/// a grid mode's map carries its evidence margin ([`grid_margin`]).
pub(super) fn simulated_map(
    body: &Body,
    mode: &Mode,
    plate: &PlateModel,
    opt: &PlanOptions,
    period: f64,
) -> StepMap {
    let mut map = sampled_map(body, mode, plate, opt.sim_starts, period);
    if opt.margin_auto && !map.neutral {
        map.evidence = grid_margin(body, mode, plate, opt.sim_starts, period, &map);
    }
    map
}

/// The fixed margin of `opt` (feed-region plans, which check their ends in simulation rather
/// than against a map's boundaries): given, or the default when the margin is automatic.
pub fn fixed(opt: &PlanOptions) -> ModeMargin {
    let source = if opt.margin_auto { MarginSource::Default } else { MarginSource::Given };
    ModeMargin { deg: opt.margin_deg, source }
}

/// The margin used for a map under options whose fixed margin is `fixed` and whose automatic
/// margin is on (`auto`): the map's evidence when it has some and `auto` is on, else `fixed`
/// (given, or the default when `auto`).
pub(crate) fn margin_of(map: &StepMap, fixed: f64, auto: bool) -> ModeMargin {
    match (auto, map.evidence) {
        (true, Some(m)) => m,
        (true, None) => ModeMargin { deg: fixed, source: MarginSource::Default },
        (false, _) => ModeMargin { deg: fixed, source: MarginSource::Given },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planner::mode_margin::MAX_MARGIN_DEG;

    #[test]
    fn spread_is_the_farthest_boundary_from_the_other_set() {
        assert_eq!(boundary_spread(&[], &[]), 0.0);
        assert!(boundary_spread(&[10.0], &[]).is_infinite());
        // 359° and 1° are 2° apart across 0°; the lone 180° of b is 170° from 10°.
        assert!((boundary_spread(&[359.0, 90.0], &[1.0, 91.5]) - 2.0).abs() < 1e-9);
        assert!((boundary_spread(&[10.0], &[10.0, 180.0]) - 170.0).abs() < 1e-9);
    }

    #[test]
    fn the_margin_follows_the_spread_within_its_bounds() {
        let m = ModeMargin::from_spread(2.25, [41, 28], [21, 14]);
        assert_eq!(m.deg, 2.25);
        assert!(m.describe().contains("move 2.25°"), "{}", m.describe());
        assert_eq!(ModeMargin::from_spread(0.0, [41, 28], [21, 14]).deg, MIN_MARGIN_DEG);
        assert_eq!(ModeMargin::from_spread(40.0, [41, 28], [21, 14]).deg, MAX_MARGIN_DEG);
        let lost = ModeMargin::from_spread(f64::INFINITY, [41, 28], [21, 14]);
        assert_eq!(lost.deg, MAX_MARGIN_DEG);
        assert_eq!(lost.to_json()["spread_deg"], serde_json::Value::Null);
    }

    #[test]
    fn resampling_keeps_a_cubic_field_and_halves_the_grid() {
        // Catmull–Rom reproduces polynomials up to degree 2 exactly inside the grid; a
        // quadratic field resampled to half the resolution is the same field.
        let (nx, ny, size) = (41, 28, [300.0, 200.0]);
        let f = |x: f64, y: f64| ((x - 150.0) * (y - 80.0) + 0.01 * (x - 100.0).powi(2)) / 30000.0;
        let values = (0..ny)
            .flat_map(|j| {
                (0..nx).map(move |i| {
                    f(i as f64 * 300.0 / (nx - 1) as f64, j as f64 * 200.0 / (ny - 1) as f64)
                })
            })
            .collect();
        let g = Grid { nx, ny, size_mm: size, values };
        let c = coarse_grid(&g);
        assert_eq!([c.nx, c.ny], [21, 14]);
        let big =
            g.values.iter().copied().fold(0.0f64, |m, v| if v.abs() > m.abs() { v } else { m });
        for p in [[100.0, 50.0], [150.0, 150.0], [222.0, 33.0]] {
            let (a, b) = (grid_eval(&g, p).0 / big, grid_eval(&c, p).0);
            assert!((a - b).abs() < 1e-6, "{p:?}: {a} vs {b}");
        }
    }

    /// A grid mode whose node is the straight line through the plate centre at `angle_deg`:
    /// φ = the signed distance from it (a linear field: its resampling is exact inside the
    /// grid), on 41 × 41 samples over 300 × 200 mm.
    fn line_grid_plate(angles: &[f64]) -> PlateModel {
        let text = "[plate]\nname = \"t\"\nsize_mm = [300.0, 200.0]\n[[mode]]\nfreq_hz = 60.0\n\
                    speed_mm_s = 30.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n";
        let file = crate::model::plate_file::PlateFile::parse(text, "t").unwrap();
        let mut plate = PlateModel::from_file(&file).unwrap();
        let template = plate.modes[0].clone();
        plate.modes = angles
            .iter()
            .enumerate()
            .map(|(k, &a)| {
                let (s, c) = a.to_radians().sin_cos();
                let (n, size) = (41, [300.0, 200.0]);
                let values = (0..n)
                    .flat_map(|j| {
                        (0..n).map(move |i| {
                            let x = i as f64 * size[0] / (n - 1) as f64 - 150.0;
                            let y = j as f64 * size[1] / (n - 1) as f64 - 100.0;
                            (c * y - s * x) / 200.0
                        })
                    })
                    .collect();
                let node = Node::Grid(Grid { nx: n, ny: n, size_mm: size, values });
                Mode {
                    name: format!("mode {}", k + 1),
                    freq_hz: 60.0 + 10.0 * k as f64,
                    node,
                    ..template.clone()
                }
            })
            .collect();
        plate
    }

    #[test]
    fn the_evidence_margin_is_how_far_the_boundaries_moved() {
        // The triangle under a straight grid node at 30° and at 40°: turning the node turns
        // every basin boundary with it, by 10° — one start spacing at 36 starts, so the
        // sampled boundaries move by exactly that. The margin made from the two maps is 10°;
        // the 30° node's own resampling (a linear field, kept exactly) moves nothing: the floor.
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/parts/triangle.json");
        let part = crate::model::part::Part::load(&path).unwrap();
        let body = Body::with_samples(&part, crate::motion::body::PLANNER_BODY_SAMPLES);
        let plate = line_grid_plate(&[30.0, 40.0]);
        let (n, period) = (36, 360.0);
        let a = sampled_map(&body, &plate.modes[0], &plate, n, period);
        let b = sampled_map(&body, &plate.modes[1], &plate, n, period);
        assert!(!a.boundaries.is_empty(), "{a:?}");
        let turned: Vec<f64> = a.boundaries.iter().map(|x| (x + 10.0) % 360.0).collect();
        assert!(boundary_spread(&turned, &b.boundaries) < 1e-6, "{turned:?} vs {:?}", b.boundaries);
        let moved = boundary_spread(&a.boundaries, &b.boundaries);
        assert!((moved - 10.0).abs() < 1e-6, "{moved}");
        assert_eq!(ModeMargin::from_spread(moved, [41, 41], [21, 21]).deg, 10.0);
        // The windowed measurement finds the same 10° move from a few runs per boundary.
        let windowed = windowed_spread(&body, &plate.modes[1], &plate, n, period, &a);
        assert!((windowed - 10.0).abs() < 1e-6, "{windowed}");
        let own = grid_margin(&body, &plate.modes[0], &plate, n, period, &a).unwrap();
        assert_eq!(own.deg, MIN_MARGIN_DEG, "{own:?}");
        assert_eq!(
            own.source,
            MarginSource::Resampled { spread_deg: 0.0, grid: [41, 41], coarse: [21, 21] }
        );
    }
}
