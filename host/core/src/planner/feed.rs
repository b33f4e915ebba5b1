//! Feed-region planning: plans for parts that arrive at a known place (a chute).
//!
//! On plates with several curved node lines (free plates, a hinged rod's elastic modes) where a
//! part comes to rest depends on where it started, not only on its orientation, so the
//! orientation-set search of [`super::Problem`] sees ambiguity everywhere. When parts are fed
//! into a known rectangle, the planner can instead track poses:
//! 1. **Starts.** An n × n grid of centroid positions over the feed region × `starts`
//!    orientations (offset 0.3 of a step off 0°, as [`super::sampled_map`] does).
//! 2. **Search.** Breadth-first over mode sequences up to `depth` steps. Applying a mode
//!    simulates every tracked pose to rest (limit 5000 T₀, as for simulated maps); a run that
//!    does not rest, falls off an open edge or ends against a clamped rim kills the sequence
//!    (a rest against a free wall counts: the rim is an orienting feature). Rest poses are
//!    clustered (1° mod the period, 2 mm) and only one pose per cluster is tracked further; a
//!    sequence whose pose set falls into the same coarse cells (2°, 4 mm) as one already seen
//!    is pruned.
//! 3. **Success.** Every tracked pose within `tol_deg` of one orientation (mod the period).
//!    Each such sequence of the shortest length is confirmed from scratch: all starts tracked
//!    without clustering, durations from their settle times
//!    (× safety + ramp, as [`super::plan_with`]), then the plan run as the simulator runs it
//!    (fixed durations, [`simulate_plan`](crate::motion::steps::simulate_plan)) from interleaved starts (grid shifted half a cell,
//!    orientations half a step; and from the tracked starts again when some lingered and
//!    were left out of the durations); every end must lie within the margin of the
//!    predicted orientation. The fastest confirmed sequence wins; the candidates are redone
//!    best first, so slower ones stop once they outlast it (`feed::candidates::confirm`).
//!
//! **Several parts** ([`plan_parts`]; in practice the two faces of a part that flips,
//! docs/plan.md "Both faces") are tracked together through the same sequences, each part from
//! its own starts in the region (they are never on the plate at once): a sequence succeeds when
//! every part's poses end within `tol_deg` of one orientation of its own, and the confirmation
//! checks every part against its own prediction. A search that brings one part there but not
//! another fails naming the part left apart ([`PlanFailure::PartsApart`]).

use crate::model::angle::circular_mean;
use crate::motion::body::PLANNER_BODY_SAMPLES;
use std::collections::{HashMap, HashSet};

use crate::progress::Progress;
use rayon::prelude::*;

use super::capture::{clamped_rims, touches};
use super::edges::PlateEdge;
use super::options::FeedSearch;
use super::{PlanFailure, PlanOptions, Synthesis, plan_period};
use crate::model::angle::cdist;
use crate::model::part::Part;
use crate::model::plate::{PlateModel, on_plate};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::field::FieldModel;
use crate::motion::integrate::REST_LIMIT_T0;
use crate::motion::integrate::SimParams;

pub use crate::model::feed_region::FeedRegion;

mod candidates;
mod twins;
use candidates::confirm;
use twins::twins;

/// The largest `--max-steps`: sequences grow as (modes − 1)^depth.
pub const MAX_DEPTH: usize = 8;

/// What every stage of one feed-region search reads: the options, the region, and the names
/// of the parts (a part and its flipped face, or the parts of one plan).
#[derive(Clone, Copy)]
pub(crate) struct Context<'a> {
    pub(crate) opt: &'a PlanOptions,
    pub(crate) region: &'a FeedRegion,
    pub(crate) names: &'a [&'a str],
}

/// The starts a candidate is confirmed from: those its poses are tracked from, and the
/// interleaved ones its finished plan is checked from.
#[derive(Clone, Copy)]
pub(crate) struct Starts<'a> {
    pub(crate) tracked: &'a [Tagged],
    pub(crate) verify: &'a [Tagged],
}

/// What the confirmation of a feed-region plan measured.
#[derive(Debug, Clone, PartialEq)]
pub struct FeedCheck {
    /// The region.
    pub region: FeedRegion,
    /// Start poses tracked.
    pub starts: usize,
    /// Start poses the finished plan was run from with its fixed step durations: the
    /// interleaved ones, and the tracked ones again when some lingered near an unstable rest
    /// (their settle times are left out of the durations).
    pub checked: usize,
    /// Largest final orientation error of those runs and of the tracked poses at rest (deg,
    /// mod the period).
    pub worst_error_deg: f64,
    /// Mode sequences the search found but the confirmation rejected (as far as it redid
    /// them: a candidate it stopped redoing once slower than the plan is not counted).
    pub rejected: usize,
}

