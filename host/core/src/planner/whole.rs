//! Whole-plate plans on simulated (grid) modes, refined by counterexamples (docs/plan.md,
//! "Whole-plate plans on grid modes").
//!
//! A grid mode's map is simulated from a handful of start points ([`super::map_starts`]), so
//! a plan found on it may not hold from where the maps never looked. After the search finds a
//! plan, it is run as `chladni simulate` runs it, for every part of the plan (each face of a
//! part that flips is a part here): one part, or the faces of one part (never on the plate
//! together), alone from a fixed grid of drop points over the whole plate ([`drops`]); parts
//! of several part files together, with contacts, from as many seeded random drops
//! ([`TOGETHER_SEED`]). Which planned parts come from which part file the caller says
//! ([`OnPlate`]): the planner does not guess it from names or outlines. The drop points whose runs end elsewhere become extra start points of
//! that part's maps of the plan's grid modes, and the search runs again, at most
//! [`PlanOptions::refine_rounds`] times. The answer is a plan confirmed from every drop of
//! every part or [`PlanFailure::NotWholePlate`] for the part that fails most: which share of
//! its drops no plan holds from, where they lie and how they end, with a feed region that
//! avoids them.

use crate::model::angle::wrap_deg;
use crate::motion::body::PLANNER_BODY_SAMPLES;
use rayon::prelude::*;

use super::edges::{PlateEdge, on_plate_edge};
use super::maps::sampled_map_from;
use super::{PlanFailure, PlanOptions, Problem, Synthesis, deadline};
use crate::model::angle::cdist;
use crate::model::part::Part;
use crate::model::part::mirror::{Face, FaceOf};
use crate::model::plate::{Node, PlateModel, on_plate};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::bulk::{Drop, run_drops};
use crate::motion::field::FieldModel;
use crate::motion::shape::Pieces;
use crate::motion::steps::SimStep;
use crate::motion::steps::simulate_plan;

/// Drop points across the plate: columns (along x) and rows (along y) of the grid.
pub const DROP_GRID: [usize; 2] = [6, 4];
/// Start orientations per drop point.
pub const DROP_TURNS: usize = 2;
/// A drop counts as held when it ends within this of the predicted orientation (deg), as
/// `chladni simulate`'s default `--tol-deg`.
pub(crate) const DROP_TOL_DEG: f64 = 5.0;
/// The default of [`PlanOptions::refine_rounds`] in `chladni plan` (`--refine-rounds`).
pub const REFINE_ROUNDS: usize = 3;
/// New start points added per round at most (each costs a map's runs per mode).
const NEW_STARTS_PER_ROUND: usize = 6;
/// Seed of the random drops of parts on the plate together (the same drops every round).
pub const TOGETHER_SEED: u64 = 1;

/// Why no plan holds over the whole plate ([`PlanFailure::NotWholePlate`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
        "{part}: no plan holds over the whole plate: of {drops} {}, {failed} ({:.0} %) end \
         elsewhere ({ends}), from x {:.0}–{:.0} mm, y {:.0}–{:.0} mm, after {rounds} of at most \
         {max_rounds} refinement rounds (--refine-rounds){}{}",
        drops_how(self.together),
        100.0 * self.failed as f64 / self.drops.max(1) as f64,
        self.region_mm[0], self.region_mm[2], self.region_mm[1], self.region_mm[3],
        self.capture.as_ref().map(|c| format!("; {c}")).unwrap_or_default(),
        self.feed_mm.map(|f| format!("; the plan held from every drop in x {:.0}–{:.0} mm, y {:.0}–{:.0} mm: \
            try --feed {:.0} {:.0} {:.0} {:.0}", f[0], f[2], f[1], f[3], f[0], f[1], f[2], f[3])).unwrap_or_default()
    )]
