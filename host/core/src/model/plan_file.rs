//! The plan JSON file, one format for people, scripts, `chladni plan --out` and
//! `chladni device run-file`:
//!
//! ```json
//! {"name": "triangle", "repeat": 1,
//!  "steps": [{"freq_hz": 60.0, "duration_ms": 2500, "amplitude": 0.8, "ramp_ms": 20},
//!            {"freq_hz": 181.5, "duration_ms": 1500, "accel_mps2": 25.0, "ramp_ms": 20}],
//!  "final_orientation_deg": 110.7, "period_deg": 180.0, "final_position_mm": null}
//! ```
//! A step gives exactly one level: `amplitude` (fraction of full scale, open loop) or
//! `accel_mps2` (the plate's acceleration amplitude the controller holds, closed loop).
//! Converted to and from [`chladni_shared::icd::plan::Plan`] (the value the firmware stores and
//! runs): frequency Hz → mHz, amplitude 0..1 → Q15 and m/s² → mm/s² rounded to nearest (the
//! conversions of [`chladni_shared::icd::units`]), then validated against [`DeviceLimits`].
//! The planner writes open-loop steps only.

use chladni_shared::icd::plan::{DeviceLimits, Level, MAX_NAME, MAX_STEPS, Plan, PlanError, Step};
use chladni_shared::icd::units::Given;
use chladni_shared::icd::units::{FrequencyError, MilliHz, MmPerS2, Q15};
use serde::{Deserialize, Serialize};

/// Keys `chladni plan --json` prints beside the plan file's own (the step margins, the parts
/// that end overlapping, the `--copies` numbers): [`PlanFile::parse`] reads past them, so the
/// printed object saved to a file is a plan file; they are never written by `--out`.
pub(crate) const REPORT_KEYS: [&str; 8] = [
    "margins",
    "end_overlaps",
    "copies",
    "oriented",
    "lost",
    "parts_per_min",
    "candidates",
    "device_limit",
];

/// Rounds to 10⁻⁴: the plan file's resolution for orientations (degrees), also used for the
/// orientations of a failed plan's JSON.
pub fn r4(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

/// The one check of a drive frequency (Hz) against the controller's limits: the shared
/// conversion, [`MilliHz::from_hz`], and its one message.
pub(crate) fn check_drive_freq(hz: f64) -> Result<u32, FrequencyError> {
    MilliHz::from_hz(hz).map(|f| f.0)
}

/// One step as written.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepJson {
    /// Drive frequency (Hz).
    pub freq_hz: f64,
    /// Step length (ms), ramp included.
    pub duration_ms: u32,
    /// Drive amplitude, fraction of full scale (0..=1): open loop. Exactly one of this and
    /// `accel_mps2`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amplitude: Option<f64>,
    /// Acceleration amplitude the controller holds, m/s²: closed loop.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accel_mps2: Option<f64>,
    /// Amplitude (or acceleration target) ramp (ms).
    #[serde(default)]
    pub ramp_ms: u32,
}

/// The level of a plan file step, as given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StepLevel {
    /// Open loop: fraction of full scale.
    Amplitude(f64),
    /// Closed loop: acceleration target, m/s².
    AccelMps2(f64),
}

impl StepJson {
    /// An open-loop step (what the planner writes).
    pub fn open_loop(freq_hz: f64, duration_ms: u32, amplitude: f64, ramp_ms: u32) -> StepJson {
        StepJson { freq_hz, duration_ms, amplitude: Some(amplitude), accel_mps2: None, ramp_ms }
    }

    /// The step's one level; both or neither is a [`PlanFileError::Level`] naming step `step`.
    pub fn level(&self, step: usize) -> Result<StepLevel, PlanFileError> {
        match (self.amplitude, self.accel_mps2) {
            (Some(a), None) => Ok(StepLevel::Amplitude(a)),
            (None, Some(a)) => Ok(StepLevel::AccelMps2(a)),
            (amplitude, accel) => {
                Err(PlanFileError::Level { step, both: amplitude.is_some() && accel.is_some() })
            }
        }
    }

