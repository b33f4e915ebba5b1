//! `chladni device …`: requests to a running controller.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use chladni::controller::client::DeviceClient;
use chladni::model::plan_file::PlanFile;
use chladni_shared::icd::link::StatusReport;
use chladni_shared::icd::plan::{DeviceLimits, Plan};
use chladni_shared::icd::units::{MilliHz, Q15};
use clap::{Args, Subcommand};
use serde::Serialize;

use super::InputError;
use super::parse::{drive_amplitude, drive_freq};

/// Where the controller is.
#[derive(Debug, Args)]
pub struct PortArg {
    /// Serial device (e.g. /dev/ttyACM0) or tcp://HOST:PORT (the emulator prints it).
    #[arg(long, short)]
    port: String,
}

impl PortArg {
    fn open(&self) -> anyhow::Result<DeviceClient> {
        DeviceClient::open(&self.port).with_context(|| format!("connecting to {}", self.port))
    }
}

#[derive(Debug, Subcommand)]
pub enum DeviceCommand {
    /// Firmware version, board, protocol version and build id.
    Info {
        #[command(flatten)]
        port: PortArg,
        /// Print one JSON object instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Round-trip time of a ping.
    Ping {
        #[command(flatten)]
        port: PortArg,
        /// How many pings.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=10_000))]
        count: u32,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Drive a steady sine (manual mode) until `stop` or another command.
    Drive {
        #[command(flatten)]
        port: PortArg,
        /// Frequency, Hz (1–2000, resolved to 1 mHz).
        #[arg(long, value_name = "HZ", value_parser = drive_freq)]
        freq: u32,
        /// Amplitude, fraction of the DAC's full scale (0–1).
        #[arg(long, value_name = "A", value_parser = drive_amplitude)]
        amplitude: u16,
    },
    /// Send a plan (JSON file) and run it.
    RunFile {
        #[command(flatten)]
        port: PortArg,
        /// Plan file (as written by `chladni plan --out`): {"name", "repeat", "steps":
        /// [{"freq_hz", "duration_ms", "amplitude" (0..1), "ramp_ms"}], ...}; see docs/plan.md.
        plan: PathBuf,
        /// Stay and show the plan's progress until the drive is idle again (exit 1 on a fault).
        #[arg(long)]
        wait: bool,
    },
    /// Ramp the drive to zero and idle (also clears a fault).
    Stop {
        #[command(flatten)]
        port: PortArg,
    },
    /// The drive's state, step, elapsed time, frequency, amplitude and underruns.
    Status {
        #[command(flatten)]
        port: PortArg,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
}

/// Reads and validates a plan file; every problem is bad input (exit code 2).
pub fn read_plan(path: &std::path::Path) -> Result<Plan, InputError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| InputError(format!("cannot read plan {}: {e}", path.display())))?;
    let file =
        PlanFile::parse(&text).map_err(|e| InputError(format!("plan {}: {e}", path.display())))?;
    file.to_plan(&DeviceLimits::DEFAULT)
        .map_err(|e| InputError(format!("plan {} refused: {e}", path.display())))
}

/// The `status --json` object (keys in alphabetical order, as printed).
#[derive(Debug, Serialize)]
pub struct StatusJson {
    amplitude: f64,
    elapsed_ms: f64,
    freq_hz: f64,
    state: &'static str,
    step: Option<u16>,
    underruns: u32,
}

impl From<&StatusReport> for StatusJson {
    fn from(s: &StatusReport) -> Self {
        StatusJson {
            amplitude: Q15(s.amplitude_q15).to_fraction(),
            elapsed_ms: s.elapsed_ms(),
            freq_hz: MilliHz(s.freq_mhz).to_hz(),
            state: s.state.name(),
            step: s.step,
            underruns: s.underruns,
        }
    }
}

/// The `status --json` object as a JSON value.
#[cfg(test)]
pub fn status_json(s: &StatusReport) -> serde_json::Value {
    serde_json::to_value(StatusJson::from(s)).unwrap_or_default()
}

/// The `info --json` object.
#[derive(Debug, Serialize)]
struct InfoJson<'a> {
    board: &'static str,
    build_id: String,
    firmware_version: &'a str,
    protocol_version: u16,
}

/// The `ping --json` object.
#[derive(Debug, Serialize)]
struct PingJson {
    count: u32,
    max_ms: f64,
    mean_ms: f64,
}

