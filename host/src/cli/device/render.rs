//! What `chladni device` prints: the JSON shapes (documented in docs/drive.md; keys in
//! alphabetical order, as printed) and the tables for people.

use std::process::ExitCode;

use chladni_shared::icd::link::{DeviceInfo, RunNumber, StatusReport, Telemetry};
use chladni_shared::icd::store::{DeviceConfig, PlanSummary};
use chladni_shared::icd::units::{MilliHz, Q15};
use serde::Serialize;

use super::values::{CONFIG_KEYS, ConfigKey, ConfigValue};

/// Prints one JSON value on one line.
pub fn print_json(value: &impl Serialize) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string(value)?);
    Ok(())
}

/// The `status --json` object: the keys of protocol v1's status, and `fault`, `plan`,
/// `remaining_ms`, `run`.
#[derive(Debug, Serialize)]
pub struct StatusJson {
    amplitude: f64,
    elapsed_ms: f64,
    fault: Option<&'static str>,
    freq_hz: f64,
    plan: Option<String>,
    remaining_ms: f64,
    run: u32,
    state: &'static str,
    step: Option<u16>,
    underruns: u32,
}

impl From<&StatusReport> for StatusJson {
    fn from(s: &StatusReport) -> Self {
        StatusJson {
            amplitude: Q15(s.amplitude_q15).to_fraction(),
            elapsed_ms: s.elapsed_ms(),
            fault: s.fault.map(|f| f.cause.name()),
            freq_hz: MilliHz(s.freq_mhz).to_hz(),
            plan: s.plan.as_ref().map(|p| p.to_string()),
            remaining_ms: s.remaining_ms(),
            run: s.run.0,
            state: s.state.name(),
            step: s.step,
            underruns: s.underruns,
        }
    }
}

/// One line of `monitor --json`: the sample's number, how many are still to come, and the
/// status keys of `status --json`.
#[derive(Debug, Serialize)]
pub struct TelemetryJson {
    left: u32,
    seq: u32,
    #[serde(flatten)]
    status: StatusJson,
}

impl From<&Telemetry> for TelemetryJson {
    fn from(t: &Telemetry) -> Self {
        TelemetryJson { left: t.left, seq: t.seq, status: StatusJson::from(&t.status) }
    }
}

/// One stored plan, as `plans --json`, `upload --json` and `delete --json` print it.
#[derive(Debug, Serialize)]
pub struct PlanJson {
    bytes: u32,
    /// The plan CRC (CRC-32/ISO-HDLC), as a number; the tables print it as 8 hex digits.
    crc: u32,
    name: String,
    slot: u8,
    steps: u16,
    total_ms: u64,
}

impl From<&PlanSummary> for PlanJson {
    fn from(p: &PlanSummary) -> Self {
        PlanJson {
            bytes: p.bytes,
            crc: p.crc,
            name: p.name.to_string(),
            slot: p.slot,
            steps: p.steps,
            total_ms: p.total_ms,
        }
    }
}

/// The `plans --json` object.
#[derive(Debug, Serialize)]
pub struct PlansJson {
    free_bytes: u32,
    plans: Vec<PlanJson>,
}

