//! Which burst to record next while learning, and bringing parts back home when they have
//! gathered or drifted to the rim.
//!
//! The policy: modes are taken least-recorded first (so each is recorded about as often as
//! the others, from the poses the previous bursts left: varied), each with the longest burst
//! of the menu after which every part is predicted to stay [`Rules::rim_mm`] clear of the
//! rim, to move no more than [`Rules::max_move_mm`], and not to come within
//! [`Rules::gap_mm`] of another; among modes recorded equally often, one that moves some part
//! by [`Rules::min_move_mm`] comes first (a part that stays put shows where the node is, not
//! the speed). When no mode has such a burst, or parts already touch each other or the rim
//! ([`needs_recover`]), the step is [`LearnStep::Recover`]: the command that brings them
//! towards spread home positions ([`recover`]).

use crate::model::geometry::bounds;
use crate::model::plate::PlateModel;
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::shape::contacts;
use crate::steer::SteerError;
use crate::steer::assign::assign;
use crate::steer::choose::{Command, Menu, choose};
use crate::steer::cost::Piece;
use crate::steer::cost::{PartGoal, distance_mm};
use crate::steer::model::{Model, check_bursts};

/// The limits the learning policy keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rules {
    /// Clearance (mm) each part keeps from the plate's edge.
    pub rim_mm: f64,
    /// Parts that come within this (mm) of touching have gathered.
    pub gap_mm: f64,
    /// Largest predicted move (mm) of any part in one burst.
    pub max_move_mm: f64,
    /// Smallest predicted move (mm) of some part for a burst to be informative.
    pub min_move_mm: f64,
}

impl Default for Rules {
    /// 3 mm from the rim and between parts, moves of 2–40 mm.
    fn default() -> Self {
        Rules { rim_mm: 3.0, gap_mm: 3.0, max_move_mm: 40.0, min_move_mm: 2.0 }
    }
}

/// The next thing to do while learning.
#[derive(Debug, Clone, PartialEq)]
pub enum LearnStep {
    /// Record this burst.
    Burst {
        /// Mode index.
        mode: usize,
        /// Burst length (s).
        burst_s: f64,
    },
    /// Bring the parts home first with this command (not recorded for the fit).
    Recover(Command),
}

/// Parts this close (mm) to the rim or to each other touch it: their motion is no longer the
/// motion of one free part that the fit predicts.
pub const TOUCH_MM: f64 = 0.5;

/// Must the parts (at their poses) be brought home before a burst is recorded: does one touch
/// the rim or another part ([`TOUCH_MM`])? Parts merely near each other are not: a burst is
/// recorded from there if it is predicted to part them ([`Rules`]).
pub fn needs_recover(plate: &PlateModel, parts: &[(&Piece, Pose)]) -> bool {
    too_close(plate, parts, TOUCH_MM, TOUCH_MM)
}

/// Does a part come within `rim` (mm) of the plate's edge or within `gap` of another part?
pub(crate) fn too_close(plate: &PlateModel, parts: &[(&Piece, Pose)], rim: f64, gap: f64) -> bool {
    let [w, h] = plate.size_mm;
    let near_rim = parts.iter().any(|(p, q)| {
        let placed = p.body.placed(*q);
        let (lo, hi) = bounds(placed.iter().flatten());
        lo[0] < rim || lo[1] < rim || hi[0] > w - rim || hi[1] > h - rim
    });
    near_rim || gathered(parts, &parts.iter().map(|p| p.1).collect::<Vec<_>>(), gap)
}

/// Do any two parts at `poses` come within `gap` (mm) of touching?
fn gathered(parts: &[(&Piece, Pose)], poses: &[Pose], gap: f64) -> bool {
    (0..parts.len()).any(|i| {
        (i + 1..parts.len()).any(|j| {
            let (a, b) = (parts[i].0, parts[j].0);
            distance_mm(poses[i], poses[j]) < a.body.radius + b.body.radius + gap
                && !contacts(&a.shapes, poses[i], &b.shapes, poses[j], gap).is_empty()
        })
    })
}

