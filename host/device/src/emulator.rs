//! Runs the controller in QEMU: the QEMU-board firmware on `qemu-system-arm -M b-l475e-iot01a`,
//! its USART1 on a TCP socket on 127.0.0.1 that [`crate::client::DeviceClient`]
//! connects to.
//!
//! QEMU's socket serves one TCP client at a time and lets a second one wait unseen, its bytes
//! run late when the first leaves; so the public port belongs to a frame-aware
//! [`Proxy`] that shares the serial line among any number of clients, as a real serial port
//! is shared, and QEMU listens on an internal port behind it. The proxy binds the public port
//! before anything else starts, so an emulator on a busy port fails with the port's number.
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

use crate::client::{DeviceClient, DeviceError};
use crate::firmware::{self, FirmwareError};
use crate::proxy::Proxy;

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
    /// Run the core at a fixed emulated speed ([`EmulatedSpeed`], QEMU's `-icount`) instead of
    /// as fast as the host goes; `None`: as fast as the host goes.
    pub speed: Option<EmulatedSpeed>,
}

/// A fixed emulated core speed: QEMU's `-icount shift=N` runs exactly 10⁹ / 2ᴺ instructions
/// per second of the guest's clock (shift 4: 62.5 MIPS, 5: 31.25 MIPS), so the firmware's
/// timing is what a core of that speed would see, whatever the host does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EmulatedSpeed {
    /// QEMU's icount shift.
    pub shift: u8,
}

/// Largest icount shift offered (≈ 0.98 MIPS).
pub(crate) const MAX_ICOUNT_SHIFT: u8 = 10;

/// A `--mips` value that no icount shift gives.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "--mips {0}: give a speed from 1 to 1000 million instructions per second (QEMU runs \
     10^9/2^N of them: 1000, 500, 250, 125, 62.5, 31.25, ... down to 0.98)"
)]
pub struct BadMips(pub String);

impl EmulatedSpeed {
    /// The icount shift whose speed is nearest to `mips` (on a log scale): 62 → shift 4
    /// (62.5 MIPS), 31 → shift 5 (31.25 MIPS).
    pub fn nearest(mips: f64) -> Result<Self, BadMips> {
        if !mips.is_finite() || !(1.0..=1000.0).contains(&mips) {
            return Err(BadMips(mips.to_string()));
        }
        let shift = (1000.0 / mips).log2().round().clamp(0.0, f64::from(MAX_ICOUNT_SHIFT));
        Ok(Self { shift: shift as u8 })
    }

    /// Million instructions per second at this shift.
    pub fn mips(self) -> f64 {
        1000.0 / f64::from(1u32 << self.shift)
    }
}

impl EmulatorConfig {
    /// A throw-away controller for a test or a try-out: an erased flash bank and the log in
    /// the temp folder, named after `name` and this process (so parallel runs never share
    /// them), and QEMU killed after `time_limit` even if the caller hangs.
    pub fn scratch(name: &str, time_limit: Duration) -> Self {
        let base = std::env::temp_dir().join(format!("chladni-{name}-{}", std::process::id()));
        let flash = base.with_extension("flash");
        // A bank left by an earlier process of the same pid would not be erased.
        let _ = std::fs::remove_file(&flash);
        EmulatorConfig {
            time_limit: Some(time_limit),
            log_file: Some(base.with_extension("log")),
            flash_file: Some(flash),
            ..Default::default()
        }
    }
}

/// Size of the flash bank the QEMU board keeps in [`EmulatorConfig::flash_file`].
pub(crate) const FLASH_FILE_SIZE: u64 = 512 * 1024;

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
    /// The firmware did not answer a `Hello` in time.
    #[error("the emulated controller did not answer within {0:?}: {1}")]
    NotReady(Duration, DeviceError),
    /// The firmware answered, in another protocol version.
    #[error("the emulated controller cannot be used: {0}")]
    Incompatible(DeviceError),
    /// The link's port is taken (another emulator, or any other program).
    #[error(
        "port {port} is in use (another emulator or program listens there): pick another \
         with --tcp, or leave it out to use a free port"
    )]
    PortInUse {
        /// The port asked for.
        port: u16,
    },
}

/// How long QEMU and the firmware get to answer a `Hello` after (re)start.
const READY_WITHIN: Duration = Duration::from_secs(20);

/// A running emulated controller: QEMU behind the link proxy. Dropping it stops both.
pub struct Emulator {
    qemu: Child,
    log_decoder: Option<Child>,
    proxy: Proxy,
    qemu_port: u16,
    elf: PathBuf,
    flash: Option<PathBuf>,
    config: EmulatorConfig,
}

