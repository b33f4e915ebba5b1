//! Plans that meet what the user asks for: a goal orientation, a fixed or goal position, least
//! steps or least time, and several parts at once (docs/plan.md, `--goal-deg`,
//! `--fix-position`, `--goal-pos`, `--minimize`, several parts).
//!
//! The search itself is [`super::search`]; this module gives it its costs (simulated step
//! durations, memoised per orientation so a cost is cheap to ask for during the search), its
//! position test ([`super::position`]), checks the found plan's transitions dynamically (as
//! [`super::plan_with`] always did), and names the failures: an unreachable goal with the
//! orientations that are reachable, a position no plan fixes, parts kept apart.

use crate::motion::body::PLANNER_BODY_SAMPLES;
use std::collections::HashMap;

use crate::model::part::Part;
use crate::model::plate::{Node, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::field::FieldModel;
use crate::progress::Progress;

use super::position::{self, POSITION_TOL_MM};
use super::search::{Minimize, Path, Reach, Search, State, Target};
use super::whole::OnPlate;
use super::{
    PlanFailure, PlanOptions, PlannedStep, Problem, Settle, Synthesis, confirm_any, deadline,
    settle_time, slowest_settled, start_points, step_duration_ms,
};
use crate::model::angle::cdist;

/// One part of a plan for several parts: its predictions.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PartPlan {
    /// Part name.
    pub name: String,
    /// Its period (deg).
    pub period_deg: f64,
    /// Its predicted final orientation (deg, in [0, period)).
    pub final_orientation_deg: f64,
    /// Its final centroid when fixed (mm).
    pub final_position_mm: Option<[f64; 2]>,
    /// The goal asked for (deg).
    pub goal_deg: Option<f64>,
    /// Final orientations plans of at most [`Synthesis::max_steps`] steps can end at (deg).
    pub reachable_deg: Vec<f64>,
    /// Predicted orientations after each step (deg).
    pub after: Vec<Vec<f64>>,
}

/// A simulated start is at most this far (mm) from the predicted position for the position to
/// count as confirmed.
pub(crate) const POSITION_CONFIRM_MM: f64 = 2.0;

/// Settle times memoised per (part, mode, orientation): a step's duration from a set of
/// orientations is computed from them as [`settle_time`] computes it.
struct Durations<'a> {
    bodies: &'a [Body],
    plate: &'a PlateModel,
    problems: &'a [&'a Problem],
    opt: &'a PlanOptions,
    /// (settle time, ended on the plate edge) per start point.
    memo: HashMap<(usize, usize, i64), Vec<(f64, bool)>>,
}

/// The first step's simulated start orientations (every 15°, those the map takes).
fn first_starts(problem: &Problem, k: usize, margin: f64) -> Vec<f64> {
    (0..24)
        .map(|i| i as f64 * 15.0)
        .filter(|&t| problem.maps[k].apply_all(t, margin).is_ok())
        .collect()
}

impl Durations<'_> {
    fn runs(&mut self, i: usize, k: usize, theta: f64) -> &[(f64, bool)] {
        let key = (i, k, (theta * 1000.0).round() as i64);
        let (body, plate) = (&self.bodies[i], self.plate);
        self.memo.entry(key).or_insert_with(|| {
            let mode = &plate.modes[k];
            let field = FieldModel::new(mode, plate);
            let p = super::settle::settle_params(mode, plate);
            start_points(body, mode, plate)
                .into_iter()
                .map(|pt| {
                    let q = Pose { x: pt[0], y: pt[1], theta: theta.to_radians() };
                    let r = crate::motion::integrate::run(body, &field, p, q);
                    (r.settle_s, super::maps::outside_reach(body, mode, plate, r.pose))
                })
                .collect()
        })
    }

    /// The duration (ms) of mode `k` from `before` (`None`: the first step): the longest over
    /// the parts.
    fn step_ms(&mut self, k: usize, before: Option<&[Vec<f64>]>) -> u64 {
        let mut worst = 0;
        for i in 0..self.bodies.len() {
            let thetas = match before {
                Some(b) => b[i].clone(),
                None => first_starts(self.problems[i], k, self.opt.margin_deg),
            };
            let per: Vec<Vec<(f64, bool)>> =
                thetas.iter().map(|&t| self.runs(i, k, t).to_vec()).collect();
            let points = per.first().map_or(0, Vec::len);
            let mut times = Vec::new();
            for j in 0..points {
                if per.iter().any(|r| r[j].1) {
                    continue;
                }
                times.extend(per.iter().map(|r| r[j].0));
            }
            let (settle, _) = slowest_settled(times);
            let ms = step_duration_ms(settle, self.opt.safety, self.plate.modes[k].ramp_ms);
            worst = worst.max(u64::from(ms));
        }
        worst
    }
}