pub struct NotWhole {
    /// The part.
    pub part: String,
    /// Drops run over the plate.
    pub drops: usize,
    /// Drops the last plan did not hold from.
    pub failed: usize,
    /// The box of those drop points (mm: x0, y0, x1, y1).
    pub region_mm: [f64; 4],
    /// How they ended (counts by edge, inside, off the plate).
    pub ends: String,
    /// Refinement rounds run.
    pub rounds: usize,
    /// The bound on them ([`PlanOptions::refine_rounds`]).
    pub max_rounds: usize,
    /// The largest block of drop cells the last plan held from (mm: x0, y0, x1, y1), outside
    /// the clamp's capture zone.
    pub feed_mm: Option<[f64; 4]>,
    /// The clamp's capture zone and how many of the failed drops lie in it
    /// ([`super::capture`]; `None`: the plate has none).
    pub capture: Option<super::capture::InZone>,
    /// Whether the drops were those of the parts together (parts of several files, contacts
    /// between them: random drops, [`TOGETHER_SEED`]) rather than the part alone on the grid
    /// of [`drops`].
    pub together: bool,
}

/// What the drops were, after their count: the grid of [`drops`] or the parts together.
fn drops_how(together: bool) -> &'static str {
    if together { "random drops of the parts together" } else { "drops on a grid over the plate" }
}

/// How a drop that the plan does not hold from ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DropEnd {
    /// Against the plate edge at x = 0 (the cantilever's clamp) or another edge.
    Edge(PlateEdge),
    /// Inside the plate, at another orientation (a wrong node, or still on its way).
    Interior,
    /// Off the plate (open edge).
    Lost,
}

/// What a plan's drops over the whole plate gave.
#[derive(Debug, Clone, PartialEq)]
pub struct WholePlate {
    /// Drops run, over every part of the plan.
    pub drops: usize,
    /// Drops that ended at the part's predicted orientation.
    pub held: usize,
    /// Refinement rounds used (0: the first plan held).
    pub rounds: usize,
    /// False when the check could not run: the parts of several part files do not fit on the
    /// plate together (`drops` and `held` are 0; `chladni simulate` refuses the same drops).
    pub checked: bool,
    /// Per part of the plan (each face of a part that flips is one), in the plan's order.
    pub parts: Vec<PartHeld>,
    /// Whether the parts were dropped together (several part files, contacts between them:
    /// random drops) rather than each alone on the grid of [`drops`].
    pub together: bool,
}

/// One part's (or face's) share of [`WholePlate`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PartHeld {
    /// The part's name (`NAME (flipped)` for the other face).
    pub name: String,
    /// Its drops.
    pub drops: usize,
    /// Those that ended at its predicted orientation.
    pub held: usize,
}

impl WholePlate {
    /// The `plan` text after `whole plate  `: the drops held, per part when there are several.
    pub fn describe(&self) -> String {
        if !self.checked {
            return "not checked: the plan's parts do not fit on the plate together; \
                    `chladni simulate` drops them and says so"
                .into();
        }
        let how = drops_how(self.together);
        let per = if self.parts.len() > 1 {
            let each: Vec<String> =
                self.parts.iter().map(|p| format!("{} {}/{}", p.name, p.held, p.drops)).collect();
            format!(": {}", each.join(", "))
        } else {
            String::new()
        };
        format!(
            "held from {} of {} {how} ({} refinement round(s)){per}",
            self.held, self.drops, self.rounds
        )
    }
}

/// One part's drops: how many ran and those the plan does not hold from.
#[derive(Debug, Clone, PartialEq)]
pub struct PartDrops {
    /// Drops run.
    pub drops: usize,
    /// The failed ones.
    pub failed: Failed,
    /// Where every drop started (mm), held or not.
    pub starts: Vec<[f64; 2]>,
}

/// The drops a plan does not hold from: (drop point, start orientation deg, how it ended).
pub type Failed = Vec<([f64; 2], f64, DropEnd)>;

