//! Live frames for the closed loop (`--camera URL` of `chladni plate learn` and `chladni steer`,
//! docs/camera.md): an HTTP snapshot camera (`http://…`, `https://…`: each GET returns one JPEG
//! or PNG) or a folder a camera writes images to (`dir:PATH`).
//!
//! A frame is used only if it was taken at or after the time the last drive change settled
//! ([`Camera::frame_after`]). When it was taken is known from the response's `X-Frame-Time`
//! header (Unix seconds) when the camera sends one, else it is bounded by the request's time
//! less [`CameraOptions::max_age`]; for a folder it is the file's modification time.
//! Every frame is decoded from its content (not its name) to 8-bit grey, its size checked on the
//! header first ([`chladni_core::plate::photo::input`]); `frozen_after` byte-identical frames
//! in a row are an error, since a live sensor's noise changes every frame.

mod dir;
mod error;
mod http;
#[cfg(test)]
mod tests;

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::{Duration, Instant, SystemTime};

use chladni_core::plate::photo::input::{self, PhotoError};
use chladni_shared::vectors::Digest;
use image::GrayImage;

pub use error::CameraError;

/// Most bytes one HTTP frame may have: 64 MiB (a 50 MP RGB PNG compresses to well under it).
pub const MAX_BODY_BYTES: u64 = 64 << 20;

/// How often a stamped camera is asked again for a newer frame, and a folder listed again for a
/// newer file: 20 ms, under one frame of a 30 fps camera, so the wait adds little to the loop.
pub const POLL: Duration = Duration::from_millis(20);

/// Where frames come from: the parsed `--camera` value.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CameraSource {
    /// `http://…` or `https://…`: each GET returns one JPEG or PNG frame.
    Http(String),
    /// `dir:PATH`: the newest `*.png`, `*.jpg` or `*.jpeg` in the folder.
    Dir(PathBuf),
}

impl FromStr for CameraSource {
    type Err = CameraError;

    fn from_str(s: &str) -> Result<Self, CameraError> {
        let bad = |reason: &str| CameraError::BadSource { value: s.into(), reason: reason.into() };
        if let Some(path) = s.strip_prefix("dir:") {
            return if path.is_empty() {
                Err(bad("no folder after dir:"))
            } else {
                Ok(CameraSource::Dir(PathBuf::from(path)))
            };
        }
        let Some((scheme, _)) = s.split_once("://") else {
            return Err(bad("neither a URL nor dir:PATH"));
        };
        let scheme = scheme.to_ascii_lowercase();
        if scheme == "rtsp" || scheme == "rtp" {
            return Err(bad("a video stream; give the camera's still-image (snapshot) URL"));
        }
        if scheme != "http" && scheme != "https" {
            return Err(bad(&format!("the scheme {scheme}:// is not served")));
        }
        let uri: ureq::http::Uri = s.parse().map_err(|e| bad(&format!("not a valid URL ({e})")))?;
        if uri.host().is_none_or(str::is_empty) {
            return Err(bad("no host in the URL"));
        }
        Ok(CameraSource::Http(s.into()))
    }
}

impl fmt::Display for CameraSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CameraSource::Http(url) => f.write_str(url),
            CameraSource::Dir(path) => write!(f, "dir:{}", path.display()),
        }
    }
}

/// How long to wait and how fresh a frame must be.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraOptions {
    /// How long [`Camera::frame_after`] waits for a usable frame, counted from the later of the
    /// call and `not_before` (default 5 s). It also bounds each HTTP request.
    pub timeout: Duration,
    /// How old a snapshot may be when served by a camera that does not stamp its frames
    /// (default 100 ms): such a frame is taken to be from (request sent) − `max_age`.
    pub max_age: Duration,
    /// This many byte-identical frames in a row are an error (default 5); below 2, never.
    pub frozen_after: u32,
}

impl Default for CameraOptions {
    fn default() -> Self {
        CameraOptions {
            timeout: Duration::from_secs(5),
            max_age: Duration::from_millis(100),
            frozen_after: 5,
        }
    }
}

/// One frame.
#[derive(Debug, Clone)]
pub struct Frame {
    /// The picture, 8-bit grey.
    pub image: GrayImage,
    /// When it was taken (a bound: see [`Camera::frame_after`]).
    pub taken: SystemTime,
    /// FNV-1a 64 of the encoded bytes (the same bytes, the same digest, in any run).
    pub digest: u64,
    /// Size of the encoded image (bytes).
    pub bytes: usize,
    /// How long getting the encoded bytes took (one request, or one file read).
    pub fetch: Duration,
}

/// A frame from a source, before the freeze check.
struct Fetched {
    frame: Frame,
    /// Whether it is a frame not seen before: false when a stamped camera serves the frame with
    /// the same time again, or a folder's newest file is the one already read. Only new frames
    /// count towards [`CameraOptions::frozen_after`].
    new: bool,
}

enum Kind {
    Http(http::Snapshots),
    Dir(dir::Folder),
}

