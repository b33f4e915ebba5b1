//! `chladni serve --http` against the QEMU controller: an operator's run through the dashboard
//! in headless Chromium (tests/cell/dashboard.py: the stored plan listed, Run, busy, done, the
//! acceleration plot drawn, screenshots in target/cell/), and the JSON API by plain HTTP
//! (shapes, a bad slot named, stop, and the error state once the controller is gone). Before
//! the operator's run, pages from elsewhere attack through the same browser
//! (tests/cell/cross_origin.py: a no-CORS fetch, a text/plain form POST, a JSON fetch, a
//! DNS-rebinding page): the pages ran and nothing ran on the controller. After it, a second
//! `serve` with `--token-file` refuses requests without the token, and the dashboard logs in
//! from the URL it printed, runs the plan and stops it.
//!
//! The same browser plays the camera's partner: a photo posted to `POST /api/verify` while the
//! dashboard is open shows there (its event) with the found outlines; then the photo route by
//! plain HTTP: a JPEG checked, the figure served, and the guard (a foreign Host or Origin, a
//! form's content type, an oversized body) and a body that is no photo refused by name.
//!
//! Needs Debian's chromium, chromium-driver and python3-selenium (scripts/install-deps.sh): a
//! machine without them fails here, naming the script, rather than skipping the test.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use chladni_core::model::plan_file::PlanFile;
use chladni_device::emulator::Emulator;
use chladni_shared::icd::plan::DeviceLimits;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

use crate::support;
use serde_json::Value;
use support::emu;

/// Two closed-loop steps of 3 s (the plot shows the level change).
const PLAN: &str = r#"{"name": "cell-http-2step", "repeat": 1, "steps": [
    {"freq_hz": 180, "accel_mps2": 15, "duration_ms": 3000, "ramp_ms": 300},
    {"freq_hz": 185, "accel_mps2": 25, "duration_ms": 3000, "ramp_ms": 300}]}"#;

fn upload_plan(emu: &Emulator) {
    let plan = PlanFile::parse(PLAN).unwrap().to_plan(&DeviceLimits::DEFAULT).unwrap();
    let summary = emu::upload(emu, &plan, 0);
    assert_eq!((summary.slot, summary.steps), (0, 2));
}

/// `chladni serve`, stopped with SIGTERM when dropped.
struct Serve {
    child: Child,
    addr: SocketAddr,
}

impl Serve {
    /// With more arguments; the URL printed (the login URL with a token).
    fn start_with(port: &str, args: &[&str]) -> (Serve, String) {
        let mut child = Command::new(env!("CARGO_BIN_EXE_chladni"))
            .args(["serve", "--port", port, "--http", "127.0.0.1:0"])
            .args(args)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let url = line.trim().strip_prefix("http listening on ").unwrap_or_else(|| {
            panic!("serve printed {line:?}, not `http listening on http://ADDR/`")
        });
        let addr = url.trim_start_matches("http://").split('/').next().unwrap().parse().unwrap();
        (Serve { addr, child }, url.to_owned())
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
    http_as(addr, None, head, body)
}

/// The same with a bearer token.
fn http_as(addr: SocketAddr, token: Option<&str>, head: &str, body: &str) -> (u16, Value) {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let auth = token.map_or(String::new(), |t| format!("Authorization: Bearer {t}\r\n"));
    let request = format!(
        "{head} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\nContent-Type: application/json\r\n\
         {auth}Content-Length: {}\r\n\r\n{body}",
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
        assert!(answer["message"].as_str().unwrap().contains(words), "{body}: {answer}");
    }
}

/// Another program holds the controller (it cleared a fault: a command that takes ownership):
/// the cell's run is refused, 409 naming the owner; once it lets go, nothing is left over.
fn refused_while_another_session_owns(emu: &Emulator, addr: SocketAddr) {
    let mut other = emu.connect("cli_serve_http other owner").unwrap();
    other.clear_fault().unwrap();
    let (code, answer) = http(addr, "POST /api/run", r#"{"slot": 0}"#);
    assert_eq!(code, 409, "{answer}");
    assert_eq!(answer["error"], "refused", "{answer}");
    let message = answer["message"].as_str().unwrap();
    assert!(message.contains("busy: cli_serve_http other owner holds it"), "{answer}");
    drop(other);
}

/// The operator's run in the browser (`stop`: stopped once busy; `photo`: posted first, and
/// its check seen on the page); what the script saw.
fn browser_run(url: &str, stop: bool, photo: Option<&Path>) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/cell/dashboard.py");
    let shots = screenshot_dir();
    let out = Command::new("/usr/bin/python3")
        .arg(&script)
        .args([url, "cell-http-2step"])
        .arg(&shots)
        .args(stop.then_some("stop"))
        .args(photo.map(|p| format!("photo={}", p.display())))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "dashboard.py failed: {stdout}\n{stderr}");
    assert!(shots.join("dashboard.png").is_file());
    serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"))
}

