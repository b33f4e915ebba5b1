//! Monte Carlo check of a plan (`chladni simulate`): random start poses on the plate (or in a
//! feed region), each run through the plan's steps; the success rate against the plan's
//! predicted orientation, the orientation and position errors and the final spread.

use crate::model::angle::circular_mean;
use crate::progress::Progress;
use serde::Serialize;

use crate::model::feed_region::FeedRegion;
use crate::model::plan_file::PlanFile;
use crate::model::plate::PlateModel;
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::contact::Rim;
use crate::motion::field::FieldModel;
use crate::motion::steps::SimStep;
use crate::motion::steps::simulate_plan;
use crate::rng::Rng;

/// Missed trials listed in a [`Report`] (all are counted).
pub const MAX_LISTED_MISSES: usize = 100;
/// Trials whose traces are kept for the figure.
pub const TRACED_TRIALS: usize = 6;
/// Trials whose step-by-step poses are kept for the figure.
pub const EXAMPLE_TRIALS: usize = 3;

/// A random pose on the plate, or in the feed region when given (centroid at least the
/// part's radius from the plate's edges).
pub fn random_pose(
    rng: &mut Rng,
    body: &Body,
    plate: &PlateModel,
    feed: Option<&FeedRegion>,
) -> Pose {
    let [w, h] = plate.size_mm;
    let r = body.radius.min(w / 2.0).min(h / 2.0);
    let (u, v) = (rng.uniform(), rng.uniform());
    let [x, y] = match feed {
        Some(f) => f.at(u, v, r, plate),
        None => [r + (w - 2.0 * r) * u, r + (h - 2.0 * r) * v],
    };
    Pose { x, y, theta: std::f64::consts::TAU * rng.uniform() }
}

/// What a Monte Carlo run simulates: a part on a plate, a plan's steps, where parts start.
#[derive(Debug, Clone, Copy)]
pub struct Setup<'a> {
    /// The part.
    pub body: &'a Body,
    /// The plate.
    pub plate: &'a PlateModel,
    /// The field of each plate mode.
    pub fields: &'a [FieldModel],
    /// The plan's steps.
    pub steps: &'a [SimStep],
    /// Start positions in this region instead of over the whole plate.
    pub feed: Option<&'a FeedRegion>,
}

/// The simulated trials.
#[derive(Debug, Clone, Default)]
pub struct Trials {
    /// Start pose of each trial.
    pub starts: Vec<Pose>,
    /// Final pose of each trial.
    pub finals: Vec<Pose>,
    /// Full traces of the first [`TRACED_TRIALS`] trials.
    pub traces: Vec<Vec<(f64, Pose)>>,
    /// End time of each step (the same for every trial).
    pub step_ends: Vec<f64>,
    /// Poses before each step and at the end, of the first [`EXAMPLE_TRIALS`] trials.
    pub examples: Vec<Vec<Pose>>,
    /// Whether each trial fell off an open edge (`[plate] edge = "open"`).
    pub lost: Vec<bool>,
}

/// What [`run_trials_keeping`] keeps of every trial beyond the first few.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Keep {
    /// The poses before each step and at the end (`Trials::examples`), of every trial.
    pub poses: bool,
    /// The full trace (`Trials::traces`), of every trial.
    pub traces: bool,
}

/// Runs `trials` random starts drawn from `seed` through the plan; `progress` is called
/// after each trial.
pub fn run_trials(setup: &Setup<'_>, trials: u32, seed: u64, progress: &dyn Progress) -> Trials {
    run_trials_keeping(setup, trials, seed, Keep::default(), progress)
}

/// [`run_trials`], keeping what `keep` asks for of every trial (the same trials: the start
/// poses come from `seed` alone).
pub fn run_trials_keeping(
    setup: &Setup<'_>,
    trials: u32,
    seed: u64,
    keep: Keep,
    progress: &dyn Progress,
) -> Trials {
    let mut rng = Rng::seeded(seed);
    let mut out = Trials {
        starts: Vec::with_capacity(trials as usize),
        finals: Vec::with_capacity(trials as usize),
        ..Trials::default()
    };
    for i in 0..trials as usize {
        let start = random_pose(&mut rng, setup.body, setup.plate, setup.feed);
        let (poses, trace, ends) =
            simulate_plan(setup.body, setup.plate, setup.fields, setup.steps, start);
        out.starts.push(start);
        let end = *poses.last().unwrap_or(&start);
        out.lost.push(Rim::of(setup.plate).lost(end));
        out.finals.push(end);
        if i < TRACED_TRIALS || keep.traces {
            out.traces.push(trace);
            out.step_ends = ends;
        }
        if i < EXAMPLE_TRIALS || keep.poses {
            out.examples.push(poses);
        }
        progress.advance(1);
    }
    out
}

