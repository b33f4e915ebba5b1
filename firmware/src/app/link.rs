//! Serves the host link: reads frames, answers every request (or names what was wrong).
//!
//! Garbage never stops the loop: a bad frame costs one error response, and the reader
//! resynchronises at the next delimiter.

use chladni_shared::icd::link::{
    self, Board, DeviceInfo, Envelope, FrameReader, LinkError, MAX_FRAME, PROTOCOL_VERSION,
    Request, Response,
};
use embedded_io_async::{Read, Write};

use super::drive::{Command, DriveShared};

/// Pause after a failed read before trying again, ms (short enough not to lose a UART byte
/// burst behind a framing error: the port's RX buffer keeps receiving meanwhile).
const READ_ERROR_BACKOFF_MS: u64 = 10;

/// What the link needs to know about the device to answer requests.
#[derive(Debug, Clone, Copy)]
pub struct Identity {
    /// The board this image runs on.
    pub board: Board,
}

/// Answers one request; drive commands are queued for the drive task.
pub fn handle(identity: &Identity, drive: &DriveShared, request: &Request) -> Response {
    let submit = |command| match drive.submit(command) {
        Ok(()) => Response::Ack,
        Err(e) => Response::Rejected(e),
    };
    match request {
        Request::Ping { nonce } => Response::Pong { nonce: *nonce },
        Request::GetInfo => Response::Info(DeviceInfo {
            firmware_version: heapless::String::try_from(crate::FIRMWARE_VERSION)
                .unwrap_or_default(),
            board: identity.board,
            protocol_version: PROTOCOL_VERSION,
            build_id: crate::BUILD_ID,
        }),
        Request::Drive { freq_mhz, amplitude_q15 } => {
            submit(Command::Drive { freq_mhz: *freq_mhz, amplitude_q15: *amplitude_q15 })
        }
        Request::RunPlan(plan) => submit(Command::RunPlan(plan.clone())),
        Request::Stop => submit(Command::Stop),
        Request::Status => Response::Status(drive.status()),
    }
}

/// The response to one frame from [`FrameReader::push`]: the answer to its request, or the
/// error that kept it from being read (with the frame's id when it got that far, else 0).
pub fn respond(
    identity: &Identity,
    drive: &DriveShared,
    frame: Result<&mut [u8], LinkError>,
) -> Envelope<Response> {
    let (id, body) = match frame {
        Ok(frame) => match link::decode::<Request>(frame) {
            Ok(env) => {
                defmt::debug!("link: request {} {}", env.id, env.body);
                (env.id, handle(identity, drive, &env.body))
            }
            Err(e) => (e.id, Response::Error(e.error)),
        },
        Err(error) => (0, Response::Error(error)),
    };
    if let Response::Error(e) = &body {
        defmt::warn!("link: refused frame (id {}): {}", id, e);
    }
    Envelope { version: PROTOCOL_VERSION, id, body }
}

/// Runs the link forever on `port`.
pub async fn serve<P: Read + Write>(identity: Identity, drive: &DriveShared, port: &mut P) -> ! {
    let mut reader = FrameReader::<MAX_FRAME>::new();
    let mut rx = [0u8; 64];
    let mut tx = [0u8; MAX_FRAME + 2];
    loop {
        let n = match port.read(&mut rx).await {
            Ok(n) => n,
            Err(_) => {
                defmt::warn!("link: read error");
                // Back off before reading again: some ports fail at once and keep failing
                // (a USB CDC endpoint before the host configures it), and without an await
                // here this loop would never yield and starve every other task (livelock).
                embassy_time::Timer::after_millis(READ_ERROR_BACKOFF_MS).await;
                continue;
            }
        };
        for &byte in &rx[..n] {
            let Some(frame) = reader.push(byte) else { continue };
            let envelope = respond(&identity, drive, frame);
            let id = envelope.id;
            match link::encode(&envelope, &mut tx) {
                Ok(bytes) => {
                    if port.write_all(bytes).await.is_err() {
                        defmt::warn!("link: write error");
                    }
                }
                Err(_) => defmt::error!("link: response {} does not fit a frame", id),
            }
        }
    }
}
