//! `chladni serve` as a careless or hostile network sees it, without a controller behind it
//! (the link stays down; every front end still answers): start-up refusals of unsafe binds,
//! Modbus conformance by raw frames (exceptions where the spec gives them, the connection kept),
//! a flood of rejected writes that costs a few log lines, the client limit and allow-list, and
//! 1100 idle connections under `ulimit -n 1024` with slow headers cut off.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use serde_json::Value;

/// A controller port nobody listens on.
fn dead_port() -> String {
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    format!("tcp://{}", closed.local_addr().unwrap())
}

/// `chladni serve` (through `sh`, so that a `ulimit` can come first), killed when dropped; its
/// stderr is counted, and kept.
struct Serve {
    child: Child,
    modbus: Option<SocketAddr>,
    http: Option<SocketAddr>,
    stderr_bytes: Arc<AtomicUsize>,
    stderr: Arc<std::sync::Mutex<String>>,
}

impl Serve {
    fn start(prefix: &str, args: &[&str]) -> Serve {
        let bin = env!("CARGO_BIN_EXE_chladni");
        let line =
            format!("{prefix} exec {bin} serve --json --port {} {}", dead_port(), args.join(" "));
        let mut child = Command::new("/bin/sh")
            .args(["-c", &line])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stderr_bytes = Arc::new(AtomicUsize::new(0));
        let stderr = Arc::new(std::sync::Mutex::new(String::new()));
        let (count, keep) = (Arc::clone(&stderr_bytes), Arc::clone(&stderr));
        let mut err = child.stderr.take().unwrap();
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n @ 1..) = err.read(&mut buf) {
                count.fetch_add(n, Ordering::Relaxed);
                let mut kept = keep.lock().unwrap();
                if kept.len() < 100_000 {
                    kept.push_str(&String::from_utf8_lossy(&buf[..n]));
                }
            }
        });
        let mut out = BufReader::new(child.stdout.take().unwrap());
        let (mut modbus, mut http) = (None, None);
        let fronts = args.iter().filter(|a| matches!(**a, "--modbus" | "--http")).count();
        for _ in 0..fronts {
            let mut line = String::new();
            out.read_line(&mut line).unwrap();
            let v: Value =
                serde_json::from_str(line.trim()).unwrap_or_else(|e| panic!("{e}: {line}"));
            if let Some(m) = v["modbus"].as_str() {
                modbus = Some(m.parse().unwrap());
            }
            if let Some(h) = v["http"].as_str() {
                http = Some(h.trim_start_matches("http://").trim_end_matches('/').parse().unwrap());
            }
        }
        Serve { child, modbus, http, stderr_bytes, stderr }
    }

    fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `chladni serve ARGS`: its exit code and stderr.