/// Start poses: `n` × `n` positions at fractions `frac(i)` of the region, `m` orientations
/// at `(j + shift)` steps.
fn poses(
    region: &FeedRegion,
    body: &Body,
    plate: &PlateModel,
    (n, frac): (usize, &dyn Fn(usize) -> f64),
    (m, shift): (usize, f64),
) -> Vec<Pose> {
    let mut out = Vec::with_capacity(n * n * m);
    for i in 0..n {
        for j in 0..n {
            let p = region.at(frac(i), frac(j), body.radius, plate);
            for k in 0..m {
                let theta = ((k as f64 + shift) * 360.0 / m as f64).to_radians();
                out.push(Pose { x: p[0], y: p[1], theta });
            }
        }
    }
    out
}

/// The tracked starts: a grid including the region's corners (its centre for n = 1).
fn tracked_starts(
    region: &FeedRegion,
    body: &Body,
    plate: &PlateModel,
    s: &FeedSearch,
) -> Vec<Pose> {
    let n = s.points.max(1);
    let frac = |i: usize| if n == 1 { 0.5 } else { i as f64 / (n - 1) as f64 };
    poses(region, body, plate, (n, &frac), (s.starts.max(1), 0.3))
}

/// Starts between the tracked ones: the grid shifted half a cell, orientations half a step.
fn interleaved_starts(
    region: &FeedRegion,
    body: &Body,
    plate: &PlateModel,
    s: &FeedSearch,
) -> Vec<Pose> {
    let n = s.points.max(1) + 1;
    let frac = |i: usize| (i as f64 + 0.5) / n as f64;
    poses(region, body, plate, (n, &frac), (s.starts.max(1), 0.8))
}

/// What a run to rest from one pose under one mode gave.
#[derive(Debug, Clone, Copy)]
struct Outcome {
    /// Where the run stopped.
    pose: Pose,
    /// Settle time (s).
    settle_s: f64,
    /// When it stopped (s).
    t_end: f64,
    /// Came to rest within 5000 T₀.
    rested: bool,
    /// Fell off an open edge.
    lost: bool,
}

/// A tracked pose: the index of its part (face) and the pose.
type Tagged = (usize, Pose);

/// A (part, mode, pose) triple as a memo key: the same pose bit for bit.
type Key = (usize, usize, [u64; 3]);

fn key(k: usize, (i, q): Tagged) -> Key {
    (i, k, [q.x.to_bits(), q.y.to_bits(), q.theta.to_bits()])
}

/// The parts, the plate and its fields: simulates one run (shared by the worker threads).
struct Sim<'a> {
    bodies: Vec<Body>,
    plate: &'a PlateModel,
    fields: Vec<FieldModel>,
    /// Each part's period (deg).
    periods: Vec<f64>,
    /// The plate's clamped rims ([`clamped_rims`]).
    clamped: Vec<PlateEdge>,
}

impl Sim<'_> {
    /// Settings of a run under mode `k` stopped at `t_limit` (s): the mode's own speed, as
    /// `simulate_plan` runs a step at the mode's amplitude.
    fn params(&self, k: usize, t_limit: f64) -> SimParams {
        SimParams::under(&self.plate.modes[k], self.plate, t_limit)
    }

    /// 5000 T₀ of mode `k` for part `i`: the limit of a run to rest, as for simulated maps.
    fn rest_limit(&self, i: usize, k: usize) -> f64 {
        let (mode, field) = (&self.plate.modes[k], &self.fields[k]);
        REST_LIMIT_T0 * crate::motion::integrate::t0(self.bodies[i].radius, mode.speed_mm_s, field)
    }

    /// The run under mode `k` from the tagged pose, stopped at `t_limit` or at rest.
    fn run(&self, k: usize, (i, pose): Tagged, t_limit: f64) -> Outcome {
        let run = crate::motion::integrate::run(
            &self.bodies[i],
            &self.fields[k],
            self.params(k, t_limit),
            pose,
        );
        let (pose, settle_s, t_end) = (run.pose, run.settle_s, run.t_end);
        Outcome { pose, settle_s, t_end, rested: run.rested, lost: run.lost }
    }

    /// A run to rest of part `i` that counts: it rested on the plate, in the interior or
    /// against a free wall (the field pushing the part against the rim is an orienting
    /// feature, as the whole-plate check takes it), not against a clamped rim, where every
    /// mode's field fades (φ ≈ a·d²) and the rest is a creep the model cannot place.
    fn ok(&self, i: usize, o: &Outcome) -> bool {
        self.fault(i, o).is_none()
    }

    /// Why a run of part `i` does not count ([`Sim::ok`]), or `None` when it does.
    fn fault(&self, i: usize, o: &Outcome) -> Option<RunFault> {
        if o.lost || !on_plate(self.plate.size_mm, [o.pose.x, o.pose.y]) {
            Some(RunFault::Off)
        } else if !o.rested {
            Some(RunFault::Unsettled)
        } else if touches(&self.clamped, &self.bodies[i], self.plate, o.pose) {
            Some(RunFault::Clamped)
        } else {
            None
        }
    }
}

