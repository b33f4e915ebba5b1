//! `chladni demo`: the feeder's whole job in one command (the README's first command runs it).
//!
//! A part and a plate go through the planner; the plan and its simulated traces are drawn by
//! the plot code and checked by a Monte Carlo run of the motion model ([`prepare`]); then the
//! plan goes to a controller — the QEMU firmware started here through [`Emulator`], or a real
//! one on a serial port or `tcp://` address ([`connect`]) — as a stored plan, and runs while its
//! telemetry streams ([`run::watch`]). [`Summary`] sums it up: the predicted final pose, the
//! simulated success rate, the run's timing by the controller's own sample clock, and faults.
//!
//! **Closed loop.** The planner gives each step an open-loop amplitude (a fraction of the
//! drive's full scale), which means different plate motion on every rig and at every frequency.
//! The demo has the controller hold the plate's *acceleration* instead (`Level::Accel`, from
//! its accelerometer): a step of amplitude `a` holds `a × accel_mps2` (`--accel`, the
//! acceleration at full amplitude), which keeps the planner's ratios between modes.
//!
//! **Sample-exact timing.** The runner advances plan steps by counting DAC samples, and status
//! and telemetry carry its sample clock and the samples output since the run started; so the
//! run's start and end clocks are known to the sample, and the steps' executed length must
//! equal the plan's exactly. The final ramp to zero (max(last step's ramp, 20 ms)) follows the
//! last step and is reported apart.
//!
//! **`--fast`.** Step durations divided by a whole factor so the run takes at most
//! [`FAST_TARGET_MS`]: a look at the controller at work, not a feeder run (the parts would not
//! have time to settle); the factor is in the output and the summary.

pub mod run;
pub mod steer;

use std::path::{Path, PathBuf};

use chladni_shared::icd::link::DeviceInfo;
use chladni_shared::icd::plan::{DeviceLimits, Plan};
use chladni_shared::icd::store::PlanSummary;
use serde::Serialize;

use chladni_core::model::part::Part;
use chladni_core::model::plan_file::{PlanFile, PlanFileError, StepJson};
use chladni_core::model::plate::PlateModel;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::montecarlo::{self, RmsMax, Setup};
use chladni_core::output::{OutputError, OutputGuard, write_atomic};
use chladni_core::planner::{self, PlanFailure, PlanOptions, Synthesis};
use chladni_device::client::{DeviceClient, DeviceError};
use chladni_device::emulator::{Emulator, EmulatorConfig, EmulatorError};
use chladni_device::firmware;
use chladni_device::json::FaultJson;
use chladni_media::plot::PlotError;
use chladni_media::plot::plan as plan_plot;
use chladni_media::vision::LocateError;
use chladni_media::vision::verify::VerifyError;
use chladni_rig::RigError;
use chladni_steer::LoopError;
use chladni_steer::camera::CameraError;

pub use run::{RunReport, watch};

/// The example part, relative to the source tree (or the working directory).
pub const DEFAULT_PART: &str = "examples/parts/triangle.json";
/// The example plate (four straight-node modes).
pub const DEFAULT_PLATE: &str = "examples/plates/four-lines.toml";
/// Where the plan, figures and logs go.
pub const DEFAULT_OUT: &str = "target/demo";
/// The acceleration held at full amplitude (m/s²). QEMU's simulated plate (resonance 180 Hz,
/// ζ 0.05, 20 m/s² per full scale below resonance) reaches ≈ 2.5 m/s² at 60 Hz at full drive;
/// 2.0 leaves the closed loop headroom at the example plate's lowest mode (60 Hz, amplitude
/// 0.8: 1.6 m/s²). A real plate that makes parts move needs more: pass `--accel` for the rig.
pub const DEFAULT_ACCEL_MPS2: f64 = 2.0;
/// `--fast`: the whole run takes at most this long (ms).
pub const FAST_TARGET_MS: u64 = 25_000;
/// `--fast`: no step shorter than this (ms), so the closed loop's check and settling (well
/// under 0.5 s, docs/control.md) stay a small part of every step.
pub const MIN_FAST_STEP_MS: u32 = 1_000;
/// The name the plan is stored under on the controller.
pub const STORED_NAME: &str = "demo";
/// Monte Carlo trials, seed, and the orientation tolerance of a success (deg), as
/// `chladni simulate`'s defaults.
pub const TRIALS: u32 = 200;
/// Seed of the Monte Carlo start poses.
pub const SEED: u64 = 1;
/// A trial succeeds within this of the predicted orientation (deg).
pub const TOL_DEG: f64 = 5.0;

