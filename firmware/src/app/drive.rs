//! The drive task: owns the plan runner and feeds its sample blocks to the board's output.
//!
//! The link task talks to it through [`DriveShared`]: commands go through an embassy-sync
//! [`Channel`], each with the [`RunNumber`] it was given when accepted, and the drive publishes
//! a [`StatusReport`] after every block into a blocking mutex the link reads. The status names
//! the run number of the command in effect, so a host can tell "its" run from an older one. The
//! runner itself is owned by the drive task alone.
//!
//! The output is anything that takes blocks of 12-bit DAC codes at the sample rate
//! ([`SampleOutput`]): on the board, the DAC's circular DMA buffer; in QEMU,
//! [`SimulatedDac`], which paces blocks with embassy-time and feeds the simulated plant.

use core::cell::{Cell, RefCell};
use core::future::Future;

use chladni_shared::drive::plant::{Plant, PlantParams};
use chladni_shared::drive::runner::{BLOCK_LEN, Runner};
use chladni_shared::icd::link::{DriveError, RunNumber, StatusReport};
use chladni_shared::icd::plan::{DeviceLimits, Level, Plan};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_time::{Duration, Instant, Timer};

/// A command for the drive task (plans go through [`DriveShared::run_plan`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Manual drive.
    Drive {
        /// Frequency, mHz.
        freq_mhz: u32,
        /// Amplitude (open loop) or acceleration target (closed loop).
        level: Level,
    },
    /// Ramp to zero and idle.
    Stop,
    /// Clear a latched fault.
    ClearFault,
}

/// What the command queue carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Queued {
    /// Run the plan staged by [`DriveShared::run_plan`].
    RunPlan,
    /// A manual drive or a stop.
    Command(Command),
}

/// The plan waiting for the drive task: plans (up to ~4 KiB) are handed over here, one at a
/// time, rather than through the command queue, so no plan is ever copied on the stack.
struct Staged {
    plan: Plan,
    waiting: bool,
}

/// What the link task and the drive task share.
pub struct DriveShared {
    commands: Channel<CriticalSectionRawMutex, (RunNumber, Queued), 2>,
    staged: Mutex<CriticalSectionRawMutex, RefCell<Staged>>,
    status: Mutex<CriticalSectionRawMutex, RefCell<StatusReport>>,
    limits: Mutex<CriticalSectionRawMutex, Cell<DeviceLimits>>,
    last_run: Mutex<CriticalSectionRawMutex, Cell<u32>>,
}

impl Default for DriveShared {
    fn default() -> Self {
        Self::new()
    }
}

impl DriveShared {
    /// Empty queue, idle status, the default device limits.
    pub const fn new() -> Self {
        Self {
            commands: Channel::new(),
            staged: Mutex::new(RefCell::new(Staged {
                plan: Plan {
                    name: heapless::String::new(),
                    repeat: 0,
                    steps: heapless::Vec::new(),
                },
                waiting: false,
            })),
            status: Mutex::new(RefCell::new(StatusReport::IDLE)),
            limits: Mutex::new(Cell::new(DeviceLimits::DEFAULT)),
            last_run: Mutex::new(Cell::new(0)),
        }
    }

    /// The device limits commands are checked against.
    pub fn limits(&self) -> DeviceLimits {
        self.limits.lock(|l| l.get())
    }

    /// Checks later commands against `limits` (a new configuration); what runs goes on.
    pub fn set_limits(&self, limits: DeviceLimits) {
        self.limits.lock(|l| l.set(limits));
    }

    /// Checks `plan`, stages a copy of it and queues it to run; returns its run number.
    /// Only one plan waits at a time: a second one before the drive took the first is
    /// [`DriveError::QueueFull`].
    pub fn run_plan(&self, plan: &Plan) -> Result<RunNumber, DriveError> {
        plan.validate(&self.limits()).map_err(DriveError::Plan)?;
        self.check_not_faulted()?;
        critical_section::with(|cs| {
            let mut staged = self.staged.borrow(cs).borrow_mut();
            if staged.waiting {
                return Err(DriveError::QueueFull);
            }
            let run = self.queue(cs, Queued::RunPlan)?;
            staged.plan.clone_from(plan);
            staged.waiting = true;
            Ok(run)
        })
    }

    /// Queues a manual drive or a stop for the drive task and returns the run number it will
    /// carry in the status. Setpoints are validated first, and a faulted drive refuses
    /// anything but a stop, so the caller can answer with the precise error.
    pub fn submit(&self, command: Command) -> Result<RunNumber, DriveError> {
        match command {
            Command::Drive { freq_mhz, level } => {
                let limits = self.limits();
                limits.check_setpoint(freq_mhz, level).map_err(DriveError::Setpoint)?;
                self.check_not_faulted()?;
            }
            Command::Stop | Command::ClearFault => {}
        }
        critical_section::with(|cs| self.queue(cs, Queued::Command(command)))
    }

    fn check_not_faulted(&self) -> Result<(), DriveError> {
        match self.status.lock(|s| s.borrow().fault) {
            Some(_) => Err(DriveError::Faulted),
            None => Ok(()),
        }
    }

