//! The `--json` objects of `chladni plan` and `chladni simulate` beyond the plan file and the
//! simulate report: the bulk numbers of `plan --copies N` ([`with_bulk`]), one entry per part
//! of a several-part simulation ([`PartReport`], [`parts_json`]) and a refused drop of parts
//! together ([`cannot_place_json`]), the parts a plan ends on top of each other
//! ([`end_overlaps_json`]) and the margin each step kept ([`with_margins`]). Keys in alphabetical order, as printed.

use serde::Serialize;
use serde_json::{Value, json};

use crate::shapes::SimulateReport;
use chladni_core::model::part::Part;
use chladni_core::model::part::mirror::Face;
use chladni_core::model::plan_file::{PlanFile, r4};
use chladni_core::motion::bulk::CannotPlace;
use chladni_core::planner::PlannedStep;
use chladni_core::planner::collide::EndOverlap;
use chladni_core::planner::copies::Ranked;

/// The plan's JSON with the chosen candidate's bulk numbers (`copies`, `oriented`, `lost`,
/// `parts_per_min`) and every candidate's (`candidates`); unchanged without `--copies`.
pub fn with_bulk(mut json: Value, ranked: &Option<Ranked>) -> Value {
    let Some(r) = ranked else { return json };
    let c = &r.candidates[r.chosen].report;
    json["copies"] = json!(c.copies);
    json["oriented"] = json!(c.oriented);
    json["lost"] = json!(c.lost);
    json["parts_per_min"] = json!(c.parts_per_min);
    json["candidates"] = r
        .candidates
        .iter()
        .map(|s| {
            json!({
                "final_orientation_deg": s.file.final_orientation_deg,
                "plan_s": s.report.plan_s, "oriented": s.report.oriented,
                "lost": s.report.lost, "parts_per_min": s.report.parts_per_min,
            })
        })
        .collect();
    json
}

/// One part's `chladni simulate --json` entry in a plan for several parts (or faces).
#[derive(Debug, Serialize)]
pub struct PartReport<'a> {
    /// The face, for a part simulated on both faces.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub face: Option<Face>,
    pub part: &'a str,
    #[serde(flatten)]
    pub report: SimulateReport,
}

/// `simulate --json` for several parts or faces: `{"parts": [{"part", "face"?, …report}]}`.
pub fn parts_json(entries: &[PartReport<'_>]) -> Value {
    json!({ "parts": entries })
}

/// The `--json` failure of a drop that could not place every part (`cannot_place`).
pub fn cannot_place_json(e: &CannotPlace) -> Value {
    json!({
        "error": "cannot_place", "parts": e.parts, "placed": e.placed,
        "attempts": e.attempts, "message": e.to_string(),
    })
}

/// `end_overlaps` of a plan for several parts: `[{"depth_mm", "parts": [a, b]}]`, the pairs
/// whose predicted end poses overlap ([`chladni_core::planner::collide`]).
pub fn end_overlaps_json(parts: &[Part], found: &[EndOverlap]) -> Value {
    let list = found.iter().map(|o| {
        json!({
            "depth_mm": r4(o.depth_mm),
            "parts": [parts[o.a].name, parts[o.b].name],
        })
    });
    Value::Array(list.collect())
}

/// `plan --json` with the margin each step kept and where it came from, as `"margins":
/// [{"step", "mode", "deg", "source", …}]` beside the plan file's keys (docs/plan.md,
/// "Margins from evidence"; steps and modes numbered from 1).
pub fn with_margins(mut json: Value, steps: &[PlannedStep]) -> Value {
    let m: Vec<Value> = steps
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let mut v = s.margin.to_json();
            v["step"] = (i + 1).into();
            v["mode"] = (s.mode + 1).into();
            v
        })
        .collect();
    json["margins"] = m.into();
    json
}

/// `plan --json` of a whole-plate plan on grid modes with what its drops over the plate gave,
/// as `"whole_plate": {"checked": true, "drops", "held", "held_share", "rounds", "together",
/// "parts": [{"part", "drops", "held", "failed"}]}` (one entry per part, each face of a part
/// that flips one; docs/plan.md, "Whole-plate plans on grid modes"), or `{"checked": false,
/// "why"}` when the parts could not be dropped together; unchanged when the plan was not
/// checked so.
pub fn with_whole_plate(
    mut json: Value,
    whole: Option<&chladni_core::planner::whole::WholePlate>,
) -> Value {
    match whole {
        Some(w) if w.checked => {
            let parts: Vec<Value> = w
                .parts
                .iter()
                .map(|p| {
                    json!({"part": p.name, "drops": p.drops, "held": p.held,
                    "failed": p.drops - p.held})
                })
                .collect();
            json["whole_plate"] = json!({"checked": true, "drops": w.drops, "held": w.held,
                "held_share": r4(w.held as f64 / w.drops.max(1) as f64), "rounds": w.rounds,
                "together": w.together, "parts": parts});
        }
        Some(w) => json["whole_plate"] = json!({"checked": false, "why": w.describe()}),
        None => {}
    }
    json
}

/// `device_limit` of `plan --json` when the plan exceeds a controller limit (research first:
/// a warning, not a failure): `{"warning", "plan_ms", "max_total_ms"}`, the warning naming the
/// limit, the plan's length and the fix ([`PlanFile::device_limit_warning`]).
pub fn device_limit_json(warning: &str, file: &PlanFile, max_total_ms: u64) -> Value {
    let plan_ms: u64 =
        file.steps.iter().map(|s| u64::from(s.duration_ms)).sum::<u64>() * u64::from(file.repeat);
    json!({ "warning": warning, "plan_ms": plan_ms, "max_total_ms": max_total_ms })
}
