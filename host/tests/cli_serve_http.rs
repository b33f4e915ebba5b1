//! `chladni serve --http` against the QEMU controller: an operator's run through the dashboard
//! in headless Chromium (tests/cell/dashboard.py: the stored plan listed, Run, busy, done, the
//! acceleration plot drawn, screenshots in target/cell/), and the JSON API by plain HTTP
//! (shapes, a bad slot named, stop, and the error state once the controller is gone).
//!
//! Needs Debian's chromium, chromium-driver and python3-selenium (scripts/install-deps.sh): a
//! machine without them fails here, naming the script, rather than skipping the test.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use chladni::controller::emulator::{Emulator, EmulatorConfig};
use chladni::model::plan_file::PlanFile;
use chladni_shared::icd::plan::DeviceLimits;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use serde_json::Value;

/// Two closed-loop steps of 3 s (the plot shows the level change).
const PLAN: &str = r#"{"name": "cell-http-2step", "repeat": 1, "steps": [
    {"freq_hz": 180, "accel_mps2": 15, "duration_ms": 3000, "ramp_ms": 300},
    {"freq_hz": 185, "accel_mps2": 25, "duration_ms": 3000, "ramp_ms": 300}]}"#;

fn emulator() -> Emulator {
    let config = EmulatorConfig::scratch("cli-serve-http", Duration::from_secs(120));
    Emulator::start(&config).expect("start the emulator")
}

fn upload_plan(emu: &Emulator) {
    let plan = PlanFile::parse(PLAN).unwrap().to_plan(&DeviceLimits::DEFAULT).unwrap();
    let mut client = emu.connect("cli_serve_http upload").unwrap();
    let summary = client.upload(&plan, Some(0), |_, _| {}).unwrap();
    assert_eq!((summary.slot, summary.steps), (0, 2));
}

/// `chladni serve`, stopped with SIGTERM when dropped.
struct Serve {
    child: Child,
    addr: SocketAddr,
}

impl Serve {
    fn start(port: &str) -> Serve {
        let mut child = Command::new(env!("CARGO_BIN_EXE_chladni"))
            .args(["serve", "--port", port, "--http", "127.0.0.1:0"])
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let url = line.trim().strip_prefix("http listening on http://").unwrap_or_else(|| {
            panic!("serve printed {line:?}, not `http listening on http://ADDR/`")
        });
        Serve { addr: url.trim_end_matches('/').parse().unwrap(), child }
    }

    fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// SIGTERM, and the exit code.
    fn terminate(&mut self) -> Option<i32> {
        let _ = kill(Pid::from_raw(self.child.id() as i32), Signal::SIGTERM);
        self.child.wait().unwrap().code()
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            self.terminate();
        }
    }
}

/// One HTTP/1.1 request (`Connection: close`): the status and the body as JSON.
fn http(addr: SocketAddr, head: &str, body: &str) -> (u16, Value) {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let request = format!(
        "{head} HTTP/1.1\r\nHost: test\r\nConnection: close\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\n\r\n{body}",
        body.len()
    );
    stream.write_all(request.as_bytes()).unwrap();
    let mut answer = String::new();
    stream.read_to_string(&mut answer).unwrap();
    let (head, body) = answer.split_once("\r\n\r\n").unwrap();
    let json = serde_json::from_str(body).unwrap_or_else(|e| panic!("{head}: {e}: {body}"));
    (head[9..12].parse().unwrap(), json)
}

