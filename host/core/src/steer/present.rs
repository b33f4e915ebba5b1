//! Presenting parts to a robot: a part steered to a pick pose while every other part is kept
//! out of the pick zone, one part after another (issue 45).
//!
//! Two decisions, pure: which part to present ([`choose_part`]: the one predicted to get
//! there soonest, [`Estimate::Soonest`]), and each cycle's objective ([`objective`]: the
//! chosen part to the pick pose, the others out of the zone), whose command the ordinary
//! [`crate::steer::choose()`] finds. The loop (frames, bursts, the robot's pick) is the caller's.
//!
//! Why "soonest" and not "nearest": the plate moves a part along its modes' flows, not
//! straight; a part 60 mm away on the flow of a mode that runs into the pick pose arrives
//! before one 30 mm away across a node line. The estimate follows each mode's predicted run
//! from the part for a few seconds ([`SOONEST_HORIZON_S`]) and values each point of it at the
//! time to get there plus the rest of the way at the parts' typical speed: one step of a
//! search, its remainder guessed (`benches/present.rs` measures it against nearest).

use crate::model::pose::Pose;
use crate::steer::SteerError;
use crate::steer::cost::{
    KeepOut, MM_PER_DEG, NEAR_MM, PartGoal, Piece, angle_error_deg, distance_mm,
};
use crate::steer::model::Model;
use crate::steer::reach::{Reach, reachable_orientation};

/// How far ahead the soonest estimate follows each mode's run (s of drive): the longest burst
/// of the default menu and twice more, long enough to see where a mode's flow takes a part.
pub const SOONEST_HORIZON_S: f64 = 6.0;

/// Mm of cost per mm a part not presented lies inside the pick zone ([`KeepOut::per_mm`]) once
/// the presented part is near the pick pose (its error within [`NEAR_MM`]): twice a goal's
/// pull, so that clearing the zone is worth more than the presented part's progress by the
/// same distance.
pub const KEEP_OUT_PER_MM: f64 = 2.0;

/// The same while the presented part is still on its way: a quarter of a goal's pull. The mode
/// that holds a part at the pick pose draws its neighbours there too; a strong keep-out all the
/// way stalls the presented part tens of mm short (measured in `benches/present.rs`), a weak
/// one lets it come and only keeps the others from following for nothing.
pub const KEEP_OUT_APPROACH_PER_MM: f64 = 0.25;

/// The typical speed (mm/s) a part closes on a goal when the runs give none (all parts at
/// rest under every mode): a slow plate's.
const FALLBACK_CLOSING_MM_S: f64 = 5.0;

/// One part on the plate.
#[derive(Debug, Clone, Copy)]
pub struct OnPlate<'a> {
    /// Its body and symmetry (the face it lies on).
    pub piece: &'a Piece,
    /// Its part type (an index the caller gives; a pick pose is for one type).
    pub kind: usize,
    /// Where it is.
    pub pose: Pose,
}

/// Where the robot picks, and what counts as presented there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pick {
    /// The pick pose (mm, rad).
    pub pose: Pose,
    /// The part type picked there.
    pub kind: usize,
    /// The pick zone's radius around the pick pose's centroid (mm): the gripper's reach, no
    /// other part may lie in it (its bounding circle included).
    pub zone_mm: f64,
    /// Presented: within this distance (mm) of the pick pose...
    pub tol_mm: f64,
    /// ...and this orientation error (deg, modulo the part's symmetry).
    pub tol_deg: f64,
    /// A pick pose is refused when no mode of the model rests the part within this distance
    /// (mm) of it: looser than `tol_mm`, since the model's nodes may be a few mm off until the
    /// loop has corrected them.
    pub hold_mm: f64,
    /// ...or within this orientation error (deg).
    pub hold_deg: f64,
}