    /// The device level: Q15 or mm/s², through the shared conversions.
    fn device_level(&self, step: usize) -> Result<Level, PlanFileError> {
        match self.level(step)? {
            StepLevel::Amplitude(value) => Q15::from_fraction(value)
                .map(|q| Level::Drive(q.0))
                .map_err(|_| PlanFileError::Amplitude { step, value }),
            StepLevel::AccelMps2(value) => MmPerS2::from_mps2(value)
                .map(|a| Level::Accel(a.0))
                .map_err(|e| PlanFileError::Accel { step, message: e.to_string() }),
        }
    }
}

/// The whole file.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanFile {
    /// Name (at most 32 bytes).
    #[serde(default = "default_name")]
    pub name: String,
    /// Runs (≥ 1).
    #[serde(default = "one")]
    pub repeat: u16,
    /// Steps.
    pub steps: Vec<StepJson>,
    /// Predicted final orientation (degrees, modulo `period_deg`), informative.
    #[serde(default)]
    pub final_orientation_deg: Option<f64>,
    /// Period of the orientation (part symmetry, 180° for symmetric fields), informative.
    #[serde(default)]
    pub period_deg: Option<f64>,
    /// Predicted final centroid position (mm) when the nodes fix it, informative.
    #[serde(default)]
    pub final_position_mm: Option<[f64; 2]>,
    /// The goal orientation the plan was made for (deg, modulo `period_deg`), informative.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_deg: Option<f64>,
    /// Final orientations plans as long as this one (or one step longer) can reach (deg),
    /// informative.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reachable_deg: Option<Vec<f64>>,
    /// A plan for several parts at once: one prediction per part, in the order the parts
    /// were given (the top-level predictions are then `null`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parts: Option<Vec<PartPrediction>>,
}

/// One part's predictions in a plan for several parts (the top-level fields of a one-part
/// plan, plus the part's name).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartPrediction {
    /// The part's name.
    pub name: String,
    /// Its predicted final orientation (deg, modulo `period_deg`).
    #[serde(default)]
    pub final_orientation_deg: Option<f64>,
    /// Its period (deg).
    #[serde(default)]
    pub period_deg: Option<f64>,
    /// Its predicted final centroid (mm) when fixed.
    #[serde(default)]
    pub final_position_mm: Option<[f64; 2]>,
    /// Its goal orientation (deg).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_deg: Option<f64>,
    /// Its reachable final orientations (deg).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reachable_deg: Option<Vec<f64>>,
    /// The face on the plate, for a part planned for both faces (`"up"` or `"flipped"`;
    /// see `model::part::mirror`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face: Option<crate::model::part::mirror::Face>,
}

fn default_name() -> String {
    "plan".into()
}
fn one() -> u16 {
    1
}

/// Why a plan file cannot become a device plan.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanFileError {
    /// Not JSON of the right shape.
    #[error("not a valid plan: {0}")]
    Json(String),
    /// A frequency that is not a positive finite number of Hz the device can represent.
    #[error(
        "step {}: {} (give Hz, e.g. 60.0)",
        step + 1,
        FrequencyError::outside(*value, &DeviceLimits::DEFAULT)
    )]
    Frequency {
        /// Step index, 0-based (the message prints it 1-based, as `chladni plan` does).
        step: usize,
        /// Value.
        value: f64,
    },
    /// Amplitude outside 0..=1.
    #[error(
        "step {}: amplitude {} outside 0..=1 (fraction of full scale)",
        step + 1,
        Given(*.value)
    )]
    Amplitude {
        /// Step index, 0-based (the message prints it 1-based, as `chladni plan` does).
        step: usize,
        /// Value.
        value: f64,
    },
    /// Neither or both of `amplitude` and `accel_mps2`.
    #[error(
        "step {}: {} (give \"amplitude\": 0..1 for open loop or \"accel_mps2\": m/s² for \
         closed loop)",
        step + 1,
        if *both { "both amplitude and accel_mps2" } else { "no amplitude or accel_mps2" }
    )]
    Level {
        /// Step index, 0-based (the message prints it 1-based, as `chladni plan` does).
        step: usize,
        /// Both were given (else neither).
        both: bool,
    },
    /// An acceleration target that is not a non-negative number of m/s².
    #[error("step {}: {message}", step + 1)]
    Accel {
        /// Step index, 0-based (the message prints it 1-based, as `chladni plan` does).
        step: usize,
        /// The conversion's message.
        message: String,
    },
    /// Name longer than the device stores.
    #[error("name \"{0}\" is longer than {MAX_NAME} bytes")]
    NameTooLong(String),
    /// More steps than a plan can hold.
    #[error("{0} steps: a plan holds at most {MAX_STEPS}")]
    TooManySteps(usize),
    /// Refused by the device limits.
    #[error("{0}")]
    Invalid(PlanError),
}