/// Why a run kills a sequence ([`Sim::fault`]); the failure counts each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RunFault {
    /// Not at rest within 5000 T₀.
    Unsettled = 0,
    /// Fell off an open edge or ended off the plate.
    Off = 1,
    /// At rest against a clamped rim.
    Clamped = 2,
}

/// Simulates parts to rest under the plate's modes, each (part, mode, pose) once: runs are
/// memoised, and the runs a batch still needs are simulated in parallel (`rayon`; results are
/// collected in order, so plans do not depend on the thread count).
struct Tracker<'a> {
    sim: Sim<'a>,
    /// Runs to rest (limit 5000 T₀).
    memo: HashMap<Key, Outcome>,
    /// Runs stopped at a step duration before they rested: (key, duration bits).
    fixed: HashMap<(Key, u64), Pose>,
    /// The runs to rest of `memo` by start cell, for [`Tracker::near`].
    near: HashMap<NearCell, Vec<(Pose, Outcome)>>,
}

/// A start cell of [`Tracker::near`]: (part, mode, 1° of orientation mod the period, 2 mm of x,
/// 2 mm of y).
type NearCell = (usize, usize, i64, i64, i64);

/// The search's levels beyond this reuse a run from a start within the cluster tolerance
/// ([`Tracker::near`]); levels up to it run every tracked pose, so their answers do not depend
/// on how deep the search may go. Four: the default depth before it was 6, so every plan of
/// up to 4 steps is the one found before.
const EXACT_LEVELS: usize = 4;

fn near_cell(k: usize, (i, q): Tagged, period: f64) -> NearCell {
    let th = q.theta.to_degrees().rem_euclid(period);
    (i, k, th.floor() as i64, (q.x / 2.0).floor() as i64, (q.y / 2.0).floor() as i64)
}

impl<'a> Tracker<'a> {
    fn new(bodies: Vec<Body>, plate: &'a PlateModel, periods: Vec<f64>) -> Self {
        let fields = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
        Tracker {
            sim: Sim { bodies, plate, fields, periods, clamped: clamped_rims(plate) },
            memo: HashMap::new(),
            fixed: HashMap::new(),
            near: HashMap::new(),
        }
    }

    /// A run to rest under mode `k` from a start of the same part within 1° (mod its period)
    /// and 2 mm of `q` — the tolerance within which [`cluster`] already lets one pose stand
    /// for others. The first found, cells and runs in a fixed order (the order runs were
    /// simulated in, collected in order), so the search does not depend on the thread count.
    fn near(&self, k: usize, q: Tagged) -> Option<Outcome> {
        let period = self.sim.periods[q.0];
        let (i, _, c, x, y) = near_cell(k, q, period);
        let wrap = (period.ceil() as i64).max(1);
        let close = |p: &Pose| {
            cdist(p.theta.to_degrees(), q.1.theta.to_degrees(), period) < 1.0
                && (p.x - q.1.x).hypot(p.y - q.1.y) < 2.0
        };
        for dc in -1..=1 {
            for dx in -1..=1 {
                for dy in -1..=1 {
                    let cell = (i, k, (c + dc).rem_euclid(wrap), x + dx, y + dy);
                    let runs = self.near.get(&cell).map_or(&[][..], Vec::as_slice);
                    if let Some((_, o)) = runs.iter().find(|(p, _)| close(p)) {
                        return Some(*o);
                    }
                }
            }
        }
        None
    }

    /// Remembers a run to rest (exact memo and start cells).
    fn remember(&mut self, k: usize, q: Tagged, o: Outcome) {
        if self.memo.insert(key(k, q), o).is_none() {
            let cell = near_cell(k, q, self.sim.periods[q.0]);
            self.near.entry(cell).or_default().push((q.1, o));
        }
    }

    /// The run to rest (limit 5000 T₀) of every job (mode, tagged pose), simulating those not
    /// yet memoised in parallel. With `near`, a job without a run of its own takes one from a
    /// start within the cluster tolerance when there is one ([`Tracker::near`]; the search's
    /// levels beyond [`EXACT_LEVELS`] only).
    fn outcomes(&mut self, jobs: &[(usize, Tagged)], near: bool) -> Vec<Outcome> {
        let mut todo: Vec<(usize, Tagged)> = Vec::new();
        let mut queued = HashSet::new();
        let mut borrowed: HashMap<Key, Outcome> = HashMap::new();
        for &(k, q) in jobs {
            if self.memo.contains_key(&key(k, q)) || borrowed.contains_key(&key(k, q)) {
                continue;
            }
            if let Some(o) = near.then(|| self.near(k, q)).flatten() {
                borrowed.insert(key(k, q), o);
            } else if queued.insert(key(k, q)) {
                todo.push((k, q));
            }
        }
        let sim = &self.sim;
        let done: Vec<Outcome> =
            todo.par_iter().map(|&(k, q)| sim.run(k, q, sim.rest_limit(q.0, k))).collect();
        for (&(k, q), o) in todo.iter().zip(done) {
            self.remember(k, q, o);
        }
        jobs.iter()
            .map(|&(k, q)| {
                borrowed.get(&key(k, q)).copied().unwrap_or_else(|| self.memo[&key(k, q)])
            })
            .collect()
    }

