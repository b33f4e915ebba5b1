//! The host ↔ controller wire protocol.
//!
//! A frame on the wire is `0x00 · COBS(postcard(Envelope)) · 0x00`: the COBS encoding leaves no
//! zero byte inside a frame, so `0x00` delimits frames and a receiver resynchronises after
//! garbage at the next zero. Senders put a zero *before* each frame too, which flushes whatever
//! partial garbage the receiver may hold; empty frames are ignored.
//!
//! Every [`Envelope`] carries the protocol version and a request id; the controller answers
//! each request with a response of the same id, or an [`Response::Error`] naming what was wrong
//! (id 0 when the frame was too broken to read an id from).

use serde::{Deserialize, Serialize};

pub use crate::icd::plan::{Plan, PlanError, SetpointError};

/// Version of this protocol; bumped on any incompatible change of [`Request`] or [`Response`].
pub const PROTOCOL_VERSION: u16 = 2;

/// Largest COBS-encoded frame (without delimiters) either side accepts, in bytes.
pub const MAX_FRAME: usize = 1024;

/// What every frame carries: protocol version, request id, and the message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Envelope<T> {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u16,
    /// Chosen by the host; echoed in the response. 0 is reserved for "unknown".
    pub id: u32,
    /// The request or response.
    pub body: T,
}

/// Requests from the host to the controller.
// No allocator on the controller: a plan travels inline (≈ 570 bytes); requests are decoded
// once per frame, so the size costs stack, not copies.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Request {
    /// Liveness check; answered by [`Response::Pong`] with the same nonce.
    Ping {
        /// Any value; echoed back.
        nonce: u32,
    },
    /// Asks for [`DeviceInfo`].
    GetInfo,
    /// Manual drive: a steady sine at `freq_mhz`, amplitude ramped to `amplitude_q15`.
    /// Answered by [`Response::Ack`] or [`Response::Rejected`].
    Drive {
        /// Frequency, millihertz.
        freq_mhz: u32,
        /// Amplitude, Q15 fraction of the DAC's full scale.
        amplitude_q15: u16,
    },
    /// Runs a plan sent inline. Answered by [`Response::Ack`] or [`Response::Rejected`].
    RunPlan(Plan),
    /// Ramps the drive to zero and idles (clears a fault). Answered by [`Response::Ack`].
    Stop,
    /// Asks for the drive's [`StatusReport`] ([`Response::Status`]).
    Status,
}

/// Responses from the controller to the host.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Response {
    /// Answer to [`Request::Ping`].
    Pong {
        /// The request's nonce.
        nonce: u32,
    },
    /// Answer to [`Request::GetInfo`].
    Info(DeviceInfo),
    /// The request could not be carried out.
    Error(LinkError),
    /// The drive's state (answer to [`Request::Status`]).
    Status(StatusReport),
    /// The command was accepted and queued for the drive.
    Ack,
    /// The drive refused the command (invalid plan or setpoint, faulted, busy).
    Rejected(DriveError),
}

// ---- The drive's status and refusals ----

/// What the drive is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriveState {
    /// No output (mid-scale).
    Idle,
    /// Amplitude rising towards the step's (or setpoint's) target.
    RampUp,
    /// Steady amplitude.
    Running,
    /// Amplitude falling towards a lower target within a plan or setpoint.
    RampDown,
    /// Ramping to zero after a stop request or the end of a plan; then idle.
    Stopping,
    /// Ramped to zero after a fault; stays silent until a stop request clears it.
    Faulted,
}

impl DriveState {
    /// Lowercase name as printed by the CLI (`stopping` is reported as `ramp_down`).
    pub const fn name(self) -> &'static str {
        match self {
            DriveState::Idle => "idle",
            DriveState::RampUp => "ramp_up",
            DriveState::Running => "running",
            DriveState::RampDown | DriveState::Stopping => "ramp_down",
            DriveState::Faulted => "faulted",
        }
    }
}