fn refused(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_chladni"))
        .args(["serve", "--port", &dead_port()])
        .args(args)
        .output()
        .unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn unsafe_binds_are_refused_at_start_naming_the_fix() {
    let (code, text) = refused(&["--http", "0.0.0.0:0"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("--token-file") && text.contains("--no-auth"), "{text}");
    let (code, text) = refused(&["--modbus", "0.0.0.0:0"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("--modbus-allow") && text.contains("192.168.10.0/24"), "{text}");
    let (code, text) = refused(&["--modbus", "127.0.0.1:0", "--modbus-allow", "plc"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("'plc' is not a network"), "{text}");
    let (code, text) = refused(&["--http", "127.0.0.1:0", "--http-allow-origin", "evil"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("is not an origin"), "{text}");
}

/// One Modbus TCP request (transaction id `id`, unit 1); the answer's PDU.
fn modbus(stream: &mut TcpStream, id: u16, pdu: &[u8]) -> Vec<u8> {
    let mut frame = id.to_be_bytes().to_vec();
    frame.extend([0, 0]);
    frame.extend(u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    frame.push(1);
    frame.extend(pdu);
    stream.write_all(&frame).unwrap();
    let mut header = [0u8; 7];
    stream.read_exact(&mut header).unwrap();
    assert_eq!(u16::from_be_bytes([header[0], header[1]]), id);
    let mut answer = vec![0u8; usize::from(u16::from_be_bytes([header[4], header[5]])) - 1];
    stream.read_exact(&mut answer).unwrap();
    answer
}

fn connect(addr: SocketAddr) -> TcpStream {
    let stream = TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    stream
}

/// Whether the server closes `stream` within `within` (EOF or reset, after whatever answer it
/// sent first, such as a refusal): how long it took.
fn closed_within(stream: &mut TcpStream, within: Duration) -> Option<Duration> {
    let start = Instant::now();
    let mut buf = [0u8; 512];
    loop {
        let left = within.checked_sub(start.elapsed()).filter(|d| !d.is_zero())?;
        stream.set_read_timeout(Some(left)).unwrap();
        match stream.read(&mut buf) {
            Ok(0) => return Some(start.elapsed()),
            Ok(_) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return None;
            }
            Err(_) => return Some(start.elapsed()),
        }
    }
}

#[test]
fn modbus_answers_the_spec_exceptions_and_a_flood_costs_a_few_log_lines() {
    let serve = Serve::start("", &["--modbus", "127.0.0.1:0"]);
    let addr = serve.modbus.unwrap();
    let mut plc = connect(addr);
    let mut fc16_124 = vec![0x10, 0, 0, 0, 124, 248];
    fc16_124.extend([0u8; 248]);
    let cases: [(&str, Vec<u8>, [u8; 2]); 7] = [
        ("FC16 of 124 registers", fc16_124, [0x90, 0x03]),
        ("FC16 byte count 3 for 2 registers", vec![0x10, 0, 0, 0, 2, 3, 0, 1, 0], [0x90, 0x03]),
        ("FC05 value 0x1234", vec![0x05, 0, 0, 0x12, 0x34], [0x85, 0x03]),
        ("FC05 a coil value", vec![0x05, 0, 0, 0xFF, 0x00], [0x85, 0x01]),
        ("FC 0x2B MEI 0x0D", vec![0x2B, 0x0D, 0, 0], [0xAB, 0x01]),
        ("FC 0x01 read coils", vec![0x01, 0, 0, 0, 1], [0x81, 0x01]),
        ("FC04 of 126 registers", vec![0x04, 0, 0, 0, 126], [0x84, 0x03]),
    ];
    for (id, (what, pdu, expected)) in (1u16..).zip(cases) {
        let answer = modbus(&mut plc, id, &pdu);
        assert_eq!(answer, expected, "{what}: {answer:02x?}");
    }
    // The connection is kept: a good read after all of them.
    let answer = modbus(&mut plc, 100, &[0x03, 0, 0, 0, 3]);
    assert_eq!(answer, [0x03, 6, 0, 0, 0, 0, 0, 0]);
    let id = modbus(&mut plc, 101, &[0x2B, 0x0E, 1, 0]);
    assert_eq!(&id[..3], &[0x2B, 0x0E, 1]);

    // A second client while one is connected (--modbus-clients 1): closed at once.
    let mut second = connect(addr);
    assert!(
        closed_within(&mut second, Duration::from_secs(3)).is_some(),
        "a second client was kept"
    );

    // 5 s of rejected 123-register writes (past the 3 holding registers: 0x02).
    let before = serve.stderr_bytes.load(Ordering::Relaxed);
    let mut flood = vec![0x10, 0, 0, 0, 123, 246];
    flood.extend([0, 200]);
    flood.extend([0u8; 244]);
    let start = Instant::now();
    let mut answered = 0u32;
    while start.elapsed() < Duration::from_secs(5) {
        assert_eq!(modbus(&mut plc, 7, &flood), [0x90, 0x02]);
        answered += 1;
    }
    let logged = serve.stderr_bytes.load(Ordering::Relaxed) - before;
    eprintln!("{answered} rejected writes in 5 s logged {logged} bytes");
    assert!(answered > 500, "{answered}");
    assert!(logged < 2_000, "{logged} bytes of log for {answered} rejected writes");

    // Broken frames close the connection: a length promising 300 bytes at once, a frame that
    // promises 100 and sends 10 after the frame timeout.
    plc.write_all(&[0, 9, 0, 0, 0x01, 0x2C, 1, 0x03]).unwrap();
    assert!(closed_within(&mut plc, Duration::from_secs(3)).is_some(), "length 300 was kept");
    drop(plc);
    let mut slow = loop {
        // The client slot frees when the server has seen the close.
        let mut s = connect(addr);
        s.write_all(&[0, 1, 0, 0, 0, 100, 1, 0x10, 0, 0, 0, 2]).unwrap();
        if closed_within(&mut s, Duration::from_millis(300)).is_none() {
            break s;
        }
        assert!(start.elapsed() < Duration::from_secs(30), "no client slot came free");
    };
    let cut = closed_within(&mut slow, Duration::from_secs(6)).expect("a partial frame was held");
    eprintln!("a partial frame was cut after {cut:?} more");
    drop(serve);
}

#[test]
fn modbus_clients_outside_the_allow_list_are_closed() {
    let serve = Serve::start("", &["--modbus", "127.0.0.1:0", "--modbus-allow", "127.0.0.2/32"]);
    let mut stranger = connect(serve.modbus.unwrap());
    assert!(closed_within(&mut stranger, Duration::from_secs(3)).is_some());
    let start = Instant::now();
    while !serve.stderr.lock().unwrap().contains("not in the allow-list (127.0.0.2/32)") {
        assert!(start.elapsed() < Duration::from_secs(5), "{}", serve.stderr.lock().unwrap());
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `GET /api/status` on a new connection: the status code (0 if the connection failed).
fn status_code(addr: SocketAddr) -> u16 {
    let Ok(mut stream) = TcpStream::connect_timeout(&addr, Duration::from_secs(2)) else {
        return 0;
    };
    stream.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let request = format!("GET /api/status HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n");
    if stream.write_all(request.as_bytes()).is_err() {
        return 0;
    }
    let mut answer = String::new();
    let _ = stream.read_to_string(&mut answer);
    answer.get(9..12).and_then(|c| c.parse().ok()).unwrap_or(0)
}

/// Raises this test process's own open-file limit (it holds 1100 sockets and more).
fn raise_own_file_limit() {
    use nix::sys::resource::{Resource, getrlimit, setrlimit};
    let (_, hard) = getrlimit(Resource::RLIMIT_NOFILE).unwrap();
    assert!(hard >= 2_500, "this test needs an open-file hard limit of 2500, not {hard}");
    setrlimit(Resource::RLIMIT_NOFILE, hard, hard).unwrap();
}

#[test]
fn a_thousand_idle_connections_under_ulimit_1024_do_not_stop_the_server() {
    raise_own_file_limit();
    let mut serve =
        Serve::start("ulimit -n 1024;", &["--modbus", "127.0.0.1:0", "--http", "127.0.0.1:0"]);
    let (http, modbus) = (serve.http.unwrap(), serve.modbus.unwrap());
    assert_eq!(status_code(http), 200);
    let start = Instant::now();
    let mut idle: Vec<TcpStream> =
        (0..1000).filter_map(|_| TcpStream::connect(http).ok()).collect();
    idle.extend((0..100).filter_map(|_| TcpStream::connect(modbus).ok()));
    eprintln!("{} idle connections open after {:?}", idle.len(), start.elapsed());
    assert_eq!(idle.len(), 1100);
    // 20 clients sending their headers a byte every 300 ms.
    let mut slow: Vec<TcpStream> = (0..20).map(|_| TcpStream::connect(http).unwrap()).collect();
    // Serve keeps answering: within the overflow lane's header timeout at worst.
    let answered = (0..100).find_map(|_| {
        let code = status_code(http);
        (code == 200).then(|| start.elapsed()).or_else(|| {
            std::thread::sleep(Duration::from_millis(100));
            None
        })
    });
    let answered = answered.expect("no 200 from /api/status within 10 s of the flood");
    eprintln!("status answered 200 {answered:?} after the flood began");
    let drip = b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n";
    let mut cut = vec![None; slow.len()];
    for i in 0..drip.len() {
        for (stream, cut) in slow.iter_mut().zip(cut.iter_mut()) {
            if cut.is_none() && stream.write_all(&drip[i..=i]).is_err() {
                *cut = Some(start.elapsed());
            }
        }
        if cut.iter().all(Option::is_some) {
            break;
        }
        std::thread::sleep(Duration::from_millis(300));
    }
    // Whatever the writes saw, the server must have closed every slow client by now.
    for stream in &mut slow {
        assert!(closed_within(stream, Duration::from_secs(5)).is_some(), "a slow client was kept");
    }
    eprintln!("slow-header clients cut off after {:?}", start.elapsed());
    // The idle ones too (header timeout 10 s), and the server is still up and answering.
    // (The first Modbus one, number 1000, holds the client slot: Modbus's idle timeout is 30 s.)
    let mut kept = Vec::new();
    for (i, stream) in idle.iter_mut().enumerate().step_by(50).filter(|(i, _)| *i != 1000) {
        if closed_within(stream, Duration::from_secs(12)).is_none() {
            kept.push(i);
        }
    }
    assert!(kept.is_empty(), "idle connections {kept:?} still open after {:?}", start.elapsed());
    assert!(serve.alive(), "serve ended: {}", serve.stderr.lock().unwrap());
    assert_eq!(status_code(http), 200);
    drop(idle);
    // Unflooded, a client dripping its headers a byte every 500 ms is cut at the header
    // timeout (10 s), long before it would finish.
    let mut drip_one = TcpStream::connect(http).unwrap();
    let dripping = Instant::now();
    for byte in drip.iter().cycle().take(60) {
        if drip_one.write_all(&[*byte]).is_err() {
            break;
        }
        if closed_within(&mut drip_one, Duration::from_millis(500)).is_some() {
            break;
        }
    }
    let cut_after = dripping.elapsed();
    eprintln!("an unflooded slow-header client was cut after {cut_after:?}");
    assert!(cut_after < Duration::from_secs(15), "{cut_after:?}");
    let mut plc = connect(modbus);
    let deadline = Instant::now() + Duration::from_secs(40);
    // The Modbus client slot frees once the one idle client that held it is closed (30 s).
    loop {
        plc.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        let mut frame = vec![0, 1, 0, 0, 0, 6, 1, 0x04, 0, 0, 0, 1];
        if plc.write_all(&frame).is_ok() {
            frame.clear();
            let mut answer = [0u8; 11];
            if plc.read_exact(&mut answer).is_ok() {
                assert_eq!(answer[7], 0x04);
                break;
            }
        }
        assert!(Instant::now() < deadline, "modbus never answered after the flood");
        std::thread::sleep(Duration::from_millis(200));
        plc = connect(modbus);
    }
    let text = serve.stderr.lock().unwrap().clone();
    assert!(!text.contains("Too many open files") || serve.alive(), "{text}");
    eprintln!("serve stderr after the flood: {} bytes", serve.stderr_bytes.load(Ordering::Relaxed));
}
