//! HTTP snapshot cameras, served by a real server on 127.0.0.1.

use std::io::{BufRead, BufReader, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, SystemTime};

use image::ImageFormat;

use super::{encoded, failed, from_stamp, photo, quick, stamp};
use crate::camera::{Camera, CameraError, CameraOptions, CameraSource, MAX_BODY_BYTES, digest};

/// One answer of the test server.
struct Reply {
    status: u16,
    stamp: Option<String>,
    body: Vec<u8>,
    /// A Content-Length other than the body's.
    declared: Option<u64>,
}

impl Reply {
    fn ok(body: Vec<u8>) -> Reply {
        Reply { status: 200, stamp: None, body, declared: None }
    }
    fn stamped(mut self, t: SystemTime) -> Reply {
        self.stamp = Some(stamp(t));
        self
    }
}

/// What the server saw and sent for one request.
#[derive(Debug, Clone)]
struct Served {
    /// When the request had arrived.
    at: SystemTime,
    digest: u64,
    stamp: Option<String>,
}

struct Server {
    url: String,
    log: Arc<Mutex<Vec<Served>>>,
}

impl Server {
    fn log(&self) -> Vec<Served> {
        self.log.lock().expect("the server thread does not panic").clone()
    }
}

/// Serves request `n` (from 0) with `reply(n)`, one connection per request.
fn serve(reply: impl Fn(usize) -> Reply + Send + 'static) -> Server {
    let listener = TcpListener::bind("127.0.0.1:0").expect("a free port");
    let url = format!("http://{}/snapshot", listener.local_addr().expect("bound"));
    let log = Arc::new(Mutex::new(Vec::new()));
    let seen = Arc::clone(&log);
    thread::spawn(move || {
        for (n, stream) in listener.incoming().enumerate() {
            let Ok(mut stream) = stream else { return };
            read_head(&stream);
            let at = SystemTime::now();
            let r = reply(n);
            seen.lock().expect("no panic while held").push(Served {
                at,
                digest: digest(&r.body),
                stamp: r.stamp.clone(),
            });
            // The client may hang up early (a refused body): write errors are expected.
            let _ = write_reply(&mut stream, &r);
        }
    });
    Server { url, log }
}

fn read_head(stream: &TcpStream) {
    for line in BufReader::new(stream).lines() {
        match line {
            Ok(l) if !l.is_empty() => {}
            _ => return,
        }
    }
}

fn write_reply(stream: &mut TcpStream, r: &Reply) -> std::io::Result<()> {
    let len = r.declared.unwrap_or(r.body.len() as u64);
    let mut head = format!(
        "HTTP/1.1 {} X\r\nContent-Type: image/png\r\nContent-Length: {len}\r\n\
         Connection: close\r\n",
        r.status
    );
    if let Some(s) = &r.stamp {
        head += &format!("X-Frame-Time: {s}\r\n");
    }
    stream.write_all(format!("{head}\r\n").as_bytes())?;
    stream.write_all(&r.body)
}

fn open(url: &str, options: CameraOptions) -> Camera {
    let source: CameraSource = url.parse().expect("a valid URL");
    Camera::open(source, options).expect("an HTTP camera opens without a request")
}

#[test]
fn sources_parse_and_bad_values_name_the_accepted_forms() {
    for s in ["http://10.0.0.7/snap.jpg", "https://cam.local:8443/still?res=hi", "HTTP://c/x"] {
        let src: CameraSource = s.parse().expect(s);
        assert_eq!(src, CameraSource::Http(s.into()));
        assert_eq!(src.to_string(), s);
    }
    let dir: CameraSource = "dir:/var/cam".parse().expect("a folder");
    assert_eq!(dir, CameraSource::Dir("/var/cam".into()));
    assert_eq!(dir.to_string(), "dir:/var/cam");
    for (bad, why) in [
        ("ftp://cam/snap.jpg", "ftp"),
        ("rtsp://cam/stream", "video stream"),
        ("cam.local/snap.jpg", "neither"),
        ("dir:", "no folder"),
        ("http://", "URL"),
        ("http:///snap", "URL"),
    ] {
        let e = bad.parse::<CameraSource>().expect_err(bad);
        let msg = e.to_string();
        assert_eq!(e.name(), "bad_camera");
        assert!(msg.contains(bad) && msg.contains(why), "{bad}: {msg}");
        assert!(msg.contains("http://") && msg.contains("dir:PATH"), "{msg}");
    }
}

