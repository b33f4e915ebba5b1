//! The planner's time limit (`chladni plan --max-time-s`): planning stops with
//! [`PlanFailure::OutOfTime`] once it has passed, so a user never waits minutes without an
//! answer. It is checked between the stages that take time (each mode's step map, the search
//! every few thousand sets, the dynamic check, the step durations, each depth of a feed-region
//! search and each step its confirmation redoes), so a plan may run past it by at most one
//! such stage.

use std::time::{Duration, Instant};

use super::PlanFailure;

/// When planning must stop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deadline {
    at: Instant,
    limit_s: f64,
}

impl Deadline {
    /// `limit_s` seconds from now (at most about 30 years, whatever is asked).
    pub fn after_s(limit_s: f64) -> Deadline {
        let span = Duration::try_from_secs_f64(limit_s.max(0.0)).unwrap_or(Duration::MAX);
        let far = Duration::from_secs(1 << 30);
        let now = Instant::now();
        Deadline { at: now + span.min(far), limit_s }
    }

    /// The limit given (s).
    pub fn limit_s(&self) -> f64 {
        self.limit_s
    }

    /// Has the time run out?
    pub fn passed(&self) -> bool {
        Instant::now() >= self.at
    }

    /// `Err(OutOfTime)` naming `stage` once the time has run out.
    pub fn check(&self, stage: impl FnOnce() -> String) -> Result<(), PlanFailure> {
        if self.passed() {
            return Err(PlanFailure::OutOfTime { limit_s: self.limit_s, stage: stage() });
        }
        Ok(())
    }
}

/// [`Deadline::check`] for an optional deadline (`None`: no limit).
pub(crate) fn check(
    d: Option<Deadline>,
    stage: impl FnOnce() -> String,
) -> Result<(), PlanFailure> {
    d.map_or(Ok(()), |d| d.check(stage))
}

/// Has an optional deadline passed?
pub(crate) fn passed(d: Option<Deadline>) -> bool {
    d.is_some_and(|d| d.passed())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_passed_deadline_names_the_stage_and_the_limit() {
        let d = Deadline::after_s(0.0);
        assert!(d.passed());
        let e = d.check(|| "step maps".into()).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("step maps") && msg.contains("--max-time-s"), "{msg}");
        assert!(Deadline::after_s(3600.0).check(|| unreachable!()).is_ok());
        assert!(check(None, || unreachable!()).is_ok());
        // Any limit is accepted: a huge one is far away, not an overflow.
        assert!(!Deadline::after_s(f64::MAX).passed() && !Deadline::after_s(1e300).passed());
    }
}
