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
//! [`SimulatedDac`] ([`simulated`]), which paces blocks with embassy-time and feeds the
//! simulated plant and accelerometer.
//!
//! Sensing and control run here too, once per block, so the drive never waits on them: the
//! sense task queues the accelerometer's batches ([`DriveShared::push_batch`]); the drive
//! hands them to [`ClosedLoop`] (lock-in, loop check, PI, fault monitors), applies its effort
//! and faults to the runner, and publishes the measurement in the status. Sweeps
//! ([`sweep`]) are drives whose frequency steps point by point, measured at each point's end.

use core::cell::{Cell, RefCell};
use core::future::Future;

use chladni_shared::drive::closed_loop::{BlockInput, ClosedLoop};
use chladni_shared::drive::dds::q15_of_gain;
use chladni_shared::drive::runner::{BLOCK_LEN, Runner};
use chladni_shared::icd::link::{DriveError, RunNumber, StatusReport, SweepPage};
use chladni_shared::icd::plan::{DeviceLimits, Level, Plan};
use chladni_shared::icd::sense::{ControlConfig, Measurement, ResetCause, SensorFault};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_time::Duration;

use crate::app::watchdog::{Supervisor, Task};

pub mod simulated;
pub mod sweep;

pub use simulated::SimulatedDac;
pub use sweep::CheckedSweep;
use sweep::{SweepRecord, SweepRun};

/// Most accelerometer samples in one batch handed to the drive.
pub const SENSOR_BATCH: usize = 64;

/// What the sense task hands to the drive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SensorEvent {
    /// Z samples (raw LSB, oldest first) read at drive sample `stamp`.
    Batch {
        /// The samples.
        samples: heapless::Vec<i16, SENSOR_BATCH>,
        /// The drive's sample clock when they were read.
        stamp: u64,
    },
    /// The sensor failed.
    Error(SensorFault),
}

