//! The link owner: one thread holds the controller session; everything else sends it commands
//! and reads the status it publishes.
//!
//! Why a thread and not a lock around the client: a command (run, stop) and the status polls
//! must be one ordered conversation on one session, or two front ends' frames would interleave
//! and answers could reach the wrong asker. The thread takes one command at a time, answers it
//! on its own reply channel, and reads the status every [`POLL_PERIOD`]. Front ends are async
//! (tokio) and sync alike: replies come on a `tokio::sync::oneshot`, the status and the plan
//! list on `tokio::sync::watch`es, both usable from either.
//!
//! What keeps the cell responsive under any front-end load:
//! - stop and clear-fault go into their own lane, taken before anything else: they wait at
//!   most for the one link request in flight (a few ms), never behind runs;
//! - a status poll that is due is made before the next run: the heartbeat keeps its rate;
//! - runs wait in a bounded queue ([`MAX_QUEUED_RUNS`]; beyond it they are refused at once),
//!   and a run whose asker has gone (an HTTP client that hung up) is dropped, not carried out;
//! - the plan list is a cache ([`Cell::plans`]) the owner reads from the controller when the
//!   link comes up, every [`PLAN_REFRESH`], and when a run names a slot it does not list: a
//!   page that lists plans in a loop costs the link nothing.
//!
//! The cell's state follows the Asycube convention a PLC expects:
//! - `error`: the link is down (the reason is kept), the controller latched a fault, or the
//!   controller restarted while a run of this cell's was under way (the run was lost: a stop or
//!   clear-fault acknowledges it);
//! - `busy`: a run this cell asked for is accepted but not yet reported, or the drive is on;
//! - `done`: the controller reported the run this cell started, and then reported it idle
//!   (ended by itself; a stop is a newer command, so a stopped run reads `idle`);
//! - `idle`: otherwise (nothing run yet, stopped, or someone else's command since).
//!
//! The device's word wins: a controller that restarted (its sample clock or run number went
//! back) has forgotten every run, so the cell forgets them too and never reads a stale `busy`.
//! A link that fails (closed, I/O error, no answer) is dropped and reopened every
//! [`RECONNECT_PERIOD`]; until then the state is `error`, whatever the controller did last.

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use chladni_shared::icd::link::{DriveState, RunNumber, StatusReport};
use chladni_shared::icd::store::{PLAN_SLOTS, PlanRef, PlanSummary};
use serde::Serialize;
use tokio::sync::{oneshot, watch};

use chladni_device::client::{DeviceClient, DeviceError};
use chladni_device::json::StatusJson;

/// How often the owner reads the controller's status when no command is waiting.
pub const POLL_PERIOD: Duration = Duration::from_millis(100);
/// How often a lost link is tried again.
pub const RECONNECT_PERIOD: Duration = Duration::from_secs(1);
/// How often the plan list is read again while the link is up (another program may upload).
pub const PLAN_REFRESH: Duration = Duration::from_secs(10);
/// Runs that may wait for the owner at once; one more is refused ([`CellError::QueueFull`]).
pub const MAX_QUEUED_RUNS: usize = 8;
/// How long an accepted run may stay missing from the controller's report before the cell
/// takes it as lost (it shows within one control block, a few ms).
pub(crate) const RUN_REPORT_LIMIT: Duration = Duration::from_secs(2);

/// Why a cell command was not carried out.
#[derive(Debug, thiserror::Error)]
pub enum CellError {
    /// The controller link is down; nothing was sent.
    #[error(
        "the controller link is down ({reason}): check that the controller runs and that this \
         is its port; the cell tries again every second"
    )]
    LinkDown {
        /// Why the link was lost, or why it did not open.
        reason: String,
    },
    /// The slot number is outside the controller's store.
    #[error("slot {slot} does not exist: slots are 0..{}", PLAN_SLOTS - 1)]
    BadSlot {
        /// The slot asked for.
        slot: u32,
    },
    /// No plan is stored in the slot.
    #[error(
        "slot {slot} holds no plan (stored: {stored}); upload one with `chladni device upload`"
    )]
    NoPlan {
        /// The slot asked for.
        slot: u8,
        /// The slots that hold plans, for the message.
        stored: String,
    },
    /// The controller refused or could not take the command.
    #[error(transparent)]
    Device(#[from] DeviceError),
    /// Too many runs wait for the controller already.
    #[error(
        "{MAX_QUEUED_RUNS} run requests are waiting for the controller already: try again \
         when one is answered"
    )]
    QueueFull,
    /// The owner thread has ended (the process is shutting down).
    #[error("the cell's link owner has stopped")]
    Stopped,
}

