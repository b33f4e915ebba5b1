//! Can a part hold a goal pose? A goal is held when some mode keeps the part there: run to
//! rest from the goal pose under each mode, and see whether it stays within tolerance.

use crate::model::pose::Pose;
use crate::steer::SteerError;
use crate::steer::cost::{MM_PER_DEG, Piece, angle_error_deg, distance_mm};
use crate::steer::model::Model;

/// How near a goal the part can rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reach {
    /// Some mode holds the part within the tolerances of the goal.
    pub reachable: bool,
    /// The mode whose rest from the goal pose is nearest the goal (cost: mm + [`MM_PER_DEG`]
    /// per degree): the one that holds it, or the nearest hold there is.
    pub mode: usize,
    /// That rest pose: where the loop holds a part whose goal is not reachable.
    pub rest: Pose,
    /// Its distance from the goal (mm).
    pub error_mm: f64,
    /// Its orientation error (deg, modulo the part's symmetry period).
    pub error_deg: f64,
}

/// Whether the part can rest at `goal` (within `tol_mm` and `tol_deg`) under some mode of
/// `model`: each mode's run to rest from the goal pose, the nearest rest reported.
pub fn reachable_orientation(
    model: &Model,
    piece: &Piece,
    goal: Pose,
    tol_mm: f64,
    tol_deg: f64,
) -> Result<Reach, SteerError> {
    if model.mode_count() == 0 {
        return Err(SteerError::NoMode { index: 0, count: 0 });
    }
    let (body, period) = (&piece.body, piece.period_deg);
    let mut best: Option<(f64, Reach)> = None;
    for mode in 0..model.mode_count() {
        let rest = model.run_to_rest(body, goal, mode).pose;
        let (error_mm, error_deg) = (distance_mm(rest, goal), angle_error_deg(rest, goal, period));
        let reachable = error_mm <= tol_mm && error_deg <= tol_deg;
        // Any holding mode beats every non-holding one; then the lower cost.
        let cost = error_mm + MM_PER_DEG * error_deg + if reachable { 0.0 } else { 1e9 };
        if best.as_ref().is_none_or(|b| cost < b.0) {
            best = Some((cost, Reach { reachable, mode, rest, error_mm, error_deg }));
        }
    }
    best.map(|b| b.1).ok_or(SteerError::NoMode { index: 0, count: 0 })
}
