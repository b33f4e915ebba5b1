//! `chladni demo`: the feeder's whole job in one command. Thin: parse, show progress (a bar on
//! a terminal, plain telemetry lines otherwise), render [`crate::demo::Summary`]; the work is
//! [`crate::demo`]'s. With `--json`, stdout carries only the summary (or `{"error",
//! "message"}`) and everything else goes to stderr.

use std::io::IsTerminal;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::demo::{self, DemoConfig, DemoError, DemoStep, Prepared, Summary};
use chladni_media::shapes::failure::FailureJson;
use chladni_shared::icd::link::Telemetry;
use chladni_shared::icd::units::{MilliHz, MmPerS2, ms_from_samples};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use super::device::render::{FaultJson, print_json, telemetry_line};
use super::device::watch::{EXIT_INTERRUPTED, interrupt_flag};
use super::parse::f64_where;

mod steer;

/// Plan a part, simulate it, and run it on the controller (QEMU, or a real one with --port).
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Part file (.json, .svg or .dxf).
    #[arg(long, default_value = demo::DEFAULT_PART)]
    part: PathBuf,
    /// Plate model (TOML; docs/plan.md).
    #[arg(long, value_name = "PLATE.toml", default_value = demo::DEFAULT_PLATE)]
    plate: PathBuf,
    /// Output folder: plan files, figures, the QEMU controller's flash and log.
    #[arg(long, value_name = "DIR", default_value = demo::DEFAULT_OUT)]
    out: PathBuf,
    /// A real controller: serial device (see `chladni device list`) or tcp://HOST:PORT.
    /// Default: start one in QEMU.
    #[arg(long, short, value_name = "DEVICE")]
    port: Option<String>,
    /// Acceleration the controller holds at full amplitude, m/s²: a step of amplitude a holds
    /// a × this (closed loop).
    #[arg(long, value_name = "MPS2", default_value_t = demo::DEFAULT_ACCEL_MPS2,
          value_parser = f64_where("accel", "in (0, 100] m/s²", |v| v > 0.0 && v <= 100.0))]
    accel: f64,
    /// Run the plan time-scaled: step durations divided by a whole factor so the run takes at
    /// most 25 s.
    #[arg(long)]
    fast: bool,
    /// The camera story without hardware: a virtual rig (three triangles on the free plate,
    /// warped) follows the controller in QEMU; learn the plate, steer the parts to three goals,
    /// plan on the learned plate, run the plan and verify it from a frame (docs/demo.md).
    #[arg(long, conflicts_with_all = ["part", "plate", "port", "accel", "fast"])]
    steer: bool,
    /// Print the summary as one JSON object (progress goes to stderr).
    #[arg(long)]
    json: bool,
}

/// Where the lines for people go: stdout, or stderr with `--json`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Say {
    json: bool,
}

impl Say {
    pub(super) fn line(self, text: impl AsRef<str>) {
        if self.json {
            eprintln!("{}", text.as_ref());
        } else {
            println!("{}", text.as_ref());
        }
    }
}

impl DemoArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        if self.steer {
            return self.ended(steer::run(&self.out, self.json));
        }
        let config = DemoConfig {
            part: demo::resolve_input(&self.part),
            plate: demo::resolve_input(&self.plate),
            out: self.out.clone(),
            port: self.port.clone(),
            accel_mps2: self.accel,
            fast: self.fast,
        };
        self.ended(self.demo(&config))
    }

    /// The exit code; an error printed (`--json`: its object too). Ctrl-C in the camera loop
    /// is 130.
    fn ended(&self, result: Result<ExitCode, DemoError>) -> anyhow::Result<ExitCode> {
        match result {
            Ok(code) => Ok(code),
            Err(e) => {
                if self.json {
                    print_json(&FailureJson { error: e.name(), message: e.to_string() })?;
                }
                eprintln!("error: {e}");
                if e.is_interrupted() {
                    return Ok(ExitCode::from(EXIT_INTERRUPTED));
                }
                Ok(ExitCode::from(e.exit_code()))
            }
        }
    }

    fn demo(&self, config: &DemoConfig) -> Result<ExitCode, DemoError> {
        let say = Say { json: self.json };
        demo::preflight(config)?;
        say.line(format!("planning    {} on {}", config.part.display(), config.plate.display()));
        let prepared = demo::prepare(config)?;
        show_prepared(say, &prepared, config);
        // From here on a controller may run: Ctrl-C stops the plan rather than the program.
        let interrupted = interrupt_flag().ok();
        say.line(match &config.port {
            Some(port) => format!("controller  connecting to {port}"),
            None => "controller  starting it in QEMU (its firmware is built if missing or stale)"
                .to_string(),
        });
        let mut controller = demo::connect(config, &prepared)?;
        let info = controller.client.info();
        say.line(format!(
            "controller  {} ({}, firmware {})",
            controller.port,
            info.board.name(),
            info.firmware_version
        ));
        let stored = upload(&mut controller, &prepared)?;
        say.line(format!(
            "stored      '{}' in slot {}: {} step(s), {} ms, CRC {:08x}",
            stored.name, stored.slot, stored.steps, stored.total_ms, stored.crc
        ));
        if is_set(interrupted) {
            eprintln!("interrupted before the run: nothing was started");
            return Ok(ExitCode::from(EXIT_INTERRUPTED));
        }
        let mut progress = Progress::new(say, &prepared);
        let report = demo::run_plan(&mut controller, &prepared.device_plan, |t| {
            progress.show(t);
            if is_set(interrupted) { ControlFlow::Break(()) } else { ControlFlow::Continue(()) }
        });
        progress.finish();
        let summary = Summary::new(&prepared, config, &controller, &stored, report?);
        show_summary(say, &summary);
        if self.json {
            print_json(&demo::SummaryJson::of(&summary))
                .map_err(|e| DemoError::Input(e.to_string()))?;
        }
        Ok(exit_code(&summary))
    }
}