/// Root mean square and maximum of an error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RmsMax {
    /// Largest absolute error.
    pub max: f64,
    /// Root mean square.
    pub rms: f64,
}

impl RmsMax {
    fn of(errors: &[f64]) -> Self {
        let n = errors.len().max(1) as f64;
        RmsMax {
            max: errors.iter().fold(0.0f64, |m, e| m.max(e.abs())),
            rms: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        }
    }

    fn rounded(self) -> Self {
        RmsMax { max: r6(self.max), rms: r6(self.rms) }
    }
}

/// The statistics of a Monte Carlo run against a plan's predictions.
#[derive(Debug, Clone, PartialEq)]
pub struct Stats {
    /// Fraction of trials within the tolerance of the predicted orientation (`None` when the
    /// plan predicts none).
    pub success_rate: Option<f64>,
    /// Error of the final orientation against the prediction, degrees modulo the period.
    pub orientation_error_deg: Option<RmsMax>,
    /// Distance of the final centroid from the predicted position (mm), when predicted.
    pub position_error_mm: Option<RmsMax>,
    /// Mean final centroid (mm).
    pub mean_position_mm: [f64; 2],
    /// Circular mean of the final orientations modulo the plan's period (360° when it
    /// predicts none), in [0, period) degrees.
    pub mean_orientation_deg: f64,
    /// RMS distance of the final centroids from their mean (mm).
    pub position_spread_mm: f64,
    /// Start poses of the trials that missed the predicted orientation: where a plan's reach
    /// ends (e.g. near a cantilever's clamp) shows in them.
    pub misses: Vec<Pose>,
    /// Trials that fell off an open edge.
    pub lost: usize,
}

/// The statistics of `trials` against `plan`'s predictions; a trial succeeds when its final
/// orientation is within `tol_deg` of the prediction, modulo the period.
pub fn statistics(trials: &Trials, plan: &PlanFile, tol_deg: f64) -> Stats {
    let finals = &trials.finals;
    let n = finals.len().max(1) as f64;
    let mut stats = Stats {
        success_rate: None,
        orientation_error_deg: None,
        position_error_mm: None,
        mean_position_mm: [0.0; 2],
        mean_orientation_deg: circular_mean(
            finals.iter().map(|q| q.theta.to_degrees()),
            plan.period_deg.unwrap_or(360.0),
        ),
        position_spread_mm: 0.0,
        misses: Vec::new(),
        lost: trials.lost.iter().filter(|&&l| l).count(),
    };
    if let (Some(t), Some(p)) = (plan.final_orientation_deg, plan.period_deg) {
        let errs: Vec<f64> = finals
            .iter()
            .map(|q| crate::model::angle::signed_diff(q.theta.to_degrees(), t, p))
            .collect();
        // A part lost off an open edge is not oriented, wherever it fell.
        let lost = |i: usize| trials.lost.get(i).copied().unwrap_or(false);
        stats.misses = (trials.starts.iter().zip(&errs).enumerate())
            .filter(|(i, (_, e))| e.abs() > tol_deg || lost(*i))
            .map(|(_, (s, _))| *s)
            .collect();
        stats.success_rate = Some(1.0 - stats.misses.len() as f64 / n);
        stats.orientation_error_deg = Some(RmsMax::of(&errs));
    }
    if let Some(p) = plan.final_position_mm {
        let d: Vec<f64> = finals.iter().map(|q| (q.x - p[0]).hypot(q.y - p[1])).collect();
        stats.position_error_mm = Some(RmsMax::of(&d));
    }
    let (mx, my) =
        (finals.iter().map(|q| q.x).sum::<f64>() / n, finals.iter().map(|q| q.y).sum::<f64>() / n);
    stats.mean_position_mm = [mx, my];
    stats.position_spread_mm =
        (finals.iter().map(|q| (q.x - mx).powi(2) + (q.y - my).powi(2)).sum::<f64>() / n).sqrt();
    stats
}

/// Rounds to 1e-6 (the report's resolution).
fn r6(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// The `chladni simulate --json` object (keys in alphabetical order, as printed).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Final orientation the plan predicts (degrees).
    pub final_orientation_deg: Option<f64>,
    /// Trials that fell off an open edge (always 0 with a wall; also counted as missed).
    pub lost: usize,
    /// The simulated final orientation: the circular mean of the trials' modulo the period.
    pub mean_final_orientation_deg: f64,
    /// The simulated final position: the mean of the trials' final centroids (mm).
    pub mean_final_position_mm: [f64; 2],
    /// Number of trials that missed.
    pub missed: usize,
    /// The first [`MAX_LISTED_MISSES`] missed trials' start poses: `[x_mm, y_mm, θ_deg]`.
    pub missed_starts: Vec<[f64; 3]>,
    /// Orientation error (degrees).
    pub orientation_error_deg: Option<RmsMax>,
    /// Period of the predicted orientation (degrees).
    pub period_deg: Option<f64>,
    /// Position error (mm).
    pub position_error_mm: Option<RmsMax>,
    /// Spread of the final centroids (mm).
    pub position_spread_mm: f64,
    /// The start poses' seed.
    pub seed: u64,
    /// Success rate.
    pub success_rate: Option<f64>,
    /// The tolerance of a success (degrees).
    pub tolerance_deg: f64,
    /// Number of trials.
    pub trials: u32,
}

