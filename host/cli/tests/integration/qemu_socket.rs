//! Evidence for the emulator's link proxy (issue 11, defect 1): how QEMU's
//! `-chardev socket,server=on` treats a second TCP client, measured on QEMU itself, and the
//! same through `Emulator` (the proxy in front of QEMU).
//!
//! The probe is a frame of garbage that every firmware of every protocol version answers with
//! an error frame, so the measurement does not depend on the protocol.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use chladni_device::emulator::qemu_command_line;
use chladni_device::firmware;
use chladni_device::proxy::FrameSplitter;
use chladni_shared::icd::link::Board;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

use crate::support;

const PROBE: [u8; 5] = [0, 1, 2, 3, 0];

/// QEMU started by hand (no proxy), under `timeout` so it cannot outlive the test.
struct Qemu(Child);

impl Drop for Qemu {
    fn drop(&mut self) {
        // SIGTERM to `timeout` is forwarded to QEMU.
        let _ = kill(Pid::from_raw(self.0.id() as i32), Signal::SIGTERM);
        let _ = self.0.wait();
    }
}

/// Waits up to `within` for one whole frame on `stream`; the time it took, if one came.
fn answer_within(stream: &mut TcpStream, within: Duration) -> Option<Duration> {
    let start = Instant::now();
    let mut splitter = FrameSplitter::default();
    let mut buf = [0u8; 512];
    while start.elapsed() < within {
        stream.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        if let Ok(n) = stream.read(&mut buf) {
            let mut frames = 0;
            splitter.push(&buf[..n], |_| frames += 1);
            if frames > 0 {
                return Some(start.elapsed());
            }
            if n == 0 {
                return None;
            }
        }
    }
    None
}

/// A first client that the firmware answers (QEMU and the firmware take a moment to boot).
fn first_client(port: u16) -> TcpStream {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        if let Ok(mut a) = TcpStream::connect(("127.0.0.1", port)) {
            a.write_all(&PROBE).unwrap();
            if answer_within(&mut a, Duration::from_millis(500)).is_some() {
                return a;
            }
        }
        assert!(Instant::now() < deadline, "QEMU never answered on port {port}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn qemus_socket_serves_one_client_and_runs_a_waiting_clients_bytes_late() {
    let elf = firmware::build(Board::Qemu).expect("build the QEMU firmware");
    let port = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let _qemu = Qemu(
        Command::new("timeout")
            .arg("120")
            .arg("qemu-system-arm")
            .args(qemu_command_line(&elf, port, None))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start QEMU"),
    );
    let mut a = first_client(port);

    let connecting = Instant::now();
    let mut b = TcpStream::connect(("127.0.0.1", port)).expect("a second connect succeeds");
    let connect_took = connecting.elapsed();
    b.write_all(&PROBE).unwrap();
    let sent = Instant::now();
    let hold = Duration::from_secs(2);
    assert_eq!(answer_within(&mut b, hold), None, "QEMU answered a second client at once");
    a.write_all(&PROBE).unwrap();
    assert!(answer_within(&mut a, Duration::from_secs(1)).is_some(), "A is still served");

    drop(a);
    let after_leave =
        answer_within(&mut b, Duration::from_secs(5)).expect("B's bytes are run once A leaves");
    let late = sent.elapsed();
    println!(
        "QEMU socket: second connect took {connect_took:?}; no answer for {hold:?} while the \
         first client held the socket; answered {after_leave:?} after it left, {late:?} after \
         it was sent"
    );
    assert!(after_leave < Duration::from_secs(1) && late > hold);
}

#[test]
fn through_the_proxy_a_second_client_is_answered_at_once() {
    let emulator = support::emu::emulator_for("qemu-socket-proxy", Duration::from_secs(120));
    let mut a = first_client(emulator.port());
    let mut b = TcpStream::connect(("127.0.0.1", emulator.port())).unwrap();
    // The proxy takes B on before B's request is timed.
    let deadline = Instant::now() + Duration::from_secs(5);
    while emulator.clients() < 2 {
        assert!(Instant::now() < deadline, "the proxy never took the second client on");
        std::thread::sleep(Duration::from_millis(2));
    }
    b.write_all(&PROBE).unwrap();
    let took = answer_within(&mut b, Duration::from_secs(2)).expect("B answered while A is on");
    println!("through the proxy: the second client was answered after {took:?}");
    assert!(took < Duration::from_secs(1));
    a.write_all(&PROBE).unwrap();
    assert!(answer_within(&mut a, Duration::from_secs(1)).is_some(), "A is still served");
}
