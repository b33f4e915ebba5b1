//! The candidates of one depth of a feed-region search, confirmed: redone from
//! every tracked start without clustering (their durations), best first, and the fastest
//! checked as the simulator runs a plan, from the interleaved starts (module documentation of
//! [`super`], step 3).

use super::{
    Context, FeedCheck, Node, Starts, Tagged, Tracker, of_part, orientations, part_orientations,
    spreads,
};
use crate::model::angle::cdist;
use crate::planner::position::tracked_position;
use crate::progress::Progress;
use chladni_shared::icd::units::s_from_ms;

use crate::planner::{PartPlan, PlanFailure, PlanOptions, PlannedStep, Settle, Synthesis};
use crate::planner::{deadline, margin, slowest_settled, step_duration_ms};

/// Most starts one refinement round adds (those of the first failing batch of the check).
pub(super) const REFINE_STARTS: usize = 16;

/// The candidates of one depth: the fastest that passes the check, by best-first search.
/// The candidate of least duration so far (then the search's order) is tracked one step
/// further ([`Tracking`]: every start, no clustering); once the least is tracked to its end it
/// is checked from the interleaved starts. A step's duration is never negative, so the
/// durations so far of the others are lower bounds of theirs: the first to pass is the
/// fastest (ties: the first found), as tracking all and checking them by duration would
/// find, and the candidates slower than it are tracked only as far as that shows. Returns
/// the plan, the rejections in the order the search found them (candidates whose tracking
/// failed as far as it went, and every check failed before the plan), and the checked
/// starts that ended off (first failing batch of each, at most [`REFINE_STARTS`] in all);
/// [`PlanFailure::OutOfTime`] when the deadline passes (checked before every step redone and
/// every check). `progress` counts the steps redone.
pub(super) fn confirm(
    t: &mut Tracker,
    found: &[Node],
    from: Starts<'_>,
    ctx: Context<'_>,
    progress: &dyn Progress,
) -> Result<Confirmed, PlanFailure> {
    let (opt, starts) = (ctx.opt, from.tracked);
    let mut open: Vec<Tracking> = (found.iter().take(opt.feed_search.candidates).enumerate())
        .map(|(i, c)| Tracking::new(i, &c.seq, starts, t.sim.periods.len()))
        .collect();
    if !open.is_empty() {
        let what = format!("feed plan: confirming {} candidate(s)", open.len());
        progress.stage(&what, open.iter().map(|c| c.seq.len() as u64).sum());
    }
    let mut why: Vec<(usize, String)> = Vec::new();
    let (mut best, mut off) = (None, Vec::new());
    while let Some(k) = (0..open.len()).min_by_key(|&k| (open[k].so_far_ms(), open[k].i)) {
        let stage = || {
            let c = &open[k];
            format!(
                "the feed-region confirmation, modes {} ({} of {} steps redone)",
                c.modes(),
                c.steps.len(),
                c.seq.len()
            )
        };
        deadline::check(opt.deadline, stage)?;
        if !open[k].done() {
            progress.advance(1);
            if let Err(e) = open[k].advance(t, opt, starts.len()) {
                why.push((open[k].i, e));
                open.swap_remove(k);
            }
            continue;
        }
        let c = open.swap_remove(k);
        let i = c.i;
        let d = match c.draft(&t.sim.periods, ctx) {
            Ok(d) => d,
            Err(e) => {
                why.push((i, e));
                continue;
            }
        };
        match check(t, d, from, ctx) {
            Ok(syn) => {
                best = Some(syn);
                break;
            }
            Err((e, bad)) => {
                why.push((i, e));
                for q in bad {
                    if off.len() < REFINE_STARTS && !off.contains(&q) && !starts.contains(&q) {
                        off.push(q);
                    }
                }
            }
        }
    }
    why.sort_by_key(|w| w.0);
    Ok((best, why.into_iter().map(|w| w.1).collect(), off))
}

/// What [`confirm`] found: the plan, the rejections, the checked starts that ended off.
pub(super) type Confirmed = (Option<Synthesis>, Vec<String>, Vec<Tagged>);

/// A candidate sequence with every start tracked: its steps (durations from the settle
/// times) and where the tracked starts end.
struct Draft {
    modes: String,
    steps: Vec<PlannedStep>,
    poses: Vec<Tagged>,
    /// Each part's orientations after each step (deg).
    afters: Vec<Vec<Vec<f64>>>,
    /// Each part's circular mean orientation of the ends and their largest distance from it
    /// (deg).
    spreads: Vec<(f64, f64)>,
}