/// What the demo does, from the command line.
#[derive(Debug, Clone)]
pub struct DemoConfig {
    /// Part file.
    pub part: PathBuf,
    /// Plate file.
    pub plate: PathBuf,
    /// Output folder (created).
    pub out: PathBuf,
    /// A real controller (serial device or `tcp://HOST:PORT`); `None`: start QEMU.
    pub port: Option<String>,
    /// Acceleration held at full amplitude (m/s²).
    pub accel_mps2: f64,
    /// Run the plan time-scaled (see the module docs).
    pub fast: bool,
}

/// Why the demo stopped before its summary. Each message names the fix.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    /// A part, plate or option the demo cannot use (exit code 2).
    #[error("{0}")]
    Input(String),
    /// A program the QEMU controller needs is not installed.
    #[error(
        "{program} is not installed (not found on PATH): run scripts/install-deps.sh (it \
         installs QEMU 10 and defmt-print), or pass --port DEVICE to use a real controller"
    )]
    QemuMissing {
        /// The program.
        program: &'static str,
    },
    /// The QEMU controller did not start.
    #[error("the QEMU controller did not start: {0}")]
    Emulator(EmulatorError),
    /// The controller given with `--port` does not answer.
    #[error(
        "cannot reach the controller at {port}: {source} (check the cable and `chladni device \
         list`, or that `chladni emulator` listens there; leave out --port to start one in QEMU)"
    )]
    PortUnreachable {
        /// The port as given.
        port: String,
        /// What failed.
        source: DeviceError,
    },
    /// The planner found no plan.
    #[error(
        "no plan for this part on this plate: {0} (try --plate with more modes, or another --part)"
    )]
    PlanFailed(PlanFailure),
    /// The closed-loop plan does not fit the device limits.
    #[error("the demo plan does not fit the controller: {0} (lower --accel)")]
    DevicePlan(PlanFileError),
    /// A figure could not be drawn.
    #[error(transparent)]
    Figure(#[from] PlotError),
    /// An output file could not be written.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// The controller holds a fault from before: it runs nothing until it is cleared.
    #[error(
        "the controller holds a latched fault ({cause}): find its cause (shaker, amplifier, \
         sensor wiring), then run `chladni device clear-fault --port {port}`"
    )]
    FaultLatched {
        /// The fault's name.
        cause: &'static str,
        /// The controller's port.
        port: String,
    },
    /// A request to the controller failed or was refused.
    #[error("{stage}: {source}")]
    Device {
        /// What the demo was doing.
        stage: &'static str,
        /// Why it failed.
        source: DeviceError,
    },
    /// `--steer`: the virtual rig could not start, or stopped.
    #[error("the virtual rig: {0}")]
    Rig(RigError),
    /// `--steer`: the virtual rig did not listen in time.
    #[error(
        "the virtual rig did not listen within {within_s} s: the controller in QEMU did not \
         answer it; run the demo again"
    )]
    RigSilent {
        /// How long it was waited for.
        within_s: u64,
    },
    /// `--steer`: the virtual rig's thread ended without an error.
    #[error(
        "the virtual rig's thread ended without saying why (a bug): run the demo again, and \
         report it if it repeats"
    )]
    RigEnded,
    /// `--steer`: the camera loop failed; the drive was stopped.
    #[error("{stage}: {source}")]
    Loop {
        /// What the demo was doing.
        stage: &'static str,
        /// Why it failed.
        source: LoopError,
    },
    /// `--steer`: the frame to verify the plan by did not come.
    #[error("the frame after the plan: {0}")]
    Camera(CameraError),
    /// `--steer`: the parts could not be located in that frame.
    #[error("locating the parts after the plan: {0}")]
    Locate(LocateError),
    /// `--steer`: the plan's prediction cannot be checked.
    #[error("the plan's prediction: {0}")]
    Verify(VerifyError),
    /// `--steer`: the learned plate could not be made from the given one.
    #[error("the learned plate: {0}")]
    Learned(String),
    /// `--steer`: no plan on the learned plate for parts fed into the box.
    #[error(
        "no plan on the learned plate for parts fed into {region}: {source} (what was learned \
         varies with the rig's timing: run the demo again)"
    )]
    FedPlan {
        /// The feed box, as said.
        region: String,
        /// Why.
        source: PlanFailure,
    },
}

