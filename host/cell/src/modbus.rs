//! The cell's Modbus TCP front end: a PLC starts and stops plans by writing holding registers
//! and follows the feeder by reading input registers (the register map is in docs/cell.md).
//!
//! Why Modbus TCP: it is what a PLC or robot controller on a cell speaks without extra
//! software, and feeders of this kind (Asycube and the like) are driven through a small
//! register map of the same shape: a few holding registers to choose and command, input
//! registers for the state, a result register that says why a command was refused.
//!
//! The map is pure data here ([`input_registers`], [`parse_write`], [`CommandResult::of`]),
//! tested without a network; [`serve`] puts it behind the framing of [`super::mbap`]. Every
//! connection shares one [`Registers`]: the holding registers (slot, repeat, last command) and
//! the last command's result are the cell's, not a connection's. Commands go through the link
//! owner ([`Cell`]), so a PLC and the dashboard never interleave frames on the link.
//!
//! A written command is carried out before the write is answered: the PLC's write succeeds
//! only when the controller accepted the command, and otherwise comes back as an exception
//! (the result register says which refusal). Reads never fail for a lost link: the state reads
//! `error` (3) and the fault register reads [`FAULT_LINK_DOWN`], never a stale `busy`.

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use chladni_shared::icd::link::{DriveError, Refusal, StatusReport};
use chladni_shared::icd::sense::{FaultCause, SensorFault};
use chladni_shared::icd::store::PLAN_SLOTS;
use chladni_shared::icd::units::whole_ms_from_samples;
use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tokio_modbus::{ExceptionCode, Request, Response};

use super::mbap::{self, MAX_WRITE};
use super::net::{self, Cidr};
use super::owner::{Cell, CellError, CellStatus};
use super::ratelog;
use super::verify::Verifier;
use chladni_device::client::DeviceError;

/// Holding register: the plan slot a run command runs (0..[`PLAN_SLOTS`]).
pub(crate) const HOLDING_SLOT: u16 = 0;
/// Holding register: how many times a run command runs the plan (0: as stored in the plan).
pub(crate) const HOLDING_REPEAT: u16 = 1;
/// Holding register: the command, carried out when written ([`Command`]); reads back the last
/// command carried out (0: none yet).
pub const HOLDING_COMMAND: u16 = 2;
/// Number of holding registers; addresses from here on are illegal.
pub(crate) const HOLDING_COUNT: u16 = 3;

/// Input register addresses (FC04).
pub mod input {
    /// The cell's state: 0 idle, 1 busy, 2 done, 3 error ([`crate::CellState::code`]).
    pub(crate) const STATE: u16 = 0;
    /// 1 when the cell holds a working session with the controller, else 0.
    pub(crate) const LINK_UP: u16 = 1;
    /// The slot of the plan running, or of the one this cell ran last; [`super::NONE`] if none.
    pub const SLOT: u16 = 2;
    /// The plan step running (0-based); [`super::NONE`] outside a plan.
    pub(crate) const STEP: u16 = 3;
    /// The repetition of the plan running (0-based).
    pub(crate) const REPETITION: u16 = 4;
    /// Time left in the plan, ms, 32 bits: high word here, low word at `REMAINING_MS + 1`.
    pub(crate) const REMAINING_MS: u16 = 5;
    /// Measured acceleration amplitude, 0.01 m/s² (0: no measurement; saturates at 65535).
    pub(crate) const ACCEL: u16 = 7;
    /// Drive frequency, 0.1 Hz.
    pub(crate) const FREQ: u16 = 8;
    /// Fault code ([`super::fault_code`], [`super::FAULT_LINK_DOWN`]); 0: none.
    pub const FAULT: u16 = 9;
    /// The last write's result ([`super::CommandResult`]): 0 ok, else why it was refused.
    pub(crate) const RESULT: u16 = 10;
    /// Status reads from the controller so far, low 16 bits: it counts while the link is up.
    pub(crate) const HEARTBEAT: u16 = 11;
    /// The controller's run number for the last command this front end had accepted, 32 bits
    /// (high word first); 0: none yet.
    pub(crate) const COMMAND_RUN: u16 = 12;
    /// The run number of the drive command in effect on the controller, 32 bits (high word
    /// first).
    pub(crate) const DEVICE_RUN: u16 = 14;
    /// Number of the registers above, from the cell's status ([`super::input_registers`]).
    pub(crate) const STATUS_COUNT: u16 = 16;
    /// The last photo check's number, low 16 bits (0: none yet; [`crate::verify`]).
    pub const VERIFY_SEQ: u16 = 16;
    /// Its result: 0 none, 1 ok, 2 off, 3 no part found, 4 photo refused
    /// ([`crate::verify::ResultCode`]).
    pub const VERIFY_RESULT: u16 = 17;
    /// Parts found in it.
    pub const VERIFY_FOUND: u16 = 18;
    /// Parts in it as the plan predicts.
    pub const VERIFY_ORIENTED: u16 = 19;
    /// Its success rate, 0.1 % (0..=1000); 0xFFFF none.
    pub const VERIFY_RATE: u16 = 20;
    /// Number of input registers; addresses from here on are illegal.
    pub const COUNT: u16 = 21;
}

