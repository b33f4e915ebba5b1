//! The data the commands hand to researchers, one home for their shapes: JSON objects and CSV
//! rows that `analyze --samples/--csv`, `simulate --poses/--traces` and the string model print,
//! and the `--json` object of a failed plan ([`plan_failure_json`]).
//! Keys are snake_case with their unit in the name (`_deg`, `_mm`, `_s`); steps are numbered
//! from 1, as `plan` prints them. Every file is written atomically ([`chladni_core::output`]).

use chladni_core::model::angle::wrap_deg;
use std::path::Path;

use serde::Serialize;

use chladni_core::model::plan_file::r4;
use chladni_core::model::pose::Pose;
use chladni_core::motion::montecarlo::{Report, Trials};
use chladni_core::output::{OutputError, write_with};
use chladni_core::planner::PlanFailure;

pub use chladni_core::analysis::samples::TurnSample;

pub mod analyze;
pub mod capture;
pub mod failure;
pub mod plan;
pub mod plate;

/// A pose in the plate's frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct PoseJson {
    /// Centroid x (mm).
    pub x_mm: f64,
    /// Centroid y (mm).
    pub y_mm: f64,
    /// Orientation (degrees, [0, 360)).
    pub theta_deg: f64,
}

impl PoseJson {
    /// From (x mm, y mm, θ radians).
    pub(crate) fn from_mm_rad(x: f64, y: f64, theta_rad: f64) -> Self {
        PoseJson { x_mm: x, y_mm: y, theta_deg: wrap_deg(theta_rad.to_degrees()) }
    }
}

/// One Monte Carlo trial of `simulate --poses`: where it started and where each step left it.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct TrialPoses {
    /// Trial number, from 1.
    pub trial: usize,
    /// The start pose.
    pub start: PoseJson,
    /// The pose at the end of each step (`steps[k]` ends step k + 1).
    pub steps: Vec<PoseJson>,
    /// The pose after the last step.
    pub end: PoseJson,
}

/// One line of `simulate --traces F.jsonl`: one trial's trajectory, sampled at the
/// integrator's output times.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct TraceLine {
    /// The part's name.
    pub part: String,
    /// Trial number, from 1.
    pub trial: usize,
    /// Samples `[t (s), step (from 1), x (mm), y (mm), θ (deg, unwrapped)]`.
    pub samples: Vec<[f64; 5]>,
}

/// `simulate --poses`: every trial's start, each step's end and its end, trials from 1.
pub fn trial_poses(trials: &Trials) -> Vec<TrialPoses> {
    let pose = |p: &Pose| PoseJson::from_mm_rad(p.x, p.y, p.theta);
    (trials.starts.iter().zip(&trials.finals).enumerate())
        .map(|(i, (start, end))| TrialPoses {
            trial: i + 1,
            start: pose(start),
            steps: trials
                .examples
                .get(i)
                .map_or(Vec::new(), |p| p.iter().skip(1).map(pose).collect()),
            end: pose(end),
        })
        .collect()
}

/// `simulate --traces`: one line per kept trace, step numbers from 1, θ unwrapped (a turn
/// through 360° reads 361°, not 1°).
pub fn trace_lines(trials: &Trials, part: &str) -> Vec<TraceLine> {
    (trials.traces.iter().enumerate())
        .map(|(i, trace)| {
            let mut theta: Vec<f64> = Vec::with_capacity(trace.len());
            for (_, p) in trace {
                let d = p.theta.to_degrees();
                theta.push(match theta.last() {
                    Some(&prev) => prev + chladni_core::model::angle::signed_diff(d, prev, 360.0),
                    None => d,
                });
            }
            let samples = (trace.iter().zip(theta))
                .map(|(&(t, p), th)| {
                    let step = trials.step_ends.iter().take_while(|&&e| e < t).count() + 1;
                    let step = step.min(trials.step_ends.len().max(1));
                    [t, step as f64, p.x, p.y, th]
                })
                .collect();
            TraceLine { part: part.to_string(), trial: i + 1, samples }
        })
        .collect()
}

/// One part's `simulate --json` report, with the trials' poses under `--poses`.
#[derive(Debug, Clone, Serialize)]
pub struct SimulateReport {
    /// The statistics.
    #[serde(flatten)]
    pub report: Report,
    /// Every trial's poses (`--poses`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub poses: Option<Vec<TrialPoses>>,
}

