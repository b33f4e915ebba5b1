//! The byte-level half of the client: one session on a transport, frames out, frames in.
//!
//! A link may be shared: several programs on one serial port, or a new client reading what an
//! old one left in the stream (answers to someone else, the tail of an error frame). So the
//! receive side takes only frames of *this* session and the id it waits for, and skips every
//! other frame, decodable or not, without acting on it. Telemetry frames of the session's
//! subscription that arrive while an answer is awaited are kept for
//! [`Link::next_telemetry`].

use std::collections::VecDeque;
use std::io::ErrorKind;
use std::time::{Duration, Instant};

use chladni_shared::icd::frame::CRC32;
use chladni_shared::icd::link::{
    ENCODE_BUF, Envelope, FrameError, FrameReader, LinkError, MAX_FRAME, PROTOCOL_VERSION, Request,
    Response, Telemetry, decode, encode,
};

use super::{DeviceError, Tamper, Transport};

/// Telemetry samples kept while the caller is busy elsewhere; older ones are dropped first.
const TELEMETRY_BACKLOG: usize = 4096;
/// Bytes read from the transport at a time.
const READ_CHUNK: usize = 4096;

/// One decoded frame from the stream, of any session, or why it could not be read.
pub type Frame = Result<Envelope<Response>, FrameError>;

/// What arrived while waiting for an answer that never came: tells a dead link from a
/// controller of another protocol version.
#[derive(Debug, Default, Clone, Copy)]
struct Seen {
    /// The protocol version of the last frame refused for its version, if any.
    other_version: Option<u16>,
    /// Frames that could not be read at all (bad CRC, malformed, not COBS).
    unreadable: u32,
}

/// A session on a transport: ids, the frame reader and the bytes not yet looked at.
pub struct Link {
    io: Box<dyn Transport>,
    reader: FrameReader<MAX_FRAME>,
    /// Bytes read but not yet fed to `reader` (a call returns at the end of its frame).
    rx: Vec<u8>,
    rx_pos: usize,
    pub(super) session: u32,
    next_id: u32,
    pub(super) timeout: Duration,
    /// Id of the session's `Subscribe`: its telemetry frames carry it.
    subscription: Option<u32>,
    telemetry: VecDeque<Telemetry>,
}

impl Link {
    /// A link with a random session and a random first id.
    pub fn new(io: Box<dyn Transport>, timeout: Duration) -> Self {
        let (session, first_id) = random_session_and_id();
        Self {
            io,
            reader: FrameReader::new(),
            rx: Vec::new(),
            rx_pos: 0,
            session,
            next_id: first_id,
            timeout,
            subscription: None,
            telemetry: VecDeque::new(),
        }
    }

    /// The id for the next request: +1 each time, never 0.
    fn take_id(&mut self) -> u32 {
        let id = self.next_id;
        self.next_id = match self.next_id.wrapping_add(1) {
            0 => FIRST_ID_MIN,
            next => next,
        };
        id
    }

    /// Sends `request` and returns the body of the answer with the session and id of it.
    pub(crate) fn exchange(&mut self, request: Request) -> Result<Response, DeviceError> {
        let name = request.name();
        let id = self.send(request, Tamper::None)?;
        self.wait_answer(id, name)
    }

    /// Encodes `request` under a fresh id (tampered with as asked), sends it, returns the id.
    pub fn send(&mut self, request: Request, tamper: Tamper) -> Result<u32, DeviceError> {
        let id = self.take_id();
        if matches!(request, Request::Subscribe(_)) {
            // The stream that follows carries this id; samples of an older stream are stale.
            self.subscription = Some(id);
            self.telemetry.clear();
        }
        let bytes = self.frame_bytes(request, id, tamper)?;
        self.send_raw(&bytes)?;
        Ok(id)
    }

    /// The bytes of one frame carrying `request`, tampered with as asked.
    fn frame_bytes(&self, body: Request, id: u32, tamper: Tamper) -> Result<Vec<u8>, DeviceError> {
        let version = match tamper {
            Tamper::Version(v) => v,
            _ => PROTOCOL_VERSION,
        };
        let envelope = Envelope { version, session: self.session, id, body };
        let mut buf = vec![0u8; ENCODE_BUF];
        let bytes = encode(&envelope, &mut buf).map_err(|e| {
            DeviceError::Io(std::io::Error::other(format!(
                "{} does not fit a frame of {MAX_FRAME} bytes: {e}",
                envelope.body.name()
            )))
        })?;
        match tamper {
            Tamper::None | Tamper::Version(_) => Ok(bytes.to_vec()),
            Tamper::CorruptCrc | Tamper::FlipBodyBit(_) => Ok(tampered(&envelope, tamper)),
        }
    }

