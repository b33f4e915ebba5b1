//! Serves the host link: reads frames, answers every request exactly once (or names what was
//! wrong), keeps one owner at a time, and streams telemetry.
//!
//! Each request is carried out by the [`Handler`] method its line of the endpoint table names
//! (the impl on [`Link`]); the method returns that request's reply type, and the shared crate
//! turns it into the response, so an answer of the wrong kind does not compile.
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
    self, Board, DeviceInfo, Envelope, FrameReader, Handler, InjectFault, LinkError,
    MAX_CLIENT_NAME, MAX_FRAME, MAX_TELEMETRY_HZ, OWNER_LEASE_MS, PROTOCOL_VERSION, Refusal,
    Request, Response, RunNumber, StatusReport, SweepPage, Telemetry, TestFault,
};
use chladni_shared::icd::plan::Plan;
use chladni_shared::icd::store::{
    self, DeviceConfig, PlanPage, PlanSummary, StoreError, StoreInfo, StoreState,
};
use embassy_futures::select::{Either, select};
use embassy_time::{Duration, Instant, Timer};
use embedded_io_async::{Read, Write};
use embedded_storage_async::nor_flash::NorFlash;

use super::drive::{CheckedSweep, Command, DriveShared};
use super::store::PlanStore;
use super::watchdog::{Supervisor, Task};

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
    /// Simulates a fault (the QEMU board's test hook); `None` on real hardware, which
    /// answers `InjectFault` with `Unsupported`.
    pub inject: Option<fn(TestFault)>,
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
        self.drive.set_control(self.config.control);
    }

    /// The response to one frame from [`FrameReader::push`]: the answer to its request, or the
    /// error that kept it from being read (with the frame's session and id when readable).
    pub async fn respond(
        &mut self,
        frame: Result<&mut [u8], LinkError>,
        now: Instant,
    ) -> Envelope<Response> {
        let mut out = blank();
        self.respond_into(frame, now, &mut out).await;
        out
    }

    /// [`Link::respond`] written into `out`, the link task's one response buffer (a response
    /// is up to ~660 bytes: built in place and encoded from there, it is never moved by value
    /// through the callers' frames).
    pub async fn respond_into(
        &mut self,
        frame: Result<&mut [u8], LinkError>,
        now: Instant,
        out: &mut Envelope<Response>,
    ) {
        let (session, id) = match frame.map(link::decode::<Request>) {
            Ok(Ok(env)) => {
                defmt::debug!(
                    "link: {=u32:08x}/{=u32} {=str}",
                    env.session,
                    env.id,
                    env.body.name()
                );
                let (session, id) = (env.session, env.id);
                self.handle_into(session, id, env.body, now, &mut out.body).await;
                (session, id)
            }
            Ok(Err(e)) => {
                out.body = Response::Error(e.error);
                (e.session, e.id)
            }
            Err(error) => {
                out.body = Response::Error(error);
                (0, 0)
            }
        };
        match &out.body {
            Response::Error(e) => defmt::warn!("link: refused frame ({=u32}): {}", id, e),
            Response::Refused(r) => defmt::info!("link: refused request {=u32}: {}", id, r),
            _ => {}
        }
        out.version = PROTOCOL_VERSION;
        out.session = session;
        out.id = id;
    }

    /// Answers one request of `session`.
    pub async fn handle(
        &mut self,
        session: u32,
        id: u32,
        request: Request,
        now: Instant,
    ) -> Response {
        let mut out = blank().body;
        self.handle_into(session, id, request, now, &mut out).await;
        out
    }

    /// [`Link::handle`] written into `out`.
    pub async fn handle_into(
        &mut self,
        session: u32,
        id: u32,
        request: Request,
        now: Instant,
        out: &mut Response,
    ) {
        match self.sessions.admit(session, &request, now) {
            Err(refusal) => *out = Response::Refused(refusal),
            Ok(()) => request.answer_into(self, Call { session, id, now }, out).await,
        }
    }

    fn store(&mut self) -> Result<&mut PlanStore<F>, Refusal> {
        self.store.as_mut().ok_or(Refusal::Store(StoreError::Flash))
    }

    /// Hands a command to the drive; its run number.
    fn submit(&self, command: Command) -> Result<RunNumber, Refusal> {
        self.drive.submit(command).map_err(Refusal::Drive)
    }

    /// Starts (replaces, or with a count of 0 ends) the telemetry stream.
    fn start_stream(&mut self, call: Call, sub: link::Subscribe) -> Result<(), Refusal> {
        let Call { session, id, now } = call;
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

    /// Writes a chunk the store accepted before writing it (`PlanStore::chunk_deferred`); its
    /// failure is answered to the upload's next request.
    pub async fn flush_store(&mut self) {
        if let Some(store) = &mut self.store {
            let _ = store.flush().await;
        }
    }

    /// When the next telemetry sample is due, if a stream runs.
    pub fn next_sample_at(&self) -> Option<Instant> {
        self.stream.map(|s| s.next)
    }

    /// The telemetry sample due at `now`, if any (and schedules the next one).
    pub fn sample(&mut self, now: Instant) -> Option<Envelope<Response>> {
        let mut out = blank();
        self.sample_into(now, &mut out).then_some(out)
    }

    /// [`Link::sample`] written into `out`; whether a sample was due.
    pub fn sample_into(&mut self, now: Instant, out: &mut Envelope<Response>) -> bool {
        let Some(stream) = self.stream.as_mut().filter(|s| s.next <= now) else {
            return false;
        };
        stream.left -= 1;
        *out = Envelope {
            version: PROTOCOL_VERSION,
            session: stream.session,
            id: stream.id,
            body: Response::Telemetry(Telemetry {
                seq: stream.seq,
                left: stream.left,
                status: self.drive.status(),
            }),
        };
        stream.seq += 1;
        // Catch up without bursts: a late sample moves the schedule, it does not pile up.
        stream.next = (stream.next + stream.period).max(now);
        if stream.left == 0 {
            self.stream = None;
        }
        true
    }
}

