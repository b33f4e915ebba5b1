//! The HTTP front end without a controller: request validation, error statuses and the JSON
//! shapes, through a real server on loopback and a cell whose link cannot open (the QEMU
//! controller is exercised in host/cli/tests/integration/cli_serve_http.rs).

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};

use chladni_shared::icd::link::Refusal;
use tokio::runtime::Runtime;

use super::*;
use crate::CellError;
use chladni_device::client::DeviceError;

#[test]
fn a_run_request_takes_a_slot_and_an_optional_repeat() {
    assert_eq!(RunRequest::parse(br#"{"slot": 3}"#), Ok(RunRequest { slot: 3, repeat: None }));
    assert_eq!(
        RunRequest::parse(br#"{"slot": 0, "repeat": 7}"#),
        Ok(RunRequest { slot: 0, repeat: Some(7) })
    );
    assert_eq!(
        RunRequest::parse(br#"{"slot": 1, "repeat": null}"#),
        Ok(RunRequest { slot: 1, repeat: None })
    );
}

/// The error of a body, which must be `status` and name every one of `words`.
fn rejected(body: &str, status: StatusCode, words: &[&str]) {
    let e = RunRequest::parse(body.as_bytes()).unwrap_err();
    assert_eq!(e.status, status, "{body}: {}", e.message);
    for word in words {
        assert!(e.message.contains(word), "{body}: {} lacks {word}", e.message);
    }
}

#[test]
fn a_bad_run_request_is_rejected_naming_the_value_and_the_fix() {
    let bad = StatusCode::BAD_REQUEST;
    rejected("", bad, &["not JSON", r#"{"slot": N}"#]);
    rejected("slot=3", bad, &["not JSON", "GET /api/plans"]);
    rejected("[3]", bad, &["[3]", "not a JSON object"]);
    rejected("{}", bad, &["\"slot\" is missing"]);
    rejected(r#"{"slto": 3}"#, bad, &["unknown key \"slto\""]);
    rejected(r#"{"slot": "3"}"#, bad, &["slot \"3\" is not a slot number"]);
    rejected(r#"{"slot": -1}"#, bad, &["slot -1", "whole numbers 0.."]);
    rejected(r#"{"slot": 2.5}"#, bad, &["slot 2.5"]);
    rejected(r#"{"slot": 1, "repeat": 70000}"#, bad, &["repeat 70000", "0..65535"]);
    rejected(r#"{"slot": 1, "repeat": -2}"#, bad, &["repeat -2"]);
    rejected(
        r#"{"slot": 5000000000}"#,
        StatusCode::UNPROCESSABLE_ENTITY,
        &["slot 5000000000 does not exist"],
    );
}

#[test]
fn cell_errors_map_to_statuses_by_kind() {
    let status = |e: CellError| ApiError::from(e).status;
    assert_eq!(status(CellError::BadSlot { slot: 40 }), StatusCode::UNPROCESSABLE_ENTITY);
    let no_plan = CellError::NoPlan { slot: 2, stored: "0, 1".into() };
    assert_eq!(status(no_plan), StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(status(CellError::LinkDown { reason: "x".into() }), StatusCode::SERVICE_UNAVAILABLE);
    let busy = Refusal::Busy { owner: heapless::String::new(), idle_ms: 5 };
    assert_eq!(status(CellError::Device(DeviceError::Refused(busy))), StatusCode::CONFLICT);
    assert_eq!(status(CellError::Device(DeviceError::Closed)), StatusCode::SERVICE_UNAVAILABLE);
    // The message is the cell's own, which names the value and the fix.
    let e = ApiError::from(CellError::NoPlan { slot: 2, stored: "0, 1".into() });
    assert!(e.message.contains("slot 2 holds no plan (stored: 0, 1)"), "{}", e.message);
}

/// A server on loopback (on its own runtime, which the caller keeps) for a cell whose
/// controller port refuses connections.
fn server_without_controller() -> (Runtime, SocketAddr) {
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = format!("tcp://{}", closed.local_addr().unwrap());
    drop(closed);
    let cell = Cell::start(&port, "http unit test");
    let runtime = Runtime::new().unwrap();
    let listener = runtime.block_on(tokio::net::TcpListener::bind("127.0.0.1:0")).unwrap();
    let addr = listener.local_addr().unwrap();
    runtime.spawn(serve(cell, listener, Options::local()));
    (runtime, addr)
}

/// One HTTP/1.1 request on its own connection: the status and the body (`Connection: close`,
/// so the body is everything after the head). `stop_at` ends reading early, for streams.
fn request(addr: SocketAddr, head: &str, body: &str, stop_at: Option<&str>) -> (u16, String) {
    let mut stream = TcpStream::connect(addr).unwrap();
    let text = format!(
        "{head} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\
         Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    stream.write_all(text.as_bytes()).unwrap();
    let mut answer = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        let n = stream.read(&mut buf).unwrap();
        answer.extend_from_slice(&buf[..n]);
        let seen = String::from_utf8_lossy(&answer);
        if n == 0 || stop_at.is_some_and(|s| seen.contains(s)) {
            break;
        }
    }
    let answer = String::from_utf8(answer).unwrap();
    let (head, body) = answer.split_once("\r\n\r\n").unwrap();
    (head[9..12].parse().unwrap(), body.to_owned())
}

fn json_request(addr: SocketAddr, head: &str, body: &str) -> (u16, Value) {
    let (status, body) = request(addr, head, body, None);
    (status, serde_json::from_str(&body).unwrap_or_else(|e| panic!("{e}: {body}")))
}

#[test]
fn without_a_controller_the_api_answers_link_down_and_validates_requests() {
    let (_runtime, addr) = server_without_controller();
    let (code, status) = json_request(addr, "GET /api/status", "");
    assert_eq!(code, 200);
    assert_eq!(status["state"], "error");
    assert_eq!(status["link_up"], false);
    let keys: Vec<&str> = status.as_object().unwrap().keys().map(String::as_str).collect();
    assert_eq!(keys, ["device", "error", "heartbeat", "last_run", "link_up", "slot", "state"]);

    let (code, answer) = json_request(addr, "POST /api/run", r#"{"slot": 99}"#);
    assert_eq!(code, 422);
    assert!(answer["message"].as_str().unwrap().contains("slot 99 does not exist"), "{answer}");
    // The CLI's failure shape: the kind, the message, and the kind's own fields.
    assert_eq!((&answer["error"], &answer["slot"]), (&Value::from("bad_slot"), &Value::from(99)));
    let (code, answer) = json_request(addr, "POST /api/run", "{}");
    assert_eq!(code, 400, "{answer}");
    for (head, body) in
        [("POST /api/run", r#"{"slot": 0}"#), ("GET /api/plans", ""), ("POST /api/stop", "")]
    {
        let (code, answer) = json_request(addr, head, body);
        assert_eq!(code, 503, "{head}: {answer}");
        assert!(answer["message"].as_str().unwrap().contains("link is down"), "{answer}");
        assert_eq!(answer["error"], "link_down", "{answer}");
    }
}

#[test]
fn unknown_routes_and_methods_answer_json_naming_the_routes() {
    let (_runtime, addr) = server_without_controller();
    let (code, answer) = json_request(addr, "GET /api/nothing", "");
    assert_eq!(code, 404);
    assert!(answer["message"].as_str().unwrap().contains("no route GET /api/nothing"));
    assert_eq!(answer["error"], "not_found");
    assert!(answer["message"].as_str().unwrap().contains("POST /api/run"));
    let (code, answer) = json_request(addr, "GET /api/run", "");
    assert_eq!(code, 405);
    assert!(answer["message"].as_str().unwrap().contains("/api/run does not take GET"));
}

#[test]
fn the_page_is_self_contained_and_the_events_stream_statuses() {
    let (_runtime, addr) = server_without_controller();
    let (code, page) = request(addr, "GET /", "", None);
    assert_eq!(code, 200);
    assert!(page.contains("<canvas") && page.contains("/api/events"));
    // No resource from elsewhere: the cell has no internet.
    assert!(!page.contains("http://") && !page.contains("https://") && !page.contains("//cdn"));
    let (code, stream) = request(addr, "GET /api/events", "", Some("\n\n"));
    assert_eq!(code, 200);
    let data = stream.lines().find_map(|l| l.strip_prefix("data: ")).unwrap();
    let status: Value = serde_json::from_str(data).unwrap();
    assert_eq!(status["state"], "error");
    assert!(stream.contains("event: status"));
}

/// A request with the given header lines (no defaults but `Connection: close` and the body's
/// length): the status, the head and the body.
fn raw(addr: SocketAddr, head: &str, headers: &[&str], body: &str) -> (u16, String, String) {
    let mut stream = TcpStream::connect(addr).unwrap();
    let mut text = format!("{head} HTTP/1.1\r\nConnection: close\r\n");
    for line in headers {
        text.push_str(line);
        text.push_str("\r\n");
    }
    text.push_str(&format!("Content-Length: {}\r\n\r\n{body}", body.len()));
    stream.write_all(text.as_bytes()).unwrap();
    // A refused body may end in a reset after the answer: keep what was read.
    let mut bytes = Vec::new();
    let _ = stream.read_to_end(&mut bytes);
    let answer = String::from_utf8_lossy(&bytes);
    let (head, body) = answer.split_once("\r\n\r\n").unwrap_or_else(|| panic!("{answer}"));
    (head[9..12].parse().unwrap(), head.to_owned(), body.to_owned())
}

/// The error message of a JSON error answer.
fn error_of(body: &str) -> String {
    let value: Value =
        serde_json::from_str(body).unwrap_or_else(|e| panic!("not JSON ({e}): {body}"));
    assert!(value["error"].is_string(), "no error kind: {body}");
    value["message"].as_str().unwrap_or_else(|| panic!("no message: {body}")).to_owned()
}

#[test]
fn commands_from_other_sites_and_foreign_hosts_are_refused_before_any_route() {
    let (_runtime, addr) = server_without_controller();
    let own = format!("Host: {addr}");
    // A form or a no-CORS fetch can only send these types: refused, whatever the body.
    for kind in
        ["text/plain", "application/x-www-form-urlencoded", "multipart/form-data; boundary=x"]
    {
        let content = format!("Content-Type: {kind}");
        let (code, _, body) = raw(addr, "POST /api/run", &[&own, &content], r#"{"slot":0}"#);
        assert_eq!(code, 415, "{kind}: {body}");
        assert!(error_of(&body).contains("application/json"), "{body}");
    }
    let (code, _, body) = raw(addr, "POST /api/stop", &[&own], "");
    assert_eq!(code, 415, "{body}");
    // JSON from a page of another origin.
    let json = "Content-Type: application/json";
    let evil = "Origin: http://evil.example";
    let (code, _, body) = raw(addr, "POST /api/run", &[&own, json, evil], r#"{"slot":0}"#);
    assert_eq!(code, 403, "{body}");
    let e = error_of(&body);
    assert!(e.contains("http://evil.example") && e.contains("--http-allow-origin"), "{e}");
    // The page's own origin passes (and meets the link that is down).
    let origin = format!("Origin: http://{addr}");
    let (code, _, body) = raw(addr, "POST /api/stop", &[&own, json, &origin], "{}");
    assert_eq!(code, 503, "{body}");
    // DNS rebinding: the attacker's name in Host, on reads and commands alike.
    for route in ["GET /api/status", "GET /", "GET /api/plans", "POST /api/stop"] {
        let rebound = format!("Host: evil.example:{}", addr.port());
        let (code, _, body) = raw(addr, route, &[&rebound, json], "{}");
        assert_eq!(code, 421, "{route}: {body}");
        assert!(error_of(&body).contains("--http-allow-host evil.example"), "{body}");
    }
    let (code, _, _) = raw(addr, "GET /api/status", &["Host: localhost"], "");
    assert_eq!(code, 200);
}

#[test]
fn limits_answer_json_too() {
    let (_runtime, addr) = server_without_controller();
    let own = format!("Host: {addr}");
    let json = "Content-Type: application/json";
    let big = format!(r#"{{"slot": 0, "pad": "{}"}}"#, "x".repeat(MAX_BODY));
    let (code, _, body) = raw(addr, "POST /api/run", &[&own, json], &big);
    assert_eq!(code, 413, "{body}");
    assert!(error_of(&body).contains(&format!("larger than {MAX_BODY} bytes")), "{body}");
    let long = format!("X-Filler: {}", "y".repeat(guard::MAX_HEADER_BYTES));
    let (code, _, body) = raw(addr, "GET /api/status", &[&own, &long], "");
    assert_eq!(code, 431, "{body}");
    assert!(error_of(&body).contains("headers"), "{body}");
    // Repeat 0 means "as stored" here too, as on Modbus: the request parses, the link is down.
    let (code, _, body) = raw(addr, "POST /api/run", &[&own, json], r#"{"slot":0,"repeat":0}"#);
    assert_eq!(code, 503, "{body}");
}

#[test]
fn with_a_token_requests_need_it_and_the_login_url_sets_a_strict_cookie() {
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = format!("tcp://{}", closed.local_addr().unwrap());
    drop(closed);
    let cell = Cell::start(&port, "http token test");
    let runtime = Runtime::new().unwrap();
    let listener = runtime.block_on(tokio::net::TcpListener::bind("127.0.0.1:0")).unwrap();
    let addr = listener.local_addr().unwrap();
    let token = "0123456789abcdef0123456789abcdef";
    let access = Access { token: Some(token.into()), ..Access::default() };
    runtime.spawn(serve(cell, listener, Options { access, ..Options::local() }));
    let own = format!("Host: {addr}");
    let (code, head, body) = raw(addr, "GET /api/status", &[&own], "");
    assert_eq!(code, 401, "{body}");
    assert!(head.contains("www-authenticate: Bearer"), "{head}");
    assert!(error_of(&body).contains("Authorization: Bearer"), "{body}");
    let bearer = format!("Authorization: Bearer {token}");
    let (code, _, _) = raw(addr, "GET /api/status", &[&own, &bearer], "");
    assert_eq!(code, 200);
    let (code, _, _) = raw(addr, "GET /?token=wrong", &[&own], "");
    assert_eq!(code, 401);
    let (code, head, _) = raw(addr, &format!("GET /?token={token}"), &[&own], "");
    assert_eq!(code, 303, "{head}");
    let cookie = head.lines().find_map(|l| l.strip_prefix("set-cookie: ")).unwrap();
    assert!(cookie.contains("HttpOnly") && cookie.contains("SameSite=Strict"), "{cookie}");
    let sent = format!("Cookie: {}", cookie.split(';').next().unwrap());
    let (code, _, page) = raw(addr, "GET /", &[&own, &sent], "");
    assert_eq!(code, 200);
    assert!(page.contains("<canvas"));
}
