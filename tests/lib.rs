//! The one test support of the end-to-end tests and of the host's integration tests: the
//! controller under test, which is the firmware in QEMU (started the same way `chladni
//! emulator` does, with a time limit and a log file per test: kept in target/e2e-logs for the
//! end-to-end tests, in the temp folder for the host's, [`emulator`]) or, when `CHLADNI_PORT`
//! is set, a real board on that port (a serial device path or `tcp://HOST:PORT`): hardware in
//! the loop, run by `scripts/hitl.sh`; plans to put on it.

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use chladni_device::client::{DeviceClient, DeviceError};
use chladni_device::emulator::{EmulatedSpeed, Emulator, EmulatorConfig};
use chladni_shared::icd::link::{Board, StatusReport};
use chladni_shared::icd::plan::{Level, Plan, Step};
use chladni_shared::icd::store::PlanSummary;

/// The environment variable that points the tests at a real controller.
pub const PORT_VAR: &str = "CHLADNI_PORT";

/// The real controller's port, when the tests run against one.
pub fn real_port() -> Option<String> {
    std::env::var(PORT_VAR).ok().filter(|p| !p.trim().is_empty())
}

/// One real board serves one test at a time (tests in a file run on parallel threads).
static REAL_BOARD: Mutex<()> = Mutex::new(());

/// The controller a test talks to.
pub enum Controller {
    /// The firmware in QEMU, owned by the test (boxed: it is far larger than the other).
    Emulated(Box<Emulator>),
    /// A real board on a port; the guard keeps other tests of this process off it.
    Real {
        /// Serial path or `tcp://HOST:PORT`.
        port: String,
        /// Held for the test's lifetime.
        _turn: MutexGuard<'static, ()>,
    },
}

impl Controller {
    /// The real board from `CHLADNI_PORT` if set, else a fresh emulator for test `name`.
    pub fn start(name: &str) -> Controller {
        match real_port() {
            Some(port) => Controller::Real {
                port,
                _turn: REAL_BOARD.lock().unwrap_or_else(|poisoned| poisoned.into_inner()),
            },
            None => Controller::Emulated(Box::new(start_emulator(name))),
        }
    }

    /// A new client on the controller's link, named `client_name` (a busy controller shows
    /// the owner's name to others).
    pub fn connect(&self, client_name: &str) -> Result<DeviceClient, DeviceError> {
        match self {
            Controller::Emulated(emulator) => emulator.connect(client_name),
            Controller::Real { port, .. } => DeviceClient::open(port, client_name),
        }
    }

    /// The link address (`tcp://…` or the serial device).
    pub fn address(&self) -> String {
        match self {
            Controller::Emulated(emulator) => emulator.address(),
            Controller::Real { port, .. } => port.clone(),
        }
    }

    /// The board the controller must report: QEMU for the emulator; on a port, the board named
    /// by `CHLADNI_EXPECT_BOARD` (`qemu` when the port is a `chladni emulator` started by hand,
    /// which is how the hardware-in-the-loop path itself is tried without a board), else the
    /// B-L475E-IOT01A.
    pub fn expected_board(&self) -> Board {
        match self {
            Controller::Emulated(_) => Board::Qemu,
            Controller::Real { .. } => match std::env::var("CHLADNI_EXPECT_BOARD").as_deref() {
                Ok("qemu") => Board::Qemu,
                Ok("stm32l475") | Err(_) => Board::Stm32l475,
                Ok(other) => panic!("CHLADNI_EXPECT_BOARD={other}: expected qemu or stm32l475"),
            },
        }
    }

    /// The emulator, for what only QEMU can do (restart, its process, its log, its flash file);
    /// `None` on a real board, after printing that `what` is skipped there.
    pub fn emulator(&mut self, what: &str) -> Option<&mut Emulator> {
        match self {
            Controller::Emulated(emulator) => Some(emulator),
            Controller::Real { port, .. } => {
                println!("skipped on the real board at {port}: {what} (needs QEMU)");
                None
            }
        }
    }
}

/// Longest any one emulator may live: QEMU is killed after this even if the test hangs.
pub const EMULATOR_TIME_LIMIT: Duration = Duration::from_secs(600);

/// The workspace root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Where test `name` writes the firmware's decoded log.
pub fn log_path(name: &str) -> PathBuf {
    let dir = root().join("target/e2e-logs");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{name}.log"))
}

/// The flash file of test `name`'s controller.
pub fn flash_path(name: &str) -> PathBuf {
    log_path(name).with_extension("flash")
}

/// Builds the QEMU firmware if needed and starts it; panics with the log's tail on failure.
pub fn start_emulator(name: &str) -> Emulator {
    start_emulator_at(name, None)
}