/// The plan for several parts at once (one for a single part): one sequence that brings each
/// part to one orientation of its own, `goals[i]` for part `i` when given. The whole-plate
/// check drops each part alone ([`OnPlate::Alone`]); [`plan_parts_progress`] takes where the
/// parts come from.
pub fn plan_parts(
    parts: &[Part],
    plate: &PlateModel,
    opt: &PlanOptions,
    goals: &[Option<f64>],
) -> Result<Synthesis, PlanFailure> {
    plan_parts_progress(parts, OnPlate::Alone, plate, opt, goals, &crate::progress::Silent)
}

/// [`plan_parts`] of `parts` that lie on the plate as `on` says (the faces of given part
/// files: [`OnPlate::Faces`], as `chladni plan` plans them), calling `progress` as the maps
/// are made (and made again for the fallback).
pub fn plan_parts_progress(
    parts: &[Part],
    on: OnPlate<'_>,
    plate: &PlateModel,
    opt: &PlanOptions,
    goals: &[Option<f64>],
    progress: &dyn Progress,
) -> Result<Synthesis, PlanFailure> {
    let problems = parts
        .iter()
        .map(|p| Problem::with_progress(p, plate, opt, progress))
        .collect::<Result<Vec<_>, _>>()?;
    let parts: Vec<&Part> = parts.iter().collect();
    // Whole-plate plans on grid modes are refined by the drops they do not hold from.
    let plan =
        |problems: &[Problem]| planned_or_fallback(&parts, plate, opt, problems, goals, progress);
    super::whole::refined(&parts, on, plate, opt, problems, &plan)
}

/// [`plan_parts_with`] over `problems`, then over the [`super::fallback`] maps when that gives
/// no plan.
fn planned_or_fallback(
    parts: &[&Part],
    plate: &PlateModel,
    opt: &PlanOptions,
    problems: &[Problem],
    goals: &[Option<f64>],
    progress: &dyn Progress,
) -> Result<Synthesis, PlanFailure> {
    let refs: Vec<&Problem> = problems.iter().collect();
    let first = plan_parts_with(parts, plate, opt, &refs, goals);
    match (first, super::fallback(opt)) {
        (Err(e), Some(kind)) if super::falls_back(&e, plate, opt) => {
            let other = PlanOptions { maps: kind, ..*opt };
            progress.stage("dynamic step maps (the static ones gave no plan)", 0);
            let remapped = parts
                .iter()
                .zip(problems)
                .map(|(p, pr)| super::remapped(p, plate, opt, pr, kind))
                .collect::<Result<Vec<_>, _>>()?;
            let refs: Vec<&Problem> = remapped.iter().collect();
            plan_parts_with(parts, plate, &other, &refs, goals)
                .map_err(|second| super::reported(e, second, opt))
        }
        (other, _) => other,
    }
}

