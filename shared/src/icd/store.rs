//! The plan store as the link sees it: slots, chunked uploads, summaries, configuration, and
//! the typed errors of each.
//!
//! A plan is uploaded in three kinds of request: [`UploadBegin`] (name, repeat, step count and
//! the plan's CRC), then one [`UploadChunk`] per [`CHUNK_STEPS`] steps in order, then
//! `UploadCommit`. Only the commit makes the plan visible: until then the slot keeps its old plan,
//! whole, even across a power cut. The plan CRC is [`plan_crc`]: CRC-32/ISO-HDLC over the
//! postcard encoding of the [`Plan`] (name, repeat, steps), so both sides compute it from the
//! same bytes.

use serde::{Deserialize, Serialize};

use crate::icd::frame::CRC32;
use crate::icd::plan::{DeviceLimits, MAX_NAME, MAX_STEPS, Plan, PlanError, Step};
use crate::icd::sense::ControlConfig;

/// Plans the store holds: slots `0..PLAN_SLOTS`.
pub const PLAN_SLOTS: u8 = 65;
/// The slot `chladni device run-file` uploads to (the last one), so a file run never replaces a
/// named plan.
pub const SCRATCH_SLOT: u8 = PLAN_SLOTS - 1;
/// Steps per upload chunk (and per stored chunk): 32 steps fit one frame with room to spare.
pub const CHUNK_STEPS: usize = 32;
/// Chunks of the longest plan.
pub const MAX_CHUNKS: usize = MAX_STEPS.div_ceil(CHUNK_STEPS);
/// Plan summaries per [`PlanPage`] (a page must fit one frame).
pub const PAGE_PLANS: usize = 8;

/// A plan's name on the wire.
pub type PlanName = heapless::String<MAX_NAME>;

/// Which stored plan: by slot or by name.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PlanRef {
    /// Slot number, `0..PLAN_SLOTS`.
    Slot(u8),
    /// The plan's name (exact, case-sensitive).
    Name(PlanName),
}

/// Starts an upload (replacing any upload in progress).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UploadBegin {
    /// Slot to store into; `None`: the slot of the plan with this name if there is one, else
    /// the lowest free slot below [`SCRATCH_SLOT`].
    pub slot: Option<u8>,
    /// The plan's name: unique among slots below [`SCRATCH_SLOT`] (an upload under another
    /// plan's name into another such slot is refused); the scratch slot may repeat a name, and a
    /// lookup by name tries the other slots first.
    pub name: PlanName,
    /// How many times the steps run.
    pub repeat: u16,
    /// How many steps the chunks will carry.
    pub steps: u16,
    /// [`plan_crc`] of the whole plan.
    pub crc: u32,
}

impl UploadBegin {
    /// The `UploadBegin` of `plan` into `slot` (`None`: the controller picks), with its
    /// [`plan_crc`].
    pub fn of(plan: &Plan, slot: Option<u8>) -> Self {
        UploadBegin {
            slot,
            name: plan.name.clone(),
            repeat: plan.repeat,
            steps: plan.steps.len() as u16,
            crc: plan_crc(plan),
        }
    }
}

/// One chunk of an upload: steps `index * CHUNK_STEPS ..`, at most [`CHUNK_STEPS`] of them;
/// every chunk but the last is full.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UploadChunk {
    /// Chunk number, from 0.
    pub index: u16,
    /// The steps.
    pub steps: heapless::Vec<Step, CHUNK_STEPS>,
}

/// What the store says about one plan.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlanSummary {
    /// Slot.
    pub slot: u8,
    /// Name.
    pub name: PlanName,
    /// Steps.
    pub steps: u16,
    /// Repeats.
    pub repeat: u16,
    /// Length of all repeats, ms.
    pub total_ms: u64,
    /// [`plan_crc`].
    pub crc: u32,
    /// Flash the plan takes (items and their headers), bytes.
    pub bytes: u32,
}

/// One page of the plan list, slots from the request's `from_slot` on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlanPage {
    /// Stored plans, by slot.
    pub plans: heapless::Vec<PlanSummary, PAGE_PLANS>,
    /// The slot to ask for next, `None` after the last plan.
    pub next: Option<u8>,
    /// Flash still free for plans (the store's range less live items and one page kept for
    /// garbage collection), bytes.
    pub free_bytes: u32,
}

