//! The drive task: owns the plan runner and feeds its sample blocks to the board's output.
//!
//! The link task talks to it through [`DriveShared`]: commands go through an embassy-sync
//! [`Channel`], each with the [`RunNumber`] it was given when accepted, and the drive publishes
//! a [`StatusReport`] after every block into a blocking mutex the link reads. The status names
//! the run number of the command in effect, so a host can tell "its" run from an older one. The
//! runner itself is owned by the drive task alone.
//!
//! Priorities: the drive task runs on an interrupt executor above the link, store, USB and sense
//! tasks (which share the thread-mode executor), so everything in [`DriveShared`] is reached
//! from two priority levels. Every piece is either a critical-section mutex held for O(1) work
//! (a command, a status of ~150 bytes, a sensor batch, a page of sweep points) or one of two
//! plan buffers behind async mutexes: the link copies a new plan into the buffer the drive is
//! not reading, outside any critical section, and the drive starts it by taking that buffer's
//! lock and dropping the other's. Nothing O(plan), and no log, runs with interrupts off.
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
use core::sync::atomic::{AtomicU32, Ordering};

use chladni_shared::drive::closed_loop::{BlockInput, ClosedLoop};
use chladni_shared::drive::dds::q15_of_gain;
use chladni_shared::drive::runner::{BLOCK_LEN, Runner};
use chladni_shared::icd::link::{DriveError, RunNumber, StatusReport, SweepPage};
use chladni_shared::icd::plan::{DeviceLimits, Level, Plan};
use chladni_shared::icd::sense::{ControlConfig, Measurement, ResetCause, SensorFault};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::mutex::{Mutex as AsyncMutex, MutexGuard};
use embassy_time::Duration;

use crate::app::watchdog::{Supervisor, Task};

pub mod simulated;
pub mod sweep;

pub use simulated::SimulatedDac;

/// Plan steps [`DriveShared::check_plan`] checks between two yields.
pub const STEPS_PER_YIELD: usize = 64;

/// A plan checked against the drive's limits: only [`DriveShared::run_plan`] and
/// [`DriveShared::check_plan`] make one, so [`DriveShared::stage_plan`] takes no unchecked plan.
/// (Only the link changes the limits, and it stages what it checked before doing anything
/// else.)
pub struct CheckedPlan<'p>(&'p Plan);
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
    /// Run the plan [`DriveShared::run_plan`] staged in this plan buffer.
    RunPlan(usize),
    /// A manual drive or a stop.
    Command(Command),
}

/// One of the two plan buffers (a plan is up to ~5 KiB).
type PlanBuffer = AsyncMutex<CriticalSectionRawMutex, Plan>;
/// The drive's hold on the plan buffer it runs from.
pub type PlanGuard<'a> = MutexGuard<'a, CriticalSectionRawMutex, Plan>;
/// The runner as the drive task has it: reading its plan through a buffer's lock.
pub type DriveRunner<'a> = Runner<PlanGuard<'a>>;

const EMPTY_PLAN: Plan =
    Plan { name: heapless::String::new(), repeat: 0, steps: heapless::Vec::new() };

/// Least refill slack not yet measured.
const NO_SLACK: u32 = u32::MAX;

/// What the link task and the drive task share.
pub struct DriveShared {
    commands: Channel<CriticalSectionRawMutex, (RunNumber, Queued), 2>,
    /// Plans change hands here, never through the command queue or the stack.
    plans: [PlanBuffer; 2],
    /// A plan is being staged or waits for the drive: only one at a time.
    staging: Mutex<CriticalSectionRawMutex, Cell<bool>>,
    /// Least refill slack seen since boot, µs ([`NO_SLACK`] before the first).
    least_slack_us: AtomicU32,
    /// Stack high water, bytes (0: not measured on this board).
    stack_high_water: AtomicU32,
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
            plans: [AsyncMutex::new(EMPTY_PLAN), AsyncMutex::new(EMPTY_PLAN)],
            staging: Mutex::new(Cell::new(false)),
            least_slack_us: AtomicU32::new(NO_SLACK),
            stack_high_water: AtomicU32::new(0),
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

    /// Checks `plan`, copies it into the plan buffer the drive is not running from and queues
    /// it to run; returns its run number. Only one plan waits at a time: a second one before
    /// the drive took the first is [`DriveError::QueueFull`]. The copy runs with interrupts on
    /// (the drive may preempt it); only the flag and the queueing are critical sections.
    pub fn run_plan(&self, plan: &Plan) -> Result<RunNumber, DriveError> {
        plan.validate(&self.limits()).map_err(DriveError::Plan)?;
        self.stage_plan(CheckedPlan(plan))
    }

