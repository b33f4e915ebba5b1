//! The byte examples of docs/protocol.md, checked against the code: each fenced block after a
//! `<!-- protocol-example: NAME -->` line holds lines `label  hex bytes…` (`|` separators and
//! trailing words are skipped; lines without bytes are captions), and each label is compared
//! here with what the encoder makes or the decoder answers. A client written from that page
//! relies on these bytes, so a change to them fails here until the page says the same.

extern crate std;

use std::collections::BTreeMap;
use std::string::{String, ToString};
use std::vec::Vec;

use crate::icd::frame::{CRC32, ENCODE_BUF, Envelope, FrameError, LinkError, decode, encode};
use crate::icd::link::{Ping, Request, Response};
use crate::icd::plan::{Level, Plan, Step};
use crate::icd::store::plan_crc;

const PAGE: &str = include_str!("../../../docs/protocol.md");

/// The labelled byte lines of example `name`.
fn example(name: &str) -> BTreeMap<String, Vec<u8>> {
    let marker = std::format!("<!-- protocol-example: {name} -->");
    let at = PAGE.find(&marker).unwrap_or_else(|| panic!("docs/protocol.md lacks {marker}"));
    let rest = &PAGE[at + marker.len()..];
    let open = rest.find("```").expect("a fenced block after the marker");
    let body = &rest[open + 3..];
    let body = &body[body.find('\n').unwrap() + 1..];
    let body = &body[..body.find("```").expect("the block's end")];
    let mut lines = BTreeMap::new();
    for line in body.lines() {
        let mut words = line.split_whitespace();
        let Some(label) = words.next() else { continue };
        let bytes: Vec<u8> = words
            .filter(|w| *w != "|")
            .map_while(|w| (w.len() == 2).then(|| u8::from_str_radix(w, 16).ok()).flatten())
            .collect();
        if !bytes.is_empty() {
            lines.insert(label.to_string(), bytes);
        }
    }
    lines
}

fn postcard<T: serde::Serialize>(value: &T) -> Vec<u8> {
    postcard::to_stdvec(value).unwrap()
}

fn wire<T: serde::Serialize>(envelope: &Envelope<T>) -> Vec<u8> {
    let mut buf = [0u8; ENCODE_BUF];
    encode(envelope, &mut buf).unwrap().to_vec()
}

/// The decoder's verdict on a frame as it is on the wire (delimiters included).
fn decoded(wire: &[u8]) -> Result<Envelope<Request>, FrameError> {
    let mut frame = wire[1..wire.len() - 1].to_vec();
    decode::<Request>(&mut frame)
}

const SESSION: u32 = 0x1234_5678;

#[test]
fn the_ping_frame_is_the_one_on_the_page() {
    let shown = example("ping");
    let ping = Envelope {
        version: 6,
        session: SESSION,
        id: 1,
        body: Request::Ping(Ping { nonce: 0x0102_0304 }),
    };
    let bytes = postcard(&ping);
    assert_eq!(shown["postcard"], bytes);
    assert_eq!(shown["CRC-32"], CRC32.checksum(&bytes).to_le_bytes());
    assert_eq!(shown["wire"], wire(&ping));
    assert_eq!(decoded(&shown["wire"]), Ok(ping));
    // "The answer … happens to be the same bytes."
    let pong = Envelope { version: 6, session: SESSION, id: 1, body: Response::Ping(0x0102_0304) };
    assert_eq!(shown["wire"], wire(&pong));
}

#[test]
fn the_malformed_answer_and_the_short_frame_are_the_ones_on_the_page() {
    let shown = example("malformed");
    let answer = Envelope {
        version: 6,
        session: SESSION,
        id: 1,
        body: Response::Error(LinkError::Malformed),
    };
    let bytes = postcard(&answer);
    assert_eq!(shown["postcard"], bytes);
    assert_eq!(shown["CRC-32"], CRC32.checksum(&bytes).to_le_bytes());
    assert_eq!(shown["wire"], wire(&answer));
    let short = FrameError { session: 0, id: 0, error: LinkError::Malformed };
    assert_eq!(decoded(&shown["short"]), Err(short));
}

#[test]
fn the_plan_crc_example_is_the_one_on_the_page() {
    let shown = example("plan-crc");
    let step =
        Step { freq_mhz: 100_000, level: Level::Drive(16_384), duration_ms: 500, ramp_ms: 20 };
    let plan = Plan {
        name: heapless::String::try_from("ab").unwrap(),
        repeat: 1,
        steps: heapless::Vec::from_slice(&[step]).unwrap(),
    };
    assert_eq!(shown["plan"], postcard(&plan));
    assert_eq!(shown["crc"], plan_crc(&plan).to_le_bytes());
    assert_eq!(plan_crc(&plan), CRC32.checksum(&shown["plan"]));
}

#[test]
fn signed_integers_are_zigzag_varints_as_the_table_says() {
    for (n, bytes) in
        [(0i32, &[0x00][..]), (-1, &[0x01]), (1, &[0x02]), (-2, &[0x03]), (-300, &[0xd7, 0x04])]
    {
        assert_eq!(postcard(&n), bytes, "{n}");
    }
}

/// Section 1, step 6: a string over its bound in a frame whose CRC is good is `Malformed`,
/// answered to the frame's own session and id.
#[test]
fn a_33_byte_plan_name_is_malformed_under_the_frames_own_id() {
    // UploadBegin (request 8) with a 33-byte name, built by hand: the type cannot hold it.
    let mut bytes = postcard(&Envelope { version: 6u16, session: SESSION, id: 9u32, body: 8u8 });
    bytes.push(0); // slot: None
    bytes.push(33);
    bytes.extend([b'a'; 33]);
    bytes.extend([1, 1, 0]); // repeat, steps, crc
    bytes.extend(CRC32.checksum(&bytes).to_le_bytes());
    let mut cobs = std::vec![0u8; cobs::max_encoding_length(bytes.len())];
    let len = cobs::encode(&bytes, &mut cobs);
    let verdict = decode::<Request>(&mut cobs[..len]);
    assert_eq!(verdict, Err(FrameError { session: SESSION, id: 9, error: LinkError::Malformed }));
}