/// The cell's state, as a PLC reads it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CellState {
    /// Nothing of this cell's is running; no fault.
    Idle,
    /// A run of this cell's is accepted or the drive is on.
    Busy,
    /// The run this cell started last has ended by itself.
    Done,
    /// The link is down or the controller latched a fault.
    Error,
}

impl CellState {
    /// The value of the Modbus state register and the order of the dashboard's legend.
    pub const fn code(self) -> u16 {
        match self {
            CellState::Idle => 0,
            CellState::Busy => 1,
            CellState::Done => 2,
            CellState::Error => 3,
        }
    }
}

/// What every front end shows: the cell's state and the controller's last status.
#[derive(Debug, Clone, Serialize)]
pub struct CellStatus {
    /// Idle, busy, done or error.
    pub state: CellState,
    /// Whether the owner holds a working session with the controller.
    pub link_up: bool,
    /// Why the state is `error` (the link's loss or the latched fault), for people.
    pub error: Option<String>,
    /// Status reads from the controller so far (wraps at 2³²): a PLC sees the cell alive.
    pub heartbeat: u32,
    /// The slot of the plan being run (or run last), when it is a stored plan.
    pub slot: Option<u8>,
    /// The run number of the command this cell started last.
    pub last_run: Option<u32>,
    /// The controller's status as `chladni device status --json` prints it (null before the
    /// first read).
    pub device: Option<StatusJson>,
    /// The raw status, for front ends that encode their own units (Modbus registers).
    #[serde(skip)]
    pub report: Option<StatusReport>,
}

impl CellStatus {
    fn starting() -> Self {
        CellStatus {
            state: CellState::Error,
            link_up: false,
            error: Some("connecting to the controller".into()),
            heartbeat: 0,
            slot: None,
            last_run: None,
            device: None,
            report: None,
        }
    }
}

/// A run the controller accepted.
#[derive(Debug, Clone, Serialize)]
pub struct RunStarted {
    /// The controller's run number for it.
    pub run: u32,
    /// The slot.
    pub slot: u8,
    /// The plan's name.
    pub plan: String,
}

/// What a front end asks the owner to do.
enum Command {
    Run { slot: u8, repeat: Option<u16> },
    Stop,
    ClearFault,
}

/// The owner's answer to a [`Command`].
enum Answer {
    Run(RunStarted),
    Accepted(RunNumber),
}

struct Job {
    command: Command,
    reply: oneshot::Sender<Result<Answer, CellError>>,
}

/// The commands waiting for the owner: stop and clear-fault in their own lane, taken first.
#[derive(Default)]
struct Queue {
    urgent: VecDeque<Job>,
    runs: VecDeque<Job>,
    /// Every [`Cell`] handle is gone: the owner ends.
    closed: bool,
}

/// The queue and the owner's wake-up, shared by the handles and the owner thread.
#[derive(Default)]
struct Shared {
    queue: Mutex<Queue>,
    ready: Condvar,
    /// The owner thread has ended and its session is closed (released).
    ended: Mutex<bool>,
    ended_signal: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        self.queue.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn mark_ended(&self) {
        *self.ended.lock().unwrap_or_else(PoisonError::into_inner) = true;
        self.ended_signal.notify_all();
    }
}

/// Waits for the owner thread to end, after the last [`Cell`] handle is gone.
///
/// Why a process waits for it: the owner's session may own the controller, and dropping it
/// sends `Release`. A process that exits first leaves the controller held for the owner's lease
/// (3 s), and the next program to run the shaker is refused as busy.
pub struct OwnerEnd(Arc<Shared>);

impl OwnerEnd {
    /// Waits up to `limit` for the owner to close its session; whether it did.
    pub fn wait(self, limit: Duration) -> bool {
        let ended = self.0.ended.lock().unwrap_or_else(PoisonError::into_inner);
        let (ended, _) = self
            .0
            .ended_signal
            .wait_timeout_while(ended, limit, |ended| !*ended)
            .unwrap_or_else(PoisonError::into_inner);
        *ended
    }
}

/// Held by every handle; the last one dropped tells the owner to end.
struct Alive(Arc<Shared>);

impl Drop for Alive {
    fn drop(&mut self) {
        self.0.lock().closed = true;
        self.0.ready.notify_all();
    }
}

