//! What takes time in `chladni device`: uploads and waits with progress bars, the telemetry
//! monitor, and Ctrl-C.
//!
//! Ctrl-C (or SIGTERM) while `--wait` watches a plan does not leave the plan running behind
//! the user's back: the command sends `Stop`, says so, and exits with 130. In `monitor`,
//! which starts nothing, it ends the stream and says what the controller is still doing.

use std::collections::BTreeSet;
use std::ops::ControlFlow;
use std::process::ExitCode;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use chladni_device::client::{DeviceClient, NEVER_STARTED_AFTER, RunOutcome};
use chladni_shared::icd::link::{Plan, RunNumber, StatusReport};
use chladni_shared::icd::store::{PlanRef, PlanSummary};
use chladni_shared::icd::units::{MilliHz, Q15};
use indicatif::{ProgressBar, ProgressStyle};

use super::render::{RunJson, StatusJson, TelemetryJson, fault_text, print_json, telemetry_line};

/// Exit code after Ctrl-C (128 + SIGINT, as shells report it).
pub const EXIT_INTERRUPTED: u8 = 130;
/// Without `--count`, the monitor asks for this many seconds of samples at a time and asks
/// again before they run out: when it dies, the controller stops streaming soon after.
const MONITOR_BATCH_S: u32 = 2;

/// The flag Ctrl-C (and SIGTERM) sets; the handler is installed on first use.
pub fn interrupt_flag() -> anyhow::Result<&'static AtomicBool> {
    static FLAG: AtomicBool = AtomicBool::new(false);
    static INSTALLED: OnceLock<Result<(), String>> = OnceLock::new();
    INSTALLED
        .get_or_init(|| {
            ctrlc::set_handler(|| FLAG.store(true, Ordering::SeqCst)).map_err(|e| e.to_string())
        })
        .clone()
        .map_err(|e| anyhow::anyhow!("cannot catch Ctrl-C: {e}"))?;
    Ok(&FLAG)
}

fn bar(len: u64, template: &str) -> ProgressBar {
    let bar = ProgressBar::new(len.max(1));
    bar.set_style(ProgressStyle::with_template(template).expect("static template"));
    bar
}

/// Uploads `plan` with a progress bar over its steps.
pub fn upload(
    client: &mut DeviceClient,
    plan: &Plan,
    slot: Option<u8>,
) -> anyhow::Result<PlanSummary> {
    let bar = bar(plan.steps.len() as u64, "uploading {bar:40.cyan/blue} {pos}/{len} steps  {msg}");
    bar.set_message(plan.name.to_string());
    let result = client.upload(plan, slot, |done, _| bar.set_position(done as u64));
    bar.finish_and_clear();
    Ok(result?)
}

/// The stored plan a command runs, and its name when the command knows it.
#[derive(Debug, Clone)]
pub struct Target {
    /// How the request names it.
    pub plan: PlanRef,
    /// Its name.
    pub name: Option<String>,
}

impl Target {
    /// The plan `plan` names.
    pub fn of(plan: PlanRef) -> Self {
        let name = match &plan {
            PlanRef::Name(name) => Some(name.to_string()),
            PlanRef::Slot(_) => None,
        };
        Target { plan, name }
    }

    fn slot(&self) -> Option<u8> {
        match self.plan {
            PlanRef::Slot(slot) => Some(slot),
            PlanRef::Name(_) => None,
        }
    }

    /// How messages name it: `'NAME'`, `slot N`, or `'NAME' (slot N)`.
    fn label(&self) -> String {
        match (&self.name, self.slot()) {
            (Some(name), Some(slot)) => format!("'{name}' (slot {slot})"),
            (Some(name), None) => format!("'{name}'"),
            (None, Some(slot)) => format!("slot {slot}"),
            (None, None) => "?".to_string(),
        }
    }

    fn json(
        &self,
        outcome: &'static str,
        run: RunNumber,
        status: Option<&StatusReport>,
    ) -> RunJson {
        let status = status.map(StatusJson::from);
        RunJson { outcome, plan: self.name.clone(), run: run.0, slot: self.slot(), status }
    }
}

