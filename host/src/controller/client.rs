//! Client for the controller's link: a serial port (the board's USB CDC / ST-LINK VCP) or
//! `tcp://HOST:PORT` (QEMU's `-chardev socket`). Frames are the ones of
//! [`chladni_shared::icd::link`]; every request gets a fresh id and the client waits for the
//! response with that id, skipping stale answers (for example to garbage sent earlier).

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use chladni_shared::icd::link::{
    self, DeviceInfo, DriveError, Envelope, FrameReader, LinkError, MAX_FRAME, PROTOCOL_VERSION,
    Plan, Request, Response, StatusReport,
};

/// Default time to wait for one response.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(3);

/// Everything that can go wrong talking to the controller.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    /// The port string is neither `tcp://HOST:PORT` nor a serial device.
    #[error("cannot open port '{port}': {reason}")]
    Open {
        /// The port as given.
        port: String,
        /// Why it failed.
        reason: String,
    },
    /// Reading or writing the link failed.
    #[error("link I/O error: {0}")]
    Io(#[from] std::io::Error),
    /// No response with our id arrived in time.
    #[error("no response to request {id} within {timeout:?} (is the controller running?)")]
    Timeout {
        /// The request id.
        id: u32,
        /// How long we waited.
        timeout: Duration,
    },
    /// The controller refused the request.
    #[error("controller refused request {id}: {error}")]
    Refused {
        /// The request id.
        id: u32,
        /// What the controller said was wrong.
        error: LinkError,
    },
    /// The controller answered with a response of the wrong kind.
    #[error("unexpected response to {request}: {response:?}")]
    Unexpected {
        /// What we asked.
        request: &'static str,
        /// What came back.
        response: Box<Response>,
    },
    /// The controller's response frame could not be decoded (a firmware of another version?).
    #[error("undecodable response frame: {0}")]
    BadFrame(LinkError),
    /// The drive refused a command (invalid plan or setpoint, faulted, busy).
    #[error("drive refused request {id}: {error}")]
    Rejected {
        /// The request id.
        id: u32,
        /// Why.
        error: DriveError,
    },
}

/// A byte stream with a read timeout: the two transports implement it.
pub trait Transport: Read + Write + Send {
    /// Sets how long a `read` may block before returning `TimedOut`/`WouldBlock`.
    fn set_read_timeout(&mut self, timeout: Duration) -> std::io::Result<()>;
}

impl Transport for TcpStream {
    fn set_read_timeout(&mut self, timeout: Duration) -> std::io::Result<()> {
        TcpStream::set_read_timeout(self, Some(timeout))
    }
}

impl Transport for Box<dyn serialport::SerialPort> {
    fn set_read_timeout(&mut self, timeout: Duration) -> std::io::Result<()> {
        self.set_timeout(timeout).map_err(std::io::Error::from)
    }
}

/// A connection to one controller.
pub struct DeviceClient {
    io: Box<dyn Transport>,
    reader: FrameReader<MAX_FRAME>,
    next_id: u32,
    timeout: Duration,
}

impl DeviceClient {
    /// Opens `tcp://HOST:PORT` or a serial device path (115200 8N1).
    pub fn open(port: &str) -> Result<Self, DeviceError> {
        let open_err = |reason: String| DeviceError::Open { port: port.to_string(), reason };
        let io: Box<dyn Transport> = if let Some(addr) = port.strip_prefix("tcp://") {
            let stream = TcpStream::connect(addr).map_err(|e| open_err(e.to_string()))?;
            stream.set_nodelay(true).map_err(|e| open_err(e.to_string()))?;
            Box::new(stream)
        } else {
            let serial =
                serialport::new(port, 115_200).timeout(DEFAULT_TIMEOUT).open().map_err(|e| {
                    open_err(format!("{e} (expected tcp://HOST:PORT or a serial device)"))
                })?;
            Box::new(serial)
        };
        Ok(Self::from_transport(io))
    }

    /// Wraps an already open transport.
    pub fn from_transport(io: Box<dyn Transport>) -> Self {
        Self { io, reader: FrameReader::new(), next_id: 1, timeout: DEFAULT_TIMEOUT }
    }

