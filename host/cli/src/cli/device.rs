//! `chladni device …`: requests to a running controller (the board or the emulator).
//!
//! Thin: parse, call [`chladni_device::client`], render. Every command takes `--json`.
//! The submodules hold the value parsers and config keys ([`values`]), the JSON shapes and
//! tables ([`render`]), serial port listing ([`ports`]), what takes time: waiting for a run,
//! the telemetry monitor, Ctrl-C ([`watch`]), and the frequency sweep ([`sweep`]).

mod ports;
pub(crate) mod render;
mod sweep;
mod values;
pub(crate) mod watch;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use chladni_core::model::plan_file::PlanFile;
use chladni_device::client::DeviceClient;
use chladni_device::client::DeviceError;
use chladni_shared::icd::link::Refusal;
use chladni_shared::icd::plan::{DeviceLimits, Level, Plan};
use chladni_shared::icd::store::{DeviceConfig, PlanName, PlanRef, SCRATCH_SLOT};
use clap::{Args, Subcommand};

use super::InputError;
use super::parse::{drive_accel, drive_amplitude, drive_freq};
use chladni_device::config_keys::{ConfigKey, ConfigValueError, config_key, config_refusal};
use chladni_device::json::StoreJson;
use render::{DeletedJson, PlanJson, print_json};
use values::{plan_name, plan_target, slot};

/// Where the controller is.
#[derive(Debug, Args)]
pub struct PortArg {
    /// Serial device (e.g. /dev/ttyACM0, see `chladni device list`) or tcp://HOST:PORT (the
    /// emulator prints it).
    #[arg(long, short)]
    port: String,
}

impl PortArg {
    /// Opens a session named after the command and this process (others see it when busy).
    fn open(&self, command: &str) -> anyhow::Result<DeviceClient> {
        let name = format!("chladni device {command} (pid {})", std::process::id());
        DeviceClient::open(&self.port, &name)
            .with_context(|| format!("connecting to {}", self.port))
    }
}

