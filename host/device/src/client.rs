//! Client for the controller's link: a serial port (the board's USB CDC port or the ST-LINK
//! VCP) or `tcp://HOST:PORT` (the emulator). Frames are those of
//! [`chladni_shared::icd::link`] (protocol v4).
//!
//! - A client opens a *session*: a random session number and a random first request id, then
//!   `Hello` with its name, which checks the protocol version and names the client to others
//!   (a busy controller says who holds it).
//! - [`DeviceClient::call`] sends any request of the endpoint table and returns its typed
//!   reply; the controller's refusals and link errors come back as [`DeviceError`] variants.
//!   Frames of other sessions, late answers to earlier ids and frames that cannot be decoded
//!   are skipped, never acted on (see the private `link` module).
//! - Helpers wrap the sequences: chunked [`DeviceClient::upload`], paged
//!   [`DeviceClient::list_plans`], [`DeviceClient::wait_for_run`] (when a plan is done),
//!   telemetry ([`DeviceClient::subscribe`], [`DeviceClient::next_telemetry`]), sweeps
//!   ([`DeviceClient::sweep`], then [`DeviceClient::wait_for_run`], then
//!   [`DeviceClient::sweep_points`], paged and checked to be the sweep's).
//! - Dropping a client that may own the controller sends `Release`, so the next client need
//!   not wait for the owner's lease to lapse.

mod link;
#[cfg(test)]
mod tests;

use std::net::TcpStream;
use std::ops::ControlFlow;
use std::time::{Duration, Instant};

use chladni_shared::icd::link::{
    ClearFault, DeletePlan, DeviceInfo, DriveState, Endpoint, GetConfig, GetInfo, GetStatus,
    GetSweep, Hello, InjectFault, Level, LinkError, ListPlans, MAX_CLIENT_NAME, PROTOCOL_VERSION,
    Ping, Plan, Refusal, Release, Response, RunNumber, RunPlan, SetConfig, StatusReport, Stop,
    Subscribe, Sweep, SweepPoint, Telemetry, TestFault, UploadCommit,
};
use chladni_shared::icd::store::{
    CHUNK_STEPS, DeviceConfig, PlanRef, PlanSummary, UploadBegin, UploadChunk,
};

pub use link::Frame;

/// Default time to wait for one answer.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(3);
/// Time given to the `Release` a dropped client sends (best effort: the lease lapses anyway).
pub const RELEASE_TIMEOUT: Duration = Duration::from_millis(300);
/// How often [`DeviceClient::wait_for_run`] asks for the status.
pub(crate) const WAIT_POLL: Duration = Duration::from_millis(50);
/// A run whose number the status has not reached after this long never started.
pub const NEVER_STARTED_AFTER: Duration = Duration::from_secs(2);

/// Everything that can go wrong talking to the controller.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    /// The port string is neither `tcp://HOST:PORT` nor a serial device that opens.
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
    /// The other end closed the link (the emulator stopped, the cable was pulled).
    #[error("controller closed the link")]
    Closed,
    /// No answer with our session and id arrived in time.
    #[error("{}", timeout_message(request, *id, *timeout, *unreadable))]
    Timeout {
        /// The request's name.
        request: &'static str,
        /// The request id.
        id: u32,
        /// How long we waited.
        timeout: Duration,
        /// Frames that arrived meanwhile but could not be read.
        unreadable: u32,
    },
    /// The controller could not read our frame (bad CRC, malformed, too long); nothing was done.
    #[error("the controller could not read the request: {0}")]
    Link(LinkError),
    /// The controller read the request and refused it; nothing was changed.
    #[error("{0}")]
    Refused(Refusal),
    /// The controller answered with a response of another kind (a firmware bug).
    #[error(
        "the controller answered {request} with {response:?}: a firmware bug, please report it"
    )]
    Protocol {
        /// What we asked.
        request: &'static str,
        /// What came back.
        response: Box<Response>,
    },
    /// The controller's last sweep is not the one asked for (another client started one since,
    /// or the controller restarted): its points would be another sweep's.
    #[error(
        "the controller's last sweep is run {found}, not run {expected}: another sweep replaced \
         it (or the controller restarted); run the sweep again"
    )]
    StaleSweep {
        /// The sweep's run number.
        expected: u32,
        /// The run number of the sweep the controller holds (0: none since reset).
        found: u32,
    },
    /// The controller's sweep is not complete (it was stopped or faulted before its end).
    #[error("sweep run {run} has {done} of {total} points: it was stopped before its end")]
    SweepIncomplete {
        /// The sweep's run number.
        run: u32,
        /// Points measured.
        done: u16,
        /// Points asked for.
        total: u16,
    },
    /// The controller speaks another protocol version.
    #[error(
        "the controller speaks protocol version {device}, this chladni speaks {host}: flash \
         matching firmware with `chladni flash`"
    )]
    VersionMismatch {
        /// The controller's version.
        device: u16,
        /// This program's version.
        host: u16,
    },
}