/// The drop grid: [`DROP_GRID`] cell centres, inset by the part's radius, [`DROP_TURNS`]
/// orientations each (deterministic, spread so that neighbouring points differ).
pub fn drops(body: &Body, plate: &PlateModel) -> Vec<([f64; 2], f64)> {
    let [w, h] = plate.size_mm;
    let r = body.radius.min(w / 2.0).min(h / 2.0);
    let [nx, ny] = DROP_GRID;
    let mut out = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            let x = (w * (i as f64 + 0.5) / nx as f64).clamp(r, w - r);
            let y = (h * (j as f64 + 0.5) / ny as f64).clamp(r, h - r);
            for k in 0..DROP_TURNS {
                let turn = 360.0 * k as f64 / DROP_TURNS as f64;
                let th = wrap_deg(17.0 + 53.0 * (i * ny + j) as f64 + turn);
                out.push(([x, y], th));
            }
        }
    }
    out
}

/// Whether a run of the part ending at `e` held (on the plate, within [`DROP_TOL_DEG`] of
/// `(final, period)`); if not, how it ended.
fn held(body: &Body, plate: &PlateModel, e: Pose, lost: bool, pred: (f64, f64)) -> Option<DropEnd> {
    let off = lost || !on_plate(plate.size_mm, [e.x, e.y]);
    let ok = cdist(e.theta.to_degrees(), pred.0, pred.1);
    if !off && ok <= DROP_TOL_DEG {
        return None;
    }
    Some(ending(body, plate, e, off))
}

/// Runs `syn` (one part, or its first) from every drop of [`drops`]: the drops it does not
/// hold from.
pub fn check(body: &Body, plate: &PlateModel, syn: &Synthesis) -> (usize, Failed) {
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let d = check_alone(body, plate, &fields, &syn.sim_steps(), syn.predicted(0));
    (d.drops, d.failed)
}

/// One part alone from every drop of [`drops`] against its prediction `pred`.
fn check_alone(
    body: &Body,
    plate: &PlateModel,
    fields: &[FieldModel],
    steps: &[SimStep],
    pred: (f64, f64),
) -> PartDrops {
    let all = drops(body, plate);
    let failed = all
        .par_iter()
        .filter_map(|&(p, th)| {
            let start = Pose { x: p[0], y: p[1], theta: th.to_radians() };
            let (poses, _, _) = simulate_plan(body, plate, fields, steps, start);
            let e = poses.last().copied().unwrap_or(start);
            held(body, plate, e, false, pred).map(|end| (p, th, end))
        })
        .collect();
    PartDrops { drops: all.len(), failed, starts: all.iter().map(|d| d.0).collect() }
}

/// Which of a plan's parts lie on the plate at once in the whole-plate check: what the caller
/// knows of where each planned part comes from. `chladni plan` knows it ([`Faces::of`]); the
/// planner does not guess it (a part the user named `x (flipped)` is a part of its own).
///
/// [`Faces::of`]: crate::model::part::mirror::Faces::of
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub enum OnPlate<'a> {
    /// Each part alone on the plate, from the grid of [`drops`]: one part, or a library caller
    /// that plans parts without saying where they come from.
    #[default]
    Alone,
    /// `of[i]`: the part file and face planned part `i` comes from, one entry per part
    /// ([`crate::model::part::mirror::faces`]); an `of` of another length than the parts says
    /// nothing, as [`OnPlate::Alone`].
    Faces(&'a [FaceOf]),
}

/// Which of `n` planned parts lie on the plate at once, and whether any do ([`OnPlate`]). The
/// faces of one part file are never on the plate together, so parts of one file run alone
/// (one group each); parts of several files are dropped together, as `chladni simulate` drops
/// them: a group of every face-up entry and, when a part flips, one with its flipped faces
/// instead.
pub fn plate_groups(n: usize, on: OnPlate<'_>) -> (Vec<Vec<usize>>, bool) {
    let alone = || ((0..n).map(|i| vec![i]).collect(), false);
    let OnPlate::Faces(of) = on else { return alone() };
    if of.len() != n || of.iter().all(|o| o.source == of[0].source) {
        return alone();
    }
    let up: Vec<usize> = (0..n).filter(|&i| of[i].face != Some(Face::Flipped)).collect();
    let mut groups = vec![up];
    if of.iter().any(|o| o.face == Some(Face::Flipped)) {
        groups.push((0..n).filter(|&i| of[i].face != Some(Face::Up)).collect());
    }
    (groups, true)
}