/// The stored plans as the owner last read them from the controller.
#[derive(Debug, Clone, Default)]
pub(crate) struct PlanCache {
    /// The plans, by slot.
    pub plans: Vec<PlanSummary>,
    /// The controller's free plan flash, bytes.
    pub free_bytes: u32,
    /// Whether the list was ever read (false: not since the cell started).
    pub read: bool,
}

/// A handle on the link owner; clones share it. The owner thread ends when the last handle is
/// dropped.
#[derive(Clone)]
pub struct Cell {
    shared: Arc<Shared>,
    _alive: Arc<Alive>,
    status: watch::Receiver<CellStatus>,
    plans: watch::Receiver<PlanCache>,
}

impl Cell {
    /// Starts the owner of the controller at `port` (`tcp://HOST:PORT` or a serial device),
    /// naming its session `client_name`. It never fails: a link that does not open shows as
    /// the `error` state and is tried again every [`RECONNECT_PERIOD`].
    pub fn start(port: &str, client_name: &str) -> Cell {
        let shared = Arc::new(Shared::default());
        let (publish, status) = watch::channel(CellStatus::starting());
        let (publish_plans, plans) = watch::channel(PlanCache::default());
        let mut owner = Owner::new(port.to_owned(), client_name.to_owned(), publish);
        owner.publish_plans = Some(publish_plans);
        let queue = Arc::clone(&shared);
        std::thread::Builder::new()
            .name("cell-link-owner".into())
            .spawn(move || {
                owner.serve(&queue);
                // The session is released (dropped) before anyone is told the owner ended.
                drop(owner);
                queue.mark_ended();
            })
            .expect("spawning a thread only fails when the OS is out of resources");
        Cell { _alive: Arc::new(Alive(Arc::clone(&shared))), shared, status, plans }
    }

    /// A handle to wait for the owner thread's end (it does not keep the owner alive).
    pub fn owner_end(&self) -> OwnerEnd {
        OwnerEnd(Arc::clone(&self.shared))
    }

    /// The latest status.
    pub fn status(&self) -> CellStatus {
        self.status.borrow().clone()
    }

    /// A receiver that wakes on every new status (telemetry streams).
    pub fn watch(&self) -> watch::Receiver<CellStatus> {
        self.status.clone()
    }

    /// Runs the plan stored in `slot`, `repeat` times (`None` or 0: as stored, the one meaning
    /// of 0 for every front end). `slot` is a `u32` so that front ends pass what they received
    /// and get [`CellError::BadSlot`] naming it.
    pub async fn run(&self, slot: u32, repeat: Option<u16>) -> Result<RunStarted, CellError> {
        let slot = u8::try_from(slot)
            .ok()
            .filter(|s| *s < PLAN_SLOTS)
            .ok_or(CellError::BadSlot { slot })?;
        let repeat = repeat.filter(|n| *n != 0);
        match self.ask(Command::Run { slot, repeat }, false).await? {
            Answer::Run(started) => Ok(started),
            Answer::Accepted(_) => unreachable!("the owner answers Run with Run"),
        }
    }

    /// Stops the drive (ramped); the controller's run number of the stop. Never waits behind
    /// runs.
    pub async fn stop(&self) -> Result<u32, CellError> {
        self.ask_urgent(Command::Stop).await
    }

    /// Clears a latched fault; the controller's run number of the clear. Never waits behind
    /// runs.
    pub async fn clear_fault(&self) -> Result<u32, CellError> {
        self.ask_urgent(Command::ClearFault).await
    }

    /// The stored plans and the free flash, bytes, from the owner's cache (no link request).
    /// Before the list was ever read it is the link's error.
    pub fn plans(&self) -> Result<(Vec<PlanSummary>, u32), CellError> {
        let cache = self.plans.borrow();
        if !cache.read {
            let status = self.status.borrow();
            let reason = status.error.clone().unwrap_or_else(|| "not read yet".into());
            return Err(CellError::LinkDown { reason });
        }
        Ok((cache.plans.clone(), cache.free_bytes))
    }

    async fn ask_urgent(&self, command: Command) -> Result<u32, CellError> {
        match self.ask(command, true).await? {
            Answer::Accepted(run) => Ok(run.0),
            Answer::Run(_) => unreachable!("the owner answers Stop and ClearFault with a run"),
        }
    }

    async fn ask(&self, command: Command, urgent: bool) -> Result<Answer, CellError> {
        let (reply, answer) = oneshot::channel();
        {
            let mut queue = self.shared.lock();
            let job = Job { command, reply };
            if urgent {
                queue.urgent.push_back(job);
            } else if queue.runs.len() >= MAX_QUEUED_RUNS {
                return Err(CellError::QueueFull);
            } else {
                queue.runs.push_back(job);
            }
        }
        self.shared.ready.notify_one();
        answer.await.map_err(|_| CellError::Stopped)?
    }
}

