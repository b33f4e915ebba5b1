//! Deterministic test vectors, run on the host *and* on Cortex-M in QEMU.
//!
//! Each vector computes something with this crate and folds every output bit into a
//! [`Digest`]. The on-target test binary (`firmware/tests/on_target.rs`) prints
//! `vector <name> <digest>` for each, and the host test (`tests/on_target.rs`) checks that the
//! digests equal the ones computed here on x86-64: same code, same bits.
//!
//! A vector may also check invariants itself and return `Err` with a message; that fails on
//! both sides.

use crate::analysis::field::{Field, FieldKind};
use crate::analysis::fx::Fx;
use crate::analysis::geometry::Pt;
use crate::analysis::rest::{Analysis, Analyzer};
use crate::drive::plant::{Plant, PlantParams};
use crate::drive::runner::{BLOCK_LEN, Runner};
use crate::icd::link::DriveState;
use crate::icd::link::{self, Envelope, Request, Response};
use crate::icd::plan::{DeviceLimits, Level, Plan, Step};

/// FNV-1a, 64-bit: small, dependency-free, and plenty to tell two bit patterns apart.
#[derive(Debug, Clone, Copy)]
pub struct Digest(u64);

impl Default for Digest {
    fn default() -> Self {
        Self::new()
    }
}

impl Digest {
    /// The FNV-1a offset basis.
    pub const fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
    /// Folds bytes in.
    pub fn bytes(&mut self, bytes: &[u8]) -> &mut Self {
        for &b in bytes {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
        self
    }
    /// Folds an integer in (little-endian).
    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.bytes(&v.to_le_bytes())
    }
    /// Folds a signed integer in (little-endian).
    pub fn i64(&mut self, v: i64) -> &mut Self {
        self.bytes(&v.to_le_bytes())
    }
    /// The digest so far.
    pub const fn value(&self) -> u64 {
        self.0
    }
}

/// A named vector: returns the digest of its outputs, or a failed self-check.
pub type Vector = fn() -> Result<u64, &'static str>;

/// Every vector, in a fixed order. Add new ones at the end.
pub const ALL: &[(&str, Vector)] = &[
    ("link_frames", link_frames),
    ("drive_plan_stream", drive_plan_stream),
    ("drive_link_frames", drive_link_frames),
    ("plant_response", plant_response),
    ("rest_rectangle_sign", rest_rectangle_sign),
    ("rest_lshape_hole_linear_skewed", rest_lshape_hole_linear_skewed),
    ("rest_trapezoid_sine", rest_trapezoid_sine),
];

/// Encodes and decodes a fixed set of requests and responses; digests the wire bytes.
fn link_frames() -> Result<u64, &'static str> {
    let mut d = Digest::new();
    let mut buf = [0u8; 64];
    let requests = [
        Request::Ping(link::Ping { nonce: 0 }),
        Request::Ping(link::Ping { nonce: u32::MAX }),
        Request::GetInfo(link::GetInfo),
    ];
    for (i, body) in requests.into_iter().enumerate() {
        let env = Envelope {
            version: link::PROTOCOL_VERSION,
            session: 0x5eed_0000 + i as u32,
            id: i as u32 * 1000,
            body,
        };
        let wire = link::encode(&env, &mut buf).map_err(|_| "encode failed")?;
        d.bytes(wire);
        let mut frame = [0u8; 64];
        let n = wire.len() - 2;
        frame[..n].copy_from_slice(&wire[1..wire.len() - 1]);
        let back = link::decode::<Request>(&mut frame[..n]).map_err(|_| "decode failed")?;
        if back != env {
            return Err("request did not round-trip");
        }
    }
    let errors = [
        link::LinkError::BadCobs,
        link::LinkError::FrameTooLong { max: link::MAX_FRAME as u16 },
        link::LinkError::UnsupportedVersion { got: 7, supported: 1 },
        link::LinkError::BadCrc,
        link::LinkError::Malformed,
    ];
    for e in errors {
        let body = Response::Error(e);
        let env = Envelope { version: link::PROTOCOL_VERSION, session: 3, id: 1, body };
        d.bytes(link::encode(&env, &mut buf).map_err(|_| "encode failed")?);
    }
    Ok(d.value())
}

/// A three-step plan, run twice: every DAC code and the status after every block.
fn drive_plan_stream() -> Result<u64, &'static str> {
    let mut d = Digest::new();
    let mut runner = Runner::new(DeviceLimits::DEFAULT);
    runner.start_plan(vector_plan()).map_err(|_| "plan refused")?;
    let mut block = [0u16; BLOCK_LEN];
    let mut blocks = 0u32;
    while runner.state() != DriveState::Idle {
        runner.fill(&mut block);
        for &c in &block {
            d.u64(c as u64);
        }
        let s = runner.status();
        d.u64(s.step.map_or(u64::MAX, |s| s as u64))
            .u64(s.elapsed_samples)
            .u64(s.amplitude_q15 as u64);
        blocks += 1;
        if blocks > 10_000 {
            return Err("plan never ended");
        }
    }
    // 2 × 130 ms of steps + a 20 ms ramp to zero, at 50 samples/ms.
    if runner.status().elapsed_samples != 2 * 130 * 50 + 20 * 50 {
        return Err("plan ran for the wrong number of samples");
    }
    Ok(d.value())
}

