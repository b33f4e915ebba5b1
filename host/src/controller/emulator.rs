//! Runs the controller in QEMU: the QEMU-board firmware on `qemu-system-arm -M b-l475e-iot01a`,
//! its USART1 on a TCP socket on 127.0.0.1 that [`crate::controller::client::DeviceClient`] connects to.
//!
//! `chladni emulator`, the end-to-end tests and the demo all start the controller through
//! [`Emulator::start`]. QEMU is stopped by PID when the [`Emulator`] is dropped; with
//! [`EmulatorConfig::time_limit`] it also runs under coreutils `timeout`, so it cannot outlive a
//! test process that was killed outright.

use std::fs::File;
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use chladni_shared::icd::link::Board;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

use crate::controller::client::{DeviceClient, DeviceError};
use crate::controller::firmware::{self, FirmwareError};

/// How to start the emulated controller.
#[derive(Debug, Clone, Default)]
pub struct EmulatorConfig {
    /// TCP port for the link; `None` picks a free one.
    pub port: Option<u16>,
    /// Firmware image; `None` builds the QEMU board's image from the source tree.
    pub firmware: Option<PathBuf>,
    /// Where the decoded defmt log goes; `None` inherits stderr.
    pub log_file: Option<PathBuf>,
    /// Kill QEMU after this long whatever happens (tests set it).
    pub time_limit: Option<Duration>,
    /// Host file holding the controller's flash bank 2 across restarts; created erased
    /// (512 KiB of 0xFF) if missing. `None`: the bank does not persist.
    pub flash_file: Option<PathBuf>,
}

/// Size of the flash bank the QEMU board keeps in [`EmulatorConfig::flash_file`].
pub const FLASH_FILE_SIZE: u64 = 512 * 1024;

/// Why the emulator could not start.
#[derive(Debug, thiserror::Error)]
pub enum EmulatorError {
    /// The firmware image could not be built or found.
    #[error(transparent)]
    Firmware(#[from] FirmwareError),
    /// The image path does not exist.
    #[error("firmware image {0} does not exist")]
    NoImage(PathBuf),
    /// QEMU (or defmt-print) could not be started.
    #[error(
        "cannot start {program}: {source} (run scripts/install-deps.sh to install QEMU 10 and defmt-print)"
    )]
    Spawn {
        /// The program.
        program: &'static str,
        /// The OS error.
        source: std::io::Error,
    },
    /// Could not find or open the TCP port or log file.
    #[error("emulator setup: {0}")]
    Io(#[from] std::io::Error),
    /// The flash file cannot serve as the controller's flash bank.
    #[error("flash file {path}: {reason}")]
    FlashFile {
        /// The file.
        path: PathBuf,
        /// What is wrong, and what to do.
        reason: String,
    },
    /// QEMU exited before the firmware answered.
    #[error("QEMU exited during start-up ({0}); see its log")]
    EarlyExit(String),
    /// The firmware did not answer a ping in time.
    #[error("the emulated controller did not answer within {0:?}: {1}")]
    NotReady(Duration, DeviceError),
}

/// A running emulated controller. Dropping it stops QEMU.
pub struct Emulator {
    qemu: Child,
    log_decoder: Option<Child>,
    port: u16,
}

impl Emulator {
    /// Builds the firmware if needed, starts QEMU, and waits until the firmware answers a ping.
    pub fn start(config: &EmulatorConfig) -> Result<Self, EmulatorError> {
        let elf = match &config.firmware {
            Some(path) => path.clone(),
            None => firmware::build(Board::Qemu)?,
        };
        if !elf.is_file() {
            return Err(EmulatorError::NoImage(elf));
        }
        let port = match config.port {
            Some(port) => port,
            None => free_port()?,
        };
        let flash = config.flash_file.as_deref().map(prepare_flash_file).transpose()?;
        let mut emulator = Self::spawn(&elf, port, flash.as_deref(), config)?;
        emulator.wait_ready(Duration::from_secs(20))?;
        Ok(emulator)
    }