fn seen_beat(addr: SocketAddr) -> u64 {
    http(addr, "GET /api/status", "").1["heartbeat"].as_u64().unwrap()
}

/// Pages from elsewhere in the operator's browser: they ran, and nothing ran on the controller.
fn cross_origin_attacks_run_nothing(addr: SocketAddr) {
    // A status read after every earlier command (two polls later).
    let (_, now) = http(addr, "GET /api/status", "");
    let beat = now["heartbeat"].as_u64().unwrap();
    let before =
        status_until(addr, Duration::from_secs(3), |s| s["heartbeat"].as_u64() > Some(beat + 1));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/cell/cross_origin.py");
    let out = Command::new("/usr/bin/python3")
        .arg(&script)
        .arg(format!("http://{addr}/"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "cross_origin.py failed: {stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let seen: Value =
        serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    eprintln!("the attacking pages saw {seen}");
    // The page ran every attempt (an opaque no-CORS answer, the form's frame loaded, the JSON
    // fetch blocked by the browser for want of a CORS grant).
    let attempts = &seen["cross_origin"];
    assert_eq!(
        (&attempts["nocors"], &attempts["form"]),
        (&"sent".into(), &"submitted".into()),
        "{seen}"
    );
    assert!(attempts["json"].as_str().unwrap().starts_with("blocked"), "{seen}");
    assert!(attempts["photo"].as_str().unwrap().starts_with("blocked"), "{seen}");
    assert_eq!(attempts["photo_nocors"], "sent", "{seen}");
    let (code, none) = http(addr, "GET /api/verify", "");
    assert_eq!(code, 404, "a photo from another site was checked: {none}");
    assert!(
        seen["rebinding_page"].as_str().unwrap().contains("does not answer for host"),
        "{seen}"
    );
    assert!(seen["rebinding_run"].as_str().unwrap().starts_with("421"), "{seen}");
    let beat = seen_beat(addr);
    let after =
        status_until(addr, Duration::from_secs(3), |s| s["heartbeat"].as_u64() > Some(beat + 1));
    assert_eq!(after["device"]["run"], before["device"]["run"], "something ran: {after}");
    assert_eq!(after["state"], "idle", "{after}");
}

/// A second server with a token: refused without it; the dashboard logs in from the printed
/// URL, runs the plan and stops it. The server is handed back for the lost-link checks.
fn token_login_runs_and_stops(emu: &Emulator) -> (Serve, String) {
    let file = screenshot_dir().join("serve-token");
    let _ = std::fs::create_dir_all(screenshot_dir());
    let _ = std::fs::remove_file(&file);
    let (serve, login) =
        Serve::start_with(&emu.address(), &["--token-file", file.to_str().unwrap()]);
    let token = std::fs::read_to_string(&file).unwrap().trim().to_owned();
    assert_eq!(login, format!("http://{}/?token={token}", serve.addr));
    let (code, refused) = http(serve.addr, "GET /api/status", "");
    assert_eq!(code, 401, "{refused}");
    let (code, refused) = http(serve.addr, "POST /api/run", r#"{"slot": 0}"#);
    assert_eq!(code, 401, "{refused}");
    let up = Instant::now();
    while http_as(serve.addr, Some(&token), "GET /api/status", "").1["state"] != "idle" {
        assert!(up.elapsed() < Duration::from_secs(10), "the token server never read idle");
        std::thread::sleep(Duration::from_millis(100));
    }
    let seen = browser_run(&login, true, None);
    eprintln!("the logged-in dashboard saw {seen}");
    assert!(seen["message"].as_str().unwrap().contains("run"), "{seen}");
    (serve, token)
}

#[test]
fn the_dashboard_runs_a_stored_plan_and_the_api_reports_a_lost_link() {
    require_browser();
    let mut emu = emu::emulator_for("cli-serve-http", Duration::from_secs(120));
    upload_plan(&emu);
    let verify = support::photos::serve_args();
    let verify: Vec<&str> = verify.iter().map(String::as_str).collect();
    let mut serve = Serve::start_with(&emu.address(), &verify).0;
    let addr = serve.addr;
    let up = status_until(addr, Duration::from_secs(10), |s| s["state"] == "idle");
    assert_eq!(up["link_up"], true, "{up}");
    assert_eq!(up["device"]["state"], "idle", "{up}");
    check_api_requests(addr);
    refused_while_another_session_owns(&emu, addr);
    cross_origin_attacks_run_nothing(addr);
    // One meaning of repeat 0 on both front ends: the plan's own count.
    let (code, zero) = http(addr, "POST /api/run", r#"{"slot": 0, "repeat": 0}"#);
    assert_eq!(code, 200, "{zero}");
    let (code, stopped) = http(addr, "POST /api/stop", "{}");
    assert_eq!(code, 200, "{stopped}");
    status_until(addr, Duration::from_secs(5), |s| s["state"] == "idle");

    std::fs::create_dir_all(screenshot_dir()).unwrap();
    let photo = screenshot_dir().join("verify-photo.png");
    support::photos::one_good_one_off().save(&photo).unwrap();
    let seen = browser_run(&serve.url(), false, Some(&photo));
    check_seen_photo(&seen["verify"]);
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
    check_photo_route(addr, &photo);
    // This server owns the controller while it serves, and releases it as it stops: the next
    // client owns it at once, not after the lease.
    assert_eq!(serve.terminate(), Some(0));
    let mut next = emu.connect("cli_serve_http next owner").unwrap();
    next.clear_fault().expect("the stopped server released the controller");
    drop(next);
    let (mut serve, token) = token_login_runs_and_stops(&emu);
    let addr = serve.addr;

    // A power cut: the proxy stays, nothing answers.
    emu.kill();
    let start = Instant::now();
    let lost = loop {
        let (_, status) = http_as(addr, Some(&token), "GET /api/status", "");
        if status["state"] == "error" || start.elapsed() > Duration::from_secs(8) {
            break status;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!((&lost["state"], &lost["link_up"]), (&"error".into(), &false.into()), "{lost}");
    assert!(lost["error"].as_str().unwrap().contains("controller link down"), "{lost}");
    let (code, refused) = http_as(addr, Some(&token), "POST /api/run", r#"{"slot": 0}"#);
    assert_eq!(code, 503, "{refused}");
    assert!(refused["message"].as_str().unwrap().contains("link is down"), "{refused}");
    assert_eq!(serve.terminate(), Some(0));
}

/// What the dashboard showed of the photo posted while it was open.
fn check_seen_photo(seen: &Value) {
    let posted = &seen["posted"];
    assert_eq!((&posted["seq"], &posted["result"]), (&1.into(), &"off".into()), "{seen}");
    assert_eq!((&posted["found"], &posted["oriented"]), (&2.into(), &1.into()), "{seen}");
    assert_eq!(seen["result"], "off", "{seen}");
    assert!(seen["summary"].as_str().unwrap().contains("1 of 2 parts as planned (50.0 %)"));
    let off = seen["parts_off"].as_array().unwrap();
    assert_eq!(off.len(), 1, "{seen}");
    assert!(off[0].as_str().unwrap().starts_with("key: θ"), "{seen}");
    // The outlines over the photo: green (as planned) and red (off), each a few hundred px.
    let outlines = &seen["outlines"];
    assert!(outlines["width"].as_u64().unwrap() > 500, "{seen}");
    assert!(outlines["green"].as_u64().unwrap() > 200, "{seen}");
    assert!(outlines["red"].as_u64().unwrap() > 200, "{seen}");
}

/// One request with a byte body and the given headers (Host is the server's unless given):
/// the status and the body as JSON.
fn post_bytes(addr: SocketAddr, headers: &[&str], body: &[u8]) -> (u16, Value) {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let mut head = "POST /api/verify HTTP/1.1\r\nConnection: close\r\n".to_string();
    if !headers.iter().any(|h| h.starts_with("Host:")) {
        head.push_str("Host: 127.0.0.1\r\n");
    }
    for h in headers {
        head.push_str(h);
        head.push_str("\r\n");
    }
    if !headers.iter().any(|h| h.starts_with("Content-Length:")) {
        head.push_str(&format!("Content-Length: {}\r\n", body.len()));
    }
    head.push_str("\r\n");
    stream.write_all(head.as_bytes()).unwrap();
    // A refused body may be cut off: the answer is read whatever happened to it.
    let _ = stream.write_all(body);
    let mut answer = Vec::new();
    let _ = stream.read_to_end(&mut answer);
    let answer = String::from_utf8_lossy(&answer);
    let (head, body) = answer.split_once("\r\n\r\n").unwrap_or_else(|| panic!("{answer}"));
    let json = serde_json::from_str(body).unwrap_or_else(|e| panic!("{head}: {e}: {body}"));
    (head[9..12].parse().unwrap(), json)
}

/// The photo route by plain HTTP: a JPEG checked (the second photo), the last one and its
/// figure read back, and every refusal named.
fn check_photo_route(addr: SocketAddr, png: &Path) {
    let img = image::open(png).unwrap();
    let mut jpeg = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut jpeg), image::ImageFormat::Jpeg).unwrap();
    let (code, v) = post_bytes(addr, &["Content-Type: image/jpeg"], &jpeg);
    assert_eq!(code, 200, "{v}");
    assert_eq!((&v["seq"], &v["result"], &v["oriented"]), (&2.into(), &"off".into(), &1.into()));
    let (code, last) = http(addr, "GET /api/verify", "");
    assert_eq!((code, &last["seq"]), (200, &2.into()), "{last}");
    let mut stream = TcpStream::connect(addr).unwrap();
    write!(
        stream,
        "GET /api/verify/photo.png HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut answer = Vec::new();
    stream.read_to_end(&mut answer).unwrap();
    let split = answer.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let head = String::from_utf8_lossy(&answer[..split]).to_ascii_lowercase();
    assert!(head.starts_with("http/1.1 200") && head.contains("content-type: image/png"), "{head}");
    let fig = image::load_from_memory(&answer[split + 4..]).unwrap();
    assert!(fig.width() > 500, "{}", fig.width());
    let bytes = std::fs::read(png).unwrap();
    for (headers, status, words) in [
        (vec!["Content-Type: image/png", "Host: evil.example"], 421, "--http-allow-host"),
        (vec!["Content-Type: image/png", "Origin: http://evil.example"], 403, "origin"),
        (vec!["Content-Type: text/plain"], 415, "image/png"),
        (vec!["Content-Type: application/json"], 415, "image/jpeg"),
        (vec!["Content-Type: image/png", "Content-Length: 40000000"], 413, "over the 16 MiB"),
    ] {
        let (code, v) = post_bytes(addr, &headers, &bytes);
        assert_eq!(code, status, "{headers:?}: {v}");
        assert!(v["message"].as_str().unwrap().contains(words), "{headers:?}: {v}");
    }
    let (_, last) = http(addr, "GET /api/verify", "");
    assert_eq!(last["seq"], 2, "a refused request was checked: {last}");
    // Not a photo: refused by name, and published (a PLC must not read the old result).
    let (code, v) = post_bytes(addr, &["Content-Type: image/png"], b"not a photo at all");
    assert_eq!((code, &v["error"], &v["seq"]), (422, &"not_a_photo".into(), &3.into()), "{v}");
    let (_, last) = http(addr, "GET /api/verify", "");
    assert_eq!((&last["seq"], &last["result"]), (&3.into(), &"refused".into()), "{last}");
}