impl DemoError {
    /// The error's name in `--json` output.
    pub fn name(&self) -> &'static str {
        match self {
            DemoError::Input(_) => "bad_input",
            DemoError::QemuMissing { .. } => "qemu_missing",
            DemoError::Emulator(_) => "emulator",
            DemoError::PortUnreachable { .. } => "port_unreachable",
            DemoError::PlanFailed(_) => "plan_failed",
            DemoError::DevicePlan(_) => "device_plan",
            DemoError::Figure(_) => "figure",
            DemoError::Output(_) => "output",
            DemoError::FaultLatched { .. } => "fault_latched",
            DemoError::Device { .. } => "device",
            DemoError::Rig(_) => "rig",
            DemoError::RigSilent { .. } => "rig_silent",
            DemoError::RigEnded => "rig_ended",
            DemoError::Loop { source, .. } => source.name(),
            DemoError::Camera(e) => e.name(),
            DemoError::Locate(e) => e.name(),
            DemoError::Verify(e) => e.name(),
            DemoError::Learned(_) => "learned_plate",
            DemoError::FedPlan { .. } => "plan_failed",
        }
    }

    /// Ctrl-C ended the camera loop (the drive was stopped).
    pub fn is_interrupted(&self) -> bool {
        matches!(self, DemoError::Loop { source: LoopError::Interrupted, .. })
    }

    /// Exit code: 2 for bad input, 1 for everything else.
    pub fn exit_code(&self) -> u8 {
        match self {
            DemoError::Input(_) => 2,
            DemoError::Output(e) if e.is_bad_input() => 2,
            DemoError::Figure(e) if e.is_bad_input() => 2,
            DemoError::Rig(e) if e.is_bad_input() => 2,
            _ => 1,
        }
    }
}

/// `path` as given when it exists, else the same path inside the source tree this binary was
/// built from (so the defaults work from any directory of a checkout).
pub fn resolve_input(path: &Path) -> PathBuf {
    if path.exists() || path.is_absolute() {
        return path.to_path_buf();
    }
    match firmware::source_root() {
        Some(root) if root.join(path).exists() => root.join(path),
        _ => path.to_path_buf(),
    }
}

/// `program` on `PATH`, if there.
pub fn find_program(program: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).map(|dir| dir.join(program)).find(|p| p.is_file())
}

/// Checks, before any work, that the QEMU controller can start (without `--port`): see
/// [`preflight_qemu`].
pub fn preflight(config: &DemoConfig) -> Result<(), DemoError> {
    if config.port.is_some() {
        return Ok(());
    }
    preflight_qemu()
}

/// Checks that QEMU, the log decoder and coreutils `timeout` (which keeps QEMU from outliving
/// a killed demo) are on `PATH`.
pub fn preflight_qemu() -> Result<(), DemoError> {
    for program in ["qemu-system-arm", "defmt-print", "timeout"] {
        if find_program(program).is_none() {
            return Err(DemoError::QemuMissing { program });
        }
    }
    Ok(())
}

/// The files the demo writes into its output folder.
#[derive(Debug, Clone, Serialize)]
pub struct Files {
    /// The planner's plan (open loop), as `chladni plan --out` writes it.
    pub plan: PathBuf,
    /// The plan as stored on the controller (closed loop, time-scaled with `--fast`).
    pub device_plan: PathBuf,
    /// The step-by-step plan figure.
    pub plan_figure: PathBuf,
    /// Simulated traces.
    pub traces: PathBuf,
    /// The simulated trials step by step.
    pub traces_plan: PathBuf,
    /// The QEMU controller's flash bank: the stored plan survives a restart (emulator only).
    pub flash: PathBuf,
    /// The firmware's decoded log (emulator only).
    pub firmware_log: PathBuf,
}

