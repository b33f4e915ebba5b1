//! Serves the host link: reads frames, answers every request exactly once (or names what was
//! wrong), keeps one owner at a time, and streams telemetry.
//!
//! Garbage never stops the loop: a bad frame costs one error response, and the reader
//! resynchronises at the next delimiter. Nothing in a frame is acted on unless its CRC matches
//! and it decodes whole.
//!
//! Ownership ([`Sessions`]): requests that change the controller are taken from one client
//! session at a time. Another session is refused at once with the owner's name, so a command
//! that a host reported as failed never runs later. The owner keeps the controller while it
//! sends requests, and loses it on `Release` or after [`OWNER_LEASE_MS`] of silence (a killed
//! client cannot hold it for ever). `Stop` is taken from anyone.

use chladni_shared::icd::link::{
    self, Board, DeviceInfo, Endpoint, Envelope, FrameReader, LinkError, MAX_CLIENT_NAME,
    MAX_FRAME, MAX_TELEMETRY_HZ, OWNER_LEASE_MS, PROTOCOL_VERSION, Refusal, Request, Response,
    Telemetry,
};
use chladni_shared::icd::plan::Plan;
use chladni_shared::icd::store::{self, DeviceConfig, StoreError};
use embassy_futures::select::{Either, select};
use embassy_time::{Duration, Instant, Timer};
use embedded_io_async::{Read, Write};
use embedded_storage_async::nor_flash::NorFlash;

use super::drive::{Command, DriveShared};
use super::store::PlanStore;

/// Pause after a failed read before trying again, ms (short enough not to lose a UART byte
/// burst behind a framing error: the port's RX buffer keeps receiving meanwhile).
const READ_ERROR_BACKOFF_MS: u64 = 10;

/// Client names remembered from `Hello` (the owner's is shown to others).
const NAMES: usize = 4;

/// What the link needs to know about the device to answer requests.
#[derive(Debug, Clone, Copy)]
pub struct Identity {
    /// The board this image runs on.
    pub board: Board,
}

impl Identity {
    /// The identity answered to `Hello` and `GetInfo`.
    pub fn info(&self) -> DeviceInfo {
        DeviceInfo {
            firmware_version: heapless::String::try_from(crate::FIRMWARE_VERSION)
                .unwrap_or_default(),
            board: self.board,
            protocol_version: PROTOCOL_VERSION,
            build_id: crate::BUILD_ID,
        }
    }
}

type ClientName = heapless::String<MAX_CLIENT_NAME>;

/// The session that owns the controller.
#[derive(Debug, Clone)]
struct Owner {
    session: u32,
    name: ClientName,
    last: Instant,
}

/// Client sessions: who owns the controller, and the names clients gave.
#[derive(Debug, Default)]
pub struct Sessions {
    owner: Option<Owner>,
    names: heapless::Deque<(u32, ClientName), NAMES>,
}

impl Sessions {
    /// No owner, no names.
    pub const fn new() -> Self {
        Self { owner: None, names: heapless::Deque::new() }
    }

    /// Remembers the name `session` gave in its `Hello`.
    pub fn hello(&mut self, session: u32, name: ClientName) {
        if let Some(owner) = self.owner.as_mut().filter(|o| o.session == session) {
            owner.name = name.clone();
        }
        self.names.retain(|(s, _)| *s != session);
        if self.names.is_full() {
            self.names.pop_front();
        }
        let _ = self.names.push_back((session, name));
    }

    /// Whether `session` may send `request` now; takes ownership for it when it needs it and
    /// nobody holds it. Any request of the owner renews its lease.
    pub fn admit(&mut self, session: u32, request: &Request, now: Instant) -> Result<(), Refusal> {
        if let Some(owner) = &mut self.owner {
            if owner.session == session {
                owner.last = now;
                return Ok(());
            }
            if now.saturating_duration_since(owner.last).as_millis() > OWNER_LEASE_MS as u64 {
                defmt::info!("link: ownership of session {=u32:08x} lapsed", owner.session);
                self.owner = None;
            }
        }
        if !request.needs_owner() {
            return Ok(());
        }
        match &self.owner {
            Some(owner) => Err(Refusal::Busy {
                owner: owner.name.clone(),
                idle_ms: now.saturating_duration_since(owner.last).as_millis() as u32,
            }),
            None => {
                let name = self.name_of(session);
                defmt::info!(
                    "link: session {=u32:08x} ({=str}) owns the controller",
                    session,
                    name.as_str()
                );
                self.owner = Some(Owner { session, name, last: now });
                Ok(())
            }
        }
    }

    /// Ends `session`'s ownership, if it holds it.
    pub fn release(&mut self, session: u32) {
        if self.owner.as_ref().is_some_and(|o| o.session == session) {
            self.owner = None;
        }
    }

    fn name_of(&self, session: u32) -> ClientName {
        let named = self.names.iter().find(|(s, _)| *s == session);
        named.map(|(_, n)| n.clone()).unwrap_or_default()
    }
}

