//! Several parts on the plate at once (docs/motion.md, "Bulk feeding"): random
//! non-overlapping drops, each run through a plan with contacts ([`crate::motion::many`]);
//! the oriented fraction, the parts lost off an open edge and the throughput of N copies of a
//! part, and the per-part trials of a plan for several parts simulated together.

use crate::progress::Progress;
use serde::Serialize;

use crate::model::feed_region::FeedRegion;
use crate::model::plan_file::PlanFile;
use crate::model::plate::PlateModel;
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::contact::Rim;
use crate::motion::field::FieldModel;
use crate::motion::many::{Group, ManyRun, simulate_plan_many};
use crate::motion::montecarlo::{Trials, random_pose};
use crate::motion::shape::{self, Pieces};
use crate::motion::steps::{SimStep, simulate_plan};
use crate::rng::Rng;

/// Random poses tried for each part before a drop is refused.
pub(crate) const PLACE_ATTEMPTS: usize = 500;

/// A drop that cannot place every part without overlap.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "cannot place {parts} parts without overlap on the {w} × {h} mm plate{region}: only {placed} \
     fitted in {attempts} random poses each (fewer copies, or a larger plate or feed region)"
)]
pub struct CannotPlace {
    /// Parts asked for.
    pub parts: usize,
    /// Parts placed before one found no room.
    pub placed: usize,
    /// Random poses tried for that part.
    pub attempts: usize,
    /// Plate width (mm).
    pub w: f64,
    /// Plate height (mm).
    pub h: f64,
    /// " (feed region)" when drawn in one.
    pub region: String,
}

/// What a drop simulates: the parts, their pieces, the plate and the plan.
#[derive(Debug, Clone, Copy)]
pub struct Drop<'a> {
    /// The bodies dropped together (N copies, or the parts of a plan).
    pub bodies: &'a [&'a Body],
    /// Their pieces.
    pub pieces: &'a [&'a Pieces],
    /// The plate.
    pub plate: &'a PlateModel,
    /// The field of each plate mode.
    pub fields: &'a [FieldModel],
    /// The plan's steps.
    pub steps: &'a [SimStep],
    /// Start positions in this region instead of over the whole plate.
    pub feed: Option<&'a FeedRegion>,
}

/// Random poses for every body, none overlapping another (parry's contacts, seeded).
pub fn place(rng: &mut Rng, d: &Drop<'_>) -> Result<Vec<Pose>, CannotPlace> {
    let refuse = |placed: usize, attempts: usize| CannotPlace {
        parts: d.bodies.len(),
        placed,
        attempts,
        w: d.plate.size_mm[0],
        h: d.plate.size_mm[1],
        region: if d.feed.is_some() { " (feed region)".into() } else { String::new() },
    };
    // More area than the plate has can never be placed: refused before any try.
    let total: f64 = d.bodies.iter().map(|b| b.area).sum();
    if total > d.plate.size_mm[0] * d.plate.size_mm[1] {
        return Err(refuse(0, 0));
    }
    let mut out: Vec<Pose> = Vec::with_capacity(d.bodies.len());
    for (i, b) in d.bodies.iter().enumerate() {
        let free = |q: Pose, out: &[Pose]| {
            out.iter().enumerate().all(|(j, &p)| {
                let far = (p.x - q.x).hypot(p.y - q.y) > b.radius + d.bodies[j].radius;
                far || shape::overlap(d.pieces[i], q, d.pieces[j], p) == 0.0
            })
        };
        let found = (0..PLACE_ATTEMPTS).find_map(|_| {
            let q = random_pose(rng, b, d.plate, d.feed);
            free(q, &out).then_some(q)
        });
        match found {
            Some(q) => out.push(q),
            None => return Err(refuse(i, PLACE_ATTEMPTS)),
        }
    }
    Ok(out)
}

/// The drops: each body's trials (start and final poses, lost, and the poses before each
/// step and at the end in `examples`, for every drop), and the deepest overlap of any two
/// parts at the end of any drop (mm).
#[derive(Debug, Clone, Default)]
pub struct Drops {
    /// One [`Trials`] per body (traces left empty; `examples`: every drop's poses at steps).
    pub per_body: Vec<Trials>,
    /// Deepest final overlap (mm).
    pub max_overlap_mm: f64,
}