/// A snapshot of the drive, as answered to [`crate::icd::link::Request::Status`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StatusReport {
    /// What the drive is doing.
    pub state: DriveState,
    /// Index of the plan step being run; `None` outside a plan (idle, manual, final ramp).
    pub step: Option<u16>,
    /// Which repetition of the plan is running (0-based).
    pub run: u16,
    /// Samples output since the current plan or manual drive started (kept when idle).
    pub elapsed_samples: u64,
    /// Samples per second, to turn `elapsed_samples` into time.
    pub sample_rate: u32,
    /// Frequency being output, millihertz.
    pub freq_mhz: u32,
    /// Amplitude being output right now (ramps included), Q15.
    pub amplitude_q15: u16,
    /// Sample blocks the output needed before they were ready (missed refills).
    pub underruns: u32,
    /// Commands applied so far (start, drive, stop, fault).
    pub commands: u32,
}

impl StatusReport {
    /// `elapsed_samples` in milliseconds.
    pub fn elapsed_ms(&self) -> f64 {
        self.elapsed_samples as f64 * 1000.0 / self.sample_rate as f64
    }
}

/// Why a command was not applied.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriveError {
    /// The plan does not fit the device's limits.
    Plan(PlanError),
    /// The manual setpoint does not fit the device's limits.
    Setpoint(SetpointError),
    /// The drive is faulted; send a stop to clear it first.
    Faulted,
    /// The drive's command queue is full; try again.
    Busy,
}

impl core::fmt::Display for DriveError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DriveError::Plan(e) => write!(f, "invalid plan: {e}"),
            DriveError::Setpoint(e) => write!(f, "invalid setpoint: {e}"),
            DriveError::Faulted => write!(f, "drive is faulted (send stop to clear)"),
            DriveError::Busy => write!(f, "drive command queue full"),
        }
    }
}

// ---- Device identity ----

/// Which hardware the firmware was built for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Board {
    /// The B-L475E-IOT01A discovery kit (STM32L475VG).
    Stm32l475,
    /// The same application on `qemu-system-arm -M b-l475e-iot01a`, with a simulated shaker.
    Qemu,
}

impl Board {
    /// Short lowercase name, as used by the CLI and the firmware's cargo features.
    pub const fn name(self) -> &'static str {
        match self {
            Board::Stm32l475 => "stm32l475",
            Board::Qemu => "qemu",
        }
    }
}

/// Identity of the running firmware.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceInfo {
    /// Firmware crate version (semver).
    pub firmware_version: heapless::String<24>,
    /// Board the firmware runs on.
    pub board: Board,
    /// [`PROTOCOL_VERSION`] of the firmware.
    pub protocol_version: u16,
    /// First 32 bits of the git commit the firmware was built from (0 if unknown).
    pub build_id: u32,
}

/// Why a frame or request was refused. Sent back as [`Response::Error`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkError {
    /// The bytes between two delimiters are not valid COBS.
    BadCobs,
    /// A frame grew past [`MAX_FRAME`] bytes before its delimiter; it was dropped.
    FrameTooLong {
        /// The limit, [`MAX_FRAME`].
        max: u16,
    },
    /// The sender speaks another protocol version.
    UnsupportedVersion {
        /// Version in the frame.
        got: u16,
        /// Version this side speaks.
        supported: u16,
    },
    /// The frame decoded, but not as a known message (unknown variant, truncated, trailing bytes).
    Malformed,
}

impl core::fmt::Display for LinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LinkError::BadCobs => write!(f, "frame is not valid COBS"),
            LinkError::FrameTooLong { max } => write!(f, "frame longer than {max} bytes"),
            LinkError::UnsupportedVersion { got, supported } => {
                write!(f, "protocol version {got} not supported (this side speaks {supported})")
            }
            LinkError::Malformed => write!(f, "frame does not decode as a known message"),
        }
    }
}

/// A frame that could not be decoded, with the request id when it was readable (else 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameError {
    /// Id to answer with: the frame's own if it got that far, else 0.
    pub id: u32,
    /// What was wrong.
    pub error: LinkError,
}