/// The drive requests and responses on the wire.
fn drive_link_frames() -> Result<u64, &'static str> {
    let mut d = Digest::new();
    let mut buf = [0u8; link::ENCODE_BUF];
    let plan = vector_plan();
    let chunk = crate::icd::store::UploadChunk {
        index: 0,
        steps: heapless::Vec::from_slice(&plan.steps).map_err(|_| "chunk too small")?,
    };
    let begin = crate::icd::store::UploadBegin {
        slot: Some(3),
        name: plan.name.clone(),
        repeat: plan.repeat,
        steps: plan.steps.len() as u16,
        crc: crate::icd::store::plan_crc(&plan),
    };
    let requests = [
        Request::Drive(link::Drive { freq_mhz: 123_456, level: Level::Drive(20_000) }),
        Request::UploadBegin(begin),
        Request::UploadChunk(chunk),
        Request::UploadCommit(link::UploadCommit),
        Request::RunPlan(link::RunPlan { plan: crate::icd::store::PlanRef::Slot(3), repeat: None }),
        Request::Stop(link::Stop),
        Request::Status(link::GetStatus),
    ];
    for (i, body) in requests.into_iter().enumerate() {
        let env = Envelope { version: link::PROTOCOL_VERSION, session: 77, id: i as u32 + 1, body };
        d.bytes(link::encode(&env, &mut buf).map_err(|_| "encode failed")?);
    }
    let mut runner = Runner::<Plan>::new(DeviceLimits::DEFAULT);
    runner.drive(55_000, Level::Drive(1000)).map_err(|_| "drive refused")?;
    let responses = [
        Response::Status(runner.status()),
        Response::Drive(link::RunNumber(4)),
        Response::Refused(link::Refusal::Drive(link::DriveError::Plan(
            crate::icd::plan::PlanError::Empty,
        ))),
        Response::Refused(link::Refusal::Drive(link::DriveError::QueueFull)),
    ];
    for body in responses {
        let env = Envelope { version: link::PROTOCOL_VERSION, session: 77, id: 9, body };
        d.bytes(link::encode(&env, &mut buf).map_err(|_| "encode failed")?);
    }
    Ok(d.value())
}

/// The simulated plant's acceleration (f32 bits) under a 180 Hz drive.
fn plant_response() -> Result<u64, &'static str> {
    let mut d = Digest::new();
    let mut plant = Plant::new(PlantParams::DEFAULT);
    let mut dds = crate::drive::dds::Dds::new(crate::drive::dds::tuning_word(180_000));
    let mut block = [0u16; BLOCK_LEN];
    for _ in 0..40 {
        dds.fill_steady(&mut block, crate::drive::dds::gain_of_q15(16384));
        for &c in &block {
            d.u64(plant.step(c).to_bits() as u64);
        }
    }
    Ok(d.value())
}

fn vector_plan() -> Plan {
    let steps = [
        Step { freq_mhz: 100_000, level: Level::Drive(16384), duration_ms: 40, ramp_ms: 10 },
        Step { freq_mhz: 250_500, level: Level::Drive(26000), duration_ms: 60, ramp_ms: 5 },
        Step { freq_mhz: 1_234_567, level: Level::Drive(8000), duration_ms: 30, ramp_ms: 3 },
    ];
    let mut plan = Plan { name: heapless::String::new(), repeat: 2, steps: heapless::Vec::new() };
    let _ = plan.name.push_str("vector");
    for s in steps {
        let _ = plan.steps.push(s);
    }
    plan
}

/// Folds a whole analysis in: every rest (angle bits, kind), the flags, the order, and the
/// balance offset, turn value and alignment at a few fixed angles.
fn digest_analysis(d: &mut Digest, an: &Analyzer<'_>, a: &Analysis) {
    d.u64(a.rests.len() as u64).u64(a.neutral as u64).u64(a.order as u64);
    for r in &a.rests {
        d.u64(r.angle as u64).u64(r.stable as u64);
    }
    for theta in [0u32, 0x1234_5678, 0x8000_0000, 0xdead_beef] {
        let b = an.balance(theta, Fx::ZERO);
        d.i64(b.offset.raw()).i64(b.turn.raw()).u64(a.align(theta, b.turn.signum()) as u64);
    }
}

/// Rest angle nearest to `deg` degrees is within `tol_bam` binary-angle units of it.
fn has_rest(a: &Analysis, deg: u32, stable: bool, tol_bam: u32) -> bool {
    let target = ((deg as u64) << 32) / 360;
    a.rests.iter().any(|r| {
        let e = r.angle.wrapping_sub(target as u32);
        r.stable == stable && e.min(e.wrapping_neg()) <= tol_bam
    })
}