/// What the owner does next.
enum Next {
    Job(Job),
    Poll,
    End,
}

/// The owner thread's state.
struct Owner {
    port: String,
    name: String,
    client: Option<DeviceClient>,
    /// Why the link is down (kept for the status until it is up again).
    down_reason: String,
    next_connect: Instant,
    publish: watch::Sender<CellStatus>,
    publish_plans: Option<watch::Sender<PlanCache>>,
    heartbeat: u32,
    last_run: Option<RunNumber>,
    /// When the last run was accepted (a report may lag it by one control block).
    run_accepted: Option<Instant>,
    /// A run of this cell's lost by a controller restart, until a stop or clear-fault.
    lost_run: Option<String>,
    slot: Option<u8>,
    plans: Vec<PlanSummary>,
    next_plan_read: Instant,
    last_report: Option<StatusReport>,
    /// Runs dropped because their asker had gone, since the last log line about them.
    dropped: u32,
}

impl Owner {
    fn new(port: String, name: String, publish: watch::Sender<CellStatus>) -> Self {
        Owner {
            port,
            name,
            client: None,
            down_reason: "not connected yet".into(),
            next_connect: Instant::now(),
            publish,
            publish_plans: None,
            heartbeat: 0,
            last_run: None,
            run_accepted: None,
            lost_run: None,
            slot: None,
            plans: Vec::new(),
            next_plan_read: Instant::now(),
            last_report: None,
            dropped: 0,
        }
    }

    /// Takes commands and polls the status until every [`Cell`] handle is gone.
    fn serve(&mut self, shared: &Shared) {
        let mut next_poll = Instant::now();
        loop {
            let job = match Self::next(shared, next_poll) {
                Next::End => return,
                Next::Poll => {
                    // Timed from the poll's start: the link's round trip does not slow the rate.
                    let began = Instant::now();
                    self.poll();
                    next_poll = began + POLL_PERIOD;
                    continue;
                }
                Next::Job(job) => job,
            };
            if job.reply.is_closed() {
                // The asker hung up: nobody would learn the run started.
                self.dropped += 1;
                crate::ratelog::global().log(
                    "owner",
                    "dropped",
                    &format!("cell: {} run request(s) dropped: their asker had gone", self.dropped),
                );
                continue;
            }
            let answer = self.execute(job.command);
            // Published before the answer: a front end that reads the state right after its
            // run was accepted sees `busy`, never the last run's `done`.
            self.publish.send_replace(self.snapshot());
            let _ = job.reply.send(answer);
            // A command changes the state: read it soon (the next poll is not delayed).
            next_poll = next_poll.min(Instant::now() + POLL_PERIOD / 4);
        }
    }

    /// The next thing to do: an urgent command, else a due poll, else a run, else wait.
    fn next(shared: &Shared, next_poll: Instant) -> Next {
        let mut queue = shared.lock();
        loop {
            if let Some(job) = queue.urgent.pop_front() {
                return Next::Job(job);
            }
            let now = Instant::now();
            if now >= next_poll {
                return Next::Poll;
            }
            if let Some(job) = queue.runs.pop_front() {
                return Next::Job(job);
            }
            if queue.closed {
                return Next::End;
            }
            let wait = next_poll - now;
            queue =
                shared.ready.wait_timeout(queue, wait).unwrap_or_else(PoisonError::into_inner).0;
        }
    }

    /// The session, opening it if it is down and its retry time has come.
    fn client(&mut self) -> Result<&mut DeviceClient, CellError> {
        if self.client.is_none() && Instant::now() >= self.next_connect {
            match DeviceClient::open(&self.port, &self.name) {
                Ok(client) => {
                    self.client = Some(client);
                    // Another program may have changed the store while the link was down.
                    self.next_plan_read = Instant::now();
                }
                Err(e) => {
                    self.down_reason = e.to_string();
                    self.next_connect = Instant::now() + RECONNECT_PERIOD;
                }
            }
        }
        self.client.as_mut().ok_or_else(|| CellError::LinkDown { reason: self.down_reason.clone() })
    }