/// The telemetry stream in progress.
#[derive(Debug, Clone, Copy)]
struct Stream {
    session: u32,
    id: u32,
    period: Duration,
    next: Instant,
    seq: u32,
    left: u32,
}

/// The link's state: everything a request can touch.
pub struct Link<'a, F: NorFlash> {
    identity: Identity,
    drive: &'a DriveShared,
    store: Option<PlanStore<F>>,
    config: DeviceConfig,
    sessions: Sessions,
    stream: Option<Stream>,
    /// Where a stored plan is read before it goes to the drive (a 256-step plan is ~4 KiB:
    /// kept here rather than on the stack).
    plan: Plan,
}

impl<'a, F: NorFlash> Link<'a, F> {
    /// A link over `store` (`None`: no flash, so nothing can be stored), with the default
    /// configuration until [`Link::load_config`].
    pub fn new(identity: Identity, drive: &'a DriveShared, store: Option<PlanStore<F>>) -> Self {
        Self {
            identity,
            drive,
            store,
            config: DeviceConfig::DEFAULT,
            sessions: Sessions::new(),
            stream: None,
            plan: Plan { name: heapless::String::new(), repeat: 0, steps: heapless::Vec::new() },
        }
    }

    /// Reads the stored configuration (the default without one) and applies it to the drive.
    // Separate from `new` so that no future ever holds a whole `Link` (~17 KiB) by value.
    pub async fn load_config(&mut self) {
        if let Some(store) = &mut self.store {
            self.config = store.load_config().await;
        }
        self.drive.set_limits(self.config.limits);
    }

    /// The response to one frame from [`FrameReader::push`]: the answer to its request, or the
    /// error that kept it from being read (with the frame's session and id when readable).
    pub async fn respond(
        &mut self,
        frame: Result<&mut [u8], LinkError>,
        now: Instant,
    ) -> Envelope<Response> {
        let (session, id, body) = match frame.map(link::decode::<Request>) {
            Ok(Ok(env)) => {
                defmt::debug!(
                    "link: {=u32:08x}/{=u32} {=str}",
                    env.session,
                    env.id,
                    env.body.name()
                );
                let body = self.handle(env.session, env.id, env.body, now).await;
                (env.session, env.id, body)
            }
            Ok(Err(e)) => (e.session, e.id, Response::Error(e.error)),
            Err(error) => (0, 0, Response::Error(error)),
        };
        match &body {
            Response::Error(e) => defmt::warn!("link: refused frame ({=u32}): {}", id, e),
            Response::Refused(r) => defmt::info!("link: refused request {=u32}: {}", id, r),
            _ => {}
        }
        Envelope { version: PROTOCOL_VERSION, session, id, body }
    }

    /// Answers one request of `session`.
    pub async fn handle(
        &mut self,
        session: u32,
        id: u32,
        request: Request,
        now: Instant,
    ) -> Response {
        if let Err(refusal) = self.sessions.admit(session, &request, now) {
            return Response::Refused(refusal);
        }
        match self.dispatch(session, id, request, now).await {
            Ok(response) => response,
            Err(refusal) => Response::Refused(refusal),
        }
    }

    async fn dispatch(
        &mut self,
        session: u32,
        id: u32,
        request: Request,
        now: Instant,
    ) -> Result<Response, Refusal> {
        let limits = self.config.limits;
        let shared = self.drive;
        let drive = |command| shared.submit(command).map_err(Refusal::Drive);
        Ok(match request {
            Request::Hello(hello) => {
                self.sessions.hello(session, hello.client);
                link::Hello::respond(self.identity.info())
            }
            Request::Ping(ping) => link::Ping::respond(ping.nonce),
            Request::GetInfo(_) => link::GetInfo::respond(self.identity.info()),
            Request::Release(_) => {
                self.sessions.release(session);
                link::Release::respond(())
            }
            Request::Drive(d) => link::Drive::respond(drive(Command::Drive {
                freq_mhz: d.freq_mhz,
                level: d.level,
            })?),
            Request::ClearFault(_) => link::ClearFault::respond(drive(Command::ClearFault)?),
            Request::Sweep(_) | Request::GetSweep(_) | Request::InjectFault(_) => {
                return Err(Refusal::Unsupported);
            }
            Request::Stop(_) => link::Stop::respond(drive(Command::Stop)?),
            Request::Status(_) => link::GetStatus::respond(self.drive.status()),
            Request::RunPlan(run) => {
                let store = self.store.as_mut().ok_or(Refusal::Store(StoreError::Flash))?;
                store.load(&run.plan, &mut self.plan).await?;
                if let Some(repeat) = run.repeat {
                    self.plan.repeat = repeat;
                }
                let run = self.drive.run_plan(&self.plan);
                link::RunPlan::respond(run.map_err(Refusal::Drive)?)
            }
            Request::UploadBegin(begin) => {
                store::UploadBegin::respond(self.store()?.begin(begin, &limits).await?)
            }
            Request::UploadChunk(chunk) => {
                store::UploadChunk::respond(self.store()?.chunk(chunk, &limits).await?)
            }
            Request::UploadCommit(_) => {
                link::UploadCommit::respond(self.store()?.commit(&limits).await?)
            }
            Request::ListPlans(list) => {
                link::ListPlans::respond(self.store()?.list(list.from_slot).await?)
            }
            Request::DeletePlan(delete) => {
                link::DeletePlan::respond(self.store()?.delete(&delete.plan).await?)
            }
            Request::Subscribe(sub) => {
                self.subscribe(session, id, sub, now)?;
                link::Subscribe::respond(())
            }
            Request::GetConfig(_) => link::GetConfig::respond(self.config),
            Request::SetConfig(set) => {
                set.0.validate().map_err(Refusal::Config)?;
                self.config = self.store()?.set_config(set.0).await?;
                self.drive.set_limits(self.config.limits);
                link::SetConfig::respond(self.config)
            }
        })
    }