fn timeout_message(request: &str, id: u32, timeout: Duration, unreadable: u32) -> String {
    let mut text = format!(
        "no answer to {request} (id {id}) within {:.1} s: is the controller running and is \
         this its port?",
        timeout.as_secs_f64()
    );
    if unreadable > 0 {
        text.push_str(&format!(
            " ({unreadable} frame(s) arrived that this chladni cannot read: if no other program \
             uses the link, the firmware may be older than this chladni; flash matching \
             firmware with `chladni flash`)"
        ));
    }
    text
}

/// How [`DeviceClient::send_tampered`] damages a frame (tests of the controller's checks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tamper {
    /// An intact frame.
    None,
    /// Claims another protocol version.
    Version(u16),
    /// The CRC does not match the bytes.
    CorruptCrc,
    /// One bit of the message body flipped after the CRC was computed (bit 0 is the lowest bit
    /// of the body's first byte), as noise on the wire would do.
    FlipBodyBit(usize),
}

/// A byte stream with a read timeout: the two transports implement it.
pub trait Transport: std::io::Read + std::io::Write + Send {
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

/// Opens `tcp://HOST:PORT` or a serial device path (115200 8N1; USB CDC ignores the rate).
pub fn open_transport(port: &str) -> Result<Box<dyn Transport>, DeviceError> {
    let open_err = |reason: String| DeviceError::Open { port: port.to_string(), reason };
    if let Some(addr) = port.strip_prefix("tcp://") {
        let stream = TcpStream::connect(addr).map_err(|e| open_err(e.to_string()))?;
        stream.set_nodelay(true).map_err(|e| open_err(e.to_string()))?;
        return Ok(Box::new(stream));
    }
    let serial = serialport::new(port, 115_200).timeout(DEFAULT_TIMEOUT).open().map_err(|e| {
        open_err(format!(
            "{e} (expected tcp://HOST:PORT or a serial device; `chladni device list` shows them)"
        ))
    })?;
    Ok(Box::new(serial))
}

/// How a run that [`DeviceClient::wait_for_run`] watched ended.
#[derive(Debug, Clone, PartialEq)]
pub enum RunOutcome {
    /// The run ended by itself: the status shows its number and the drive idle.
    Done(StatusReport),
    /// Another command (from any client: a stop, a drive, another plan) took over.
    Superseded(StatusReport),
    /// The status never reached the run's number within [`NEVER_STARTED_AFTER`].
    NeverStarted(StatusReport),
    /// The drive faulted during the run.
    Faulted(StatusReport),
    /// The caller's callback asked to stop waiting (the run goes on).
    Interrupted(StatusReport),
}

impl RunOutcome {
    /// The last status seen.
    pub fn status(&self) -> &StatusReport {
        match self {
            RunOutcome::Done(s)
            | RunOutcome::Superseded(s)
            | RunOutcome::NeverStarted(s)
            | RunOutcome::Faulted(s)
            | RunOutcome::Interrupted(s) => s,
        }
    }

    /// Lowercase name, as the CLI prints it.
    pub fn name(&self) -> &'static str {
        match self {
            RunOutcome::Done(_) => "done",
            RunOutcome::Superseded(_) => "superseded",
            RunOutcome::NeverStarted(_) => "never_started",
            RunOutcome::Faulted(_) => "faulted",
            RunOutcome::Interrupted(_) => "interrupted",
        }
    }
}