/// A 40 × 10 mm rectangle under the sign field: rests at 90°/270° (stable), 0°/180°.
fn rest_rectangle_sign() -> Result<u64, &'static str> {
    let r = [Pt::int(5, 5), Pt::int(45, 5), Pt::int(45, 15), Pt::int(5, 15)];
    let rings: [&[Pt]; 1] = [&r];
    let an = Analyzer::new(&rings, Field::symmetric(FieldKind::Sign)).map_err(|_| "prepare")?;
    let a = an.analyze().map_err(|_| "analyze")?;
    let tol = 50; // ≈ 4·10⁻⁶°
    if a.rests.len() != 4
        || !has_rest(&a, 90, true, tol)
        || !has_rest(&a, 270, true, tol)
        || !has_rest(&a, 0, false, tol)
        || !has_rest(&a, 180, false, tol)
    {
        return Err("rectangle rests are not 90/270 stable, 0/180 unstable");
    }
    let mut d = Digest::new();
    digest_analysis(&mut d, &an, &a);
    Ok(d.value())
}

/// An L-shape with a square hole under a linear field with gains 1 (left) and 2.5 (right).
fn rest_lshape_hole_linear_skewed() -> Result<u64, &'static str> {
    let outline = [
        Pt::int(0, 0),
        Pt::int(60, 0),
        Pt::int(60, 20),
        Pt::int(20, 20),
        Pt::int(20, 50),
        Pt::int(0, 50),
    ];
    let hole = [Pt::int(5, 5), Pt::int(5, 15), Pt::int(15, 15), Pt::int(15, 5)];
    let rings: [&[Pt]; 2] = [&outline, &hole];
    let field = Field { kind: FieldKind::Linear, gain_left: Fx::ONE, gain_right: Fx::ratio(5, 2) };
    let an = Analyzer::new(&rings, field).map_err(|_| "prepare")?;
    let a = an.analyze().map_err(|_| "analyze")?;
    if a.neutral || a.rests.len() < 2 || !a.rests.len().is_multiple_of(2) {
        return Err("L-shape: expected an even number of rests");
    }
    let mut d = Digest::new();
    digest_analysis(&mut d, &an, &a);
    Ok(d.value())
}

/// A trapezoid (fractional coordinates) under a sine field, w = 90 mm.
fn rest_trapezoid_sine() -> Result<u64, &'static str> {
    let p = |x: i64, y: i64| Pt::new(Fx::ratio(x, 8), Fx::ratio(y, 8));
    let r = [p(0, 0), p(320, 0), p(250, 130), p(41, 130)];
    let rings: [&[Pt]; 1] = [&r];
    let field = Field::symmetric(FieldKind::Sine { wavelength: Fx::from_int(90) });
    let an = Analyzer::new(&rings, field).map_err(|_| "prepare")?;
    let a = an.analyze().map_err(|_| "analyze")?;
    if a.neutral || a.order < 2 {
        return Err("trapezoid: expected a 180°-periodic rest pattern");
    }
    let mut d = Digest::new();
    digest_analysis(&mut d, &an, &a);
    Ok(d.value())
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn every_vector_passes_its_self_checks() {
        for (name, vector) in ALL {
            assert!(vector().is_ok(), "vector {name} failed: {:?}", vector());
        }
    }

    /// What the on-target comparison relies on: each vector gives the same digest every time it
    /// runs (no state carried between runs, nothing from the clock or a hash map's order), folds
    /// something in (not the empty digest), and differs from every other vector (two equal
    /// digests would mean one vector checks nothing of its own). `cargo test -p chladni-shared
    /// print_digests -- --nocapture` also prints the digests in the on-target format, to compare
    /// by eye with `scripts/firmware.sh test qemu`.
    #[test]
    fn print_digests() {
        let mut seen = std::collections::BTreeMap::new();
        for (name, vector) in ALL {
            let digest = vector().unwrap();
            std::println!("vector {name} {digest:016x}");
            assert_eq!(vector().unwrap(), digest, "vector {name} differs from one run to the next");
            assert_ne!(digest, Digest::new().value(), "vector {name} folds nothing in");
            if let Some(other) = seen.insert(digest, name) {
                panic!("vectors {other} and {name} have the same digest {digest:016x}");
            }
        }
        assert_eq!(seen.len(), ALL.len());
    }

    #[test]
    #[ignore = "prints timings; run with --ignored --nocapture"]
    fn vector_timings() {
        // The on-target runner is ~20× slower than the host; keep each vector small.
        for (name, vector) in ALL {
            let t = std::time::Instant::now();
            let digest = vector().unwrap();
            let ms = t.elapsed().as_secs_f64() * 1e3;
            std::println!("vector {name} {digest:016x} ({ms:.1} ms)");
        }
    }

    #[test]
    fn digest_is_fnv1a() {
        // Published FNV-1a 64 test value for "a".
        assert_eq!(Digest::new().bytes(b"a").value(), 0xaf63_dc4c_8601_ec8c);
    }
}
