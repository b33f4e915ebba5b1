//! `chladni demo --steer` for people: each step of [`crate::demo::steer`] a paragraph, with a
//! progress bar on a terminal (plain lines otherwise); `--json`: one object at the end, and
//! the paragraphs on stderr. The learning job and the tables are `chladni plate learn`'s and
//! `chladni steer`'s ([`super::super::steer`]).

use std::ops::ControlFlow;
use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use crate::demo::steer::{
    self as work, AgainstTruth, BURSTS_PER_MODE, FEED_HALF_MM, FedPlan, GOALS, LEARN_LIMIT, STARTS,
    SteerConfig, SteerDemo, TOL_MM, Verified,
};
use crate::demo::{self, DemoError, RunReport};
use chladni_core::model::plate_file::Learned as LearnedTable;
use chladni_media::vision::verify::Outcome;
use chladni_shared::icd::link::Telemetry;
use chladni_shared::icd::store::PlanSummary;
use chladni_steer::learn::LearnOutcome;
use chladni_steer::steer::SteerReport;

use super::super::device::render::{FaultJson, print_json, telemetry_line};
use super::super::device::watch::{EXIT_INTERRUPTED, interrupt_flag};
use super::super::progress::message_bar;
use super::super::steer::{learn_job, learned_lines, learned_table, steer_lines};
use super::Say;

/// Runs the demo into `out`; exit 0 when the four steps ran to their end, whatever the
/// verdicts (as `chladni demo` exits 0 when its plan ran; `ok` in the summary says whether the
/// parts reached their goals and the fed part ended as planned), 130 after Ctrl-C, 1 when a
/// step failed or the plan did not run to its end.
pub(super) fn run(out: &Path, json: bool) -> Result<ExitCode, DemoError> {
    let say = Say { json };
    let started = Instant::now();
    let config = SteerConfig {
        part: demo::resolve_input(Path::new(demo::DEFAULT_PART)),
        plate: demo::resolve_input(Path::new(work::PLATE)),
        out: out.to_path_buf(),
    };
    let interrupted = interrupt_flag().ok();
    say.line(
        "controller  starting it in QEMU (its firmware is built if missing or stale), then the \
         virtual rig",
    );
    let mut d = SteerDemo::start(&config, interrupted)?;
    show_start(say, &d);
    let (outcome, table, truth) = learn(say, json, &mut d)?;
    let steered = steer(say, json, &mut d)?;
    let plan = plan(say, json, &d, &steered)?;
    let (stored, ran) = run_plan(say, json, &mut d, &plan, interrupted)?;
    let verified = if ran.outcome == "done" { Some(verify(say, &d, &plan)?) } else { None };
    let ok =
        steered.reached && verified.as_ref().is_some_and(|v| v.verification.result == Outcome::Ok);
    let elapsed_s = started.elapsed().as_secs_f64();
    say.line(format!(
        "\n{} in {:.0} min {:02.0} s; every file in {}",
        if ok { "done" } else { "done, not all as it should be" },
        (elapsed_s / 60.0).floor(),
        elapsed_s % 60.0,
        out.display()
    ));
    if json {
        let summary = serde_json::json!({
            "ok": ok, "elapsed_s": elapsed_s, "controller": d.controller.port,
            "rig": {"url": d.rig.url, "true_plate": d.rig.modes},
            "learn": {"bursts": outcome.bursts.len(), "recoveries": outcome.recoveries,
                "held_out": table.held_out, "elapsed_s": outcome.elapsed_s,
                "timed_out": outcome.timed_out, "modes": table.mode, "against_truth": truth},
            "steer": steered,
            "plan": {"part": plan.part, "feed_mm": plan.box_mm, "totals_s": plan.totals_s,
                "steps": plan.steps,
                "orientation_deg": plan.syn.final_orientation_deg,
                "period_deg": plan.syn.period_deg, "position_mm": plan.syn.final_position_mm,
                "total_ms": plan.device.total_ms()},
            "stored": {"slot": stored.slot, "name": stored.name.to_string(), "crc": stored.crc},
            "run": ran, "verify": verified, "files": d.files,
        });
        print_json(&summary).map_err(|e| DemoError::Input(e.to_string()))?;
    }
    Ok(match ran.outcome {
        "done" => ExitCode::SUCCESS,
        "interrupted" => ExitCode::from(EXIT_INTERRUPTED),
        _ => ExitCode::FAILURE,
    })
}