    /// Every pose's rest under mode `k`, or `None` when one does not come to rest within
    /// 5000 T₀, falls off or ends against a clamped rim ([`Sim::ok`]).
    fn rests(&mut self, k: usize, poses: &[Tagged]) -> Option<Vec<Outcome>> {
        let jobs: Vec<(usize, Tagged)> = poses.iter().map(|&q| (k, q)).collect();
        let out = self.outcomes(&jobs, false);
        out.iter().zip(poses).all(|(o, q)| self.sim.ok(q.0, o)).then_some(out)
    }

    /// Where each pose is after mode `k` for `duration_s`, as `simulate_plan` runs a step: a
    /// memoised run that rested by then stopped at the same pose (the duration only caps the
    /// last integration step, which it did not reach); others are run with the duration as
    /// their limit, in parallel.
    fn after(&mut self, k: usize, duration_s: f64, poses: &[Tagged]) -> Vec<Tagged> {
        let done = |o: &Outcome| o.rested && o.t_end <= duration_s;
        let fkey = |q: Tagged| (key(k, q), duration_s.to_bits());
        let mut todo: Vec<Tagged> = Vec::new();
        let mut queued = HashSet::new();
        for &q in poses {
            let known =
                self.memo.get(&key(k, q)).is_some_and(done) || self.fixed.contains_key(&fkey(q));
            if !known && queued.insert(fkey(q)) {
                todo.push(q);
            }
        }
        let sim = &self.sim;
        let runs: Vec<Outcome> = todo.par_iter().map(|&q| sim.run(k, q, duration_s)).collect();
        for (q, o) in todo.into_iter().zip(runs) {
            if o.rested && o.t_end < self.sim.rest_limit(q.0, k) {
                // Also the run to rest (the same trajectory).
                self.remember(k, q, o);
            } else {
                self.fixed.insert(fkey(q), o.pose);
            }
        }
        poses
            .iter()
            .map(|&q| match self.memo.get(&key(k, q)) {
                Some(o) if done(o) => (q.0, o.pose),
                _ => (q.0, self.fixed[&fkey(q)]),
            })
            .collect()
    }
}

/// The poses of part `i` among tagged ones.
fn of_part(poses: &[Tagged], i: usize) -> Vec<Pose> {
    poses.iter().filter(|q| q.0 == i).map(|q| q.1).collect()
}

/// Per part: the circular mean orientation of its poses and their largest distance from it
/// ([`spread`]; deg).
fn spreads(poses: &[Tagged], periods: &[f64]) -> Vec<(f64, f64)> {
    periods.iter().enumerate().map(|(i, &p)| spread(&of_part(poses, i), p)).collect()
}

/// The largest of the parts' spreads (deg).
fn worst_spread(poses: &[Tagged], periods: &[f64]) -> f64 {
    spreads(poses, periods).iter().map(|s| s.1).fold(0.0, f64::max)
}

/// Circular mean (mod `period`) of the orientations of `poses` (deg) and the largest distance
/// of one of them from it.
fn spread(poses: &[Pose], period: f64) -> (f64, f64) {
    let mean = circular_mean(poses.iter().map(|q| q.theta.to_degrees()), period);
    let dev = poses.iter().map(|q| cdist(q.theta.to_degrees(), mean, period)).fold(0.0, f64::max);
    (mean, dev)
}

/// Tracked poses closer than this in orientation (deg, mod the period) and [`SAME_POSE_MM`]
/// in position stand for one another in the search ([`cluster`]). Not [`super::cluster`]'s
/// rests (running means of simulated final orientations) nor the goal test's merge of
/// reachable orientations: a representative pose, so that runs are memoised.
const SAME_POSE_DEG: f64 = 1.0;
/// See [`SAME_POSE_DEG`] (mm).
const SAME_POSE_MM: f64 = 2.0;

/// Greedy clustering of rest poses: a pose joins the first cluster of its part whose first
/// pose is within 1° (mod the part's period) and 2 mm; that first pose stands for the cluster.
/// Poses that close end alike under the next mode unless they lie on a basin boundary, which
/// the confirmation (every start tracked, no clustering) catches.
fn cluster(poses: &[Tagged], periods: &[f64]) -> Vec<Tagged> {
    let mut reps: Vec<Tagged> = Vec::new();
    for &(i, q) in poses {
        let near = |&(j, r): &Tagged| {
            j == i
                && cdist(r.theta.to_degrees(), q.theta.to_degrees(), periods[i]) < SAME_POSE_DEG
                && (r.x - q.x).hypot(r.y - q.y) < SAME_POSE_MM
        };
        if !reps.iter().any(near) {
            reps.push((i, q));
        }
    }
    reps
}