/// Writes `rows` as CSV with a header row (the field names) to `path`, atomically.
pub fn write_csv<T: Serialize>(path: &Path, rows: &[T]) -> Result<(), OutputError> {
    write_with(path, |tmp| -> Result<(), String> {
        let mut w = csv::Writer::from_path(tmp).map_err(|e| e.to_string())?;
        for r in rows {
            w.serialize(r).map_err(|e| e.to_string())?;
        }
        w.flush().map_err(|e| e.to_string())
    })
}

/// Writes one JSON object per line to `path`, atomically.
pub fn write_jsonl<T: Serialize>(path: &Path, lines: &[T]) -> Result<(), OutputError> {
    write_with(path, |tmp| -> Result<(), String> {
        let mut text = String::new();
        for l in lines {
            text += &serde_json::to_string(l).map_err(|e| e.to_string())?;
            text.push('\n');
        }
        std::fs::write(tmp, text).map_err(|e| e.to_string())
    })
}

/// The `--json` object of a failed plan (`chladni plan --json`): `error` (the failure's name),
/// `message`, and the failure's data (an unreachable goal: `reachable_deg` and `nearest_deg`).
pub fn plan_failure_json(e: &PlanFailure) -> serde_json::Value {
    use serde_json::json;
    let mut v = match e {
        PlanFailure::NoPlan(_) => json!({"error": "no_plan"}),
        PlanFailure::Model(_) => json!({"error": "model"}),
        PlanFailure::GoalUnreachable {
            part,
            goal_deg,
            period_deg,
            tol_deg,
            max_steps,
            reachable_deg,
            nearest_deg,
        } => json!({"error": "goal_unreachable", "part": part, "goal_deg": goal_deg,
            "period_deg": period_deg, "tolerance_deg": tol_deg, "max_steps": max_steps,
            "reachable_deg": reachable_deg.iter().map(|&d| r4(d)).collect::<Vec<_>>(),
            "nearest_deg": nearest_deg.map(r4)}),
        PlanFailure::PositionNotFixed { part, max_steps, tol_mm } => json!({
            "error": "position_not_fixed", "part": part, "max_steps": max_steps,
            "tolerance_mm": tol_mm}),
        PlanFailure::PositionNotConfirmed { part, predicted_mm, worst_mm } => json!({
            "error": "position_not_confirmed", "part": part, "predicted_mm": predicted_mm,
            "worst_mm": worst_mm}),
        PlanFailure::PartsApart { apart, searched, max_steps } => json!({
            "error": "parts_apart", "searched": searched, "max_steps": max_steps,
            "apart": apart.iter().map(|(n, d, p)| json!({"part": n, "orientations_deg": d,
                "period_deg": p})).collect::<Vec<_>>()}),
        PlanFailure::NotWholePlate(n) => {
            json!({"error": "not_whole_plate", "part": n.part, "drops": n.drops,
            "failed": n.failed, "held_share": r4(1.0 - n.failed as f64 / n.drops.max(1) as f64),
            "failed_region_mm": n.region_mm, "ends": n.ends, "rounds": n.rounds,
            "max_rounds": n.max_rounds, "feed_mm": n.feed_mm, "together": n.together,
            "capture_zone": n.capture.as_ref().map(capture::in_zone_json)})
        }
        PlanFailure::OutOfTime { limit_s, stage } => {
            json!({"error": "out_of_time", "max_time_s": limit_s, "stage": stage})
        }
    };
    v["message"] = json!(e.to_string());
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_has_a_header_and_one_row_per_sample() {
        let d = std::env::temp_dir().join(format!("chladni-shapes-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let f = d.join("s.csv");
        let rows = [
            TurnSample { theta_deg: 0.0, turn: 0.5, alignment_deg: 90.0 },
            TurnSample { theta_deg: 1.0, turn: -0.25, alignment_deg: 90.0 },
        ];
        write_csv(&f, &rows).unwrap();
        let text = std::fs::read_to_string(&f).unwrap();
        assert_eq!(text, "theta_deg,turn,alignment_deg\n0.0,0.5,90.0\n1.0,-0.25,90.0\n");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
