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

use chladni::controller::client::{DeviceClient, RunOutcome};
use chladni_shared::icd::link::{Plan, RunNumber, StatusReport};
use chladni_shared::icd::store::{PlanRef, PlanSummary};
use chladni_shared::icd::units::{MilliHz, Q15};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use super::render::{StatusJson, TelemetryJson, print_json, telemetry_line};

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

/// The `run`/`run-file --json` object.
#[derive(Debug, Serialize)]
struct RunJson {
    /// `started` without `--wait`; else how the run ended ([`RunOutcome::name`]).
    outcome: &'static str,
    plan: String,
    run: u32,
    /// The last status seen (with `--wait`).
    status: Option<StatusJson>,
}

/// How the plan is named in messages.
fn label(plan: &PlanRef) -> String {
    match plan {
        PlanRef::Slot(slot) => format!("slot {slot}"),
        PlanRef::Name(name) => format!("'{name}'"),
    }
}

/// Runs a stored plan; with `wait`, watches it to its end (see [`wait_run`]).
pub fn start_plan(
    client: &mut DeviceClient,
    plan: PlanRef,
    repeat: Option<u16>,
    wait: bool,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let what = label(&plan);
    let interrupted = if wait { Some(interrupt_flag()?) } else { None };
    let run = client.run(plan, repeat)?;
    let Some(interrupted) = interrupted else {
        if json {
            print_json(&RunJson { outcome: "started", plan: what, run: run.0, status: None })?;
        } else {
            println!("running plan {what}: run {}", run.0);
        }
        return Ok(ExitCode::SUCCESS);
    };
    if !json {
        println!("running plan {what}: run {} (Ctrl-C stops it)", run.0);
    }
    let outcome = wait_run(client, run, interrupted)?;
    report(client, &what, run, &outcome, json)
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
        s.step.map_or("-".to_string(), |i| i.to_string()),
        s.repetition,
        MilliHz(s.freq_mhz).to_hz(),
        Q15(s.amplitude_q15).to_fraction()
    ));
}

/// Prints how the run ended; exit 0 only when it is done, 130 after Ctrl-C (the plan is
/// stopped first).
fn report(
    client: &mut DeviceClient,
    what: &str,
    run: RunNumber,
    (outcome, steps_seen): &(RunOutcome, usize),
    json: bool,
) -> anyhow::Result<ExitCode> {
    let s = outcome.status();
    let (code, message) = match outcome {
        RunOutcome::Done(_) => (
            ExitCode::SUCCESS,
            format!(
                "plan {what} done (run {}): {steps_seen} step(s) seen running, {:.1} ms, {} underrun(s)",
                run.0,
                s.elapsed_ms(),
                s.underruns
            ),
        ),
        RunOutcome::Superseded(_) => (
            ExitCode::FAILURE,
            format!(
                "error: plan {what} (run {}) was superseded by run {} (a stop, drive or plan from \
             this or another client); the drive is {}",
                run.0,
                s.run.0,
                s.state.name()
            ),
        ),
        RunOutcome::NeverStarted(_) => (
            ExitCode::FAILURE,
            format!(
                "error: plan {what} (run {}) never started: the controller still shows run {}",
                run.0, s.run.0
            ),
        ),
        RunOutcome::Faulted(_) => (
            ExitCode::FAILURE,
            format!(
                "error: the drive faulted during plan {what} (run {}): {}; `chladni device stop` \
             clears it",
                run.0,
                s.fault.map_or("fault", |f| f.name())
            ),
        ),
        RunOutcome::Interrupted(_) => {
            let stop = client.stop()?;
            (
                ExitCode::from(EXIT_INTERRUPTED),
                format!(
                    "interrupted: stopped plan {what} (run {}; the stop is run {})",
                    run.0, stop.0
                ),
            )
        }
    };
    if json {
        let status = Some(StatusJson::from(s));
        print_json(&RunJson {
            outcome: outcome.name(),
            plan: what.to_string(),
            run: run.0,
            status,
        })?;
    }
    match outcome {
        RunOutcome::Done(_) if !json => println!("{message}"),
        RunOutcome::Done(_) => {}
        _ => eprintln!("{message}"),
    }
    Ok(code)
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