/// Coarse cells (part, 2°, 4 mm) of a pose set: sequences reaching the same cells are
/// equivalent.
fn cells(poses: &[Tagged], periods: &[f64]) -> Vec<[i64; 4]> {
    let mut c: Vec<[i64; 4]> = poses
        .iter()
        .map(|&(i, q)| {
            let period = periods[i];
            let th = q.theta.to_degrees().rem_euclid(period);
            [
                i as i64,
                (th / 2.0) as i64 % (period / 2.0).ceil() as i64,
                (q.x / 4.0) as i64,
                (q.y / 4.0) as i64,
            ]
        })
        .collect();
    c.sort_unstable();
    c.dedup();
    c
}

/// Orientations (deg, mod `period`, 1° apart) of a pose set, for [`PlannedStep`].
fn orientations(poses: &[Pose], period: f64) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::new();
    for q in poses {
        let th = q.theta.to_degrees().rem_euclid(period);
        if !out.iter().any(|&o| cdist(o, th, period) < 1.0) {
            out.push(th);
        }
    }
    out.sort_by(f64::total_cmp);
    out.iter().map(|v| (v * 100.0).round() / 100.0).collect()
}

/// Each part's orientations ([`orientations`]) in a tagged pose set.
fn part_orientations(poses: &[Tagged], periods: &[f64]) -> Vec<Vec<f64>> {
    periods.iter().enumerate().map(|(i, &p)| orientations(&of_part(poses, i), p)).collect()
}

/// A partial sequence in the search: its modes and the (clustered) poses it leaves.
struct Node {
    seq: Vec<usize>,
    poses: Vec<Tagged>,
}

/// The closest a sequence came: (orientations left over all parts, the modes, each part's
/// orientations).
type Closest = (usize, Vec<usize>, Vec<Vec<f64>>);

/// Why the search found nothing, for the failure message.
#[derive(Default)]
struct Tally {
    tried: usize,
    dead: usize,
    /// The runs that killed those sequences, by [`RunFault`].
    faults: [usize; 3],
    best: Option<Closest>,
}

impl Tally {
    /// Remembers the sequence leaving the fewest distinct orientations (summed over parts).
    fn note(&mut self, seq: &[usize], poses: &[Tagged], periods: &[f64]) {
        let o = part_orientations(poses, periods);
        let n: usize = o.iter().map(Vec::len).sum();
        if self.best.as_ref().is_none_or(|b| n < b.0) {
            self.best = Some((n, seq.to_vec(), o));
        }
    }
}

/// The search: mode sequences of increasing length whose tracked poses end in one orientation
/// per part.
struct Search<'a> {
    tracker: Tracker<'a>,
    deadline: Option<super::Deadline>,
    seen: HashSet<Vec<[i64; 4]>>,
    tally: Tally,
}

impl Search<'_> {
    /// BFS level `depth`: the children of `level`, and the sequences among them that
    /// succeed; [`PlanFailure::OutOfTime`] when the deadline passes on the way (checked at
    /// every node: a deep level takes minutes). Beyond [`EXACT_LEVELS`] runs may come from
    /// starts within the cluster tolerance ([`Tracker::near`]).
    fn expand(
        &mut self,
        level: &[Node],
        (tol, depth): (f64, usize),
        progress: &dyn Progress,
    ) -> Result<(Vec<Node>, Vec<Node>), PlanFailure> {
        let nm = self.tracker.sim.plate.modes.len();
        let periods = self.tracker.sim.periods.clone();
        let near = depth > EXACT_LEVELS;
        let (mut next, mut found) = (Vec::new(), Vec::new());
        for (i, node) in level.iter().enumerate() {
            super::deadline::check(self.deadline, || {
                format!(
                    "the feed-region search, {depth}-step sequences ({i} of {} extended)",
                    level.len()
                )
            })?;
            // A mode applied twice in a row leaves every part where it rested.
            let modes: Vec<usize> = (0..nm).filter(|&k| node.seq.last() != Some(&k)).collect();
            // Every run this node's children need, at once (in parallel); memoised: the same
            // cluster pose recurs across sequences.
            let jobs: Vec<(usize, Tagged)> =
                modes.iter().flat_map(|&k| node.poses.iter().map(move |&q| (k, q))).collect();
            let outs = self.tracker.outcomes(&jobs, near);
            progress.advance((nm - modes.len()) as u64);
            let n = node.poses.len();
            for (j, &k) in modes.iter().enumerate() {
                progress.advance(1);
                self.tally.tried += 1;
                let runs = &outs[j * n..(j + 1) * n];
                let sim = &self.tracker.sim;
                let faults: Vec<RunFault> =
                    runs.iter().zip(&node.poses).filter_map(|(o, q)| sim.fault(q.0, o)).collect();
                if !faults.is_empty() {
                    self.tally.dead += 1;
                    faults.iter().for_each(|&f| self.tally.faults[f as usize] += 1);
                    continue;
                }
                let rests: Vec<Tagged> =
                    node.poses.iter().zip(runs).map(|(q, o)| (q.0, o.pose)).collect();
                let poses = cluster(&rests, &periods);
                if !self.seen.insert(cells(&poses, &periods)) {
                    continue;
                }
                let seq = [node.seq.as_slice(), &[k]].concat();
                self.tally.note(&seq, &poses, &periods);
                let child = Node { seq, poses };
                if worst_spread(&child.poses, &periods) <= tol {
                    found.push(child);
                } else {
                    next.push(child);
                }
            }
        }
        Ok((next, found))
    }
}