/// An envelope to be overwritten (the link task's response buffer before its first answer).
pub fn blank() -> Envelope<Response> {
    Envelope {
        version: PROTOCOL_VERSION,
        session: 0,
        id: 0,
        body: Response::Error(LinkError::Malformed),
    }
}

/// Who sent the request being answered, and when.
#[derive(Debug, Clone, Copy)]
pub struct Call {
    session: u32,
    id: u32,
    now: Instant,
}

/// The link's answer to each request of the table (`chladni_shared::icd::link::endpoints!`):
/// each method returns its own request's reply, so no request gets another one's answer.
impl<F: NorFlash> Handler for Link<'_, F> {
    type Context = Call;

    async fn hello(&mut self, call: Call, hello: link::Hello) -> Result<DeviceInfo, Refusal> {
        self.sessions.hello(call.session, hello.client);
        Ok(self.identity.info())
    }

    async fn ping(&mut self, _: Call, ping: link::Ping) -> Result<u32, Refusal> {
        Ok(ping.nonce)
    }

    async fn get_info(&mut self, _: Call, _: link::GetInfo) -> Result<DeviceInfo, Refusal> {
        Ok(self.identity.info())
    }

    async fn release(&mut self, call: Call, _: link::Release) -> Result<(), Refusal> {
        self.sessions.release(call.session);
        Ok(())
    }

    async fn drive(&mut self, _: Call, d: link::Drive) -> Result<RunNumber, Refusal> {
        self.submit(Command::Drive { freq_mhz: d.freq_mhz, level: d.level })
    }

    async fn run_plan(&mut self, _: Call, run: link::RunPlan) -> Result<RunNumber, Refusal> {
        let store = self.store.as_mut().ok_or(Refusal::Store(StoreError::Flash))?;
        store.load(&run.plan, &mut self.plan).await?;
        if let Some(repeat) = run.repeat {
            self.plan.repeat = repeat;
        }
        let checked = self.drive.check_plan(&self.plan).await.map_err(Refusal::Drive)?;
        self.drive.stage_plan(checked).map_err(Refusal::Drive)
    }

    async fn stop(&mut self, _: Call, _: link::Stop) -> Result<RunNumber, Refusal> {
        self.submit(Command::Stop)
    }

    async fn status(&mut self, _: Call, _: link::GetStatus) -> Result<StatusReport, Refusal> {
        Ok(self.drive.status())
    }

    async fn upload_begin(&mut self, _: Call, begin: store::UploadBegin) -> Result<u8, Refusal> {
        let limits = self.config.limits;
        self.store()?.begin(begin, &limits).await
    }

    async fn upload_chunk(&mut self, _: Call, chunk: store::UploadChunk) -> Result<u16, Refusal> {
        let limits = self.config.limits;
        // Written after the answer is sent (`Link::flush_store`), while the next chunk comes.
        self.store()?.chunk_deferred(chunk, &limits).await
    }

    async fn upload_commit(
        &mut self,
        _: Call,
        _: link::UploadCommit,
    ) -> Result<PlanSummary, Refusal> {
        let limits = self.config.limits;
        self.store()?.commit(&limits).await
    }

    async fn list_plans(&mut self, _: Call, list: link::ListPlans) -> Result<PlanPage, Refusal> {
        self.store()?.list(list.from_slot).await
    }

    async fn delete_plan(
        &mut self,
        _: Call,
        delete: link::DeletePlan,
    ) -> Result<PlanSummary, Refusal> {
        self.store()?.delete(&delete.plan).await
    }

    async fn subscribe(&mut self, call: Call, sub: link::Subscribe) -> Result<(), Refusal> {
        self.start_stream(call, sub)
    }

    async fn get_config(&mut self, _: Call, _: link::GetConfig) -> Result<DeviceConfig, Refusal> {
        Ok(self.config)
    }

    async fn set_config(&mut self, _: Call, set: link::SetConfig) -> Result<DeviceConfig, Refusal> {
        set.0.validate().map_err(Refusal::Config)?;
        self.config = self.store()?.set_config(set.0).await?;
        self.drive.set_limits(self.config.limits);
        self.drive.set_control(self.config.control);
        Ok(self.config)
    }

    async fn clear_fault(&mut self, _: Call, _: link::ClearFault) -> Result<RunNumber, Refusal> {
        self.submit(Command::ClearFault)
    }

    async fn sweep(&mut self, _: Call, sweep: link::Sweep) -> Result<RunNumber, Refusal> {
        let sweep = CheckedSweep::new(sweep).map_err(Refusal::Sweep)?;
        self.submit(Command::Sweep(sweep))
    }

    async fn get_sweep(&mut self, _: Call, get: link::GetSweep) -> Result<SweepPage, Refusal> {
        Ok(self.drive.sweep_page(get.from))
    }

    async fn get_store(&mut self, _: Call, _: link::GetStore) -> Result<StoreInfo, Refusal> {
        Ok(match &mut self.store {
            Some(store) => store.info().await,
            None => StoreInfo { state: StoreState::Unavailable, layout: 0, area_bytes: 0 },
        })
    }

    async fn format_store(&mut self, _: Call, _: link::FormatStore) -> Result<StoreInfo, Refusal> {
        let info = self.store()?.format().await?;
        // The configuration went with the rest: back to the default, as at a first boot.
        self.config = DeviceConfig::DEFAULT;
        self.drive.set_limits(self.config.limits);
        self.drive.set_control(self.config.control);
        Ok(info)
    }

    async fn inject_fault(&mut self, _: Call, inject: InjectFault) -> Result<(), Refusal> {
        let simulate = self.identity.inject.ok_or(Refusal::Unsupported)?;
        // The drive's sample clock at the injection, for the tests' fault latencies (the
        // status polled before it is a round trip older).
        defmt::warn!("link: simulating {} at sample {=u64}", inject.0, self.drive.clock());
        simulate(inject.0);
        Ok(())
    }
}