/// Runs `drops` random drops from `seed` through the plan with contacts; `progress` after
/// each drop.
pub fn run_drops(
    d: &Drop<'_>,
    drops: u32,
    seed: u64,
    progress: &dyn Progress,
) -> Result<Drops, CannotPlace> {
    let mut rng = Rng::seeded(seed);
    let rim = Rim::of(d.plate);
    let g = Group { bodies: d.bodies, pieces: d.pieces, rim: Some(rim), friction: rim.friction };
    let mut out = Drops { per_body: vec![Trials::default(); d.bodies.len()], max_overlap_mm: 0.0 };
    for _ in 0..drops {
        let start = place(&mut rng, d)?;
        // One part alone runs the single-part path (motion::integrate), unchanged.
        let (r, at_steps) = if let ([body], [q]) = (d.bodies, start.as_slice()) {
            let (poses, _, _) = simulate_plan(body, d.plate, d.fields, d.steps, *q);
            let end = *poses.last().unwrap_or(q);
            let at_steps = poses.iter().map(|&p| vec![p]).collect();
            let r = ManyRun {
                poses: vec![end],
                lost: vec![rim.lost(end)],
                trace: Vec::new(),
                t_end: 0.0,
                rested: true,
                steps: 0,
            };
            (r, at_steps)
        } else {
            let r = simulate_plan_many(&g, d.plate, d.fields, d.steps, &start);
            let at_steps = step_poses(&r, d.steps);
            (r, at_steps)
        };
        out.max_overlap_mm = out.max_overlap_mm.max(g.max_overlap(&r.poses, &r.lost));
        for (i, t) in out.per_body.iter_mut().enumerate() {
            t.starts.push(start[i]);
            t.finals.push(r.poses[i]);
            t.lost.push(r.lost[i]);
            t.examples.push(at_steps.iter().map(|qs| qs[i]).collect());
        }
        progress.advance(1);
    }
    Ok(out)
}

/// The poses of a group's run before each step and at the end of every step (the last of
/// its trace samples at each step's end time: [`run_many`] ends each step with a sample at
/// its time limit).
///
/// [`run_many`]: crate::motion::many::run_many
fn step_poses(r: &ManyRun, steps: &[SimStep]) -> Vec<Vec<Pose>> {
    let mut out = vec![r.trace.first().map_or_else(|| r.poses.clone(), |(_, q)| q.clone())];
    let mut end = 0.0;
    for s in steps {
        end += s.duration_s;
        let slack = 1e-9 * end.max(1.0);
        let at = r.trace.iter().rev().find(|(t, _)| *t <= end + slack);
        out.push(at.map_or_else(|| r.poses.clone(), |(_, q)| q.clone()));
    }
    out
}

/// The `chladni simulate --copies N --json` object (keys in alphabetical order).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BulkReport {
    /// Copies dropped together in each drop.
    pub copies: usize,
    /// Final poses of the first drop's copies: `[x_mm, y_mm, θ_deg]`.
    pub final_poses: Vec<[f64; 3]>,
    /// Copies lost off an open edge, over all drops.
    pub lost: usize,
    /// Deepest overlap of two copies at the end of any drop (mm).
    pub max_overlap_mm: f64,
    /// Fraction of all dropped copies within the tolerance of the predicted orientation
    /// (`None` when the plan predicts none).
    pub oriented: Option<f64>,
    /// Oriented copies per minute of plan time (`oriented · copies / plan minutes`).
    pub parts_per_min: Option<f64>,
    /// One run of the plan (s).
    pub plan_s: f64,
    /// Seed of the drops.
    pub seed: u64,
    /// The tolerance of an oriented copy (degrees).
    pub tolerance_deg: f64,
    /// Drops.
    pub trials: u32,
}

/// Is the final orientation `theta` (rad) within `tol_deg` of the plan's prediction?
fn oriented(plan: &PlanFile, theta: f64, tol_deg: f64) -> Option<bool> {
    let (t, p) = plan.final_orientation_deg.zip(plan.period_deg)?;
    let d = (theta.to_degrees() - t).rem_euclid(p);
    Some(d.min(p - d) <= tol_deg)
}