/// A candidate sequence being tracked from every start without clustering (see the module
/// documentation), a step at a time: its steps so far (durations from the slowest of every
/// part's runs) and where the starts are.
struct Tracking<'a> {
    /// The candidate's place in the search's order.
    i: usize,
    seq: &'a [usize],
    poses: Vec<Tagged>,
    steps: Vec<PlannedStep>,
    /// Each part's orientations after each step so far (deg).
    afters: Vec<Vec<Vec<f64>>>,
}

impl<'a> Tracking<'a> {
    fn new(i: usize, seq: &'a [usize], starts: &[Tagged], parts: usize) -> Self {
        let (poses, steps) = (starts.to_vec(), Vec::with_capacity(seq.len()));
        Tracking { i, seq, poses, steps, afters: vec![Vec::with_capacity(seq.len()); parts] }
    }

    fn done(&self) -> bool {
        self.steps.len() == self.seq.len()
    }

    /// The steps' total duration so far (ms): a lower bound of the whole sequence's.
    fn so_far_ms(&self) -> u64 {
        self.steps.iter().map(|s| s.duration_ms as u64).sum()
    }

    fn modes(&self) -> String {
        self.seq.iter().map(|k| (k + 1).to_string()).collect::<Vec<_>>().join(", ")
    }

    /// Tracks every pose through the next step; `Err` when a run there does not count.
    fn advance(&mut self, t: &mut Tracker, opt: &PlanOptions, starts: usize) -> Result<(), String> {
        let (i, k) = (self.steps.len(), self.seq[self.steps.len()]);
        let Some(runs) = t.rests(k, &self.poses) else {
            let modes = self.modes();
            return Err(format!("modes {modes}: step {} leaves a part off any node", i + 1));
        };
        let periods = &t.sim.periods;
        let (settle_s, lingering) = slowest_settled(runs.iter().map(|r| r.settle_s).collect());
        let before =
            if i == 0 { Vec::new() } else { orientations(&of_part(&self.poses, 0), periods[0]) };
        self.poses = self.poses.iter().zip(&runs).map(|(q, r)| (q.0, r.pose)).collect();
        for (a, o) in self.afters.iter_mut().zip(part_orientations(&self.poses, periods)) {
            a.push(o);
        }
        self.steps.push(PlannedStep {
            mode: k,
            before,
            after: self.afters[0][i].clone(),
            duration_ms: step_duration_ms(settle_s, opt.safety, t.sim.plate.modes[k].ramp_ms),
            settle: Settle { settle_s, lingering, points: starts, ends_on_edge: Vec::new() },
            margin: margin::fixed(opt),
        });
        Ok(())
    }

    /// The tracked sequence as a draft, or `Err` when a part's ends spread over more than
    /// the search's tolerance.
    fn draft(
        self,
        periods: &[f64],
        Context { opt, names, .. }: Context<'_>,
    ) -> Result<Draft, String> {
        let spreads = spreads(&self.poses, periods);
        let modes = self.modes();
        for (name, &(_, dev)) in names.iter().zip(&spreads) {
            if dev > opt.feed_search.tol_deg {
                let whose = if names.len() > 1 { format!("{name}'s ") } else { String::new() };
                return Err(format!(
                    "modes {modes}: {whose}tracked orientations spread ±{dev:.2}°"
                ));
            }
        }
        let Tracking { poses, steps, afters, .. } = self;
        Ok(Draft { modes, steps, poses, afters, spreads })
    }
}