impl Pick {
    /// A pick pose for parts of type `kind`, pick zone `zone_mm`, presented within 2 mm and
    /// 3°, refused when no rest lies within 10 mm and 10° of it (a node 4–8 mm off, as on a
    /// plate not yet learned, still counts).
    pub fn new(pose: Pose, kind: usize, zone_mm: f64) -> Pick {
        Pick { pose, kind, zone_mm, tol_mm: 2.0, tol_deg: 3.0, hold_mm: 10.0, hold_deg: 10.0 }
    }

    /// Every number finite, the radii and tolerances ≥ 0.
    pub fn check(&self) -> Result<(), PresentError> {
        let p = self.pose;
        let fields = [
            ("pose x", p.x, false),
            ("pose y", p.y, false),
            ("pose theta", p.theta, false),
            ("zone_mm", self.zone_mm, true),
            ("tol_mm", self.tol_mm, true),
            ("tol_deg", self.tol_deg, true),
            ("hold_mm", self.hold_mm, true),
            ("hold_deg", self.hold_deg, true),
        ];
        match fields.iter().find(|(_, v, positive)| !v.is_finite() || (*positive && *v < 0.0)) {
            Some(&(field, value, _)) => Err(PresentError::BadPick { field, value }),
            None => Ok(()),
        }
    }
}

/// How the part to present is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Estimate {
    /// The part predicted to get there soonest (each mode's run followed, the rest of the way
    /// at the typical speed).
    Soonest,
    /// The part nearest the pick pose (distance plus [`MM_PER_DEG`] per degree): the baseline.
    Nearest,
}

/// The part chosen to present.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Choice {
    /// Its index into the parts given.
    pub part: usize,
    /// Its estimated time to the pick pose (s of drive; for [`Estimate::Nearest`] its error at
    /// the typical speed).
    pub estimate_s: f64,
    /// Whether and how near its piece rests at the pick pose under the model.
    pub reach: Reach,
}