/// The controller and the rig, started.
fn show_start(say: Say, d: &SteerDemo) {
    let at: Vec<String> = STARTS.iter().map(|s| format!("({}, {})", s[0], s[1])).collect();
    say.line(format!("controller  {} (QEMU)", d.controller.port));
    say.line(format!(
        "rig         {}: 3 × {} at {} mm on '{}' warped (seed {}: each mode's nodes moved \
         4–8 mm, its speed ×0.4–2.5), the truth in {}",
        d.rig.url,
        d.part.name,
        at.join(", "),
        d.given.name,
        work::RIG_SEED,
        d.files.true_plate.display()
    ));
}

/// Step 1: learn the plate, print the table, write the learned plate.
fn learn(
    say: Say,
    json: bool,
    d: &mut SteerDemo,
) -> Result<(LearnOutcome, LearnedTable, Option<AgainstTruth>), DemoError> {
    say.line(format!(
        "\nlearn       {} modes × {BURSTS_PER_MODE} bursts, the parts located before and after \
         each (as `chladni plate learn`; a quarter held out to score the fit)",
        d.given.modes.len()
    ));
    let (kinds, parts) = d.kinds();
    let job = learn_job(kinds, parts, BURSTS_PER_MODE, LEARN_LIMIT);
    let bar = message_bar(json);
    bar.set_message("bursts");
    let outcome = d.learn(&job, |done, wanted| {
        bar.set_length(wanted as u64);
        bar.set_position(done as u64);
    });
    bar.finish_and_clear();
    let outcome = outcome?;
    let table = learned_table(&outcome, d.given_path(), &d.rig.url);
    d.write_learned(&table)?;
    for line in learned_lines(&table) {
        say.line(line);
    }
    let truth = work::against_truth(&table, &d.rig.modes);
    let against = truth.map_or(String::new(), |t| {
        format!(
            "; against the rig's true plate: speeds off by {:.0} % (median; at most {:.0} %), \
             nodes by {:.1} mm (at most {:.1} mm)",
            100.0 * t.speed_off[0],
            100.0 * t.speed_off[1],
            t.shift_off_mm[0],
            t.shift_off_mm[1]
        )
    });
    let note = if outcome.timed_out { " (time limit: some modes have fewer bursts)" } else { "" };
    say.line(format!(
        "{} bursts ({} bringing parts home) in {:.0} s{note}{against}; wrote {}",
        outcome.bursts.len(),
        outcome.recoveries,
        outcome.elapsed_s,
        d.files.learned.display()
    ));
    Ok((outcome, table, truth))
}

/// Step 2: steer the parts to their goals on the learned plate.
fn steer(say: Say, json: bool, d: &mut SteerDemo) -> Result<SteerReport, DemoError> {
    let goals: Vec<String> = GOALS.iter().map(|g| format!("({}, {})", g[0], g[1])).collect();
    say.line(format!(
        "\nsteer       the 3 parts to {} mm, each within {TOL_MM} mm in any orientation, on the \
         learned plate (as `chladni steer`)",
        goals.join(", ")
    ));
    let bar = message_bar(json);
    bar.set_message("steering");
    let report = d.steer(|c| {
        bar.set_message(format!("steering: cycle {}", c.cycle));
        bar.tick();
    });
    bar.finish_and_clear();
    let report = report?;
    for line in steer_lines(&report) {
        say.line(line);
    }
    say.line(format!("every cycle in {}", d.files.steer_log.display()));
    Ok(report)
}

/// Step 3: plan on the learned plate from each part's place; the shortest is run.
fn plan(say: Say, json: bool, d: &SteerDemo, steered: &SteerReport) -> Result<FedPlan, DemoError> {
    say.line(format!(
        "\nplan        on the learned plate for a {} fed where each part lies (± {FEED_HALF_MM} \
         mm: a sensorless plan holds where parts are fed, and step 2 fed them); the shortest \
         runs",
        d.part.name
    ));
    let bar = message_bar(json);
    let plan = d.plan(steered, |done, n| {
        bar.set_length(n as u64);
        bar.set_position(done as u64);
        bar.set_message("planning");
    });
    bar.finish_and_clear();
    let plan = plan?;
    let totals: Vec<String> = (plan.totals_s.iter().zip(&steered.parts))
        .map(|(t, p)| {
            let t = t.map_or("no plan".to_string(), |t| format!("{t:.0} s"));
            format!("{t} from ({:.1}, {:.1})", p.x_mm, p.y_mm)
        })
        .collect();
    say.line(format!("plans       {}", totals.join(", ")));
    for (i, s) in plan.steps.iter().enumerate() {
        say.line(format!(
            "step {:<6} {:<16} {:>8.3} Hz  amplitude {:.3}  {:>7} ms",
            i + 1,
            s.mode,
            s.freq_hz,
            s.amplitude,
            s.duration_ms
        ));
    }
    let syn = &plan.syn;
    let at = syn
        .final_position_mm
        .map_or("position not fixed".to_string(), |[x, y]| format!("at ({x:.2}, {y:.2}) mm"));
    say.line(format!(
        "predicted   the part fed into {}: θ = {:.3}° (mod {}°) {at} after {:.1} s; wrote {}",
        work::feed_text(plan.box_mm),
        syn.final_orientation_deg,
        syn.period_deg,
        plan.device.total_ms() as f64 / 1000.0,
        d.files.plan.display()
    ));
    Ok(plan)
}

