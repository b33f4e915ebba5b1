//! The one `--json` object of a failed command, `{"error": kind, "message": …}`: what every
//! command prints on stdout when it fails with `--json` (the commands with data of their own
//! add keys: [`crate::shapes::plan_failure_json`], [`crate::shapes::plan::cannot_place_json`]).

use serde::Serialize;

/// A failure's `--json` object: its snake_case name and the message people read.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FailureJson<'a> {
    /// The failure's name (`bad_input`, `no_plan`, `link`, …; each command documents its own).
    pub error: &'a str,
    /// The error's text.
    pub message: String,
}

impl<'a> FailureJson<'a> {
    /// Of the failure's name and its message (trailing white space trimmed).
    pub fn new(error: &'a str, message: &str) -> Self {
        FailureJson { error, message: message.trim_end().to_string() }
    }
}
