//! Stop latency of `chladni serve` under front-end load: how long a stop takes from the request
//! to the controller's acceptance, idle and with 60 HTTP clients reading the plan list in a
//! loop and 50 Modbus clients writing run commands, against the controller in QEMU. Also the
//! heartbeat (status reads a second) in both phases: the poll must keep its 100 ms rate.
//!
//! `cargo bench -p chladni --bench cell_stop` (about a minute; numbers in docs/cell.md).
//! `CELL_BENCH_STOPS=N` sets the stops per phase (default 100). A bench binary, not criterion:
//! the interesting figure is the tail (p99) under a load that runs for the whole phase.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use chladni_cell::{Cell, http, modbus};
use chladni_device::emulator::{Emulator, EmulatorConfig};
use chladni_shared::icd::plan::{Level, Plan, Step};

/// One HTTP/1.1 request on a new connection; the status code (0: failed) and the body.
fn request(addr: SocketAddr, head: &str, body: &str) -> (u16, String) {
    let Ok(mut s) = TcpStream::connect(addr) else { return (0, String::new()) };
    let _ = s.set_read_timeout(Some(Duration::from_secs(20)));
    let text = format!(
        "{head} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\n\r\n{body}",
        body.len()
    );
    if s.write_all(text.as_bytes()).is_err() {
        return (0, String::new());
    }
    let mut answer = String::new();
    let _ = s.read_to_string(&mut answer);
    let code = answer.get(9..12).and_then(|c| c.parse().ok()).unwrap_or(0);
    (code, answer.split_once("\r\n\r\n").map(|(_, b)| b.to_owned()).unwrap_or_default())
}

fn heartbeat(addr: SocketAddr) -> u64 {
    let (_, body) = request(addr, "GET /api/status", "");
    serde_json::from_str::<serde_json::Value>(&body)
        .ok()
        .and_then(|v| v["heartbeat"].as_u64())
        .unwrap_or(0)
}

