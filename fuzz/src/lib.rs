//! Helpers shared by the fuzz targets (`fuzz_targets/`) and the seed writer (`examples/seeds.rs`):
//! valid messages to start from, frames built around arbitrary message bytes, a byte-driven
//! mutator, and a reader of structured choices from the fuzzer's input.
//!
//! `arbitrary` is not derived on the shared types (the no_std crate stays free of fuzzing
//! dependencies): structured inputs are valid messages encoded here, then mutated.
#![forbid(unsafe_code)]

/// The NOR flash model the store's own tests use (`chladni-firmware`'s `mock-flash` feature):
/// the L4's programming rule, power cuts per word for the fuzzer.
pub mod flash {
    pub use chladni_firmware::app::store::mock_flash::{
        Cuts, MockFlash, MockFlashError, PAGE_SIZE, Rule, SharedFlash, WORD_SIZE,
    };

    /// A flash of `pages` erased pages with the L4's rule, cut per word programmed or page
    /// erased.
    pub fn fuzz_flash(pages: usize) -> MockFlash {
        MockFlash::with(pages, Rule::Stm32l4, Cuts::PerWord)
    }
}

use chladni_shared::icd::frame::{CRC32, ENCODE_BUF, Envelope, PROTOCOL_VERSION, encode};
use chladni_shared::icd::link::{
    Board, ClearFault, DeletePlan, DeviceInfo, Drive, DriveError, DriveState, Fault, FaultCause,
    GetConfig, GetInfo, GetStatus, GetSweep, Hello, InjectFault, ListPlans, Measurement, Ping,
    Refusal, Release, Request, Response, RunNumber, RunPlan, SetConfig, StatusReport, Stop,
    Subscribe, Sweep, SweepError, SweepPage, SweepPoint, Telemetry, TestFault, UploadCommit,
};
use chladni_shared::icd::plan::{DeviceLimits, Level, Plan, PlanError, Step};
use chladni_shared::icd::store::{
    CHUNK_STEPS, DeviceConfig, PlanPage, PlanRef, PlanSummary, StoreError, UploadBegin,
    UploadChunk, UploadError,
};
use serde::Serialize;
use std::sync::LazyLock;

/// [`sample_requests`], built once per process: `request_handler` picks from it at every
/// step (building the list for each execution was an eighth of its time).
pub static SAMPLE_REQUESTS: LazyLock<Vec<Request>> = LazyLock::new(sample_requests);

/// Drops what the firmware logged. On the host, defmt (feature `unstable-test`, as in the
/// firmware's own host tests) appends every log frame to a thread-local buffer that only this
/// empties: without it a long run grows by every log line (about 400 bytes an execution for
/// `request_handler`) until libFuzzer stops it for memory. `scripts/fuzz.sh` builds with
/// `DEFMT_LOG=off`, so there it is empty; a build with logging on still runs in bounded memory.
pub fn discard_logs() {
    drop(defmt::export::fetch_bytes());
}

/// The bytes sent for `envelope`: `0x00 · COBS(postcard · CRC) · 0x00`.
///
/// Panics if it does not encode: only for messages known to fit a frame.
pub fn wire<T: Serialize>(envelope: &Envelope<T>) -> Vec<u8> {
    let mut buf = [0u8; ENCODE_BUF];
    encode(envelope, &mut buf).expect("a sample message fits a frame").to_vec()
}

/// The postcard bytes of `envelope` (what the CRC covers).
pub fn message<T: Serialize>(envelope: &Envelope<T>) -> Vec<u8> {
    postcard::to_allocvec(envelope).expect("a sample message serialises")
}

/// A frame on the wire around arbitrary message bytes: their CRC is appended, then COBS and
/// the delimiters, as a correct sender would. Lets the fuzzer reach the deserialiser past the CRC.
pub fn frame_around(message: &[u8]) -> Vec<u8> {
    let mut raw = Vec::with_capacity(message.len() + 4);
    raw.extend_from_slice(message);
    raw.extend_from_slice(&CRC32.checksum(message).to_le_bytes());
    let mut out = vec![0u8; cobs::max_encoding_length(raw.len()) + 2];
    let used = cobs::encode(&raw, &mut out[1..]);
    out.truncate(used + 2);
    out[used + 1] = 0;
    out
}

/// An envelope of this protocol version.
pub fn envelope<T>(session: u32, id: u32, body: T) -> Envelope<T> {
    Envelope { version: PROTOCOL_VERSION, session, id, body }
}

fn name<const N: usize>(s: &str) -> heapless::String<N> {
    heapless::String::try_from(s).expect("sample name fits")
}