/// "None" in the slot and step registers.
pub const NONE: u16 = 0xFFFF;
/// Fault code while the controller link is down (or not up yet).
pub const FAULT_LINK_DOWN: u16 = 100;
/// Most registers one read may ask for (Modbus application protocol, FC03/FC04).
const MAX_READ: u16 = 125;

/// The commands of the command register.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// 1: run the plan in the slot register, the repeat register's times.
    Run = 1,
    /// 2: stop the drive (ramped).
    Stop = 2,
    /// 3: clear a latched fault.
    ClearFault = 3,
}

impl Command {
    fn from_code(code: u16) -> Option<Self> {
        match code {
            1 => Some(Command::Run),
            2 => Some(Command::Stop),
            3 => Some(Command::ClearFault),
            _ => None,
        }
    }
}

/// The result register's values: why the last write (a command, or a bad slot or command
/// value) was refused; 0 once a write succeeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CommandResult {
    /// 0: written and carried out (or nothing written yet).
    #[default]
    Ok = 0,
    /// 1: the command register was written with a value that is no command.
    UnknownCommand = 1,
    /// 2: the slot register was written with a slot the controller does not have.
    BadSlot = 2,
    /// 3: run: the slot holds no plan.
    NoPlan = 3,
    /// 4: the controller link is down; nothing was sent.
    LinkDown = 4,
    /// 5: another program's session owns the controller.
    DeviceBusy = 5,
    /// 6: run: a fault is latched; clear it (command 3) first.
    Faulted = 6,
    /// 7: the controller refused otherwise (the plan does not fit its limits, queue full).
    Refused = 7,
    /// 8: the cell is shutting down.
    Stopped = 8,
    /// 9: run: too many commands wait for the controller already; try again.
    QueueFull = 9,
}

impl CommandResult {
    /// The register value.
    pub const fn code(self) -> u16 {
        self as u16
    }

    /// The exception a write that ended with this result answers; `None` for [`Self::Ok`].
    pub const fn exception(self) -> Option<ExceptionCode> {
        match self {
            CommandResult::Ok => None,
            CommandResult::UnknownCommand | CommandResult::BadSlot | CommandResult::NoPlan => {
                Some(ExceptionCode::IllegalDataValue)
            }
            CommandResult::LinkDown => Some(ExceptionCode::GatewayTargetDevice),
            CommandResult::DeviceBusy
            | CommandResult::Faulted
            | CommandResult::Refused
            | CommandResult::Stopped => Some(ExceptionCode::ServerDeviceFailure),
            CommandResult::QueueFull => Some(ExceptionCode::ServerDeviceBusy),
        }
    }

    /// The result a failed cell command leaves.
    pub fn of(error: &CellError) -> Self {
        match error {
            CellError::LinkDown { .. } => CommandResult::LinkDown,
            CellError::BadSlot { .. } => CommandResult::BadSlot,
            CellError::NoPlan { .. } => CommandResult::NoPlan,
            CellError::Stopped => CommandResult::Stopped,
            CellError::QueueFull => CommandResult::QueueFull,
            CellError::Device(e) => match e {
                // The owner drops the session on these: the link is what failed.
                DeviceError::Closed
                | DeviceError::Io(_)
                | DeviceError::Timeout { .. }
                | DeviceError::Open { .. } => CommandResult::LinkDown,
                DeviceError::Refused(Refusal::Busy { .. }) => CommandResult::DeviceBusy,
                DeviceError::Refused(Refusal::Drive(DriveError::Faulted)) => CommandResult::Faulted,
                _ => CommandResult::Refused,
            },
        }
    }
}