    fn spawn(
        elf: &Path,
        port: u16,
        flash: Option<&Path>,
        config: &EmulatorConfig,
    ) -> Result<Self, EmulatorError> {
        let qemu_args = qemu_command_line(elf, port, flash);
        let mut command = match config.time_limit {
            Some(limit) => {
                let mut c = Command::new("timeout");
                c.args(["--kill-after=5", &format!("{}", limit.as_secs().max(1))]);
                c.arg("qemu-system-arm").args(&qemu_args);
                c
            }
            None => {
                let mut c = Command::new("qemu-system-arm");
                c.args(&qemu_args);
                c
            }
        };
        let log: Stdio = match &config.log_file {
            Some(path) => File::create(path)?.into(),
            None => Stdio::inherit(),
        };
        let log_err: Stdio = match &config.log_file {
            Some(path) => File::options().append(true).open(path)?.into(),
            None => Stdio::inherit(),
        };
        command.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(log_err);
        let mut qemu = command
            .spawn()
            .map_err(|source| EmulatorError::Spawn { program: "qemu-system-arm", source })?;
        // The firmware's defmt log arrives on QEMU's stdout (semihosting); decode it.
        let defmt = qemu.stdout.take().expect("piped stdout");
        let log_decoder = Command::new("defmt-print")
            .args(["-e"])
            .arg(elf)
            .arg("stdin")
            .stdin(defmt)
            .stdout(log)
            .stderr(Stdio::null())
            .spawn();
        let log_decoder = match log_decoder {
            Ok(child) => Some(child),
            Err(source) => {
                let _ = qemu.kill();
                return Err(EmulatorError::Spawn { program: "defmt-print", source });
            }
        };
        Ok(Self { qemu, log_decoder, port })
    }

    fn wait_ready(&mut self, within: Duration) -> Result<(), EmulatorError> {
        let start = Instant::now();
        loop {
            if let Some(status) = self.qemu.try_wait()? {
                return Err(EmulatorError::EarlyExit(status.to_string()));
            }
            let attempt = TcpStream::connect(("127.0.0.1", self.port))
                .map_err(DeviceError::from)
                .and_then(|stream| {
                    let mut client = DeviceClient::from_transport(Box::new(stream));
                    client.set_timeout(Duration::from_millis(500));
                    client.ping()
                });
            match attempt {
                Ok(_) => return Ok(()),
                Err(e) if start.elapsed() > within => {
                    return Err(EmulatorError::NotReady(within, e));
                }
                Err(_) => std::thread::sleep(Duration::from_millis(100)),
            }
        }
    }

    /// The TCP port of the controller's link.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// The link address for [`DeviceClient::open`]: `tcp://127.0.0.1:PORT`.
    pub fn address(&self) -> String {
        format!("tcp://127.0.0.1:{}", self.port)
    }

    /// PID of the QEMU process (or of the `timeout` wrapping it).
    pub fn pid(&self) -> u32 {
        self.qemu.id()
    }

    /// Connects a client to the controller.
    pub fn connect(&self) -> Result<DeviceClient, DeviceError> {
        DeviceClient::open(&self.address())
    }

    /// Waits until QEMU exits by itself (the firmware exits, or a signal stops it).
    pub fn wait(&mut self) -> std::io::Result<std::process::ExitStatus> {
        self.qemu.wait()
    }

    /// QEMU's exit status if it has ended.
    pub fn try_exit_status(&mut self) -> std::io::Result<Option<std::process::ExitStatus>> {
        self.qemu.try_wait()
    }

    /// True when `status` (from [`Emulator::try_exit_status`]) says the run ended because its
    /// [`EmulatorConfig::time_limit`] expired: coreutils `timeout` then exits with 124.
    pub fn ended_by_time_limit(config: &EmulatorConfig, status: &std::process::ExitStatus) -> bool {
        config.time_limit.is_some() && status.code() == Some(124)
    }

    /// Stops QEMU: SIGTERM (forwarded by `timeout` when present), then SIGKILL after 3 s.
    pub fn stop(&mut self) {
        if matches!(self.qemu.try_wait(), Ok(None)) {
            let _ = kill(Pid::from_raw(self.qemu.id() as i32), Signal::SIGTERM);
            let deadline = Instant::now() + Duration::from_secs(3);
            while matches!(self.qemu.try_wait(), Ok(None)) && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = self.qemu.kill();
            let _ = self.qemu.wait();
        }
        if let Some(mut decoder) = self.log_decoder.take() {
            // It ends by itself at EOF on QEMU's stdout; don't hang if it doesn't.
            let deadline = Instant::now() + Duration::from_secs(2);
            while matches!(decoder.try_wait(), Ok(None)) && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = decoder.kill();
            let _ = decoder.wait();
        }
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop();
    }
}