/// Device settings kept in the store and checked when loaded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceConfig {
    /// What plans and manual drives are checked against (within the hardware's
    /// [`DeviceLimits::DEFAULT`]).
    pub limits: DeviceLimits,
    /// Thresholds of the fault monitors and the loop check.
    pub control: ControlConfig,
}

impl DeviceConfig {
    /// The factory configuration: the hardware's limits.
    pub const DEFAULT: DeviceConfig =
        DeviceConfig { limits: DeviceLimits::DEFAULT, control: ControlConfig::DEFAULT };

    /// Checks that the configuration narrows the hardware's limits and is usable.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let (l, hw) = (&self.limits, &DeviceLimits::DEFAULT);
        if l.min_freq_mhz < hw.min_freq_mhz || l.max_freq_mhz > hw.max_freq_mhz {
            return Err(ConfigError::FrequencyRange {
                min_mhz: l.min_freq_mhz,
                max_mhz: l.max_freq_mhz,
            });
        }
        if l.min_freq_mhz >= l.max_freq_mhz {
            return Err(ConfigError::FrequencyRange {
                min_mhz: l.min_freq_mhz,
                max_mhz: l.max_freq_mhz,
            });
        }
        if l.max_amplitude_q15 > hw.max_amplitude_q15 {
            return Err(ConfigError::Amplitude { max_q15: l.max_amplitude_q15 });
        }
        if l.max_steps == 0 || l.max_steps > hw.max_steps {
            return Err(ConfigError::Steps { max_steps: l.max_steps });
        }
        if l.max_total_ms == 0 || l.max_total_ms > hw.max_total_ms {
            return Err(ConfigError::Length { max_ms: l.max_total_ms });
        }
        if l.max_accel_mmps2 == 0 || l.max_accel_mmps2 > hw.max_accel_mmps2 {
            return Err(ConfigError::Accel { max_mmps2: l.max_accel_mmps2 });
        }
        self.validate_control()
    }

    /// The monitors' thresholds: each within a range that keeps the fault checks meaningful.
    fn validate_control(&self) -> Result<(), ConfigError> {
        let c = &self.control;
        let bad = |field, value: u32| Err(ConfigError::Control { field, value });
        if c.warn_band_mdb == 0 || c.warn_band_mdb >= c.abort_band_mdb {
            return bad(ControlField::WarnBand, c.warn_band_mdb);
        }
        if c.abort_band_mdb > 20_000 {
            return bad(ControlField::AbortBand, c.abort_band_mdb);
        }
        if c.max_accel_mmps2 <= self.limits.max_accel_mmps2 {
            return bad(ControlField::MaxAccel, c.max_accel_mmps2);
        }
        let times = [
            (ControlField::OpenLoopMs, c.open_loop_ms),
            (ControlField::BandMs, c.band_ms),
            (ControlField::NoDataMs, c.no_data_ms),
            (ControlField::SaturationMs, c.saturation_ms),
            (ControlField::CheckMs, c.check_ms),
        ];
        for (field, ms) in times {
            if !(10..=10_000).contains(&ms) {
                return bad(field, ms);
            }
        }
        if c.check_effort_q15 == 0 || c.check_effort_q15 > self.limits.max_amplitude_q15 {
            return bad(ControlField::CheckEffort, c.check_effort_q15 as u32);
        }
        if c.open_loop_effort_q15 == 0 {
            return bad(ControlField::OpenLoopEffort, 0);
        }
        Ok(())
    }
}

impl Default for DeviceConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why a configuration was refused. Each names the offending value; the hardware's bounds are
/// [`DeviceLimits::DEFAULT`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// The frequency range is empty or outside the hardware's.
    FrequencyRange {
        /// Lowest, mHz.
        min_mhz: u32,
        /// Highest, mHz.
        max_mhz: u32,
    },
    /// The amplitude limit is above full scale.
    Amplitude {
        /// The limit asked for, Q15.
        max_q15: u16,
    },
    /// The step limit is 0 or above what the store holds.
    Steps {
        /// The limit asked for.
        max_steps: u16,
    },
    /// The plan length limit is 0 or above the hardware's.
    Length {
        /// The limit asked for, ms.
        max_ms: u64,
    },
    /// The acceleration limit is 0 or above the hardware's.
    Accel {
        /// The limit asked for, mm/s².
        max_mmps2: u32,
    },
    /// A threshold of the fault monitors is out of its range.
    Control {
        /// Which.
        field: ControlField,
        /// The value asked for (the field's unit).
        value: u32,
    },
}