/// A plan for parts fed into `region`: see the module documentation. `progress` follows the
/// search ([`Silent`](crate::progress::Silent) for none).
pub fn plan(
    part: &Part,
    plate: &PlateModel,
    opt: &PlanOptions,
    region: &FeedRegion,
    progress: &dyn Progress,
) -> Result<Synthesis, PlanFailure> {
    plan_parts(std::slice::from_ref(part), plate, opt, region, progress)
}

/// [`plan`] for several parts at once (the two faces of a part that flips: the part and its
/// mirror image, [`Part::mirrored`]): one sequence that brings every part dropped in `region`
/// to one orientation of its own; [`Synthesis::parts`] holds each part's prediction when there
/// are several.
pub fn plan_parts(
    parts: &[Part],
    plate: &PlateModel,
    opt: &PlanOptions,
    region: &FeedRegion,
    progress: &dyn Progress,
) -> Result<Synthesis, PlanFailure> {
    let s = opt.feed_search;
    let periods: Vec<f64> = parts.iter().map(|p| plan_period(p, plate)).collect();
    // The planner's body resolution, as `plan_with`'s settle times (grid nodes integrate along the outline
    // and do not use them).
    let bodies: Vec<Body> =
        parts.iter().map(|p| Body::with_samples(p, PLANNER_BODY_SAMPLES)).collect();
    let tag = |f: &dyn Fn(&Body) -> Vec<Pose>| -> Vec<Tagged> {
        (bodies.iter().enumerate())
            .flat_map(|(i, b)| f(b).into_iter().map(move |q| (i, q)))
            .collect()
    };
    let starts = tag(&|b| tracked_starts(region, b, plate, &s));
    let verify = tag(&|b| interleaved_starts(region, b, plate, &s));
    let names: Vec<&str> = parts.iter().map(|p| p.name.as_str()).collect();
    let tracker = Tracker::new(bodies, plate, periods);
    let mut search =
        Search { tracker, deadline: opt.deadline, seen: HashSet::new(), tally: Tally::default() };
    let (mut starts, mut rejected) = (starts, Vec::new());
    for round in 0..=s.refine {
        let rounds = (round, s.refine);
        let ctx = Context { opt, region, names: &names };
        match search.levels(&starts, &verify, ctx, rounds, progress)? {
            Round::Plan(mut syn) => {
                if let Some(f) = syn.feed.as_mut() {
                    f.rejected += rejected.len();
                }
                return Ok(*syn);
            }
            Round::Refine(why, off) => {
                // The check found starts the tracked ones missed (a basin boundary between
                // them): track those too and search again; memoised runs are reused.
                rejected.extend(why);
                starts.extend(off);
                search.seen.clear();
                search.tally = Tally::default();
            }
            Round::Fail(why, bound) => {
                rejected.extend(why);
                let twins = twins(&mut search, &starts);
                return Err(failure(&search, &rejected, bound, &names, twins.as_deref()));
            }
        }
    }
    unreachable!("the last round never refines")
}

/// How one search over the tracked starts ended.
enum Round {
    /// A confirmed plan.
    Plan(Box<Synthesis>),
    /// Candidates failed the check: the rejections and the checked starts that ended off.
    Refine(Vec<String>, Vec<Tagged>),
    /// No plan: the rejections and how far the search went.
    Fail(Vec<String>, Bound),
}