/// The fault register's code for a latched fault's cause (1..=10; docs/cell.md).
pub const fn fault_code(cause: FaultCause) -> u16 {
    match cause {
        FaultCause::LoopOpen => 1,
        FaultCause::LoopCheck => 2,
        FaultCause::OutOfBand => 3,
        FaultCause::OverAcceleration => 4,
        FaultCause::Sensor(SensorFault::Nack) => 5,
        FaultCause::Sensor(SensorFault::WrongId(_)) => 6,
        FaultCause::Sensor(SensorFault::Overrun) => 7,
        FaultCause::Sensor(SensorFault::Bus) => 8,
        FaultCause::NoData => 9,
        FaultCause::Saturation => 10,
    }
}

/// The holding registers and what the last command left, shared by every connection.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Holding {
    /// The slot register.
    pub slot: u16,
    /// The repeat register (0: as stored).
    pub repeat: u16,
    /// The last command carried out or tried (0: none yet).
    pub last_command: u16,
    /// The last command's (or write's) result.
    pub result: CommandResult,
    /// The controller's run number for the last accepted command (0: none).
    pub command_run: u32,
}

impl Holding {
    /// The holding registers' values, in address order.
    pub fn registers(&self) -> [u16; HOLDING_COUNT as usize] {
        [self.slot, self.repeat, self.last_command]
    }
}

/// The two words of a 32-bit value, high word first.
const fn words(value: u32) -> [u16; 2] {
    [(value >> 16) as u16, value as u16]
}

/// Time left in the plan, whole ms (saturating at `u32::MAX`).
fn remaining_ms(report: &StatusReport) -> u32 {
    let ms = whole_ms_from_samples(report.remaining_samples, report.sample_rate);
    u32::try_from(ms).unwrap_or(u32::MAX)
}

/// The input registers for a status and the holding state, in address order. Nothing that
/// comes from the controller is shown while the link is down: those registers read "none"/0.
pub fn input_registers(
    status: &CellStatus,
    holding: &Holding,
) -> [u16; input::STATUS_COUNT as usize] {
    use input::*;
    let live = status.report.as_ref().filter(|_| status.link_up);
    let mut r = [0u16; STATUS_COUNT as usize];
    let mut set = |address: u16, value: u16| r[usize::from(address)] = value;
    set(STATE, status.state.code());
    set(LINK_UP, u16::from(status.link_up));
    set(SLOT, live.and(status.slot).map_or(NONE, u16::from));
    set(STEP, live.and_then(|s| s.step).unwrap_or(NONE));
    set(REPETITION, live.map_or(0, |s| s.repetition));
    let [high, low] = words(live.map_or(0, remaining_ms));
    set(REMAINING_MS, high);
    set(REMAINING_MS + 1, low);
    let accel = live.and_then(|s| s.measured).map_or(0, |m| m.accel_mmps2.saturating_add(5) / 10);
    set(ACCEL, saturate(accel));
    set(FREQ, saturate(live.map_or(0, |s| s.freq_mhz.saturating_add(50) / 100)));
    let fault = match live {
        None => FAULT_LINK_DOWN,
        Some(s) => s.fault.map_or(0, |f| fault_code(f.cause)),
    };
    set(FAULT, fault);
    set(RESULT, holding.result.code());
    set(HEARTBEAT, status.heartbeat as u16);
    let [high, low] = words(holding.command_run);
    set(COMMAND_RUN, high);
    set(COMMAND_RUN + 1, low);
    let [high, low] = words(live.map_or(0, |s| s.run.0));
    set(DEVICE_RUN, high);
    set(DEVICE_RUN + 1, low);
    r
}

fn saturate(value: u32) -> u16 {
    u16::try_from(value).unwrap_or(u16::MAX)
}