#[derive(Debug, Subcommand)]
pub enum DeviceCommand {
    /// Serial ports, with USB vendor:product ids; the controller and the ST-LINK console marked.
    List {
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Firmware version, board, protocol version, build id, and what the plan store holds.
    Info {
        #[command(flatten)]
        port: PortArg,
        /// Print JSON.
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
    /// What the plan store's flash holds; `--format` erases it (every plan and the
    /// configuration, or data the controller did not write) and formats it.
    Store {
        #[command(flatten)]
        port: PortArg,
        /// Erase the whole store and format it (the only way to reuse flash that holds data
        /// the controller did not write).
        #[arg(long)]
        format: bool,
        /// Print JSON: {"area_bytes","layout","state"}.
        #[arg(long)]
        json: bool,
    },
    /// The plans stored on the controller, and the free flash.
    Plans {
        #[command(flatten)]
        port: PortArg,
        /// Print JSON: {"plans":[{"slot","name","steps","total_ms","crc","bytes"}],"free_bytes"}.
        #[arg(long)]
        json: bool,
    },
    /// Store a plan file on the controller (replaces the plan of the same name or slot).
    Upload {
        #[command(flatten)]
        port: PortArg,
        /// Plan file (as written by `chladni plan --out`; see docs/plan.md).
        plan: PathBuf,
        /// Slot to store into (0..=64); default: the plan of the same name, else the first free.
        #[arg(long, value_parser = slot)]
        slot: Option<u8>,
        /// Store under this name instead of the file's.
        #[arg(long, value_parser = plan_name)]
        name: Option<PlanName>,
        /// Print the stored plan as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Delete a stored plan, by name or slot (a value that is a number is a slot).
    Delete {
        #[command(flatten)]
        port: PortArg,
        /// Plan name, or slot number.
        #[arg(value_name = "NAME|SLOT", value_parser = plan_target)]
        plan: PlanRef,
        /// Print what was deleted as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Run a stored plan, by name or slot (a value that is a number is a slot).
    Run {
        #[command(flatten)]
        port: PortArg,
        /// Plan name, or slot number.
        #[arg(value_name = "NAME|SLOT", value_parser = plan_target)]
        plan: PlanRef,
        /// Run the steps this many times instead of the plan's own repeat count.
        #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
        repeat: Option<u16>,
        #[command(flatten)]
        wait: WaitArgs,
    },
    /// Upload a plan file to the scratch slot (64) and run it.
    RunFile {
        #[command(flatten)]
        port: PortArg,
        /// Plan file (as written by `chladni plan --out`): {"name", "repeat", "steps":
        /// [{"freq_hz", "duration_ms", "amplitude" (0..1) or "accel_mps2", "ramp_ms"}], ...};
        /// see docs/plan.md.
        plan: PathBuf,
        #[command(flatten)]
        wait: WaitArgs,
    },
    /// Drive a steady sine (manual mode) until `stop` or another command.
    Drive {
        #[command(flatten)]
        port: PortArg,
        /// Frequency, Hz (1–2000, resolved to 1 mHz).
        #[arg(long, value_name = "HZ", value_parser = drive_freq)]
        freq: u32,
        #[command(flatten)]
        level: LevelArgs,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Ramp the drive to zero and idle (a latched fault stays: `clear-fault`). Taken from any
    /// client.
    Stop {
        #[command(flatten)]
        port: PortArg,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Clear a latched fault (nothing else clears it: not a stop, not a new run).
    ClearFault {
        #[command(flatten)]
        port: PortArg,
        /// Print JSON: {"run"}.
        #[arg(long)]
        json: bool,
    },
    /// Sweep the drive over a frequency range, measure the plate's response, find its
    /// resonances (frequency and Q): table, CSV, Bode plot, plate-file modes.
    Sweep(sweep::SweepArgs),
    /// The drive's state, plan, step, times, frequency, amplitude, run number, the measured
    /// acceleration and phase, the closed-loop target, the warning, the fault and the reset
    /// cause.
    Status {
        #[command(flatten)]
        port: PortArg,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Live telemetry: one line per sample until Ctrl-C (or --count samples).
    Monitor {
        #[command(flatten)]
        port: PortArg,
        /// Samples per second (1..=100).
        #[arg(long, value_name = "HZ", default_value_t = 10,
              value_parser = clap::value_parser!(u16).range(1..=100))]
        rate: u16,
        /// Stop after this many samples.
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
        count: Option<u32>,
        /// One JSON object per line.
        #[arg(long)]
        json: bool,
    },
    /// The controller's configuration (device limits and fault-monitor thresholds).
    #[command(subcommand)]
    Config(ConfigCommand),
}

/// The level of a manual drive: exactly one of `--amplitude` and `--accel`.
#[derive(Debug, Args)]
#[group(required = true, multiple = false)]
pub struct LevelArgs {
    /// Amplitude, fraction of the DAC's full scale (0–1): open loop.
    #[arg(long, value_name = "A", value_parser = drive_amplitude)]
    amplitude: Option<u16>,
    /// Acceleration amplitude the controller holds, m/s² (resolved to 1 mm/s²): closed loop,
    /// after a short loop check.
    #[arg(long, value_name = "MPS2", value_parser = drive_accel)]
    accel: Option<u32>,
}

impl LevelArgs {
    fn level(&self) -> Level {
        match (self.amplitude, self.accel) {
            (_, Some(accel)) => Level::Accel(accel),
            (amplitude, None) => Level::Drive(amplitude.unwrap_or(0)),
        }
    }
}

/// `--wait` and `--json` of the commands that start a plan.
#[derive(Debug, Args)]
pub struct WaitArgs {
    /// Stay until the plan ends: exit 1 if it never starts, is superseded or faults; Ctrl-C
    /// stops the plan (exit 130).
    #[arg(long)]
    wait: bool,
    /// Print JSON (with --wait: at the end).
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Subcommand)]
pub enum ConfigCommand {
    /// Print the configuration, or one key of it.
    Get {
        #[command(flatten)]
        port: PortArg,
        /// A key (see docs/device.md): min_freq_hz, max_freq_hz, max_amplitude,
        /// max_accel_mps2, max_steps, max_total_ms, or a fault-monitor threshold
        /// (open_loop_mps2, warn_band_db, ..., check_min_mps2).
        #[arg(value_parser = config_key)]
        key: Option<ConfigKey>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Change one key (the controller checks and stores the whole configuration).
    Set {
        #[command(flatten)]
        port: PortArg,
        /// A key, as for `config get`.
        #[arg(value_parser = config_key)]
        key: ConfigKey,
        /// The new value in the key's unit: Hz, fraction of full scale (0..1), m/s², dB, ms or
        /// steps.
        value: String,
        /// Print the configuration now in effect as JSON.
        #[arg(long)]
        json: bool,
    },
}

/// Reads and validates a plan file; every problem is bad input (exit code 2).
pub fn read_plan(path: &Path) -> Result<Plan, InputError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| InputError(format!("cannot read plan {}: {e}", path.display())))?;
    let file =
        PlanFile::parse(&text).map_err(|e| InputError(format!("plan {}: {e}", path.display())))?;
    file.to_plan(&DeviceLimits::DEFAULT).map_err(|e| match e.device_limit_fix() {
        Some(fix) => InputError(format!(
            "plan {} refused by the controller's limits: {e}; {fix}",
            path.display()
        )),
        None => InputError(format!("plan {} refused: {e}", path.display())),
    })
}

impl DeviceCommand {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        match self {
            DeviceCommand::List { json } => ports::list(*json),
            DeviceCommand::Info { port, json } => info(port, *json),
            DeviceCommand::Store { port, format, json } => store(port, *format, *json),
            DeviceCommand::Ping { port, count, json } => ping(port, *count, *json),
            DeviceCommand::Plans { port, json } => {
                let (plans, free) = port.open("plans")?.list_plans()?;
                render::plans(&plans, free, *json)
            }
            DeviceCommand::Upload { port, plan, slot, name, json } => {
                let mut plan = read_plan(plan)?;
                if let Some(name) = name {
                    plan.name = name.clone();
                }
                let summary = watch::upload(&mut port.open("upload")?, &plan, *slot)?;
                render::uploaded(&summary, *json)
            }
            DeviceCommand::Delete { port, plan, json } => {
                let deleted = port.open("delete")?.delete(plan.clone())?;
                if *json {
                    print_json(&DeletedJson { deleted: PlanJson::from(&deleted) })?;
                } else {
                    println!("deleted '{}' from slot {}", deleted.name, deleted.slot);
                }
                Ok(ExitCode::SUCCESS)
            }
            DeviceCommand::Run { port, plan, repeat, wait } => {
                let mut client = port.open("run")?;
                let target = watch::Target::of(plan.clone());
                watch::start_plan(&mut client, &target, *repeat, wait.wait, wait.json)
            }
            DeviceCommand::RunFile { port, plan, wait } => run_file(port, plan, wait),
            DeviceCommand::Drive { port, freq, level, json } => {
                drive(port, *freq, level.level(), *json)
            }
            DeviceCommand::Stop { port, json } => {
                let run = port.open("stop")?.stop()?;
                render::stopped(run, *json)
            }
            DeviceCommand::ClearFault { port, json } => {
                let run = port.open("clear-fault")?.clear_fault()?;
                render::cleared(run, *json)
            }
            DeviceCommand::Sweep(args) => args.run(),
            DeviceCommand::Status { port, json } => {
                render::status(&port.open("status")?.status()?, *json)
            }
            DeviceCommand::Monitor { port, rate, count, json } => {
                watch::monitor(&mut port.open("monitor")?, *rate, *count, *json)
            }
            DeviceCommand::Config(cmd) => cmd.run(),
        }
    }
}

fn ping(port: &PortArg, count: u32, json: bool) -> anyhow::Result<ExitCode> {
    let mut client = port.open("ping")?;
    let mut rtts = Vec::with_capacity(count as usize);
    for _ in 0..count {
        rtts.push(client.ping()?.as_secs_f64() * 1e3);
    }
    render::pings(&rtts, json)
}

fn drive(port: &PortArg, freq: u32, level: Level, json: bool) -> anyhow::Result<ExitCode> {
    DeviceLimits::DEFAULT
        .check_setpoint(freq, level)
        .map_err(|e| InputError(format!("drive refused: {e}")))?;
    let run = port.open("drive")?.drive(freq, level)?;
    render::driving(freq, level, run, json)
}

/// `run-file`: the plan checked here first (bad input exits 2 before any connection), then
/// uploaded to the scratch slot and run from there.
/// `info`: the identity from the session's `Hello`; for people, also the plan store's state
/// (the JSON keeps its shape: `store --json` has the store's).
fn info(port: &PortArg, json: bool) -> anyhow::Result<ExitCode> {
    let mut client = port.open("info")?;
    if json {
        return render::info(client.info(), true);
    }
    let store = StoreJson::from(&client.store_info()?);
    render::info(client.info(), false)?;
    println!("store      {}", store.text());
    Ok(ExitCode::SUCCESS)
}

/// `store [--format]`.
fn store(port: &PortArg, format: bool, json: bool) -> anyhow::Result<ExitCode> {
    let mut client = port.open("store")?;
    let info = if format { client.format_store()? } else { client.store_info()? };
    let store = StoreJson::from(&info);
    if json {
        print_json(&store)?;
    } else if format {
        println!("formatted: {}", store.text());
    } else {
        println!("{}", store.text());
    }
    Ok(ExitCode::SUCCESS)
}

fn run_file(port: &PortArg, path: &Path, wait: &WaitArgs) -> anyhow::Result<ExitCode> {
    let plan = read_plan(path)?;
    let mut client = port.open("run-file")?;
    // Ctrl-C during the upload must not start the plan afterwards.
    let interrupted = if wait.wait { Some(watch::interrupt_flag()?) } else { None };
    let summary = watch::upload(&mut client, &plan, Some(SCRATCH_SLOT))?;
    if interrupted.is_some_and(|flag| flag.load(std::sync::atomic::Ordering::SeqCst)) {
        eprintln!("interrupted during the upload: the plan was not started");
        return Ok(ExitCode::from(watch::EXIT_INTERRUPTED));
    }
    if !wait.json {
        println!(
            "uploaded '{}' to the scratch slot {}: {} step(s), {} ms",
            summary.name, summary.slot, summary.steps, summary.total_ms
        );
    }
    let target =
        watch::Target { plan: PlanRef::Slot(SCRATCH_SLOT), name: Some(plan.name.to_string()) };
    watch::start_plan(&mut client, &target, None, wait.wait, wait.json)
}

impl ConfigCommand {
    fn run(&self) -> anyhow::Result<ExitCode> {
        match self {
            ConfigCommand::Get { port, key, json } => {
                let config = port.open("config get")?.config()?;
                render::config(&config, *key, *json)
            }
            ConfigCommand::Set { port, key, value, json } => {
                // The value alone is checked before connecting (bad input exits 2 at once).
                let refused = |e: ConfigValueError| InputError(e.to_string());
                key.set(&mut DeviceConfig::default(), value).map_err(refused)?;
                let mut client = port.open("config set")?;
                let mut config = client.config()?;
                key.set(&mut config, value).map_err(refused)?;
                config.validate().map_err(|e| {
                    InputError(format!("{} {value} refused: {}", key.name(), config_refusal(&e)))
                })?;
                let now = match client.set_config(config) {
                    Err(DeviceError::Refused(Refusal::Config(e))) => anyhow::bail!(
                        "the controller refused {} {value}: {}",
                        key.name(),
                        config_refusal(&e)
                    ),
                    other => other?,
                };
                render::config(&now, None, *json)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_plan_file_is_bad_input_naming_the_step() {
        let dir = std::env::temp_dir().join(format!("chladni-plan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("p.json");
        let step = r#"{"freq_hz":0.5,"amplitude":0.1,"duration_ms":5,"ramp_ms":0}"#;
        std::fs::write(&path, format!(r#"{{"name":"x","repeat":1,"steps":[{step}]}}"#)).unwrap();
        assert!(read_plan(&path).unwrap_err().0.contains("step 1: frequency 0.500 Hz"));
        std::fs::write(&path, "{").unwrap();
        assert!(read_plan(&path).unwrap_err().0.contains("not a valid plan"));
        let many: Vec<&str> =
            vec![r#"{"freq_hz":50,"amplitude":0.1,"duration_ms":5,"ramp_ms":0}"#; 257];
        std::fs::write(&path, format!(r#"{{"name":"x","repeat":1,"steps":[{}]}}"#, many.join(",")))
            .unwrap();
        assert!(read_plan(&path).unwrap_err().0.contains("257 steps: a plan holds at most 256"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