fn is_set(flag: Option<&AtomicBool>) -> bool {
    flag.is_some_and(|f| f.load(Ordering::SeqCst))
}

/// Uploads with a progress bar over the steps (drawn only on a terminal).
fn upload(
    controller: &mut demo::Controller,
    prepared: &Prepared,
) -> Result<chladni_shared::icd::store::PlanSummary, DemoError> {
    let bar = ProgressBar::new(prepared.device_plan.steps.len() as u64);
    bar.set_style(style("uploading {bar:40.cyan/blue} {pos}/{len} steps"));
    let stored =
        demo::upload(controller, &prepared.device_plan, |done, _| bar.set_position(done as u64));
    bar.finish_and_clear();
    stored
}

fn style(template: &str) -> ProgressStyle {
    ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar())
}

/// What was computed before the controller: plan, simulation, levels, time scale, files.
fn show_prepared(say: Say, p: &Prepared, config: &DemoConfig) {
    for (i, s) in p.steps.iter().enumerate() {
        say.line(format!(
            "step {:<3}    {:<16} {:>8.3} Hz  amplitude {:.3} → holds {:.3} m/s²  {:>6} ms{}",
            i + 1,
            s.mode,
            s.freq_hz,
            s.amplitude,
            s.accel_mps2,
            s.duration_ms,
            if p.time_scale > 1 {
                format!(" (planned {} ms)", s.nominal_ms)
            } else {
                String::new()
            }
        ));
    }
    say.line(predicted_line(p));
    let sim = &p.simulation;
    say.line(format!(
        "simulated   {:.1} % of {} trials within {}° (the plan claims {:.1} %)",
        100.0 * sim.success_rate,
        sim.trials,
        sim.tolerance_deg,
        100.0 * sim.claimed_success_rate
    ));
    say.line(format!(
        "closed loop each step holds its amplitude × {:.3} m/s² (--accel: the acceleration at \
         full amplitude)",
        config.accel_mps2
    ));
    if p.time_scale > 1 {
        say.line(format!(
            "time scale  1/{} (--fast): step durations divided by {}, a look at the controller, \
             too short for parts to settle",
            p.time_scale, p.time_scale
        ));
    }
    let f = &p.files;
    say.line(format!(
        "written     {} {} {} {} {}",
        f.plan.display(),
        f.device_plan.display(),
        f.plan_figure.display(),
        f.traces.display(),
        f.traces_plan.display()
    ));
}

fn predicted_line(p: &Prepared) -> String {
    let pos = p
        .syn
        .final_position_mm
        .map_or("position not fixed".to_string(), |[x, y]| format!("at ({x:.2}, {y:.2}) mm"));
    format!("predicted   θ = {:.3}° (mod {}°) {pos}", p.syn.final_orientation_deg, p.syn.period_deg)
}

/// Live telemetry: a bar on a terminal, else a plain line per second and per step change.
struct Progress<'a> {
    say: Say,
    steps: &'a [DemoStep],
    bar: Option<ProgressBar>,
    last_line: Option<Instant>,
    last_step: Option<u16>,
}

/// Plain lines at most this often (and at every step change).
const LINE_EVERY: Duration = Duration::from_secs(1);