/// [`plan_parts`] with the maps already built.
pub(crate) fn plan_parts_with(
    parts: &[&Part],
    plate: &PlateModel,
    opt: &PlanOptions,
    problems: &[&Problem],
    goals: &[Option<f64>],
) -> Result<Synthesis, PlanFailure> {
    let bodies: Vec<Body> =
        parts.iter().map(|p| Body::with_samples(p, PLANNER_BODY_SAMPLES)).collect();
    let mut durations = Durations { bodies: &bodies, plate, problems, opt, memo: HashMap::new() };
    let mut forbidden: Vec<Vec<(f64, usize)>> = vec![Vec::new(); parts.len()];
    // Search, then check every straight-node transition of the plan dynamically (approaching
    // the node from either side, from afar and from half-way across); a transition the
    // simulation does not confirm is ruled out and the search repeated.
    let (path, reachable, max_steps) = loop {
        let search = Search::new(problems, opt, &forbidden);
        let found = find(&search, parts, plate, opt, goals, &mut durations)?;
        deadline::check(opt.deadline, || "the dynamic check of the plan found".into())?;
        let bad: Vec<Vec<(f64, usize)>> = (0..parts.len())
            .map(|i| unconfirmed(&bodies[i], plate, problems[i], &found.0, i, opt))
            .collect();
        if bad.iter().all(Vec::is_empty) || forbidden.iter().map(Vec::len).sum::<usize>() > 200 {
            break found;
        }
        for (f, b) in forbidden.iter_mut().zip(bad) {
            f.extend(b);
        }
    };
    deadline::check(opt.deadline, || "the step durations".into())?;
    let steps = planned_steps(&bodies, plate, problems, &path, opt);
    let mut per_part = Vec::new();
    for (i, part) in parts.iter().enumerate() {
        let period = problems[i].period;
        let own: Vec<(usize, Vec<f64>)> = path.iter().map(|(k, a)| (*k, a[i].clone())).collect();
        per_part.push(PartPlan {
            name: part.name.clone(),
            period_deg: period,
            final_orientation_deg: own.last().map_or(0.0, |s| s.1[0]).rem_euclid(period),
            final_position_mm: position::fixed_position(part, plate, period, &own),
            goal_deg: goals.get(i).copied().flatten(),
            reachable_deg: reachable[i].clone(),
            after: own.into_iter().map(|s| s.1).collect(),
        });
    }
    let first = per_part[0].clone();
    let mut syn = Synthesis {
        steps,
        final_orientation_deg: first.final_orientation_deg,
        period_deg: first.period_deg,
        final_position_mm: first.final_position_mm,
        feed: None,
        goal_deg: first.goal_deg,
        reachable_deg: first.reachable_deg,
        max_steps,
        position_check_mm: None,
        whole_plate: None,
        parts: if parts.len() > 1 { per_part } else { Vec::new() },
    };
    if opt.fix_position || opt.goal_pos_mm.is_some() {
        confirm_position(parts[0], plate, &mut syn)?;
    }
    Ok(syn)
}

/// Runs the plan from spread starts and checks the predicted position (the model's
/// projection argument, [`position`], checked against the motion it abstracts).
fn confirm_position(
    part: &Part,
    plate: &PlateModel,
    syn: &mut Synthesis,
) -> Result<(), PlanFailure> {
    let Some(p) = syn.final_position_mm else { return Ok(()) };
    let worst = position::simulated_position_error(part, plate, syn, p);
    syn.position_check_mm = Some(worst);
    if worst > POSITION_CONFIRM_MM {
        return Err(PlanFailure::PositionNotConfirmed {
            part: part.name.clone(),
            predicted_mm: p,
            worst_mm: worst,
        });
    }
    Ok(())
}

/// The transitions (orientation, mode) of part `i` along `path` that the simulation does not
/// confirm.
fn unconfirmed(
    body: &Body,
    plate: &PlateModel,
    problem: &Problem,
    path: &Path,
    i: usize,
    opt: &PlanOptions,
) -> Vec<(f64, usize)> {
    let mut bad = Vec::new();
    for w in path.windows(2) {
        let (k, mode) = (w[1].0, &plate.modes[w[1].0]);
        // Simulated maps (curved, grid and rim nodes) are measured already.
        if !matches!(mode.node, Node::Line { .. }) || problem.maps[k].sampled.is_some() {
            continue;
        }
        for &u in &w[0].1[i] {
            let Ok(vs) = problem.maps[k].apply_all(u, opt.margin_deg) else { continue };
            if !confirm_any(body, mode, plate, u, &vs, problem.period) {
                bad.push((u, k));
            }
        }
    }
    bad
}