/// Every part of `syn` (`bodies[i]` the body of planned part `i`) dropped over the plate as
/// [`plate_groups`] puts them: each part's drops and failures, and whether they were dropped
/// together; `None` when parts of a group do not fit on the plate together.
pub fn check_parts(
    bodies: &[Body],
    on: OnPlate<'_>,
    plate: &PlateModel,
    syn: &Synthesis,
) -> Option<(Vec<PartDrops>, bool)> {
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let steps = syn.sim_steps();
    let (groups, together) = plate_groups(bodies.len(), on);
    let mut out =
        vec![PartDrops { drops: 0, failed: Vec::new(), starts: Vec::new() }; bodies.len()];
    for group in groups {
        if !together {
            let i = group[0];
            out[i] = check_alone(&bodies[i], plate, &fields, &steps, syn.predicted(i));
            continue;
        }
        let on: Vec<&Body> = group.iter().map(|&i| &bodies[i]).collect();
        let pieces: Vec<Pieces> = on.iter().map(|b| Pieces::of(b)).collect();
        let refs: Vec<&Pieces> = pieces.iter().collect();
        let d =
            Drop { bodies: &on, pieces: &refs, plate, fields: &fields, steps: &steps, feed: None };
        let n = DROP_GRID[0] * DROP_GRID[1] * DROP_TURNS;
        let runs = run_drops(&d, n as u32, TOGETHER_SEED, &crate::progress::Silent).ok()?;
        for (&i, t) in group.iter().zip(&runs.per_body) {
            let pred = syn.predicted(i);
            let o = &mut out[i];
            o.drops += t.finals.len();
            o.starts.extend(t.starts.iter().map(|q| [q.x, q.y]));
            for ((q, e), &lost) in t.starts.iter().zip(&t.finals).zip(&t.lost) {
                if let Some(end) = held(&bodies[i], plate, *e, lost, pred) {
                    o.failed.push(([q.x, q.y], q.theta.to_degrees(), end));
                }
            }
        }
    }
    Some((out, together))
}

/// How a failed drop ended at `e`.
fn ending(body: &Body, plate: &PlateModel, e: Pose, off: bool) -> DropEnd {
    if off {
        return DropEnd::Lost;
    }
    if !on_plate_edge(body, plate, e) {
        return DropEnd::Interior;
    }
    let [w, h] = plate.size_mm;
    let d = [(e.x, PlateEdge::Left), (w - e.x, PlateEdge::Right), (e.y, PlateEdge::Bottom)];
    let (_, edge) =
        d.into_iter().fold((h - e.y, PlateEdge::Top), |a, b| if b.0 < a.0 { b } else { a });
    DropEnd::Edge(edge)
}

