//! The controller's request handler: frames from arbitrary bytes through `FrameReader` into the
//! firmware's `app::link::Link::respond`, with the real drive (`DriveShared` + `DriveCore`) and
//! plan store (`app::store::PlanStore`) over a RAM flash, on a clock the input moves.
//!
//! Asserts, for every input:
//! - nothing panics (the handler, the drive, the store; overflow included);
//! - every frame gets exactly one answer, with the frame's version, session and id: a frame
//!   that decodes as a request is answered by that request's own response variant or refused
//!   (`Refused`), never `Error`; reads (`Hello`, `Ping` with its nonce, `GetInfo`, `Status`,
//!   `GetConfig`, `Release`) are never refused, and only requests that need ownership are
//!   refused as `Busy`; a frame that does not decode is answered `Error` with the decoder's
//!   error, session and id (0, 0 for an overlong frame);
//! - every answer and every telemetry sample fits a frame (`encode` accepts it: the firmware
//!   would otherwise drop it silently) and reads back as the same value;
//! - telemetry samples carry the session and id of the `Subscribe` that started the stream.
//!
//! The input is a program of steps, each chosen by one byte:
//! - 0: raw bytes onto the link (a length, then the bytes);
//! - 1: a postcard message with a correct CRC and COBS around it (a length, then the bytes);
//! - 2–4: a sample request from one of three sessions, possibly edited before its CRC;
//! - 5: the clock moves on (ownership lapses after `OWNER_LEASE_MS`);
//! - 6: the drive plays some blocks (queued commands take effect);
//! - 7: a telemetry sample is asked for;
//! - 8: one byte repeated onto the link (a length, then the byte): overlong frames and long
//!   runs from three bytes of input.
//!
//! At most [`MAX_STEPS`] steps are read (scripts/fuzz.sh also caps the input at 1 KiB): a
//! longer program mostly repeats what short ones do, at a cost that grows with its length.
#![no_main]

use chladni_firmware::app::drive::{DriveCore, DriveShared};
use chladni_firmware::app::link::{Identity, Link};
use chladni_firmware::app::store::PlanStore;
use chladni_fuzz::flash::{PAGE_SIZE, fuzz_flash};
use chladni_fuzz::{Choices, SAMPLE_REQUESTS, envelope, frame_around, message, mutate};
use chladni_shared::drive::runner::BLOCK_LEN;
use chladni_shared::icd::frame::{
    ENCODE_BUF, Envelope, FrameReader, LinkError, MAX_FRAME, PROTOCOL_VERSION, decode, encode,
};
use chladni_shared::icd::link::{Board, Refusal, Request, Response};
use embassy_time::{Duration, Instant};
use libfuzzer_sys::fuzz_target;

/// Pages of the RAM flash the store gets (the QEMU board's bank is larger; a small one fills
/// up, which the fuzzer should see too). Four hold a few plans and one page kept erased for
/// garbage collection; every execution erases and scans them, so more would only cost.
const STORE_PAGES: usize = 4;

/// Steps read from one input, at most (the bytes after them are ignored).
const MAX_STEPS: usize = 64;

/// The sessions of the sample requests (two clients and a third that comes and goes).
const SESSIONS: [u32; 3] = [0x1111_1111, 0x2222_2222, 0x3333_3333];

fuzz_target!(|data: &[u8]| {
    embassy_futures::block_on(run(data));
    chladni_fuzz::discard_logs();
});

/// The telemetry stream the harness expects: who asked for it.
type Stream = Option<(u32, u32)>;