/// The registers `[address, address + quantity)` of a table of `len`, checked the Modbus way:
/// a quantity outside `1..=max` is a bad value, a range past the table a bad address.
pub(crate) fn read_range<T: Copy>(
    table: &[T],
    address: u16,
    quantity: u16,
    max: u16,
) -> Result<Vec<T>, ExceptionCode> {
    if quantity == 0 || quantity > max {
        return Err(ExceptionCode::IllegalDataValue);
    }
    let start = usize::from(address);
    let end = start + usize::from(quantity);
    table.get(start..end).map(<[T]>::to_vec).ok_or(ExceptionCode::IllegalDataAddress)
}

/// A checked write to the holding registers: what to set, then what to carry out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Write {
    /// A new slot register value.
    pub slot: Option<u16>,
    /// A new repeat register value.
    pub repeat: Option<u16>,
    /// A command to carry out after the registers are set.
    pub command: Option<Command>,
}

/// Why a write was refused: the exception to answer and, for a bad value, the result register's
/// new value (a bad address leaves it as it is).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rejected {
    /// The Modbus exception.
    pub exception: ExceptionCode,
    /// The result register's new value, if the write names a reason for it.
    pub result: Option<CommandResult>,
}

impl Rejected {
    const fn address() -> Self {
        Rejected { exception: ExceptionCode::IllegalDataAddress, result: None }
    }

    const fn value(result: CommandResult) -> Self {
        Rejected { exception: ExceptionCode::IllegalDataValue, result: Some(result) }
    }
}

/// Checks a write of `values` from `address` (FC06: one value; FC16: several, set in address
/// order). Nothing is set unless every value is good.
pub fn parse_write(address: u16, values: &[u16]) -> Result<Write, Rejected> {
    if values.is_empty() || values.len() > usize::from(MAX_WRITE) {
        return Err(Rejected { exception: ExceptionCode::IllegalDataValue, result: None });
    }
    if usize::from(address) + values.len() > usize::from(HOLDING_COUNT) {
        return Err(Rejected::address());
    }
    let mut write = Write::default();
    for (value, register) in values.iter().zip(address..) {
        match register {
            HOLDING_SLOT if *value >= u16::from(PLAN_SLOTS) => {
                return Err(Rejected::value(CommandResult::BadSlot));
            }
            HOLDING_SLOT => write.slot = Some(*value),
            HOLDING_REPEAT => write.repeat = Some(*value),
            _ => match Command::from_code(*value) {
                Some(command) => write.command = Some(command),
                None => return Err(Rejected::value(CommandResult::UnknownCommand)),
            },
        }
    }
    Ok(write)
}

/// The register state every connection shares, and the cell it commands.
#[derive(Clone)]
pub struct Registers {
    cell: Cell,
    holding: Arc<Mutex<Holding>>,
    verifier: Verifier,
}

impl mbap::RegisterMap for Registers {
    async fn handle(&self, request: Request<'_>) -> Result<Response, ExceptionCode> {
        Registers::handle(self, request).await
    }

    fn last_result(&self) -> String {
        format!("{:?}", self.holding().result)
    }
}

impl Registers {
    /// Registers in their start state (slot 0, repeat 0, no command yet) for `cell`.
    pub fn new(cell: Cell) -> Self {
        let holding = Arc::new(Mutex::new(Holding::default()));
        Registers { cell, holding, verifier: Verifier::new(None) }
    }

    /// The same, the verification registers reading `verifier`'s last photo check.
    pub fn with_verifier(self, verifier: Verifier) -> Self {
        Registers { verifier, ..self }
    }

    /// The whole input map: the status registers, then the last photo check's.
    pub(crate) fn input_table(&self) -> Vec<u16> {
        let mut table = input_registers(&self.cell.status(), &self.holding()).to_vec();
        table.extend(self.verifier.registers());
        table
    }