/// The plan's steps with simulated durations: the longest settle over the parts.
fn planned_steps(
    bodies: &[Body],
    plate: &PlateModel,
    problems: &[&Problem],
    path: &Path,
    opt: &PlanOptions,
) -> Vec<PlannedStep> {
    let mut steps = Vec::new();
    let mut before: Vec<Vec<f64>> = vec![Vec::new(); bodies.len()];
    for (k, after) in path {
        let mode = &plate.modes[*k];
        let settle = if opt.durations {
            (0..bodies.len())
                .map(|i| {
                    let starts = if steps.is_empty() {
                        first_starts(problems[i], *k, opt.margin_deg)
                    } else {
                        before[i].clone()
                    };
                    settle_time(&bodies[i], mode, plate, &starts)
                })
                .max_by(|a, b| a.settle_s.total_cmp(&b.settle_s))
                .unwrap_or_default()
        } else {
            Settle::default()
        };
        let duration_ms = if opt.durations {
            step_duration_ms(settle.settle_s, opt.safety, mode.ramp_ms)
        } else {
            1000
        };
        steps.push(PlannedStep {
            mode: *k,
            before: before[0].clone(),
            after: after[0].clone(),
            duration_ms,
            settle,
            margin: super::margin::margin_of(
                &problems[0].maps[*k],
                opt.margin_deg,
                opt.margin_auto,
            ),
        });
        before = after.clone();
    }
    steps
}

/// Reach, then select; the failures named.
fn find(
    search: &Search<'_>,
    parts: &[&Part],
    plate: &PlateModel,
    opt: &PlanOptions,
    goals: &[Option<f64>],
    durations: &mut Durations<'_>,
) -> Result<(Path, Vec<Vec<f64>>, usize), PlanFailure> {
    let reach = search.reach();
    reach.in_time(opt)?;
    let Some(shortest) = reach.shortest else {
        return Err(no_plan(search, &reach, parts, durations.problems, opt));
    };
    let max_steps = shortest + opt.extra_steps;
    let target = Target {
        deg: goals.to_vec(),
        tol_deg: opt.margin_deg.max(0.01),
        fix_position: opt.fix_position,
        pos_mm: opt.goal_pos_mm,
    };
    let reachable: Vec<Vec<f64>> =
        (0..parts.len()).map(|i| reachable_of(search, &reach, i, target.tol_deg)).collect();
    let mut cost = |k: usize, before: Option<&State>| match opt.minimize {
        Minimize::Steps => 1,
        Minimize::Time => durations.step_ms(k, before.map(|s| search.degrees(s)).as_deref()),
    };
    let mut position = |path: &Path| -> Vec<Option<[f64; 2]>> {
        parts
            .iter()
            .enumerate()
            .map(|(i, part)| {
                let own: Vec<(usize, Vec<f64>)> =
                    path.iter().map(|(k, a)| (*k, a[i].clone())).collect();
                position::fixed_position(part, plate, search.unis[i].period, &own)
            })
            .collect()
    };
    match search.select(&target, max_steps, &mut cost, &mut position) {
        Some(path) => Ok((path, reachable, max_steps)),
        None => {
            deadline::check(opt.deadline, || "choosing among the plans found".into())?;
            Err(unmet(search, &reach, &target, parts, max_steps))
        }
    }
}

/// Part `i`'s reachable final orientations (sorted, merged within `tol`).
fn reachable_of(search: &Search<'_>, reach: &Reach, i: usize, tol: f64) -> Vec<f64> {
    merged(reach.finals.iter().map(|f| f[i]).collect(), tol, search.unis[i].period)
}

/// Orientations (deg, mod `p`) sorted, each kept only when it is more than `tol` from the one
/// kept before it (and the last from the first, around the circle): orientations the goal
/// test cannot tell apart are one reachable orientation (89.99° and 90.00° are one).
fn merged(mut v: Vec<f64>, tol: f64, p: f64) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    let mut out: Vec<f64> = Vec::with_capacity(v.len());
    for x in v {
        if out.last().is_none_or(|&last| cdist(last, x, p) > tol) {
            out.push(x);
        }
    }
    if out.len() > 1 && cdist(out[0], out[out.len() - 1], p) <= tol {
        out.pop();
    }
    out
}

