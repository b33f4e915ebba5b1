//! Why a camera gives no frame: one variant per cause, each message naming the value and the
//! fix, each with a stable [`CameraError::name`] for `--json` failure output.

use std::path::PathBuf;

use chladni_core::plate::photo::input::MAX_PIXELS;

use super::MAX_BODY_BYTES;

/// Why a camera gives no frame.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// The `--camera` value is none of the accepted forms.
    #[error(
        "--camera {value}: {reason}; give http://HOST[:PORT]/PATH or https://… (each GET \
         returns one JPEG or PNG snapshot) or dir:PATH (the newest image in a folder)"
    )]
    BadSource {
        /// The value given.
        value: String,
        /// What is wrong with it.
        reason: String,
    },
    /// Nothing listens at the camera's address.
    #[error(
        "the camera at {url} refused the connection; check that it is on and that the host \
         and port are right"
    )]
    ConnectRefused {
        /// The snapshot URL.
        url: String,
    },
    /// The camera's host name does not resolve.
    #[error("the camera host in {url} is not found; check the name or give its IP address")]
    HostNotFound {
        /// The snapshot URL.
        url: String,
    },
    /// Any other network failure (reset connection, protocol error, too many redirects, …).
    #[error("cannot fetch a frame from {url}: {reason}; check the camera and its network")]
    Network {
        /// The snapshot URL.
        url: String,
        /// What the HTTP client said.
        reason: String,
    },
    /// The TLS handshake of an `https://` camera failed.
    #[error(
        "TLS with the camera at {url} failed: {reason}; the camera needs a certificate from a \
         public authority, else use http:// on a closed network"
    )]
    Tls {
        /// The snapshot URL.
        url: String,
        /// What the TLS layer said.
        reason: String,
    },
    /// No answer in time.
    #[error(
        "no frame from {url} within {seconds} s; check that the camera is on and answers at \
         that address, or allow it more time"
    )]
    Timeout {
        /// The snapshot URL.
        url: String,
        /// The timeout (s).
        seconds: f64,
    },
    /// Every frame in the time allowed was taken before the one wanted.
    #[error(
        "{camera} gave only frames taken before {wanted_s:.3} (Unix s; the newest at \
         {newest_s:.3}) within {seconds} s; check that the camera still takes frames and that \
         its clock agrees with this computer's (NTP)"
    )]
    Stale {
        /// The camera (`http…` or `dir:…`).
        camera: String,
        /// The newest frame's time (Unix s).
        newest_s: f64,
        /// The earliest time a frame could be used (Unix s).
        wanted_s: f64,
        /// The timeout (s).
        seconds: f64,
    },
    /// An HTTP status other than 200.
    #[error(
        "the camera at {url} answered HTTP {status}, not 200; check the snapshot path (and \
         credentials) in the URL"
    )]
    Status {
        /// The snapshot URL.
        url: String,
        /// The status code.
        status: u16,
    },
    /// An `X-Frame-Time` header that is not Unix seconds.
    #[error(
        "the camera at {url} sent X-Frame-Time: {value:?}; it must be Unix seconds with an \
         optional fraction, e.g. 1765130000.125, or be left out"
    )]
    BadFrameTime {
        /// The snapshot URL.
        url: String,
        /// The header's value.
        value: String,
    },
    /// A response body over [`MAX_BODY_BYTES`].
    #[error(
        "the camera at {url} sent more than {limit} MiB for one frame; set it to a smaller \
         resolution or a compressed format (JPEG)",
        limit = MAX_BODY_BYTES >> 20
    )]
    BodyTooLarge {
        /// The snapshot URL.
        url: String,
    },
    /// Bytes that are no PNG or JPEG image.
    #[error(
        "{from}: {len} bytes that are not a PNG or JPEG image ({what}); the camera must serve \
         one still image per request, not a web page or a video stream"
    )]
    NotAnImage {
        /// The URL or file.
        from: String,
        /// How many bytes.
        len: usize,
        /// What they are, or how they begin.
        what: String,
    },
    /// A PNG or JPEG the decoder refuses (truncated, corrupt).
    #[error("{from}: broken image: {reason}; check the camera's output")]
    Broken {
        /// The URL or file.
        from: String,
        /// The decoder's message.
        reason: String,
    },
    /// An image whose header announces more than 50 MP.
    #[error(
        "{from}: the frame is {w}×{h} px ({mp:.0} MP), over the limit of {limit} MP; set the \
         camera to a smaller resolution",
        mp = *w as f64 * *h as f64 / 1e6,
        limit = MAX_PIXELS / 1_000_000
    )]
    TooLarge {
        /// The URL or file.
        from: String,
        /// Width (px).
        w: u32,
        /// Height (px).
        h: u32,
    },
    /// A `dir:` path that is no readable folder.
    #[error("--camera dir:{path}: not a folder the camera writes to ({reason}); check the path")]
    NotAFolder {
        /// The path.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// No image file in the folder within the timeout.
    #[error(
        "--camera dir:{path}: no image (*.png, *.jpg, *.jpeg) appeared within {seconds} s; \
         check that the camera writes there"
    )]
    EmptyFolder {
        /// The folder.
        path: PathBuf,
        /// The timeout (s).
        seconds: f64,
    },
    /// An image file that cannot be read.
    #[error("cannot read {path}: {reason}; check its permissions")]
    UnreadableFile {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// The same bytes frame after frame.
    #[error(
        "the camera at {camera} sent the same frame {n} times: it is frozen; check it (a live \
         sensor's noise changes every frame)"
    )]
    Frozen {
        /// The camera (`http…` or `dir:…`).
        camera: String,
        /// How many identical frames in a row.
        n: u32,
    },
}

impl CameraError {
    /// A short stable name for `--json` failure output.
    pub fn name(&self) -> &'static str {
        match self {
            CameraError::BadSource { .. } => "bad_camera",
            CameraError::ConnectRefused { .. } => "connect_refused",
            CameraError::HostNotFound { .. } => "host_not_found",
            CameraError::Network { .. } => "network_failed",
            CameraError::Tls { .. } => "tls_failed",
            CameraError::Timeout { .. } => "timeout",
            CameraError::Stale { .. } => "stale_frames",
            CameraError::Status { .. } => "http_status",
            CameraError::BadFrameTime { .. } => "bad_frame_time",
            CameraError::BodyTooLarge { .. } => "body_too_large",
            CameraError::NotAnImage { .. } => "not_an_image",
            CameraError::Broken { .. } => "broken_image",
            CameraError::TooLarge { .. } => "too_large",
            CameraError::NotAFolder { .. } => "not_a_folder",
            CameraError::EmptyFolder { .. } => "empty_folder",
            CameraError::UnreadableFile { .. } => "unreadable_file",
            CameraError::Frozen { .. } => "frozen",
        }
    }
}
