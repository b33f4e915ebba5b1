//! Frequency sweeps: the drive steps through a sweep's points at one amplitude, and at the end
//! of each point's dwell records the newest lock-in measurement taken at that frequency.
//!
//! A sweep is a run like a plan: it has a run number, the status names it (`plan` "sweep", the
//! point as `step`, the time left), any other command ends it, a fault ends it, and its last
//! point ends with the usual ramp to zero. The points stay in [`SweepRecord`] for `GetSweep`
//! until the next sweep starts. The first point's dwell includes the ramp up from rest.

use core::ops::Deref;

use chladni_shared::drive::runner::Runner;
use chladni_shared::icd::link::{
    DriveError, MAX_SWEEP_POINTS, RunNumber, SWEEP_PAGE, StatusReport, Sweep, SweepError,
    SweepPage, SweepPoint,
};
use chladni_shared::icd::plan::{Level, Plan};
use chladni_shared::icd::sense::Measurement;
use chladni_shared::icd::units::SAMPLES_PER_MS;

/// A sweep whose shape was checked ([`Sweep::check`]): the only kind the drive accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CheckedSweep(Sweep);

impl CheckedSweep {
    /// `spec` if its shape is valid (points, range, dwell).
    pub fn new(spec: Sweep) -> Result<Self, SweepError> {
        spec.check().map(|()| CheckedSweep(spec))
    }

    /// The sweep.
    pub fn spec(&self) -> &Sweep {
        &self.0
    }
}

/// The points of the last sweep, for `GetSweep`.
pub struct SweepRecord {
    run: RunNumber,
    total: u16,
    points: heapless::Vec<SweepPoint, { MAX_SWEEP_POINTS as usize }>,
}

impl SweepRecord {
    /// No sweep yet.
    pub const fn new() -> Self {
        Self { run: RunNumber(0), total: 0, points: heapless::Vec::new() }
    }

    /// Up to [`SWEEP_PAGE`] points from `from` on.
    pub fn page(&self, from: u16) -> SweepPage {
        let from = (from as usize).min(self.points.len());
        let end = (from + SWEEP_PAGE).min(self.points.len());
        SweepPage {
            run: self.run,
            total: self.total,
            done: self.points.len() as u16,
            points: heapless::Vec::from_slice(&self.points[from..end]).unwrap_or_default(),
        }
    }
}

impl Default for SweepRecord {
    fn default() -> Self {
        Self::new()
    }
}

/// A sweep in progress (owned by the drive task).
#[derive(Debug, Clone, Copy)]
pub struct SweepRun {
    spec: Sweep,
    index: u16,
    left: u32,
    last: Option<Measurement>,
}

impl SweepRun {
    /// Starts `sweep` as run `run`: clears `record`, drives the first point.
    pub fn start(
        sweep: CheckedSweep,
        run: RunNumber,
        runner: &mut Runner<impl Deref<Target = Plan>>,
        record: &mut SweepRecord,
    ) -> Result<SweepRun, DriveError> {
        let spec = *sweep.spec();
        runner.drive(spec.from_mhz, Level::Drive(spec.amplitude_q15))?;
        // Field by field: the record is locked (interrupts off), and a whole new one would be
        // a 3 KiB copy.
        record.run = run;
        record.total = spec.points;
        record.points.clear();
        Ok(SweepRun { spec, index: 0, left: dwell_samples(&spec), last: None })
    }

    /// Accounts for the next `n` samples with the measurement that arrived in this block
    /// (`fresh`); at a point's end records it and moves on. Returns true when the sweep is
    /// over (the runner then ramps to zero).
    pub fn advance(
        &mut self,
        runner: &mut Runner<impl Deref<Target = Plan>>,
        record: &mut SweepRecord,
        n: u32,
        fresh: Option<Measurement>,
    ) -> bool {
        if fresh.is_some() {
            self.last = fresh;
        }
        self.left = self.left.saturating_sub(n);
        if self.left > 0 {
            return false;
        }
        let point = SweepPoint { freq_mhz: self.spec.freq_mhz(self.index), measured: self.last };
        // Capacity: the sweep was checked to have at most MAX_SWEEP_POINTS points.
        let _ = record.points.push(point);
        self.index += 1;
        if self.index >= self.spec.points {
            runner.stop();
            return true;
        }
        self.last = None;
        self.left = dwell_samples(&self.spec);
        let level = Level::Drive(self.spec.amplitude_q15);
        if runner.drive(self.spec.freq_mhz(self.index), level).is_err() {
            // Only a fault refuses a drive here, and a fault ends the sweep anyway.
            return true;
        }
        false
    }

    /// Shows the sweep in `status`: "sweep" as the plan, the point as the step, time left.
    pub fn describe(&self, status: &mut StatusReport) {
        status.plan = heapless::String::try_from("sweep").ok();
        status.step = Some(self.index);
        let after = (self.spec.points - self.index - 1) as u64;
        status.remaining_samples = self.left as u64 + after * dwell_samples(&self.spec) as u64;
    }
}

fn dwell_samples(spec: &Sweep) -> u32 {
    spec.dwell_ms.saturating_mul(SAMPLES_PER_MS)
}