/// Encodes `0x00 · COBS(postcard(envelope)) · 0x00` into `buf`; returns the bytes to send.
///
/// Fails only if `buf` is too small (it needs `MAX_FRAME + 2` bytes for any frame).
pub fn encode<'a, T: Serialize>(
    envelope: &Envelope<T>,
    buf: &'a mut [u8],
) -> Result<&'a [u8], postcard::Error> {
    let (lead, rest) = buf.split_first_mut().ok_or(postcard::Error::SerializeBufferFull)?;
    *lead = 0;
    let used = postcard::to_slice_cobs(envelope, rest)?.len();
    Ok(&buf[..1 + used])
}

/// Decodes one frame as returned by [`FrameReader::push`] (COBS bytes, no delimiters).
///
/// The frame is decoded in place, so `frame` is scratch afterwards.
pub fn decode<T: for<'de> Deserialize<'de>>(frame: &mut [u8]) -> Result<Envelope<T>, FrameError> {
    let unknown = |error| FrameError { id: 0, error };
    let len = cobs::decode_in_place(frame).map_err(|_| unknown(LinkError::BadCobs))?;
    let data = &frame[..len];
    let (version, rest) =
        postcard::take_from_bytes::<u16>(data).map_err(|_| unknown(LinkError::Malformed))?;
    let (id, rest) =
        postcard::take_from_bytes::<u32>(rest).map_err(|_| unknown(LinkError::Malformed))?;
    if version != PROTOCOL_VERSION {
        return Err(FrameError {
            id,
            error: LinkError::UnsupportedVersion { got: version, supported: PROTOCOL_VERSION },
        });
    }
    match postcard::take_from_bytes::<T>(rest) {
        Ok((body, [])) => Ok(Envelope { version, id, body }),
        _ => Err(FrameError { id, error: LinkError::Malformed }),
    }
}

/// Splits a byte stream into frames at `0x00` delimiters.
///
/// Holds at most `N` bytes of one frame; a longer frame is dropped and reported as
/// [`LinkError::FrameTooLong`] when its delimiter finally arrives, so a flood of garbage never
/// stalls the reader.
#[derive(Debug)]
pub struct FrameReader<const N: usize = MAX_FRAME> {
    buf: heapless::Vec<u8, N>,
    overflowed: bool,
    frame_ready: bool,
}

impl<const N: usize> Default for FrameReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameReader<N> {
    /// An empty reader.
    pub const fn new() -> Self {
        Self { buf: heapless::Vec::new(), overflowed: false, frame_ready: false }
    }

