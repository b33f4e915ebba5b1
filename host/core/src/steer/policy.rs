//! Which burst to record next while learning, and bringing parts back home when they have
//! gathered or drifted to the rim.
//!
//! The policy: modes are taken least-recorded first (so each is recorded about as often as
//! the others, from the poses the previous bursts left: varied), each with the longest burst
//! of the menu after which every part is predicted to stay [`Rules::rim_mm`] clear of the
//! rim, to move no more than [`Rules::max_move_mm`], and not to gather with another; a burst
//! that moves no part by [`Rules::min_move_mm`] shows little and is taken only if no mode
//! offers better. When no mode has such a burst, or the parts already gathered or reached the
//! rim ([`needs_recover`]), the step is [`LearnStep::Recover`]: the command that brings them
//! towards spread home positions ([`recover`]).

use crate::model::plate::PlateModel;
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::steer::SteerError;
use crate::steer::assign::assign;
use crate::steer::choose::{Command, Menu, choose};
use crate::steer::cost::Piece;
use crate::steer::cost::{PartGoal, distance_mm};
use crate::steer::model::{Model, check_bursts};

/// The limits the learning policy keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rules {
    /// Clearance (mm) each part's bounding circle keeps from the plate's edge.
    pub rim_mm: f64,
    /// Parts whose bounding circles come closer than this (mm) have gathered.
    pub gap_mm: f64,
    /// Largest predicted move (mm) of any part in one burst.
    pub max_move_mm: f64,
    /// Smallest predicted move (mm) of some part for a burst to be informative.
    pub min_move_mm: f64,
}

impl Default for Rules {
    /// 5 mm from the rim, 5 mm between parts, moves of 2–40 mm.
    fn default() -> Self {
        Rules { rim_mm: 5.0, gap_mm: 5.0, max_move_mm: 40.0, min_move_mm: 2.0 }
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

/// Are the parts (bodies at poses) too near the rim or each other to record a burst?
pub fn needs_recover(plate: &PlateModel, parts: &[(&Piece, Pose)], rules: &Rules) -> bool {
    let [w, h] = plate.size_mm;
    let near_rim = parts.iter().any(|(b, q)| {
        let r = b.body.radius + rules.rim_mm;
        q.x < r || q.y < r || q.x > w - r || q.y > h - r
    });
    near_rim || gathered(parts, &parts.iter().map(|p| p.1).collect::<Vec<_>>(), rules.gap_mm)
}

/// Do any two parts at `poses` come closer than `gap` (mm) between bounding circles?
fn gathered(parts: &[(&Piece, Pose)], poses: &[Pose], gap: f64) -> bool {
    (0..parts.len()).any(|i| {
        (i + 1..parts.len()).any(|j| {
            distance_mm(poses[i], poses[j]) < parts[i].0.body.radius + parts[j].0.body.radius + gap
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
    if needs_recover(model.given(), parts, rules) {
        return Ok(LearnStep::Recover(recover(model, parts, menu)?));
    }
    let mut order: Vec<usize> = (0..model.mode_count()).collect();
    order.sort_by_key(|m| counts.get(*m).copied().unwrap_or(0));
    let bodies: Vec<(&Body, Pose)> = parts.iter().map(|(p, q)| (&p.body, *q)).collect();
    let mut fallback = None;
    for mode in order {
        let preds = model.predict_all(&bodies, mode, &menu.bursts_s)?;
        // Longest first: the longest safe burst shows the most.
        for (k, &burst_s) in menu.bursts_s.iter().enumerate().rev() {
            let after: Vec<Pose> = preds.iter().map(|p| p[k]).collect();
            let moves: Vec<f64> =
                parts.iter().zip(&after).map(|(p, q)| distance_mm(p.1, *q)).collect();
            let moved: Vec<(&Piece, Pose)> =
                parts.iter().zip(&after).map(|(p, q)| (p.0, *q)).collect();
            let safe = moves.iter().all(|d| *d <= rules.max_move_mm)
                && !needs_recover(model.given(), &moved, rules);
            if !safe {
                continue;
            }
            if moves.iter().any(|d| *d >= rules.min_move_mm) {
                return Ok(LearnStep::Burst { mode, burst_s });
            }
            fallback = fallback.or(Some(LearnStep::Burst { mode, burst_s }));
        }
    }
    match fallback {
        Some(step) => Ok(step),
        None => Ok(LearnStep::Recover(recover(model, parts, menu)?)),
    }
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
