//! Command-line interface: one module per command group; each parses with clap and calls the
//! library. Exit codes: 0 success, 1 the operation failed, 2 bad input (arguments, files).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use chladni_core::output::{OutputError, OutputGuard};
use chladni_media::plot::{PlotError, check_extension};
use chladni_media::shapes::failure::FailureJson;
use clap::{Parser, Subcommand};

mod analyze;
mod calibrate;
mod demo;
mod device;
mod emulator;
mod flash;
mod locate;
mod parse;
mod part;
mod physics;
mod plan;
mod plate;
mod progress;
mod rig;
mod serve;
mod steer;
mod verify;

/// Bad input from the user: exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct InputError(pub String);

/// A plot error: a file name the figure cannot be written as is bad input.
pub fn plot_error(e: PlotError) -> anyhow::Error {
    if e.is_bad_input() { InputError(e.to_string()).into() } else { e.into() }
}

/// An output error: an output that names an input is bad input.
pub fn output_error(e: OutputError) -> anyhow::Error {
    if e.is_bad_input() { InputError(e.to_string()).into() } else { e.into() }
}

/// The guard of a command's inputs, `(role, path)`.
pub fn guard(inputs: &[(&str, &Path)]) -> OutputGuard {
    inputs.iter().fold(OutputGuard::new(), |g, (role, path)| g.input(role, path))
}

/// Checks an output file before any work: it overwrites none of `inputs`.
pub fn check_output(flag: &str, path: &Path, inputs: &[(&str, &Path)]) -> anyhow::Result<()> {
    guard(inputs).check(flag, path).map_err(output_error)
}

/// Checks an optional figure file before any work: its extension is one of `extensions` and
/// it overwrites none of `inputs`.
pub fn check_plot(
    flag: &str,
    path: &Option<PathBuf>,
    extensions: &[&str],
    inputs: &[(&str, &Path)],
) -> anyhow::Result<()> {
    if let Some(path) = path {
        check_extension(flag, path, extensions).map_err(plot_error)?;
        check_output(flag, path, inputs)?;
    }
    Ok(())
}

/// Set once a command has printed its own `--json` failure object.
static FAILURE_JSON_PRINTED: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// Does the command line ask for `--json` (before a `--`)? Read from the raw arguments, so
/// that even a command line clap refuses can answer in JSON.
pub fn wants_json(args: impl Iterator<Item = std::ffi::OsString>) -> bool {
    args.take_while(|a| a != "--").any(|a| a == "--json")
}

/// Prints a failure's one JSON object on stdout, `{"error": kind, "message": …}`.
pub fn print_failure_json(kind: &str, message: &str) {
    print_failure_value(serde_json::json!(FailureJson::new(kind, message)));
}

/// Prints a command's own failure object (with its data) on stdout; `main` then prints none.
pub fn print_failure_value(value: serde_json::Value) {
    FAILURE_JSON_PRINTED.store(true, std::sync::atomic::Ordering::Relaxed);
    println!("{value}");
}

/// A command's failure and its `--json` name (`locate`, `verify`, `plate calibrate-speed`).
pub(crate) struct Failure {
    pub kind: &'static str,
    pub error: anyhow::Error,
}

impl Failure {
    /// The error for `main`, after printing the one `--json` failure object when asked.
    pub(crate) fn report(self, json: bool) -> anyhow::Error {
        if json {
            let message = format!("{:#}", self.error);
            print_failure_value(serde_json::json!(FailureJson { error: self.kind, message }));
        }
        self.error
    }
}

/// Has a failure object been printed already?
pub fn failure_json_printed() -> bool {
    FAILURE_JSON_PRINTED.load(std::sync::atomic::Ordering::Relaxed)
}

/// Exit code for an error: 2 for bad input, 1 for everything else.
pub fn exit_code_of(err: &anyhow::Error) -> u8 {
    if err.chain().any(|e| e.is::<InputError>()) { 2 } else { 1 }
}

/// Chladni: a programmable sensorless parts feeder on a vibrating plate.
#[derive(Debug, Parser)]
#[command(name = "chladni", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Rest orientations of a part at a straight node: turn and alignment functions.
    Analyze(analyze::AnalyzeArgs),
    /// The feeder's whole job: plan a part, simulate it, run it on the controller (QEMU, or a
    /// real one with --port) while watching, and sum up.
    Demo(demo::DemoArgs),
    /// Talk to a controller (board or emulator).
    #[command(subcommand)]
    Device(device::DeviceCommand),
    /// Run the controller firmware in QEMU, its link on a TCP port.
    Emulator(emulator::EmulatorArgs),
    /// Write the controller firmware to the board through a debug probe.
    Flash(flash::FlashArgs),
    /// The parts in a photo of the plate: poses, faces, match scores (docs/plate.md).
    Locate(locate::LocateArgs),
    /// Plate modes from theory, node lines from Chladni photos.
    #[command(subcommand)]
    Plate(plate::PlateCommand),
    /// Sensorless plan: the shortest mode sequence that orients a part from any start.
    Plan(plan::PlanArgs),
    /// Monte Carlo simulation of a plan: success rate, final pose spread, traces.
    Simulate(plan::SimulateArgs),
    /// Physics models (particle on a vibrating string).
    #[command(subcommand)]
    Physics(physics::PhysicsCommand),
    /// A virtual rig: a snapshot camera over a simulated plate whose parts move under what the
    /// controller drives, on a true plate that differs from the given one (docs/rig.md).
    Rig(rig::RigArgs),
    /// Serve the controller to a cell: Modbus TCP for a PLC, HTTP for people (docs/cell.md).
    Serve(serve::ServeArgs),
    /// Drive parts to goal poses with a camera in the loop; exit 1 if the time runs out first
    /// (docs/steer.md).
    Steer(steer::SteerArgs),
    /// A photo of the plate after a run against the plan's prediction: per part ok or off,
    /// the success rate; exit 1 when any part is off (docs/plate.md).
    Verify(verify::VerifyArgs),
}

impl Cli {
    /// Runs the parsed command.
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        match &self.command {
            Command::Analyze(args) => args.run(),
            Command::Demo(args) => args.run(),
            Command::Device(cmd) => cmd.run(),
            Command::Emulator(args) => args.run(),
            Command::Flash(args) => args.run(),
            Command::Locate(args) => args.run(),
            Command::Plate(cmd) => cmd.run(),
            Command::Physics(cmd) => cmd.run(),
            Command::Plan(args) => args.run(),
            Command::Simulate(args) => args.run(),
            Command::Rig(args) => args.run(),
            Command::Serve(args) => args.run(),
            Command::Steer(args) => args.run(),
            Command::Verify(args) => args.run(),
        }
    }
}
