//! Watching the demo's plan run on the controller: its telemetry stream (renewed before it runs
//! out, as `chladni device monitor` does), the outcome decided by run numbers
//! ([`judge_run`], as `--wait` does), and the run's timing by the controller's sample clock.
//!
//! Telemetry rather than status polls: the stream arrives at a steady rate without a request
//! per sample, and each sample is a whole status (step, frequency, measured acceleration,
//! remaining time, run number, fault). When the stream stops (another client's monitor took
//! the controller's one stream) the watch falls back to asking for the status, so the run is
//! still followed to its end.

use std::ops::ControlFlow;
use std::time::{Duration, Instant};

use chladni_shared::drive::runner::STOP_RAMP_MS;
use chladni_shared::icd::link::{DriveState, RunNumber, StatusReport, Telemetry};
use chladni_shared::icd::plan::Plan;
use chladni_shared::icd::sense::Fault;
use chladni_shared::icd::store::PlanRef;
use chladni_shared::icd::units::SAMPLES_PER_MS;
use chladni_shared::icd::units::ms_from_samples;
use serde::Serialize;

use super::DemoError;
use chladni_device::client::{DeviceClient, DeviceError, RunOutcome, judge_run};

/// Telemetry samples per second.
pub const TELEMETRY_HZ: u16 = 10;
/// Each subscription asks for this many seconds of samples; it is renewed half a second
/// before it runs out, so a demo that dies leaves the controller streaming for at most this.
const BATCH_S: u32 = 2;
/// No sample for this long: the stream has stopped; ask for the status instead.
const SILENCE: Duration = Duration::from_secs(1);

/// How the run went, timed by the controller's sample clock.
#[derive(Debug, Clone, Serialize)]
pub struct RunReport {
    /// The run number the controller gave the plan.
    pub run: u32,
    /// How it ended: `done`, `faulted`, `superseded`, `never_started` or `interrupted`
    /// ([`RunOutcome::name`]).
    pub outcome: &'static str,
    /// The latched fault, if the drive faulted (rendered by the CLI).
    #[serde(skip)]
    pub fault: Option<Fault>,
    /// The controller's samples per second.
    pub sample_rate: u32,
    /// The sample clock when the run's first sample was output (`None`: never seen running).
    pub start_clock: Option<u64>,
    /// The sample clock after its last sample (the final ramp included).
    pub end_clock: Option<u64>,
    /// The plan's steps, in samples (the nominal duration of the plan as stored).
    pub planned_samples: u64,
    /// The same in ms.
    pub planned_ms: f64,
    /// Samples the steps took as run: the run's samples less the final ramp when it ended by
    /// itself (else every sample it ran).
    pub executed_samples: u64,
    /// The same in ms.
    pub executed_ms: f64,
    /// The final ramp to zero after the last step (samples).
    pub final_ramp_samples: u64,
    /// `executed_samples − planned_samples`: 0 when the steps ran sample-exact.
    pub difference_samples: i64,
    /// Statuses of the running plan whose `clock − elapsed_samples` was not the start clock
    /// (0: every status agreed to the sample on when the run started).
    pub clock_disagreements: u32,
    /// Distinct steps seen running.
    pub steps_seen: usize,
    /// Telemetry samples received.
    pub telemetry_samples: u32,
    /// Sample blocks the output missed during the run.
    pub underruns: u32,
    /// Wall time from the controller's answer to the end (s).
    pub wall_s: f64,
    /// After Ctrl-C: the run number of the stop the demo sent.
    pub stop_run: Option<u32>,
}

/// Where the run started on the sample clock, and whether every status agreed.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct StartClock {
    /// The sample clock at the run's first sample, from the first status that showed it.
    pub start: Option<u64>,
    /// Later statuses that put the start elsewhere.
    pub disagreements: u32,
}

impl StartClock {
    /// Takes the start from a status of run `run` while it outputs samples (`clock` and
    /// `elapsed_samples` advance together then; idle, the clock runs on alone).
    pub fn see(&mut self, run: RunNumber, s: &StatusReport) {
        let outputting = !matches!(s.state, DriveState::Idle | DriveState::Faulted);
        if s.run != run || !outputting {
            return;
        }
        let start = s.clock.saturating_sub(s.elapsed_samples);
        match self.start {
            None => self.start = Some(start),
            Some(known) if known != start => self.disagreements += 1,
            Some(_) => {}
        }
    }
}