impl Emulator {
    /// Binds the link's port, builds the firmware if needed, starts QEMU behind the proxy, and
    /// waits until the firmware answers a `Hello`.
    pub fn start(config: &EmulatorConfig) -> Result<Self, EmulatorError> {
        // The public port first: on a busy port nothing else starts, and no other program's
        // answer can be taken for this emulator's.
        let proxy = Proxy::bind(config.port).map_err(|e| match e.kind() {
            std::io::ErrorKind::AddrInUse => {
                EmulatorError::PortInUse { port: config.port.unwrap_or_default() }
            }
            _ => EmulatorError::Io(e),
        })?;
        let flash = config.flash_file.as_deref().map(prepare_flash_file).transpose()?;
        let elf = match &config.firmware {
            Some(path) => path.clone(),
            None => firmware::build(Board::Qemu)?,
        };
        if !elf.is_file() {
            return Err(EmulatorError::NoImage(elf));
        }
        let qemu_port = free_port()?;
        let (qemu, log_decoder) = spawn(&elf, qemu_port, flash.as_deref(), config, false)?;
        proxy.set_upstream(qemu_port);
        let config = config.clone();
        let mut emulator = Self { qemu, log_decoder, proxy, qemu_port, elf, flash, config };
        emulator.wait_ready(READY_WITHIN)?;
        Ok(emulator)
    }

    /// Stops QEMU and starts it again on the same image and flash file; the link's port stays
    /// (connected clients stay connected and get no answers meanwhile). The log is appended to.
    pub fn restart(&mut self) -> Result<(), EmulatorError> {
        self.stop_qemu();
        let qemu_port = free_port()?;
        let (qemu, log_decoder) =
            spawn(&self.elf, qemu_port, self.flash.as_deref(), &self.config, true)?;
        self.qemu = qemu;
        self.log_decoder = log_decoder;
        self.qemu_port = qemu_port;
        self.proxy.set_upstream(qemu_port);
        self.wait_ready(READY_WITHIN)
    }

    /// Kills QEMU at once (SIGKILL: no chance to finish a flash write), as a power cut would.
    /// [`Self::restart`] powers the controller up again.
    pub fn kill(&mut self) {
        if self.signal(Signal::SIGKILL) {
            let _ = self.qemu.wait();
        }
        self.stop_log_decoder();
    }

    /// Freezes QEMU where it is (SIGSTOP), as a controller that hangs: the link's port and
    /// its connections stay open, bytes sent are buffered, and nothing answers until
    /// [`Self::resume`].
    pub fn pause(&mut self) {
        self.signal(Signal::SIGSTOP);
    }

    /// Lets a [`Self::pause`]d QEMU go on (SIGCONT): it reads what was sent meanwhile.
    pub fn resume(&mut self) {
        self.signal(Signal::SIGCONT);
    }

    /// Sends `sig` to QEMU while it runs; false when it had ended.
    fn signal(&mut self, sig: Signal) -> bool {
        if !matches!(self.qemu.try_wait(), Ok(None)) {
            return false;
        }
        let pid = self.qemu.id() as i32;
        // Under coreutils `timeout`, QEMU is timeout's child in timeout's own process group:
        // signal the group. Without it, QEMU is our child.
        let target = if self.config.time_limit.is_some() { -pid } else { pid };
        let _ = kill(Pid::from_raw(target), sig);
        true
    }

    fn wait_ready(&mut self, within: Duration) -> Result<(), EmulatorError> {
        let start = Instant::now();
        loop {
            if let Some(status) = self.qemu.try_wait()? {
                return Err(EmulatorError::EarlyExit(status.to_string()));
            }
            let attempt = TcpStream::connect(("127.0.0.1", self.port()))
                .map_err(DeviceError::from)
                .and_then(|stream| {
                    let name = "chladni emulator (start-up check)";
                    DeviceClient::with_timeout(Box::new(stream), name, Duration::from_millis(500))
                });
            match attempt {
                Ok(_) => return Ok(()),
                Err(e @ DeviceError::VersionMismatch { .. }) => {
                    return Err(EmulatorError::Incompatible(e));
                }
                Err(e) if start.elapsed() > within => {
                    return Err(EmulatorError::NotReady(within, e));
                }
                Err(_) => std::thread::sleep(Duration::from_millis(100)),
            }
        }
    }

    /// The TCP port of the controller's link (the proxy's).
    pub fn port(&self) -> u16 {
        self.proxy.port()
    }

    /// Clients connected to the link's port right now (the proxy's count).
    pub fn clients(&self) -> usize {
        self.proxy.clients()
    }

    /// The link address for [`DeviceClient::open`]: `tcp://127.0.0.1:PORT`.
    pub fn address(&self) -> String {
        format!("tcp://127.0.0.1:{}", self.port())
    }

    /// PID of the QEMU process (or of the `timeout` wrapping it).
    pub fn pid(&self) -> u32 {
        self.qemu.id()
    }