async fn run(data: &[u8]) {
    let drive = DriveShared::new();
    let mut flash = fuzz_flash(STORE_PAGES);
    let store = PlanStore::new(&mut flash, 0..(STORE_PAGES * PAGE_SIZE) as u32);
    let mut link = Link::new(Identity { board: Board::Qemu, inject: None }, &drive, Some(store));
    link.load_config().await;
    let mut core = DriveCore::new(&drive);
    let mut reader = FrameReader::<MAX_FRAME>::new();
    let mut now = Instant::from_millis(1_000);
    let mut stream: Stream = None;
    let samples = &*SAMPLE_REQUESTS;
    let mut c = Choices::new(data);
    for _ in 0..MAX_STEPS {
        if c.is_empty() {
            break;
        }
        let bytes = match c.u8() % 9 {
            0 => {
                let n = c.u16() as usize % 2048;
                c.take(n).to_vec()
            }
            1 => {
                let n = c.u16() as usize % 1100;
                frame_around(c.take(n))
            }
            2..=4 => {
                let session = SESSIONS[c.u8() as usize % SESSIONS.len()];
                let request = samples[c.below(samples.len())].clone();
                let mut msg = message(&envelope(session, c.u32(), request));
                let edits = (c.u8() % 4) as usize;
                mutate(&mut msg, &mut c, edits);
                frame_around(&msg)
            }
            5 => {
                now += Duration::from_millis(c.u16() as u64);
                continue;
            }
            6 => {
                let mut block = [0u16; BLOCK_LEN];
                for _ in 0..c.u8() % 16 {
                    core.refill(&mut block);
                }
                continue;
            }
            7 => {
                let sample = link.sample(now);
                check_sample(sample, &mut stream);
                continue;
            }
            _ => {
                let n = c.u16() as usize % 2048;
                vec![c.u8(); n]
            }
        };
        for byte in bytes {
            let Some(frame) = reader.push(byte) else { continue };
            let copy = frame.as_ref().map(|f| f.to_vec()).map_err(|e| *e);
            let answer = link.respond(frame, now).await;
            check_answer(copy, &answer, &mut stream);
        }
    }
    drop(link);
    assert_eq!(flash.violation(), None, "a program the L4 refuses (PROGERR) at this address");
}

/// The answer to one frame (`frame`: its bytes, or the reader's error).
fn check_answer(
    frame: Result<Vec<u8>, LinkError>,
    answer: &Envelope<Response>,
    stream: &mut Stream,
) {
    assert_eq!(answer.version, PROTOCOL_VERSION);
    fits_a_frame(answer);
    let mut bytes = match frame {
        Err(error) => {
            assert_eq!((answer.session, answer.id), (0, 0));
            assert_eq!(answer.body, Response::Error(error));
            return;
        }
        Ok(bytes) => bytes,
    };
    let request = match decode::<Request>(&mut bytes) {
        Err(e) => {
            assert_eq!((answer.session, answer.id), (e.session, e.id), "an error to another id");
            assert_eq!(answer.body, Response::Error(e.error));
            return;
        }
        Ok(request) => request,
    };
    assert_eq!((answer.session, answer.id), (request.session, request.id), "answer to another id");
    let body = &answer.body;
    match body {
        Response::Refused(refusal) => {
            assert!(
                !matches!(
                    request.body,
                    Request::Hello(_)
                        | Request::Ping(_)
                        | Request::GetInfo(_)
                        | Request::Status(_)
                        | Request::GetConfig(_)
                        | Request::Release(_)
                ),
                "a read was refused: {:?} -> {refusal:?}",
                request.body
            );
            if matches!(refusal, Refusal::Busy { .. }) {
                assert!(request.body.needs_owner(), "{:?} refused as busy", request.body);
            }
        }
        _ => {
            assert!(request.body.is_answered_by(body), "{:?} answered with {body:?}", request.body)
        }
    }
    if let (Request::Ping(ping), Response::Ping(nonce)) = (&request.body, body) {
        assert_eq!(ping.nonce, *nonce);
    }
    if let (Request::Subscribe(sub), Response::Subscribe(())) = (&request.body, body) {
        *stream = (sub.count > 0).then_some((request.session, request.id));
    }
}

/// A telemetry sample comes only from a running stream, to the session and id that asked.
fn check_sample(sample: Option<Envelope<Response>>, stream: &mut Stream) {
    let Some(sample) = sample else { return };
    let Some((session, id)) = *stream else {
        panic!("a telemetry sample without a stream: {sample:?}");
    };
    assert_eq!((sample.session, sample.id), (session, id));
    let Response::Telemetry(t) = &sample.body else {
        panic!("a sample that is not telemetry: {sample:?}");
    };
    if t.left == 0 {
        *stream = None;
    }
    fits_a_frame(&sample);
}

/// `env` encodes into a frame and decodes back to itself.
fn fits_a_frame(env: &Envelope<Response>) {
    let mut buf = [0u8; ENCODE_BUF];
    let bytes = match encode(env, &mut buf) {
        Ok(bytes) => bytes,
        Err(e) => panic!("an answer does not fit a frame ({e:?}): {env:?}"),
    };
    let mut frame = bytes[1..bytes.len() - 1].to_vec();
    assert_eq!(decode::<Response>(&mut frame).as_ref(), Ok(env));
}