/// What a status says about run `run`, `waited` after it was accepted; `None`: not over yet.
pub fn judge_run(run: RunNumber, status: &StatusReport, waited: Duration) -> Option<RunOutcome> {
    let s = status.clone();
    if status.run > run {
        return Some(RunOutcome::Superseded(s));
    }
    if status.run == run {
        return match status.state {
            DriveState::Faulted => Some(RunOutcome::Faulted(s)),
            DriveState::Idle => Some(RunOutcome::Done(s)),
            _ => None,
        };
    }
    // The status still shows an older command: ours is queued, or was lost.
    (waited > NEVER_STARTED_AFTER).then_some(RunOutcome::NeverStarted(s))
}

/// A session with one controller.
pub struct DeviceClient {
    link: link::Link,
    info: DeviceInfo,
    /// A request that needs ownership was sent: this session may own the controller.
    may_own: bool,
}

impl DeviceClient {
    /// Opens `port` (`tcp://HOST:PORT` or a serial device) and starts a session named
    /// `client_name` (cut to [`MAX_CLIENT_NAME`] bytes).
    pub fn open(port: &str, client_name: &str) -> Result<Self, DeviceError> {
        Self::from_transport(open_transport(port)?, client_name)
    }

    /// Starts a session on an open transport: `Hello`, which checks the protocol version.
    pub fn from_transport(io: Box<dyn Transport>, client_name: &str) -> Result<Self, DeviceError> {
        Self::with_timeout(io, client_name, DEFAULT_TIMEOUT)
    }

    /// [`Self::from_transport`] with another answer timeout (for the `Hello` too).
    pub fn with_timeout(
        io: Box<dyn Transport>,
        client_name: &str,
        timeout: Duration,
    ) -> Result<Self, DeviceError> {
        let mut link = link::Link::new(io, timeout);
        let client = client_label(client_name);
        let info = call_on(&mut link, Hello { client })?;
        if info.protocol_version != PROTOCOL_VERSION {
            return Err(DeviceError::VersionMismatch {
                device: info.protocol_version,
                host: PROTOCOL_VERSION,
            });
        }
        Ok(Self { link, info, may_own: false })
    }

    /// The controller's identity, as it answered `Hello`.
    pub fn info(&self) -> &DeviceInfo {
        &self.info
    }

    /// This client's session number.
    pub fn session(&self) -> u32 {
        self.link.session
    }

    /// Sets how long to wait for each answer.
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.link.timeout = timeout;
    }

    /// Sends `request` and returns its reply. A refusal is [`DeviceError::Refused`], a frame
    /// the controller could not read [`DeviceError::Link`].
    pub fn call<E: Endpoint>(&mut self, request: E) -> Result<E::Reply, DeviceError> {
        let request = request.into_request();
        self.may_own |= request.needs_owner();
        let response = self.link.exchange(request)?;
        reply_of::<E>(response)
    }

    /// Writes raw bytes to the link (tests send garbage with it).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), DeviceError> {
        self.link.send_raw(bytes)
    }

    /// Sends `request` in a damaged frame and returns its id, without waiting for an answer.
    pub fn send_tampered<E: Endpoint>(
        &mut self,
        request: E,
        tamper: Tamper,
    ) -> Result<u32, DeviceError> {
        let request = request.into_request();
        self.may_own |= request.needs_owner();
        self.link.send(request, tamper)
    }

    /// Every frame that arrives within `within`, of any session, decoded or not (tests).
    pub fn receive_frames(&mut self, within: Duration) -> Result<Vec<Frame>, DeviceError> {
        self.link.receive_frames(within)
    }
}

/// `client_name` cut to [`MAX_CLIENT_NAME`] bytes at a character boundary.
fn client_label(client_name: &str) -> heapless::String<MAX_CLIENT_NAME> {
    let mut label = heapless::String::new();
    for c in client_name.chars() {
        if label.push(c).is_err() {
            break;
        }
    }
    label
}

/// [`DeviceClient::call`] on a bare link (the `Hello` before the client exists).
fn call_on<E: Endpoint>(link: &mut link::Link, request: E) -> Result<E::Reply, DeviceError> {
    reply_of::<E>(link.exchange(request.into_request())?)
}