/// Runs a stored plan; with `wait`, watches it to its end (see [`wait_run`]).
pub fn start_plan(
    client: &mut DeviceClient,
    target: &Target,
    repeat: Option<u16>,
    wait: bool,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let what = target.label();
    let interrupted = if wait { Some(interrupt_flag()?) } else { None };
    let run = client.run(target.plan.clone(), repeat)?;
    let Some(interrupted) = interrupted else {
        if json {
            print_json(&target.json("started", run, None))?;
        } else {
            println!("running plan {what}: run {}", run.0);
        }
        return Ok(ExitCode::SUCCESS);
    };
    if !json {
        println!("running plan {what}: run {} (Ctrl-C stops it)", run.0);
    }
    let outcome = wait_run(client, run, interrupted)?;
    report(client, target, run, &outcome, json)
}

/// Watches run `run` with a progress bar until it is over or Ctrl-C.
fn wait_run(
    client: &mut DeviceClient,
    run: RunNumber,
    interrupted: &AtomicBool,
) -> anyhow::Result<(RunOutcome, usize)> {
    let bar = bar(1, "{bar:40.cyan/blue} {pos:>7}/{len} ms  {msg}");
    let mut steps_seen = BTreeSet::new();
    let outcome = client.wait_for_run(run, |s| {
        if interrupted.load(Ordering::SeqCst) {
            return ControlFlow::Break(());
        }
        if s.run == run {
            show_progress(&bar, s);
            steps_seen.extend(s.step);
        }
        ControlFlow::Continue(())
    });
    bar.finish_and_clear();
    Ok((outcome?, steps_seen.len()))
}

fn show_progress(bar: &ProgressBar, s: &StatusReport) {
    let (elapsed, remaining) = (s.elapsed_ms() as u64, s.remaining_ms() as u64);
    if s.step.is_some() {
        bar.set_length((elapsed + remaining).max(1));
    }
    bar.set_position(elapsed.min(bar.length().unwrap_or(u64::MAX)));
    bar.set_message(format!(
        "{} · step {} · rep {} · {:.3} Hz · amplitude {:.3}",
        s.state.name(),
        s.step.map_or("-".to_string(), |i| super::render::counted(i).to_string()),
        super::render::counted(s.repetition),
        MilliHz(s.freq_mhz).to_hz(),
        Q15(s.amplitude_q15).to_fraction()
    ));
}

/// Prints how the run ended; exit 0 only when it is done, 130 after Ctrl-C (the plan is
/// stopped first).
fn report(
    client: &mut DeviceClient,
    target: &Target,
    run: RunNumber,
    (outcome, steps_seen): &(RunOutcome, usize),
    json: bool,
) -> anyhow::Result<ExitCode> {
    let stop = match outcome {
        RunOutcome::Interrupted(_) => Some(client.stop()?),
        _ => None,
    };
    let message = outcome_message(&target.label(), run, outcome, *steps_seen, stop);
    if json {
        print_json(&target.json(outcome.name(), run, Some(outcome.status())))?;
    }
    Ok(match outcome {
        RunOutcome::Done(_) => {
            if !json {
                println!("{message}");
            }
            ExitCode::SUCCESS
        }
        RunOutcome::Interrupted(_) => {
            eprintln!("{message}");
            ExitCode::from(EXIT_INTERRUPTED)
        }
        _ => {
            eprintln!("{message}");
            ExitCode::FAILURE
        }
    })
}

/// What the user is told about run `run` of plan `what` ended as `outcome`; `stop` is the run
/// number of the stop sent after Ctrl-C.
fn outcome_message(
    what: &str,
    run: RunNumber,
    outcome: &RunOutcome,
    steps_seen: usize,
    stop: Option<RunNumber>,
) -> String {
    let s = outcome.status();
    let (run, now) = (run.0, s.run.0);
    match outcome {
        RunOutcome::Done(_) => format!(
            "plan {what} done (run {run}): {steps_seen} step(s) seen running, {:.1} ms, \
             {} underrun(s)",
            s.elapsed_ms(),
            s.underruns
        ),
        RunOutcome::Superseded(_) => format!(
            "error: plan {what} (run {run}) was superseded by run {now} (a stop, drive or plan \
             from this or another client); the drive is {}",
            s.state.name()
        ),
        RunOutcome::NeverStarted(_) => format!(
            "error: plan {what} (run {run}) never started: after {} s the controller still \
             shows run {now}",
            NEVER_STARTED_AFTER.as_secs()
        ),
        RunOutcome::Faulted(_) => {
            format!("error: the drive faulted during plan {what} (run {run}): {}", fault_text(s))
        }
        RunOutcome::Interrupted(_) => format!(
            "interrupted: stopped plan {what} (run {run}; the stop is run {})",
            stop.map_or("not sent".to_string(), |r| r.0.to_string())
        ),
    }
}