    /// Drops the session after an error that means the link itself failed.
    fn check<T>(&mut self, result: Result<T, DeviceError>) -> Result<T, CellError> {
        if let Err(e) = &result
            && matches!(e, DeviceError::Closed | DeviceError::Io(_) | DeviceError::Timeout { .. })
        {
            self.client = None;
            self.down_reason = e.to_string();
            self.next_connect = Instant::now() + RECONNECT_PERIOD;
        }
        result.map_err(CellError::from)
    }

    fn execute(&mut self, command: Command) -> Result<Answer, CellError> {
        match command {
            Command::Run { slot, repeat } => self.run(slot, repeat).map(Answer::Run),
            Command::Stop | Command::ClearFault => {
                let client = self.client()?;
                let result = match command {
                    Command::Stop => client.stop(),
                    _ => client.clear_fault(),
                };
                let run = self.check(result)?;
                // A newer command than any run of ours: whatever was lost is acknowledged.
                self.last_run = None;
                self.run_accepted = None;
                self.lost_run = None;
                Ok(Answer::Accepted(run))
            }
        }
    }

    /// Reads the plan list into the cache.
    fn read_plans(&mut self) -> Result<(), CellError> {
        let listed = self.client()?.list_plans();
        let (plans, free_bytes) = self.check(listed)?;
        self.plans.clone_from(&plans);
        self.next_plan_read = Instant::now() + PLAN_REFRESH;
        if let Some(publish) = &self.publish_plans {
            publish.send_replace(PlanCache { plans, free_bytes, read: true });
        }
        Ok(())
    }

    fn run(&mut self, slot: u8, repeat: Option<u16>) -> Result<RunStarted, CellError> {
        if !self.plans.iter().any(|p| p.slot == slot) {
            // Maybe uploaded since the cache was read: one list read before refusing.
            self.read_plans()?;
        }
        let Some(plan) = self.plans.iter().find(|p| p.slot == slot).cloned() else {
            let stored: Vec<String> = self.plans.iter().map(|p| p.slot.to_string()).collect();
            let stored = if stored.is_empty() { "none".into() } else { stored.join(", ") };
            return Err(CellError::NoPlan { slot, stored });
        };
        let result = self.client()?.run(PlanRef::Slot(slot), repeat);
        if matches!(result, Err(DeviceError::Refused(_))) {
            // The store may have changed under the cache (deleted, replaced).
            self.next_plan_read = Instant::now();
        }
        let run = self.check(result)?;
        self.last_run = Some(run);
        self.run_accepted = Some(Instant::now());
        self.lost_run = None;
        self.slot = Some(slot);
        Ok(RunStarted { run: run.0, slot, plan: plan.name.to_string() })
    }

    fn poll(&mut self) {
        let report = match self.client() {
            Ok(client) => {
                let result = client.status();
                self.check(result).ok()
            }
            Err(_) => None,
        };
        if let Some(report) = report {
            self.heartbeat = self.heartbeat.wrapping_add(1);
            self.follow_restart(&report);
            self.forget_a_run_the_device_never_reported(&report);
            self.last_report = Some(report);
        }
        // Before the status is published: a front end that sees the link up finds the list.
        if self.client.is_some() && Instant::now() >= self.next_plan_read {
            // A failed read shows in the link state; the cache keeps its last list.
            let _ = self.read_plans();
            self.next_plan_read = self.next_plan_read.max(Instant::now() + RECONNECT_PERIOD);
        }
        self.publish.send_replace(self.snapshot());
    }

    /// A controller whose clock or run number went back has restarted and forgotten every
    /// run: the cell forgets them too (a run of ours that was under way is reported lost).
    fn follow_restart(&mut self, report: &StatusReport) {
        let Some(previous) = &self.last_report else { return };
        if report.clock >= previous.clock && report.run >= previous.run {
            return;
        }
        let cause = report.reset_cause.name();
        if let Some(run) = self.last_run.take() {
            let was_done = previous.run == run && matches!(previous.state, DriveState::Idle);
            if !was_done {
                self.lost_run = Some(format!(
                    "the controller restarted (reset cause {cause}) during run {}: the run did \
                     not finish; stop or clear fault to acknowledge",
                    run.0
                ));
            }
        }
        self.run_accepted = None;
        self.next_plan_read = Instant::now();
        crate::ratelog::global().log(
            "owner",
            "restart",
            &format!("cell: the controller restarted (reset cause {cause}); the cell follows it"),
        );
    }