    /// Checks `plan` against the limits as [`Plan::validate`] does, in one pass, yielding to
    /// the other thread-mode tasks every [`STEPS_PER_YIELD`] steps (the link's way:
    /// a 256-step check is a few thousand instructions, not worth holding the executor for).
    pub async fn check_plan<'p>(&self, plan: &'p Plan) -> Result<CheckedPlan<'p>, DriveError> {
        let limits = self.limits();
        let len = plan.steps.len().min(u16::MAX as usize) as u16;
        limits.check_plan_header(plan.repeat, len).map_err(DriveError::Plan)?;
        let mut total_ms = 0u64;
        for (i, step) in plan.steps.iter().enumerate() {
            limits.check_step(i as u16, step).map_err(DriveError::Plan)?;
            total_ms += step.duration_ms as u64;
            if (i + 1) % STEPS_PER_YIELD == 0 {
                embassy_futures::yield_now().await;
            }
        }
        limits.check_total_ms(total_ms * plan.repeat as u64).map_err(DriveError::Plan)?;
        Ok(CheckedPlan(plan))
    }

    /// [`DriveShared::run_plan`] of a plan [`DriveShared::check_plan`] passed.
    pub fn stage_plan(&self, plan: CheckedPlan<'_>) -> Result<RunNumber, DriveError> {
        let CheckedPlan(plan) = plan;
        self.check_not_faulted()?;
        if self.staging.lock(|s| s.replace(true)) {
            return Err(DriveError::QueueFull);
        }
        // The drive holds at most one buffer, and only this call stages: one is free.
        let free =
            self.plans.iter().enumerate().find_map(|(i, b)| b.try_lock().ok().map(|g| (i, g)));
        let Some((slot, mut buffer)) = free else {
            self.staging.lock(|s| s.set(false));
            return Err(DriveError::QueueFull);
        };
        buffer.copy_from(plan);
        drop(buffer);
        let queued = critical_section::with(|cs| self.queue(cs, Queued::RunPlan(slot)));
        if queued.is_err() {
            self.staging.lock(|s| s.set(false));
        }
        queued
    }

    /// Records a refill's slack (µs between the block being handed over and the output
    /// running dry); the status reports the least since boot.
    pub fn note_slack_us(&self, slack_us: u32) {
        self.least_slack_us.fetch_min(slack_us, Ordering::Relaxed);
    }

    /// The least refill slack since boot, µs (`None` before the first block).
    pub fn least_slack_us(&self) -> Option<u32> {
        Some(self.least_slack_us.load(Ordering::Relaxed)).filter(|&s| s != NO_SLACK)
    }

    /// Records the stack's high water (bytes), measured by the board.
    pub fn set_stack_high_water(&self, bytes: u32) {
        self.stack_high_water.store(bytes, Ordering::Relaxed);
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

    /// The status published after the last block, with the least slack and the stack's high
    /// water as of now.
    pub fn status(&self) -> StatusReport {
        let mut status = self.status.lock(|s| s.borrow().clone());
        status.least_slack_us = self.least_slack_us();
        status.stack_high_water = self.stack_high_water.load(Ordering::Relaxed);
        status
    }
}

