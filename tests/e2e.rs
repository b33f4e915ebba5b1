//! End to end: the host client against the firmware running in QEMU over USART1 ↔ TCP (through
//! the emulator's link proxy), or against the real board on `CHLADNI_PORT` (hardware in the
//! loop). One QEMU boot for the whole sequence (boots cost seconds on a 2-core CI machine).

use std::time::Duration;

use chladni_device::client::{DeviceClient, Frame, Tamper};
use chladni_e2e::{Controller, frames_until, poll_until, pseudo_random_bytes};
use chladni_shared::icd::frame::CRC32;
use chladni_shared::icd::link::{
    Drive, DriveState, GetInfo, LinkError, MAX_FRAME, PROTOCOL_VERSION, Response,
};

/// Longest wait for an answer that follows kilobytes of garbage through QEMU's serial port.
const WAIT: Duration = Duration::from_secs(20);

/// Whether `frames` hold an `Error(error)` frame with `session` (0: addressed to nobody).
fn has_error(frames: &[Frame], session: u32, error: LinkError) -> bool {
    frames.iter().any(
        |f| matches!(f, Ok(env) if env.session == session && env.body == Response::Error(error)),
    )
}

#[test]
fn link_survives_everything_the_host_can_throw_at_it() {
    let _ = std::fs::remove_file(chladni_e2e::flash_path("link"));
    let mut controller = Controller::start("link");
    let mut client = controller.connect("e2e link").expect("connect to the controller");
    client.set_timeout(Duration::from_secs(10));

    let info = client.get_info().expect("GetInfo");
    assert_eq!(&info, client.info(), "Hello (in connect) and GetInfo agree");
    client.ping().expect("first ping");

    // 1 KiB of garbage, then the next valid ping still gets its answer.
    for seed in [1u64, 0xdead_beef, 42] {
        client.send_raw(&pseudo_random_bytes(seed, 1024)).unwrap();
        client.ping().unwrap_or_else(|e| panic!("ping after garbage (seed {seed}): {e}"));
    }

    // Garbage with no delimiter at all, longer than any frame: dropped, the link recovers.
    client.send_raw(&vec![0x5a; 3 * MAX_FRAME]).unwrap();
    client.send_raw(&[0]).unwrap();
    let too_long = LinkError::FrameTooLong { max: MAX_FRAME as u16 };
    let frames =
        frames_until(&mut client, WAIT, |f| has_error(std::slice::from_ref(f), 0, too_long));
    assert!(has_error(&frames, 0, too_long), "no FrameTooLong for the endless frame: {frames:?}");
    client.ping().expect("ping after an endless frame");

    // A frame of another protocol version is refused with a typed error naming both versions
    // (addressed to session 0: its session cannot be read); the link carries on.
    client.send_tampered(GetInfo, Tamper::Version(PROTOCOL_VERSION + 1)).unwrap();
    let refusal =
        LinkError::UnsupportedVersion { got: PROTOCOL_VERSION + 1, supported: PROTOCOL_VERSION };
    let frames =
        frames_until(&mut client, WAIT, |f| has_error(std::slice::from_ref(f), 0, refusal));
    assert!(has_error(&frames, 0, refusal), "no UnsupportedVersion: {frames:?}");
    client.ping().expect("ping after a foreign-version frame");

    // A frame with a valid CRC that is no known request: Malformed, with its session.
    let session = client.session();
    let mut raw = postcard::to_stdvec(&(PROTOCOL_VERSION, session, 31337u32)).unwrap();
    raw.push(0x7e); // no such Request variant
    raw.extend(CRC32.checksum(&raw).to_le_bytes());
    let mut frame = vec![0u8];
    frame.extend(cobs::encode_vec(&raw));
    frame.push(0);
    client.send_raw(&frame).unwrap();
    let malformed = |f: &Frame| has_error(std::slice::from_ref(f), session, LinkError::Malformed);
    let frames = frames_until(&mut client, WAIT, malformed);
    assert!(has_error(&frames, session, LinkError::Malformed), "no Malformed: {frames:?}");
    client.ping().expect("ping after a malformed request");

    // Requests keep their ids straight across many round trips.
    for _ in 0..50 {
        client.ping().expect("ping in a burst");
    }

    // A second client after the first disconnects.
    drop(client);
    let mut second = controller.connect("e2e link, second").expect("reconnect");
    second.set_timeout(Duration::from_secs(10));
    second.ping().expect("ping from a second connection");
    drop(second);

    let Some(emulator) = controller.emulator("flash file and QEMU process checks") else {
        return;
    };
    let pid = emulator.pid();
    emulator.stop();
    let log = chladni_e2e::read_log(&chladni_e2e::log_path("link"));
    assert!(log.contains("flash bank 2 backed by"), "flash file not in use:\n{log}");
    assert!(
        std::fs::metadata(format!("/proc/{pid}")).is_err(),
        "QEMU (pid {pid}) still running after stop"
    );
}

#[test]
fn the_controller_names_itself_and_garbage_does_not_disturb_the_drive() {
    let controller = Controller::start("link-drive");
    let mut client = controller.connect("e2e identity").expect("connect to the controller");
    client.set_timeout(Duration::from_secs(10));
    let info = client.info().clone();
    assert_eq!(info.board, controller.expected_board());
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    assert_eq!(info.firmware_version.as_str(), env!("CARGO_PKG_VERSION"));
    garbage_does_not_disturb_the_drive(&mut client);
}

/// Garbage while the shaker is driven: the drive carries on undisturbed (same frequency and
/// amplitude, samples still counting), and stops with a ramp when asked.
fn garbage_does_not_disturb_the_drive(client: &mut DeviceClient) {
    let run = client
        .drive(120_000, chladni_shared::icd::plan::Level::Drive(8_192))
        .expect("manual drive accepted");
    let seen = poll_until(client, Duration::from_secs(60), |s| {
        s.run == run && s.state == DriveState::Running && s.amplitude_q15 == 8_192
    });
    let before = seen.last().unwrap().clone();
    for seed in 100..110u64 {
        client.send_raw(&pseudo_random_bytes(seed, 1024)).unwrap();
    }
    // A corrupted drive command among the garbage: refused, never executed.
    let drive = Drive { freq_mhz: 130_000, level: chladni_shared::icd::plan::Level::Drive(8_192) };
    client.send_tampered(drive, Tamper::CorruptCrc).unwrap();
    let after = client.status().expect("status after garbage");
    assert_eq!(after.state, DriveState::Running, "garbage disturbed the drive: {after:?}");
    assert_eq!((after.run, after.freq_mhz, after.amplitude_q15), (run, 120_000, 8_192));
    assert!(after.elapsed_samples > before.elapsed_samples, "drive stalled: {after:?}");
    let stop = client.stop().expect("stop");
    assert!(stop > run, "the stop's run number {stop:?} follows the drive's {run:?}");
    poll_until(client, Duration::from_secs(60), |s| {
        s.run == stop && s.state == DriveState::Idle && s.amplitude_q15 == 0
    });
}
