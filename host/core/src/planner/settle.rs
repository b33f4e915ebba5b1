//! Step durations: simulated settle times from a step's predicted orientations, lingering
//! starts left out, and the duration rule (docs/plan.md, "Durations").

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::maps::outside_reach;
use crate::model::plate::{Mode, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::field::FieldModel;
use crate::motion::integrate::SimParams;

/// Inset plate corners (by the part radius) farthest from a straight node on each side, or
/// the corners, edge midpoints and centre for curved and grid nodes.
pub(crate) fn start_points(body: &Body, mode: &Mode, plate: &PlateModel) -> Vec<[f64; 2]> {
    let [w, h] = plate.size_mm;
    let r = body.radius.min(w / 2.0).min(h / 2.0);
    let corners = [[r, r], [w - r, r], [w - r, h - r], [r, h - r]];
    match FieldModel::new(mode, plate) {
        FieldModel::Line { xhat, c, .. } => {
            let xi = |p: &[f64; 2]| xhat[0] * p[0] + xhat[1] * p[1] - c;
            let lo = corners.iter().min_by(|a, b| xi(a).total_cmp(&xi(b))).copied();
            let hi = corners.iter().max_by(|a, b| xi(a).total_cmp(&xi(b))).copied();
            lo.into_iter().chain(hi).collect()
        }
        // Curved and grid nodes: corners, edge midpoints and the centre (the pull, and so
        // the settle time, varies over the plate).
        _ => {
            let mid =
                [[w / 2.0, r], [w - r, h / 2.0], [w / 2.0, h - r], [r, h / 2.0], plate.center()];
            corners.iter().chain(&mid).copied().collect()
        }
    }
}

/// What [`settle_time`] measured.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Settle {
    /// The slowest start (s), lingering ones left out.
    pub settle_s: f64,
    /// Starts set apart by a gap in the settle times (`slowest_settled`): they linger near
    /// an unstable rest (metastable; their time is unbounded in the model).
    pub lingering: usize,
    /// Start points simulated.
    pub points: usize,
    /// Grid modes: start points from which the part ended on the plate edge instead of a
    /// node (outside the mode's reach, e.g. at a cantilever's clamp; left out of the settle
    /// time).
    pub ends_on_edge: Vec<[f64; 2]>,
}

/// How the planner runs a part to rest under one mode: at the mode's speed, inside the
/// plate's rim, until at rest (at most an hour of plate time).
pub(crate) fn settle_params(mode: &Mode, plate: &PlateModel) -> SimParams {
    SimParams::under(mode, plate, 3600.0)
}

/// Simulated settle time of a step from the given orientations (deg), from the start points
/// of `start_points`: the slowest start, except lingering ones and those that end on the
/// plate edge (see [`Settle`]).
pub fn settle_time(body: &Body, mode: &Mode, plate: &PlateModel, orientations: &[f64]) -> Settle {
    let field = FieldModel::new(mode, plate);
    let p = settle_params(mode, plate);
    let mut times = Vec::new();
    let points = start_points(body, mode, plate);
    let mut ends_on_edge = Vec::new();
    for &pt in &points {
        // Grid modes: a corner outside the mode's reach (see [`sampled_map`]) never reaches a
        // node; its drift onto the clamp is no settle time. Once one run from `pt` ends there
        // the point is left out, so its runs not yet begun are skipped (`None`).
        let edge = AtomicBool::new(false);
        let runs: Vec<Option<f64>> = orientations
            .par_iter()
            .map(|&th| {
                if edge.load(Ordering::Relaxed) {
                    return None;
                }
                let q = Pose { x: pt[0], y: pt[1], theta: th.to_radians() };
                let r = crate::motion::integrate::run(body, &field, p, q);
                if outside_reach(body, mode, plate, r.pose) {
                    edge.store(true, Ordering::Relaxed);
                }
                Some(r.settle_s)
            })
            .collect();
        if edge.into_inner() {
            ends_on_edge.push(pt);
            continue;
        }
        times.extend(runs.into_iter().flatten());
    }
    let (settle_s, lingering) = slowest_settled(times);
    Settle { settle_s, lingering, points: points.len(), ends_on_edge }
}

/// Ratio between consecutive sorted settle times, above the median, beyond which the slower
/// starts count as lingering (see `slowest_settled`).
pub(crate) const LINGER_GAP: f64 = 3.0;

/// The slowest of some settle times (s) and how many were left out as lingering: those above
/// the first gap of more than [`LINGER_GAP`]× between consecutive sorted times above the
/// median. A part near an unstable rest leaves it after a time that grows without bound as
/// it starts closer (metastable), so such starts stand apart from the rest; parts creeping
/// along a node settle over a continuum of times with no such gap and all count. A fixed
/// threshold (formerly 10× the median) fell inside such a continuum, and integration error
/// then decided which creeping runs counted; a gap of 3× is far wider than that error.
pub(crate) fn slowest_settled(mut times: Vec<f64>) -> (f64, usize) {
    times.sort_by(f64::total_cmp);
    let mid = times.len() / 2;
    let kept = (mid..times.len())
        .find(|&i| times.get(i + 1).is_some_and(|&next| next > LINGER_GAP * times[i].max(1e-3)))
        .map_or(times.len(), |i| i + 1);
    (times[..kept].last().copied().unwrap_or(0.0), times.len() - kept)
}

/// A step's duration (ms): settle time × safety, rounded up to 10 ms, plus the ramp; at
/// least 100 ms.
pub(crate) fn step_duration_ms(settle_s: f64, safety: f64, ramp_ms: u32) -> u32 {
    let ms = (settle_s * safety * 1000.0 / 10.0).ceil() as u32 * 10;
    (ms + ramp_ms).max(100)
}

#[cfg(test)]
mod tests {
    use super::slowest_settled;

    #[test]
    fn lingering_starts_are_those_beyond_a_gap() {
        // Most starts settle in 50–90 s; creeping ones over a continuum up to 40× that
        // (consecutive ratios ≤ 1.3): all count, however far above the median.
        let mut times: Vec<f64> = (0..60).map(|i| 50.0 + 0.7 * i as f64).collect();
        let mut t = 100.0;
        while t < 3000.0 {
            times.push(t);
            t *= 1.3;
        }
        let slowest = *times.last().unwrap();
        assert_eq!(slowest_settled(times.clone()), (slowest, 0));
        // Two starts set apart by a gap of more than 3×: left out, whatever their times.
        for far in [3.2 * slowest, 100.0 * slowest] {
            let mut with = times.clone();
            with.extend([far, 1.1 * far]);
            assert_eq!(slowest_settled(with), (slowest, 2), "{far}");
        }
        // A gap below the median is no cut (the fast half may settle at once).
        let mut fast: Vec<f64> = vec![0.0; 10];
        fast.extend((0..11).map(|i| 40.0 + i as f64));
        assert_eq!(slowest_settled(fast), (50.0, 0));
        assert_eq!(slowest_settled(Vec::new()), (0.0, 0));
    }
}