fn step(i: u32) -> Step {
    Step {
        freq_mhz: 100_000 + i * 1_001,
        level: Level::Drive((i * 97 % 32_768) as u16),
        duration_ms: 10 + i,
        ramp_ms: i % 11,
    }
}

/// The plan the sample upload carries: 40 valid steps (two chunks, the second short).
pub fn sample_plan() -> Plan {
    Plan { name: name("square-45"), repeat: 1, steps: (0..40).map(step).collect() }
}

/// The chunks of an upload of `plan`.
pub fn chunks_of(plan: &Plan) -> Vec<UploadChunk> {
    plan.steps
        .chunks(CHUNK_STEPS)
        .enumerate()
        .map(|(i, steps)| UploadChunk { index: i as u16, steps: steps.iter().copied().collect() })
        .collect()
}

/// The `UploadBegin` of `plan` into `slot`, with its CRC.
pub fn begin_of(plan: &Plan, slot: Option<u8>) -> UploadBegin {
    UploadBegin::of(plan, slot)
}

/// One valid request of every kind (some twice, with other field shapes). The uploads are
/// consistent: `UploadBegin` (slot 4) then the two `UploadChunk`s then `UploadCommit` stores
/// [`sample_plan`]; the second `UploadBegin` and the one-step chunk store a plan "x".
pub fn sample_requests() -> Vec<Request> {
    let plan = sample_plan();
    let small = Plan { name: name("x"), repeat: 3, steps: [step(0)].into_iter().collect() };
    let mut requests = vec![
        Request::Hello(Hello { client: name("chladni device run (pid 4242)") }),
        Request::Ping(Ping { nonce: 0xdead_beef }),
        Request::GetInfo(GetInfo),
        Request::Release(Release),
        Request::Drive(Drive { freq_mhz: 123_000, level: Level::Drive(16_384) }),
        Request::RunPlan(RunPlan { plan: PlanRef::Slot(4), repeat: None }),
        Request::RunPlan(RunPlan { plan: PlanRef::Name(name("square-45")), repeat: Some(2) }),
        Request::Stop(Stop),
        Request::Status(GetStatus),
        Request::UploadBegin(begin_of(&plan, Some(4))),
        Request::UploadBegin(begin_of(&small, None)),
    ];
    requests.extend(chunks_of(&plan).into_iter().map(Request::UploadChunk));
    requests.extend(chunks_of(&small).into_iter().map(Request::UploadChunk));
    requests.extend([
        Request::UploadCommit(UploadCommit),
        Request::ListPlans(ListPlans { from_slot: 0 }),
        Request::DeletePlan(DeletePlan { plan: PlanRef::Name(name("x")) }),
        Request::DeletePlan(DeletePlan { plan: PlanRef::Slot(4) }),
        Request::Subscribe(Subscribe { rate_hz: 10, count: 100 }),
        Request::GetConfig(GetConfig),
        Request::SetConfig(SetConfig(DeviceConfig::DEFAULT)),
        Request::ClearFault(ClearFault),
        Request::Sweep(Sweep {
            from_mhz: 100_000,
            to_mhz: 300_000,
            points: 41,
            amplitude_q15: 3_000,
            dwell_ms: 120,
        }),
        Request::GetSweep(GetSweep { from: 0 }),
        Request::InjectFault(InjectFault(TestFault::Heal)),
    ]);
    requests
}

fn status() -> StatusReport {
    StatusReport {
        state: DriveState::Running,
        step: Some(3),
        repetition: 1,
        run: RunNumber(17),
        plan: Some(name("square-45")),
        remaining_samples: 48_000,
        elapsed_samples: 96_000,
        sample_rate: 48_000,
        freq_mhz: 120_000,
        amplitude_q15: 16_000,
        level: Some(Level::Accel(20_000)),
        measured: Some(Measurement { accel_mmps2: 19_987, phase_mdeg: -12_345 }),
        clock: 1_000_000,
        commands: 5,
        least_slack_us: Some(1_234),
        stack_high_water: 12_000,
        ..StatusReport::IDLE
    }
}

fn summary(slot: u8) -> PlanSummary {
    PlanSummary {
        slot,
        name: name("square-45"),
        steps: 40,
        repeat: 2,
        total_ms: 12_345,
        crc: 0xcafe_f00d,
        bytes: 1_024,
    }
}