impl Files {
    fn in_dir(out: &Path) -> Self {
        let traces = out.join("traces.png");
        Files {
            plan: out.join("plan.json"),
            device_plan: out.join("device-plan.json"),
            plan_figure: out.join("plan.png"),
            traces_plan: plan_plot::trials_plan_path(&traces),
            traces,
            flash: out.join("flash.bin"),
            firmware_log: out.join("firmware.log"),
        }
    }

    /// Every output file (each checked against the inputs before any work).
    fn all(&self) -> [&Path; 7] {
        [
            &self.plan,
            &self.device_plan,
            &self.plan_figure,
            &self.traces,
            &self.traces_plan,
            &self.flash,
            &self.firmware_log,
        ]
    }
}

/// The Monte Carlo check of the plan.
#[derive(Debug, Clone, Serialize)]
pub struct Simulation {
    /// Random start poses over the plate.
    pub trials: u32,
    /// Their seed.
    pub seed: u64,
    /// A success ends within this of the predicted orientation (deg).
    pub tolerance_deg: f64,
    /// Fraction of trials that succeeded.
    pub success_rate: f64,
    /// What the plan claims: the fraction of the planner's simulated start points that reach a
    /// node in every step (1 for straight nodes: a sensorless plan orients every start).
    pub claimed_success_rate: f64,
    /// Final orientation error against the prediction (deg).
    pub orientation_error_deg: Option<RmsMax>,
    /// Final position error against the prediction (mm), when the plan fixes the position.
    pub position_error_mm: Option<RmsMax>,
}

/// One step as the controller runs it.
#[derive(Debug, Clone, Serialize)]
pub struct DemoStep {
    /// The plate mode's name.
    pub mode: String,
    /// Drive frequency (Hz).
    pub freq_hz: f64,
    /// The planner's open-loop amplitude (fraction of full scale).
    pub amplitude: f64,
    /// The acceleration the controller holds (m/s²): amplitude × `--accel`.
    pub accel_mps2: f64,
    /// The planned duration (ms).
    pub nominal_ms: u32,
    /// The duration run (ms): the planned one divided by the time scale.
    pub duration_ms: u32,
}

/// Everything computed before the controller is involved.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The part.
    pub part: Part,
    /// The plate.
    pub plate: PlateModel,
    /// The plan as found.
    pub syn: Synthesis,
    /// The steps as run.
    pub steps: Vec<DemoStep>,
    /// Step durations are divided by this (1 without `--fast`).
    pub time_scale: u32,
    /// The plan the controller stores and runs (closed loop).
    pub device_plan: Plan,
    /// The Monte Carlo check.
    pub simulation: Simulation,
    /// The files written.
    pub files: Files,
}

/// Plans, draws, simulates and writes the plan files (no controller yet).
pub fn prepare(config: &DemoConfig) -> Result<Prepared, DemoError> {
    if !(config.accel_mps2.is_finite() && config.accel_mps2 > 0.0) {
        return Err(DemoError::Input(format!("--accel {} must be above 0", config.accel_mps2)));
    }
    let files = Files::in_dir(&config.out);
    let guard = OutputGuard::new().input("part", &config.part).input("plate", &config.plate);
    for path in files.all() {
        guard.check("--out", path)?;
    }
    let part = Part::load(&config.part)
        .map_err(|e| DemoError::Input(format!("{}: {e}", config.part.display())))?;
    let plate = PlateModel::load(&config.plate).map_err(|e| DemoError::Input(e.to_string()))?;
    planner::check_input(&part, &plate).map_err(|e| DemoError::Input(e.to_string()))?;
    std::fs::create_dir_all(&config.out).map_err(|e| {
        DemoError::Input(format!("cannot create --out {}: {e}", config.out.display()))
    })?;
    let syn =
        planner::plan(&part, &plate, &PlanOptions::default()).map_err(DemoError::PlanFailed)?;
    let plan_file = syn.to_file(&plate, &part.name);
    write_json(&files.plan, &plan_file.to_json())?;
    plan_plot::synthesis_figure(&files.plan_figure, &part, &plate, &syn, None)?;
    let simulation = simulate(&part, &plate, &syn, &plan_file, &files.traces)?;
    let time_scale = time_scale(&plan_file, config.fast);
    let steps = demo_steps(&plate, &syn, &plan_file, config.accel_mps2, time_scale);
    let device_file = device_file(&plan_file, &steps);
    let device_plan = device_file.to_plan(&DeviceLimits::DEFAULT).map_err(DemoError::DevicePlan)?;
    write_json(&files.device_plan, &device_file.to_json())?;
    Ok(Prepared { part, plate, syn, steps, time_scale, device_plan, simulation, files })
}