/// `n` stops over HTTP, 100 ms apart: their latencies, ms, sorted.
fn stops(addr: SocketAddr, n: usize) -> Vec<f64> {
    let mut ms: Vec<f64> = (0..n)
        .map(|_| {
            let start = Instant::now();
            let (code, body) = request(addr, "POST /api/stop", "{}");
            assert_eq!(code, 200, "stop: {body}");
            let took = start.elapsed().as_secs_f64() * 1e3;
            std::thread::sleep(Duration::from_millis(100));
            took
        })
        .collect();
    ms.sort_by(f64::total_cmp);
    ms
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// Runs `phase` while measuring the heartbeat: (stop latencies, status reads a second).
fn measured(addr: SocketAddr, n: usize) -> (Vec<f64>, f64) {
    let (hb, start) = (heartbeat(addr), Instant::now());
    let ms = stops(addr, n);
    let rate = (heartbeat(addr) - hb) as f64 / start.elapsed().as_secs_f64();
    (ms, rate)
}

fn report(name: &str, ms: &[f64], rate: f64) {
    println!(
        "{name:>5}: stop p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms ({} stops); heartbeat {rate:.1}/s",
        quantile(ms, 0.5),
        quantile(ms, 0.99),
        ms[ms.len() - 1],
        ms.len()
    );
}

/// A Modbus client writing "run slot 0" (FC16 of slot, repeat, command) until `stop`.
fn modbus_writer(addr: SocketAddr, stop: Arc<AtomicBool>, answers: Arc<[AtomicU64; 3]>) {
    let Ok(mut s) = TcpStream::connect(addr) else { return };
    let _ = s.set_read_timeout(Some(Duration::from_secs(20)));
    let frame = [0, 1, 0, 0, 0, 13, 1, 0x10, 0, 0, 0, 3, 6, 0, 0, 0, 0, 0, 1];
    while !stop.load(Ordering::Relaxed) {
        let mut answer = [0u8; 9];
        if s.write_all(&frame).is_err() || s.read_exact(&mut answer).is_err() {
            return;
        }
        // 0x10: accepted; an exception 0x06 (busy: the run queue is full) or another.
        let kind = match (answer[7], answer[8]) {
            (0x10, _) => 0,
            (0x90, 0x06) => 1,
            _ => 2,
        };
        answers[kind].fetch_add(1, Ordering::Relaxed);
        if answer[7] == 0x10 {
            let mut rest = [0u8; 3];
            let _ = s.read_exact(&mut rest);
        }
    }
}

/// An HTTP client reading the plan list until `stop`.
fn plan_reader(addr: SocketAddr, stop: Arc<AtomicBool>, reads: Arc<AtomicU64>) {
    while !stop.load(Ordering::Relaxed) {
        if request(addr, "GET /api/plans", "").0 == 200 {
            reads.fetch_add(1, Ordering::Relaxed);
        }
    }
}

fn main() {
    let n: usize =
        std::env::var("CELL_BENCH_STOPS").ok().and_then(|v| v.parse().ok()).unwrap_or(100);
    let config = EmulatorConfig::scratch("cell-stop-bench", Duration::from_secs(900));
    let emu = Emulator::start(&config).expect("start the emulator");
    let step =
        |freq_mhz| Step { freq_mhz, level: Level::Drive(8_000), duration_ms: 30_000, ramp_ms: 50 };
    let plan = Plan {
        name: heapless::String::try_from("bench").unwrap(),
        repeat: 1,
        steps: heapless::Vec::from_slice(&[step(120_000), step(150_000)]).unwrap(),
    };
    emu.connect("cell_stop upload").unwrap().upload(&plan, Some(0), |_, _| {}).unwrap();

    let runtime =
        tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let cell = Cell::start(&emu.address(), "cell_stop bench");
    let (http_addr, modbus_addr) = runtime.block_on(async {
        let h = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let m = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addrs = (h.local_addr().unwrap(), m.local_addr().unwrap());
        tokio::spawn(http::serve(cell.clone(), h, http::Options::local()));
        let options = modbus::Options { clients: 64, ..modbus::Options::local() };
        tokio::spawn(modbus::serve(m, modbus::Registers::new(cell.clone()), options));
        addrs
    });
    let start = Instant::now();
    while !cell.status().link_up || cell.plans().is_err() {
        assert!(start.elapsed() < Duration::from_secs(20), "the link never came up");
        std::thread::sleep(Duration::from_millis(50));
    }
    let (code, body) = request(http_addr, "POST /api/run", r#"{"slot": 0}"#);
    assert_eq!(code, 200, "{body}");
    let (idle, idle_rate) = measured(http_addr, n);
    report("idle", &idle, idle_rate);

    let stop = Arc::new(AtomicBool::new(false));
    let reads = Arc::new(AtomicU64::new(0));
    let answers: Arc<[AtomicU64; 3]> = Arc::new(Default::default());
    let mut load = Vec::new();
    for _ in 0..60 {
        let (stop, reads) = (Arc::clone(&stop), Arc::clone(&reads));
        load.push(std::thread::spawn(move || plan_reader(http_addr, stop, reads)));
    }
    for _ in 0..50 {
        let (stop, answers) = (Arc::clone(&stop), Arc::clone(&answers));
        load.push(std::thread::spawn(move || modbus_writer(modbus_addr, stop, answers)));
    }
    std::thread::sleep(Duration::from_secs(1));
    let began = Instant::now();
    let (loaded, loaded_rate) = measured(http_addr, n);
    let secs = began.elapsed().as_secs_f64();
    stop.store(true, Ordering::Relaxed);
    for thread in load {
        let _ = thread.join();
    }
    report("load", &loaded, loaded_rate);
    let [ok, busy, other] = [0, 1, 2].map(|i| answers[i].load(Ordering::Relaxed));
    println!(
        "  load: {:.0} plan reads/s over 60 clients; Modbus run writes: {ok} accepted, {busy} \
         refused busy (queue full), {other} other, over 50 clients in {secs:.1} s",
        reads.load(Ordering::Relaxed) as f64 / secs
    );
}