impl PlanFileError {
    /// What only the controller limits (a plan's hour, its step count, the drive's frequency
    /// and level ranges, the stored name), with the fix; `None` for a plan no run can take.
    pub fn device_limit_fix(&self) -> Option<&'static str> {
        match self {
            PlanFileError::Invalid(PlanError::TooLong { .. }) => Some(
                "shorten it: measure the plate's real speed (`chladni plate calibrate-speed`; \
                 the durations scale as 1/speed_mm_s, and the plate file's default 10 mm/s is \
                 no measurement), feed the parts into a region (`--feed`), plan on another \
                 plate, use fewer repeats or a lower --safety; or split it into plans of at \
                 most an hour",
            ),
            PlanFileError::Invalid(PlanError::TooManySteps { .. })
            | PlanFileError::TooManySteps(_) => Some("split it into several plans"),
            PlanFileError::Invalid(PlanError::FrequencyOutOfRange { .. }) => {
                Some("plan with modes between 1 and 2000 Hz")
            }
            PlanFileError::Invalid(
                PlanError::AmplitudeTooHigh { .. } | PlanError::AccelTooHigh { .. },
            ) => Some("lower the step's level"),
            PlanFileError::NameTooLong(_) => Some("give the plan a shorter name"),
            _ => None,
        }
    }
}

impl PlanFile {
    /// Research first: a plan only a simulation will run may pass the controller's limits
    /// ([`PlanFileError::device_limit_fix`]). `Ok(Some(warning))` names the limit and that
    /// `chladni device upload` refuses it, with the fix; `Err` for what no run can take.
    pub fn device_limit_warning(
        &self,
        limits: &DeviceLimits,
    ) -> Result<Option<String>, PlanFileError> {
        match self.to_plan(limits) {
            Ok(_) => Ok(None),
            Err(e) => match e.device_limit_fix() {
                Some(fix) => Ok(Some(format!(
                    "{e}: the controller refuses this plan at `chladni device upload`; {fix}"
                ))),
                None => Err(e),
            },
        }
    }

    /// Parses JSON text.
    pub fn parse(text: &str) -> Result<PlanFile, PlanFileError> {
        if let Some(kind) = crate::model::json_top::not_an_object(text) {
            return Err(PlanFileError::Json(format!(
                "the file is {kind}; a plan file is one JSON object: {{\"steps\": [{{\"freq_hz\": …, \
                 \"duration_ms\": …, \"amplitude\": …}}, …]}} (docs/plan.md, \"Plan file\")"
            )));
        }
        let strict = serde_json::from_str(text).map_err(|e| PlanFileError::Json(e.to_string()));
        let Err(refused) = strict else { return strict };
        // `plan --json` prints the plan file with its report keys beside it: that output saved
        // to a file is a plan file too. Any other unknown key is still refused, with the strict
        // parse's error (it has the line and column) when no report key is there.
        let Ok(serde_json::Value::Object(mut object)) = serde_json::from_str(text) else {
            return Err(refused);
        };
        if !REPORT_KEYS.iter().any(|k| object.contains_key(*k)) {
            return Err(refused);
        }
        object.retain(|k, _| !REPORT_KEYS.contains(&k.as_str()));
        // Refused without the report keys: that error names the real offender.
        serde_json::from_value(serde_json::Value::Object(object))
            .map_err(|e| PlanFileError::Json(e.to_string()))
    }