/// Plans with `plan` over `problems` and refines whole-plate plans on grid modes by
/// counterexamples (see the module doc), the parts on the plate as `on` says; other plans (a
/// feed region, no grid mode, `refine_rounds` 0) are returned as `plan` gives them.
pub(super) fn refined(
    parts: &[&Part],
    on: OnPlate<'_>,
    plate: &PlateModel,
    opt: &PlanOptions,
    mut problems: Vec<Problem>,
    plan: &dyn Fn(&[Problem]) -> Result<Synthesis, PlanFailure>,
) -> Result<Synthesis, PlanFailure> {
    let grid = |k: usize| matches!(plate.modes[k].node, Node::Grid(_));
    let mut syn = plan(&problems)?;
    if opt.refine_rounds == 0 || opt.feed.is_some() || !(0..plate.modes.len()).any(grid) {
        return Ok(syn);
    }
    let bodies: Vec<Body> =
        parts.iter().map(|p| Body::with_samples(p, PLANNER_BODY_SAMPLES)).collect();
    let mut extra: Vec<Vec<Vec<[f64; 2]>>> = vec![vec![Vec::new(); plate.modes.len()]; parts.len()];
    let mut round = 0;
    loop {
        deadline::check(opt.deadline, || {
            format!("{}: whole-plate check, round {round}", names(parts))
        })?;
        let Some((checked, together)) = check_parts(&bodies, on, plate, &syn) else {
            syn.whole_plate = Some(unchecked());
            return Ok(syn);
        };
        if checked.iter().all(|c| c.failed.is_empty()) {
            syn.whole_plate = Some(whole_of(parts, &checked, round, together));
            return Ok(syn);
        }
        // The part that fails most is the one the failure names.
        let worst = (0..parts.len()).max_by_key(|&i| checked[i].failed.len()).unwrap_or(0);
        let fail = |round| {
            let c = &checked[worst];
            let n = not_whole(parts[worst], plate, &bodies[worst], c, round, opt);
            PlanFailure::NotWholePlate(Box::new(NotWhole { together, ..n }))
        };
        let mut modes: Vec<usize> = syn.steps.iter().map(|s| s.mode).filter(|&k| grid(k)).collect();
        modes.sort_unstable();
        modes.dedup();
        let learned: Vec<bool> =
            (0..parts.len()).map(|i| learn(&mut extra[i], &modes, &checked[i].failed)).collect();
        if round == opt.refine_rounds || !learned.contains(&true) {
            return Err(fail(round));
        }
        round += 1;
        for i in (0..parts.len()).filter(|&i| learned[i]) {
            remap(&bodies[i], &parts[i].name, plate, opt, &mut problems[i], &modes, &extra[i])?;
        }
        syn = match plan(&problems) {
            Ok(s) => s,
            Err(e @ PlanFailure::OutOfTime { .. }) => return Err(e),
            Err(_) => return Err(fail(round)),
        };
    }
}

/// The parts' names, for the stage of an out-of-time failure.
fn names(parts: &[&Part]) -> String {
    parts.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join(", ")
}

/// A plan whose parts could not be dropped together (see [`WholePlate::checked`]).
fn unchecked() -> WholePlate {
    WholePlate { drops: 0, held: 0, rounds: 0, checked: false, parts: Vec::new(), together: true }
}

/// The check's answer for a plan every part held in.
fn whole_of(parts: &[&Part], checked: &[PartDrops], rounds: usize, together: bool) -> WholePlate {
    let per: Vec<PartHeld> = parts
        .iter()
        .zip(checked)
        .map(|(p, c)| PartHeld {
            name: p.name.clone(),
            drops: c.drops,
            held: c.drops - c.failed.len(),
        })
        .collect();
    WholePlate {
        drops: per.iter().map(|p| p.drops).sum(),
        held: per.iter().map(|p| p.held).sum(),
        rounds,
        checked: true,
        parts: per,
        together,
    }
}

/// `problem`'s maps of `modes` made again with the extra start points `extra` (per mode).
fn remap(
    body: &Body,
    name: &str,
    plate: &PlateModel,
    opt: &PlanOptions,
    problem: &mut Problem,
    modes: &[usize],
    extra: &[Vec<[f64; 2]>],
) -> Result<(), PlanFailure> {
    for &k in modes {
        deadline::check(opt.deadline, || format!("{name}: refined step map of mode {}", k + 1))?;
        let old = &problem.maps[k];
        let mut map = sampled_map_from(
            body,
            &plate.modes[k],
            plate,
            opt.sim_starts,
            problem.period,
            &extra[k],
        );
        map.evidence = old.evidence;
        problem.maps[k] = map;
    }
    Ok(())
}

/// Adds up to [`NEW_STARTS_PER_ROUND`] failed drop points not yet there to the extra start
/// points of each of `modes`; whether any was new.
fn learn(extra: &mut [Vec<[f64; 2]>], modes: &[usize], failed: &Failed) -> bool {
    let mut any = false;
    for &k in modes {
        let new: Vec<[f64; 2]> =
            failed.iter().map(|d| d.0).filter(|p| !extra[k].contains(p)).collect();
        // Spread over the failed drops (they come column by column), not the first few.
        let stride = new.len().div_ceil(NEW_STARTS_PER_ROUND).max(1);
        for p in new.iter().step_by(stride) {
            if !extra[k].contains(p) {
                extra[k].push(*p);
                any = true;
            }
        }
    }
    any
}