impl Search<'_> {
    /// Breadth-first over the depths from `starts`: the first depth with a confirmed candidate
    /// gives the plan; a depth whose candidates all fail the check ends the round with the
    /// starts that ended off when refinement rounds are left (`rounds`: this one, the most).
    fn levels(
        &mut self,
        starts: &[Tagged],
        verify: &[Tagged],
        ctx: Context<'_>,
        rounds: (usize, usize),
        progress: &dyn Progress,
    ) -> Result<Round, PlanFailure> {
        let opt = ctx.opt;
        let s = opt.feed_search;
        let nm = self.tracker.sim.plate.modes.len();
        let mut level = vec![Node { seq: Vec::new(), poses: starts.to_vec() }];
        let mut rejected = Vec::new();
        for depth in 1..=s.depth {
            super::deadline::check(opt.deadline, || {
                format!("the feed-region search, {depth}-step sequences")
            })?;
            let what = if rounds.0 == 0 {
                format!("feed plan: {depth}-step sequences")
            } else {
                format!(
                    "feed plan: {depth}-step sequences (refined {}, {} starts)",
                    rounds.0,
                    starts.len()
                )
            };
            progress.stage(&what, (level.len() * nm) as u64);
            let (next, found) = self.expand(&level, (s.tol_deg, depth), progress)?;
            let from = Starts { tracked: starts, verify };
            let (best, why, off) = confirm(&mut self.tracker, &found, from, ctx, progress)?;
            rejected.extend(why);
            if let Some(syn) = best {
                let mut syn = syn;
                if let Some(f) = syn.feed.as_mut() {
                    f.rejected = rejected.len();
                }
                return Ok(Round::Plan(Box::new(syn)));
            }
            if !off.is_empty() && rounds.0 < rounds.1 {
                return Ok(Round::Refine(rejected, off));
            }
            level = next;
            if level.is_empty() {
                return Ok(Round::Fail(rejected, Bound { depth: s.depth, exhausted: Some(depth) }));
            }
        }
        Ok(Round::Fail(rejected, Bound { depth: s.depth, exhausted: None }))
    }
}

/// `1 mode`, `4 modes`.
fn modes(n: usize) -> String {
    if n == 1 { "1 mode".into() } else { format!("{n} modes") }
}

/// How far a failed search went: its step bound (`--max-steps`) and, when it ran out of new
/// pose sets before that, the depth where it did.
#[derive(Debug, Clone, Copy)]
struct Bound {
    depth: usize,
    exhausted: Option<usize>,
}

impl Bound {
    /// What the failure message says about the bound: whether a larger `--max-steps` could
    /// find more.
    fn note(&self) -> String {
        match self.exhausted {
            Some(d) => format!(
                "; every sequence was searched: after {} none reaches a pose set not seen \
                 before, so a larger --max-steps finds nothing more",
                modes(d)
            ),
            None => format!(
                "; the search stopped at {} (--max-steps {}; a larger value searches longer \
                 sequences)",
                modes(self.depth),
                self.depth
            ),
        }
    }
}

/// The failure of a search that found no plan: for one part (or when candidates failed the
/// check), [`PlanFailure::NoPlan`] with [`explain`]; for several, the parts the closest
/// sequence leaves with several orientations ([`PlanFailure::PartsApart`], naming the face
/// that does not get there).
fn failure(
    search: &Search,
    rejected: &[String],
    bound: Bound,
    names: &[&str],
    twins: Option<&str>,
) -> PlanFailure {
    let periods = &search.tracker.sim.periods;
    let t = &search.tally;
    if names.len() > 1
        && rejected.is_empty()
        && let Some((_, _, o)) = &t.best
    {
        let apart: Vec<(String, Vec<f64>, f64)> = (0..names.len())
            .filter(|&i| o[i].len() > 1)
            .map(|i| (names[i].to_string(), o[i].clone(), periods[i]))
            .collect();
        if !apart.is_empty() {
            return PlanFailure::PartsApart {
                apart,
                searched: t.tried,
                max_steps: Some(bound.depth),
            };
        }
    }
    PlanFailure::NoPlan(explain(t, rejected, bound, periods[0], names, twins))
}