/// Step 4a: store the plan and run it, a bar over its time (plain lines at step changes).
fn run_plan(
    say: Say,
    json: bool,
    d: &mut SteerDemo,
    plan: &FedPlan,
    interrupted: Option<&'static AtomicBool>,
) -> Result<(PlanSummary, RunReport), DemoError> {
    say.line(
        "\nverify      the plan on the controller (open loop) while the rig moves all 3 parts, \
         then one frame",
    );
    let bar = message_bar(json);
    let plain = bar.is_hidden() && !json;
    bar.set_length(plan.device.total_ms());
    bar.set_message("running the plan (ms)");
    let mut last_step = None;
    let ran = d.run(plan, |t: &Telemetry| {
        let s = &t.status;
        if s.step.is_some() {
            bar.set_position(s.elapsed_ms() as u64);
        }
        if plain && s.step != last_step {
            say.line(telemetry_line(t));
        }
        last_step = s.step;
        let stop = interrupted.is_some_and(|f| f.load(Ordering::SeqCst));
        if stop { ControlFlow::Break(()) } else { ControlFlow::Continue(()) }
    });
    bar.finish_and_clear();
    let (stored, ran) = ran?;
    let fault = (ran.fault.iter())
        .map(|f| format!("; {}", FaultJson::of(f, ran.sample_rate).text()))
        .collect::<String>();
    say.line(format!(
        "ran         '{}' (slot {}): {}, {:.1} s by the controller's clock{fault}",
        stored.name,
        stored.slot,
        ran.outcome,
        ran.executed_ms / 1000.0
    ));
    Ok((stored, ran))
}

/// Step 4b: the frame, the fed part judged, the others shown.
fn verify(say: Say, d: &SteerDemo, plan: &FedPlan) -> Result<Verified, DemoError> {
    let verified = d.verify(plan)?;
    let v = &verified.verification;
    for c in &v.parts {
        let l = &c.located;
        let how = match (&c.reason, c.orientation_error_deg, c.position_error_mm) {
            (Some(r), _, _) => format!("OFF: {r}"),
            (None, Some(deg), Some(mm)) => {
                format!("as planned (θ {deg:.2}° off, {mm:.2} mm off)")
            }
            (None, Some(deg), None) => format!("as planned (θ {deg:.2}° off)"),
            (None, None, _) => "as planned".to_string(),
        };
        say.line(format!(
            "{:<11} x {:.2} mm  y {:.2} mm  θ {:.2}°  {how}",
            l.part, l.x_mm, l.y_mm, l.theta_deg
        ));
    }
    for u in &v.unseen {
        say.line(format!("not seen    {}", u.reason));
    }
    if v.found == 0 {
        say.line(format!(
            "not seen    no part within {} mm of the planned position",
            work::FED_RADIUS_MM
        ));
    }
    for l in &verified.others {
        say.line(format!(
            "{:<11} x {:.2} mm  y {:.2} mm  θ {:.2}°  not fed where the plan holds: not judged",
            l.part, l.x_mm, l.y_mm, l.theta_deg
        ));
    }
    say.line(format!(
        "verdict     {} (within {}° and {} mm); frame {}, figure {}",
        if v.result == Outcome::Ok {
            "the fed part ended as planned"
        } else {
            "the fed part did NOT end as planned"
        },
        v.tolerance_deg,
        v.tolerance_mm,
        d.files.frame.display(),
        d.files.verify_figure.display()
    ));
    Ok(verified)
}
