//! Where a plan leaves the part's centroid (docs/plan.md, "Position").
//!
//! At a straight node the net force is along the node's normal n̂ (the field depends only on
//! the signed distance to the line), so a step moves the centroid along n̂ only, onto the line
//! n̂·(p − c) = offset − s(θ), s = the balance offset at the rest orientation θ. The set of
//! places the centroid can be is therefore tracked through the plan as a point set whose
//! convex hull holds it: the inset plate at first; a straight-node step projects it along n̂
//! onto the node line (one segment per predicted orientation); any other node forgets it
//! (back to the whole plate). The position is fixed when that set is smaller than
//! [`POSITION_TOL_MM`] across.
//!
//! Perpendicular last two nodes fix it at once (the projection of a segment onto a
//! perpendicular line is a point). Two non-parallel nodes at angle Δ shrink a segment by
//! |cos Δ| per step only: after nodes at 0° and 60° the part can still be anywhere along half
//! the first node's chord, which the simulation confirms (`host/cli/tests/integration/goal_plan.rs`).

use crate::model::part::Part;
use crate::model::plate::{Node, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::body::PLANNER_BODY_SAMPLES;
use crate::motion::field::FieldModel;

use super::{Synthesis, balance_offset};

/// A position is fixed when every place the centroid can be lies within this (mm) across.
pub const POSITION_TOL_MM: f64 = 1.0;
/// Tracked final poses (simulated runs, with the integrator's scatter) fix the position when
/// every one lies within this (mm) of their mean: a radius, where [`POSITION_TOL_MM`] bounds
/// the exact region's diameter.
pub(crate) const TRACKED_POSITION_TOL_MM: f64 = 2.0;

/// The mean of `points` (mm); the origin for none.
fn mean(points: &[[f64; 2]]) -> [f64; 2] {
    let n = points.len().max(1) as f64;
    [points.iter().map(|p| p[0]).sum::<f64>() / n, points.iter().map(|p| p[1]).sum::<f64>() / n]
}

/// A fixed position as plans report it: rounded to 1 µm.
fn reported(m: [f64; 2]) -> [f64; 2] {
    [(m[0] * 1000.0).round() / 1000.0, (m[1] * 1000.0).round() / 1000.0]
}

/// The position tracked final poses fix ([`TRACKED_POSITION_TOL_MM`]), rounded to 1 µm, or
/// `None` when they spread wider.
pub(crate) fn tracked_position(poses: &[Pose]) -> Option<[f64; 2]> {
    let points: Vec<[f64; 2]> = poses.iter().map(|q| [q.x, q.y]).collect();
    let m = mean(&points);
    let fixed = points.iter().all(|p| (p[0] - m[0]).hypot(p[1] - m[1]) <= TRACKED_POSITION_TOL_MM);
    fixed.then(|| reported(m))
}

/// The points whose convex hull holds every place the centroid can be after `path` (mode,
/// predicted orientations after the step, deg), starting anywhere on the plate.
pub fn reachable_region(
    part: &Part,
    plate: &PlateModel,
    period: f64,
    path: &[(usize, Vec<f64>)],
) -> Vec<[f64; 2]> {
    let [w, h] = plate.size_mm;
    let radius = Body::new(part).radius;
    let r = radius.min(w / 2.0).min(h / 2.0);
    let whole = vec![[r, r], [w - r, r], [w - r, h - r], [r, h - r]];
    let c = plate.center();
    let mut pts = whole.clone();
    for (k, after) in path {
        let mode = &plate.modes[*k];
        // A node along or beyond an edge leaves the part against the rim, not on the node.
        let Node::Line { angle_deg, offset_mm } = mode.node else {
            pts = whole.clone();
            continue;
        };
        if super::edges::rim_line(radius, mode, plate) {
            pts = whole.clone();
            continue;
        }
        let (s, co) = angle_deg.to_radians().sin_cos();
        let (n, t) = ([-s, co], [co, s]);
        let tau = |p: &[f64; 2]| t[0] * (p[0] - c[0]) + t[1] * (p[1] - c[1]);
        let lo = pts.iter().map(tau).fold(f64::INFINITY, f64::min);
        let hi = pts.iter().map(tau).fold(f64::NEG_INFINITY, f64::max);
        let mut next = Vec::new();
        // Every orientation equivalent mod the period is a distinct physical pose with its
        // own balance offset (e.g. θ and θ + 180° under symmetric fields).
        let copies = (360.0 / period).round().max(1.0) as usize;
        for &theta in after {
            for j in 0..copies {
                let d = offset_mm - balance_offset(part, mode, theta + j as f64 * period);
                for tt in [lo, hi] {
                    next.push([c[0] + d * n[0] + tt * t[0], c[1] + d * n[1] + tt * t[1]]);
                }
            }
        }
        pts = next;
    }
    pts
}

/// Largest distance between two points of a set (mm).
pub fn diameter(pts: &[[f64; 2]]) -> f64 {
    let mut d: f64 = 0.0;
    for (i, a) in pts.iter().enumerate() {
        for b in &pts[i + 1..] {
            d = d.max((a[0] - b[0]).hypot(a[1] - b[1]));
        }
    }
    d
}

/// The fixed final position after `path` (the region's centre, rounded to 1 µm), or `None`
/// when the region is [`POSITION_TOL_MM`] or more across.
pub(crate) fn fixed_position(
    part: &Part,
    plate: &PlateModel,
    period: f64,
    path: &[(usize, Vec<f64>)],
) -> Option<[f64; 2]> {
    let pts = reachable_region(part, plate, period, path);
    if pts.is_empty() || diameter(&pts) >= POSITION_TOL_MM {
        return None;
    }
    Some(reported(mean(&pts)))
}

/// Runs a plan (as `chladni simulate` does, fixed durations) from the inset plate corners and
/// centre, 8 orientations each: the largest distance (mm) of a final centroid from
/// `predicted`.
pub(crate) fn simulated_position_error(
    part: &Part,
    plate: &PlateModel,
    syn: &Synthesis,
    predicted: [f64; 2],
) -> f64 {
    let body = Body::with_samples(part, PLANNER_BODY_SAMPLES);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let steps = syn.sim_steps();
    let [w, h] = plate.size_mm;
    let r = body.radius.min(w / 2.0).min(h / 2.0);
    let points = [[r, r], [w - r, r], [w - r, h - r], [r, h - r], plate.center()];
    let mut worst: f64 = 0.0;
    for p in points {
        for j in 0..8 {
            let start = Pose { x: p[0], y: p[1], theta: (j as f64 * 45.0 + 7.0).to_radians() };
            let (poses, _, _) =
                crate::motion::steps::simulate_plan(&body, plate, &fields, &steps, start);
            let end = poses.last().copied().unwrap_or(start);
            worst = worst.max((end.x - predicted[0]).hypot(end.y - predicted[1]));
        }
    }
    worst
}