/// Polls `/api/status` until `check` holds; the last status either way.
fn status_until(addr: SocketAddr, within: Duration, check: impl Fn(&Value) -> bool) -> Value {
    let start = Instant::now();
    loop {
        let (code, status) = http(addr, "GET /api/status", "");
        assert_eq!(code, 200, "{status}");
        if check(&status) || start.elapsed() > within {
            return status;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Fails naming scripts/install-deps.sh when the browser or its driver is missing.
fn require_browser() {
    let missing: Vec<&str> =
        [("/usr/bin/chromium", "chromium"), ("/usr/bin/chromedriver", "chromium-driver")]
            .into_iter()
            .filter(|(path, _)| !Path::new(path).exists())
            .map(|(_, package)| package)
            .chain(selenium_missing().then_some("python3-selenium"))
            .collect();
    assert!(
        missing.is_empty(),
        "the dashboard test needs Debian's {}: run scripts/install-deps.sh",
        missing.join(", ")
    );
}

fn selenium_missing() -> bool {
    let import = Command::new("/usr/bin/python3").args(["-c", "import selenium"]).output();
    !import.is_ok_and(|out| out.status.success())
}

/// Where the screenshots go: target/cell/ beside the binary's target/debug/.
fn screenshot_dir() -> PathBuf {
    let bin = Path::new(env!("CARGO_BIN_EXE_chladni"));
    bin.parent().and_then(Path::parent).unwrap().join("cell")
}

/// The API before the browser: the plan listed, bad requests named.
fn check_api_requests(addr: SocketAddr) {
    let (code, plans) = http(addr, "GET /api/plans", "");
    assert_eq!(code, 200, "{plans}");
    assert_eq!(plans["plans"][0]["name"], "cell-http-2step");
    assert_eq!(plans["plans"][0]["steps"], 2);
    assert_eq!(plans["plans"][0]["total_ms"], 6000);
    for (body, code, words) in [
        (r#"{"slot": 300}"#, 422, "slot 300 does not exist"),
        (r#"{"slot": 7}"#, 422, "slot 7 holds no plan (stored: 0)"),
        (r#"{"slot": "zero"}"#, 400, "slot \"zero\" is not a slot number"),
        ("{}", 400, "\"slot\" is missing"),
    ] {
        let (got, answer) = http(addr, "POST /api/run", body);
        assert_eq!(got, code, "{body}: {answer}");
        assert!(answer["error"].as_str().unwrap().contains(words), "{body}: {answer}");
    }
}

/// Another program holds the controller (it cleared a fault: a command that takes ownership):
/// the cell's run is refused, 409 naming the owner; once it lets go, nothing is left over.
fn refused_while_another_session_owns(emu: &Emulator, addr: SocketAddr) {
    let mut other = emu.connect("cli_serve_http other owner").unwrap();
    other.clear_fault().unwrap();
    let (code, answer) = http(addr, "POST /api/run", r#"{"slot": 0}"#);
    assert_eq!(code, 409, "{answer}");
    let error = answer["error"].as_str().unwrap();
    assert!(error.contains("busy: cli_serve_http other owner holds it"), "{answer}");
    drop(other);
}

/// The operator's run in the browser; what the script saw.
fn browser_run(url: &str) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/cell/dashboard.py");
    let shots = screenshot_dir();
    let out = Command::new("/usr/bin/python3")
        .arg(&script)
        .args([url, "cell-http-2step"])
        .arg(&shots)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "dashboard.py failed: {stdout}\n{stderr}");
    assert!(shots.join("dashboard.png").is_file());
    serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"))
}

#[test]
fn the_dashboard_runs_a_stored_plan_and_the_api_reports_a_lost_link() {
    require_browser();
    let mut emu = emulator();
    upload_plan(&emu);
    let mut serve = Serve::start(&emu.address());
    let addr = serve.addr;
    let up = status_until(addr, Duration::from_secs(10), |s| s["state"] == "idle");
    assert_eq!(up["link_up"], true, "{up}");
    assert_eq!(up["device"]["state"], "idle", "{up}");
    check_api_requests(addr);
    refused_while_another_session_owns(&emu, addr);

    let seen = browser_run(&serve.url());
    assert!(seen["busy_after_s"].as_f64().unwrap() < 2.0, "{seen}");
    // The plan is 6 s: done when it ended, not before (6.5-7 s measured; slack for a loaded
    // machine, where QEMU's controller runs late).
    let done_after = seen["done_after_s"].as_f64().unwrap();
    assert!((5.5..15.0).contains(&done_after), "{seen}");
    assert!(seen["points_busy"].as_u64().unwrap() >= 20, "{seen}");

    let done = status_until(addr, Duration::from_secs(2), |s| s["state"] == "done");
    assert_eq!(done["state"], "done", "{done}");
    assert_eq!(done["slot"], 0);
    assert_eq!(done["last_run"], done["device"]["run"], "{done}");
    let (code, stopped) = http(addr, "POST /api/stop", "");
    assert_eq!(code, 200, "{stopped}");
    assert!(stopped["run"].as_u64().unwrap() > done["last_run"].as_u64().unwrap());
    let idle = status_until(addr, Duration::from_secs(3), |s| s["state"] == "idle");
    assert_eq!(idle["state"], "idle", "{idle}");

    // A power cut: the proxy stays, nothing answers.
    emu.kill();
    let lost = status_until(addr, Duration::from_secs(8), |s| s["state"] == "error");
    assert_eq!((&lost["state"], &lost["link_up"]), (&"error".into(), &false.into()), "{lost}");
    assert!(lost["error"].as_str().unwrap().contains("controller link down"), "{lost}");
    let (code, refused) = http(addr, "POST /api/run", r#"{"slot": 0}"#);
    assert_eq!(code, 503, "{refused}");
    assert!(refused["error"].as_str().unwrap().contains("link is down"), "{refused}");
    assert_eq!(serve.terminate(), Some(0));
}
