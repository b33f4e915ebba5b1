//! Pins the wire encoding of every message to [`PROTOCOL_VERSION`].
//!
//! Each message type (every request, every response, every refusal and link error, and the
//! plan whose encoding the plan CRC covers) has one fixed canonical value here, with a distinct
//! multi-byte value in every field, so that reordering, adding, removing or retyping a field
//! (to a fixed-width type), or inserting a variant before another, changes its postcard bytes.
//! The CRC-32 of those bytes is its digest; `wire_pins.txt` holds the digests together with
//! the protocol version they belong to. The test fails when a digest changed while the version
//! did not (bump [`PROTOCOL_VERSION`]), and when the version changed while the pins did not
//! (regenerate them). Regenerating is one command, which refuses to change a pin without a bump:
//!
//! ```text
//! CHLADNI_UPDATE_PINS=1 cargo test -p chladni-shared --lib wire_pins
//! ```
//!
//! (postcard writes integers as varints, so widening `u16` to `u32` without changing a value
//! keeps the bytes; such a change is compatible for the values the old type held, and is not
//! caught here.)

extern crate std;

use std::collections::BTreeMap;
use std::format;
use std::string::String;
use std::vec::Vec;

use serde::Serialize;

use crate::icd::frame::{CRC32, LinkError, PROTOCOL_VERSION};
use crate::icd::link::*;
use crate::icd::plan::{DeviceLimits, Level, Plan, PlanError, SetpointError, Step};
use crate::icd::sense::{ControlConfig, Fault, FaultCause, Measurement, ResetCause, SensorFault};
use crate::icd::store::{
    ConfigError, ControlField, DeviceConfig, PlanPage, PlanRef, PlanSummary, StoreError, StoreInfo,
    StoreState, UploadBegin, UploadChunk, UploadError,
};

/// The pinned digests, as `version N` then one `label digest` line per message.
const PINS: &str = include_str!("wire_pins.txt");
/// Where [`PINS`] lives, for the regenerating run.
const PINS_PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/src/icd/wire_pins.txt");
const REGENERATE: &str = "CHLADNI_UPDATE_PINS=1 cargo test -p chladni-shared --lib wire_pins";

fn s<const N: usize>(text: &str) -> heapless::String<N> {
    heapless::String::try_from(text).expect("canonical text fits")
}

fn step() -> Step {
    Step { freq_mhz: 123_456, level: Level::Accel(234_567), duration_ms: 3_456, ramp_ms: 456 }
}

fn status() -> StatusReport {
    StatusReport {
        state: DriveState::RampDown,
        step: Some(1_001),
        repetition: 1_002,
        run: RunNumber(1_003),
        plan: Some(s("plan")),
        remaining_samples: 1_000_004,
        fault: Some(Fault {
            cause: FaultCause::Sensor(SensorFault::WrongId(0x6a)),
            value: -1_005,
            at_sample: 1_000_006,
        }),
        level: Some(Level::Drive(1_007)),
        measured: Some(Measurement { accel_mmps2: 1_008, phase_mdeg: -1_009 }),
        warning: true,
        reset_cause: ResetCause::Watchdog,
        clock: 1_000_010,
        elapsed_samples: 1_000_011,
        sample_rate: 48_000,
        freq_mhz: 1_000_012,
        amplitude_q15: 1_013,
        underruns: 1_014,
        commands: 1_015,
        least_slack_us: Some(1_016),
        stack_high_water: 1_017,
    }
}

fn info() -> DeviceInfo {
    DeviceInfo {
        firmware_version: s("1.2.3"),
        board: Board::Stm32l475,
        protocol_version: 0x0102,
        build_id: 0x0a0b_0c0d,
    }
}

fn summary() -> PlanSummary {
    PlanSummary {
        slot: 7,
        name: s("summary"),
        steps: 2_001,
        repeat: 2_002,
        total_ms: 2_000_003,
        crc: 0x1122_3344,
        bytes: 2_004,
    }
}

fn config() -> DeviceConfig {
    DeviceConfig {
        limits: DeviceLimits {
            min_freq_mhz: 3_001,
            max_freq_mhz: 3_002,
            max_amplitude_q15: 3_003,
            max_accel_mmps2: 3_004,
            max_steps: 3_005,
            max_total_ms: 3_006,
        },
        control: ControlConfig {
            open_loop_mmps2: 4_001,
            open_loop_effort_q15: 4_002,
            open_loop_ms: 4_003,
            warn_band_mdb: 4_004,
            abort_band_mdb: 4_005,
            band_ms: 4_006,
            max_accel_mmps2: 4_007,
            no_data_ms: 4_008,
            saturation_ms: 4_009,
            check_effort_q15: 4_010,
            check_ms: 4_011,
            check_min_mmps2: 4_012,
        },
    }
}