    /// Feeds one byte. Returns a complete frame (COBS bytes without delimiters, to pass to
    /// [`decode`]) when `byte` is a delimiter ending a non-empty frame, or the error of an
    /// over-long one. Empty frames (consecutive delimiters) return `None`.
    pub fn push(&mut self, byte: u8) -> Option<Result<&mut [u8], LinkError>> {
        if self.frame_ready {
            self.buf.clear();
            self.frame_ready = false;
        }
        if byte != 0 {
            if self.buf.push(byte).is_err() {
                self.overflowed = true;
            }
            return None;
        }
        if self.overflowed {
            self.overflowed = false;
            self.buf.clear();
            return Some(Err(LinkError::FrameTooLong { max: N as u16 }));
        }
        if self.buf.is_empty() {
            return None;
        }
        self.frame_ready = true;
        Some(Ok(&mut self.buf[..]))
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    fn frames_of(bytes: &[u8]) -> Vec<Result<Envelope<Request>, FrameError>> {
        let mut reader = FrameReader::<MAX_FRAME>::new();
        let mut out = Vec::new();
        for &b in bytes {
            match reader.push(b) {
                Some(Ok(frame)) => out.push(decode::<Request>(frame)),
                Some(Err(error)) => out.push(Err(FrameError { id: 0, error })),
                None => {}
            }
        }
        out
    }

    fn wire(id: u32, body: Request) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME + 2];
        encode(&Envelope { version: PROTOCOL_VERSION, id, body }, &mut buf).unwrap().to_vec()
    }

    #[test]
    fn request_round_trips() {
        let bytes = wire(7, Request::Ping { nonce: 0xdead_beef });
        assert_eq!(bytes[0], 0);
        assert_eq!(*bytes.last().unwrap(), 0);
        assert!(!bytes[1..bytes.len() - 1].contains(&0));
        let got = frames_of(&bytes);
        assert_eq!(
            got,
            [Ok(Envelope {
                version: PROTOCOL_VERSION,
                id: 7,
                body: Request::Ping { nonce: 0xdead_beef }
            })]
        );
    }

    #[test]
    fn response_round_trips() {
        let info = DeviceInfo {
            firmware_version: heapless::String::try_from("0.1.0").unwrap(),
            board: Board::Qemu,
            protocol_version: PROTOCOL_VERSION,
            build_id: 0x1234_5678,
        };
        let env = Envelope { version: PROTOCOL_VERSION, id: 99, body: Response::Info(info) };
        let mut buf = [0u8; MAX_FRAME + 2];
        let bytes = encode(&env, &mut buf).unwrap().to_vec();
        let mut frame = bytes[1..bytes.len() - 1].to_vec();
        assert_eq!(decode::<Response>(&mut frame), Ok(env));
    }

    #[test]
    fn other_version_is_refused_with_its_id() {
        let mut buf = [0u8; 64];
        let env = Envelope { version: 9, id: 42, body: Request::GetInfo };
        let bytes = encode(&env, &mut buf).unwrap().to_vec();
        assert_eq!(
            frames_of(&bytes),
            [Err(FrameError {
                id: 42,
                error: LinkError::UnsupportedVersion { got: 9, supported: PROTOCOL_VERSION }
            })]
        );
    }

    #[test]
    fn unknown_variant_and_trailing_bytes_are_malformed() {
        // this version, id 5, variant 200 (no such request)
        let mut raw = postcard::to_stdvec(&(PROTOCOL_VERSION, 5u32)).unwrap();
        raw.push(200);
        let mut frame = cobs::encode_vec(&raw);
        assert_eq!(
            decode::<Request>(&mut frame),
            Err(FrameError { id: 5, error: LinkError::Malformed })
        );
        let mut raw = postcard::to_stdvec(&Envelope {
            version: PROTOCOL_VERSION,
            id: 6,
            body: Request::GetInfo,
        })
        .unwrap();
        raw.push(0x55);
        let mut frame = cobs::encode_vec(&raw);
        assert_eq!(
            decode::<Request>(&mut frame),
            Err(FrameError { id: 6, error: LinkError::Malformed })
        );
    }

    #[test]
    fn overlong_frame_is_dropped_and_reader_recovers() {
        let mut bytes = std::vec![0x11u8; MAX_FRAME + 10];
        bytes.push(0);
        bytes.extend(wire(3, Request::GetInfo));
        let got = frames_of(&bytes);
        assert_eq!(got.len(), 2);
        assert_eq!(
            got[0],
            Err(FrameError { id: 0, error: LinkError::FrameTooLong { max: MAX_FRAME as u16 } })
        );
        assert_eq!(
            got[1],
            Ok(Envelope { version: PROTOCOL_VERSION, id: 3, body: Request::GetInfo })
        );
    }

    proptest::proptest! {
        /// Whatever garbage came before, a frame sent with its leading delimiter is read intact.
        #[test]
        fn garbage_never_hides_the_next_frame(garbage in proptest::collection::vec(proptest::num::u8::ANY, 0..3000), nonce: u32) {
            let mut bytes = garbage.clone();
            bytes.extend(wire(0xabcd, Request::Ping { nonce }));
            let got = frames_of(&bytes);
            proptest::prop_assert_eq!(
                got.last().cloned(),
                Some(Ok(Envelope { version: PROTOCOL_VERSION, id: 0xabcd, body: Request::Ping { nonce } }))
            );
        }
    }
}