    fn store(&mut self) -> Result<&mut PlanStore<F>, Refusal> {
        self.store.as_mut().ok_or(Refusal::Store(StoreError::Flash))
    }

    fn subscribe(
        &mut self,
        session: u32,
        id: u32,
        sub: link::Subscribe,
        now: Instant,
    ) -> Result<(), Refusal> {
        if sub.count == 0 {
            self.stream = None;
            return Ok(());
        }
        if sub.rate_hz == 0 || sub.rate_hz > MAX_TELEMETRY_HZ {
            return Err(Refusal::TelemetryRate { rate_hz: sub.rate_hz });
        }
        let period = Duration::from_micros(1_000_000 / sub.rate_hz as u64);
        // The first sample follows the answer at once; then one per period.
        self.stream = Some(Stream { session, id, period, next: now, seq: 0, left: sub.count });
        Ok(())
    }

    /// When the next telemetry sample is due, if a stream runs.
    pub fn next_sample_at(&self) -> Option<Instant> {
        self.stream.map(|s| s.next)
    }

    /// The telemetry sample due at `now`, if any (and schedules the next one).
    pub fn sample(&mut self, now: Instant) -> Option<Envelope<Response>> {
        let stream = self.stream.as_mut().filter(|s| s.next <= now)?;
        stream.left -= 1;
        let sample = Telemetry { seq: stream.seq, left: stream.left, status: self.drive.status() };
        let envelope = Envelope {
            version: PROTOCOL_VERSION,
            session: stream.session,
            id: stream.id,
            body: Response::Telemetry(sample),
        };
        stream.seq += 1;
        // Catch up without bursts: a late sample moves the schedule, it does not pile up.
        stream.next = (stream.next + stream.period).max(now);
        if stream.left == 0 {
            self.stream = None;
        }
        Some(envelope)
    }
}

/// Writes one envelope as a frame.
async fn send<P: Write>(port: &mut P, envelope: &Envelope<Response>, tx: &mut [u8]) {
    match link::encode(envelope, tx) {
        Ok(bytes) => {
            if port.write_all(bytes).await.is_err() {
                defmt::warn!("link: write error");
            }
        }
        Err(_) => defmt::error!("link: response {=u32} does not fit a frame", envelope.id),
    }
}

/// Runs the link forever on `port`.
///
/// Reading waits alongside the next telemetry sample; the read is the only future ever
/// cancelled (a byte stream read loses nothing when dropped), never a store operation.
pub async fn serve<F: NorFlash, P: Read + Write>(link: &mut Link<'_, F>, port: &mut P) -> ! {
    let mut reader = FrameReader::<MAX_FRAME>::new();
    let mut rx = [0u8; 64];
    let mut tx = [0u8; link::ENCODE_BUF];
    loop {
        let due = link.next_sample_at();
        let tick = async {
            match due {
                Some(at) => Timer::at(at).await,
                None => core::future::pending().await,
            }
        };
        let n = match select(port.read(&mut rx), tick).await {
            Either::First(Ok(n)) => n,
            Either::First(Err(_)) => {
                defmt::warn!("link: read error");
                // Back off before reading again: some ports fail at once and keep failing
                // (a USB CDC endpoint before the host configures it), and without an await
                // here this loop would never yield and starve every other task (livelock).
                Timer::after_millis(READ_ERROR_BACKOFF_MS).await;
                continue;
            }
            Either::Second(()) => {
                if let Some(sample) = link.sample(Instant::now()) {
                    send(port, &sample, &mut tx).await;
                }
                continue;
            }
        };
        for &byte in &rx[..n] {
            let Some(frame) = reader.push(byte) else { continue };
            let envelope = link.respond(frame, Instant::now()).await;
            send(port, &envelope, &mut tx).await;
        }
    }
}