/// The failure after the last round: the share of the drops held, where the others lie and
/// how they ended, and the largest block of drop cells the plan held from as a feed region
/// (the drops of the part alone; [`NotWhole::together`] is the caller's).
fn not_whole(
    part: &Part,
    plate: &PlateModel,
    body: &Body,
    c: &PartDrops,
    rounds: usize,
    opt: &PlanOptions,
) -> NotWhole {
    let (drops, failed) = (c.drops, &c.failed);
    let count = |f: &dyn Fn(DropEnd) -> bool| failed.iter().filter(|d| f(d.2)).count();
    let mut ends = Vec::new();
    for edge in [PlateEdge::Left, PlateEdge::Right, PlateEdge::Bottom, PlateEdge::Top] {
        let c = count(&|e| e == DropEnd::Edge(edge));
        if c > 0 {
            ends.push(format!("{c} against the {} edge", edge.name()));
        }
    }
    for (what, end) in [
        (
            "inside the plate at another orientation (on another node, or still moving when the plan ended)",
            DropEnd::Interior,
        ),
        ("off the plate", DropEnd::Lost),
    ] {
        let c = count(&|e| e == end);
        if c > 0 {
            ends.push(format!("{c} {what}"));
        }
    }
    let xs = failed.iter().map(|d| d.0[0]);
    let ys = failed.iter().map(|d| d.0[1]);
    let span = |v: &mut dyn Iterator<Item = f64>| {
        v.fold([f64::INFINITY, f64::NEG_INFINITY], |a, x| [a[0].min(x), a[1].max(x)])
    };
    let (sx, sy) = (span(&mut xs.clone()), span(&mut ys.clone()));
    let zone = super::capture::zone(plate, part);
    let mut feed_mm = held_block(body, plate, &c.starts, failed);
    if let Some(z) = &zone {
        feed_mm = feed_mm.and_then(|b| z.clip(plate, b));
    }
    let capture = zone.map(|z| {
        let failed_in = failed.iter().filter(|d| z.contains(plate, d.0)).count();
        super::capture::InZone::new(z, plate, failed_in, failed.len())
    });
    NotWhole {
        part: part.name.clone(),
        drops,
        failed: failed.len(),
        region_mm: [sx[0], sy[0], sx[1], sy[1]],
        ends: ends.join(", "),
        rounds,
        max_rounds: opt.refine_rounds,
        feed_mm,
        capture,
        together: false,
    }
}