    /// Sets how long to wait for each response.
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// Writes raw bytes to the link (tests use it to send garbage).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), DeviceError> {
        self.io.write_all(bytes)?;
        self.io.flush()?;
        Ok(())
    }

    /// Sends `body` and waits for the response with the same id.
    /// A [`Response::Error`] for our id becomes [`DeviceError::Refused`].
    pub fn request(&mut self, body: Request) -> Result<Response, DeviceError> {
        self.request_with_version(PROTOCOL_VERSION, body)
    }

    /// Like [`Self::request`] but claims protocol `version` (to test how peers refuse others).
    pub fn request_with_version(
        &mut self,
        version: u16,
        body: Request,
    ) -> Result<Response, DeviceError> {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1).max(1);
        let mut buf = vec![0u8; MAX_FRAME + 2];
        let bytes = link::encode(&Envelope { version, id, body }, &mut buf)
            .map_err(|_| DeviceError::Io(std::io::Error::other("request does not fit a frame")))?;
        self.send_raw(bytes)?;
        match self.receive(id)? {
            Response::Error(error) => Err(DeviceError::Refused { id, error }),
            Response::Rejected(error) => Err(DeviceError::Rejected { id, error }),
            response => Ok(response),
        }
    }

    fn receive(&mut self, id: u32) -> Result<Response, DeviceError> {
        let deadline = Instant::now() + self.timeout;
        let mut chunk = [0u8; 256];
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(DeviceError::Timeout { id, timeout: self.timeout });
            }
            self.io.set_read_timeout(left)?;
            let n = match self.io.read(&mut chunk) {
                Ok(0) => {
                    return Err(DeviceError::Io(std::io::Error::new(
                        ErrorKind::UnexpectedEof,
                        "controller closed the link",
                    )));
                }
                Ok(n) => n,
                Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock) => {
                    continue;
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => return Err(e.into()),
            };
            for &byte in &chunk[..n] {
                match self.reader.push(byte) {
                    None => {}
                    Some(Err(e)) => return Err(DeviceError::BadFrame(e)),
                    Some(Ok(frame)) => match link::decode::<Response>(frame) {
                        Ok(env) if env.id == id => return Ok(env.body),
                        Ok(_) => {} // a stale answer to an earlier request or to garbage
                        Err(e) => return Err(DeviceError::BadFrame(e.error)),
                    },
                }
            }
        }
    }

    /// Round-trips a ping; returns the time it took.
    pub fn ping(&mut self) -> Result<Duration, DeviceError> {
        let nonce: u32 = rand_nonce();
        let start = Instant::now();
        match self.request(Request::Ping { nonce })? {
            Response::Pong { nonce: n } if n == nonce => Ok(start.elapsed()),
            other => Err(DeviceError::Unexpected { request: "Ping", response: Box::new(other) }),
        }
    }

    /// Asks for the firmware's identity.
    pub fn info(&mut self) -> Result<DeviceInfo, DeviceError> {
        match self.request(Request::GetInfo)? {
            Response::Info(info) => Ok(info),
            other => Err(DeviceError::Unexpected { request: "GetInfo", response: Box::new(other) }),
        }
    }
}

impl DeviceClient {
    fn expect_ack(&mut self, request: Request, name: &'static str) -> Result<(), DeviceError> {
        match self.request(request)? {
            Response::Ack => Ok(()),
            other => Err(DeviceError::Unexpected { request: name, response: Box::new(other) }),
        }
    }

    /// Manual drive: a steady sine at `freq_mhz` with amplitude `amplitude_q15`.
    pub fn drive(&mut self, freq_mhz: u32, amplitude_q15: u16) -> Result<(), DeviceError> {
        self.expect_ack(Request::Drive { freq_mhz, amplitude_q15 }, "Drive")
    }

    /// Sends `plan` and starts it.
    pub fn run_plan(&mut self, plan: Plan) -> Result<(), DeviceError> {
        self.expect_ack(Request::RunPlan(plan), "RunPlan")
    }

    /// Ramps the drive to zero (and clears a fault).
    pub fn stop(&mut self) -> Result<(), DeviceError> {
        self.expect_ack(Request::Stop, "Stop")
    }

    /// The drive's status.
    pub fn status(&mut self) -> Result<StatusReport, DeviceError> {
        match self.request(Request::Status)? {
            Response::Status(s) => Ok(s),
            other => Err(DeviceError::Unexpected { request: "Status", response: Box::new(other) }),
        }
    }
}

/// A nonce that differs between calls and processes (no RNG crate needed for that).
fn rand_nonce() -> u32 {
    use std::hash::{BuildHasher, RandomState};
    RandomState::new().hash_one(Instant::now()) as u32
}
