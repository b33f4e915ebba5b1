//! A `chladni rig` process (docs/rig.md) for the tests that need a camera: started, its
//! listening line read, killed when dropped; and a plain HTTP GET to ask it.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, ChildStdout, Stdio};
use std::time::Duration;

use serde_json::Value;

use super::cli::command;

/// A running `chladni rig`, killed when dropped.
pub struct RigProcess {
    pub child: Child,
    /// Its stdout, kept open (a closed stdout would end it when it prints its failure).
    out: BufReader<ChildStdout>,
    /// `http://127.0.0.1:PORT`.
    pub url: String,
    /// Its listening line.
    pub listening: Value,
}

impl RigProcess {
    /// `chladni rig ARGS --json`, once it listens.
    pub fn start(args: &[&str]) -> RigProcess {
        let mut child = command()
            .arg("rig")
            .args(args)
            .arg("--json")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        let mut out = BufReader::new(child.stdout.take().unwrap());
        out.read_line(&mut line).unwrap();
        let listening: Value = serde_json::from_str(&line).unwrap_or_else(|e| {
            let mut err = String::new();
            let _ = child.stderr.take().unwrap().read_to_string(&mut err);
            panic!("rig printed {line:?} ({e}); stderr: {err}")
        });
        let url = listening["url"].as_str().unwrap().trim_end_matches("/frame.png").to_owned();
        RigProcess { child, out, url, listening }
    }

    /// Waits for the end: the exit code, the rest of stdout and stderr.
    pub fn wait(mut self) -> (Option<i32>, String, String) {
        let code = self.child.wait().unwrap().code();
        let (mut out, mut err) = (String::new(), String::new());
        self.out.read_to_string(&mut out).unwrap();
        self.child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
        (code, out, err)
    }
}

impl Drop for RigProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// An answer: status, headers (lowercase names) and body.
pub struct Answer {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Answer {
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }
}

/// `GET url` over HTTP/1.1 with `Connection: close`; `None` when no answer comes in `wait`.
pub fn get(url: &str, wait: Duration) -> Option<Answer> {
    request("GET", url, None, wait)
}

/// `POST url` with a JSON `body`, as [`get`].
pub fn post(url: &str, body: &[u8], wait: Duration) -> Option<Answer> {
    request("POST", url, Some(body), wait)
}

fn request(method: &str, url: &str, body: Option<&[u8]>, wait: Duration) -> Option<Answer> {
    let rest = url.strip_prefix("http://").unwrap();
    let (addr, path) = rest.split_at(rest.find('/').unwrap());
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(wait)).unwrap();
    write!(s, "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n").unwrap();
    if let Some(body) = body {
        let len = body.len();
        write!(s, "Content-Type: application/json\r\nContent-Length: {len}\r\n\r\n").unwrap();
        // A body the server refuses early (too large) may close the connection mid-write.
        let _ = s.write_all(body);
    } else {
        write!(s, "\r\n").unwrap();
    }
    let mut raw = Vec::new();
    if s.read_to_end(&mut raw).is_err() || raw.is_empty() {
        return None;
    }
    let end = raw.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let head = String::from_utf8_lossy(&raw[..end]).into_owned();
    let mut lines = head.lines();
    let status = lines.next().unwrap().split(' ').nth(1).unwrap().parse().unwrap();
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_owned()))
        .collect();
    Some(Answer { status, headers, body: raw[end + 4..].to_vec() })
}
