//! End to end: a host that stops reading stalls neither the drive nor the link.
//!
//! QEMU's USART leaves TXE clear while its chardev refuses a byte, which happens when the host
//! does not read the socket. Behind the emulator's proxy that never comes about (QEMU writes to
//! a loopback TCP socket whose buffer grows to megabytes, and the proxy always reads it), so
//! this test gives QEMU's serial a Unix stream socket of its own: one that holds only a few
//! hundred one-byte writes. A closed-loop drive runs with telemetry at 100 Hz while the test
//! reads nothing for 3 s, three times the watchdog's timeout. The link must neither spin (the
//! sense task would starve and the monitor trip `no_data` within 12 ms) nor wait for ever in a
//! write (no check-in: the watchdog would reset the controller); afterwards the same session is
//! answered and the drive still runs, with no fault. A real board cannot be made to refuse
//! bytes this way, so the test runs in QEMU only.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use chladni_device::client::{DeviceClient, Transport};
use chladni_device::{emulator, firmware};
use chladni_e2e::{log_path, poll_until};
use chladni_shared::icd::link::{Board, DriveState};
use chladni_shared::icd::plan::Level;

/// QEMU under a time limit ([`emulator::limited`]), stopped when the test ends however it
/// ends, and by the limit should the test process itself be killed.
struct Qemu(Child);

impl Drop for Qemu {
    fn drop(&mut self) {
        emulator::stop_child(&mut self.0);
    }
}

/// QEMU's time limit: the test takes about 10 s.
const QEMU_LIMIT: Duration = Duration::from_secs(120);

/// The client's end of QEMU's Unix socket.
struct Unix(UnixStream);

impl Read for Unix {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.0.read(buf)
    }
}

impl Write for Unix {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
}

impl Transport for Unix {
    fn set_read_timeout(&mut self, timeout: Duration) -> std::io::Result<()> {
        self.0.set_read_timeout(Some(timeout))
    }
}

/// How long the host reads nothing: three times the watchdog's 1 s timeout.
const DEAF: Duration = Duration::from_secs(3);

/// QEMU with the firmware, its USART1 on a Unix socket at `sock`; the connected client.
fn start(sock: &std::path::Path) -> (Qemu, DeviceClient) {
    let elf = firmware::build(Board::Qemu).expect("build the QEMU firmware");
    let mut args = emulator::qemu_command_line(&elf, 0, None);
    let chardev = args.iter().position(|a| a == "-chardev").expect("a -chardev argument") + 1;
    args[chardev] = format!("socket,id=s0,path={},server=on,wait=off", sock.display());
    // The raw defmt stream (semihosting): `defmt-print -e ELF < slow_reader.defmt` reads it.
    let log = std::fs::File::create(log_path("slow_reader").with_extension("defmt"))
        .expect("the log file");
    let qemu = emulator::limited("qemu-system-arm", &args, Some(QEMU_LIMIT))
        .stdin(Stdio::null())
        .stdout(log)
        .stderr(Stdio::null())
        .spawn()
        .expect("start qemu-system-arm (scripts/install-deps.sh installs it)");
    let qemu = Qemu(qemu);
    // As the emulator's start-up check: connect and say Hello until the firmware answers
    // (QEMU listens before the firmware has booted; it serves one client at a time).
    let deadline = Instant::now() + Duration::from_secs(20);
    let client = loop {
        let attempt = UnixStream::connect(sock).map_err(|e| e.to_string()).and_then(|s| {
            let io = Box::new(Unix(s));
            DeviceClient::with_timeout(io, "e2e slow reader", Duration::from_millis(500))
                .map_err(|e| e.to_string())
        });
        match attempt {
            Ok(mut client) => {
                client.set_timeout(Duration::from_secs(10));
                break client;
            }
            Err(e) if Instant::now() > deadline => panic!("no Hello on {sock:?} within 20 s: {e}"),
            // Polling a condition (the firmware answers), bounded by the deadline above.
            Err(_) => std::thread::sleep(Duration::from_millis(100)),
        }
    };
    (qemu, client)
}

#[test]
fn a_host_that_stops_reading_stalls_neither_the_drive_nor_the_link() {
    if chladni_e2e::real_port().is_some() {
        println!("skipped on the real board: needs QEMU's serial on a Unix socket");
        return;
    }
    let sock = log_path("slow_reader").with_extension("sock");
    let _ = std::fs::remove_file(&sock);
    let (_qemu, mut client) = start(&sock);
    let before = client.status().expect("status");
    let run = client.drive(180_000, Level::Accel(15_000)).expect("start a closed-loop drive");
    poll_until(&mut client, Duration::from_secs(30), |s| {
        s.run == run && s.state == DriveState::Running
    });
    client.subscribe(100, 100_000).expect("subscribe at 100 Hz");
    assert!(
        client.next_telemetry(Duration::from_secs(5)).expect("telemetry").is_some(),
        "telemetry flows before the host stops reading"
    );

    // The scenario is an absence (the host reads nothing), so it takes a fixed time: long
    // enough for the watchdog to have reset a stalled controller three times over. No state
    // of the firmware can be waited on instead, since the host is not listening.
    std::thread::sleep(DEAF);

    let after = client.status();
    let _ = std::fs::remove_file(&sock);
    let after = after.unwrap_or_else(|e| {
        panic!("the same session is answered after {DEAF:?} of not reading: {e}")
    });
    assert_eq!(after.reset_cause, before.reset_cause, "no reset: {after:?}");
    assert_eq!(after.fault, None, "no fault: {after:?}");
    assert_eq!((after.run, after.state), (run, DriveState::Running), "still driving: {after:?}");
    client.subscribe(100, 0).expect("end the stream");
    client.stop().expect("stop");
}
