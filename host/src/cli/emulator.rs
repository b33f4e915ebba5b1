//! `chladni emulator`: the controller in QEMU, in the foreground until Ctrl-C or SIGTERM.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::mpsc;

use chladni::controller::emulator::{Emulator, EmulatorConfig, EmulatorError};

use super::InputError;
use clap::Args;

#[derive(Debug, Args)]
pub struct EmulatorArgs {
    /// TCP port for the controller's link (default: a free port, printed at start).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
    tcp: Option<u16>,
    /// Firmware image to run instead of building the QEMU board's image.
    #[arg(long)]
    firmware: Option<PathBuf>,
    /// Keep the controller's flash (plans, configuration) in this file across restarts;
    /// created erased (512 KiB of 0xFF) if missing.
    #[arg(long)]
    flash_file: Option<PathBuf>,
    /// Write the firmware's decoded log here instead of stderr.
    #[arg(long)]
    log: Option<PathBuf>,
    /// Stop after this many seconds, at least 1 (default: run until Ctrl-C / SIGTERM). Reaching
    /// the limit is the end asked for: exit code 0, with a message saying so.
    #[arg(long, value_name = "S", value_parser = time_limit)]
    time_limit_s: Option<u64>,
    /// Print the ready line as JSON (`{"port": "tcp://127.0.0.1:PORT", "pid": QEMU's pid}`).
    #[arg(long)]
    json: bool,
}

/// `--time-limit-s`: whole seconds, at least 1.
fn time_limit(s: &str) -> Result<u64, String> {
    match s.trim().parse::<u64>() {
        Ok(v) if v >= 1 => Ok(v),
        _ => Err(format!("--time-limit-s must be a whole number of seconds ≥ 1, got {s}")),
    }
}

impl EmulatorArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let config = EmulatorConfig {
            port: self.tcp,
            firmware: self.firmware.clone(),
            log_file: self.log.clone(),
            time_limit: self.time_limit_s.map(std::time::Duration::from_secs),
            flash_file: self.flash_file.clone(),
        };
        let (stop_tx, stop_rx) = mpsc::channel();
        ctrlc::set_handler(move || {
            let _ = stop_tx.send(());
        })?;
        let mut emulator = Emulator::start(&config).map_err(|e| match e {
            EmulatorError::FlashFile { .. } => anyhow::Error::new(InputError(e.to_string())),
            e => e.into(),
        })?;
        if self.json {
            let ready = serde_json::json!({ "port": emulator.address(), "pid": emulator.pid() });
            println!("{ready}");
        } else {
            println!("controller ready on {}", emulator.address());
            println!("try: chladni device info --port {}", emulator.address());
        }
        // A script reads the address from the first line while the emulator keeps running.
        std::io::Write::flush(&mut std::io::stdout())?;
        // Wait for a signal, or for QEMU to end on its own (time limit, firmware exit).
        loop {
            if stop_rx.recv_timeout(std::time::Duration::from_millis(200)).is_ok() {
                eprintln!("stopping the emulator");
                emulator.stop();
                return Ok(ExitCode::SUCCESS);
            }
            if let Some(status) = emulator.try_exit_status()? {
                if Emulator::ended_by_time_limit(&config, &status) {
                    eprintln!(
                        "time limit of {} s reached: the emulator stopped",
                        self.time_limit_s.unwrap_or_default()
                    );
                    return Ok(ExitCode::SUCCESS);
                }
                eprintln!("QEMU exited: {status}");
                return Ok(if status.success() { ExitCode::SUCCESS } else { ExitCode::FAILURE });
            }
        }
    }
}