/// `monitor`: telemetry lines until `count` samples, Ctrl-C, or the stream stops.
pub fn monitor(
    client: &mut DeviceClient,
    rate_hz: u16,
    count: Option<u32>,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let interrupted = interrupt_flag()?;
    let batch = count.unwrap_or(u32::from(rate_hz) * MONITOR_BATCH_S);
    // Ask for the next batch when half a second of samples is left.
    let renew_at = u32::from(rate_hz / 2);
    // A stream that is silent for five periods (at least 1 s) has stopped.
    let silence = Duration::from_secs_f64((5.0 / f64::from(rate_hz)).max(1.0));
    client.subscribe(rate_hz, batch)?;
    loop {
        if interrupted.load(Ordering::SeqCst) {
            return end_monitor(client, rate_hz);
        }
        let Some(sample) = client.next_telemetry(silence)? else {
            eprintln!(
                "error: telemetry stopped: no sample for {:.1} s (another client's monitor took \
                 the controller's one stream, or the controller stopped answering)",
                silence.as_secs_f64()
            );
            return Ok(ExitCode::FAILURE);
        };
        if json {
            print_json(&TelemetryJson::from(&sample))?;
        } else {
            println!("{}", telemetry_line(&sample));
        }
        match count {
            Some(_) if sample.left == 0 => return Ok(ExitCode::SUCCESS),
            None if sample.left <= renew_at => client.subscribe(rate_hz, batch)?,
            _ => {}
        }
    }
}

/// Ctrl-C in `monitor`: end the stream, and say what the drive is doing (it goes on).
fn end_monitor(client: &mut DeviceClient, rate_hz: u16) -> anyhow::Result<ExitCode> {
    let _ = client.subscribe(rate_hz, 0);
    match client.status() {
        Ok(s) if s.state.name() != "idle" => eprintln!(
            "monitor stopped; the controller goes on: {} (run {}); `chladni device stop` stops it",
            s.state.name(),
            s.run.0
        ),
        _ => eprintln!("monitor stopped"),
    }
    Ok(ExitCode::from(EXIT_INTERRUPTED))
}

#[cfg(test)]
mod tests {
    use super::*;
    use chladni_shared::icd::link::{DriveState, Fault, FaultCause};

    fn status(run: u32, state: DriveState) -> StatusReport {
        let fault = Fault { cause: FaultCause::LoopOpen, value: 0, at_sample: 0 };
        StatusReport {
            state,
            run: RunNumber(run),
            fault: (state == DriveState::Faulted).then_some(fault),
            elapsed_samples: 50_000,
            underruns: 2,
            commands: 4,
            least_slack_us: None,
            stack_high_water: 0,
            ..StatusReport::IDLE
        }
    }

    #[test]
    fn each_outcome_is_told_with_the_run_numbers() {
        let target = Target { plan: PlanRef::Slot(64), name: Some("tri".into()) };
        let what = target.label();
        assert_eq!(what, "'tri' (slot 64)");
        let run = RunNumber(7);
        let say = |o: RunOutcome| outcome_message(&what, run, &o, 2, Some(RunNumber(8)));
        assert_eq!(
            say(RunOutcome::Done(status(7, DriveState::Idle))),
            "plan 'tri' (slot 64) done (run 7): 2 step(s) seen running, 1000.0 ms, 2 underrun(s)"
        );
        assert!(
            say(RunOutcome::Superseded(status(9, DriveState::Running)))
                .contains("(run 7) was superseded by run 9")
        );
        assert!(
            say(RunOutcome::NeverStarted(status(6, DriveState::Idle)))
                .contains("never started: after 2 s the controller still shows run 6")
        );
        assert_eq!(
            say(RunOutcome::Faulted(status(7, DriveState::Faulted))),
            "error: the drive faulted during plan 'tri' (slot 64) (run 7): loop_open 0 mm/s² at \
             0.000 s (`chladni device clear-fault` clears it)"
        );
        assert_eq!(
            say(RunOutcome::Interrupted(status(7, DriveState::Running))),
            "interrupted: stopped plan 'tri' (slot 64) (run 7; the stop is run 8)"
        );
        let json = serde_json::to_value(target.json("done", run, None)).unwrap();
        assert_eq!(
            json,
            serde_json::json!({"outcome": "done", "plan": "tri", "run": 7, "slot": 64, "status": null})
        );
        assert_eq!(Target::of(PlanRef::Name("x".try_into().unwrap())).label(), "'x'");
    }
}