    /// The device plan, validated against `limits`.
    pub fn to_plan(&self, limits: &DeviceLimits) -> Result<Plan, PlanFileError> {
        if self.steps.len() > MAX_STEPS {
            return Err(PlanFileError::TooManySteps(self.steps.len()));
        }
        let mut steps = heapless::Vec::new();
        for (i, s) in self.steps.iter().enumerate() {
            let Some(MilliHz(freq_mhz)) = MilliHz::rounded(s.freq_hz) else {
                return Err(PlanFileError::Frequency { step: i, value: s.freq_hz });
            };
            let step = Step {
                freq_mhz,
                level: s.device_level(i)?,
                duration_ms: s.duration_ms,
                ramp_ms: s.ramp_ms,
            };
            // Capacity checked above.
            let _ = steps.push(step);
        }
        let name = heapless::String::try_from(self.name.as_str())
            .map_err(|_| PlanFileError::NameTooLong(self.name.clone()))?;
        let plan = Plan { name, repeat: self.repeat, steps };
        plan.validate(limits).map_err(PlanFileError::Invalid)?;
        Ok(plan)
    }

    #[cfg(test)]
    /// The file form of a device plan (no predictions).
    pub(crate) fn from_plan(plan: &Plan) -> PlanFile {
        PlanFile {
            name: plan.name.to_string(),
            repeat: plan.repeat,
            steps: plan
                .steps
                .iter()
                .map(|s| {
                    let (amplitude, accel_mps2) = match s.level {
                        // Six decimals: enough to round back to the same Q15 step.
                        Level::Drive(q15) => {
                            (Some((Q15(q15).to_fraction() * 1e6).round() / 1e6), None)
                        }
                        Level::Accel(mm) => (None, Some(MmPerS2(mm).to_mps2())),
                    };
                    StepJson {
                        freq_hz: MilliHz(s.freq_mhz).to_hz(),
                        duration_ms: s.duration_ms,
                        amplitude,
                        accel_mps2,
                        ramp_ms: s.ramp_ms,
                    }
                })
                .collect(),
            ..PlanFile::default()
        }
    }

    /// The plan as seen by one part: part `i`'s predictions at the top level (for
    /// `chladni simulate` and its statistics); a one-part plan is itself for `i = 0`.
    pub fn for_part(&self, i: usize) -> Option<PlanFile> {
        let Some(parts) = &self.parts else {
            return (i == 0).then(|| self.clone());
        };
        let p = parts.get(i)?;
        Some(PlanFile {
            final_orientation_deg: p.final_orientation_deg,
            period_deg: p.period_deg,
            final_position_mm: p.final_position_mm,
            goal_deg: p.goal_deg,
            reachable_deg: p.reachable_deg.clone(),
            parts: None,
            ..self.clone()
        })
    }

    /// The documented JSON object (the derived serialisation): steps,
    /// final_orientation_deg, period_deg, final_position_mm (null when not fixed), name,
    /// repeat.
    pub fn to_json(&self) -> serde_json::Value {
        // Serialising plain numbers, strings and options into a Value cannot fail.
        serde_json::to_value(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_through_the_device_plan() {
        let text = r#"{"name": "t", "steps": [{"freq_hz": 60.0004, "duration_ms": 500, "amplitude": 0.5, "ramp_ms": 20},
            {"freq_hz": 181.5, "duration_ms": 700, "amplitude": 1.0}], "final_orientation_deg": 90.0,
            "period_deg": 180.0, "final_position_mm": null}"#;
        let f = PlanFile::parse(text).unwrap();
        let p = f.to_plan(&DeviceLimits::DEFAULT).unwrap();
        assert_eq!(p.repeat, 1);
        assert_eq!(p.steps[0].freq_mhz, 60_000);
        assert_eq!(p.steps[0].level, Level::Drive(16384));
        assert_eq!(p.steps[1].ramp_ms, 0);
        assert_eq!(p.steps[1].level, Level::Drive(32767));
        let back = PlanFile::from_plan(&p);
        assert_eq!(back.steps[1].freq_hz, 181.5);
        assert_eq!(back.to_plan(&DeviceLimits::DEFAULT).unwrap(), p);
        let v = f.to_json();
        assert!(v["final_position_mm"].is_null());
        assert_eq!(v["steps"][0].as_object().unwrap().len(), 4);
        assert!(v["steps"][0].get("accel_mps2").is_none(), "open-loop steps write no accel");
    }

