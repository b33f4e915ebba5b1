//! The frame decoder: arbitrary bytes through `FrameReader` and `decode::<Request>` /
//! `decode::<Response>`.
//!
//! Asserts, for every input:
//! - nothing panics (no overflow either: built with debug assertions);
//! - the reader splits the stream exactly as the spec says (a model of it runs alongside):
//!   frames end at `0x00`, empty ones are skipped, ones over `MAX_FRAME` are dropped as
//!   `FrameTooLong`, anything else comes out byte for byte;
//! - a frame refused as both types is refused with the same error, session and id (they come
//!   from the envelope, never the body); one that decodes as one type is at worst `Malformed`
//!   as the other;
//! - every frame that decodes re-encodes: `encode` accepts the value, the new frame reads back
//!   through a fresh reader as exactly one frame that decodes to the same value, and encoding
//!   that again gives the same bytes.
//!
//! The first byte picks how the rest is used:
//! - 0: the bytes are the stream (garbage, partial and overlong frames, COBS, CRC);
//! - 1: the bytes are a postcard message: a valid CRC and COBS are put around it (reaches the
//!   deserialiser past the CRC);
//! - 2: a valid sample request or response is encoded, then edited as the bytes say, before the
//!   CRC (the frame stays well formed) or after it (the CRC must catch it).
#![no_main]

use chladni_fuzz::{
    Choices, envelope, frame_around, message, mutate, sample_requests, sample_responses, wire,
};
use chladni_shared::icd::frame::{
    ENCODE_BUF, Envelope, FrameError, FrameReader, LinkError, MAX_FRAME, PROTOCOL_VERSION, decode,
    encode,
};
use chladni_shared::icd::link::{Request, Response};
use libfuzzer_sys::fuzz_target;
use serde::Serialize;
use serde::de::DeserializeOwned;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else { return };
    match mode % 3 {
        0 => check_stream(rest),
        1 => check_stream(&frame_around(rest)),
        _ => check_stream(&mutated_sample(rest)),
    }
});

/// A sample message, encoded and edited as `bytes` say.
fn mutated_sample(bytes: &[u8]) -> Vec<u8> {
    let mut c = Choices::new(bytes);
    let (session, id) = (c.u32(), c.u32());
    let flags = c.u8();
    let mut msg = if flags & 1 == 0 {
        let all = sample_requests();
        message(&envelope(session, id, all[c.below(all.len())].clone()))
    } else {
        let all = sample_responses();
        message(&envelope(session, id, all[c.below(all.len())].clone()))
    };
    let edits = (c.u8() % 8) as usize;
    if flags & 2 == 0 {
        mutate(&mut msg, &mut c, edits);
        frame_around(&msg)
    } else {
        let mut frame = frame_around(&msg);
        mutate(&mut frame, &mut c, edits);
        frame
    }
}

/// Feeds `stream` through a reader, checks each frame against the model, and decodes it.
fn check_stream(stream: &[u8]) {
    let mut reader = FrameReader::<MAX_FRAME>::new();
    let mut model: Vec<u8> = Vec::new();
    for &byte in stream {
        let got = reader.push(byte).map(|r| r.map(|f| f.to_vec()));
        if byte != 0 {
            assert_eq!(got, None, "a non-delimiter byte ended a frame");
            model.push(byte);
            continue;
        }
        let frame = core::mem::take(&mut model);
        if frame.is_empty() {
            assert_eq!(got, None, "an empty frame was reported");
        } else if frame.len() > MAX_FRAME {
            assert_eq!(got, Some(Err(LinkError::FrameTooLong { max: MAX_FRAME as u16 })));
        } else {
            assert_eq!(got.as_ref(), Some(&Ok(frame.clone())), "the frame changed in the reader");
            check_frame(&frame);
        }
    }
}

/// Decodes one frame as each type; checks the errors agree and that what decodes round-trips.
fn check_frame(frame: &[u8]) {
    let as_request = decode::<Request>(&mut frame.to_vec());
    let as_response = decode::<Response>(&mut frame.to_vec());
    match (&as_request, &as_response) {
        // Session and id come from the header alone, so both refusals are the same.
        (Err(a), Err(b)) => assert_eq!(a, b, "the error depends on the body type"),
        // The envelope was fine: only the body can be wrong for the other type.
        (Ok(_), Err(e)) | (Err(e), Ok(_)) => assert_eq!(e.error, LinkError::Malformed),
        (Ok(_), Ok(_)) => {}
    }
    if let Err(FrameError { error: LinkError::FrameTooLong { .. }, .. }) = as_request {
        panic!("decode reported FrameTooLong (only the reader may)");
    }
    if let Ok(env) = as_request {
        round_trip(&env);
    }
    if let Ok(env) = as_response {
        round_trip(&env);
    }
}

/// `env` encodes, reads back as one frame equal to it, and encodes again to the same bytes.
fn round_trip<T>(env: &Envelope<T>)
where
    T: Serialize + DeserializeOwned + PartialEq + core::fmt::Debug,
{
    assert_eq!(env.version, PROTOCOL_VERSION);
    let mut buf = [0u8; ENCODE_BUF];
    let bytes = match encode(env, &mut buf) {
        Ok(bytes) => bytes.to_vec(),
        Err(e) => panic!("a decoded frame does not encode again: {e:?}: {env:?}"),
    };
    let mut reader = FrameReader::<MAX_FRAME>::new();
    let mut frames = Vec::new();
    for &b in &bytes {
        if let Some(r) = reader.push(b) {
            frames.push(r.expect("an encoded frame is not overlong").to_vec());
        }
    }
    assert_eq!(frames.len(), 1, "one encoded message is not one frame");
    let again: Envelope<T> = decode(&mut frames[0]).expect("an encoded frame decodes");
    assert_eq!(&again, env, "the value changed through encode + decode");
    assert_eq!(wire(&again), bytes, "the value encodes to other bytes the second time");
}
