//! Framing of the host ↔ controller link: how one message becomes bytes on the wire, and back.
//!
//! A frame on the wire is
//! `0x00 · COBS( postcard(Envelope) · CRC-32 ) · 0x00`:
//! - the [`Envelope`] (protocol version, client session, request id, body) is postcard-encoded;
//! - the CRC-32/ISO-HDLC of those bytes follows, little-endian (4 bytes);
//! - COBS leaves no zero byte inside, so `0x00` delimits frames and a receiver resynchronises
//!   after garbage at the next zero. Senders put a zero *before* each frame too, which flushes
//!   whatever partial garbage the receiver may hold; empty frames are ignored.
//!
//! The version comes first in every version of this protocol, so a peer of another version is
//! told "protocol version X, this side speaks Y" ([`LinkError::UnsupportedVersion`]) instead of
//! a CRC or decode error. A frame whose CRC does not match is never acted on
//! ([`LinkError::BadCrc`]).

use crc::{CRC_32_ISO_HDLC, Crc};
use serde::{Deserialize, Serialize};

/// Version of this protocol; bumped on any incompatible change of a message or of framing.
pub const PROTOCOL_VERSION: u16 = 6;

/// Largest COBS-encoded frame (without delimiters) either side accepts, in bytes.
pub const MAX_FRAME: usize = 1024;

/// Bytes of the CRC after the postcard message.
pub const CRC_LEN: usize = 4;

/// The frame CRC: CRC-32/ISO-HDLC (the CRC of zlib, Ethernet, PNG), also used for plan CRCs.
pub static CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// What every frame carries: protocol version, client session, request id, and the message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Envelope<T> {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u16,
    /// Chosen at random by a client when it connects, echoed in every answer; tells clients
    /// sharing one link apart. 0 in the controller's answers to frames it could not read.
    pub session: u32,
    /// Chosen by the client (random start, then +1 per request), echoed in the answer.
    /// 0 is reserved for "unknown".
    pub id: u32,
    /// The request or response.
    pub body: T,
}

/// Why a frame was refused. Sent back as `Response::Error`.
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
    /// The frame's CRC does not match its bytes: it was corrupted on the way, and ignored.
    BadCrc,
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
            LinkError::BadCrc => write!(f, "frame CRC does not match (corrupted on the link)"),
            LinkError::Malformed => write!(f, "frame does not decode as a known message"),
        }
    }
}

/// A frame that could not be decoded, with the session and id when they were readable (else 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameError {
    /// Session to answer to: the frame's own if it got that far, else 0.
    pub session: u32,
    /// Id to answer with: the frame's own if it got that far, else 0.
    pub id: u32,
    /// What was wrong.
    pub error: LinkError,
}

impl FrameError {
    const fn unknown(error: LinkError) -> Self {
        Self { session: 0, id: 0, error }
    }
}

/// Room [`encode`] needs for any frame: the largest frame and its two delimiters.
pub const ENCODE_BUF: usize = MAX_FRAME + 2;

/// Encodes `0x00 · COBS(postcard(envelope) · CRC) · 0x00` into `buf`; returns the bytes to send.
///
/// Fails if the message does not fit a frame ([`MAX_FRAME`]) or `buf` ([`ENCODE_BUF`] is
/// always enough).
pub fn encode<'a, T: Serialize>(
    envelope: &Envelope<T>,
    buf: &'a mut [u8],
) -> Result<&'a [u8], postcard::Error> {
    // postcard + CRC first, in a scratch buffer sized so its COBS form fits MAX_FRAME.
    const RAW: usize = MAX_FRAME - MAX_FRAME / 254 - 1;
    let mut raw = [0u8; RAW];
    let len = postcard::to_slice(envelope, &mut raw[..RAW - CRC_LEN])?.len();
    let crc = CRC32.checksum(&raw[..len]);
    raw[len..len + CRC_LEN].copy_from_slice(&crc.to_le_bytes());
    let raw = &raw[..len + CRC_LEN];
    if buf.len() < cobs::max_encoding_length(raw.len()) + 2 {
        return Err(postcard::Error::SerializeBufferFull);
    }
    buf[0] = 0;
    let used = cobs::encode(raw, &mut buf[1..]);
    buf[1 + used] = 0;
    Ok(&buf[..used + 2])
}