fn device(stage: &'static str) -> impl FnOnce(DeviceError) -> DemoError {
    move |source| DemoError::Device { stage, source }
}

/// Runs the stored `plan` (by name) and watches it to its end. `on_sample` sees each
/// telemetry sample, numbered from 0 across the stream's renewals (when the stream has
/// stopped, each status polled instead, as a sample); `Break` stops the plan (Ctrl-C) and ends the watch as `interrupted`.
pub fn watch(
    client: &mut DeviceClient,
    plan: &Plan,
    mut on_sample: impl FnMut(&Telemetry) -> ControlFlow<()>,
) -> Result<RunReport, DemoError> {
    let batch = u32::from(TELEMETRY_HZ) * BATCH_S;
    let renew_at = u32::from(TELEMETRY_HZ / 2);
    // Subscribed before the run starts, so its first samples are seen.
    client.subscribe(TELEMETRY_HZ, batch).map_err(device("subscribing to telemetry"))?;
    let run =
        client.run(PlanRef::Name(plan.name.clone()), None).map_err(device("running the plan"))?;
    let accepted = Instant::now();
    let (mut clock, mut samples, mut steps) = (StartClock::default(), 0u32, Vec::new());
    let outcome = loop {
        let sample = match client.next_telemetry(SILENCE).map_err(device("telemetry"))? {
            Some(t) => {
                if t.left <= renew_at {
                    client.subscribe(TELEMETRY_HZ, batch).map_err(device("telemetry"))?;
                }
                // Numbered across renewals (each subscription counts from 0).
                Telemetry { seq: samples, ..t }
            }
            None => {
                let status = client.status().map_err(device("reading the status"))?;
                Telemetry { seq: samples, left: 0, status }
            }
        };
        samples += 1;
        let s = &sample.status;
        clock.see(run, s);
        if s.run == run
            && let Some(step) = s.step
            && !steps.contains(&step)
        {
            steps.push(step);
        }
        if on_sample(&sample).is_break() {
            break RunOutcome::Interrupted(sample.status);
        }
        if let Some(outcome) = judge_run(run, s, accepted.elapsed()) {
            break outcome;
        }
    };
    let wall_s = accepted.elapsed().as_secs_f64();
    // Best effort: the stream lapses by itself within BATCH_S anyway.
    let _ = client.subscribe(TELEMETRY_HZ, 0);
    let stop_run = match outcome {
        RunOutcome::Interrupted(_) => Some(client.stop().map_err(device("stopping the plan"))?.0),
        _ => None,
    };
    let mut report = timing(plan, run, &outcome, clock);
    report.steps_seen = steps.len();
    report.telemetry_samples = samples;
    report.wall_s = wall_s;
    report.stop_run = stop_run;
    Ok(report)
}

/// The run's timing from its last status: executed against planned samples.
pub fn timing(plan: &Plan, run: RunNumber, outcome: &RunOutcome, clock: StartClock) -> RunReport {
    let s = outcome.status();
    let ours = s.run == run;
    let rate = s.sample_rate.max(1);
    let planned_samples: u64 =
        plan.steps.iter().map(|st| u64::from(st.duration_samples())).sum::<u64>()
            * u64::from(plan.repeat.max(1));
    let last_ramp = plan.steps.last().map_or(0, |st| st.ramp_ms);
    let final_ramp_samples = u64::from(last_ramp.max(STOP_RAMP_MS) * SAMPLES_PER_MS);
    let elapsed = if ours { s.elapsed_samples } else { 0 };
    let executed_samples = match outcome {
        RunOutcome::Done(_) if ours => elapsed.saturating_sub(final_ramp_samples),
        _ => elapsed,
    };
    let ms = |samples: u64| ms_from_samples(samples, rate);
    RunReport {
        run: run.0,
        outcome: outcome.name(),
        fault: if ours { s.fault } else { None },
        sample_rate: rate,
        start_clock: clock.start,
        end_clock: clock.start.filter(|_| ours).map(|start| start + elapsed),
        planned_samples,
        planned_ms: ms(planned_samples),
        executed_samples,
        executed_ms: ms(executed_samples),
        final_ramp_samples,
        difference_samples: executed_samples as i64 - planned_samples as i64,
        clock_disagreements: clock.disagreements,
        steps_seen: 0,
        telemetry_samples: 0,
        underruns: s.underruns,
        wall_s: 0.0,
        stop_run: None,
    }
}