fn write_json(path: &Path, value: &serde_json::Value) -> Result<(), OutputError> {
    let text = serde_json::to_string_pretty(value).unwrap_or_default() + "\n";
    write_atomic(path, text.as_bytes())
}

/// The Monte Carlo check (as `chladni simulate`: [`TRIALS`] starts over the plate, seed
/// [`SEED`]) and its traces figures.
fn simulate(
    part: &Part,
    plate: &PlateModel,
    syn: &Synthesis,
    file: &PlanFile,
    traces: &Path,
) -> Result<Simulation, DemoError> {
    let steps = chladni_core::motion::steps::plan_steps(file, plate)
        .map_err(|e| DemoError::Input(e.to_string()))?;
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let body = Body::new(part);
    let setup = Setup { body: &body, plate, fields: &fields, steps: &steps, feed: None };
    let trials = montecarlo::run_trials(&setup, TRIALS, SEED, &chladni_core::progress::Silent);
    let stats = montecarlo::statistics(&trials, file, TOL_DEG);
    let target = file.final_orientation_deg.zip(file.period_deg);
    plan_plot::trials_figures(traces, part, &setup, &trials, target)?;
    Ok(Simulation {
        trials: TRIALS,
        seed: SEED,
        tolerance_deg: TOL_DEG,
        success_rate: stats.success_rate.unwrap_or(0.0),
        claimed_success_rate: claimed_success(syn),
        orientation_error_deg: stats.orientation_error_deg,
        position_error_mm: stats.position_error_mm,
    })
}

/// The plan's claim: the least fraction, over its steps, of the planner's simulated start
/// points that end on a node rather than the plate edge.
pub fn claimed_success(syn: &Synthesis) -> f64 {
    syn.steps
        .iter()
        .filter(|s| s.settle.points > 0)
        .map(|s| 1.0 - s.settle.ends_on_edge.len() as f64 / s.settle.points as f64)
        .fold(1.0, f64::min)
}

/// The whole factor step durations are divided by: 1, or with `fast` the least that brings
/// the plan within [`FAST_TARGET_MS`].
pub fn time_scale(file: &PlanFile, fast: bool) -> u32 {
    let total: u64 = file.steps.iter().map(|s| u64::from(s.duration_ms)).sum::<u64>()
        * u64::from(file.repeat.max(1));
    if !fast || total <= FAST_TARGET_MS {
        return 1;
    }
    u32::try_from(total.div_ceil(FAST_TARGET_MS)).unwrap_or(u32::MAX)
}

/// A step's duration divided by `scale` (rounded to nearest), at least [`MIN_FAST_STEP_MS`]
/// when scaled at all (never longer than the step was).
pub fn scaled_ms(duration_ms: u32, scale: u32) -> u32 {
    if scale <= 1 {
        return duration_ms;
    }
    let scaled = (u64::from(duration_ms) * 2 + u64::from(scale)) / (2 * u64::from(scale));
    (scaled as u32).max(MIN_FAST_STEP_MS).min(duration_ms)
}

