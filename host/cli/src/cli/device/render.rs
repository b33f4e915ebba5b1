//! What `chladni device` prints: the JSON shapes of [`chladni_device::json`] (documented
//! in docs/device.md; keys in alphabetical order, as printed) and the tables for people.

use std::process::ExitCode;

use chladni_shared::icd::link::{DeviceInfo, RunNumber, StatusReport, Telemetry};
use chladni_shared::icd::plan::Level;
use chladni_shared::icd::store::{DeviceConfig, PlanSummary};
use serde::Serialize;

pub use chladni_device::json::{
    DeletedJson, DriveJson, FaultJson, InfoJson, PingsJson, PlanJson, PlansJson, RunJson,
    RunNumberJson, StatusJson, TelemetryJson,
};

use chladni_device::config_keys::{CONFIG_KEYS, ConfigKey, ConfigValue};
use chladni_device::json::config_json;

/// Prints one JSON value on one line.
pub fn print_json(value: &impl Serialize) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string(value)?);
    Ok(())
}

/// The latched fault of `s` for people (cause, value and unit, time, the fix), or "-".
pub fn fault_text(s: &StatusReport) -> String {
    s.fault.map_or("-".into(), |f| FaultJson::of(&f, s.sample_rate).text())
}

/// `info`.
pub fn info(info: &DeviceInfo, json: bool) -> anyhow::Result<ExitCode> {
    if json {
        print_json(&InfoJson::from(info))?;
    } else {
        println!("firmware   {}", info.firmware_version);
        println!("board      {}", info.board.name());
        println!("protocol   {}", info.protocol_version);
        println!("build id   {:08x}", info.build_id);
    }
    Ok(ExitCode::SUCCESS)
}

/// `ping`: round-trip times in ms.
pub fn pings(rtts: &[f64], json: bool) -> anyhow::Result<ExitCode> {
    let p = PingsJson::of(rtts);
    if json {
        print_json(&p)?;
    } else {
        println!("{} ping(s): mean {:.3} ms, max {:.3} ms", p.count, p.mean_ms, p.max_ms);
    }
    Ok(ExitCode::SUCCESS)
}

/// `plans`.
pub fn plans(plans: &[PlanSummary], free_bytes: u32, json: bool) -> anyhow::Result<ExitCode> {
    if json {
        let plans = plans.iter().map(PlanJson::from).collect();
        print_json(&PlansJson { free_bytes, plans })?;
        return Ok(ExitCode::SUCCESS);
    }
    if plans.is_empty() {
        println!("no plans stored");
    } else {
        println!("slot  {:<32}  steps  repeat  total ms  crc       bytes", "name");
        for p in plans {
            println!(
                "{:>4}  {:<32}  {:>5}  {:>6}  {:>8}  {:08x}  {:>5}",
                p.slot, p.name, p.steps, p.repeat, p.total_ms, p.crc, p.bytes
            );
        }
    }
    println!("free: {free_bytes} bytes");
    Ok(ExitCode::SUCCESS)
}