/// QEMU's arguments: the board, the image, USART1 on a TCP server socket, semihosting on
/// (its command line tells the firmware where its flash file is).
pub fn qemu_command_line(elf: &Path, port: u16, flash: Option<&Path>) -> Vec<String> {
    let mut semihosting = String::from("enable=on,target=native,arg=chladni-firmware");
    if let Some(flash) = flash {
        semihosting.push_str(&format!(",arg=flash={}", flash.display()));
    }
    vec![
        "-M".into(),
        "b-l475e-iot01a".into(),
        "-display".into(),
        "none".into(),
        "-monitor".into(),
        "none".into(),
        "-chardev".into(),
        format!("socket,id=s0,host=127.0.0.1,port={port},server=on,wait=off,nodelay=on"),
        "-serial".into(),
        "chardev:s0".into(),
        "-semihosting-config".into(),
        semihosting,
        "-kernel".into(),
        elf.display().to_string(),
    ]
}

/// Checks the flash file (creating it erased if missing) and returns its absolute path.
pub fn prepare_flash_file(path: &Path) -> Result<PathBuf, EmulatorError> {
    let fail = |reason: String| EmulatorError::FlashFile { path: path.to_path_buf(), reason };
    if path.is_dir() {
        return Err(fail("is a directory: pass a file path (created erased if missing)".into()));
    }
    if !path.exists() {
        crate::output::write_atomic(path, &vec![0xffu8; FLASH_FILE_SIZE as usize])
            .map_err(|e| fail(format!("cannot create it: {e}")))?;
    }
    let len = std::fs::metadata(path).map_err(|e| fail(e.to_string()))?.len();
    if len != FLASH_FILE_SIZE {
        return Err(fail(format!(
            "is {len} bytes, a flash bank is {FLASH_FILE_SIZE}: pass another path, or delete it \
             to start with an erased bank"
        )));
    }
    let abs = path.canonicalize().map_err(|e| fail(e.to_string()))?;
    let text = abs.to_str().ok_or_else(|| fail("path is not UTF-8".into()))?;
    if text.contains([',', ' ', '\t', '\n']) || text.len() > 250 {
        return Err(fail(
            "QEMU's semihosting command line cannot carry a path with commas or spaces, or \
             longer than 250 bytes: use a simpler path"
                .into(),
        ));
    }
    Ok(abs)
}

/// A TCP port that was free a moment ago (the OS picks it).
fn free_port() -> std::io::Result<u16> {
    Ok(TcpListener::bind(("127.0.0.1", 0))?.local_addr()?.port())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flash_file_is_created_erased_and_checked() {
        let dir = std::env::temp_dir().join(format!("chladni-flash-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bank.bin");
        let _ = std::fs::remove_file(&path);
        let abs = prepare_flash_file(&path).unwrap();
        assert!(abs.is_absolute());
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(bytes.len() as u64, FLASH_FILE_SIZE);
        assert!(bytes.iter().all(|&b| b == 0xff));

        std::fs::write(&path, [0u8; 100]).unwrap();
        let err = prepare_flash_file(&path).unwrap_err().to_string();
        assert!(err.contains("is 100 bytes"), "{err}");
        let err = prepare_flash_file(&dir).unwrap_err().to_string();
        assert!(err.contains("is a directory") && !err.contains("bytes"), "{err}");

        let odd = dir.join("a,b.bin");
        let err = prepare_flash_file(&odd).unwrap_err().to_string();
        assert!(err.contains("commas"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn an_expired_time_limit_is_told_apart_from_a_failure() {
        use std::os::unix::process::ExitStatusExt;
        let limited =
            EmulatorConfig { time_limit: Some(Duration::from_secs(5)), ..Default::default() };
        let expired = std::process::ExitStatus::from_raw(124 << 8);
        let failed = std::process::ExitStatus::from_raw(1 << 8);
        assert!(Emulator::ended_by_time_limit(&limited, &expired));
        assert!(!Emulator::ended_by_time_limit(&limited, &failed));
        assert!(!Emulator::ended_by_time_limit(&EmulatorConfig::default(), &expired));
    }

    #[test]
    fn command_line_passes_the_flash_file_to_the_firmware() {
        let args = qemu_command_line(Path::new("/fw.elf"), 4000, Some(Path::new("/tmp/f.bin")));
        let joined = args.join(" ");
        assert!(joined.contains("arg=flash=/tmp/f.bin"), "{joined}");
        assert!(joined.contains("port=4000,server=on,wait=off,nodelay=on"), "{joined}");
        assert!(joined.contains("-kernel /fw.elf"), "{joined}");
    }
}