/// The drive's half: the runner, the closed loop, and the commands and status it exchanges
/// with the link.
pub struct DriveCore<'a> {
    shared: &'a DriveShared,
    supervisor: Option<&'a Supervisor>,
    runner: DriveRunner<'a>,
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

    // Never inlined, nor is the closed loop's construction: both run rarely, and inlined they
    // would add their locals to the drive's frame at every block, on top of whatever the
    // thread-mode tasks it preempts have on the stack.
    #[inline(never)]
    fn apply(&mut self, run: RunNumber, command: Queued) -> Result<(), DriveError> {
        // Any command ends a sweep in progress (its points so far stay readable).
        self.sweep = None;
        match command {
            Queued::RunPlan(slot) => {
                // The link dropped its hold before queueing: the lock is free. Taking it and
                // dropping the previous plan's is the whole hand-over.
                let buffer = self.shared.plans[slot].try_lock();
                self.shared.staging.lock(|s| s.set(false));
                let buffer = buffer.map_err(|_| DriveError::QueueFull)?;
                let steps = buffer.steps.len();
                drop(self.runner.start_plan(buffer)?);
                if let Some(plan) = self.runner.plan() {
                    defmt::info!("drive: plan '{}', {} steps", plan.name.as_str(), steps);
                }
                Ok(())
            }
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

    /// Builds the closed loop once the sense task has given the sensor's scale.
    #[inline(never)]
    fn start_closed_loop(&mut self) -> Option<()> {
        let scale = self.shared.scale.lock(|s| s.get())?;
        let control = self.shared.control.lock(|c| c.get());
        self.closed = Some(ClosedLoop::new(control, scale.odr_mhz, scale.lsb_mps2));
        Some(())
    }

    /// Feeds the sensor's batches to the closed loop and applies what it says: the effort in
    /// closed loop, a fault at any time. Returns the measurement completed in this block.
    fn sense_and_control(&mut self) -> Option<Measurement> {
        if self.closed.is_none() {
            self.start_closed_loop()?;
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
    /// output had run dry, and keep the least slack the output reports.
    pub async fn play_block<O: SampleOutput>(&mut self, block: &mut [u16], output: &mut O) {
        self.refill(block);
        self.hand_over(block, output).await;
    }

    /// Gives the refilled `block` to `output` (waiting for room) and notes its slack.
    pub async fn hand_over<O: SampleOutput>(&mut self, block: &[u16], output: &mut O) {
        match output.write_block(block).await {
            Ok(Some(slack_us)) => self.shared.note_slack_us(slack_us),
            Ok(None) => {}
            Err(Underrun) => {
                self.shared.note_slack_us(0);
                self.note_underrun();
            }
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
    /// Waits until the output has room for `block`, then takes it. `Ok(slack)`: the block came
    /// in time, `slack` µs before the output would have run dry without it (`None` if the
    /// output cannot tell). `Err(Underrun)` when the output had run dry before (the block is
    /// still taken).
    fn write_block(&mut self, block: &[u16])
    -> impl Future<Output = Result<Option<u32>, Underrun>>;
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

/// [`run`], also timing every refill with `clock` (a free-running counter: the board's
/// `refill_clock`, cycles on the chip) and logging the mean and the most per
/// [`RefillCost::BLOCKS`] blocks, in `unit`.
pub async fn run_metered<O: SampleOutput>(
    shared: &DriveShared,
    supervisor: &Supervisor,
    output: &mut O,
    clock: fn() -> u32,
    unit: &'static str,
) -> ! {
    let mut core = DriveCore::new(shared).with_supervisor(supervisor);
    let mut block = [0u16; BLOCK_LEN];
    let mut cost = RefillCost::new();
    loop {
        let start = clock();
        core.refill(&mut block);
        let spent = clock().wrapping_sub(start);
        // A clock that stepped back (QEMU's SysTick-based clock can, by up to a tick, when
        // read at the drive's priority around a SysTick wrap) gives no measurement.
        if spent >= 1 << 31 {
            core.hand_over(&block, output).await;
            continue;
        }
        if let Some((mean, max)) = cost.note(spent) {
            defmt::info!(
                "drive: refill mean {=u32} max {=u32} {=str} over {=u32} blocks",
                mean,
                max,
                unit,
                RefillCost::BLOCKS
            );
        }
        core.hand_over(&block, output).await;
    }
}

/// Refill costs of the last [`RefillCost::BLOCKS`] blocks (interrupt handlers that preempt a
/// refill count in it).
#[derive(Debug, Default)]
pub struct RefillCost {
    blocks: u32,
    sum: u64,
    max: u32,
}

impl RefillCost {
    /// Blocks per report: 10 s.
    pub const BLOCKS: u32 = 2_000;

    /// Nothing counted yet.
    pub const fn new() -> Self {
        Self { blocks: 0, sum: 0, max: 0 }
    }

    /// Counts one refill's `cost`; every [`Self::BLOCKS`] refills, their mean and most (and
    /// starts again).
    pub fn note(&mut self, cost: u32) -> Option<(u32, u32)> {
        self.blocks += 1;
        self.sum += cost as u64;
        self.max = self.max.max(cost);
        if self.blocks < Self::BLOCKS {
            return None;
        }
        let report = ((self.sum / self.blocks as u64) as u32, self.max);
        *self = Self::new();
        Some(report)
    }
}

/// Block period: [`BLOCK_LEN`] samples at the sample rate.
pub const BLOCK_PERIOD: Duration = Duration::from_micros(
    BLOCK_LEN as u64 * 1_000_000 / chladni_shared::icd::units::SAMPLE_RATE as u64,
);