/// `upload`.
pub fn uploaded(p: &PlanSummary, json: bool) -> anyhow::Result<ExitCode> {
    if json {
        print_json(&PlanJson::from(p))?;
    } else {
        println!(
            "stored '{}' in slot {}: {} step(s) × {}, {} ms, CRC {:08x}, {} bytes",
            p.name, p.slot, p.steps, p.repeat, p.total_ms, p.crc, p.bytes
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// `drive`: `{"accel_mps2", "amplitude", "freq_hz", "run"}`, the level not given null.
pub fn driving(freq: u32, level: Level, run: RunNumber, json: bool) -> anyhow::Result<ExitCode> {
    let d = DriveJson::of(freq, level, run);
    let hz = d.freq_hz;
    if json {
        print_json(&d)?;
    } else if let Some(a) = d.amplitude {
        println!("driving {hz:.3} Hz at amplitude {a:.4} (run {})", run.0);
    } else if let Some(a) = d.accel_mps2 {
        println!("driving {hz:.3} Hz holding {a:.3} m/s² (closed loop; run {})", run.0);
    }
    Ok(ExitCode::SUCCESS)
}

/// `clear-fault`.
pub fn cleared(run: RunNumber, json: bool) -> anyhow::Result<ExitCode> {
    if json {
        print_json(&RunNumberJson { run: run.0 })?;
    } else {
        println!("fault cleared (run {})", run.0);
    }
    Ok(ExitCode::SUCCESS)
}

/// `stop`.
pub fn stopped(run: RunNumber, json: bool) -> anyhow::Result<ExitCode> {
    if json {
        print_json(&RunNumberJson { run: run.0 })?;
    } else {
        println!("stopping (run {})", run.0);
    }
    Ok(ExitCode::SUCCESS)
}

/// `status`.
pub fn status(s: &StatusReport, json: bool) -> anyhow::Result<ExitCode> {
    if json {
        print_json(&StatusJson::from(s))?;
        return Ok(ExitCode::SUCCESS);
    }
    for (label, value) in status_lines(s) {
        println!("{label:<10} {value}");
    }
    Ok(ExitCode::SUCCESS)
}

/// A 0-based index from the controller (the running step, the repetition) as people count:
/// from 1, as `chladni plan` numbers steps. The JSON keeps the controller's index.
pub fn counted(index: u16) -> u32 {
    u32::from(index) + 1
}

/// The `status` table, as (label, value) lines.
pub fn status_lines(s: &StatusReport) -> Vec<(&'static str, String)> {
    let j = StatusJson::from(s);
    let mut lines = vec![("state", j.state.to_string()), ("run", j.run.to_string())];
    match (&s.plan, s.step) {
        (Some(plan), Some(step)) => {
            let (step, rep) = (counted(step), counted(s.repetition));
            lines.push(("plan", format!("{plan}: step {step}, repetition {rep}")));
            lines.push(("remaining", format!("{:.1} ms", j.remaining_ms)));
        }
        (Some(plan), None) => lines.push(("plan", plan.to_string())),
        _ => lines.push(("plan", "-".into())),
    }
    lines.push(("elapsed", format!("{:.2} ms ({} samples)", j.elapsed_ms, s.elapsed_samples)));
    lines.push(("frequency", format!("{:.3} Hz", j.freq_hz)));
    let target = j.target_accel_mps2.map_or(String::new(), |t| {
        format!(
            " (closed loop, target {t:.3} m/s²{})",
            if j.warning { ", WARNING: outside the warning band" } else { "" }
        )
    });
    lines.push(("effort", format!("{:.4}{target}", j.effort)));
    lines.push(match (j.accel_mps2, j.phase_deg) {
        (Some(a), Some(p)) => ("measured", format!("{a:.3} m/s² at {p:.1}°")),
        _ => ("measured", "-".into()),
    });
    if j.warning && j.target_accel_mps2.is_none() {
        lines.push(("warning", "the response is outside the warning band".into()));
    }
    lines.push(("underruns", j.underruns.to_string()));
    lines.push(("fault", j.fault.as_ref().map_or("-".into(), FaultJson::text)));
    lines.push(("reset", j.reset_cause.to_string()));
    lines
}

/// One `monitor` line for people.
pub fn telemetry_line(t: &Telemetry) -> String {
    let s = &t.status;
    let j = StatusJson::from(s);
    let step = match (&s.plan, s.step) {
        (Some(plan), Some(step)) => {
            format!(
                "plan '{plan}' step {} rep {} remaining {:.0} ms",
                counted(step),
                counted(s.repetition),
                j.remaining_ms
            )
        }
        _ => "no plan".to_string(),
    };
    let measured = match (j.accel_mps2, j.phase_deg) {
        (Some(a), Some(p)) => format!("{a:>8.3} m/s² {p:>7.1}°"),
        _ => format!("{:>8} m/s² {:>7}°", "-", "-"),
    };
    let target = j.target_accel_mps2.map_or(String::new(), |t| format!(" → {t:.3} m/s²"));
    let warning = if j.warning { "  WARN" } else { "" };
    let fault = j.fault.as_ref().map_or(String::new(), |f| format!("  FAULT {}", f.text()));
    format!(
        "#{:<5} {:<9} {:>9.3} Hz  effort {:.4}{target}  {measured}  {step}  run {}{warning}{fault}",
        t.seq, j.state, j.freq_hz, j.effort, j.run
    )
}

/// `config get [KEY]` and `config set`.
pub fn config(
    config: &DeviceConfig,
    key: Option<ConfigKey>,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let keys: Vec<ConfigKey> = key.map_or(CONFIG_KEYS.to_vec(), |k| vec![k]);
    if json {
        print_json(&config_json(config, &keys))?;
        return Ok(ExitCode::SUCCESS);
    }
    for k in keys {
        let value = match k.get(config) {
            ConfigValue::Real(v) => format!("{v}"),
            ConfigValue::Count(v) => format!("{v}"),
        };
        if key.is_some() {
            println!("{value}");
        } else {
            println!("{:<16} {value}", k.name());
        }
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use chladni_device::json::STATUS_KEYS;
    use chladni_shared::icd::link::{DriveState, Fault, FaultCause};

    pub fn status_report() -> StatusReport {
        StatusReport {
            state: DriveState::RampUp,
            step: Some(2),
            repetition: 1,
            run: RunNumber(17),
            plan: Some("square-45".try_into().unwrap()),
            remaining_samples: 25_000,
            elapsed_samples: 12_345,
            freq_mhz: 181_500,
            amplitude_q15: 32767,
            underruns: 3,
            commands: 9,
            least_slack_us: Some(4_321),
            stack_high_water: 10_240,
            ..StatusReport::IDLE
        }
    }

    fn keys(v: &serde_json::Value) -> Vec<&str> {
        v.as_object().unwrap().keys().map(|k| k.as_str()).collect()
    }

    #[test]
    fn status_json_keeps_the_old_keys_and_adds_plan_remaining_run_fault() {
        let s = status_report();
        let v = serde_json::to_value(StatusJson::from(&s)).unwrap();
        assert_eq!(keys(&v), STATUS_KEYS);
        assert_eq!(v["state"], "ramp_up");
        assert_eq!(v["step"], 2);
        assert_eq!(v["elapsed_ms"], 246.9);
        assert_eq!(v["freq_hz"], 181.5);
        assert_eq!(v["amplitude"], 1.0);
        assert_eq!(v["underruns"], 3);
        assert_eq!(
            (v["plan"].as_str(), v["remaining_ms"].as_f64()),
            (Some("square-45"), Some(500.0))
        );
        assert_eq!((v["run"].as_u64(), v["fault"].is_null()), (Some(17), true));
        let faulted = StatusReport {
            state: DriveState::Faulted,
            step: None,
            plan: None,
            fault: Some(Fault { cause: FaultCause::LoopOpen, value: 12, at_sample: 5 }),
            ..s
        };
        let v = serde_json::to_value(StatusJson::from(&faulted)).unwrap();
        assert_eq!(v["state"].as_str(), Some("faulted"));
        assert_eq!(keys(&v["fault"]), ["at_s", "cause", "unit", "value"]);
        assert!(v["step"].is_null() && v["plan"].is_null());
    }

    #[test]
    fn status_shows_the_measurement_target_warning_fault_and_reset_cause() {
        use chladni_shared::icd::link::Measurement;
        use chladni_shared::icd::sense::ResetCause;
        let closed = StatusReport {
            state: DriveState::Running,
            level: Some(Level::Accel(25_000)),
            measured: Some(Measurement { accel_mmps2: 24_310, phase_mdeg: -91_250 }),
            amplitude_q15: 8192,
            warning: true,
            reset_cause: ResetCause::Watchdog,
            fault: Some(Fault { cause: FaultCause::OutOfBand, value: -3_250, at_sample: 125_000 }),
            ..status_report()
        };
        let v = serde_json::to_value(StatusJson::from(&closed)).unwrap();
        assert_eq!(
            (v["accel_mps2"].as_f64(), v["phase_deg"].as_f64()),
            (Some(24.31), Some(-91.25))
        );
        assert_eq!(
            (v["effort"].as_f64(), v["target_accel_mps2"].as_f64()),
            (Some(8192.0 / 32767.0), Some(25.0))
        );
        assert_eq!(
            (v["warning"].as_bool(), v["reset_cause"].as_str()),
            (Some(true), Some("watchdog"))
        );
        assert_eq!(
            v["fault"],
            serde_json::json!({"at_s": 2.5, "cause": "out_of_band", "unit": "mdB", "value": -3250})
        );
        let lines = status_lines(&closed);
        let line = |label: &str| lines.iter().find(|(l, _)| *l == label).unwrap().1.clone();
        assert_eq!(line("measured"), "24.310 m/s² at -91.2°");
        assert_eq!(
            line("effort"),
            "0.2500 (closed loop, target 25.000 m/s², WARNING: outside the warning band)"
        );
        assert_eq!(
            line("fault"),
            "out_of_band -3250 mdB at 2.500 s (`chladni device clear-fault` clears it)"
        );
        assert_eq!(line("reset"), "watchdog");
        // The running step and repetition (0-based on the wire: 2 and 1) as people count them.
        assert_eq!(line("plan"), "square-45: step 3, repetition 2");
        // Open loop, no sensor data: nulls, and "-" for people.
        let open = status_report();
        let v = serde_json::to_value(StatusJson::from(&open)).unwrap();
        assert!(v["accel_mps2"].is_null() && v["phase_deg"].is_null());
        assert!(v["target_accel_mps2"].is_null() && v["fault"].is_null());
        assert_eq!(status_lines(&open).iter().find(|(l, _)| *l == "measured").unwrap().1, "-");
        let t = Telemetry { seq: 1, left: 0, status: closed };
        let text = telemetry_line(&t);
        assert!(text.contains("effort 0.2500 → 25.000 m/s²"), "{text}");
        assert!(text.contains("24.310 m/s²   -91.2°") && text.contains("WARN"), "{text}");
        assert!(text.contains("FAULT out_of_band -3250 mdB at 2.500 s"), "{text}");
    }

    #[test]
    fn telemetry_json_is_the_status_with_seq_and_left() {
        let t = Telemetry { seq: 4, left: 6, status: status_report() };
        let v = serde_json::to_value(TelemetryJson::from(&t)).unwrap();
        assert_eq!((v["seq"].as_u64(), v["left"].as_u64()), (Some(4), Some(6)));
        assert_eq!(v["state"], "ramp_up");
        assert_eq!(v.as_object().unwrap().len(), STATUS_KEYS.len() + 2);
        let line = telemetry_line(&t);
        assert!(line.contains("plan 'square-45' step 3 rep 2 remaining 500 ms"), "{line}");
        assert!(line.contains("181.500 Hz") && line.contains("run 17"), "{line}");
    }

    #[test]
    fn plans_json_has_the_documented_shape() {
        let p = PlanSummary {
            slot: 3,
            name: "a".try_into().unwrap(),
            steps: 12,
            repeat: 2,
            total_ms: 5400,
            crc: 0xdead_beef,
            bytes: 812,
        };
        let v =
            serde_json::to_value(PlansJson { free_bytes: 1000, plans: vec![PlanJson::from(&p)] })
                .unwrap();
        assert_eq!(keys(&v), ["free_bytes", "plans"]);
        assert_eq!(
            keys(&v["plans"][0]),
            ["bytes", "crc", "name", "repeat", "slot", "steps", "total_ms"]
        );
        assert_eq!(v["plans"][0]["repeat"], 2);
        assert_eq!(v["plans"][0]["crc"], 0xdead_beef_u32);
        assert_eq!(v["plans"][0]["name"], "a");
    }
}
