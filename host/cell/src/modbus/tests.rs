//! The register map without a network: encoding, request checks, the state mapping, and the
//! service's answers against a cell whose controller is not there.

use std::borrow::Cow;
use std::time::{Duration, Instant};

use chladni_shared::icd::link::{DriveState, Level, RunNumber, StatusReport};
use chladni_shared::icd::sense::{Fault, FaultCause, Measurement, SensorFault};

use super::*;
use crate::owner::{CellState, cell_state};

/// A status as the owner publishes it, from a link state, a report and the cell's last run.
fn status(link_up: bool, report: Option<StatusReport>, last_run: Option<u32>) -> CellStatus {
    let (state, error) =
        cell_state(link_up, "controller closed the link", report.as_ref(), last_run.map(RunNumber));
    CellStatus {
        state,
        link_up,
        error,
        heartbeat: 0x1_0007,
        slot: Some(4),
        last_run,
        device: None,
        report,
    }
}

/// Plan "p" in its second step of the third repetition, 1234.5 ms left, 9.87 m/s² at 150 Hz.
fn running(run: u32) -> StatusReport {
    StatusReport {
        state: DriveState::Running,
        step: Some(1),
        repetition: 2,
        run: RunNumber(run),
        plan: Some("p".try_into().unwrap()),
        remaining_samples: 12_345 * u64::from(StatusReport::IDLE.sample_rate) / 10_000,
        measured: Some(Measurement { accel_mmps2: 9_874, phase_mdeg: 0 }),
        level: Some(Level::Drive(8_000)),
        freq_mhz: 150_040,
        ..StatusReport::IDLE
    }
}

fn read(status: &CellStatus, holding: &Holding, address: u16) -> u16 {
    input_registers(status, holding)[usize::from(address)]
}

#[test]
fn a_running_plan_is_encoded_in_the_documented_units() {
    let holding = Holding { command_run: 0x0002_0003, ..Holding::default() };
    let s = status(true, Some(running(0x0001_0009)), Some(0x0001_0009));
    let r = input_registers(&s, &holding);
    assert_eq!(r[usize::from(input::STATE)], CellState::Busy.code());
    assert_eq!(r[usize::from(input::LINK_UP)], 1);
    assert_eq!(r[usize::from(input::SLOT)], 4);
    assert_eq!((r[usize::from(input::STEP)], r[usize::from(input::REPETITION)]), (1, 2));
    // 1234.5 ms as whole ms, high word first.
    let remaining = u32::from(r[5]) << 16 | u32::from(r[6]);
    assert_eq!(remaining, 1_234);
    assert_eq!(r[usize::from(input::ACCEL)], 987, "9.874 m/s² in 0.01 m/s² units, rounded");
    assert_eq!(r[usize::from(input::FREQ)], 1_500, "150.04 Hz in 0.1 Hz units");
    assert_eq!(r[usize::from(input::FAULT)], 0);
    assert_eq!(r[usize::from(input::HEARTBEAT)], 7, "heartbeat: low 16 bits");
    assert_eq!((r[12], r[13]), (2, 3), "command run: high word first");
    assert_eq!((r[14], r[15]), (1, 9), "device run: high word first");
}

#[test]
fn large_values_saturate_instead_of_wrapping() {
    let mut report = running(1);
    report.remaining_samples = u64::MAX;
    report.measured = Some(Measurement { accel_mmps2: u32::MAX, phase_mdeg: 0 });
    report.freq_mhz = u32::MAX;
    let r = input_registers(&status(true, Some(report), None), &Holding::default());
    assert_eq!((r[5], r[6]), (0xFFFF, 0xFFFF));
    assert_eq!((r[usize::from(input::ACCEL)], r[usize::from(input::FREQ)]), (0xFFFF, 0xFFFF));
}

#[test]
fn the_state_register_follows_the_cells_state() {
    let h = Holding::default();
    let idle = StatusReport { run: RunNumber(3), ..StatusReport::IDLE };
    assert_eq!(read(&status(true, Some(idle.clone()), None), &h, input::STATE), 0);
    // Accepted but not reported yet: busy, not the previous run's "done".
    assert_eq!(read(&status(true, Some(idle.clone()), Some(4)), &h, input::STATE), 1);
    assert_eq!(read(&status(true, Some(running(4)), Some(4)), &h, input::STATE), 1);
    let ended = StatusReport { run: RunNumber(4), ..StatusReport::IDLE };
    assert_eq!(read(&status(true, Some(ended), Some(4)), &h, input::STATE), 2);
    let mut faulted = running(4);
    faulted.state = DriveState::Faulted;
    faulted.fault = Some(Fault { cause: FaultCause::NoData, value: 300, at_sample: 1 });
    assert_eq!(read(&status(true, Some(faulted), Some(4)), &h, input::STATE), 3);
}