    /// Writes raw bytes to the link.
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), DeviceError> {
        self.io.write_all(bytes)?;
        self.io.flush()?;
        Ok(())
    }

    /// Reads frames until the answer to request `id` arrives (or the timeout).
    fn wait_answer(&mut self, id: u32, request: &'static str) -> Result<Response, DeviceError> {
        let deadline = Instant::now() + self.timeout;
        let mut seen = Seen::default();
        while let Some(frame) = self.next_frame(deadline)? {
            let envelope = match frame {
                Ok(envelope) => envelope,
                Err(FrameError { error: LinkError::UnsupportedVersion { got, .. }, .. }) => {
                    seen.other_version = Some(got);
                    continue;
                }
                Err(_) => {
                    seen.unreadable += 1;
                    continue;
                }
            };
            if envelope.session != self.session {
                continue; // another client's answer, or an error for a frame nobody could read
            }
            if let Response::Telemetry(sample) = envelope.body {
                self.keep_telemetry(envelope.id, sample);
            } else if envelope.id == id {
                return Ok(envelope.body);
            }
            // else: a late answer to one of this session's earlier requests; never acted on.
        }
        Err(match seen.other_version {
            Some(device) => DeviceError::VersionMismatch { device, host: PROTOCOL_VERSION },
            None => DeviceError::Timeout {
                request,
                id,
                timeout: self.timeout,
                unreadable: seen.unreadable,
            },
        })
    }

    /// Keeps a sample of the current subscription for [`Self::next_telemetry`].
    fn keep_telemetry(&mut self, id: u32, sample: Telemetry) {
        if self.subscription == Some(id) {
            if self.telemetry.len() == TELEMETRY_BACKLOG {
                self.telemetry.pop_front();
            }
            self.telemetry.push_back(sample);
        }
    }

    /// The next sample of the current subscription, waiting up to `within`; `None` if none
    /// came (the stream ended, or another client's `Subscribe` replaced it).
    pub fn next_telemetry(&mut self, within: Duration) -> Result<Option<Telemetry>, DeviceError> {
        if let Some(sample) = self.telemetry.pop_front() {
            return Ok(Some(sample));
        }
        let deadline = Instant::now() + within;
        while let Some(frame) = self.next_frame(deadline)? {
            if let Ok(Envelope { session, id, body: Response::Telemetry(sample), .. }) = frame
                && session == self.session
                && self.subscription == Some(id)
            {
                return Ok(Some(sample));
            }
        }
        Ok(None)
    }

    /// Every frame that arrives within `within`, of any session (tests, diagnostics).
    pub fn receive_frames(&mut self, within: Duration) -> Result<Vec<Frame>, DeviceError> {
        let deadline = Instant::now() + within;
        let mut frames = Vec::new();
        while let Some(frame) = self.next_frame(deadline)? {
            frames.push(frame);
        }
        Ok(frames)
    }

    /// The next frame in the stream (decoded or not), or `None` at `deadline`.
    fn next_frame(&mut self, deadline: Instant) -> Result<Option<Frame>, DeviceError> {
        loop {
            while self.rx_pos < self.rx.len() {
                let byte = self.rx[self.rx_pos];
                self.rx_pos += 1;
                match self.reader.push(byte) {
                    None => {}
                    Some(Ok(frame)) => return Ok(Some(decode::<Response>(frame))),
                    Some(Err(error)) => {
                        return Ok(Some(Err(FrameError { session: 0, id: 0, error })));
                    }
                }
            }
            if !self.fill(deadline)? {
                return Ok(None);
            }
        }
    }

    /// Reads more bytes into `rx`; false at `deadline`. A closed link is an error.
    fn fill(&mut self, deadline: Instant) -> Result<bool, DeviceError> {
        self.rx.resize(READ_CHUNK, 0);
        self.rx_pos = 0;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                self.rx.clear();
                return Ok(false);
            }
            // A zero read timeout means "block for ever" to some transports: never ask for it.
            self.io.set_read_timeout(left.max(Duration::from_millis(1)))?;
            match self.io.read(&mut self.rx) {
                Ok(0) => {
                    self.rx.clear();
                    return Err(DeviceError::Closed);
                }
                Ok(n) => {
                    self.rx.truncate(n);
                    return Ok(true);
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                    ) => {}
                Err(e) => {
                    self.rx.clear();
                    return Err(e.into());
                }
            }
        }
    }
}

/// Smallest id a client starts from or wraps to. Ids stay far from 0..=255 so that a frame of
/// this protocol can never be read as a short request by a controller of the older link,
/// which took the field after the version as the id and the next as the request's variant.
pub(super) const FIRST_ID_MIN: u32 = 1 << 16;

/// A random nonzero session and a random first id of at least [`FIRST_ID_MIN`].
///
/// `RandomState` is keyed from the OS's randomness once per process and mixed per instance,
/// so hashing the time and the process id with a fresh one differs between connections and
/// processes; a PCG generator spreads it.
fn random_session_and_id() -> (u32, u32) {
    use std::hash::{BuildHasher, RandomState};
    let seed = RandomState::new().hash_one((Instant::now(), std::process::id()));
    let mut rng = chladni_core::rng::Rng::seeded(seed);
    let session = (rng.next_u64() as u32).max(1);
    let span = u64::from(u32::MAX - FIRST_ID_MIN);
    let first_id = FIRST_ID_MIN + (rng.next_u64() % span) as u32;
    (session, first_id)
}

/// `envelope`'s frame with its CRC or one bit of its body flipped (after the CRC was
/// computed, as the wire would do it).
fn tampered(envelope: &Envelope<Request>, tamper: Tamper) -> Vec<u8> {
    let mut raw = postcard::to_stdvec(envelope).unwrap_or_default();
    let crc = CRC32.checksum(&raw);
    let header = postcard::to_stdvec(&(envelope.version, envelope.session, envelope.id))
        .map_or(0, |h| h.len());
    raw.extend(crc.to_le_bytes());
    match tamper {
        Tamper::CorruptCrc => {
            let last = raw.len() - 1;
            raw[last] ^= 0x5a;
        }
        Tamper::FlipBodyBit(bit) => {
            let byte = (header + bit / 8).min(raw.len() - 1);
            raw[byte] ^= 1 << (bit % 8);
        }
        Tamper::None | Tamper::Version(_) => {}
    }
    let mut bytes = vec![0u8];
    bytes.extend(cobs::encode_vec(&raw));
    bytes.push(0);
    bytes
}