    /// Numbers and queues `command` in one critical section, so numbers reach the drive in
    /// order; a refused command takes no number.
    fn queue(
        &self,
        cs: critical_section::CriticalSection<'_>,
        command: Queued,
    ) -> Result<RunNumber, DriveError> {
        let last = self.last_run.borrow(cs);
        let run = RunNumber(last.get().wrapping_add(1).max(1));
        self.commands.try_send((run, command)).map_err(|_| DriveError::QueueFull)?;
        last.set(run.0);
        Ok(run)
    }

    /// The status published after the last block.
    pub fn status(&self) -> StatusReport {
        self.status.lock(|s| s.borrow().clone())
    }
}

/// The drive's half: the runner, and the commands and status it exchanges with the link.
pub struct DriveCore<'a> {
    shared: &'a DriveShared,
    runner: Runner,
    run: RunNumber,
}

impl<'a> DriveCore<'a> {
    /// An idle drive.
    pub fn new(shared: &'a DriveShared) -> Self {
        Self { shared, runner: Runner::new(shared.limits()), run: RunNumber(0) }
    }

    /// Applies queued commands, fills `block`, publishes the status.
    pub fn refill(&mut self, block: &mut [u16]) {
        while let Ok((run, command)) = self.shared.commands.try_receive() {
            // The command is in effect from here on, even if the runner refuses it (a fault
            // latched since it was queued): the status then shows that run number as faulted.
            self.run = run;
            self.runner.set_limits(self.shared.limits());
            let result = match command {
                Queued::RunPlan => self.shared.staged.lock(|staged| {
                    let mut staged = staged.borrow_mut();
                    staged.waiting = false;
                    defmt::info!(
                        "drive: plan '{}', {} steps",
                        staged.plan.name.as_str(),
                        staged.plan.steps.len()
                    );
                    self.runner.start_plan_from(&mut staged.plan)
                }),
                Queued::Command(Command::Drive { freq_mhz, level }) => {
                    self.runner.drive(freq_mhz, level)
                }
                Queued::Command(Command::Stop) => {
                    self.runner.stop();
                    Ok(())
                }
                Queued::Command(Command::ClearFault) => {
                    if let Some(f) = self.runner.clear_fault() {
                        defmt::info!("drive: fault cleared: {}", f);
                    }
                    Ok(())
                }
            };
            if let Err(e) = result {
                defmt::warn!("drive: command refused: {}", e);
            }
        }
        self.runner.fill(block);
        self.publish();
    }

    /// One turn of the drive: refill `block`, hand it to `output`, count an underrun if the
    /// output had run dry.
    pub async fn play_block<O: SampleOutput>(&mut self, block: &mut [u16], output: &mut O) {
        self.refill(block);
        if output.write_block(block).await.is_err() {
            self.note_underrun();
        }
    }

    /// Counts a missed refill.
    pub fn note_underrun(&mut self) {
        self.runner.note_underrun();
        self.publish();
    }

    fn publish(&self) {
        let mut status = self.runner.status();
        status.run = self.run;
        self.shared.status.lock(|s| *s.borrow_mut() = status);
    }
}

/// The output ran dry before the next block was ready.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct Underrun;

/// Where sample blocks go, one [`BLOCK_LEN`] block at a time, at the sample rate.
pub trait SampleOutput {
    /// Waits until the output has room for `block`, then takes it. `Err(Underrun)` when the
    /// output had run dry before (the block is still taken).
    fn write_block(&mut self, block: &[u16]) -> impl Future<Output = Result<(), Underrun>>;
}

/// Runs the drive forever: refill a block, hand it to `output`, repeat.
pub async fn run<O: SampleOutput>(shared: &DriveShared, output: &mut O) -> ! {
    let mut core = DriveCore::new(shared);
    let mut block = [0u16; BLOCK_LEN];
    loop {
        core.play_block(&mut block, output).await;
    }
}

/// Block period: [`BLOCK_LEN`] samples at the sample rate.
pub const BLOCK_PERIOD: Duration = Duration::from_micros(
    BLOCK_LEN as u64 * 1_000_000 / chladni_shared::drive::dds::SAMPLE_RATE as u64,
);

/// A DAC that exists only in time: it takes one block per [`BLOCK_PERIOD`] (paced by
/// embassy-time) and drives the simulated shaker + plate with it. A block that arrives more
/// than one block period after the previous one has played out counts as an underrun (one
/// block of slack beyond the hardware's, because QEMU's clock follows the host's and slips
/// under load), and the stream restarts from then.
pub struct SimulatedDac {
    plant: Plant,
    next: Option<Instant>,
}

impl Default for SimulatedDac {
    fn default() -> Self {
        Self::new()
    }
}

impl SimulatedDac {
    /// A plant at rest with the default parameters.
    pub fn new() -> Self {
        Self { plant: Plant::new(PlantParams::DEFAULT), next: None }
    }
}

impl SampleOutput for SimulatedDac {
    async fn write_block(&mut self, block: &[u16]) -> Result<(), Underrun> {
        let now = Instant::now();
        // `next` is when the previous block has finished playing.
        let (start, result) = match self.next {
            None => (now, Ok(())),
            Some(next) if now > next + BLOCK_PERIOD => (now, Err(Underrun)),
            Some(next) => (next, Ok(())),
        };
        self.plant.run(block);
        self.next = Some(start + BLOCK_PERIOD);
        // Double buffering: the block just handed over plays while the next one is filled.
        Timer::at(start).await;
        result
    }
}