#[test]
fn a_lost_link_reads_error_and_link_lost_with_nothing_stale() {
    // The last report said busy; the link is gone since.
    let s = status(false, Some(running(4)), Some(4));
    let r = input_registers(&s, &Holding::default());
    assert_eq!(r[usize::from(input::STATE)], CellState::Error.code());
    assert_eq!(r[usize::from(input::LINK_UP)], 0);
    assert_eq!(r[usize::from(input::FAULT)], FAULT_LINK_DOWN);
    assert_eq!((r[usize::from(input::SLOT)], r[usize::from(input::STEP)]), (NONE, NONE));
    assert_eq!(&r[4..9], &[0, 0, 0, 0, 0], "repetition, remaining, accel, freq: none");
    // Up but no report read yet: the same.
    let r = input_registers(&status(true, None, None), &Holding::default());
    assert_eq!((r[0], r[9]), (CellState::Error.code(), FAULT_LINK_DOWN));
}

#[test]
fn every_fault_cause_has_its_own_code() {
    let causes = [
        FaultCause::LoopOpen,
        FaultCause::LoopCheck,
        FaultCause::OutOfBand,
        FaultCause::OverAcceleration,
        FaultCause::Sensor(SensorFault::Nack),
        FaultCause::Sensor(SensorFault::WrongId(0x12)),
        FaultCause::Sensor(SensorFault::Overrun),
        FaultCause::Sensor(SensorFault::Bus),
        FaultCause::NoData,
        FaultCause::Saturation,
    ];
    let mut codes: Vec<u16> = causes.iter().map(|c| fault_code(*c)).collect();
    assert!(codes.iter().all(|c| *c != 0 && *c != FAULT_LINK_DOWN));
    codes.sort_unstable();
    codes.dedup();
    assert_eq!(codes.len(), causes.len());
    let mut faulted = running(2);
    faulted.fault = Some(Fault { cause: FaultCause::Saturation, value: 40_000, at_sample: 5 });
    let s = status(true, Some(faulted), Some(2));
    assert_eq!(read(&s, &Holding::default(), input::FAULT), 10);
}

#[test]
fn reads_outside_the_map_or_of_bad_sizes_are_refused_the_modbus_way() {
    let table = [1u16, 2, 3];
    assert_eq!(read_range(&table, 1, 2, 125), Ok(vec![2, 3]));
    assert_eq!(read_range(&table, 2, 2, 125), Err(ExceptionCode::IllegalDataAddress));
    assert_eq!(read_range(&table, 0xFFFF, 1, 125), Err(ExceptionCode::IllegalDataAddress));
    assert_eq!(read_range(&table, 0, 0, 125), Err(ExceptionCode::IllegalDataValue));
    assert_eq!(read_range(&table, 0, 126, 125), Err(ExceptionCode::IllegalDataValue));
}

#[test]
fn writes_are_checked_whole_before_anything_is_set() {
    let run_slot_3 = Write { slot: Some(3), repeat: Some(2), command: Some(Command::Run) };
    assert_eq!(parse_write(0, &[3, 2, 1]), Ok(run_slot_3));
    assert_eq!(
        parse_write(HOLDING_COMMAND, &[2]),
        Ok(Write { command: Some(Command::Stop), ..Write::default() })
    );
    let bad_slot = parse_write(0, &[u16::from(PLAN_SLOTS), 0, 1]).unwrap_err();
    assert_eq!(bad_slot.exception, ExceptionCode::IllegalDataValue);
    assert_eq!(bad_slot.result, Some(CommandResult::BadSlot));
    let unknown = parse_write(HOLDING_COMMAND, &[9]).unwrap_err();
    assert_eq!(unknown.result, Some(CommandResult::UnknownCommand));
    let past = parse_write(HOLDING_REPEAT, &[1, 1, 1]).unwrap_err();
    assert_eq!((past.exception, past.result), (ExceptionCode::IllegalDataAddress, None));
    assert_eq!(parse_write(3, &[0]).unwrap_err().exception, ExceptionCode::IllegalDataAddress);
    assert_eq!(parse_write(0, &[]).unwrap_err().exception, ExceptionCode::IllegalDataValue);
}