/// One valid response of every kind (answers, refusals, telemetry).
pub fn sample_responses() -> Vec<Response> {
    let info = DeviceInfo {
        firmware_version: name("0.1.0"),
        board: Board::Qemu,
        protocol_version: PROTOCOL_VERSION,
        build_id: 0x1234_5678,
    };
    let mut faulted = status();
    faulted.state = DriveState::Faulted;
    faulted.fault = Some(Fault { cause: FaultCause::LoopOpen, value: 12, at_sample: 990_000 });
    faulted.plan = None;
    faulted.step = None;
    vec![
        Response::Hello(info.clone()),
        Response::Ping(0xdead_beef),
        Response::GetInfo(info),
        Response::Release(()),
        Response::Drive(RunNumber(1)),
        Response::RunPlan(RunNumber(2)),
        Response::Stop(RunNumber(3)),
        Response::Status(status()),
        Response::Status(faulted),
        Response::UploadBegin(4),
        Response::UploadChunk(32),
        Response::UploadCommit(summary(4)),
        Response::ListPlans(PlanPage {
            plans: (0..3).map(summary).collect(),
            next: Some(3),
            free_bytes: 100_000,
        }),
        Response::DeletePlan(summary(1)),
        Response::Subscribe(()),
        Response::GetConfig(DeviceConfig::DEFAULT),
        Response::SetConfig(DeviceConfig {
            limits: DeviceLimits { max_steps: 100, ..DeviceLimits::DEFAULT },
            ..DeviceConfig::DEFAULT
        }),
        Response::ClearFault(RunNumber(4)),
        Response::Sweep(RunNumber(5)),
        Response::GetSweep(SweepPage {
            run: RunNumber(5),
            total: 41,
            done: 2,
            points: (0..2)
                .map(|i| SweepPoint {
                    freq_mhz: 100_000 + i * 2_000,
                    measured: Some(Measurement { accel_mmps2: 1_000 + i, phase_mdeg: 170_000 }),
                })
                .collect(),
        }),
        Response::InjectFault(()),
        Response::Error(chladni_shared::icd::frame::LinkError::BadCrc),
        Response::Refused(Refusal::Busy { owner: name("other"), idle_ms: 120 }),
        Response::Refused(Refusal::Drive(DriveError::Plan(PlanError::ZeroDuration { step: 2 }))),
        Response::Refused(Refusal::Upload(UploadError::OutOfOrder { expected: 1, got: 3 })),
        Response::Refused(Refusal::Store(StoreError::NotFound(PlanRef::Name(name("gone"))))),
        Response::Refused(Refusal::TelemetryRate { rate_hz: 500 }),
        Response::Refused(Refusal::Sweep(SweepError::Points { points: 1 })),
        Response::Refused(Refusal::Unsupported),
        Response::Telemetry(Telemetry { seq: 9, left: 90, status: status() }),
    ]
}

/// Reads structured choices from the fuzzer's bytes; past the end it yields zeros, so every
/// input is a complete program of choices.
#[derive(Debug, Clone)]
pub struct Choices<'a> {
    bytes: &'a [u8],
}

impl<'a> Choices<'a> {
    /// Choices from `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes }
    }

    /// Whether every byte was used.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// The next byte (0 past the end).
    pub fn u8(&mut self) -> u8 {
        match self.bytes.split_first() {
            Some((&b, rest)) => {
                self.bytes = rest;
                b
            }
            None => 0,
        }
    }

    /// The next two bytes, little-endian.
    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes([self.u8(), self.u8()])
    }

    /// The next four bytes, little-endian.
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }

    /// A number in `0..n` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        self.u16() as usize % n
    }

    /// The next `n` bytes (fewer at the end).
    pub fn take(&mut self, n: usize) -> &'a [u8] {
        let (head, rest) = self.bytes.split_at(n.min(self.bytes.len()));
        self.bytes = rest;
        head
    }

    /// The bytes not used yet.
    pub fn rest(self) -> &'a [u8] {
        self.bytes
    }
}

/// Mutates `bytes` by up to `count` edits read from `choices`: flip a bit, set a byte, insert
/// or delete a byte, truncate, duplicate a run. Indices wrap, so every choice is a valid edit.
pub fn mutate(bytes: &mut Vec<u8>, choices: &mut Choices<'_>, count: usize) {
    for _ in 0..count {
        if choices.is_empty() {
            return;
        }
        let op = choices.u8() % 6;
        let at = if bytes.is_empty() { 0 } else { choices.below(bytes.len()) };
        match op {
            0 if !bytes.is_empty() => bytes[at] ^= 1 << (choices.u8() % 8),
            1 if !bytes.is_empty() => bytes[at] = choices.u8(),
            2 => bytes.insert(at, choices.u8()),
            3 if !bytes.is_empty() => {
                bytes.remove(at);
            }
            4 => bytes.truncate(at),
            5 if !bytes.is_empty() => {
                let len = (choices.u8() as usize % 8 + 1).min(bytes.len() - at);
                let run = bytes[at..at + len].to_vec();
                bytes.splice(at..at, run);
            }
            _ => {}
        }
    }
}