    /// The holding state now.
    pub fn holding(&self) -> Holding {
        *self.holding.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn update<T>(&self, change: impl FnOnce(&mut Holding) -> T) -> T {
        change(&mut self.holding.lock().unwrap_or_else(PoisonError::into_inner))
    }

    /// Answers one request.
    pub async fn handle(&self, request: Request<'_>) -> Result<Response, ExceptionCode> {
        match request {
            Request::ReadInputRegisters(address, quantity) => {
                let table = self.input_table();
                read_range(&table, address, quantity, MAX_READ).map(Response::ReadInputRegisters)
            }
            Request::ReadHoldingRegisters(address, quantity) => {
                let table = self.holding().registers();
                read_range(&table, address, quantity, MAX_READ).map(Response::ReadHoldingRegisters)
            }
            Request::WriteSingleRegister(address, value) => {
                self.write(address, &[value]).await?;
                Ok(Response::WriteSingleRegister(address, value))
            }
            Request::WriteMultipleRegisters(address, values) => {
                self.write(address, &values).await?;
                Ok(Response::WriteMultipleRegisters(address, values.len() as u16))
            }
            _ => Err(ExceptionCode::IllegalFunction),
        }
    }

    /// Sets the registers a write names, then carries out its command, if any.
    async fn write(&self, address: u16, values: &[u16]) -> Result<(), ExceptionCode> {
        let write = parse_write(address, values).map_err(|rejected| {
            if let Some(result) = rejected.result {
                self.update(|h| h.result = result);
            }
            rejected.exception
        })?;
        let (slot, repeat) = self.update(|h| {
            h.slot = write.slot.unwrap_or(h.slot);
            h.repeat = write.repeat.unwrap_or(h.repeat);
            // The result is the last write's: a good one clears an old refusal's reason.
            h.result = CommandResult::Ok;
            (h.slot, h.repeat)
        });
        let Some(command) = write.command else { return Ok(()) };
        let outcome = match command {
            Command::Run => {
                let repeat = (repeat != 0).then_some(repeat);
                self.cell.run(u32::from(slot), repeat).await.map(|started| started.run)
            }
            Command::Stop => self.cell.stop().await,
            Command::ClearFault => self.cell.clear_fault().await,
        };
        let result = outcome.as_ref().err().map_or(CommandResult::Ok, CommandResult::of);
        self.update(|h| {
            h.last_command = command as u16;
            h.result = result;
            if let Ok(run) = outcome {
                h.command_run = run;
            }
        });
        match result.exception() {
            None => Ok(()),
            Some(exception) => Err(exception),
        }
    }
}

/// How the Modbus front end is served.
#[derive(Debug, Clone)]
pub struct Options {
    /// The clients allowed to connect (by address).
    pub allow: Vec<Cidr>,
    /// How many clients may be connected at once (a PLC is one).
    pub clients: usize,
    /// A connection silent this long is closed.
    pub idle: Duration,
}

impl Options {
    /// Loopback clients only, one at a time, [`IDLE_TIMEOUT`].
    pub fn local() -> Self {
        Options { allow: Cidr::loopback(), clients: 1, idle: IDLE_TIMEOUT }
    }
}

/// A connection that sends no request for this long is closed (a PLC polls far more often).
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(30);

/// Serves the register map on `listener`; it never returns on its own (accept errors are
/// logged and retried). A client outside the allow-list, or beyond the client limit, is
/// closed at once.
pub async fn serve(
    listener: TcpListener,
    registers: Registers,
    options: Options,
) -> std::io::Result<()> {
    let clients = Arc::new(Semaphore::new(options.clients.max(1)));
    loop {
        let (stream, peer) = net::accept(&listener, "modbus").await;
        let client = peer.ip().to_string();
        if !options.allow.iter().any(|net| net.contains(peer.ip())) {
            let allowed: Vec<String> = options.allow.iter().map(ToString::to_string).collect();
            let text = format!(
                "modbus {peer}: refused, not in the allow-list ({}): add it with --modbus-allow",
                allowed.join(" ")
            );
            ratelog::global().log(&client, "modbus-allow", &text);
            continue;
        }
        let Ok(permit) = Arc::clone(&clients).try_acquire_owned() else {
            let text = format!(
                "modbus {peer}: refused, {} client(s) connected already (--modbus-clients)",
                options.clients
            );
            ratelog::global().log(&client, "modbus-clients", &text);
            continue;
        };
        let registers = registers.clone();
        let idle = options.idle;
        tokio::spawn(async move {
            mbap::connection(stream, peer, registers, idle).await;
            drop(permit);
        });
    }
}

#[cfg(test)]
mod tests;