/// Why nothing can be presented, each naming the value and the fix.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PresentError {
    /// No part of the pick's type is on the plate.
    #[error(
        "no part of type {kind} is left on the plate ({others} of other types): add parts of \
         type {kind}, or ask for another type"
    )]
    NoPartLeft {
        /// The type asked for.
        kind: usize,
        /// Parts of other types on the plate.
        others: usize,
    },
    /// No mode rests a part of the pick's type near the pick pose.
    #[error(
        "no mode holds a part of type {kind} at the pick pose ({:.1}, {:.1}, {:.1}°): the \
         nearest rest is ({:.1}, {:.1}, {:.1}°), {error_mm:.1} mm and {error_deg:.1}° off; \
         move the pick pose to a rest (or learn the plate)",
        .pick.x, .pick.y, .pick.theta.to_degrees(), .rest.x, .rest.y, .rest.theta.to_degrees()
    )]
    Unreachable {
        /// The type asked for.
        kind: usize,
        /// The pick pose.
        pick: Pose,
        /// The nearest rest some mode holds there.
        rest: Pose,
        /// Its distance from the pick pose (mm).
        error_mm: f64,
        /// Its orientation error (deg).
        error_deg: f64,
    },
    /// A pick with a number that is not usable.
    #[error("pick {field} = {value}: give a finite number (radii and tolerances ≥ 0)")]
    BadPick {
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// The steering algorithms refused.
    #[error(transparent)]
    Steer(#[from] SteerError),
}

/// The part to present at `pick`: among the parts of its type whose piece some mode of
/// `model` rests near the pick pose ([`Pick::hold_mm`]), the one of lowest estimate.
pub fn choose_part(
    model: &Model,
    parts: &[OnPlate],
    pick: &Pick,
    how: Estimate,
) -> Result<Choice, PresentError> {
    pick.check()?;
    let eligible: Vec<usize> = (0..parts.len()).filter(|&i| parts[i].kind == pick.kind).collect();
    if eligible.is_empty() {
        return Err(PresentError::NoPartLeft { kind: pick.kind, others: parts.len() });
    }
    // One reach per piece (identical parts share one), the nearest rest kept for the error.
    let mut reaches: Vec<(&Piece, Reach)> = Vec::new();
    for &i in &eligible {
        let piece = parts[i].piece;
        if !reaches.iter().any(|(p, _)| std::ptr::eq(*p, piece)) {
            let r = reachable_orientation(model, piece, pick.pose, pick.hold_mm, pick.hold_deg)?;
            reaches.push((piece, r));
        }
    }
    let reach_of =
        |piece: &Piece| reaches.iter().find(|(p, _)| std::ptr::eq(*p, piece)).map(|(_, r)| *r);
    let held: Vec<usize> = eligible
        .iter()
        .copied()
        .filter(|&i| reach_of(parts[i].piece).is_some_and(|r| r.reachable))
        .collect();
    if held.is_empty() {
        let nearest = reaches.iter().map(|(_, r)| *r).min_by(|a, b| {
            (a.error_mm + MM_PER_DEG * a.error_deg)
                .total_cmp(&(b.error_mm + MM_PER_DEG * b.error_deg))
        });
        let r = nearest.ok_or(PresentError::NoPartLeft { kind: pick.kind, others: 0 })?;
        return Err(PresentError::Unreachable {
            kind: pick.kind,
            pick: pick.pose,
            rest: r.rest,
            error_mm: r.error_mm,
            error_deg: r.error_deg,
        });
    }
    let estimates = estimates(model, parts, &held, pick, how);
    let (k, estimate_s) = estimates
        .into_iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .ok_or(PresentError::NoPartLeft { kind: pick.kind, others: 0 })?;
    let part = held[k];
    let reach = reach_of(parts[part].piece)
        .ok_or(PresentError::NoPartLeft { kind: pick.kind, others: 0 })?;
    Ok(Choice { part, estimate_s, reach })
}

/// Each of the `held` parts' estimated time (s) to the pick pose.
fn estimates(
    model: &Model,
    parts: &[OnPlate],
    held: &[usize],
    pick: &Pick,
    how: Estimate,
) -> Vec<f64> {
    let error = |i: usize, q: Pose| {
        distance_mm(q, pick.pose)
            + MM_PER_DEG * angle_error_deg(q, pick.pose, parts[i].piece.period_deg)
    };
    // Every held part's run under every mode, and the typical speed they move at.
    let runs: Vec<Vec<Vec<(f64, Pose)>>> = held
        .iter()
        .map(|&i| {
            (0..model.mode_count())
                .map(|m| model.run(&parts[i].piece.body, parts[i].pose, m, SOONEST_HORIZON_S).trace)
                .collect()
        })
        .collect();
    let closing = closing_speed(&runs);
    match how {
        Estimate::Nearest => held.iter().map(|&i| error(i, parts[i].pose) / closing).collect(),
        Estimate::Soonest => held
            .iter()
            .zip(&runs)
            .map(|(&i, modes)| {
                modes
                    .iter()
                    .flatten()
                    .map(|(t, q)| t + error(i, *q) / closing)
                    .fold(error(i, parts[i].pose) / closing, f64::min)
            })
            .collect(),
    }
}

/// The parts' typical speed (mm/s): the median over the runs that move of the distance
/// covered over the time taken (a run that rests early counts its time to rest).
fn closing_speed(runs: &[Vec<Vec<(f64, Pose)>>]) -> f64 {
    let mut speeds: Vec<f64> = runs
        .iter()
        .flatten()
        .filter_map(|trace| {
            let (&(_, a), &(t, b)) = (trace.first()?, trace.last()?);
            let d = distance_mm(a, b);
            (t > 0.0 && d > 1.0).then_some(d / t)
        })
        .collect();
    if speeds.is_empty() {
        return FALLBACK_CLOSING_MM_S;
    }
    speeds.sort_by(f64::total_cmp);
    speeds[speeds.len() / 2]
}

/// One cycle's objective: part `chosen` to the pick pose (its cost as any goal's); every other
/// part weighs nothing where it is, but pays per mm its centroid lies within the pick zone plus
/// its own bounding radius: [`KEEP_OUT_APPROACH_PER_MM`] while the chosen part comes,
/// [`KEEP_OUT_PER_MM`] once it is near (first bring it, then clear the zone around it). The
/// command is [`crate::steer::choose()`]'s.
pub fn objective<'a>(parts: &[OnPlate<'a>], chosen: usize, pick: &Pick) -> Vec<PartGoal<'a>> {
    let near = parts
        .get(chosen)
        .is_some_and(|c| PartGoal::new(c.piece, c.pose, pick.pose).error_mm(c.pose) <= NEAR_MM);
    let per_mm = if near { KEEP_OUT_PER_MM } else { KEEP_OUT_APPROACH_PER_MM };
    parts
        .iter()
        .enumerate()
        .map(|(i, p)| {
            if i == chosen {
                PartGoal::new(p.piece, p.pose, pick.pose)
            } else {
                PartGoal {
                    weight: 0.0,
                    keep_out: Some(KeepOut { per_mm, ..keep_out(p.piece, pick) }),
                    ..PartGoal::new(p.piece, p.pose, p.pose)
                }
            }
        })
        .collect()
}

