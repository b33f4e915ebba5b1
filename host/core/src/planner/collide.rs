//! Where a plan for several parts ends them on top of each other.
//!
//! The planner plans each part as if it were alone on the plate (the step maps are one part's),
//! while the motion model never lets two parts overlap (contacts, [`crate::motion::many`]).
//! When a plan fixes the end positions of two parts that can meet (different given parts: the
//! two faces of one part are never on the plate at once) and their outlines overlap there, the
//! per-part predictions cannot both hold: the parts collide at that node and push each other
//! off it. This module finds those pairs so the plan says so and points at `simulate`, which
//! drops the parts together and measures what happens.

use crate::model::part::Part;
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::shape::{Pieces, overlap};

use super::goal::PartPlan;

/// Two parts whose predicted end poses overlap.
#[derive(Debug, Clone, PartialEq)]
pub struct EndOverlap {
    /// Index of the first part (in the planned parts).
    pub a: usize,
    /// Index of the second part.
    pub b: usize,
    /// How deep their outlines overlap at the predicted end poses (mm).
    pub depth_mm: f64,
}

/// The pairs of `parts` (with their plans `plans`, same order) whose predicted end poses
/// overlap. `meet(i, j)` says whether parts `i` and `j` can be on the plate together. A pair
/// where either end position is not fixed by the plan is not judged (nothing predicts where
/// that part ends).
pub fn end_overlaps(
    parts: &[Part],
    plans: &[PartPlan],
    meet: impl Fn(usize, usize) -> bool,
) -> Vec<EndOverlap> {
    let placed: Vec<Option<(Pieces, Pose)>> = parts
        .iter()
        .zip(plans)
        .map(|(part, plan)| {
            let [x, y] = plan.final_position_mm?;
            let theta = plan.final_orientation_deg.to_radians();
            Some((Pieces::of(&Body::new(part)), Pose { x, y, theta }))
        })
        .collect();
    let mut out = Vec::new();
    for a in 0..placed.len() {
        for b in a + 1..placed.len() {
            let (Some((pa, qa)), Some((pb, qb))) = (&placed[a], &placed[b]) else { continue };
            if !meet(a, b) {
                continue;
            }
            let depth_mm = overlap(pa, *qa, pb, *qb);
            if depth_mm > 0.0 {
                out.push(EndOverlap { a, b, depth_mm });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(name: &str) -> Part {
        let json = format!(
            r#"{{"name": "{name}", "outline": [[0,0],[20,0],[20,20],[0,20]], "holes": []}}"#
        );
        Part::from_json(&json, name).expect("a square part")
    }

    fn plan_at(x: f64, y: f64) -> PartPlan {
        PartPlan { final_position_mm: Some([x, y]), period_deg: 90.0, ..Default::default() }
    }

    #[test]
    fn two_parts_ending_at_one_node_crossing_overlap_and_apart_they_do_not() {
        let parts = [square("a"), square("b")];
        let same =
            end_overlaps(&parts, &[plan_at(100.0, 100.0), plan_at(105.0, 100.0)], |_, _| true);
        assert_eq!(same.len(), 1);
        assert!((same[0].depth_mm - 15.0).abs() < 0.5, "{same:?}");
        let apart =
            end_overlaps(&parts, &[plan_at(100.0, 100.0), plan_at(130.0, 100.0)], |_, _| true);
        assert!(apart.is_empty(), "{apart:?}");
    }

    #[test]
    fn faces_that_never_meet_and_unfixed_positions_are_not_judged() {
        let parts = [square("a"), square("b")];
        let plans = [plan_at(100.0, 100.0), plan_at(100.0, 100.0)];
        assert!(end_overlaps(&parts, &plans, |_, _| false).is_empty());
        let loose = [plan_at(100.0, 100.0), PartPlan::default()];
        assert!(end_overlaps(&parts, &loose, |_, _| true).is_empty());
    }
}