/// An open camera.
pub struct Camera {
    source: CameraSource,
    options: CameraOptions,
    kind: Kind,
    /// The last new frame's digest and how many new frames in a row had it.
    last: Option<(u64, u32)>,
}

impl fmt::Debug for Camera {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Camera").field("source", &self.source).finish_non_exhaustive()
    }
}

impl Camera {
    /// Opens the source: an HTTP client with the timeouts set, or a check that the folder is
    /// one. Nothing is fetched yet.
    pub fn open(source: CameraSource, options: CameraOptions) -> Result<Camera, CameraError> {
        let kind = match &source {
            CameraSource::Http(url) => Kind::Http(http::Snapshots::new(url, &options)),
            CameraSource::Dir(path) => Kind::Dir(dir::Folder::open(path)?),
        };
        Ok(Camera { source, options, kind, last: None })
    }

    /// The source it reads.
    pub fn source(&self) -> &CameraSource {
        &self.source
    }

    /// A frame known to be taken at or after `not_before` (the time the last drive change
    /// settled). HTTP: a frame stamped `X-Frame-Time` earlier is asked for again every
    /// [`POLL`]; without the header, the request is not sent before `not_before` + `max_age`
    /// (once the camera is known not to stamp). Folder: the newest image, listed every
    /// [`POLL`] until one has a modification time at or after `not_before`. Gives up after
    /// [`CameraOptions::timeout`].
    pub fn frame_after(&mut self, not_before: SystemTime) -> Result<Frame, CameraError> {
        let wait = not_before.duration_since(SystemTime::now()).unwrap_or(Duration::ZERO);
        let deadline = within_a_year(wait.saturating_add(self.options.timeout));
        let fetched = match &mut self.kind {
            Kind::Http(h) => h.frame_after(not_before, deadline, &self.options)?,
            Kind::Dir(d) => d.frame_after(not_before, deadline, &self.options)?,
        };
        if fetched.new {
            self.check_frozen(fetched.frame.digest)?;
        }
        Ok(fetched.frame)
    }

    fn check_frozen(&mut self, digest: u64) -> Result<(), CameraError> {
        let n = match self.last {
            Some((d, n)) if d == digest => n.saturating_add(1),
            _ => 1,
        };
        self.last = Some((digest, n));
        if self.options.frozen_after >= 2 && n >= self.options.frozen_after {
            return Err(CameraError::Frozen { camera: self.source.to_string(), n });
        }
        Ok(())
    }
}

/// FNV-1a 64 of the bytes.
fn digest(bytes: &[u8]) -> u64 {
    Digest::new().bytes(bytes).value()
}

/// Decodes a PNG or JPEG to grey (the format from the content), its pixel count checked on
/// the header first; `from` names it in errors.
fn decode(from: &str, bytes: &[u8]) -> Result<GrayImage, CameraError> {
    let not_image =
        |what: String| CameraError::NotAnImage { from: from.into(), len: bytes.len(), what };
    match image::guess_format(bytes) {
        Ok(image::ImageFormat::Png | image::ImageFormat::Jpeg) => {}
        Ok(other) => return Err(not_image(format!("a {other:?} image"))),
        Err(_) if bytes.is_empty() => return Err(not_image("nothing".into())),
        Err(_) => {
            let head = &bytes[..bytes.len().min(24)];
            return Err(not_image(format!("they begin \"{}\"", head.escape_ascii())));
        }
    }
    input::read_bytes(bytes, Path::new(from)).map_err(|e| match e {
        PhotoError::TooLarge { w, h, .. } => CameraError::TooLarge { from: from.into(), w, h },
        PhotoError::Read { reason, .. } => CameraError::Broken { from: from.into(), reason },
    })
}

/// Sleeps until `t`, or fails with `late` when `t` comes after `deadline`.
fn sleep_until(
    t: SystemTime,
    deadline: Instant,
    late: impl FnOnce() -> CameraError,
) -> Result<(), CameraError> {
    let Ok(d) = t.duration_since(SystemTime::now()) else { return Ok(()) };
    if Instant::now().checked_add(d).is_none_or(|end| end > deadline) {
        return Err(late());
    }
    std::thread::sleep(d);
    Ok(())
}

/// Unix seconds of a time (negative before 1970), for messages.
fn unix_s(t: SystemTime) -> f64 {
    match t.duration_since(SystemTime::UNIX_EPOCH) {
        Ok(d) => d.as_secs_f64(),
        Err(e) => -e.duration().as_secs_f64(),
    }
}

/// `t` − `d`, or the Unix epoch when that is earlier.
fn earlier(t: SystemTime, d: Duration) -> SystemTime {
    t.checked_sub(d).unwrap_or(SystemTime::UNIX_EPOCH).max(SystemTime::UNIX_EPOCH)
}

/// Now + `d`, `d` capped at a year (an absurd `not_before` or timeout must not overflow).
fn within_a_year(d: Duration) -> Instant {
    Instant::now() + d.min(YEAR)
}

const YEAR: Duration = Duration::from_secs(365 * 86_400);
