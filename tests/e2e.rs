//! End to end: the host client against the firmware running in QEMU over USART1 ↔ TCP, or
//! against the real board on `CHLADNI_PORT` (hardware in the loop).
//! One QEMU boot for the whole sequence (boots cost seconds on a 2-core CI machine).

use std::time::Duration;

use chladni::controller::client::{DeviceClient, DeviceError};
use chladni_e2e::{Controller, pseudo_random_bytes};
use chladni_shared::icd::link::{
    DriveState, LinkError, MAX_FRAME, PROTOCOL_VERSION, Request, StatusReport,
};

/// Polls `status` until `done` holds (generous timeout: QEMU's clock slips under load).
fn wait_for(client: &mut DeviceClient, done: impl Fn(&StatusReport) -> bool) -> StatusReport {
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    loop {
        let status = client.status().expect("status");
        if done(&status) {
            return status;
        }
        assert!(std::time::Instant::now() < deadline, "status never reached: last {status:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn link_survives_everything_the_host_can_throw_at_it() {
    let _ = std::fs::remove_file(chladni_e2e::flash_path("link"));
    let mut controller = Controller::start("link");
    let mut client = controller.connect().expect("connect to the controller");
    client.set_timeout(Duration::from_secs(10));

    // Ping and GetInfo.
    client.ping().expect("first ping");
    let info = client.info().expect("GetInfo");
    assert_eq!(info.board, controller.expected_board());
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    assert_eq!(info.firmware_version.as_str(), env!("CARGO_PKG_VERSION"));

    // 1 KiB of garbage, then the next valid ping still gets its answer.
    for seed in [1u64, 0xdead_beef, 42] {
        client.send_raw(&pseudo_random_bytes(seed, 1024)).unwrap();
        client.ping().unwrap_or_else(|e| panic!("ping after garbage (seed {seed}): {e}"));
    }

    // Garbage with no delimiter at all, longer than any frame: dropped, the link recovers.
    client.send_raw(&vec![0x5a; 3 * MAX_FRAME]).unwrap();
    client.ping().expect("ping after an endless frame");

    // A frame of another protocol version is refused with a typed error naming both versions,
    // answered with the frame's own id; the link carries on.
    match client.request_with_version(PROTOCOL_VERSION + 1, Request::GetInfo) {
        Err(DeviceError::Refused { error, .. }) => assert_eq!(
            error,
            LinkError::UnsupportedVersion {
                got: PROTOCOL_VERSION + 1,
                supported: PROTOCOL_VERSION
            }
        ),
        other => panic!("expected UnsupportedVersion, got {other:?}"),
    }
    client.ping().expect("ping after a foreign-version frame");

    // A frame that is valid COBS but no known request: Malformed, with its id.
    let mut raw = Vec::new();
    raw.extend(postcard::to_stdvec(&(PROTOCOL_VERSION, 31337u32)).unwrap());
    raw.push(0xee); // no such Request variant
    let mut frame = vec![0u8];
    frame.extend(cobs::encode_vec(&raw));
    frame.push(0);
    client.send_raw(&frame).unwrap();
    client.ping().expect("ping after a malformed request");

    // Garbage while the shaker is driven: the drive carries on undisturbed (same frequency
    // and amplitude, samples still counting), and stops with a ramp when asked.
    client.drive(120_000, 8_192).expect("manual drive accepted");
    let before =
        wait_for(&mut client, |s| s.state == DriveState::Running && s.amplitude_q15 == 8_192);
    for seed in 100..110u64 {
        client.send_raw(&pseudo_random_bytes(seed, 1024)).unwrap();
    }
    let after = client.status().expect("status after garbage");
    assert_eq!(after.state, DriveState::Running, "garbage disturbed the drive: {after:?}");
    assert_eq!((after.freq_mhz, after.amplitude_q15), (120_000, 8_192));
    assert!(after.elapsed_samples > before.elapsed_samples, "drive stalled: {after:?}");
    client.stop().expect("stop");
    wait_for(&mut client, |s| s.state == DriveState::Idle && s.amplitude_q15 == 0);

    // Requests keep their ids straight across many round trips.
    for _ in 0..50 {
        client.ping().expect("ping in a burst");
    }

    // A second client after the first disconnects (QEMU's socket accepts the next one).
    drop(client);
    let mut second = controller.connect().expect("reconnect");
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