/// Decodes one frame as returned by [`FrameReader::push`] (COBS bytes, no delimiters).
///
/// The frame is decoded in place, so `frame` is scratch afterwards.
pub fn decode<T: for<'de> Deserialize<'de>>(frame: &mut [u8]) -> Result<Envelope<T>, FrameError> {
    let len = cobs::decode_in_place(frame).map_err(|_| FrameError::unknown(LinkError::BadCobs))?;
    let data = &frame[..len];
    let (version, _) = postcard::take_from_bytes::<u16>(data)
        .map_err(|_| FrameError::unknown(LinkError::Malformed))?;
    if version != PROTOCOL_VERSION {
        return Err(FrameError::unknown(LinkError::UnsupportedVersion {
            got: version,
            supported: PROTOCOL_VERSION,
        }));
    }
    let Some(body_len) = len.checked_sub(CRC_LEN) else {
        return Err(FrameError::unknown(LinkError::Malformed));
    };
    let (message, crc) = data.split_at(body_len);
    let (session, id) = header(message);
    if CRC32.checksum(message).to_le_bytes() != crc {
        // Session and id are a best guess here (the bytes are corrupt): a client that finds
        // its own id learns at once that its frame was damaged, any other ignores the answer.
        return Err(FrameError { session, id, error: LinkError::BadCrc });
    }
    match postcard::take_from_bytes::<Envelope<T>>(message) {
        Ok((envelope, [])) => Ok(envelope),
        _ => Err(FrameError { session, id, error: LinkError::Malformed }),
    }
}