/// The typed reply in `response`, or the error it carries.
fn reply_of<E: Endpoint>(response: Response) -> Result<E::Reply, DeviceError> {
    match response {
        Response::Error(error) => Err(DeviceError::Link(error)),
        Response::Refused(refusal) => Err(DeviceError::Refused(refusal)),
        other => E::reply(other).map_err(|response| DeviceError::Protocol {
            request: E::NAME,
            response: response.into(),
        }),
    }
}

impl DeviceClient {
    /// Round-trips a ping; returns the time it took.
    pub fn ping(&mut self) -> Result<Duration, DeviceError> {
        let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH);
        let nonce = self.link.session ^ now.map_or(0x5eed, |t| t.subsec_nanos());
        let start = Instant::now();
        let echoed = self.call(Ping { nonce })?;
        if echoed != nonce {
            return Err(DeviceError::Protocol {
                request: "Ping",
                response: Box::new(Response::Ping(echoed)),
            });
        }
        Ok(start.elapsed())
    }

    /// Asks for the firmware's identity again.
    pub fn get_info(&mut self) -> Result<DeviceInfo, DeviceError> {
        self.call(GetInfo)
    }

    /// Manual drive: a steady sine at `freq_mhz` at `level` (amplitude or acceleration).
    pub fn drive(&mut self, freq_mhz: u32, level: Level) -> Result<RunNumber, DeviceError> {
        self.call(chladni_shared::icd::link::Drive { freq_mhz, level })
    }

    /// Runs a stored plan, `repeat` times instead of its stored count if given.
    pub fn run(&mut self, plan: PlanRef, repeat: Option<u16>) -> Result<RunNumber, DeviceError> {
        self.call(RunPlan { plan, repeat })
    }

    /// Ramps the drive to zero (a latched fault stays: [`Self::clear_fault`]). Taken from any
    /// session.
    pub fn stop(&mut self) -> Result<RunNumber, DeviceError> {
        self.call(Stop)
    }

    /// Clears a latched fault (nothing else does); answered with its run number.
    pub fn clear_fault(&mut self) -> Result<RunNumber, DeviceError> {
        self.call(ClearFault)
    }

    /// Starts a frequency sweep (a run: wait for it with [`Self::wait_for_run`], then read its
    /// points with [`Self::sweep_points`]).
    pub fn sweep(&mut self, sweep: Sweep) -> Result<RunNumber, DeviceError> {
        self.call(sweep)
    }

    /// Every point of sweep `run`, following the pages. A page of another run is
    /// [`DeviceError::StaleSweep`]; a sweep with points missing is
    /// [`DeviceError::SweepIncomplete`].
    pub fn sweep_points(&mut self, run: RunNumber) -> Result<Vec<SweepPoint>, DeviceError> {
        let mut points = Vec::new();
        loop {
            let page = self.call(GetSweep { from: points.len() as u16 })?;
            if page.run != run {
                return Err(DeviceError::StaleSweep { expected: run.0, found: page.run.0 });
            }
            if page.done < page.total {
                let (done, total) = (page.done, page.total);
                return Err(DeviceError::SweepIncomplete { run: run.0, done, total });
            }
            let got = page.points.len();
            points.extend(page.points);
            // An empty page before the end (a firmware bug) cannot loop for ever.
            if got == 0 || points.len() >= usize::from(page.total) {
                return Ok(points);
            }
        }
    }

    /// Simulates a fault (QEMU only; a board refuses it with `Refused(Unsupported)`).
    pub fn inject_fault(&mut self, fault: TestFault) -> Result<(), DeviceError> {
        self.call(InjectFault(fault))
    }

    /// The drive's status.
    pub fn status(&mut self) -> Result<StatusReport, DeviceError> {
        self.call(GetStatus)
    }

    /// The stored configuration.
    pub fn config(&mut self) -> Result<DeviceConfig, DeviceError> {
        self.call(GetConfig)
    }

    /// Replaces the configuration; returns the one now in effect.
    pub fn set_config(&mut self, config: DeviceConfig) -> Result<DeviceConfig, DeviceError> {
        self.call(SetConfig(config))
    }

    /// Deletes a stored plan; returns what was deleted.
    pub fn delete(&mut self, plan: PlanRef) -> Result<PlanSummary, DeviceError> {
        self.call(DeletePlan { plan })
    }

    /// What the controller's plan store holds (its own format, data it did not write, or no
    /// flash).
    pub fn store_info(&mut self) -> Result<chladni_shared::icd::store::StoreInfo, DeviceError> {
        self.call(chladni_shared::icd::link::GetStore)
    }

    /// Erases the controller's whole plan store (every plan and the configuration, or the data
    /// it did not write) and formats it. Waits up to [`FORMAT_TIMEOUT`] for the answer: the
    /// chip erases a 2 KiB page in 22–25 ms, 256 of them in 6 s.
    pub fn format_store(&mut self) -> Result<chladni_shared::icd::store::StoreInfo, DeviceError> {
        let timeout = self.link.timeout;
        self.link.timeout = timeout.max(FORMAT_TIMEOUT);
        let formatted = self.call(chladni_shared::icd::link::FormatStore);
        self.link.timeout = timeout;
        formatted
    }
}