impl<'a> Progress<'a> {
    fn new(say: Say, p: &'a Prepared) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::new(p.device_plan.total_ms().max(1));
            bar.set_style(style("{bar:30.cyan/blue} {pos:>6}/{len} ms  {msg}"));
            bar
        });
        Progress { say, steps: &p.steps, bar, last_line: None, last_step: None }
    }

    fn show(&mut self, t: &Telemetry) {
        let s = &t.status;
        match &self.bar {
            Some(bar) => {
                if s.step.is_some() {
                    bar.set_position(s.elapsed_ms() as u64);
                }
                bar.set_message(self.message(t));
            }
            None => {
                let due = self.last_line.is_none_or(|at| at.elapsed() >= LINE_EVERY);
                if due || s.step != self.last_step {
                    self.say.line(telemetry_line(t));
                    self.last_line = Some(Instant::now());
                }
            }
        }
        self.last_step = s.step;
    }

    /// The bar's message: step, frequency, measured and target acceleration, time left.
    fn message(&self, t: &Telemetry) -> String {
        let s = &t.status;
        let step = s.step.map_or("-".to_string(), |i| format!("{}/{}", i + 1, self.steps.len()));
        let measured = s
            .measured
            .map_or("-".to_string(), |m| format!("{:.3}", MmPerS2(m.accel_mmps2).to_mps2()));
        let target = s
            .level
            .and_then(|l| l.accel_mmps2())
            .map_or(String::new(), |a| format!(" (target {:.3})", MmPerS2(a).to_mps2()));
        format!(
            "{} · step {step} · {:.3} Hz · {measured} m/s²{target} · {:.1} s left",
            s.state.name(),
            MilliHz(s.freq_mhz).to_hz(),
            s.remaining_ms() / 1000.0
        )
    }

    fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// The summary for people.
fn show_summary(say: Say, s: &Summary) {
    let r = &s.run;
    say.line("summary");
    say.line(format!("  part        {} on {}", s.part, s.plate));
    let pos = s
        .predicted
        .position_mm
        .map_or("position not fixed".to_string(), |[x, y]| format!("at ({x:.2}, {y:.2}) mm"));
    say.line(format!(
        "  predicted   θ = {:.3}° (mod {}°) {pos}",
        s.predicted.orientation_deg, s.predicted.period_deg
    ));
    say.line(format!(
        "  simulated   {:.1} % success ({} trials; the plan claims {:.1} %)",
        100.0 * s.simulation.success_rate,
        s.simulation.trials,
        100.0 * s.simulation.claimed_success_rate
    ));
    let levels: Vec<String> = s.steps.iter().map(|st| format!("{:.3}", st.accel_mps2)).collect();
    say.line(format!(
        "  levels      closed loop, {} m/s² (amplitude × {:.3} m/s², --accel)",
        levels.join(", "),
        s.accel_mps2
    ));
    if s.time_scale > 1 {
        say.line(format!("  time scale  1/{} (--fast)", s.time_scale));
    }
    say.line(timing_line(r));
    say.line(format!(
        "  run         {} (run {} on {}, slot {}), {} step(s) seen, {} underrun(s)",
        r.outcome, r.run, s.controller.port, s.stored.slot, r.steps_seen, r.underruns
    ));
    say.line(format!(
        "  fault       {}",
        r.fault.map_or("none".to_string(), |f| FaultJson::of(&f, r.sample_rate).text())
    ));
}

/// The run's timing by the controller's sample clock.
fn timing_line(r: &demo::RunReport) -> String {
    let clock = |c: Option<u64>| c.map_or("-".to_string(), |c| c.to_string());
    let clocks = format!(
        "clock {} → {} at {} samples/s",
        clock(r.start_clock),
        clock(r.end_clock),
        r.sample_rate
    );
    if r.outcome != "done" {
        return format!(
            "  timing      ran {:.3} ms of the {:.3} ms planned before it ended ({clocks}); wall \
             {:.1} s",
            r.executed_ms, r.planned_ms, r.wall_s
        );
    }
    format!(
        "  timing      steps ran {:.3} ms for {:.3} ms planned ({:+} samples: {}); {clocks}, \
         then a {:.0} ms ramp to zero; wall {:.1} s",
        r.executed_ms,
        r.planned_ms,
        r.difference_samples,
        if r.difference_samples == 0 { "sample-exact" } else { "NOT sample-exact" },
        ms_from_samples(r.final_ramp_samples, r.sample_rate),
        r.wall_s
    )
}

/// 0 when the plan ran to its end without a fault; 130 after Ctrl-C; else 1, with the fix.
fn exit_code(s: &Summary) -> ExitCode {
    let r = &s.run;
    let port = &s.controller.port;
    let message = match (r.outcome, r.fault) {
        ("done", None) => return ExitCode::SUCCESS,
        ("interrupted", _) => {
            let stop = r.stop_run.map_or("not sent".to_string(), |n| n.to_string());
            eprintln!("interrupted: stopped the plan (run {}; the stop is run {stop})", r.run);
            return ExitCode::from(EXIT_INTERRUPTED);
        }
        (_, Some(f)) => format!(
            "the drive faulted during the plan: {}; check the shaker, amplifier and sensor \
             first (`chladni device status --port {port}`)",
            FaultJson::of(&f, r.sample_rate).text()
        ),
        ("superseded", None) => format!(
            "another command (a stop, drive or plan, from this or another program) took over \
             the controller during run {}: run the demo again when the controller at {port} is \
             free",
            r.run
        ),
        (outcome, None) => format!(
            "the plan did not run ({outcome}, run {}): see `chladni device status --port {port}`",
            r.run
        ),
    };
    eprintln!("error: {message}");
    ExitCode::FAILURE
}
