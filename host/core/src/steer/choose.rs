//! The command of one control cycle: the mode and burst length that leaves the least to do
//! ([`crate::steer::togo`]: the cost no combination of modes removes from where it leaves
//! the parts, plus the drive time it and that combination take), or, by choice, the one
//! whose predicted outcome most reduces the parts' total cost ([`crate::steer::cost`]), with
//! a look-ahead of one more command over the best few first commands.

use crate::model::pose::Pose;
use crate::steer::SteerError;
use crate::steer::cost::{PartGoal, total_cost};
use crate::steer::model::{Model, check_bursts};
use crate::steer::togo::Velocities;

/// The commands one cycle chooses from.
#[derive(Debug, Clone, PartialEq)]
pub struct Menu {
    /// Burst lengths (s), each > 0.
    pub bursts_s: Vec<f64>,
    /// Look-ahead of the choice by cost: how many of the best first commands (by their own
    /// predicted cost) are tried with every second command; 0: none.
    pub lookahead: usize,
    /// Value commands by what they leave to do ([`crate::steer::togo`]), counting this
    /// many mm of cost per second of drive; `None`: by their cost (and the look-ahead). One
    /// part steered (one of weight > 0: presenting a part, the others only kept out of its
    /// way) is always chosen by cost: its cost falls towards its goal wherever it is, and
    /// near a rest the velocities cannot see the turn a detour gives (on the 6-mode plate a
    /// part held 0.1 mm from its goal stayed 13° off for 3000 cycles).
    pub to_go_mm_per_s: Option<f64>,
}

/// The price of drive time in the choice by what is left to do: 0.5 mm of cost per second.
/// Chosen over 0.1, 0.25 and 2 on the steer bench's three-part trials (docs/evidence/steer.md):
/// a higher price takes the quick command that leaves the parts where no combination helps;
/// a lower one spends minutes of drive on small gains.
pub const TO_GO_MM_PER_S: f64 = 0.5;

impl Default for Menu {
    /// Eight bursts from 0.03 to 2 s (short ones to nudge parts near their goals, a long one
    /// to cross the plate: a part moves at most speed × burst), chosen by what they leave to
    /// do at [`TO_GO_MM_PER_S`] (the look-ahead of 3 applies when that is turned off).
    fn default() -> Self {
        Menu {
            bursts_s: vec![0.03, 0.06, 0.1, 0.2, 0.4, 0.7, 1.2, 2.0],
            lookahead: 3,
            to_go_mm_per_s: Some(TO_GO_MM_PER_S),
        }
    }
}

/// The second command of a look-ahead, and the cost predicted after both.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Then {
    /// Mode index.
    pub mode: usize,
    /// Burst length (s).
    pub burst_s: f64,
    /// Total cost (mm) predicted after the first command and this one.
    pub cost: f64,
}

/// One cycle's command.
#[derive(Debug, Clone, PartialEq)]
pub struct Command {
    /// Mode index into the model's plate.
    pub mode: usize,
    /// Burst length (s).
    pub burst_s: f64,
    /// Each part's pose predicted after the burst, in the parts' order.
    pub predicted: Vec<Pose>,
    /// Total cost (mm) predicted after the burst.
    pub cost: f64,
    /// The look-ahead's second command, when the pair was predicted to end lower than any
    /// single command (the reason this first command was chosen).
    pub then: Option<Then>,
}

/// A first command and its prediction.
struct Candidate {
    mode: usize,
    burst_s: f64,
    poses: Vec<Pose>,
    cost: f64,
}

/// Every (mode, burst) command's predicted poses and cost from `poses`: one run per part and
/// mode, read at every burst length.
fn candidates(model: &Model, parts: &[PartGoal], poses: &[Pose], bursts: &[f64]) -> Vec<Candidate> {
    let mut out = Vec::with_capacity(model.mode_count() * bursts.len());
    let mut per_part: Vec<Vec<Pose>> = vec![Vec::new(); parts.len()];
    for mode in 0..model.mode_count() {
        for ((part, pose), pred) in parts.iter().zip(poses).zip(&mut per_part) {
            model.predict_unchecked(&part.piece.body, *pose, mode, bursts, pred);
        }
        for burst in 0..bursts.len() {
            let poses: Vec<Pose> = per_part.iter().map(|p| p[burst]).collect();
            let cost = total_cost(parts, &poses);
            out.push(Candidate { mode, burst_s: bursts[burst], poses, cost });
        }
    }
    out
}