/// One canonical value of every request.
fn requests() -> Vec<Request> {
    std::vec![
        Request::Hello(Hello { client: s("client") }),
        Request::Ping(Ping { nonce: 0x0102_0304 }),
        Request::GetInfo(GetInfo),
        Request::Release(Release),
        Request::Drive(Drive { freq_mhz: 5_001, level: Level::Accel(5_002) }),
        Request::RunPlan(RunPlan { plan: PlanRef::Name(s("run")), repeat: Some(5_003) }),
        Request::Stop(Stop),
        Request::Status(GetStatus),
        Request::UploadBegin(UploadBegin {
            slot: Some(9),
            name: s("begin"),
            repeat: 5_004,
            steps: 5_005,
            crc: 0x5566_7788,
        }),
        Request::UploadChunk(UploadChunk {
            index: 5_006,
            steps: [step(), step()].into_iter().collect(),
        }),
        Request::UploadCommit(UploadCommit),
        Request::ListPlans(ListPlans { from_slot: 11 }),
        Request::DeletePlan(DeletePlan { plan: PlanRef::Slot(12) }),
        Request::Subscribe(Subscribe { rate_hz: 5_007, count: 5_008 }),
        Request::GetConfig(GetConfig),
        Request::SetConfig(SetConfig(config())),
        Request::ClearFault(ClearFault),
        Request::Sweep(Sweep {
            from_mhz: 5_009,
            to_mhz: 5_010,
            points: 5_011,
            amplitude_q15: 5_012,
            dwell_ms: 5_013,
        }),
        Request::GetSweep(GetSweep { from: 5_014 }),
        Request::InjectFault(InjectFault(TestFault::SensorWrongId)),
        Request::GetStore(GetStore),
        Request::FormatStore(FormatStore),
    ]
}

/// One canonical value of every answer, and the telemetry sample.
fn answers() -> Vec<Response> {
    std::vec![
        Response::Hello(info()),
        Response::Ping(0x0506_0708),
        Response::GetInfo(info()),
        Response::Release(()),
        Response::Drive(RunNumber(6_001)),
        Response::RunPlan(RunNumber(6_002)),
        Response::Stop(RunNumber(6_003)),
        Response::Status(status()),
        Response::UploadBegin(13),
        Response::UploadChunk(6_004),
        Response::UploadCommit(summary()),
        Response::ListPlans(PlanPage {
            plans: [summary(), summary()].into_iter().collect(),
            next: Some(14),
            free_bytes: 6_005,
        }),
        Response::DeletePlan(summary()),
        Response::Subscribe(()),
        Response::GetConfig(config()),
        Response::SetConfig(config()),
        Response::ClearFault(RunNumber(6_006)),
        Response::Sweep(RunNumber(6_007)),
        Response::GetSweep(SweepPage {
            run: RunNumber(6_008),
            total: 6_009,
            done: 6_010,
            points: [
                SweepPoint { freq_mhz: 6_011, measured: None },
                SweepPoint {
                    freq_mhz: 6_012,
                    measured: Some(Measurement { accel_mmps2: 6_013, phase_mdeg: 6_014 }),
                },
            ]
            .into_iter()
            .collect(),
        }),
        Response::InjectFault(()),
        Response::GetStore(StoreInfo {
            state: StoreState::Foreign,
            layout: 6_017,
            area_bytes: 1_006_018,
        }),
        Response::FormatStore(StoreInfo {
            state: StoreState::Unavailable,
            layout: 6_019,
            area_bytes: 1_006_020,
        }),
        Response::Telemetry(Telemetry { seq: 6_015, left: 6_016, status: status() }),
    ]
}

/// Every link error and every refusal (each in its response), with a sample of the errors
/// they carry.
fn failures() -> Vec<Response> {
    let errors = [
        LinkError::BadCobs,
        LinkError::FrameTooLong { max: 7_001 },
        LinkError::UnsupportedVersion { got: 7_002, supported: 7_003 },
        LinkError::BadCrc,
        LinkError::Malformed,
    ];
    let plan = PlanError::RampLongerThanStep { step: 7_004, ramp_ms: 7_005, duration_ms: 7_006 };
    let refusals = [
        Refusal::Busy { owner: s("owner"), idle_ms: 7_007 },
        Refusal::Drive(DriveError::Plan(plan)),
        Refusal::Drive(DriveError::Setpoint(SetpointError::AccelTooHigh {
            accel_mmps2: 7_008,
            max_mmps2: 7_009,
        })),
        Refusal::Drive(DriveError::Faulted),
        Refusal::Drive(DriveError::QueueFull),
        Refusal::Upload(UploadError::BadChunkLength {
            index: 7_010,
            steps: 7_011,
            expected: 7_012,
        }),
        Refusal::Upload(UploadError::Plan(PlanError::TooLong { total_ms: 7_013, max_ms: 7_014 })),
        Refusal::Upload(UploadError::EmptyName),
        Refusal::Store(StoreError::NotFound(PlanRef::Name(s("gone")))),
        Refusal::Store(StoreError::Corrupt { slot: 15 }),
        Refusal::Store(StoreError::Flash),
        Refusal::Store(StoreError::Verify { offset: 1_007_019 }),
        Refusal::Store(StoreError::Foreign),
        Refusal::Config(ConfigError::Control { field: ControlField::CheckMs, value: 7_015 }),
        Refusal::TelemetryRate { rate_hz: 7_016 },
        Refusal::Sweep(SweepError::Range { from_mhz: 7_017, to_mhz: 7_018 }),
        Refusal::Unsupported,
    ];
    errors
        .into_iter()
        .map(Response::Error)
        .chain(refusals.into_iter().map(Response::Refused))
        .collect()
}