    #[test]
    fn the_printed_report_keys_are_read_past_and_any_other_unknown_key_refused() {
        let plan = r#""name": "t", "steps": [{"freq_hz": 60.0, "duration_ms": 500, "amplitude": 0.5}],
            "final_orientation_deg": 90.0, "period_deg": 180.0, "final_position_mm": null"#;
        let printed = format!(r#"{{{plan}, "margins": [{{"step": 0}}], "end_overlaps": []}}"#);
        let f = PlanFile::parse(&printed).expect("plan --json's output is a plan file");
        assert_eq!((f.name.as_str(), f.steps.len()), ("t", 1));
        for bad in [
            format!(r#"{{{plan}, "margins": [], "colour": 1}}"#),
            format!(r#"{{{plan}, "colour": 1}}"#),
        ] {
            let Err(PlanFileError::Json(e)) = PlanFile::parse(&bad) else { panic!("{bad}") };
            assert!(e.contains("unknown field `colour`"), "{e}");
        }
    }

    #[test]
    fn closed_loop_steps_convert_once_and_round_trip() {
        let text = r#"{"name": "c", "steps": [{"freq_hz": 181.5, "duration_ms": 900, "accel_mps2": 25.0004, "ramp_ms": 30},
            {"freq_hz": 60.0, "duration_ms": 500, "amplitude": 0.25}]}"#;
        let p = PlanFile::parse(text).unwrap().to_plan(&DeviceLimits::DEFAULT).unwrap();
        assert_eq!(p.steps[0].level, Level::Accel(25_000));
        assert_eq!(p.steps[1].level, Level::Drive(8192));
        let back = PlanFile::from_plan(&p);
        assert_eq!(back.steps[0].accel_mps2, Some(25.0));
        assert_eq!(back.steps[0].amplitude, None);
        assert_eq!(back.steps[1].level(1), Ok(StepLevel::Amplitude(0.250008)));
        assert_eq!(back.to_plan(&DeviceLimits::DEFAULT).unwrap(), p);
        let v = back.to_json();
        let keys: Vec<&str> =
            v["steps"][0].as_object().unwrap().keys().map(|k| k.as_str()).collect();
        assert_eq!(keys, ["accel_mps2", "duration_ms", "freq_hz", "ramp_ms"]);
        // Above the device's acceleration limit: refused by the limits, naming the step.
        let high = r#"{"steps": [{"freq_hz": 60.0, "duration_ms": 5, "amplitude": 0.1},
            {"freq_hz": 60.0, "duration_ms": 5, "accel_mps2": 150.0}]}"#;
        let err = PlanFile::parse(high).unwrap().to_plan(&DeviceLimits::DEFAULT).unwrap_err();
        assert_eq!(
            err,
            PlanFileError::Invalid(PlanError::AccelTooHigh {
                step: 1,
                accel_mmps2: 150_000,
                max_mmps2: 100_000
            })
        );
        assert_eq!(
            err.to_string(),
            "step 2: acceleration target 150.000 m/s² above the maximum 100.000 m/s²"
        );
    }

    #[test]
    fn a_step_gives_exactly_one_level() {
        let both = r#"{"freq_hz": 60.0, "duration_ms": 5, "amplitude": 0.5, "accel_mps2": 2.0}"#;
        let text = format!(r#"{{"steps": [{both}]}}"#);
        let err = PlanFile::parse(&text).unwrap().to_plan(&DeviceLimits::DEFAULT).unwrap_err();
        assert_eq!(err, PlanFileError::Level { step: 0, both: true });
        assert!(
            err.to_string().starts_with("step 1: both amplitude and accel_mps2 (give"),
            "{err}"
        );
        let neither = r#"{"freq_hz": 60.0, "duration_ms": 5, "amplitude": 0.5}"#;
        let text = format!(r#"{{"steps": [{neither}, {{"freq_hz": 60.0, "duration_ms": 5}}]}}"#);
        let err = PlanFile::parse(&text).unwrap().to_plan(&DeviceLimits::DEFAULT).unwrap_err();
        assert_eq!(err, PlanFileError::Level { step: 1, both: false });
        assert!(err.to_string().contains("step 2: no amplitude or accel_mps2"), "{err}");
        let neg = r#"{"steps": [{"freq_hz": 60.0, "duration_ms": 5, "accel_mps2": -3.0}]}"#;
        let err = PlanFile::parse(neg).unwrap().to_plan(&DeviceLimits::DEFAULT).unwrap_err();
        assert!(matches!(err, PlanFileError::Accel { step: 0, .. }), "{err:?}");
        assert!(err.to_string().contains("acceleration -3 m/s²"), "{err}");
        // A wrong type is a JSON error.
        assert!(matches!(
            PlanFile::parse(
                r#"{"steps": [{"freq_hz": 60.0, "duration_ms": 5, "accel_mps2": "x"}]}"#
            ),
            Err(PlanFileError::Json(_))
        ));
    }

    #[test]
    fn typed_errors() {
        let one = |s: &str| {
            PlanFile::parse(&format!("{{\"steps\": [{s}]}}"))
                .and_then(|f| f.to_plan(&DeviceLimits::DEFAULT))
                .unwrap_err()
        };
        assert_eq!(
            one(r#"{"freq_hz": 60.0, "duration_ms": 5, "amplitude": 1.5}"#),
            PlanFileError::Amplitude { step: 0, value: 1.5 }
        );
        assert!(matches!(
            one(r#"{"freq_hz": -1.0, "duration_ms": 5, "amplitude": 0.5}"#),
            PlanFileError::Frequency { step: 0, .. }
        ));
        assert!(matches!(
            one(r#"{"freq_hz": 0.5, "duration_ms": 5, "amplitude": 0.5}"#),
            PlanFileError::Invalid(PlanError::FrequencyOutOfRange { step: 0, freq_mhz: 500, .. })
        ));
        assert!(matches!(
            one(r#"{"freq_hz": 60.0, "duration_ms": 0, "amplitude": 0.5}"#),
            PlanFileError::Invalid(PlanError::ZeroDuration { step: 0 })
        ));
        assert!(matches!(
            one(r#"{"freq_mhz": 60000, "duration_ms": 5, "amplitude": 0.5}"#),
            PlanFileError::Json(_)
        ));
        let long = format!(r#"{{"name": "{}", "steps": []}}"#, "x".repeat(40));
        assert!(matches!(
            PlanFile::parse(&long).unwrap().to_plan(&DeviceLimits::DEFAULT),
            Err(PlanFileError::NameTooLong(_))
        ));
    }

    #[test]
    fn a_plan_over_the_hour_is_a_warning_naming_the_limit_length_and_fix() {
        let two_h = r#"{"steps": [{"freq_hz": 60.0, "duration_ms": 4000000, "amplitude": 0.5},
                                  {"freq_hz": 90.0, "duration_ms": 3200000, "amplitude": 0.5}]}"#;
        let file = PlanFile::parse(two_h).unwrap();
        let w = file.device_limit_warning(&DeviceLimits::DEFAULT).unwrap().expect("a warning");
        for needed in ["7200000 ms", "3600000 ms", "plate calibrate-speed", "--feed", "another"] {
            assert!(w.contains(needed), "{needed}: {w}");
        }
        // `plan --json`'s key (built in shapes::plan; host/cli/tests/integration/cli_plan.rs checks it there).
        let json =
            serde_json::json!({"warning": w, "plan_ms": 7_200_000, "max_total_ms": 3_600_000});
        // Saved `plan --json` output with the key still reads as a plan file.
        let mut saved: serde_json::Value = serde_json::from_str(two_h).unwrap();
        saved["device_limit"] = json;
        assert_eq!(PlanFile::parse(&saved.to_string()).unwrap().steps.len(), 2);
        // An hour exactly is no warning.
        let hour = r#"{"steps": [{"freq_hz": 60.0, "duration_ms": 3600000, "amplitude": 0.5}]}"#;
        assert_eq!(
            PlanFile::parse(hour).unwrap().device_limit_warning(&DeviceLimits::DEFAULT).unwrap(),
            None
        );
    }
}