/// The command of `menu` to drive next for `parts` (at their `pose`s) under `model`: with
/// [`Menu::to_go_mm_per_s`] and several parts steered, the command that leaves the least to do
/// ([`crate::steer::togo`]); without, the command that most reduces the total cost, with the
/// look-ahead: each of the `menu.lookahead` best first commands is valued at the lower of its
/// own cost and the best cost any second command reaches after it; the first command of
/// lowest value wins (ties: the lower cost of its own). "Do nothing" is never an option: the
/// best command is returned even when every command raises the cost (each cycle moves the
/// parts).
pub fn choose(model: &Model, parts: &[PartGoal], menu: &Menu) -> Result<Command, SteerError> {
    if parts.is_empty() {
        return Err(SteerError::NoParts);
    }
    check_bursts(&menu.bursts_s)?;
    let bursts = &menu.bursts_s;
    let start: Vec<Pose> = parts.iter().map(|p| p.pose).collect();
    let mut first = candidates(model, parts, &start, bursts);
    let steered = parts.iter().filter(|p| p.weight > 0.0).count();
    if let Some(rate) = menu.to_go_mm_per_s.filter(|_| steered > 1) {
        let v = velocities(parts, &first, bursts);
        let left = |c: &Candidate| v.value(parts, &c.poses, rate) + rate * c.burst_s;
        let c = first.iter().min_by(|a, b| left(a).total_cmp(&left(b)));
        let c = c.ok_or(SteerError::NoParts)?;
        let (mode, burst_s, cost) = (c.mode, c.burst_s, c.cost);
        return Ok(Command { mode, burst_s, predicted: c.poses.clone(), cost, then: None });
    }
    first.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    let mut best: Option<(f64, usize, Option<Then>)> = None;
    for (k, c) in first.iter().enumerate().take(menu.lookahead.max(1)) {
        let then =
            if menu.lookahead > 0 { best_second(model, parts, &c.poses, bursts) } else { None };
        let value = then.filter(|t| t.cost < c.cost).map_or(c.cost, |t| t.cost);
        let then = then.filter(|t| t.cost < c.cost);
        if best.as_ref().is_none_or(|b| value < b.0) {
            best = Some((value, k, then));
        }
    }
    let (_, k, then) = best.ok_or(SteerError::NoParts)?;
    let c = first.swap_remove(k);
    Ok(Command { mode: c.mode, burst_s: c.burst_s, predicted: c.poses, cost: c.cost, then })
}

/// Each mode's velocities at the parts, from its candidate of the shortest burst.
fn velocities(parts: &[PartGoal], first: &[Candidate], bursts: &[f64]) -> Velocities {
    let shortest = (0..bursts.len()).min_by(|&a, &b| bursts[a].total_cmp(&bursts[b])).unwrap_or(0);
    let after: Vec<Vec<Pose>> =
        first.iter().filter(|c| c.burst_s == bursts[shortest]).map(|c| c.poses.clone()).collect();
    Velocities::from_short_burst(parts, &after, bursts[shortest])
}

/// The second command of lowest cost from `poses`.
fn best_second(model: &Model, parts: &[PartGoal], poses: &[Pose], bursts: &[f64]) -> Option<Then> {
    candidates(model, parts, poses, bursts)
        .into_iter()
        .min_by(|a, b| a.cost.total_cmp(&b.cost))
        .map(|c| Then { mode: c.mode, burst_s: c.burst_s, cost: c.cost })
}

/// Cycles without a new lowest total cost after which the loop turns to its worst part
/// ([`Stall`]).
pub const STALL_CYCLES: usize = 12;

/// Cycles a turn to the worst part lasts.
pub const FOCUS_CYCLES: usize = 8;

/// The weight of the other parts while the loop turns to the worst one.
pub const FOCUS_OTHERS: f64 = 0.2;

/// A loop's memory of its progress, for what a cycle's choice cannot see: a local minimum of
/// the total cost, where every command that brings a far part nearer costs more elsewhere (the
/// other parts taken off their goals, or the part's own orientation turned off the goal's on
/// the way). When the total cost has not reached a new low for [`STALL_CYCLES`] cycles, the
/// next [`FOCUS_CYCLES`] choices weigh the worst part's position alone (its orientation at 0)
/// and the other parts at [`FOCUS_OTHERS`]: it is brought nearer, and the rest put right
/// afterwards.
#[derive(Debug, Clone, Default)]
pub struct Stall {
    best: Option<f64>,
    since: usize,
    focus: Option<(usize, usize)>,
}

impl Stall {
    /// No progress seen yet.
    pub fn new() -> Stall {
        Stall::default()
    }

    /// The parts to choose for this cycle: `parts` as they are, or re-weighted towards the
    /// worst while a turn to it lasts.
    pub fn weigh<'a>(&mut self, parts: &[PartGoal<'a>]) -> Vec<PartGoal<'a>> {
        let now: f64 = parts.iter().map(|p| p.cost_at(p.pose)).sum();
        if self.best.is_none_or(|b| now < b - 1e-6) {
            (self.best, self.since) = (Some(now), 0);
        } else {
            self.since += 1;
        }
        if self.focus.is_none() && self.since >= STALL_CYCLES {
            let worst = (0..parts.len()).max_by(|&a, &b| {
                parts[a].cost_at(parts[a].pose).total_cmp(&parts[b].cost_at(parts[b].pose))
            });
            self.focus = worst.map(|k| (k, FOCUS_CYCLES));
            self.since = 0;
        }
        let Some((k, left)) = self.focus else { return parts.to_vec() };
        self.focus = (left > 1).then_some((k, left - 1));
        parts
            .iter()
            .enumerate()
            .map(|(i, p)| {
                if i == k {
                    PartGoal { mm_per_deg: 0.0, ..*p }
                } else {
                    PartGoal { weight: p.weight * FOCUS_OTHERS, ..*p }
                }
            })
            .collect()
    }
}