/// A field of [`ControlConfig`], to name it in a [`ConfigError`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControlField {
    /// `warn_band_mdb`: above 0 and below the abort band.
    WarnBand,
    /// `abort_band_mdb`: at most 20 dB.
    AbortBand,
    /// `max_accel_mmps2`: above the largest acceleration target allowed.
    MaxAccel,
    /// `open_loop_ms`: 10..=10 000.
    OpenLoopMs,
    /// `open_loop_effort_q15`: above 0.
    OpenLoopEffort,
    /// `band_ms`: 10..=10 000.
    BandMs,
    /// `no_data_ms`: 10..=10 000.
    NoDataMs,
    /// `saturation_ms`: 10..=10 000.
    SaturationMs,
    /// `check_ms`: 10..=10 000.
    CheckMs,
    /// `check_effort_q15`: above 0, at most the amplitude limit.
    CheckEffort,
}

impl ControlField {
    /// The field's name in the configuration (as `chladni device config set` takes it).
    pub const fn name(self) -> &'static str {
        match self {
            ControlField::WarnBand => "warn_band_mdb",
            ControlField::AbortBand => "abort_band_mdb",
            ControlField::MaxAccel => "max_accel_mmps2",
            ControlField::OpenLoopMs => "open_loop_ms",
            ControlField::OpenLoopEffort => "open_loop_effort_q15",
            ControlField::BandMs => "band_ms",
            ControlField::NoDataMs => "no_data_ms",
            ControlField::SaturationMs => "saturation_ms",
            ControlField::CheckMs => "check_ms",
            ControlField::CheckEffort => "check_effort_q15",
        }
    }

    /// The rule the field must follow.
    pub const fn rule(self) -> &'static str {
        match self {
            ControlField::WarnBand => "above 0 and below abort_band_mdb",
            ControlField::AbortBand => "at most 20000 (20 dB)",
            ControlField::MaxAccel => "above the acceleration target limit max_accel_mmps2",
            ControlField::OpenLoopEffort => "above 0",
            ControlField::CheckEffort => "above 0 and at most the amplitude limit",
            _ => "10..=10000 ms",
        }
    }
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let hw = DeviceLimits::DEFAULT;
        match self {
            ConfigError::FrequencyRange { min_mhz, max_mhz } => write!(
                f,
                "frequency range {min_mhz}..{max_mhz} mHz must be non-empty and within {}..{} mHz",
                hw.min_freq_mhz, hw.max_freq_mhz
            ),
            ConfigError::Amplitude { max_q15 } => {
                write!(
                    f,
                    "amplitude limit {max_q15} (Q15) is above full scale {}",
                    hw.max_amplitude_q15
                )
            }
            ConfigError::Steps { max_steps } => {
                write!(f, "step limit {max_steps} must be 1..={}", hw.max_steps)
            }
            ConfigError::Length { max_ms } => {
                write!(f, "plan length limit {max_ms} ms must be 1..={} ms", hw.max_total_ms)
            }
            ConfigError::Accel { max_mmps2 } => write!(
                f,
                "acceleration limit {max_mmps2} mm/s² must be 1..={} mm/s²",
                hw.max_accel_mmps2
            ),
            ConfigError::Control { field, value } => {
                write!(f, "{} = {value} must be {}", field.name(), field.rule())
            }
        }
    }
}

/// Why an upload request was refused. The upload in progress (if any) is kept unless said.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UploadError {
    /// A chunk or commit arrived with no upload begun (or after it was committed).
    NotStarted,
    /// The slot is outside `0..PLAN_SLOTS`.
    BadSlot {
        /// The slot asked for.
        slot: u8,
    },
    /// No slot was named and every slot below the scratch slot holds a plan.
    StoreFull,
    /// Another slot holds a plan of this name.
    NameTaken {
        /// That plan's slot.
        slot: u8,
    },
    /// The plan's header (step count, repeat) is refused by the device's limits; the upload
    /// was not begun.
    Plan(PlanError),
    /// A chunk that was already received.
    Duplicate {
        /// Its index.
        index: u16,
    },
    /// A chunk ahead of the next expected one (chunks must come in order).
    OutOfOrder {
        /// The index expected.
        expected: u16,
        /// The index received.
        got: u16,
    },
    /// A chunk with more steps than the upload has room for, or a short chunk before the last.
    BadChunkLength {
        /// Its index.
        index: u16,
        /// Steps in it.
        steps: u16,
        /// Steps it must hold.
        expected: u16,
    },
    /// Commit before every chunk arrived.
    Missing {
        /// Steps received.
        received: u16,
        /// Steps announced.
        expected: u16,
    },
    /// The steps received do not have the CRC announced in [`UploadBegin`]; nothing was stored.
    CrcMismatch {
        /// Announced.
        expected: u32,
        /// Computed over what arrived.
        got: u32,
    },
    /// The plan's name is empty or blank (plans are run and deleted by name).
    EmptyName,
}

