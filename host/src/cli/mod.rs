//! Command-line interface: one module per command group; each parses with clap and calls the
//! library. Exit codes: 0 success, 1 the operation failed, 2 bad input (arguments, files).

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod analyze;
mod device;
mod emulator;
mod flash;
mod physics;
mod plan;
mod plate;

/// Bad input from the user: exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct InputError(pub String);

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
    /// Talk to a controller (board or emulator).
    #[command(subcommand)]
    Device(device::DeviceCommand),
    /// Run the controller firmware in QEMU, its link on a TCP port.
    Emulator(emulator::EmulatorArgs),
    /// Write the controller firmware to the board through a debug probe.
    Flash(flash::FlashArgs),
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
}

impl Cli {
    /// Runs the parsed command.
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        match &self.command {
            Command::Analyze(args) => args.run(),
            Command::Device(cmd) => cmd.run(),
            Command::Emulator(args) => args.run(),
            Command::Flash(args) => args.run(),
            Command::Plate(cmd) => cmd.run(),
            Command::Physics(cmd) => cmd.run(),
            Command::Plan(args) => args.run(),
            Command::Simulate(args) => args.run(),
        }
    }
}