fn explain(
    t: &Tally,
    rejected: &[String],
    bound: Bound,
    period: f64,
    names: &[&str],
    twins: Option<&str>,
) -> String {
    let what = if names.len() > 1 { "every part" } else { "every start" };
    let depth = bound.depth;
    let mut msg = format!(
        "no sequence of up to {} (--max-steps {depth}) brings {what} in the feed \
         region to one orientation ({} sequences simulated, {} of them ended runs that do not \
         count: {} not at rest within 5000 T₀, {} off the plate, {} against a clamped rim)",
        modes(depth),
        t.tried,
        t.dead,
        t.faults[RunFault::Unsettled as usize],
        t.faults[RunFault::Off as usize],
        t.faults[RunFault::Clamped as usize],
    );
    if let Some((_, seq, o)) = &t.best {
        let modes = seq.iter().map(|k| (k + 1).to_string()).collect::<Vec<_>>().join(", ");
        let list = |o: &[f64]| o.iter().map(|v| format!("{v:.1}°")).collect::<Vec<_>>().join(", ");
        if names.len() > 1 {
            let each: Vec<String> =
                names.iter().zip(o).map(|(n, o)| format!("{n} at {}", list(o))).collect();
            msg += &format!("; the closest, modes {modes}, leaves {}", each.join(", "));
        } else {
            msg += &format!("; the closest, modes {modes}, leaves {} (mod {period}°)", list(&o[0]));
        }
    }
    if let Some(first) = rejected.first() {
        msg += &format!("; {} candidate(s) failed the check, e.g. {first}", rejected.len());
    }
    msg += &bound.note();
    // From one side of the plate a central symmetry is already broken; a local one is not.
    // The measured twin test says which it is; without one, the generic note.
    if let Some(tw) = twins {
        msg += &format!(". {tw}");
    } else if let Some(note) =
        t.best.as_ref().and_then(|b| super::symmetry_note(None, &b.2[0], period, true))
    {
        msg += &format!(". {note}");
    }
    msg
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(super) fn tracker(plate: &PlateModel) -> Tracker<'_> {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let part = Part::load(&path.join("../../examples/parts/triangle.json")).unwrap();
        Tracker::new(
            vec![Body::with_samples(&part, crate::motion::body::PLANNER_BODY_SAMPLES)],
            plate,
            vec![360.0],
        )
    }

    fn outcome(x: f64) -> Outcome {
        let pose = Pose { x, y: 0.0, theta: 0.0 };
        Outcome { pose, settle_s: 1.0, t_end: 1.0, rested: true, lost: false }
    }

    /// A run to rest counts in the interior and against a free wall, not against the clamped
    /// rim, off the plate, lost or unrested.
    #[test]
    fn rests_against_a_free_wall_count_and_against_the_clamp_do_not() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let plate =
            PlateModel::load(&path.join("../../examples/plates/cantilever-6-modes.toml")).unwrap();
        let t = tracker(&plate);
        assert_eq!(t.sim.clamped, vec![PlateEdge::Left]);
        let [w, h] = plate.size_mm;
        let r = t.sim.bodies[0].radius;
        let at = |x: f64, y: f64| Outcome { pose: Pose { x, y, theta: 0.0 }, ..outcome(0.0) };
        let ok = |o: Outcome| t.sim.ok(0, &o);
        assert!(ok(at(w / 2.0, h / 2.0)), "interior");
        assert!(ok(at(w - 0.5 * r, h / 2.0)), "against the free wall x = W");
        assert!(ok(at(w / 2.0, 0.5 * r)), "against the free wall y = 0");
        assert!(!ok(at(0.5 * r, h / 2.0)), "against the clamped rim x = 0");
        assert!(!ok(at(w + 1.0, h / 2.0)), "off the plate");
        assert!(!ok(Outcome { lost: true, ..at(w / 2.0, h / 2.0) }), "lost");
        assert!(!ok(Outcome { rested: false, ..at(w / 2.0, h / 2.0) }), "not at rest");
    }

    /// The search's levels beyond the default depth reuse a run from a start within 1° (mod
    /// the period, across 0°) and 2 mm of the same part under the same mode, the first
    /// remembered; nothing farther, under another mode or when `near` is off.
    #[test]
    fn deep_levels_borrow_runs_from_starts_within_the_cluster_tolerance() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let plate = PlateModel::load(&path.join("../../examples/plates/four-lines.toml")).unwrap();
        let mut t = tracker(&plate);
        let at = |x: f64, y: f64, deg: f64| (0, Pose { x, y, theta: deg.to_radians() });
        t.remember(0, at(100.0, 50.0, 359.6), outcome(1.0));
        t.remember(0, at(101.0, 50.0, 359.6), outcome(2.0));
        let got = |t: &Tracker, k: usize, q: Tagged| t.near(k, q).map(|o| o.pose.x);
        assert_eq!(got(&t, 0, at(100.0, 50.0, 359.6)), Some(1.0));
        // Across 0° and a cell edge in y: both runs are near, the first remembered wins.
        assert_eq!(got(&t, 0, at(101.9, 49.5, 0.3)), Some(1.0));
        assert_eq!(got(&t, 0, at(102.5, 50.0, 0.3)), Some(2.0));
        assert_eq!(got(&t, 0, at(100.0, 52.1, 359.6)), None, "2.1 mm away");
        assert_eq!(got(&t, 0, at(100.0, 50.0, 1.0)), None, "1.4° away");
        assert_eq!(got(&t, 1, at(100.0, 50.0, 359.6)), None, "another mode");
        // `outcomes` borrows only when asked, and never stores a borrowed run as exact.
        let q = at(100.5, 50.5, 359.8);
        assert_eq!(t.outcomes(&[(0, q)], true)[0].pose.x, 1.0);
        assert!(!t.memo.contains_key(&key(0, q)));
        assert_ne!(t.outcomes(&[(0, q)], false)[0].pose.x, 1.0);
        assert!(t.memo.contains_key(&key(0, q)));
    }
}