/// [`start_emulator`] with the core at a fixed emulated speed (`chladni emulator --mips`).
pub fn start_emulator_at(name: &str, speed: Option<EmulatedSpeed>) -> Emulator {
    start(&EmulatorConfig {
        log_file: Some(log_path(name)),
        time_limit: Some(EMULATOR_TIME_LIMIT),
        flash_file: Some(flash_path(name)),
        speed,
        ..Default::default()
    })
}

/// Time limit of a host integration test's emulator unless the test says otherwise.
pub const TIME_LIMIT: Duration = Duration::from_secs(300);

/// A throw-away controller for host integration test `name`: scratch flash and log in the temp
/// folder ([`EmulatorConfig::scratch`]), QEMU killed after [`TIME_LIMIT`].
pub fn emulator(name: &str) -> Emulator {
    emulator_for(name, TIME_LIMIT)
}

/// [`emulator`] killed after `limit`.
pub fn emulator_for(name: &str, limit: Duration) -> Emulator {
    start(&EmulatorConfig::scratch(name, limit))
}

/// Starts `config`; panics with the end of its log when the controller does not come up.
pub fn start(config: &EmulatorConfig) -> Emulator {
    Emulator::start(config).unwrap_or_else(|e| {
        let log = config.log_file.as_deref().map(read_log).unwrap_or_default();
        let tail = &log[log.len().saturating_sub(4_000)..];
        panic!("the emulator did not start: {e}\nlog tail:\n{tail}")
    })
}

/// An open-loop plan `name`, run once: one step at `drive` (Q15) per frequency in `freq_mhz`,
/// each `duration_ms` long with a 50 ms ramp.
pub fn open_loop_plan(name: &str, freq_mhz: &[u32], drive: u16, duration_ms: u32) -> Plan {
    let steps: Vec<Step> = freq_mhz
        .iter()
        .map(|&freq_mhz| Step { freq_mhz, level: Level::Drive(drive), duration_ms, ramp_ms: 50 })
        .collect();
    plan(name, &steps, 1)
}

/// Uploads `plan` into `slot` over a session of its own, released when this returns (so
/// another session, a cell's for one, may run it).
pub fn upload(emu: &Emulator, plan: &Plan, slot: u8) -> PlanSummary {
    let mut client = emu.connect("test upload").expect("connect to the emulator");
    client.upload(plan, Some(slot), |_, _| {}).expect("upload the plan")
}

/// The log so far (empty if none).
pub fn read_log(path: &std::path::Path) -> String {
    std::fs::read_to_string(path).unwrap_or_default()
}

/// Reproducible pseudo-random bytes from the host's one seeded generator.
pub fn pseudo_random_bytes(seed: u64, len: usize) -> Vec<u8> {
    let mut rng = chladni_core::rng::Rng::seeded(seed);
    (0..len).map(|_| (rng.next_u64() >> 56) as u8).collect()
}

/// Polls `status` until `done` holds (generous deadline: QEMU's clock slips under load);
/// returns every status seen.
pub fn poll_until(
    client: &mut DeviceClient,
    limit: Duration,
    mut done: impl FnMut(&StatusReport) -> bool,
) -> Vec<StatusReport> {
    let deadline = std::time::Instant::now() + limit;
    let mut seen = Vec::new();
    loop {
        let status = client.status().expect("status");
        let finished = done(&status);
        seen.push(status);
        if finished {
            return seen;
        }
        assert!(std::time::Instant::now() < deadline, "gave up waiting; last {:?}", seen.last());
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A plan named `name` of `steps`, run `repeat` times.
pub fn plan(name: &str, steps: &[Step], repeat: u16) -> Plan {
    Plan {
        name: heapless::String::try_from(name).unwrap(),
        repeat,
        steps: heapless::Vec::from_slice(steps).unwrap(),
    }
}

/// `count` steps of `duration_ms` each, frequencies rising from `base_mhz`.
pub fn steps(count: usize, base_mhz: u32, duration_ms: u32) -> Vec<Step> {
    (0..count)
        .map(|i| Step {
            freq_mhz: base_mhz + 1_000 * i as u32,
            level: chladni_shared::icd::plan::Level::Drive(4_000 + (i as u16 % 8) * 1_000),
            duration_ms,
            ramp_ms: duration_ms.min(5),
        })
        .collect()
}

/// Frames received until one satisfies `wanted` (all of them, that one last), or every frame
/// received within `limit` if none does. QEMU's serial port takes a burst of bytes at its own
/// pace, so the answer to a frame sent after kilobytes of garbage may take seconds to come.
pub fn frames_until(
    client: &mut chladni_device::client::DeviceClient,
    limit: Duration,
    wanted: impl Fn(&chladni_device::client::Frame) -> bool,
) -> Vec<chladni_device::client::Frame> {
    let start = std::time::Instant::now();
    let mut frames = Vec::new();
    while start.elapsed() < limit {
        let more = client.receive_frames(Duration::from_millis(200)).expect("receive frames");
        let done = more.iter().any(&wanted);
        frames.extend(more);
        if done {
            break;
        }
    }
    frames
}