/// The largest rectangle of [`DROP_GRID`] cells each holding a drop (of `starts`) and no failed
/// drop (mm: x0, y0, x1, y1), if any cell held: random drops (the parts together) can leave a
/// cell empty, and a cell no drop started in is not one the plan held from.
fn held_block(
    body: &Body,
    plate: &PlateModel,
    starts: &[[f64; 2]],
    failed: &Failed,
) -> Option<[f64; 4]> {
    let [nx, ny] = DROP_GRID;
    let [w, h] = plate.size_mm;
    let cell = |p: [f64; 2]| {
        let i = ((p[0] / w * nx as f64) as usize).min(nx - 1);
        let j = ((p[1] / h * ny as f64) as usize).min(ny - 1);
        (i, j)
    };
    let bad: Vec<(usize, usize)> = failed.iter().map(|d| cell(d.0)).collect();
    let tried: Vec<(usize, usize)> = starts.iter().map(|&p| cell(p)).collect();
    let held = |i: usize, j: usize| tried.contains(&(i, j)) && !bad.contains(&(i, j));
    let mut best: Option<(usize, [usize; 4])> = None;
    for i0 in 0..nx {
        for i1 in i0..nx {
            for j0 in 0..ny {
                for j1 in j0..ny {
                    let clean = (i0..=i1).all(|i| (j0..=j1).all(|j| held(i, j)));
                    let area = (i1 - i0 + 1) * (j1 - j0 + 1);
                    if clean && best.is_none_or(|b| area > b.0) {
                        best = Some((area, [i0, j0, i1, j1]));
                    }
                }
            }
        }
    }
    let r = body.radius.min(w / 2.0).min(h / 2.0);
    best.map(|(_, [i0, j0, i1, j1])| {
        let x = |i: usize| (w * i as f64 / nx as f64).clamp(r, w - r);
        let y = |j: usize| (h * j as f64 / ny as f64).clamp(r, h - r);
        [x(i0), y(j0), x(i1 + 1), y(j1 + 1)]
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::part::Part;

    fn plate() -> PlateModel {
        let text = "[plate]\nname = \"t\"\nsize_mm = [300.0, 200.0]\n[[mode]]\nname = \"a\"\n\
                    freq_hz = 50.0\namplitude = 1.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n";
        PlateModel::parse(text, "t").unwrap()
    }

    fn body() -> Body {
        let outline = vec![[-20.0, -5.0], [20.0, -5.0], [20.0, 5.0], [-20.0, 5.0]];
        Body::new(&Part::new("r".into(), outline, Vec::new()).unwrap())
    }

    #[test]
    fn the_drop_grid_covers_the_plate_inset_by_the_radius() {
        let (b, p) = (body(), plate());
        let d = drops(&b, &p);
        assert_eq!(d.len(), DROP_GRID[0] * DROP_GRID[1] * DROP_TURNS);
        assert!(d.iter().all(|(q, _)| q[0] >= b.radius && q[0] <= 300.0 - b.radius));
        assert!(d.iter().all(|(q, _)| q[1] >= b.radius && q[1] <= 200.0 - b.radius));
        assert_eq!(drops(&b, &p), d, "deterministic");
    }

    #[test]
    fn the_held_block_avoids_every_failed_cell() {
        let (b, p) = (body(), plate());
        // Failures in the first column (x < 50 mm): the block is the other five columns.
        let failed: Failed = vec![
            ([25.0, 25.0], 0.0, DropEnd::Edge(PlateEdge::Left)),
            ([25.0, 175.0], 0.0, DropEnd::Interior),
        ];
        let starts: Vec<[f64; 2]> = drops(&b, &p).iter().map(|d| d.0).collect();
        let f = held_block(&b, &p, &starts, &failed).unwrap();
        assert_eq!(f, [50.0, b.radius, 300.0 - b.radius, 200.0 - b.radius]);
        assert_eq!(held_block(&b, &p, &starts, &Vec::new()).unwrap()[0], b.radius);
        // One failure in every cell: no block.
        let all: Failed = drops(&b, &p).into_iter().map(|(q, t)| (q, t, DropEnd::Lost)).collect();
        assert!(held_block(&b, &p, &starts, &all).is_none());
        // A cell no drop started in is not held: drops in the last column only, every one
        // failed but one, give that one's cell, not the empty rest of the plate.
        let last: Vec<[f64; 2]> = starts.iter().copied().filter(|q| q[0] > 250.0).collect();
        let failed: Failed =
            last.iter().filter(|&&q| q != last[0]).map(|&q| (q, 0.0, DropEnd::Interior)).collect();
        let f = held_block(&b, &p, &last, &failed).unwrap();
        assert_eq!(f, [250.0, b.radius, 300.0 - b.radius, 50.0]);
    }

    #[test]
    fn learning_adds_spread_new_points_and_says_when_none_is_new() {
        let failed: Failed = (0..12).map(|i| ([i as f64, 0.0], 0.0, DropEnd::Interior)).collect();
        let mut extra = vec![Vec::new(); 2];
        assert!(learn(&mut extra, &[1], &failed));
        assert!(extra[0].is_empty());
        assert_eq!(extra[1].len(), NEW_STARTS_PER_ROUND);
        assert_eq!(extra[1][1], [2.0, 0.0], "every other one of twelve");
        assert!(learn(&mut extra, &[1], &failed));
        assert_eq!(extra[1].len(), 12);
        assert!(!learn(&mut extra, &[1], &failed), "nothing new to learn");
    }
}