impl Report {
    /// The report of `stats` (rounded to 1e-6) for a run of `trials` from `seed`.
    pub fn new(stats: &Stats, plan: &PlanFile, trials: u32, seed: u64, tol_deg: f64) -> Self {
        let target = plan.final_orientation_deg.zip(plan.period_deg);
        Report {
            final_orientation_deg: target.map(|t| t.0),
            lost: stats.lost,
            mean_final_orientation_deg: r6(stats.mean_orientation_deg),
            mean_final_position_mm: stats.mean_position_mm.map(r6),
            missed: stats.misses.len(),
            missed_starts: (stats.misses.iter().take(MAX_LISTED_MISSES))
                .map(|q| [r6(q.x), r6(q.y), r6(q.theta.to_degrees())])
                .collect(),
            orientation_error_deg: stats.orientation_error_deg.map(RmsMax::rounded),
            period_deg: target.map(|t| t.1),
            position_error_mm: stats.position_error_mm.map(RmsMax::rounded),
            position_spread_mm: r6(stats.position_spread_mm),
            seed,
            success_rate: stats.success_rate.map(r6),
            tolerance_deg: tol_deg,
            trials,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::part::Part;
    use crate::model::plan_file::StepJson;

    fn plate() -> PlateModel {
        let text = "[plate]\nname = \"t\"\nsize_mm = [300.0, 200.0]\n\n[[mode]]\nfreq_hz = 60.0\n\
                    node = { kind = \"line\", angle_deg = 90.0, offset_mm = 0.0 }\n";
        let dir = std::env::temp_dir().join(format!("chladni-mc-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("p.toml");
        std::fs::write(&path, text).unwrap();
        let plate = PlateModel::load(&path).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        plate
    }

    #[test]
    fn a_rectangle_on_one_vertical_node_always_ends_upright_on_it() {
        let part =
            Part::new("r".into(), vec![[0.0, 0.0], [40.0, 0.0], [40.0, 10.0], [0.0, 10.0]], vec![])
                .unwrap();
        let plate = plate();
        let body = Body::new(&part);
        let fields: Vec<FieldModel> =
            plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
        let plan = PlanFile {
            name: "r".into(),
            repeat: 1,
            steps: vec![StepJson::open_loop(60.0, 600_000, plate.modes[0].amplitude, 0)],
            final_orientation_deg: Some(90.0),
            period_deg: Some(180.0),
            final_position_mm: None,
            ..PlanFile::default()
        };
        let steps = crate::motion::steps::plan_steps(&plan, &plate).unwrap();
        let setup =
            Setup { body: &body, plate: &plate, fields: &fields, steps: &steps, feed: None };
        let calls = crate::progress::Count::default();
        let trials = run_trials(&setup, 8, 3, &calls);
        assert_eq!((calls.done(), trials.finals.len(), trials.traces.len()), (8, 8, TRACED_TRIALS));
        assert_eq!(trials.examples.len(), EXAMPLE_TRIALS);
        // Same seed, same starts.
        assert_eq!(run_trials(&setup, 2, 3, &crate::progress::Silent).starts, trials.starts[..2]);
        let stats = statistics(&trials, &plan, 5.0);
        assert_eq!(stats.success_rate, Some(1.0));
        assert!(stats.orientation_error_deg.unwrap().max < 1.0, "{stats:?}");
        assert!(stats.position_error_mm.is_none());
        assert!((stats.mean_position_mm[0] - 150.0).abs() < 0.5, "{stats:?}");
        let report = Report::new(&stats, &plan, 8, 3, 5.0);
        let v = serde_json::to_value(&report).unwrap();
        let keys: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
        assert_eq!(keys.len(), 14);
        // The simulated final pose: at the node, at the predicted orientation.
        let (t, p) = plan.final_orientation_deg.zip(plan.period_deg).unwrap();
        let mean = v["mean_final_orientation_deg"].as_f64().unwrap();
        assert!(crate::model::angle::signed_diff(mean, t, p).abs() < 1.0, "{v}");
        assert!((v["mean_final_position_mm"][0].as_f64().unwrap() - 150.0).abs() < 0.5, "{v}");
        assert_eq!(v["lost"], 0);
        assert_eq!(v["missed"], 0);
        assert!(v["position_error_mm"].is_null());
    }
}