/// The next learning step for the parts (bodies at poses), `counts[m]` bursts of mode m
/// recorded so far, bursts from `menu` (see the module doc).
pub fn next_learning_step(
    model: &Model,
    parts: &[(&Piece, Pose)],
    counts: &[usize],
    menu: &Menu,
    rules: &Rules,
) -> Result<LearnStep, SteerError> {
    check_bursts(&menu.bursts_s)?;
    if parts.is_empty() {
        return Err(SteerError::NoParts);
    }
    if needs_recover(model.given(), parts) {
        return Ok(LearnStep::Recover(recover(model, parts, menu)?));
    }
    let count = |m: usize| counts.get(m).copied().unwrap_or(0);
    let mut order: Vec<usize> = (0..model.mode_count()).collect();
    order.sort_by_key(|m| count(*m));
    let bodies: Vec<(&Body, Pose)> = parts.iter().map(|(p, q)| (&p.body, *q)).collect();
    let mut fallback: Option<(usize, LearnStep)> = None;
    for mode in order {
        // A still part is no reason to record a more-recorded mode: it shows the node.
        if let Some((c, step)) = &fallback
            && count(mode) > *c
        {
            return Ok(step.clone());
        }
        let preds = model.predict_all(&bodies, mode, &menu.bursts_s)?;
        match safe_burst(model, parts, &preds, menu, rules) {
            Some((burst_s, true)) => return Ok(LearnStep::Burst { mode, burst_s }),
            Some((burst_s, false)) if fallback.is_none() => {
                fallback = Some((count(mode), LearnStep::Burst { mode, burst_s }));
            }
            _ => {}
        }
    }
    match fallback {
        Some((_, step)) => Ok(step),
        None => Ok(LearnStep::Recover(recover(model, parts, menu)?)),
    }
}

/// The longest burst of `menu` whose predictions `preds` (`[part][burst]`) keep the rules,
/// and whether it is informative (moves some part by [`Rules::min_move_mm`]).
fn safe_burst(
    model: &Model,
    parts: &[(&Piece, Pose)],
    preds: &[Vec<Pose>],
    menu: &Menu,
    rules: &Rules,
) -> Option<(f64, bool)> {
    let mut still = None;
    // Longest first: the longest safe burst shows the most.
    for (k, &burst_s) in menu.bursts_s.iter().enumerate().rev() {
        let after: Vec<Pose> = preds.iter().map(|p| p[k]).collect();
        let moves: Vec<f64> = parts.iter().zip(&after).map(|(p, q)| distance_mm(p.1, *q)).collect();
        let moved: Vec<(&Piece, Pose)> = parts.iter().zip(&after).map(|(p, q)| (p.0, *q)).collect();
        let safe = moves.iter().all(|d| *d <= rules.max_move_mm)
            && !too_close(model.given(), &moved, rules.rim_mm, rules.gap_mm);
        if !safe {
            continue;
        }
        if moves.iter().any(|d| *d >= rules.min_move_mm) {
            return Some((burst_s, true));
        }
        still = still.or(Some((burst_s, false)));
    }
    still
}

/// `n` home positions spread over the plate's middle two thirds: the cell centres of a grid
/// of about the plate's aspect ratio.
pub fn home_positions(plate: &PlateModel, n: usize) -> Vec<[f64; 2]> {
    let [w, h] = plate.size_mm;
    let cols = ((n as f64 * w / h.max(1e-9)).sqrt().ceil() as usize).clamp(1, n.max(1));
    let rows = n.div_ceil(cols).max(1);
    let (x0, y0, cw, ch) =
        (w / 6.0, h / 6.0, 2.0 * w / 3.0 / cols as f64, 2.0 * h / 3.0 / rows as f64);
    (0..n)
        .map(|k| [x0 + ((k % cols) as f64 + 0.5) * cw, y0 + ((k / cols) as f64 + 0.5) * ch])
        .collect()
}

/// The command (by [`choose`], position only) that brings the parts towards spread home
/// positions ([`home_positions`], each part to the nearest free one by [`assign`]).
pub fn recover(
    model: &Model,
    parts: &[(&Piece, Pose)],
    menu: &Menu,
) -> Result<Command, SteerError> {
    let homes = home_positions(model.given(), parts.len());
    let cost: Vec<Vec<f64>> = parts
        .iter()
        .map(|(_, q)| homes.iter().map(|h| (q.x - h[0]).hypot(q.y - h[1])).collect())
        .collect();
    let home_of = assign(&cost)?;
    let goals: Vec<PartGoal> = parts
        .iter()
        .zip(home_of)
        .map(|((piece, q), k)| {
            let goal = Pose { x: homes[k][0], y: homes[k][1], theta: q.theta };
            PartGoal { mm_per_deg: 0.0, ..PartGoal::new(piece, *q, goal) }
        })
        .collect();
    choose(model, &goals, menu)
}