#[test]
fn a_stamped_png_is_served_with_its_own_time_and_exact_pixels() {
    let img = photo(1);
    let png = encoded(&img, ImageFormat::Png);
    let body = png.clone();
    let server = serve(move |_| Reply::ok(body.clone()).stamped(SystemTime::now()));
    let mut cam = open(&server.url, CameraOptions::default());
    let not_before = SystemTime::now();
    let f = cam.frame_after(not_before).expect("a fresh stamped frame");
    let log = server.log();
    assert_eq!(log.len(), 1, "a stamped camera is asked at once, once");
    let sent = log[0].stamp.as_deref().expect("stamped");
    assert_eq!(f.taken, from_stamp(sent));
    assert!(f.taken >= not_before);
    assert_eq!(f.image, img);
    assert_eq!((f.digest, f.bytes), (digest(&png), png.len()));
}

#[test]
fn a_stamped_camera_is_not_asked_before_not_before() {
    let server = serve(|n| {
        Reply::ok(encoded(&photo(n as u64), ImageFormat::Png)).stamped(SystemTime::now())
    });
    let mut cam = open(&server.url, CameraOptions::default());
    cam.frame_after(SystemTime::now()).expect("the first frame: the camera stamps");
    // The drive settles 150 ms from now: one request, sent then, not one before to discard.
    let not_before = SystemTime::now() + Duration::from_millis(150);
    let f = cam.frame_after(not_before).expect("a frame after the settle");
    let log = server.log();
    assert_eq!(log.len(), 2, "{log:?}");
    assert!(log[1].at >= not_before && f.taken >= not_before, "{log:?}");
}

#[test]
fn an_unstamped_jpeg_is_asked_for_no_earlier_than_not_before_plus_max_age() {
    let server = serve(|n| Reply::ok(encoded(&photo(n as u64), ImageFormat::Jpeg)));
    let options = CameraOptions { max_age: Duration::from_millis(60), ..CameraOptions::default() };
    let mut cam = open(&server.url, options);
    let mut asked = 0;
    for round in 0..2 {
        let not_before = SystemTime::now();
        let f = cam.frame_after(not_before).expect("an unstamped frame");
        let log = server.log();
        let last = log.last().expect("asked");
        // The first answer tells that the camera does not stamp: the first round may ask twice
        // (once too early), the second waits before its only request.
        let more = log.len() - asked;
        asked = log.len();
        assert!(if round == 0 { more <= 2 } else { more == 1 }, "{log:?}");
        assert!(last.at >= not_before + options.max_age, "{log:?}");
        assert!(f.taken >= not_before && f.taken <= last.at - options.max_age);
        assert_eq!(f.digest, last.digest);
        assert_eq!(f.image.dimensions(), (96, 64));
        let want = photo(log.len() as u64 - 1);
        let diff: f64 =
            f.image.pixels().zip(want.pixels()).map(|(a, b)| a[0].abs_diff(b[0]) as f64).sum();
        // Within JPEG loss (a flat grey image is 60+ levels off).
        assert!(diff / (96.0 * 64.0) < 8.0, "the JPEG decodes to its photo: {diff}");
    }
}

#[test]
fn a_stale_stamp_is_asked_again_and_not_used() {
    let server = serve(|n| {
        let old = SystemTime::now() - Duration::from_secs(10);
        let t = if n == 0 { old } else { SystemTime::now() };
        Reply::ok(encoded(&photo(n as u64), ImageFormat::Png)).stamped(t)
    });
    let mut cam = open(&server.url, CameraOptions::default());
    let not_before = SystemTime::now();
    let f = cam.frame_after(not_before).expect("the second, fresh frame");
    let log = server.log();
    assert_eq!(log.len(), 2, "{log:?}");
    assert_ne!(f.digest, log[0].digest);
    assert_eq!(f.digest, log[1].digest);
    assert_eq!(Some(f.taken), log[1].stamp.as_deref().map(from_stamp));
    assert!(f.taken >= not_before);
}

#[test]
fn only_stale_stamps_until_the_timeout_are_named() {
    let server = serve(|n| {
        let old = SystemTime::now() - Duration::from_secs(10);
        Reply::ok(encoded(&photo(n as u64), ImageFormat::Png)).stamped(old)
    });
    let mut cam = open(&server.url, quick(300));
    let e = failed(cam.frame_after(SystemTime::now()), "stale_frames", &server.url);
    assert!(e.to_string().contains("NTP"), "{e}");
    assert!(server.log().len() >= 2, "asked again while stale");
}

#[test]
fn a_camera_that_never_answers_times_out() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("a free port");
    let url = format!("http://{}/snapshot", listener.local_addr().expect("bound"));
    // Accepts and holds every connection, never answering.
    thread::spawn(move || {
        let mut held = Vec::new();
        for stream in listener.incoming() {
            held.push(stream);
        }
    });
    let mut cam = open(&url, quick(300));
    let e = failed(cam.frame_after(SystemTime::now()), "timeout", &url);
    assert!(matches!(e, CameraError::Timeout { seconds, .. } if seconds == 0.3), "{e}");
}