impl DeviceCommand {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        match self {
            DeviceCommand::Info { port, json } => {
                let info = port.open()?.info()?;
                if *json {
                    let value = InfoJson {
                        board: info.board.name(),
                        build_id: format!("{:08x}", info.build_id),
                        firmware_version: info.firmware_version.as_str(),
                        protocol_version: info.protocol_version,
                    };
                    println!("{}", serde_json::to_string(&value)?);
                } else {
                    println!("firmware   {}", info.firmware_version);
                    println!("board      {}", info.board.name());
                    println!("protocol   {}", info.protocol_version);
                    println!("build id   {:08x}", info.build_id);
                }
            }
            DeviceCommand::Ping { port, count, json } => {
                let mut client = port.open()?;
                let mut rtts = Vec::with_capacity(*count as usize);
                for _ in 0..*count {
                    rtts.push(client.ping()?.as_secs_f64() * 1e3);
                }
                let mean = rtts.iter().sum::<f64>() / rtts.len() as f64;
                let max = rtts.iter().cloned().fold(0.0, f64::max);
                if *json {
                    let value = PingJson { count: *count, max_ms: max, mean_ms: mean };
                    println!("{}", serde_json::to_string(&value)?);
                } else {
                    println!("{count} ping(s): mean {mean:.3} ms, max {max:.3} ms");
                }
            }
            DeviceCommand::Drive { port, freq, amplitude } => {
                let (f, a) = (*freq, *amplitude);
                DeviceLimits::DEFAULT
                    .check_setpoint(f, a)
                    .map_err(|e| InputError(format!("drive refused: {e}")))?;
                port.open()?.drive(f, a)?;
                println!(
                    "driving {:.3} Hz at amplitude {:.4}",
                    MilliHz(f).to_hz(),
                    Q15(a).to_fraction()
                );
            }
            DeviceCommand::RunFile { port, plan, wait } => {
                let plan = read_plan(plan)?;
                let (name, steps, ms) = (plan.name.clone(), plan.steps.len(), plan.total_ms());
                let mut client = port.open()?;
                client.run_plan(plan)?;
                println!("running plan '{name}': {steps} step(s), {ms} ms");
                if *wait {
                    return watch_plan(&mut client, steps, ms);
                }
            }
            DeviceCommand::Stop { port } => {
                port.open()?.stop()?;
                println!("stopping");
            }
            DeviceCommand::Status { port, json } => {
                let s = port.open()?.status()?;
                if *json {
                    println!("{}", serde_json::to_string(&StatusJson::from(&s))?);
                } else {
                    println!("state      {}", s.state.name());
                    match s.step {
                        Some(step) => println!("step       {step} (run {})", s.run),
                        None => println!("step       -"),
                    }
                    println!("elapsed    {:.2} ms ({} samples)", s.elapsed_ms(), s.elapsed_samples);
                    println!("frequency  {:.3} Hz", MilliHz(s.freq_mhz).to_hz());
                    println!("amplitude  {:.4}", Q15(s.amplitude_q15).to_fraction());
                    println!("underruns  {}", s.underruns);
                }
            }
        }
        Ok(ExitCode::SUCCESS)
    }
}

/// Polls the controller until its drive is idle, with a progress bar over the plan's length;
/// prints what happened. A fault, or a drive that stops answering, fails the command.
fn watch_plan(client: &mut DeviceClient, steps: usize, total_ms: u64) -> anyhow::Result<ExitCode> {
    use chladni_shared::icd::link::DriveState;
    let bar = indicatif::ProgressBar::new(total_ms.max(1));
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40.cyan/blue} {pos:>7}/{len} ms  {msg}")
            .expect("static template"),
    );
    let mut steps_seen = std::collections::BTreeSet::new();
    let last = loop {
        let s = client.status()?;
        if let Some(step) = s.step {
            steps_seen.insert(step);
        }
        bar.set_position((s.elapsed_ms() as u64).min(total_ms));
        bar.set_message(format!(
            "{} · step {}/{} · {:.3} Hz · amplitude {:.3}",
            s.state.name(),
            s.step.map_or("-".to_string(), |i| (i + 1).to_string()),
            steps,
            MilliHz(s.freq_mhz).to_hz(),
            Q15(s.amplitude_q15).to_fraction()
        ));
        match s.state {
            DriveState::Idle => break s,
            DriveState::Faulted => {
                bar.abandon_with_message("faulted");
                anyhow::bail!("the drive faulted after {:.1} ms", s.elapsed_ms());
            }
            _ => std::thread::sleep(std::time::Duration::from_millis(100)),
        }
    };
    bar.finish_and_clear();
    println!(
        "plan done: {} of {} step(s) seen running, {:.1} ms, {} underrun(s)",
        steps_seen.len(),
        steps,
        last.elapsed_ms(),
        last.underruns
    );
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use chladni_shared::icd::link::DriveState;

    #[test]
    fn status_json_has_exactly_the_documented_fields() {
        let s = StatusReport {
            state: DriveState::RampUp,
            step: Some(2),
            run: 0,
            elapsed_samples: 12_345,
            sample_rate: 50_000,
            freq_mhz: 181_500,
            amplitude_q15: 32767,
            underruns: 3,
            commands: 9,
        };
        let v = status_json(&s);
        let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        assert_eq!(keys, ["amplitude", "elapsed_ms", "freq_hz", "state", "step", "underruns"]);
        assert_eq!(v["state"], "ramp_up");
        assert_eq!(v["step"], 2);
        assert_eq!(v["elapsed_ms"], 246.9);
        assert_eq!(v["freq_hz"], 181.5);
        assert_eq!(v["amplitude"], 1.0);
        assert_eq!(v["underruns"], 3);
        let idle = StatusReport { state: DriveState::Idle, step: None, ..s };
        assert!(status_json(&idle)["step"].is_null());
    }

    #[test]
    fn bad_input_is_named() {
        use super::super::parse::{drive_amplitude, drive_freq};
        assert!(drive_amplitude("1.5").unwrap_err().contains("amplitude 1.5"));
        assert_eq!(drive_amplitude("1.0"), Ok(32767));
        assert!(drive_freq("NaN").is_err());
        assert_eq!(drive_freq("440.125"), Ok(440_125));
        let dir = std::env::temp_dir().join(format!("chladni-plan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("p.json");
        std::fs::write(&path, r#"{"name":"x","repeat":1,"steps":[{"freq_hz":0.5,"amplitude":0.1,"duration_ms":5,"ramp_ms":0}]}"#).unwrap();
        assert!(read_plan(&path).unwrap_err().0.contains("step 0: frequency 0.500 Hz"));
        std::fs::write(&path, "{").unwrap();
        assert!(read_plan(&path).unwrap_err().0.contains("not a valid plan"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