/// Runs a tracked sequence with its fixed durations from the interleaved starts (and the
/// tracked ones again when some lingered) and builds its plan if every end lies within the
/// margin of its part's predicted orientation.
fn check(
    t: &mut Tracker,
    d: Draft,
    Starts { tracked: starts, verify }: Starts<'_>,
    Context { opt, region, names }: Context<'_>,
) -> Result<Synthesis, (String, Vec<Tagged>)> {
    // Tracked starts settled within their step durations unless some lingered (left out of
    // the durations); only then can they end elsewhere when run with the fixed durations.
    let lingered = d.steps.iter().any(|s| s.settle.lingering > 0);
    let again = if lingered { starts } else { &[] };
    let runs: Vec<Tagged> = again.iter().chain(verify).copied().collect();
    let bound = opt.margin_deg.max(opt.feed_search.tol_deg);
    let thetas: Vec<f64> = d.spreads.iter().map(|s| s.0).collect();
    let (checked, part, off) = checked_error(t, &d.steps, &runs, &thetas, bound);
    let dev = d.spreads.iter().map(|s| s.1).fold(0.0, f64::max);
    let worst = checked.max(dev);
    if worst > bound {
        let modes = &d.modes;
        let of = if names.len() > 1 { format!(" of {}", names[part]) } else { String::new() };
        let msg = format!("modes {modes}: a start{of} ends {worst:.2}° off (bound {bound}°)");
        return Err((msg, off));
    }
    let periods = &t.sim.periods;
    let parts = if names.len() < 2 {
        Vec::new()
    } else {
        (names.iter().enumerate())
            .map(|(i, name)| PartPlan {
                name: name.to_string(),
                period_deg: periods[i],
                final_orientation_deg: thetas[i],
                final_position_mm: tracked_position(&of_part(&d.poses, i)),
                after: d.afters[i].clone(),
                ..PartPlan::default()
            })
            .collect()
    };
    Ok(Synthesis {
        final_position_mm: tracked_position(&of_part(&d.poses, 0)),
        steps: d.steps,
        final_orientation_deg: thetas[0],
        period_deg: periods[0],
        feed: Some(FeedCheck {
            region: *region,
            starts: starts.len(),
            checked: runs.len(),
            worst_error_deg: worst,
            rejected: 0,
        }),
        parts,
        ..Synthesis::default()
    })
}

