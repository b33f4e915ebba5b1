//! The link owner: one thread holds the controller session; everything else sends it commands
//! and reads the status it publishes.
//!
//! Why a thread and not a lock around the client: a command (run, stop) and the status polls
//! must be one ordered conversation on one session, or two front ends' frames would interleave
//! and answers could reach the wrong asker. The thread takes one command at a time from a
//! queue, answers it on its own reply channel, and between commands reads the status every
//! [`POLL_PERIOD`]. Front ends are async (tokio) and sync alike: replies come on a
//! `tokio::sync::oneshot`, the status on a `tokio::sync::watch`, both usable from either.
//!
//! The cell's state follows the Asycube convention a PLC expects:
//! - `error`: the link is down (the reason is kept), or the controller latched a fault;
//! - `busy`: a run this cell asked for is accepted but not yet reported, or the drive is on;
//! - `done`: the controller reported the run this cell started, and then reported it idle
//!   (ended by itself; a stop is a newer command, so a stopped run reads `idle`);
//! - `idle`: otherwise (nothing run yet, stopped, or someone else's command since).
//!
//! A link that fails (closed, I/O error, no answer) is dropped and reopened every
//! [`RECONNECT_PERIOD`]; until then the state is `error`, whatever the controller did last.

use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::{Duration, Instant};

use chladni_shared::icd::link::{DriveState, RunNumber, StatusReport};
use chladni_shared::icd::store::{PLAN_SLOTS, PlanRef, PlanSummary};
use serde::Serialize;
use tokio::sync::{oneshot, watch};

use crate::controller::client::{DeviceClient, DeviceError};
use crate::controller::json::StatusJson;

/// How often the owner reads the controller's status when no command is waiting.
pub const POLL_PERIOD: Duration = Duration::from_millis(100);
/// How often a lost link is tried again.
pub const RECONNECT_PERIOD: Duration = Duration::from_secs(1);

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
    Plans,
}

/// The owner's answer to a [`Command`].
enum Answer {
    Run(RunStarted),
    Accepted(RunNumber),
    Plans(Vec<PlanSummary>, u32),
}

struct Job {
    command: Command,
    reply: oneshot::Sender<Result<Answer, CellError>>,
}

/// A handle on the link owner; clones share it. The owner thread ends when the last handle is
/// dropped.
#[derive(Clone)]
pub struct Cell {
    jobs: mpsc::Sender<Job>,
    status: watch::Receiver<CellStatus>,
}

impl Cell {
    /// Starts the owner of the controller at `port` (`tcp://HOST:PORT` or a serial device),
    /// naming its session `client_name`. It never fails: a link that does not open shows as
    /// the `error` state and is tried again every [`RECONNECT_PERIOD`].
    pub fn start(port: &str, client_name: &str) -> Cell {
        let (jobs, queue) = mpsc::channel();
        let (publish, status) = watch::channel(CellStatus::starting());
        let mut owner = Owner::new(port.to_owned(), client_name.to_owned(), publish);
        std::thread::Builder::new()
            .name("cell-link-owner".into())
            .spawn(move || owner.serve(&queue))
            .expect("spawning a thread only fails when the OS is out of resources");
        Cell { jobs, status }
    }

    /// The latest status.
    pub fn status(&self) -> CellStatus {
        self.status.borrow().clone()
    }

    /// A receiver that wakes on every new status (telemetry streams).
    pub fn watch(&self) -> watch::Receiver<CellStatus> {
        self.status.clone()
    }

    /// Runs the plan stored in `slot`, `repeat` times (`None`: as stored). `slot` is a `u32`
    /// so that front ends pass what they received and get [`CellError::BadSlot`] naming it.
    pub async fn run(&self, slot: u32, repeat: Option<u16>) -> Result<RunStarted, CellError> {
        let slot = u8::try_from(slot)
            .ok()
            .filter(|s| *s < PLAN_SLOTS)
            .ok_or(CellError::BadSlot { slot })?;
        match self.ask(Command::Run { slot, repeat }).await? {
            Answer::Run(started) => Ok(started),
            _ => unreachable!("the owner answers Run with Run"),
        }
    }

    /// Stops the drive (ramped); the controller's run number of the stop.
    pub async fn stop(&self) -> Result<u32, CellError> {
        self.ask_run(Command::Stop).await
    }

