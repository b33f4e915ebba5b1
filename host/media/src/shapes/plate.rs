//! The `--json` objects of the plate commands: `plate modes` ([`ModesJson`]), `plate
//! from-photo` ([`photo_json`]), `plate suggest` ([`suggest_json`]) and `plate
//! calibrate-speed` ([`calibrate_json`]). Keys in alphabetical order, as printed (the `json!`
//! objects sort their keys; the structs declare theirs in that order).

use std::path::Path;

use serde::Serialize;
use serde_json::{Value, json};

use chladni_core::model::plan_file::r4;
use chladni_core::model::plate::Mode;
use chladni_core::plate::calibrate::Fit;
use chladni_core::plate::photo::{self, job::PhotoGrid};
use chladni_core::plate::suggest;

/// The `--json` object of `plate modes`.
#[derive(Debug, Serialize)]
pub struct ModesJson {
    pub modes: Vec<ModeJson>,
}

/// One mode in [`ModesJson`]: its name ("mode 4", or "modes 4+5" for a degenerate pair
/// driven at `drive_mm`) and, with a drive point, its excitation.
#[derive(Debug, Serialize)]
pub struct ModeJson {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub excitation: Option<f64>,
    pub freq_hz: f64,
    pub lambda: f64,
    pub name: String,
}

/// The `plate from-photo --json` object: the threshold and pixel counts, each line and curve
/// found, and the grid node (null when none was asked for, `{"error"}` when it failed).
pub fn photo_json(found: &photo::Found, grid: Option<&PhotoGrid>) -> Value {
    let lines: Vec<_> = found
        .lines
        .iter()
        .map(|l| {
            json!({"angle_deg": l.angle_deg, "offset_mm": l.offset_mm, "rms_mm": l.rms_mm,
                   "length_mm": l.length_mm, "pixels": l.pixels, "ends_mm": l.ends_mm})
        })
        .collect();
    let curves: Vec<_> = found
        .curves
        .iter()
        .map(|c| {
            json!({"points": c.points, "length_mm": c.length_mm, "rms_mm": c.rms_mm,
                   "pixels": c.pixels})
        })
        .collect();
    let grid = match grid {
        None => Value::Null,
        Some(Ok(f)) => json!({"nx": f.grid.nx, "ny": f.grid.ny, "signed": f.signed,
                              "regions": f.regions, "note": f.note}),
        Some(Err(e)) => json!({"error": e.to_string()}),
    };
    json!({"threshold": found.threshold, "sand_is_dark": found.sand_is_dark,
           "skeleton_pixels": found.skeleton_pixels, "unexplained_pixels": found.unexplained_pixels,
           "lines": lines, "curves": curves, "grid": grid})
}

/// The `plate suggest --json` object: the part, the plate and every candidate's row
/// ([`suggest_row_json`]).
pub fn suggest_json(part: &str, plate: &str, rows: &[suggest::Row]) -> Value {
    let rows: Vec<Value> = rows.iter().map(suggest_row_json).collect();
    json!({"part": part, "plate": plate, "rows": rows})
}

/// One `plate suggest --json` row: `drive_mm`, `clamps_mm`, `modes`, `wall_s`, `same_as` and
/// the outcome: `"plan"` with `steps`, `total_s`, `final_orientation_deg`, `period_deg` and
/// `whole_plate` (the key of `plan --json`, [`super::plan::with_whole_plate`]); `"no_plan"`
/// with `why` and `reason` (a `not_whole_plate` row adds `drops`, `held`, `held_share` and
/// `feed_mm`, as in `plan`'s failure); or `"not_tried"`.
pub fn suggest_row_json(r: &suggest::Row) -> Value {
    let c = &r.candidate;
    let mut v = json!({"drive_mm": c.drive_mm, "clamps_mm": c.clamps_mm, "modes": r.modes,
        "wall_s": r.wall_s, "same_as": r.same_as});
    match &r.outcome {
        suggest::Outcome::Plan(f) => {
            v["outcome"] = json!("plan");
            v["steps"] = json!(f.steps);
            v["total_s"] = json!(f.total_s);
            v["final_orientation_deg"] = json!(f.final_orientation_deg);
            v["period_deg"] = json!(f.period_deg);
            v = super::plan::with_whole_plate(v, f.whole_plate.as_ref());
        }
        suggest::Outcome::NoPlan { why, reason } => {
            v["outcome"] = json!("no_plan");
            v["why"] = json!(why.name());
            v["reason"] = json!(reason);
            if let suggest::Why::NotWholePlate(h) = why {
                v["drops"] = json!(h.drops);
                v["held"] = json!(h.held);
                v["held_share"] = json!(r4(h.share()));
                v["feed_mm"] = json!(h.feed_mm);
            }
        }
        suggest::Outcome::NotTried => v["outcome"] = json!("not_tried"),
    }
    v
}

/// What `plate calibrate-speed` fitted, for [`calibrate_json`].
pub struct Calibrated<'a, S: Serialize> {
    /// The plate file.
    pub plate: &'a Path,
    /// The mode fitted (its speed before the fit).
    pub mode: &'a Mode,
    /// How near a simulated end must come to an observed one (mm).
    pub within_mm: f64,
    /// The fit.
    pub fit: &'a Fit,
    /// The file written (none with `--dry-run`).
    pub written: Option<&'a str>,
    /// With `--photos`: what each photo showed (null without).
    pub photos: Option<&'a S>,
}

/// The `plate calibrate-speed --json` object.
pub fn calibrate_json<S: Serialize>(c: &Calibrated<'_, S>) -> Value {
    let (m, fit) = (c.mode, c.fit);
    json!({"plate": c.plate, "mode": m.name, "freq_hz": m.freq_hz,
        "previous_speed_mm_s": m.speed_mm_s, "within_mm": c.within_mm,
        "speed_mm_s": fit.speed_mm_s, "method": fit.method,
        "rms_time_s": fit.rms_time_s, "rms_pose_mm": fit.rms_pose_mm,
        "residuals": fit.residuals, "written": c.written,
        "photos": c.photos})
}
