//! An HTTP snapshot camera: each GET returns one JPEG or PNG, optionally stamped with the time
//! it was taken in an `X-Frame-Time` header (Unix seconds).

use std::time::{Duration, Instant, SystemTime};

use ureq::Agent;

use super::{
    CameraError, CameraOptions, Fetched, Frame, MAX_BODY_BYTES, POLL, YEAR, earlier, sleep_until,
};

/// The header a camera (or a gateway in front of it) may send: when the frame was taken, in
/// Unix seconds with an optional fraction.
pub(super) const FRAME_TIME: &str = "x-frame-time";

pub(super) struct Snapshots {
    url: String,
    agent: Agent,
    /// Whether the camera stamps its frames: unknown until its first answer.
    stamps: Option<bool>,
    /// The time of the last stamped frame returned (the same time again is the same frame).
    last_stamp: Option<SystemTime>,
}

/// One answer.
struct Got {
    bytes: Vec<u8>,
    stamp: Option<SystemTime>,
    fetch: Duration,
}

impl Snapshots {
    pub(super) fn new(url: &str, options: &CameraOptions) -> Snapshots {
        let agent = Agent::config_builder()
            .timeout_connect(Some(options.timeout.min(YEAR)))
            .timeout_global(Some(options.timeout.min(YEAR)))
            // Statuses are checked here, to name them with the URL.
            .http_status_as_error(false)
            .build()
            .into();
        Snapshots { url: url.into(), agent, stamps: None, last_stamp: None }
    }

    /// The first frame taken at or after `not_before`, by `deadline`.
    pub(super) fn frame_after(
        &mut self,
        not_before: SystemTime,
        deadline: Instant,
        options: &CameraOptions,
    ) -> Result<Fetched, CameraError> {
        let mut newest: Option<SystemTime> = None;
        loop {
            // A snapshot camera answers with a frame taken about when it was asked (a stamped
            // one says when; an unstamped one's may be up to max_age older): a request sent
            // before `not_before` fetches a frame to throw away, and its exposure, encoding
            // and transfer delay the one that counts (on the virtual rig such a frame after
            // every burst took a third of a learning session's time).
            let due = match self.stamps {
                Some(false) => not_before.checked_add(options.max_age).unwrap_or(not_before),
                _ => not_before,
            };
            sleep_until(due, deadline, || self.late(newest, not_before, options))?;
            let sent = SystemTime::now();
            let got = match self.get(deadline, options) {
                // The time ran out while asking again: the stale frames are the cause.
                Err(CameraError::Timeout { .. }) if newest.is_some() => {
                    return Err(self.late(newest, not_before, options));
                }
                got => got?,
            };
            self.stamps = Some(got.stamp.is_some());
            let taken = got.stamp.unwrap_or_else(|| earlier(sent, options.max_age));
            if taken >= not_before {
                let new = got.stamp.is_none() || got.stamp != self.last_stamp;
                self.last_stamp = got.stamp;
                let image = super::decode(&self.url, &got.bytes)?;
                let frame = Frame {
                    image,
                    taken,
                    digest: super::digest(&got.bytes),
                    bytes: got.bytes.len(),
                    fetch: got.fetch,
                };
                return Ok(Fetched { frame, new });
            }
            newest = newest.max(Some(taken));
            if got.stamp.is_some() {
                let next = SystemTime::now().checked_add(POLL).unwrap_or(SystemTime::UNIX_EPOCH);
                sleep_until(next, deadline, || self.late(newest, not_before, options))?;
            }
        }
    }

    /// The error when the time runs out: stale frames when some came, else a timeout.
    fn late(
        &self,
        newest: Option<SystemTime>,
        not_before: SystemTime,
        options: &CameraOptions,
    ) -> CameraError {
        let seconds = options.timeout.as_secs_f64();
        match newest {
            Some(t) => CameraError::Stale {
                camera: self.url.clone(),
                newest_s: super::unix_s(t),
                wanted_s: super::unix_s(not_before),
                seconds,
            },
            None => CameraError::Timeout { url: self.url.clone(), seconds },
        }
    }

    /// One GET, bounded by `deadline`: the body (at most [`MAX_BODY_BYTES`]) and the stamp.
    fn get(&self, deadline: Instant, options: &CameraOptions) -> Result<Got, CameraError> {
        let timeout = || CameraError::Timeout {
            url: self.url.clone(),
            seconds: options.timeout.as_secs_f64(),
        };
        let left = deadline.checked_duration_since(Instant::now()).ok_or_else(timeout)?;
        let t0 = Instant::now();
        let response = self
            .agent
            .get(&self.url)
            .config()
            .timeout_global(Some(left))
            .build()
            .call()
            .map_err(|e| self.error(e, options))?;
        let status = response.status().as_u16();
        if status != 200 {
            return Err(CameraError::Status { url: self.url.clone(), status });
        }
        // A declared length over the limit fails before any byte is read; the reader's limit
        // catches a body that declares none (chunked) or lies.
        let declared = response.body().content_length();
        if declared.is_some_and(|n| n > MAX_BODY_BYTES) {
            return Err(CameraError::BodyTooLarge { url: self.url.clone() });
        }
        let stamp = match response.headers().get(FRAME_TIME) {
            Some(v) => Some(self.stamp(v.as_bytes())?),
            None => None,
        };
        let bytes = response
            .into_body()
            .with_config()
            .limit(MAX_BODY_BYTES)
            .read_to_vec()
            .map_err(|e| self.error(e, options))?;
        Ok(Got { bytes, stamp, fetch: t0.elapsed() })
    }

    fn is_https(&self) -> bool {
        self.url.get(..8).is_some_and(|s| s.eq_ignore_ascii_case("https://"))
    }

    /// The time an `X-Frame-Time` value gives.
    fn stamp(&self, value: &[u8]) -> Result<SystemTime, CameraError> {
        let text = String::from_utf8_lossy(value);
        let bad = || CameraError::BadFrameTime { url: self.url.clone(), value: text.to_string() };
        let s: f64 = text.trim().parse().map_err(|_| bad())?;
        let d = Duration::try_from_secs_f64(s).map_err(|_| bad())?;
        SystemTime::UNIX_EPOCH.checked_add(d).ok_or_else(bad)
    }

    /// The named error for what the HTTP client said.
    fn error(&self, e: ureq::Error, options: &CameraOptions) -> CameraError {
        let url = self.url.clone();
        match e {
            ureq::Error::Timeout(_) => {
                CameraError::Timeout { url, seconds: options.timeout.as_secs_f64() }
            }
            ureq::Error::Io(io) if io.kind() == std::io::ErrorKind::ConnectionRefused => {
                CameraError::ConnectRefused { url }
            }
            ureq::Error::Io(io) if io.kind() == std::io::ErrorKind::TimedOut => {
                CameraError::Timeout { url, seconds: options.timeout.as_secs_f64() }
            }
            // rustls reports a failed handshake or a refused certificate through the socket's
            // reader, as invalid data.
            ureq::Error::Io(io)
                if io.kind() == std::io::ErrorKind::InvalidData && self.is_https() =>
            {
                CameraError::Tls { url, reason: io.to_string() }
            }
            ureq::Error::HostNotFound => CameraError::HostNotFound { url },
            ureq::Error::BodyExceedsLimit(_) => CameraError::BodyTooLarge { url },
            ureq::Error::Tls(_) | ureq::Error::Rustls(_) | ureq::Error::TlsRequired => {
                CameraError::Tls { url, reason: e.to_string() }
            }
            other => CameraError::Network { url, reason: other.to_string() },
        }
    }
}