    /// Connects a client named `client_name` to the controller.
    pub fn connect(&self, client_name: &str) -> Result<DeviceClient, DeviceError> {
        DeviceClient::open(&self.address(), client_name)
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

    /// Stops QEMU (SIGTERM, forwarded by `timeout` when present; SIGKILL after 3 s) and closes
    /// the link's port.
    pub fn stop(&mut self) {
        self.stop_qemu();
        self.proxy.shutdown();
    }

    fn stop_qemu(&mut self) {
        // A paused QEMU (and its `timeout`) would hold the SIGTERM until SIGKILL, and QEMU
        // could stay stopped behind a killed `timeout`: let it run to take the signal.
        self.resume();
        stop_child(&mut self.qemu);
        self.stop_log_decoder();
    }

    fn stop_log_decoder(&mut self) {
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

/// `program` with `args`, under coreutils `timeout` when `limit` is given: it then ends after
/// `limit` (SIGTERM, then SIGKILL 5 s later) even when the process that started it was killed
/// outright and never stopped it. Stop it with [`stop_child`].
pub fn limited(program: &str, args: &[String], limit: Option<Duration>) -> Command {
    match limit {
        Some(limit) => {
            let mut c = Command::new("timeout");
            c.args(["--kill-after=5", &format!("{}", limit.as_secs().max(1))]);
            c.arg(program).args(args);
            c
        }
        None => {
            let mut c = Command::new(program);
            c.args(args);
            c
        }
    }
}

/// Stops a child started by [`limited`]: SIGTERM (which `timeout` passes on to its program; a
/// SIGKILL would end `timeout` alone and leave the program running), up to 3 s to end, then
/// SIGKILL.
pub fn stop_child(child: &mut Child) {
    if matches!(child.try_wait(), Ok(None)) {
        let _ = kill(Pid::from_raw(child.id() as i32), Signal::SIGTERM);
        let deadline = Instant::now() + Duration::from_secs(3);
        while matches!(child.try_wait(), Ok(None)) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill();
        let _ = child.wait();
    }
}

/// Starts QEMU on `elf` with its serial socket on `port`, and defmt-print decoding its log
/// into the log file (created, or appended to when `append`) or stderr.
fn spawn(
    elf: &Path,
    port: u16,
    flash: Option<&Path>,
    config: &EmulatorConfig,
    append: bool,
) -> Result<(Child, Option<Child>), EmulatorError> {
    let mut qemu_args = qemu_command_line(elf, port, flash);
    if let Some(speed) = config.speed {
        qemu_args.extend(icount_args(speed));
    }
    let mut command = limited("qemu-system-arm", &qemu_args, config.time_limit);
    let open_log = |path: &Path, append: bool| -> std::io::Result<Stdio> {
        let file = if append {
            File::options().append(true).create(true).open(path)?
        } else {
            File::create(path)?
        };
        Ok(file.into())
    };
    let (log, log_err): (Stdio, Stdio) = match &config.log_file {
        Some(path) => (open_log(path, append)?, open_log(path, true)?),
        None => (Stdio::inherit(), Stdio::inherit()),
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
    match log_decoder {
        Ok(child) => Ok((qemu, Some(child))),
        Err(source) => {
            let _ = qemu.kill();
            let _ = qemu.wait();
            Err(EmulatorError::Spawn { program: "defmt-print", source })
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

/// QEMU's arguments for a fixed emulated speed. `sleep=on` (QEMU's default, written out):
/// while the core sleeps in WFI the guest clock follows the host's, so timers still fire in
/// real time; while it runs, each instruction takes exactly 2^shift ns of guest time.
pub(crate) fn icount_args(speed: EmulatedSpeed) -> Vec<String> {
    vec!["-icount".into(), format!("shift={},sleep=on", speed.shift)]
}

/// Checks the flash file (creating it erased if missing) and returns its absolute path.
pub(crate) fn prepare_flash_file(path: &Path) -> Result<PathBuf, EmulatorError> {
    let fail = |reason: String| EmulatorError::FlashFile { path: path.to_path_buf(), reason };
    if path.is_dir() {
        return Err(fail("is a directory: pass a file path (created erased if missing)".into()));
    }
    if !path.exists() {
        chladni_core::output::write_atomic(path, &vec![0xffu8; FLASH_FILE_SIZE as usize])
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
    fn mips_map_to_the_nearest_icount_shift() {
        let shift = |m: f64| EmulatedSpeed::nearest(m).map(|s| s.shift);
        assert_eq!(shift(62.0), Ok(4));
        assert_eq!(shift(31.0), Ok(5));
        assert_eq!(shift(1000.0), Ok(0));
        assert_eq!(shift(80.0), Ok(4), "80 is nearer 62.5 than 125 on a log scale");
        assert_eq!(shift(1.0), Ok(10));
        assert_eq!(EmulatedSpeed { shift: 5 }.mips(), 31.25);
        for bad in [0.0, 0.5, 1001.0, f64::NAN, -3.0] {
            let err = EmulatedSpeed::nearest(bad).unwrap_err().to_string();
            assert!(err.contains("--mips") && err.contains("1 to 1000"), "{err}");
        }
        assert_eq!(icount_args(EmulatedSpeed { shift: 5 }), ["-icount", "shift=5,sleep=on"]);
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