impl core::fmt::Display for UploadError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            UploadError::NotStarted => write!(f, "no upload in progress (begin one first)"),
            UploadError::BadSlot { slot } => {
                write!(f, "slot {slot} does not exist (slots are 0..{})", PLAN_SLOTS - 1)
            }
            UploadError::StoreFull => {
                write!(f, "every slot holds a plan: delete one or name a slot to replace")
            }
            UploadError::NameTaken { slot } => {
                write!(f, "slot {slot} already holds a plan of this name")
            }
            UploadError::Plan(e) => write!(f, "{e}"),
            UploadError::Duplicate { index } => write!(f, "chunk {index} was already received"),
            UploadError::OutOfOrder { expected, got } => {
                write!(f, "chunk {got} out of order (expected chunk {expected})")
            }
            UploadError::BadChunkLength { index, steps, expected } => {
                write!(f, "chunk {index} holds {steps} step(s), expected {expected}")
            }
            UploadError::Missing { received, expected } => {
                write!(f, "commit after {received} of {expected} step(s): chunks are missing")
            }
            UploadError::CrcMismatch { expected, got } => write!(
                f,
                "plan CRC {got:08x} of the steps received differs from the announced {expected:08x}"
            ),
            UploadError::EmptyName => write!(f, "the plan has no name (give it one: --name)"),
        }
    }
}

/// Why the store could not do what was asked.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// No plan in that slot or of that name.
    NotFound(PlanRef),
    /// The flash has no room left for this plan: delete plans first.
    Full,
    /// A stored plan does not read back whole (its CRC or a chunk is wrong); it is not run.
    Corrupt {
        /// The slot.
        slot: u8,
    },
    /// The flash itself failed (or is absent: QEMU started without a flash file).
    Flash,
    /// A program or erase read back different from what it should have left: the flash did
    /// not take the data (a worn or failing part, or a programming error the driver did not
    /// report). What was asked is not stored.
    Verify {
        /// Offset in the store's area of the first byte that differs.
        offset: u32,
    },
    /// The store's area holds data this firmware's store did not write (another program's,
    /// the factory demo's, an older layout): nothing is stored or read until an explicit
    /// `FormatStore` erases it.
    Foreign,
}

/// What the plan store's flash area holds (the answer to `GetStore` and `FormatStore`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreState {
    /// The store's own format (its marker is there): plans can be stored.
    Ready,
    /// Data the store did not write; see [`StoreError::Foreign`].
    Foreign,
    /// No flash (an emulator without a flash file), or it could not be read.
    Unavailable,
}

/// The plan store's state and layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StoreInfo {
    /// What the area holds.
    pub state: StoreState,
    /// The store layout this firmware writes (its format marker's version).
    pub layout: u16,
    /// Bytes of flash the store's area spans (0 without flash).
    pub area_bytes: u32,
}

impl core::fmt::Display for StoreError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            StoreError::NotFound(PlanRef::Slot(slot)) => write!(f, "no plan in slot {slot}"),
            StoreError::NotFound(PlanRef::Name(name)) => write!(f, "no plan named '{name}'"),
            StoreError::Full => write!(f, "the plan store is full: delete plans first"),
            StoreError::Corrupt { slot } => {
                write!(f, "the plan in slot {slot} does not read back whole (CRC mismatch)")
            }
            StoreError::Flash => write!(
                f,
                "the controller's flash failed or is absent (an emulator keeps plans only with --flash-file)"
            ),
            StoreError::Verify { offset } => write!(
                f,
                "the controller's flash did not take a write (read back different at offset {offset:#x} of the plan store): nothing was stored"
            ),
            StoreError::Foreign => write!(
                f,
                "the controller's plan store holds data it did not write: `chladni device store --format` erases it"
            ),
        }
    }
}