    /// Clears a latched fault; the controller's run number of the clear.
    pub async fn clear_fault(&self) -> Result<u32, CellError> {
        self.ask_run(Command::ClearFault).await
    }

    /// The stored plans, read from the controller now, and its free flash, bytes.
    pub async fn plans(&self) -> Result<(Vec<PlanSummary>, u32), CellError> {
        match self.ask(Command::Plans).await? {
            Answer::Plans(plans, free) => Ok((plans, free)),
            _ => unreachable!("the owner answers Plans with Plans"),
        }
    }

    async fn ask_run(&self, command: Command) -> Result<u32, CellError> {
        match self.ask(command).await? {
            Answer::Accepted(run) => Ok(run.0),
            _ => unreachable!("the owner answers Stop and ClearFault with a run number"),
        }
    }

    async fn ask(&self, command: Command) -> Result<Answer, CellError> {
        let (reply, answer) = oneshot::channel();
        self.jobs.send(Job { command, reply }).map_err(|_| CellError::Stopped)?;
        answer.await.map_err(|_| CellError::Stopped)?
    }
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
    heartbeat: u32,
    last_run: Option<RunNumber>,
    slot: Option<u8>,
    plans: Vec<PlanSummary>,
    last_report: Option<StatusReport>,
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
            heartbeat: 0,
            last_run: None,
            slot: None,
            plans: Vec::new(),
            last_report: None,
        }
    }

    /// Takes commands and polls the status until every [`Cell`] handle is gone.
    fn serve(&mut self, queue: &mpsc::Receiver<Job>) {
        let mut next_poll = Instant::now();
        loop {
            let wait = next_poll.saturating_duration_since(Instant::now());
            match queue.recv_timeout(wait) {
                Ok(job) => {
                    let answer = self.execute(job.command);
                    // Published before the answer: a front end that reads the state right
                    // after its run was accepted sees `busy`, never the last run's `done`.
                    self.publish.send_replace(self.snapshot());
                    // The asker may have given up (a closed HTTP request): nothing to do.
                    let _ = job.reply.send(answer);
                    // A command changes the state: read it without waiting for the next poll.
                    next_poll = Instant::now();
                }
                Err(RecvTimeoutError::Timeout) => {
                    self.poll();
                    next_poll = Instant::now() + POLL_PERIOD;
                }
                Err(RecvTimeoutError::Disconnected) => return,
            }
        }
    }

    /// The session, opening it if it is down and its retry time has come.
    fn client(&mut self) -> Result<&mut DeviceClient, CellError> {
        if self.client.is_none() && Instant::now() >= self.next_connect {
            match DeviceClient::open(&self.port, &self.name) {
                Ok(client) => self.client = Some(client),
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
            Command::Stop => {
                let result = self.client()?.stop();
                self.check(result).map(Answer::Accepted)
            }
            Command::ClearFault => {
                let result = self.client()?.clear_fault();
                self.check(result).map(Answer::Accepted)
            }
            Command::Plans => {
                let result = self.client()?.list_plans();
                let (plans, free) = self.check(result)?;
                self.plans.clone_from(&plans);
                Ok(Answer::Plans(plans, free))
            }
        }
    }

    fn run(&mut self, slot: u8, repeat: Option<u16>) -> Result<RunStarted, CellError> {
        // The list is read anew: another program may have uploaded or deleted since.
        let listed = self.client()?.list_plans();
        self.plans = self.check(listed)?.0;
        let Some(plan) = self.plans.iter().find(|p| p.slot == slot).cloned() else {
            let stored: Vec<String> = self.plans.iter().map(|p| p.slot.to_string()).collect();
            let stored = if stored.is_empty() { "none".into() } else { stored.join(", ") };
            return Err(CellError::NoPlan { slot, stored });
        };
        let result = self.client()?.run(PlanRef::Slot(slot), repeat);
        let run = self.check(result)?;
        self.last_run = Some(run);
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
            self.last_report = Some(report);
        }
        self.publish.send_replace(self.snapshot());
    }

    /// The status front ends see, from the last report and what this cell asked for.
    fn snapshot(&self) -> CellStatus {
        let report = self.last_report.as_ref();
        let link_up = self.client.is_some();
        let (state, error) = cell_state(link_up, &self.down_reason, report, self.last_run);
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
pub fn cell_state(
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