/// The largest final orientation error (deg, mod the part's period) of the plan run as the
/// simulator runs it (fixed step durations,
/// [`simulate_plan`](crate::motion::steps::simulate_plan)) from `starts`, each part against its
/// own prediction `thetas[part]`, the part it was measured on, and the starts whose error
/// exceeds `bound`. Starts go in batches of 64 (each batch in parallel); after a batch with an
/// error above `bound` the rest are skipped, so a rejected plan costs less (the result then
/// exceeds `bound` but need not be the largest).
fn checked_error(
    t: &mut Tracker,
    steps: &[PlannedStep],
    starts: &[Tagged],
    thetas: &[f64],
    bound: f64,
) -> (f64, usize, Vec<Tagged>) {
    let (mut worst, mut off) = ((0.0f64, 0), Vec::new());
    for batch in starts.chunks(64) {
        let mut poses = batch.to_vec();
        for s in steps {
            poses = t.after(s.mode, s_from_ms(u64::from(s.duration_ms)), &poses);
        }
        for (&(i, q), &start) in poses.iter().zip(batch) {
            let err = cdist(q.theta.to_degrees(), thetas[i], t.sim.periods[i]);
            if err > worst.0 {
                worst = (err, i);
            }
            if err > bound {
                off.push(start);
            }
        }
        if worst.0 > bound {
            break;
        }
    }
    (worst.0, worst.1, off)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::feed_region::FeedRegion;
    use crate::model::plate::PlateModel;
    use crate::model::pose::Pose;
    use crate::planner::feed::{FeedSearch, interleaved_starts, tests::tracker, tracked_starts};

    /// The exhaustive confirmation: every candidate tracked, then checked in order of (total
    /// duration, search order) until one passes; also the tracked candidates' totals (ms).
    fn confirm_exhaustive(
        t: &mut Tracker,
        found: &[Node],
        from: Starts<'_>,
        ctx: Context<'_>,
    ) -> (Option<Synthesis>, Vec<u64>) {
        let (opt, starts) = (ctx.opt, from.tracked);
        let mut drafts: Vec<(u64, usize, Draft)> = Vec::new();
        for (i, c) in found.iter().enumerate() {
            let mut tr = Tracking::new(i, &c.seq, starts, 1);
            while !tr.done() && tr.advance(t, opt, starts.len()).is_ok() {}
            if tr.done() {
                let ms = tr.so_far_ms();
                drafts.extend(tr.draft(&t.sim.periods, ctx).ok().map(|d| (ms, i, d)));
            }
        }
        drafts.sort_by_key(|(ms, i, _)| (*ms, *i));
        let totals = drafts.iter().map(|d| d.0).collect();
        let plan = (drafts.into_iter()).find_map(|(_, _, d)| check(t, d, from, ctx).ok());
        (plan, totals)
    }

    /// The best-first confirmation finds the plan the exhaustive one finds (least total
    /// duration, then the search's order), simulating fewer runs: every 2- and 3-step sequence
    /// on the four-line plate as a candidate, in two orders.
    #[test]
    fn the_best_first_confirmation_finds_the_exhaustive_plan_with_fewer_runs() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let plate = PlateModel::load(&path.join("../../examples/plates/four-lines.toml")).unwrap();
        let region = FeedRegion::new([60.0, 40.0, 120.0, 100.0], &plate).unwrap();
        let s = FeedSearch { points: 2, starts: 6, candidates: 100, ..Default::default() };
        let opt = PlanOptions { feed: Some(region), feed_search: s, ..Default::default() };
        let nm = plate.modes.len();
        let mut seqs: Vec<Vec<usize>> = Vec::new();
        for a in 0..nm {
            for b in (0..nm).filter(|&b| b != a) {
                seqs.push(vec![a, b]);
                seqs.extend((0..nm).filter(|&c| c != b).map(|c| vec![a, b, c]));
            }
        }
        let t0 = tracker(&plate);
        let body = &t0.sim.bodies[0];
        let tag = |v: Vec<Pose>| v.into_iter().map(|q| (0, q)).collect::<Vec<Tagged>>();
        let starts = tag(tracked_starts(&region, body, &plate, &s));
        let verify = tag(interleaved_starts(&region, body, &plate, &s));
        let ctx = Context { opt: &opt, region: &region, names: &["triangle"] };
        let nodes = |seqs: &[Vec<usize>]| -> Vec<Node> {
            seqs.iter().map(|q| Node { seq: q.clone(), poses: Vec::new() }).collect()
        };
        let runs = |t: &Tracker| t.memo.len() + t.fixed.len();
        let reversed: Vec<Vec<usize>> = seqs.iter().rev().cloned().collect();
        let modes = |syn: &Synthesis| syn.steps.iter().map(|s| s.mode).collect::<Vec<_>>();
        let ms = |syn: &Synthesis| syn.steps.iter().map(|s| s.duration_ms).collect::<Vec<_>>();
        for (what, order) in [("as listed", &seqs), ("reversed", &reversed)] {
            let mut ex = tracker(&plate);
            let (want, totals) = confirm_exhaustive(
                &mut ex,
                &nodes(order),
                Starts { tracked: &starts, verify: &verify },
                ctx,
            );
            let want = want.expect("a plan among the 2- and 3-step sequences");
            // The choice matters: several candidates track to one orientation, not all as fast.
            assert!(totals.len() >= 3 && totals[0] < totals[totals.len() - 1], "{totals:?}");
            let mut bf = tracker(&plate);
            let hidden = crate::progress::Silent;
            let (got, _, _) = confirm(
                &mut bf,
                &nodes(order),
                Starts { tracked: &starts, verify: &verify },
                ctx,
                &hidden,
            )
            .unwrap();
            let got = got.expect("the best-first search finds a plan");
            assert_eq!((modes(&got), ms(&got)), (modes(&want), ms(&want)), "{what}");
            assert_eq!(got.final_orientation_deg, want.final_orientation_deg, "{what}");
            eprintln!("{what}: {} runs against {}", runs(&bf), runs(&ex));
            assert!(runs(&bf) < runs(&ex), "{what}: {} runs against {}", runs(&bf), runs(&ex));
        }
    }

    /// The confirmation stops at the deadline, naming the candidate it was redoing.
    #[test]
    fn the_confirmation_stops_at_the_deadline() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let plate = PlateModel::load(&path.join("../../examples/plates/four-lines.toml")).unwrap();
        let region = FeedRegion::new([60.0, 40.0, 120.0, 100.0], &plate).unwrap();
        let s = FeedSearch { points: 2, starts: 6, ..Default::default() };
        let deadline = Some(crate::planner::Deadline::after_s(0.0));
        let opt =
            PlanOptions { feed: Some(region), feed_search: s, deadline, ..Default::default() };
        let mut t = tracker(&plate);
        let starts: Vec<Tagged> = (tracked_starts(&region, &t.sim.bodies[0], &plate, &s))
            .into_iter()
            .map(|q| (0, q))
            .collect();
        let found = [Node { seq: vec![0, 1], poses: Vec::new() }];
        let ctx = Context { opt: &opt, region: &region, names: &["triangle"] };
        let hidden = crate::progress::Silent;
        let err =
            confirm(&mut t, &found, Starts { tracked: &starts, verify: &starts }, ctx, &hidden)
                .unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, PlanFailure::OutOfTime { .. }), "{msg}");
        assert!(
            msg.contains("the feed-region confirmation, modes 1, 2 (0 of 2 steps redone)"),
            "{msg}"
        );
        assert!(t.memo.is_empty(), "nothing was simulated");
    }
}
