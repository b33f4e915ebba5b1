//! The `chladni analyze --json` object: the part's rest orientations in one field law, its
//! period, and with `--samples N` the turn and alignment functions (docs/analyze.md). Keys in
//! alphabetical order, as printed.

use serde::Serialize;

use crate::shapes::TurnSample;

/// The `analyze --json` object.
#[derive(Debug, Serialize)]
pub struct AnalyzeJson<'a> {
    /// The field law's name (`--field`).
    pub field: &'static str,
    /// Every orientation is a rest (the part is free to turn).
    pub neutral: bool,
    pub part: &'a str,
    pub period_deg: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub samples: Option<Vec<TurnSample>>,
    pub stable_deg: Vec<f64>,
    pub unstable_deg: Vec<f64>,
}