/// The steps as run: the planner's, each holding amplitude × `accel_mps2`, durations scaled.
fn demo_steps(
    plate: &PlateModel,
    syn: &Synthesis,
    file: &PlanFile,
    accel_mps2: f64,
    scale: u32,
) -> Vec<DemoStep> {
    file.steps
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let amplitude = s.amplitude.unwrap_or(1.0);
            let mode = syn.steps.get(i).and_then(|p| plate.modes.get(p.mode));
            DemoStep {
                mode: mode.map_or_else(|| format!("step {}", i + 1), |m| m.name.clone()),
                freq_hz: s.freq_hz,
                amplitude,
                // Resolved to the controller's 1 mm/s².
                accel_mps2: (amplitude * accel_mps2 * 1000.0).round() / 1000.0,
                nominal_ms: s.duration_ms,
                duration_ms: scaled_ms(s.duration_ms, scale),
            }
        })
        .collect()
}

/// The plan file the controller stores: the planner's steps in closed loop, named
/// [`STORED_NAME`], with the planner's predictions (informative).
fn device_file(file: &PlanFile, steps: &[DemoStep]) -> PlanFile {
    PlanFile {
        name: STORED_NAME.to_string(),
        steps: file
            .steps
            .iter()
            .zip(steps)
            .map(|(s, d)| StepJson {
                freq_hz: s.freq_hz,
                duration_ms: d.duration_ms,
                amplitude: None,
                accel_mps2: Some(d.accel_mps2),
                ramp_ms: s.ramp_ms,
            })
            .collect(),
        ..file.clone()
    }
}

/// The controller the demo talks to.
pub struct Controller {
    /// The session.
    pub client: DeviceClient,
    /// Its address.
    pub port: String,
    /// The QEMU controller, when the demo started it (stopped when dropped).
    pub emulator: Option<Emulator>,
}

/// How long QEMU may run at most: the plan plus this, so a killed demo leaves no QEMU behind.
const EMULATOR_SLACK_S: u64 = 600;

/// Opens the controller: `config.port`, or QEMU started with its flash and log in the output
/// folder (building the firmware if it is missing or stale).
pub fn connect(config: &DemoConfig, prepared: &Prepared) -> Result<Controller, DemoError> {
    let name = format!("chladni demo (pid {})", std::process::id());
    if let Some(port) = &config.port {
        let client = DeviceClient::open(port, &name)
            .map_err(|source| DemoError::PortUnreachable { port: port.clone(), source })?;
        return Ok(Controller { client, port: port.clone(), emulator: None });
    }
    let limit = prepared.device_plan.total_ms() / 1000 + EMULATOR_SLACK_S;
    let files = &prepared.files;
    start_emulator(&files.flash, &files.firmware_log, limit, &name)
}

/// Starts the QEMU controller with its flash bank and decoded log in these files, killed
/// after `limit_s` whatever happens, and opens a session named `name` on it.
pub fn start_emulator(
    flash: &Path,
    log: &Path,
    limit_s: u64,
    name: &str,
) -> Result<Controller, DemoError> {
    let emulator_config = EmulatorConfig {
        log_file: Some(log.to_path_buf()),
        flash_file: Some(flash.to_path_buf()),
        time_limit: Some(std::time::Duration::from_secs(limit_s)),
        ..EmulatorConfig::default()
    };
    let emulator = Emulator::start(&emulator_config).map_err(|e| match e {
        EmulatorError::Spawn { program, .. } => DemoError::QemuMissing { program },
        e => DemoError::Emulator(e),
    })?;
    let port = emulator.address();
    let client = emulator
        .connect(name)
        .map_err(|source| DemoError::PortUnreachable { port: port.clone(), source })?;
    Ok(Controller { client, port, emulator: Some(emulator) })
}

/// Stores `plan` (the slot of a plan of its name, else the first free one);
/// `progress(steps_sent, steps_total)` after each chunk.
pub fn upload(
    controller: &mut Controller,
    plan: &Plan,
    progress: impl FnMut(usize, usize),
) -> Result<PlanSummary, DemoError> {
    controller
        .client
        .upload(plan, None, progress)
        .map_err(|source| DemoError::Device { stage: "uploading the plan", source })
}

/// The predicted final pose.
#[derive(Debug, Clone, Serialize)]
pub struct Prediction {
    /// Final orientation (deg, modulo `period_deg`).
    pub orientation_deg: f64,
    /// The part's period (deg).
    pub period_deg: f64,
    /// Final centroid (mm), when the plan fixes it.
    pub position_mm: Option<[f64; 2]>,
}