/// Rounds to 1e-6 (the report's resolution).
fn r6(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

impl BulkReport {
    /// The report of N-copy drops against the plan's prediction.
    pub fn new(drops: &Drops, plan: &PlanFile, steps: &[SimStep], seed: u64, tol: f64) -> Self {
        let copies = drops.per_body.len();
        let n = drops.per_body.first().map_or(0, |t| t.finals.len());
        let (mut ok, mut lost, mut judged) = (0usize, 0usize, true);
        for t in &drops.per_body {
            for (q, &l) in t.finals.iter().zip(&t.lost) {
                lost += usize::from(l);
                match oriented(plan, q.theta, tol) {
                    Some(o) => ok += usize::from(o && !l),
                    None => judged = false,
                }
            }
        }
        let plan_s: f64 = steps.iter().map(|s| s.duration_s).sum();
        let total = (copies * n).max(1) as f64;
        let fraction = judged.then(|| ok as f64 / total);
        BulkReport {
            copies,
            final_poses: (drops.per_body.iter())
                .filter_map(|t| t.finals.first())
                .map(|q| [r6(q.x), r6(q.y), r6(q.theta.to_degrees())])
                .collect(),
            lost,
            max_overlap_mm: r6(drops.max_overlap_mm),
            oriented: fraction.map(r6),
            parts_per_min: fraction
                .filter(|_| plan_s > 0.0)
                .map(|f| r6(f * copies as f64 * 60.0 / plan_s)),
            plan_s: r6(plan_s),
            seed,
            tolerance_deg: tol,
            trials: n as u32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::plate::DEFAULT_FRICTION;
    use crate::motion::testkit::{mode, plate, rect};

    #[test]
    fn copies_are_placed_apart_reproducibly_and_too_many_are_refused() {
        let m =
            mode("freq_hz = 50.0\nnode = { kind = \"line\", angle_deg = 90.0, offset_mm = 0.0 }");
        let pl = plate(&m);
        let body = Body::new(&rect());
        let pieces = Pieces::of(&body);
        let fields = vec![FieldModel::new(&m, &pl)];
        let mk = |n: usize| (vec![&body; n], vec![&pieces; n]);
        let (b, p) = mk(12);
        let d =
            Drop { bodies: &b, pieces: &p, plate: &pl, fields: &fields, steps: &[], feed: None };
        let a = place(&mut Rng::seeded(5), &d).unwrap();
        assert_eq!(a, place(&mut Rng::seeded(5), &d).unwrap());
        for i in 0..a.len() {
            for j in i + 1..a.len() {
                assert_eq!(shape::overlap(&pieces, a[i], &pieces, a[j]), 0.0);
            }
        }
        // 300 × 200 mm holds at most 150 rectangles of 40 × 10 mm; random drops fit far fewer.
        for (n, tried) in [(151, 0), (120, PLACE_ATTEMPTS)] {
            let (b, p) = mk(n);
            let d = Drop { bodies: &b, pieces: &p, ..d };
            let e = place(&mut Rng::seeded(5), &d).unwrap_err();
            assert!(e.placed < n && e.attempts == tried, "{e}");
            assert!(e.to_string().contains(&format!("cannot place {n} parts")), "{e}");
        }
        assert_eq!(pl.friction, DEFAULT_FRICTION);
    }

    /// Every drop keeps each part's poses at each step's end: the same poses as the plan
    /// cut after that step, run from the same start (the group's runs are deterministic).
    #[test]
    fn drops_keep_each_parts_poses_at_every_step() {
        let m =
            mode("freq_hz = 50.0\nnode = { kind = \"line\", angle_deg = 90.0, offset_mm = 0.0 }");
        let pl = plate(&m);
        let body = Body::new(&rect());
        let pieces = Pieces::of(&body);
        let fields = vec![FieldModel::new(&m, &pl)];
        let steps = [SimStep::new(0, 1500, 1.0), SimStep::new(0, 2500, 1.0)];
        let (b, p) = (vec![&body; 3], vec![&pieces; 3]);
        let d =
            Drop { bodies: &b, pieces: &p, plate: &pl, fields: &fields, steps: &steps, feed: None };
        let drops = run_drops(&d, 1, 3, &crate::progress::Silent).unwrap();
        let rim = Rim::of(&pl);
        let g = Group { bodies: &b, pieces: &p, rim: Some(rim), friction: rim.friction };
        let start: Vec<Pose> = drops.per_body.iter().map(|t| t.starts[0]).collect();
        let cut = simulate_plan_many(&g, &pl, &fields, &steps[..1], &start);
        for (i, t) in drops.per_body.iter().enumerate() {
            let at = &t.examples[0];
            assert_eq!(at.len(), 3);
            assert_eq!(at[0], start[i]);
            assert_eq!(at[1], cut.poses[i], "part {i} after step 1");
            assert_eq!(at[2], t.finals[0]);
            assert_ne!(at[1], at[2], "part {i} did not move in step 2");
        }
    }
}