/// Longest one frame may take to leave. A host that stops reading (a USB host with no program
/// holding the port, a socket nobody reads) would otherwise hold the link in `send` for ever:
/// no request served (a stop among them) and no check-in, so the watchdog would reset the
/// controller mid-run. Past this the frame is dropped, cut where it was; the host's reader
/// resynchronises at the next frame's leading delimiter. Below the watchdog's 250 ms check-in
/// period, so a link dropping every frame still checks in each period.
pub const WRITE_LIMIT: Duration = Duration::from_millis(200);

/// Writes one envelope as a frame, within [`WRITE_LIMIT`].
async fn send<P: Write>(port: &mut P, envelope: &Envelope<Response>, tx: &mut [u8]) {
    match link::encode(envelope, tx) {
        Ok(bytes) => match select(port.write_all(bytes), Timer::after(WRITE_LIMIT)).await {
            Either::First(Ok(())) => {}
            Either::First(Err(_)) => defmt::warn!("link: write error"),
            Either::Second(()) => {
                defmt::warn!(
                    "link: the host did not take the frame within {=u64} ms: dropped",
                    WRITE_LIMIT.as_millis()
                )
            }
        },
        Err(_) => defmt::error!("link: response {=u32} does not fit a frame", envelope.id),
    }
}

/// Longest the link waits for a byte before checking in with the watchdog's supervisor.
const CHECK_IN: Duration = Duration::from_millis(100);

/// Runs the link forever on `port`, checking in with `supervisor` at least every
/// [`CHECK_IN`] (an idle link is a live link; a link stuck in a request is not).
///
/// Reading waits alongside the next telemetry sample; the read is the only future ever
/// cancelled (a byte stream read loses nothing when dropped), never a store operation.
pub async fn serve<F: NorFlash, P: Read + Write>(
    link: &mut Link<'_, F>,
    port: &mut P,
    supervisor: &'static Supervisor,
) -> ! {
    // The store's flash operations are the link's progress (a request that collects garbage
    // over several pages checks in at each operation, not only when it is answered).
    if let Some(store) = &mut link.store {
        store.set_progress(supervisor, Task::Link);
    }
    let mut reader = FrameReader::<MAX_FRAME>::new();
    let mut rx = [0u8; 64];
    let mut tx = [0u8; link::ENCODE_BUF];
    // The one response buffer: answers and samples are built here and encoded from here.
    let mut out = blank();
    loop {
        supervisor.check_in(Task::Link);
        let check_in = Instant::now() + CHECK_IN;
        let due = link.next_sample_at().map_or(check_in, |at| at.min(check_in));
        let n = match select(port.read(&mut rx), Timer::at(due)).await {
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
                if link.sample_into(Instant::now(), &mut out) {
                    send(port, &out, &mut tx).await;
                }
                continue;
            }
        };
        for &byte in &rx[..n] {
            let Some(frame) = reader.push(byte) else { continue };
            link.respond_into(frame, Instant::now(), &mut out).await;
            send(port, &out, &mut tx).await;
            // An upload chunk answered before it was written: written now, while the host
            // sends the next one (the flash programs for ~3 ms a chunk on the chip).
            link.flush_store().await;
            // A chunk may hold several frames, each reply up to WRITE_LIMIT late: each one
            // served is progress, so the watchdog hears of it.
            supervisor.check_in(Task::Link);
        }
    }
}