/// `info`.
pub fn info(info: &DeviceInfo, json: bool) -> anyhow::Result<ExitCode> {
    if json {
        print_json(&serde_json::json!({
            "board": info.board.name(),
            "build_id": format!("{:08x}", info.build_id),
            "firmware_version": info.firmware_version.as_str(),
            "protocol_version": info.protocol_version,
        }))?;
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
    let mean = rtts.iter().sum::<f64>() / rtts.len().max(1) as f64;
    let max = rtts.iter().cloned().fold(0.0, f64::max);
    if json {
        print_json(&serde_json::json!({ "count": rtts.len(), "max_ms": max, "mean_ms": mean }))?;
    } else {
        println!("{} ping(s): mean {mean:.3} ms, max {max:.3} ms", rtts.len());
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

/// `drive`.
pub fn driving(freq: u32, amplitude: u16, run: RunNumber, json: bool) -> anyhow::Result<ExitCode> {
    let (hz, a) = (MilliHz(freq).to_hz(), Q15(amplitude).to_fraction());
    if json {
        print_json(&serde_json::json!({ "amplitude": a, "freq_hz": hz, "run": run.0 }))?;
    } else {
        println!("driving {hz:.3} Hz at amplitude {a:.4} (run {})", run.0);
    }
    Ok(ExitCode::SUCCESS)
}

/// `stop`.
pub fn stopped(run: RunNumber, json: bool) -> anyhow::Result<ExitCode> {
    if json {
        print_json(&serde_json::json!({ "run": run.0 }))?;
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
    println!("state      {}", s.state.name());
    println!("run        {}", s.run.0);
    match (&s.plan, s.step) {
        (Some(plan), Some(step)) => {
            println!("plan       {plan}: step {step}, repetition {}", s.repetition);
            println!("remaining  {:.1} ms", s.remaining_ms());
        }
        (Some(plan), None) => println!("plan       {plan}"),
        _ => println!("plan       -"),
    }
    println!("elapsed    {:.2} ms ({} samples)", s.elapsed_ms(), s.elapsed_samples);
    println!("frequency  {:.3} Hz", MilliHz(s.freq_mhz).to_hz());
    println!("amplitude  {:.4}", Q15(s.amplitude_q15).to_fraction());
    println!("underruns  {}", s.underruns);
    if let Some(fault) = s.fault {
        println!("fault      {} (`chladni device stop` clears it)", fault.cause.name());
    }
    Ok(ExitCode::SUCCESS)
}

/// One `monitor` line for people.
pub fn telemetry_line(t: &Telemetry) -> String {
    let s = &t.status;
    let step = match (&s.plan, s.step) {
        (Some(plan), Some(step)) => {
            format!(
                "plan '{plan}' step {step} rep {} remaining {:.0} ms",
                s.repetition,
                s.remaining_ms()
            )
        }
        _ => "no plan".to_string(),
    };
    let fault = s.fault.map_or(String::new(), |f| format!("  FAULT {}", f.cause.name()));
    format!(
        "#{:<5} {:<9} {:>9.3} Hz  amplitude {:.4}  {step}  run {}{fault}",
        t.seq,
        s.state.name(),
        MilliHz(s.freq_mhz).to_hz(),
        Q15(s.amplitude_q15).to_fraction(),
        s.run.0
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
        let map: serde_json::Map<String, serde_json::Value> =
            keys.iter().map(|k| (k.name().to_string(), k.get(config).to_json())).collect();
        print_json(&map)?;
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
            println!("{:<14} {value}", k.name());
        }
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;
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
        assert_eq!(
            keys(&v),
            [
                "amplitude",
                "elapsed_ms",
                "fault",
                "freq_hz",
                "plan",
                "remaining_ms",
                "run",
                "state",
                "step",
                "underruns"
            ]
        );
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
        assert_eq!(
            (v["state"].as_str(), v["fault"].as_str()),
            (Some("faulted"), Some("loop_open"))
        );
        assert!(v["step"].is_null() && v["plan"].is_null());
    }

    #[test]
    fn telemetry_json_is_the_status_with_seq_and_left() {
        let t = Telemetry { seq: 4, left: 6, status: status_report() };
        let v = serde_json::to_value(TelemetryJson::from(&t)).unwrap();
        assert_eq!((v["seq"].as_u64(), v["left"].as_u64()), (Some(4), Some(6)));
        assert_eq!(v["state"], "ramp_up");
        assert_eq!(v.as_object().unwrap().len(), 12);
        let line = telemetry_line(&t);
        assert!(line.contains("plan 'square-45' step 2 rep 1 remaining 500 ms"), "{line}");
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
        assert_eq!(keys(&v["plans"][0]), ["bytes", "crc", "name", "slot", "steps", "total_ms"]);
        assert_eq!(v["plans"][0]["crc"], 0xdead_beef_u32);
        assert_eq!(v["plans"][0]["name"], "a");
    }
}