#[test]
fn a_closed_port_is_a_refused_connection() {
    let url = {
        let listener = TcpListener::bind("127.0.0.1:0").expect("a free port");
        format!("http://{}/snapshot", listener.local_addr().expect("bound"))
    };
    let mut cam = open(&url, quick(1000));
    failed(cam.frame_after(SystemTime::now()), "connect_refused", &url);
}

#[test]
fn statuses_other_than_200_are_named_with_the_url() {
    for status in [404, 500] {
        let server = serve(move |_| Reply { status, ..Reply::ok(b"no".to_vec()) });
        let mut cam = open(&server.url, quick(1000));
        let e = failed(cam.frame_after(SystemTime::now()), "http_status", &server.url);
        assert!(matches!(e, CameraError::Status { status: s, .. } if s == status), "{e}");
    }
}

#[test]
fn bodies_that_are_no_image_or_a_broken_one_are_named() {
    let png = encoded(&photo(3), ImageFormat::Png);
    let cases = [
        (b"<html><body>login</body></html>".to_vec(), "not_an_image", "<html>"),
        (Vec::new(), "not_an_image", "0 bytes"),
        (png[..png.len() / 2].to_vec(), "broken_image", "broken image"),
    ];
    for (body, name, names) in cases {
        let server = serve(move |_| Reply::ok(body.clone()));
        let mut cam = open(&server.url, quick(1000));
        failed(cam.frame_after(SystemTime::now()), name, names);
    }
}

#[test]
fn a_bad_frame_time_is_named() {
    let server = serve(|_| {
        let r = Reply::ok(encoded(&photo(4), ImageFormat::Png));
        Reply { stamp: Some("yesterday".into()), ..r }
    });
    let mut cam = open(&server.url, quick(1000));
    failed(cam.frame_after(SystemTime::now()), "bad_frame_time", "yesterday");
}

#[test]
fn a_frame_over_50_megapixels_is_refused_from_its_header() {
    let server = serve(|_| Reply::ok(png_header(10_000, 6_000)));
    let mut cam = open(&server.url, quick(1000));
    let e = failed(cam.frame_after(SystemTime::now()), "too_large", "10000×6000");
    assert!(e.to_string().contains("60 MP"), "{e}");
}

#[test]
fn a_body_declared_over_the_limit_is_refused_unread() {
    let server =
        serve(|_| Reply { declared: Some(MAX_BODY_BYTES + 1), ..Reply::ok(vec![0; 1024]) });
    let mut cam = open(&server.url, quick(1000));
    failed(cam.frame_after(SystemTime::now()), "body_too_large", "64 MiB");
}

#[test]
fn five_identical_frames_are_a_frozen_camera() {
    let png = encoded(&photo(5), ImageFormat::Png);
    let server = serve(move |_| Reply::ok(png.clone()));
    let mut cam = open(&server.url, quick(1000));
    for k in 1..5 {
        cam.frame_after(SystemTime::now()).unwrap_or_else(|e| panic!("frame {k}: {e}"));
    }
    let e = failed(cam.frame_after(SystemTime::now()), "frozen", "5 times");
    assert!(e.to_string().contains(&server.url), "{e}");
}

#[test]
fn the_same_stamped_frame_served_again_is_not_frozen() {
    // A camera that caches its last frame serves the same bytes with the same time.
    let t = SystemTime::now();
    let png = encoded(&photo(6), ImageFormat::Png);
    let server = serve(move |_| Reply::ok(png.clone()).stamped(t));
    let mut cam = open(&server.url, quick(1000));
    for k in 0..7 {
        let f = cam.frame_after(t - Duration::from_secs(1)).unwrap_or_else(|e| panic!("{k}: {e}"));
        assert_eq!(f.taken, from_stamp(&stamp(t)));
    }
}

/// A PNG's signature and header announcing `w` × `h` px (grey, 8 bit), and no pixels.
fn png_header(w: u32, h: u32) -> Vec<u8> {
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 0, 0, 0, 0]);
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    out.extend(13u32.to_be_bytes());
    out.extend(&ihdr);
    out.extend(crc32(&ihdr).to_be_bytes());
    // The decoder reads the header up to the first (here empty) data chunk.
    out.extend(0u32.to_be_bytes());
    out.extend(b"IDAT");
    out.extend(crc32(b"IDAT").to_be_bytes());
    out
}

/// CRC-32 (IEEE) as PNG chunks carry it.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 == 1 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
        }
    }
    !c
}

#[test]
fn https_is_attempted_and_a_failed_handshake_is_named() {
    // A plain-HTTP server: it answers the TLS hello with HTTP, which no handshake accepts.
    let listener = TcpListener::bind("127.0.0.1:0").expect("a free port");
    let url = format!("https://{}/snapshot", listener.local_addr().expect("bound"));
    thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { return };
            let _ = write_reply(&mut stream, &Reply::ok(b"plain".to_vec()));
        }
    });
    let mut cam = open(&url, quick(1000));
    failed(cam.frame_after(SystemTime::now()), "tls_failed", &url);
}
