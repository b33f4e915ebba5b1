//! `chladni device …`: requests to a running controller.

use std::process::ExitCode;

use anyhow::Context;
use chladni::device::DeviceClient;
use clap::{Args, Subcommand};

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
}

impl DeviceCommand {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        match self {
            DeviceCommand::Info { port, json } => {
                let info = port.open()?.info()?;
                if *json {
                    let value = serde_json::json!({
                        "firmware_version": info.firmware_version.as_str(),
                        "board": info.board.name(),
                        "protocol_version": info.protocol_version,
                        "build_id": format!("{:08x}", info.build_id),
                    });
                    println!("{value}");
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
                    println!(
                        "{}",
                        serde_json::json!({"count": count, "mean_ms": mean, "max_ms": max})
                    );
                } else {
                    println!("{count} ping(s): mean {mean:.3} ms, max {max:.3} ms");
                }
            }
        }
        Ok(ExitCode::SUCCESS)
    }
}