/// The circle a part not presented keeps its centroid out of.
fn keep_out(piece: &Piece, pick: &Pick) -> KeepOut {
    KeepOut {
        centre: [pick.pose.x, pick.pose.y],
        radius_mm: pick.zone_mm + piece.body.radius,
        per_mm: KEEP_OUT_PER_MM,
    }
}

/// Is part `chosen` presented: within the pick's tolerances of the pick pose?
pub fn presented(parts: &[OnPlate], chosen: usize, pick: &Pick) -> bool {
    parts.get(chosen).is_some_and(|p| {
        distance_mm(p.pose, pick.pose) <= pick.tol_mm
            && angle_error_deg(p.pose, pick.pose, p.piece.period_deg) <= pick.tol_deg
    })
}

/// The parts other than `chosen` whose bounding circle reaches into the pick zone.
pub fn in_zone(parts: &[OnPlate], chosen: usize, pick: &Pick) -> Vec<usize> {
    (0..parts.len())
        .filter(|&i| i != chosen && keep_out(parts[i].piece, pick).cost_at(parts[i].pose) > 0.0)
        .collect()
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::model::part::Part;
    use crate::model::plate::PlateModel;
    use crate::motion::body::Body;
    use crate::steer::choose::{Menu, Stall, choose};
    use crate::steer::cost::total_cost;
    use crate::steer::sim::{Noise, Truth};

    /// The free plate's first 6 solver modes at 120 mm/s.
    fn model() -> Model {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut p = PlateModel::load(&root.join("examples/plates/free-6-modes.toml")).unwrap();
        for m in &mut p.modes {
            m.speed_mm_s = 120.0;
        }
        Model::new(p)
    }

    fn piece(name: &str) -> Piece {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let path = root.join(format!("examples/parts/ordinary/{name}.json"));
        Piece::new(&Part::load(&path).unwrap())
    }

    fn at(x: f64, y: f64, theta: f64) -> Pose {
        Pose { x, y, theta }
    }

    #[test]
    fn nothing_is_presented_when_no_part_of_the_type_is_left_or_no_mode_holds_it() {
        let (model, p) = (model(), piece("u-channel"));
        let rest = model.run_to_rest(&p.body, at(120.0, 90.0, 0.7), 1).pose;
        let parts = [OnPlate { piece: &p, kind: 1, pose: at(60.0, 60.0, 0.0) }];
        let pick = Pick::new(rest, 0, 20.0);
        let e = choose_part(&model, &parts, &pick, Estimate::Soonest).unwrap_err();
        assert_eq!(e, PresentError::NoPartLeft { kind: 0, others: 1 });
        // A pose turned 40° off the rest: no mode holds the part there.
        let parts = [OnPlate { kind: 0, ..parts[0] }];
        let turned =
            Pick { hold_deg: 3.0, ..Pick::new(at(rest.x, rest.y, rest.theta + 0.7), 0, 20.0) };
        match choose_part(&model, &parts, &turned, Estimate::Soonest) {
            Err(PresentError::Unreachable { error_mm, error_deg, .. }) => {
                assert!(error_deg > 3.0 || error_mm > 10.0, "{error_mm} {error_deg}")
            }
            other => panic!("{other:?}"),
        }
        for (bad, field) in [
            (Pick { zone_mm: f64::NAN, ..pick }, "zone_mm"),
            (Pick { tol_deg: -1.0, ..pick }, "tol_deg"),
            (Pick { pose: at(f64::INFINITY, 0.0, 0.0), ..pick }, "pose x"),
        ] {
            match choose_part(&model, &parts, &bad, Estimate::Nearest) {
                Err(PresentError::BadPick { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{field}: {other:?}"),
            }
        }
    }

    #[test]
    fn the_part_at_the_pick_pose_is_chosen_by_either_estimate_and_is_presented() {
        let (model, p, q) = (model(), piece("u-channel"), piece("keyed-gear"));
        let rest = model.run_to_rest(&p.body, at(120.0, 90.0, 0.7), 1).pose;
        let parts = [
            OnPlate { piece: &p, kind: 0, pose: at(240.0, 40.0, 2.0) },
            OnPlate { piece: &q, kind: 1, pose: at(rest.x + 1.0, rest.y, rest.theta) },
            OnPlate { piece: &p, kind: 0, pose: rest },
        ];
        let pick = Pick::new(rest, 0, 20.0);
        for how in [Estimate::Soonest, Estimate::Nearest] {
            let c = choose_part(&model, &parts, &pick, how).unwrap();
            assert_eq!(c.part, 2, "{how:?}: {c:?}");
            assert!(c.estimate_s < 0.1 && c.reach.reachable, "{how:?}: {c:?}");
        }
        assert!(presented(&parts, 2, &pick) && !presented(&parts, 0, &pick));
        assert!(!presented(&parts, 7, &pick), "no such part");
        // The gear (another type) lies in the zone, the far u-channel does not.
        assert_eq!(in_zone(&parts, 2, &pick), vec![1]);
    }

    #[test]
    fn soonest_counts_where_a_mode_carries_the_part() {
        let (model, p) = (model(), piece("u-channel"));
        // A pick pose where a mode carries the part from a start more than 30 mm away.
        let (start, rest) = [at(70.0, 150.0, 0.3), at(230.0, 60.0, 1.0), at(150.0, 40.0, 2.0)]
            .into_iter()
            .flat_map(|s| (0..model.mode_count()).map(move |m| (s, m)))
            .map(|(s, m)| (s, model.run_to_rest(&p.body, s, m).pose))
            .find(|(s, r)| distance_mm(*s, *r) > 30.0)
            .unwrap();
        let pick = Pick::new(rest, 0, 20.0);
        let parts = [OnPlate { piece: &p, kind: 0, pose: start }];
        let soon = choose_part(&model, &parts, &pick, Estimate::Soonest).unwrap();
        let near = choose_part(&model, &parts, &pick, Estimate::Nearest).unwrap();
        // The mode's own run gets there sooner than the straight line at the typical speed.
        assert!(soon.estimate_s < near.estimate_s, "{soon:?} {near:?}");
    }

    #[test]
    fn the_objective_pulls_the_chosen_part_and_pushes_the_others_out_of_the_zone() {
        let (p, q) = (piece("u-channel"), piece("keyed-gear"));
        let pick = Pick::new(at(150.0, 100.0, 0.0), 0, 20.0);
        let inside = at(160.0, 100.0, 0.0);
        let parts = [
            OnPlate { piece: &p, kind: 0, pose: at(60.0, 60.0, 0.5) },
            OnPlate { piece: &q, kind: 1, pose: inside },
        ];
        let goals = objective(&parts, 0, &pick);
        assert_eq!((goals[0].goal, goals[0].weight, goals[0].keep_out), (pick.pose, 1.0, None));
        let k = goals[1].keep_out.unwrap();
        assert_eq!(goals[1].weight, 0.0);
        assert!((k.radius_mm - (20.0 + q.body.radius)).abs() < 1e-12, "{k:?}");
        // 10 mm from the centre: (radius − 10) mm inside, weakly while the chosen part comes.
        let expected = KEEP_OUT_APPROACH_PER_MM * (k.radius_mm - 10.0);
        assert!((goals[1].cost_at(inside) - expected).abs() < 1e-9);
        let outside = at(150.0 + k.radius_mm + 0.1, 100.0, 0.0);
        assert_eq!(goals[1].cost_at(outside), 0.0);
        // The other part's cost is its keep-out's alone, wherever it goes outside the zone.
        let poses = [parts[0].pose, outside];
        assert!((total_cost(&goals, &poses) - goals[0].cost_at(parts[0].pose)).abs() < 1e-9);
        // The chosen part near the pick pose (3 mm off): the zone is cleared in earnest.
        let near = [OnPlate { pose: at(153.0, 100.0, 0.0), ..parts[0] }, parts[1]];
        let k = objective(&near, 0, &pick)[1].keep_out.unwrap();
        assert_eq!(k.per_mm, KEEP_OUT_PER_MM);
        let far = [OnPlate { pose: at(155.0, 100.0, 0.0), ..parts[0] }, parts[1]];
        assert_eq!(objective(&far, 0, &pick)[1].keep_out.unwrap().per_mm, KEEP_OUT_APPROACH_PER_MM);
    }

    /// Present cycles against `truth` until part 0 is presented with the zone clear, or
    /// `cycles` run out: the cycles run.
    fn present_loop(
        truth: &mut Truth,
        model: &Model,
        parts: &mut [OnPlate],
        pick: &Pick,
        cycles: usize,
    ) -> Option<usize> {
        let menu = Menu::default();
        let mut stall = Stall::new();
        for n in 0..cycles {
            if presented(parts, 0, pick) && in_zone(parts, 0, pick).is_empty() {
                return Some(n);
            }
            let cmd = choose(model, &stall.weigh(&objective(parts, 0, pick)), &menu).unwrap();
            let before: Vec<(&Body, Pose)> =
                parts.iter().map(|p| (&p.piece.body, p.pose)).collect();
            let after = truth.burst(&before, cmd.mode, cmd.burst_s).unwrap();
            for (p, q) in parts.iter_mut().zip(after) {
                p.pose = q;
            }
        }
        None
    }

    #[test]
    fn a_present_loop_clears_the_zone_and_keeps_the_part_presented() {
        let (model, p, q) = (model(), piece("u-channel"), piece("keyed-gear"));
        let pick = Pick::new(model.run_to_rest(&p.body, at(150.0, 100.0, 0.7), 1).pose, 0, 15.0);
        // The part presented already; a gear in the pick zone, beside it.
        let mut parts = [
            OnPlate { piece: &p, kind: 0, pose: pick.pose },
            OnPlate { piece: &q, kind: 1, pose: at(pick.pose.x + 25.0, pick.pose.y + 5.0, 0.0) },
        ];
        assert_eq!(in_zone(&parts, 0, &pick), vec![1]);
        let noise = Noise { bounces_per_s: 0.0, ..Noise::default() };
        let mut truth = Truth::new(model.clone(), noise, 3);
        let n = present_loop(&mut truth, &model, &mut parts, &pick, 300);
        let end = parts.map(|p| p.pose);
        let err =
            (distance_mm(end[0], pick.pose), angle_error_deg(end[0], pick.pose, p.period_deg));
        assert!(
            n.is_some(),
            "pick {:?}: {end:?}, off {err:?}, in zone {:?}",
            pick.pose,
            in_zone(&parts, 0, &pick)
        );
    }
}