#[test]
fn cell_errors_map_to_their_result_and_exception() {
    let cases = [
        (CellError::LinkDown { reason: "x".into() }, 4, ExceptionCode::GatewayTargetDevice),
        (CellError::BadSlot { slot: 70 }, 2, ExceptionCode::IllegalDataValue),
        (CellError::NoPlan { slot: 1, stored: "0".into() }, 3, ExceptionCode::IllegalDataValue),
        (CellError::Device(DeviceError::Closed), 4, ExceptionCode::GatewayTargetDevice),
        (
            CellError::Device(DeviceError::Refused(Refusal::Busy {
                owner: "other".try_into().unwrap(),
                idle_ms: 5,
            })),
            5,
            ExceptionCode::ServerDeviceFailure,
        ),
        (
            CellError::Device(DeviceError::Refused(Refusal::Drive(DriveError::Faulted))),
            6,
            ExceptionCode::ServerDeviceFailure,
        ),
        (
            CellError::Device(DeviceError::Refused(Refusal::Drive(DriveError::QueueFull))),
            7,
            ExceptionCode::ServerDeviceFailure,
        ),
        (CellError::Stopped, 8, ExceptionCode::ServerDeviceFailure),
    ];
    for (error, code, exception) in cases {
        let result = CommandResult::of(&error);
        assert_eq!((result.code(), result.exception()), (code, Some(exception)), "{error}");
    }
    assert_eq!(CommandResult::Ok.exception(), None);
}

/// A cell whose controller port refuses connections: the link stays down.
fn cell_without_controller() -> Cell {
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    // The listener is closed again: connecting is refused at once.
    Cell::start(&format!("tcp://127.0.0.1:{port}"), "modbus unit test")
}

#[tokio::test]
async fn the_service_answers_reads_writes_and_refusals_without_a_controller() {
    let registers = Registers::new(cell_without_controller());
    let deadline = Instant::now() + Duration::from_secs(5);
    while registers.cell.status().error.as_deref() == Some("connecting to the controller") {
        assert!(Instant::now() < deadline, "the owner never published");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let Ok(Response::ReadInputRegisters(r)) =
        registers.handle(Request::ReadInputRegisters(0, input::COUNT)).await
    else {
        panic!("reading the whole input map failed");
    };
    assert_eq!((r[0], r[1], r[9]), (3, 0, FAULT_LINK_DOWN));
    let write = Request::WriteMultipleRegisters(0, Cow::Owned(vec![5, 2]));
    assert_eq!(registers.handle(write).await, Ok(Response::WriteMultipleRegisters(0, 2)));
    assert_eq!(
        registers.handle(Request::ReadHoldingRegisters(0, 3)).await,
        Ok(Response::ReadHoldingRegisters(vec![5, 2, 0]))
    );
    // A bad slot: 0x03, the result names it, the slot register keeps its value.
    let bad = registers.handle(Request::WriteSingleRegister(HOLDING_SLOT, 200)).await;
    assert_eq!(bad, Err(ExceptionCode::IllegalDataValue));
    assert_eq!(registers.holding().result, CommandResult::BadSlot);
    assert_eq!(registers.holding().slot, 5);
    // A good write clears the reason again.
    let good = registers.handle(Request::WriteSingleRegister(HOLDING_REPEAT, 3)).await;
    assert_eq!(good, Ok(Response::WriteSingleRegister(HOLDING_REPEAT, 3)));
    assert_eq!(registers.holding().result, CommandResult::Ok);
    // Run with the link down: the gateway exception, and the result says why.
    let run = registers.handle(Request::WriteSingleRegister(HOLDING_COMMAND, 1)).await;
    assert_eq!(run, Err(ExceptionCode::GatewayTargetDevice));
    assert_eq!(registers.holding().result, CommandResult::LinkDown);
    assert_eq!(registers.holding().last_command, 1);
    let Ok(Response::ReadInputRegisters(result)) =
        registers.handle(Request::ReadInputRegisters(input::RESULT, 1)).await
    else {
        panic!("reading the result register failed");
    };
    assert_eq!(result, [CommandResult::LinkDown.code()]);
    assert_eq!(
        registers.handle(Request::ReadInputRegisters(input::COUNT, 1)).await,
        Err(ExceptionCode::IllegalDataAddress)
    );
    assert_eq!(
        registers.handle(Request::ReadCoils(0, 1)).await,
        Err(ExceptionCode::IllegalFunction)
    );
}