/// Session and id of a message, 0 where they cannot be read.
fn header(message: &[u8]) -> (u32, u32) {
    let read = || -> Result<(u32, u32), postcard::Error> {
        let (_version, rest) = postcard::take_from_bytes::<u16>(message)?;
        let (session, rest) = postcard::take_from_bytes::<u32>(rest)?;
        let (id, _) = postcard::take_from_bytes::<u32>(rest)?;
        Ok((session, id))
    };
    read().unwrap_or((0, 0))
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

    /// Forgets a partly received frame (a new client took the link).
    pub fn clear(&mut self) {
        self.buf.clear();
        self.overflowed = false;
        self.frame_ready = false;
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

    #[allow(clippy::large_enum_variant)]
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    enum Msg {
        Ping(u32),
        Text(heapless::String<8>),
        Blob(heapless::Vec<u8, 2000>),
    }

    fn frames_of(bytes: &[u8]) -> Vec<Result<Envelope<Msg>, FrameError>> {
        let mut reader = FrameReader::<MAX_FRAME>::new();
        let mut out = Vec::new();
        for &b in bytes {
            match reader.push(b) {
                Some(Ok(frame)) => out.push(decode::<Msg>(frame)),
                Some(Err(error)) => out.push(Err(FrameError::unknown(error))),
                None => {}
            }
        }
        out
    }

    fn env(session: u32, id: u32, body: Msg) -> Envelope<Msg> {
        Envelope { version: PROTOCOL_VERSION, session, id, body }
    }

    fn wire(session: u32, id: u32, body: Msg) -> Vec<u8> {
        let mut buf = [0u8; ENCODE_BUF];
        encode(&env(session, id, body), &mut buf).unwrap().to_vec()
    }

    /// The message bytes (postcard · CRC) inside a frame from [`wire`].
    fn raw_of(bytes: &[u8]) -> Vec<u8> {
        cobs::decode_vec(&bytes[1..bytes.len() - 1]).unwrap()
    }

    #[test]
    fn message_round_trips_with_delimiters_and_crc() {
        let bytes = wire(0x1234_5678, 7, Msg::Ping(0xdead_beef));
        assert_eq!((bytes[0], *bytes.last().unwrap()), (0, 0));
        assert!(!bytes[1..bytes.len() - 1].contains(&0));
        let raw = raw_of(&bytes);
        let (msg, crc) = raw.split_at(raw.len() - CRC_LEN);
        assert_eq!(crc, CRC32.checksum(msg).to_le_bytes());
        assert_eq!(frames_of(&bytes), [Ok(env(0x1234_5678, 7, Msg::Ping(0xdead_beef)))]);
    }

    #[test]
    fn crc_is_the_standard_crc32() {
        // The check value of CRC-32/ISO-HDLC, so any other implementation can be compared.
        assert_eq!(CRC32.checksum(b"123456789"), 0xcbf4_3926);
    }

    #[test]
    fn every_single_bit_flip_is_refused() {
        let bytes = wire(99, 5, Msg::Ping(120_000));
        let raw = raw_of(&bytes);
        for bit in 0..raw.len() * 8 {
            let mut bad = raw.clone();
            bad[bit / 8] ^= 1 << (bit % 8);
            let mut frame = cobs::encode_vec(&bad);
            let got = decode::<Msg>(&mut frame);
            assert!(got.is_err(), "flip of bit {bit} was accepted: {got:?}");
        }
    }

    #[test]
    fn bad_crc_names_its_session_and_id() {
        let bytes = wire(77, 5, Msg::Ping(1));
        let mut raw = raw_of(&bytes);
        let last = raw.len() - 1;
        raw[last] ^= 0x40;
        let mut frame = cobs::encode_vec(&raw);
        assert_eq!(
            decode::<Msg>(&mut frame),
            Err(FrameError { session: 77, id: 5, error: LinkError::BadCrc })
        );
    }

    #[test]
    fn other_version_is_named_before_the_crc() {
        // A version-1 frame had no session and no CRC: version, id, body.
        let raw = postcard::to_stdvec(&(1u16, 42u32, 0u8)).unwrap();
        let mut frame = cobs::encode_vec(&raw);
        assert_eq!(
            decode::<Msg>(&mut frame),
            Err(FrameError::unknown(LinkError::UnsupportedVersion {
                got: 1,
                supported: PROTOCOL_VERSION
            }))
        );
    }

    #[test]
    fn unknown_variant_and_trailing_bytes_are_malformed() {
        let with_crc = |mut raw: Vec<u8>| {
            let crc = CRC32.checksum(&raw);
            raw.extend(crc.to_le_bytes());
            cobs::encode_vec(&raw)
        };
        let mut raw = postcard::to_stdvec(&(PROTOCOL_VERSION, 3u32, 5u32)).unwrap();
        raw.push(200); // no such variant
        assert_eq!(
            decode::<Msg>(&mut with_crc(raw)),
            Err(FrameError { session: 3, id: 5, error: LinkError::Malformed })
        );
        let mut raw = postcard::to_stdvec(&env(3, 6, Msg::Ping(1))).unwrap();
        raw.push(0x55);
        assert_eq!(
            decode::<Msg>(&mut with_crc(raw)),
            Err(FrameError { session: 3, id: 6, error: LinkError::Malformed })
        );
        assert_eq!(
            decode::<Msg>(&mut cobs::encode_vec(&[PROTOCOL_VERSION as u8, 0])),
            Err(FrameError::unknown(LinkError::Malformed))
        );
    }

    #[test]
    fn a_message_too_big_for_a_frame_is_not_encoded() {
        let mut buf = [0u8; ENCODE_BUF];
        let big = Msg::Blob(heapless::Vec::from_slice(&[7u8; 1500]).unwrap());
        assert!(encode(&env(1, 1, big), &mut buf).is_err());
        let fits = Msg::Blob(heapless::Vec::from_slice(&[7u8; 900]).unwrap());
        let bytes = encode(&env(1, 1, fits.clone()), &mut buf).unwrap().to_vec();
        assert!(bytes.len() <= MAX_FRAME + 2);
        assert_eq!(frames_of(&bytes), [Ok(env(1, 1, fits))]);
    }

    #[test]
    fn overlong_frame_is_dropped_and_reader_recovers() {
        let mut bytes = std::vec![0x11u8; MAX_FRAME + 10];
        bytes.push(0);
        bytes.extend(wire(1, 3, Msg::Text("hi".try_into().unwrap())));
        let got = frames_of(&bytes);
        assert_eq!(
            got,
            [
                Err(FrameError::unknown(LinkError::FrameTooLong { max: MAX_FRAME as u16 })),
                Ok(env(1, 3, Msg::Text("hi".try_into().unwrap())))
            ]
        );
    }

    proptest::proptest! {
        /// Whatever garbage came before, a frame sent with its leading delimiter is read intact.
        #[test]
        fn garbage_never_hides_the_next_frame(
            garbage in proptest::collection::vec(proptest::num::u8::ANY, 0..3000),
            nonce: u32,
        ) {
            let mut bytes = garbage.clone();
            bytes.extend(wire(9, 0xabcd, Msg::Ping(nonce)));
            let got = frames_of(&bytes);
            proptest::prop_assert_eq!(got.last().cloned(), Some(Ok(env(9, 0xabcd, Msg::Ping(nonce)))));
        }

        /// Garbage alone never decodes as a message (the CRC catches what COBS lets through).
        #[test]
        fn garbage_alone_decodes_to_nothing(garbage in proptest::collection::vec(1u8..=255, 1..200)) {
            let mut frame = garbage.clone();
            proptest::prop_assert!(decode::<Msg>(&mut frame).is_err());
        }
    }
}
