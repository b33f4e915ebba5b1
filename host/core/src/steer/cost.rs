//! How far a part is from its goal: one number in millimetres, the distance of the centroids
//! plus [`MM_PER_DEG`] per degree of orientation error, the error taken modulo the part's
//! rotational symmetry period (a square at 90° is a square at 0°); its cost is that error,
//! squared near the goal ([`near_quadratic`]).

use crate::model::angle::cdist;
use crate::model::part::Part;
use crate::model::pose::Pose;
use crate::motion::body::{Body, PLANNER_BODY_SAMPLES};
use crate::motion::shape::Pieces;
use crate::planner::symmetry_order;

/// Millimetres one degree of orientation error counts as: 2/3, so that the tolerance box of a
/// placement (2 mm and 3°) costs the same along either side, and a part 90° off (at most, for
/// a part with no symmetry 180°) counts as 60 mm off. The fits of [`crate::steer::fit`] weigh
/// an orientation residual by the same factor.
pub const MM_PER_DEG: f64 = 2.0 / 3.0;

/// A part prepared for steering: its body for the motion model and the period (deg) its
/// orientations are taken modulo, 360° over its rotational symmetry order.
#[derive(Debug, Clone)]
pub struct Piece {
    /// The part for the motion model ([`PLANNER_BODY_SAMPLES`] samples, as the planner's runs).
    pub body: Body,
    /// Its symmetry period (deg).
    pub period_deg: f64,
    /// Its convex pieces, to tell whether two parts touch.
    pub shapes: Pieces,
}

impl Piece {
    /// A validated part, prepared.
    pub fn new(part: &Part) -> Piece {
        let body = Body::with_samples(part, PLANNER_BODY_SAMPLES);
        let shapes = Pieces::of(&body);
        Piece { body, period_deg: 360.0 / f64::from(symmetry_order(part).max(1)), shapes }
    }
}

/// The orientation error (deg, in [0, period/2]) of `pose` against `goal`.
pub fn angle_error_deg(pose: Pose, goal: Pose, period_deg: f64) -> f64 {
    cdist(pose.theta.to_degrees(), goal.theta.to_degrees(), period_deg)
}

/// The distance (mm) of `pose`'s centroid from `goal`'s.
pub fn distance_mm(pose: Pose, goal: Pose) -> f64 {
    (pose.x - goal.x).hypot(pose.y - goal.y)
}

/// Errors (mm) below which a part's cost grows as the square of its error ([`near_quadratic`]).
pub const NEAR_MM: f64 = 4.0;

/// The cost of an error `e` (mm): the error itself far from the goal (e − [`NEAR_MM`]/2), its
/// square near it (e²/(2·[`NEAR_MM`])), joined smoothly (Huber's function). Near the goals the
/// square prefers every part a little off to one part far off (all parts within tolerance at
/// once is what placing several parts needs); far from them each millimetre counts alike.
pub fn near_quadratic(e: f64) -> f64 {
    if e < NEAR_MM { e * e / (2.0 * NEAR_MM) } else { e - NEAR_MM / 2.0 }
}

/// A circle a part is to stay out of (a robot's pick zone), counted in its cost: [`KeepOut::per_mm`]
/// mm of cost per mm its centroid lies inside the circle's radius (the zone's radius plus the
/// part's bounding radius, so that no point of the part enters the zone), 0 outside. Linear,
/// so that the part is pushed out from anywhere inside as hard as a goal pulls a far part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeepOut {
    /// The circle's centre (mm).
    pub centre: [f64; 2],
    /// Its radius for this part's centroid (mm).
    pub radius_mm: f64,
    /// Cost per mm inside (mm/mm).
    pub per_mm: f64,
}

impl KeepOut {
    /// The cost (mm) of a centroid at `pose`: `per_mm` × how far inside the circle it is.
    pub fn cost_at(&self, pose: Pose) -> f64 {
        let d = (pose.x - self.centre[0]).hypot(pose.y - self.centre[1]);
        self.per_mm * (self.radius_mm - d).max(0.0)
    }
}

/// One part to steer: its body, where it is, where it should go and how much it counts.
#[derive(Debug, Clone, Copy)]
pub struct PartGoal<'a> {
    /// The part.
    pub piece: &'a Piece,
    /// Where it is now.
    pub pose: Pose,
    /// Where it should be.
    pub goal: Pose,
    /// Weight of its cost in the total (1 normally).
    pub weight: f64,
    /// Millimetres per degree of orientation error ([`MM_PER_DEG`] normally; 0 when only
    /// the position matters, as when parts are brought home).
    pub mm_per_deg: f64,
    /// A circle the part is to stay out of, its cost added to the goal's whatever the weight
    /// (none normally; a present cycle keeps the parts not presented out of the pick zone).
    pub keep_out: Option<KeepOut>,
}

impl<'a> PartGoal<'a> {
    /// A part at `pose` to be steered to `goal`, weight 1, orientation at [`MM_PER_DEG`].
    pub fn new(piece: &'a Piece, pose: Pose, goal: Pose) -> PartGoal<'a> {
        PartGoal { piece, pose, goal, weight: 1.0, mm_per_deg: MM_PER_DEG, keep_out: None }
    }

    /// The weighted cost (mm) of this part at `pose`, plus its keep-out's (unweighted).
    pub fn cost_at(&self, pose: Pose) -> f64 {
        self.weight * near_quadratic(self.error_mm(pose))
            + self.keep_out.map_or(0.0, |k| k.cost_at(pose))
    }

    /// The part's error (mm) at `pose`: its distance from the goal plus
    /// [`PartGoal::mm_per_deg`] per degree of orientation error.
    pub fn error_mm(&self, pose: Pose) -> f64 {
        distance_mm(pose, self.goal)
            + self.mm_per_deg * angle_error_deg(pose, self.goal, self.piece.period_deg)
    }

    /// Is the part at `pose` within `tol_mm` and `tol_deg` of its goal?
    pub fn within(&self, pose: Pose, tol_mm: f64, tol_deg: f64) -> bool {
        distance_mm(pose, self.goal) <= tol_mm
            && angle_error_deg(pose, self.goal, self.piece.period_deg) <= tol_deg
    }
}

/// The total cost (mm) of the parts at `poses` (one per part, in order).
pub fn total_cost(parts: &[PartGoal], poses: &[Pose]) -> f64 {
    parts.iter().zip(poses).map(|(p, q)| p.cost_at(*q)).sum()
}