/// Longest a store format may take to answer (every page of the 512 KiB bank erased at the
/// datasheet's 24.47 ms, with margin for a loaded emulator).
pub const FORMAT_TIMEOUT: Duration = Duration::from_secs(30);

impl DeviceClient {
    /// Uploads `plan` (begin, chunks of [`CHUNK_STEPS`] steps, commit) into `slot`, or the slot
    /// the controller picks (the plan of the same name, else the lowest free one).
    /// `progress(steps_sent, steps_total)` is called after each chunk.
    pub fn upload(
        &mut self,
        plan: &Plan,
        slot: Option<u8>,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<PlanSummary, DeviceError> {
        let total = plan.steps.len();
        self.call(UploadBegin::of(plan, slot))?;
        progress(0, total);
        for (index, chunk) in plan.steps.chunks(CHUNK_STEPS).enumerate() {
            let steps = heapless::Vec::from_slice(chunk).expect("chunks() yields ≤ CHUNK_STEPS");
            let received = self.call(UploadChunk { index: index as u16, steps })?;
            progress(usize::from(received), total);
        }
        self.call(UploadCommit)
    }

    /// Every stored plan (following the pages) and the free flash, bytes.
    pub fn list_plans(&mut self) -> Result<(Vec<PlanSummary>, u32), DeviceError> {
        let (mut plans, mut from_slot) = (Vec::new(), 0u8);
        loop {
            let page = self.call(ListPlans { from_slot })?;
            plans.extend(page.plans);
            match page.next {
                // Only forward: a page that points back (a firmware bug) cannot loop for ever.
                Some(next) if next > from_slot => from_slot = next,
                _ => return Ok((plans, page.free_bytes)),
            }
        }
    }

    /// Polls the status until run `run` is over (see [`judge_run`]). `on_status` sees every
    /// status; returning `Break` stops waiting ([`RunOutcome::Interrupted`], the run goes on).
    pub fn wait_for_run(
        &mut self,
        run: RunNumber,
        mut on_status: impl FnMut(&StatusReport) -> ControlFlow<()>,
    ) -> Result<RunOutcome, DeviceError> {
        let accepted = Instant::now();
        loop {
            let status = self.status()?;
            if on_status(&status).is_break() {
                return Ok(RunOutcome::Interrupted(status));
            }
            if let Some(outcome) = judge_run(run, &status, accepted.elapsed()) {
                return Ok(outcome);
            }
            std::thread::sleep(WAIT_POLL);
        }
    }

    /// Asks for `count` telemetry samples at `rate_hz` (replacing any stream on the
    /// controller; `count` 0 ends it). Read them with [`Self::next_telemetry`].
    pub fn subscribe(&mut self, rate_hz: u16, count: u32) -> Result<(), DeviceError> {
        self.call(Subscribe { rate_hz, count })
    }

    /// The next sample of this client's latest subscription, waiting up to `within`; `None`
    /// if none came in time.
    pub fn next_telemetry(&mut self, within: Duration) -> Result<Option<Telemetry>, DeviceError> {
        self.link.next_telemetry(within)
    }
}

impl Drop for DeviceClient {
    fn drop(&mut self) {
        if self.may_own {
            // Best effort: the lease lapses by itself after OWNER_LEASE_MS anyway.
            self.link.timeout = RELEASE_TIMEOUT;
            let _ = call_on(&mut self.link, Release);
        }
    }
}