/// The controller, as it introduced itself.
#[derive(Debug, Clone, Serialize)]
pub struct ControllerInfo {
    /// Its address.
    pub port: String,
    /// Started by the demo in QEMU.
    pub emulated: bool,
    /// Board name.
    pub board: &'static str,
    /// Firmware version.
    pub firmware_version: String,
}

/// The plan as stored on the controller.
#[derive(Debug, Clone, Serialize)]
pub struct Stored {
    /// Slot.
    pub slot: u8,
    /// Name.
    pub name: String,
    /// Plan CRC.
    pub crc: u32,
}

/// The `chladni demo --json` object: the summary's keys and the run's fault
/// (`{"cause","value","unit","at_s"}`, as `chladni device status --json`), null when none.
#[derive(Debug, Serialize)]
pub struct SummaryJson<'a> {
    #[serde(flatten)]
    pub summary: &'a Summary,
    pub fault: Option<FaultJson>,
}

impl<'a> SummaryJson<'a> {
    /// Of a summary, its fault in the controller's JSON shape.
    pub fn of(summary: &'a Summary) -> Self {
        let fault = summary.run.fault.map(|f| FaultJson::of(&f, summary.run.sample_rate));
        SummaryJson { summary, fault }
    }
}

/// The demo's summary (`--json` prints it as [`SummaryJson`], with the fault).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// The part's name.
    pub part: String,
    /// The plate's name.
    pub plate: String,
    /// Predicted final pose.
    pub predicted: Prediction,
    /// The Monte Carlo check.
    pub simulation: Simulation,
    /// Acceleration held at full amplitude (m/s², `--accel`).
    pub accel_mps2: f64,
    /// Step durations were divided by this (1: the plan as planned).
    pub time_scale: u32,
    /// The plan's duration as planned, before any time scaling (ms).
    pub nominal_ms: u64,
    /// The steps as run.
    pub steps: Vec<DemoStep>,
    /// The controller.
    pub controller: ControllerInfo,
    /// Where the plan was stored.
    pub stored: Stored,
    /// The run and its timing.
    pub run: RunReport,
    /// The files written.
    pub files: Files,
}

impl Summary {
    /// The summary of a demo that ran (to whatever end).
    pub fn new(
        prepared: &Prepared,
        config: &DemoConfig,
        controller: &Controller,
        stored: &PlanSummary,
        run: RunReport,
    ) -> Self {
        let syn = &prepared.syn;
        Summary {
            part: prepared.part.name.clone(),
            plate: prepared.plate.name.clone(),
            predicted: Prediction {
                orientation_deg: syn.final_orientation_deg,
                period_deg: syn.period_deg,
                position_mm: syn.final_position_mm,
            },
            simulation: prepared.simulation.clone(),
            accel_mps2: config.accel_mps2,
            time_scale: prepared.time_scale,
            nominal_ms: prepared.steps.iter().map(|s| u64::from(s.nominal_ms)).sum(),
            steps: prepared.steps.clone(),
            controller: controller_info(controller.client.info(), controller),
            stored: Stored { slot: stored.slot, name: stored.name.to_string(), crc: stored.crc },
            run,
            files: prepared.files.clone(),
        }
    }
}

fn controller_info(info: &DeviceInfo, controller: &Controller) -> ControllerInfo {
    ControllerInfo {
        port: controller.port.clone(),
        emulated: controller.emulator.is_some(),
        board: info.board.name(),
        firmware_version: info.firmware_version.to_string(),
    }
}

/// Starts the stored `plan` and watches it to its end (see [`run::watch`]).
pub fn run_plan(
    controller: &mut Controller,
    plan: &Plan,
    on_sample: impl FnMut(&chladni_shared::icd::link::Telemetry) -> std::ops::ControlFlow<()>,
) -> Result<RunReport, DemoError> {
    let status = controller
        .client
        .status()
        .map_err(|source| DemoError::Device { stage: "reading the status", source })?;
    if let Some(fault) = status.fault {
        return Err(DemoError::FaultLatched {
            cause: fault.cause.name(),
            port: controller.port.clone(),
        });
    }
    watch(&mut controller.client, plan, on_sample)
}

#[cfg(test)]
mod tests;