/// CRC of a plan: CRC-32/ISO-HDLC of its postcard encoding (name, repeat, steps).
pub fn plan_crc(plan: &Plan) -> u32 {
    let mut digest = PlanDigest::new(&plan.name, plan.repeat, plan.steps.len() as u16);
    plan.steps.iter().for_each(|s| digest.step(s));
    digest.finish()
}

/// [`plan_crc`] computed step by step, as the chunks of an upload arrive.
pub struct PlanDigest {
    digest: crc::Digest<'static, u32>,
}

impl PlanDigest {
    /// Starts with the plan's header (its name, repeat, and the length of its step list).
    pub fn new(name: &str, repeat: u16, steps: u16) -> Self {
        let mut digest = CRC32.digest();
        let mut buf = [0u8; MAX_NAME + 16];
        // The same bytes postcard writes for the first fields of a `Plan`.
        if let Ok(head) = postcard::to_slice(&(name, repeat, steps as usize), &mut buf) {
            digest.update(head);
        }
        Self { digest }
    }

    /// Adds the next step.
    pub fn step(&mut self, step: &Step) {
        let mut buf = [0u8; 24];
        if let Ok(bytes) = postcard::to_slice(step, &mut buf) {
            self.digest.update(bytes);
        }
    }

    /// Adds steps given as their postcard bytes (as a store keeps them), without encoding
    /// them again.
    pub fn step_bytes(&mut self, bytes: &[u8]) {
        self.digest.update(bytes);
    }

    /// The CRC.
    pub fn finish(self) -> u32 {
        self.digest.finalize()
    }
}

impl DeviceLimits {
    /// Checks a plan's header (repeat, step count) before its steps arrive.
    pub fn check_plan_header(&self, repeat: u16, steps: u16) -> Result<(), PlanError> {
        if steps == 0 {
            return Err(PlanError::Empty);
        }
        if steps > self.max_steps {
            return Err(PlanError::TooManySteps { count: steps, max: self.max_steps });
        }
        if repeat == 0 {
            return Err(PlanError::ZeroRepeat);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn plan(steps: usize) -> Plan {
        let step = |i: usize| Step {
            freq_mhz: 100_000 + i as u32 * 1_001,
            level: crate::icd::plan::Level::Drive((i * 97 % 32768) as u16),
            duration_ms: 10 + i as u32,
            ramp_ms: i as u32 % 11,
        };
        Plan {
            name: "crc-check".try_into().unwrap(),
            repeat: 3,
            steps: (0..steps).map(step).collect(),
        }
    }

    #[test]
    fn plan_crc_is_the_crc_of_the_postcard_bytes() {
        for n in [0, 1, 31, 32, 33, 200, MAX_STEPS] {
            let p = plan(n);
            let bytes = postcard::to_allocvec(&p).unwrap();
            assert_eq!(plan_crc(&p), CRC32.checksum(&bytes), "{n} steps");
        }
    }

    #[test]
    fn chunks_fit_a_frame() {
        use crate::icd::frame::{ENCODE_BUF, Envelope, PROTOCOL_VERSION, encode};
        let worst = Step {
            freq_mhz: u32::MAX,
            level: crate::icd::plan::Level::Drive(u16::MAX),
            duration_ms: u32::MAX,
            ramp_ms: u32::MAX,
        };
        let chunk = UploadChunk {
            index: u16::MAX,
            steps: heapless::Vec::from_slice(&[worst; CHUNK_STEPS]).unwrap(),
        };
        let env = Envelope {
            version: PROTOCOL_VERSION,
            session: u32::MAX,
            id: u32::MAX,
            body: crate::icd::link::Request::UploadChunk(chunk),
        };
        let mut buf = [0u8; ENCODE_BUF];
        assert!(encode(&env, &mut buf).is_ok());
    }

    #[test]
    fn config_outside_the_hardware_is_named() {
        let mut c = DeviceConfig::DEFAULT;
        assert_eq!(c.validate(), Ok(()));
        c.limits.max_freq_mhz = 2_500_000;
        assert!(matches!(
            c.validate(),
            Err(ConfigError::FrequencyRange { max_mhz: 2_500_000, .. })
        ));
        c.limits.max_freq_mhz = 500_000;
        c.limits.min_freq_mhz = 500_000;
        assert!(c.validate().is_err());
        c.limits.min_freq_mhz = 10_000;
        c.limits.max_steps = 0;
        assert_eq!(c.validate(), Err(ConfigError::Steps { max_steps: 0 }));
    }
}