/// Why no plan met the target: a goal orientation out of reach (with what is reachable), or
/// no plan that fixes the position.
fn unmet(
    search: &Search<'_>,
    reach: &Reach,
    target: &Target,
    parts: &[&Part],
    max_steps: usize,
) -> PlanFailure {
    let periods: Vec<f64> = search.unis.iter().map(|u| u.period).collect();
    for (i, goal) in target.deg.iter().enumerate() {
        let Some(goal) = *goal else { continue };
        // The other parts' goals, within the tolerance.
        let others: Vec<Option<f64>> =
            target.deg.iter().enumerate().map(|(j, g)| if j == i { None } else { *g }).collect();
        let reachable: Vec<f64> = reach
            .finals
            .iter()
            .filter(|f| Target { deg: others.clone(), ..target.clone() }.meets(f, &periods))
            .map(|f| f[i])
            .collect();
        let reachable = merged(reachable, target.tol_deg, periods[i]);
        if reachable.iter().any(|&t| cdist(t, goal, periods[i]) <= target.tol_deg) {
            continue;
        }
        let nearest = reachable
            .iter()
            .copied()
            .min_by(|a, b| cdist(*a, goal, periods[i]).total_cmp(&cdist(*b, goal, periods[i])));
        return PlanFailure::GoalUnreachable {
            part: parts[i].name.clone(),
            goal_deg: goal,
            period_deg: periods[i],
            tol_deg: target.tol_deg,
            max_steps,
            reachable_deg: reachable,
            nearest_deg: nearest,
        };
    }
    PlanFailure::PositionNotFixed {
        part: parts[0].name.clone(),
        max_steps,
        tol_mm: POSITION_TOL_MM,
    }
}

/// No plan at all: for one part the set search's explanation; for several, a part that has
/// no plan even alone, or the parts whose orientations the closest state keeps apart.
fn no_plan(
    search: &Search<'_>,
    reach: &Reach,
    parts: &[&Part],
    problems: &[&Problem],
    opt: &PlanOptions,
) -> PlanFailure {
    if parts.len() == 1 {
        let why = problems[0].explain_reach(search, reach, opt);
        return PlanFailure::NoPlan(why + &reach.bound_note(opt));
    }
    for (i, problem) in problems.iter().enumerate() {
        let alone = Search::new(&[*problem], opt, &[]);
        let r = alone.reach();
        if r.shortest.is_none() {
            let why = problem.explain_reach(&alone, &r, opt);
            return PlanFailure::NoPlan(format!("part {}: {why}", parts[i].name));
        }
    }
    let closest = reach.nodes.iter().min_by_key(|n| n.0.iter().map(Vec::len).sum::<usize>());
    let apart = closest
        .map(|n| {
            search
                .degrees(&n.0)
                .into_iter()
                .enumerate()
                .filter(|(_, d)| d.len() > 1)
                .map(|(i, d)| (parts[i].name.clone(), d, search.unis[i].period))
                .collect()
        })
        .unwrap_or_default();
    PlanFailure::PartsApart { apart, searched: reach.nodes.len(), max_steps: None }
}

#[cfg(test)]
mod tests {
    use super::merged;

    #[test]
    fn reachable_orientations_merge_within_the_tolerance() {
        assert_eq!(merged(vec![90.0, 89.99, 30.0], 3.0, 180.0), [30.0, 89.99]);
        // Around the circle: 179.5° and 0.5° are 1° apart.
        assert_eq!(merged(vec![0.5, 179.5, 90.0], 3.0, 180.0), [0.5, 90.0]);
        assert_eq!(merged(vec![10.0, 14.0], 3.0, 360.0), [10.0, 14.0]);
        assert!(merged(Vec::new(), 3.0, 360.0).is_empty());
    }
}