/// A label and the digest of one value's postcard bytes.
fn digest<T: Serialize + core::fmt::Debug>(label: String, value: &T) -> (String, u32) {
    let bytes = postcard::to_stdvec(value).expect("canonical values serialise");
    (label, CRC32.checksum(&bytes))
}

/// The digest of every canonical value, by label (`Request::Ping`, `Refused#3`, ...).
fn digests() -> BTreeMap<String, u32> {
    let mut all: Vec<(String, u32)> = Vec::new();
    for r in requests() {
        all.push(digest(format!("Request::{}", r.name()), &r));
    }
    let names = Request::NAMES.iter().chain(&["Telemetry"]);
    for (name, r) in names.zip(answers()) {
        all.push(digest(format!("Response::{name}"), &r));
    }
    for r in failures() {
        all.push(digest(format!("Response::{}", variant_path(&r)), &r));
    }
    let plan = Plan { name: s("plan-crc"), repeat: 8_001, steps: [step()].into_iter().collect() };
    all.push(digest(String::from("Plan (plan_crc)"), &plan));
    all.into_iter().collect()
}

/// A failure's variants, outermost first, from its `Debug` form: `Refused(Store(Corrupt))`.
fn variant_path(response: &Response) -> String {
    let debug = format!("{response:?}");
    let end = debug.find([' ', '{', ',', '"', ')']).unwrap_or(debug.len());
    let path = debug[..end].trim_end_matches('(');
    let close = ")".repeat(path.matches('(').count());
    format!("{path}{close}")
}

/// `(version, digests)` read from [`PINS`].
fn pinned() -> (u16, BTreeMap<String, u32>) {
    let mut lines = PINS.lines().filter(|l| !l.trim().is_empty() && !l.starts_with('#'));
    let version = lines
        .next()
        .and_then(|l| l.strip_prefix("version "))
        .and_then(|v| v.trim().parse().ok())
        .expect("wire_pins.txt starts with `version N`");
    let pins = lines
        .map(|l| {
            let (label, digest) = l.rsplit_once(' ').expect("`label digest` lines");
            let digest = u32::from_str_radix(digest.trim_start_matches("0x"), 16).expect("hex");
            (String::from(label), digest)
        })
        .collect();
    (version, pins)
}

fn render(digests: &BTreeMap<String, u32>) -> String {
    let mut out = String::from(
        "# Digests of the canonical encoding of every message (shared/src/icd/wire_pins.rs).\n\
         # Generated: CHLADNI_UPDATE_PINS=1 cargo test -p chladni-shared --lib wire_pins\n",
    );
    out += &format!("version {PROTOCOL_VERSION}\n");
    for (label, digest) in digests {
        out += &format!("{label} {digest:#010x}\n");
    }
    out
}

#[test]
fn wire_pins() {
    let now = digests();
    let (version, pins) = pinned();
    let changed: Vec<&String> =
        pins.iter().filter(|(l, d)| now.get(*l) != Some(d)).map(|(l, _)| l).collect();
    let update = std::env::var_os("CHLADNI_UPDATE_PINS").is_some();
    if version == PROTOCOL_VERSION && !changed.is_empty() {
        panic!(
            "the wire encoding of {changed:?} changed, but PROTOCOL_VERSION is still {version}: \
             bump PROTOCOL_VERSION (shared/src/icd/frame.rs; and docs/protocol.md), then \
             regenerate the pins: {REGENERATE}"
        );
    }
    if update {
        std::fs::write(PINS_PATH, render(&now)).expect("write wire_pins.txt");
        return;
    }
    assert_eq!(
        version, PROTOCOL_VERSION,
        "PROTOCOL_VERSION is {PROTOCOL_VERSION} but the wire pins are for version {version}: \
         regenerate them: {REGENERATE}"
    );
    let unpinned: Vec<&String> = now.keys().filter(|l| !pins.contains_key(*l)).collect();
    assert!(unpinned.is_empty(), "{unpinned:?} have no pin: regenerate the pins: {REGENERATE}");
}

/// The canonical values cover every request and every response variant of the table.
#[test]
fn canonical_values_cover_the_table() {
    let names: Vec<&str> = requests().iter().map(|r| r.name()).collect();
    assert_eq!(names, Request::NAMES, "one canonical request per endpoint, in table order");
    for (request, answer) in requests().iter().zip(answers()) {
        assert!(request.is_answered_by(&answer), "{} has no canonical answer", request.name());
    }
    let failures = failures();
    assert!(failures.iter().any(|r| matches!(r, Response::Error(_))));
    assert!(failures.iter().any(|r| matches!(r, Response::Refused(_))));
    assert!(matches!(answers().last(), Some(Response::Telemetry(_))));
}
