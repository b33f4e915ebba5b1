//! `chladni emulator`: the controller in QEMU, in the foreground until Ctrl-C or SIGTERM.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::mpsc;

use chladni_device::emulator::{EmulatedSpeed, Emulator, EmulatorConfig, EmulatorError};
use chladni_device::json::EmulatorJson;

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
    /// created erased (512 KiB of 0xFF) if missing. Without it the controller keeps its plans
    /// in a file of its own in the temp folder, removed when the emulator stops.
    #[arg(long)]
    flash_file: Option<PathBuf>,
    /// Write the firmware's decoded log here instead of stderr.
    #[arg(long)]
    log: Option<PathBuf>,
    /// Stop after this many seconds, at least 1 (default: run until Ctrl-C / SIGTERM). Reaching
    /// the limit is the end asked for: exit code 0, with a message saying so.
    #[arg(long, value_name = "S", value_parser = time_limit)]
    time_limit_s: Option<u64>,
    /// Run the core at this emulated speed, million instructions per second, instead of as
    /// fast as the host goes (QEMU `-icount`): the nearest of 1000/2^N, so 62 runs at 62.5 and
    /// 31 at 31.25 (the ready line says which). 31 is an 80 MHz STM32L475 at 2.56 cycles per
    /// instruction, a pessimistic real chip.
    #[arg(long, value_name = "M", value_parser = mips)]
    mips: Option<EmulatedSpeed>,
    /// Print the ready line as JSON (`{"port": "tcp://127.0.0.1:PORT", "pid": QEMU's pid}`).
    #[arg(long)]
    json: bool,
}

/// `--mips`: a speed the icount clock can give, as the nearest shift.
fn mips(s: &str) -> Result<EmulatedSpeed, String> {
    let value = s.trim().parse::<f64>().map_err(|_| {
        format!("--mips must be a number of million instructions per second (1 to 1000), got {s}")
    })?;
    EmulatedSpeed::nearest(value).map_err(|e| e.to_string())
}

/// `--time-limit-s`: whole seconds, at least 1.
fn time_limit(s: &str) -> Result<u64, String> {
    match s.trim().parse::<u64>() {
        Ok(v) if v >= 1 => Ok(v),
        _ => Err(format!("--time-limit-s must be a whole number of seconds ≥ 1, got {s}")),
    }
}

/// The emulator's own flash file when none is given: erased at start, removed at the end,
/// so plans stored on the controller last as long as the emulator (as on a board whose bank
/// is erased at every power-on), never shared with another emulator.
struct SessionFlash(PathBuf);

impl SessionFlash {
    fn new() -> SessionFlash {
        let name = format!("chladni-emulator-{}.flash", std::process::id());
        let path = std::env::temp_dir().join(name);
        // A file left by an earlier process of the same pid would not be erased.
        let _ = std::fs::remove_file(&path);
        SessionFlash(path)
    }
}

impl Drop for SessionFlash {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

impl EmulatorArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let session = self.flash_file.is_none().then(SessionFlash::new);
        let flash_file = self.flash_file.clone().or_else(|| session.as_ref().map(|s| s.0.clone()));
        let config = EmulatorConfig {
            port: self.tcp,
            firmware: self.firmware.clone(),
            log_file: self.log.clone(),
            time_limit: self.time_limit_s.map(std::time::Duration::from_secs),
            flash_file: flash_file.clone(),
            speed: self.mips,
        };
        let flash = flash_file.unwrap_or_default().display().to_string();
        let (stop_tx, stop_rx) = mpsc::channel();
        ctrlc::set_handler(move || {
            let _ = stop_tx.send(());
        })?;
        let mut emulator = Emulator::start(&config).map_err(|e| match e {
            EmulatorError::FlashFile { .. } => anyhow::Error::new(InputError(e.to_string())),
            e => e.into(),
        })?;
        if self.json {
            let ready = EmulatorJson {
                flash_file: flash,
                flash_kept: session.is_none(),
                icount_shift: self.mips.map(|s| s.shift),
                mips: self.mips.map(|s| s.mips()),
                pid: emulator.pid(),
                port: emulator.address(),
            };
            println!("{}", serde_json::to_string(&ready)?);
        } else {
            println!("controller ready on {}", emulator.address());
            if let Some(speed) = self.mips {
                println!(
                    "emulated core: {} MIPS (QEMU -icount shift={})",
                    speed.mips(),
                    speed.shift
                );
            }
            match &session {
                Some(_) => println!(
                    "plans kept until the emulator stops (in {flash}); --flash-file F keeps them \
                     across restarts"
                ),
                None => println!("plans kept in {flash}"),
            }
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