    /// An accepted run shows in the controller's report within a control block; one still
    /// missing long after was never started there (a lost session, a reset): not busy for good.
    fn forget_a_run_the_device_never_reported(&mut self, report: &StatusReport) {
        let (Some(run), Some(accepted)) = (self.last_run, self.run_accepted) else { return };
        if report.run >= run {
            self.run_accepted = None;
        } else if accepted.elapsed() > RUN_REPORT_LIMIT {
            self.last_run = None;
            self.run_accepted = None;
            self.lost_run = Some(format!(
                "the controller never reported run {} (it reports run {}): it was lost; stop or \
                 clear fault to acknowledge",
                run.0, report.run.0
            ));
        }
    }

    /// The status front ends see, from the last report and what this cell asked for.
    fn snapshot(&self) -> CellStatus {
        let report = self.last_report.as_ref();
        let link_up = self.client.is_some();
        let (mut state, mut error) = cell_state(link_up, &self.down_reason, report, self.last_run);
        if let (Some(lost), CellState::Idle | CellState::Done) = (&self.lost_run, state) {
            (state, error) = (CellState::Error, Some(lost.clone()));
        }
        // The slot of the plan running now if it is stored, else the one this cell ran last.
        let running = report
            .and_then(|r| r.plan.as_ref())
            .and_then(|name| self.plans.iter().find(|p| &p.name == name))
            .map(|p| p.slot);
        CellStatus {
            state,
            link_up,
            error,
            heartbeat: self.heartbeat,
            slot: running.or(self.slot),
            last_run: self.last_run.map(|r| r.0),
            device: report.map(StatusJson::from),
            report: report.cloned(),
        }
    }
}

/// The cell's state and, for `error`, why (see the module doc for the rules).
pub(crate) fn cell_state(
    link_up: bool,
    down_reason: &str,
    report: Option<&StatusReport>,
    last_run: Option<RunNumber>,
) -> (CellState, Option<String>) {
    let Some(report) = report.filter(|_| link_up) else {
        return (CellState::Error, Some(format!("controller link down: {down_reason}")));
    };
    if let Some(fault) = report.fault {
        let text = format!(
            "fault {} ({} {}); clear it to run again",
            fault.cause.name(),
            fault.value,
            fault.cause.unit()
        );
        return (CellState::Error, Some(text));
    }
    let driving = !matches!(report.state, DriveState::Idle | DriveState::Faulted);
    let state = match last_run {
        // Accepted, but the controller still reports an older command: not started yet.
        Some(run) if report.run < run => CellState::Busy,
        _ if driving => CellState::Busy,
        Some(run) if report.run == run => CellState::Done,
        _ => CellState::Idle,
    };
    (state, None)
}

#[cfg(test)]
mod tests {
    use chladni_shared::icd::sense::{Fault, FaultCause};

    use super::*;

    fn report(run: u32, state: DriveState) -> StatusReport {
        StatusReport { run: RunNumber(run), state, ..StatusReport::IDLE }
    }

    #[test]
    fn a_lost_link_is_an_error_whatever_the_last_report_said() {
        let busy = report(3, DriveState::Running);
        let (state, why) = cell_state(false, "controller closed the link", Some(&busy), None);
        assert_eq!(state, CellState::Error);
        assert!(why.unwrap().contains("closed the link"));
    }

    #[test]
    fn done_only_after_the_controller_reported_the_run_and_then_idle() {
        let run = Some(RunNumber(5));
        // Accepted, the controller still shows the previous command (idle): busy, not done.
        assert_eq!(
            cell_state(true, "", Some(&report(4, DriveState::Idle)), run).0,
            CellState::Busy
        );
        assert_eq!(
            cell_state(true, "", Some(&report(5, DriveState::Running)), run).0,
            CellState::Busy
        );
        assert_eq!(
            cell_state(true, "", Some(&report(5, DriveState::Idle)), run).0,
            CellState::Done
        );
        // Someone else's command since: no longer this cell's run.
        assert_eq!(
            cell_state(true, "", Some(&report(6, DriveState::Idle)), run).0,
            CellState::Idle
        );
        assert_eq!(
            cell_state(true, "", Some(&report(0, DriveState::Idle)), None).0,
            CellState::Idle
        );
    }

    #[test]
    fn a_latched_fault_is_an_error_naming_its_cause() {
        let mut r = report(5, DriveState::Faulted);
        r.fault = Some(Fault { cause: FaultCause::LoopOpen, value: 12, at_sample: 9 });
        let (state, why) = cell_state(true, "", Some(&r), Some(RunNumber(5)));
        assert_eq!(state, CellState::Error);
        assert!(why.unwrap().contains("loop_open (12 mm/s²)"));
    }
}