/// The accelerometer's scale and rate, as the sense task set it up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorScale {
    /// m/s² per LSB.
    pub lsb_mps2: f32,
    /// Nominal output rate, mHz.
    pub odr_mhz: u32,
}

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
    /// Sweep the frequency, measuring at each point.
    Sweep(CheckedSweep),
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
    control: Mutex<CriticalSectionRawMutex, Cell<ControlConfig>>,
    last_run: Mutex<CriticalSectionRawMutex, Cell<u32>>,
    sensor: Channel<CriticalSectionRawMutex, SensorEvent, 4>,
    scale: Mutex<CriticalSectionRawMutex, Cell<Option<SensorScale>>>,
    reset_cause: Mutex<CriticalSectionRawMutex, Cell<ResetCause>>,
    sweep: Mutex<CriticalSectionRawMutex, RefCell<SweepRecord>>,
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
            control: Mutex::new(Cell::new(ControlConfig::DEFAULT)),
            last_run: Mutex::new(Cell::new(0)),
            sensor: Channel::new(),
            scale: Mutex::new(Cell::new(None)),
            reset_cause: Mutex::new(Cell::new(ResetCause::PowerOn)),
            sweep: Mutex::new(RefCell::new(SweepRecord::new())),
        }
    }

    /// Why the controller started (the board reads it at boot); the status reports it.
    pub fn set_reset_cause(&self, cause: ResetCause) {
        self.reset_cause.lock(|c| c.set(cause));
    }

    /// The fault monitors' thresholds (a new configuration); applied at the next block.
    pub fn set_control(&self, control: ControlConfig) {
        self.control.lock(|c| c.set(control));
    }

    /// The accelerometer's scale and rate (the sense task, once set up).
    pub fn set_sensor_scale(&self, lsb_mps2: f32, odr_mhz: u32) {
        self.scale.lock(|s| s.set(Some(SensorScale { lsb_mps2, odr_mhz })));
    }

    /// The drive's sample clock as of the last block (the stamp of a sensor read).
    pub fn clock(&self) -> u64 {
        self.status.lock(|s| s.borrow().clock)
    }

    /// Queues Z samples read now for the drive. A full queue drops the batch: the drive is
    /// behind, and the timebase copes with a missing batch better than the drive with a wait.
    pub fn push_batch(&self, samples: &[i16]) {
        let stamp = self.clock();
        for chunk in samples.chunks(SENSOR_BATCH) {
            let samples = heapless::Vec::from_slice(chunk).unwrap_or_default();
            if self.sensor.try_send(SensorEvent::Batch { samples, stamp }).is_err() {
                defmt::warn!("drive: sensor batch dropped (queue full)");
            }
        }
    }

    /// Queues a sensor failure for the drive (it faults if it is driving).
    pub fn push_sensor_error(&self, e: SensorFault) {
        // Never lost: make room by dropping the oldest batch.
        while self.sensor.try_send(SensorEvent::Error(e)).is_err() {
            let _ = self.sensor.try_receive();
        }
    }

    /// A page of the last sweep's points, from point `from` on.
    pub fn sweep_page(&self, from: u16) -> SweepPage {
        self.sweep.lock(|s| s.borrow().page(from))
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
            Command::Sweep(sweep) => {
                let spec = sweep.spec();
                let limits = self.limits();
                for freq in [spec.from_mhz, spec.to_mhz] {
                    let level = Level::Drive(spec.amplitude_q15);
                    limits.check_setpoint(freq, level).map_err(DriveError::Setpoint)?;
                }
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

/// The drive's half: the runner, the closed loop, and the commands and status it exchanges
/// with the link.
pub struct DriveCore<'a> {
    shared: &'a DriveShared,
    supervisor: Option<&'a Supervisor>,
    runner: Runner,
    run: RunNumber,
    closed: Option<ClosedLoop>,
    measured: Option<Measurement>,
    warning: bool,
    sweep: Option<SweepRun>,
}

impl<'a> DriveCore<'a> {
    /// An idle drive.
    pub fn new(shared: &'a DriveShared) -> Self {
        Self {
            shared,
            supervisor: None,
            runner: Runner::new(shared.limits()),
            run: RunNumber(0),
            closed: None,
            measured: None,
            warning: false,
            sweep: None,
        }
    }

    /// Checks in with `supervisor` after every block (the watchdog is fed only while it does).
    pub fn with_supervisor(mut self, supervisor: &'a Supervisor) -> Self {
        self.supervisor = Some(supervisor);
        self
    }

    /// Applies queued commands and sensor data, runs the closed loop, fills `block`,
    /// publishes the status.
    pub fn refill(&mut self, block: &mut [u16]) {
        while let Ok((run, command)) = self.shared.commands.try_receive() {
            // The command is in effect from here on, even if the runner refuses it (a fault
            // latched since it was queued): the status then shows that run number as faulted.
            self.run = run;
            self.runner.set_limits(self.shared.limits());
            if let Err(e) = self.apply(run, command) {
                defmt::warn!("drive: command refused: {}", e);
            }
        }
        let fresh = self.sense_and_control();
        if let Some(sweep) = &mut self.sweep {
            let done = self.shared.sweep.lock(|r| {
                sweep.advance(&mut self.runner, &mut r.borrow_mut(), block.len() as u32, fresh)
            });
            if done {
                self.sweep = None;
            }
        }
        self.runner.fill(block);
        if let Some(s) = self.supervisor {
            s.check_in(Task::Drive);
        }
        self.publish();
    }

    fn apply(&mut self, run: RunNumber, command: Queued) -> Result<(), DriveError> {
        // Any command ends a sweep in progress (its points so far stay readable).
        self.sweep = None;
        match command {
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
                if let Some(c) = &mut self.closed {
                    c.clear_fault();
                }
                // Errors the sense task queued before the clear are what was cleared.
                while self.shared.sensor.try_receive().is_ok() {}
                Ok(())
            }
            Queued::Command(Command::Sweep(spec)) => {
                let sweep = self
                    .shared
                    .sweep
                    .lock(|r| SweepRun::start(spec, run, &mut self.runner, &mut r.borrow_mut()))?;
                self.sweep = Some(sweep);
                Ok(())
            }
        }
    }

    /// Feeds the sensor's batches to the closed loop and applies what it says: the effort in
    /// closed loop, a fault at any time. Returns the measurement completed in this block.
    fn sense_and_control(&mut self) -> Option<Measurement> {
        if self.closed.is_none() {
            let scale = self.shared.scale.lock(|s| s.get())?;
            let control = self.shared.control.lock(|c| c.get());
            self.closed = Some(ClosedLoop::new(control, scale.odr_mhz, scale.lsb_mps2));
        }
        let closed = self.closed.as_mut()?;
        closed.set_config(self.shared.control.lock(|c| c.get()));
        while let Ok(event) = self.shared.sensor.try_receive() {
            match event {
                SensorEvent::Batch { samples, stamp } => closed.push_batch(&samples, stamp),
                SensorEvent::Error(e) => closed.push_sensor_error(e),
            }
        }
        let setpoint = self.runner.setpoint();
        let input = BlockInput {
            now_sample: self.runner.clock(),
            mark: self.runner.phase_mark(),
            target_mmps2: setpoint.and_then(|s| s.level.accel_mmps2()),
            ramp_ms: setpoint.map_or(0, |s| s.ramp_ms),
            effort_ceiling_q15: self.runner.limits().max_amplitude_q15,
            driving: setpoint.is_some(),
            open_effort_q15: q15_of_gain(self.runner.gain()),
        };
        let out = closed.update(&input);
        if out.measurement.is_some() {
            self.measured = out.measurement;
        }
        if setpoint.is_none() && self.runner.gain() == 0 {
            // Silent: nothing to measure; keep no stale reading.
            self.measured = None;
        }
        self.warning = out.warning;
        match out.fault {
            Some(f) if self.runner.latched_fault().is_none() => {
                defmt::warn!("drive: fault {} (value {=i32})", f.cause, f.value);
                self.runner.fault(f);
                self.sweep = None;
            }
            _ => {}
        }
        if let Some(effort) = out.effort_q15 {
            self.runner.set_effort(effort);
        }
        out.measurement
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
        status.measured = self.measured;
        status.warning = self.warning;
        status.reset_cause = self.shared.reset_cause.lock(|c| c.get());
        if let Some(sweep) = &self.sweep {
            sweep.describe(&mut status);
        }
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

/// Runs the drive forever: refill a block, hand it to `output`, repeat; checks in with
/// `supervisor` after each block.
pub async fn run<O: SampleOutput>(
    shared: &DriveShared,
    supervisor: &Supervisor,
    output: &mut O,
) -> ! {
    let mut core = DriveCore::new(shared).with_supervisor(supervisor);
    let mut block = [0u16; BLOCK_LEN];
    loop {
        core.play_block(&mut block, output).await;
    }
}

/// Block period: [`BLOCK_LEN`] samples at the sample rate.
pub const BLOCK_PERIOD: Duration = Duration::from_micros(
    BLOCK_LEN as u64 * 1_000_000 / chladni_shared::drive::dds::SAMPLE_RATE as u64,
);
