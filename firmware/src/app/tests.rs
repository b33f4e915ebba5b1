//! Host unit tests of the application: the link's answers and the drive's command and status
//! logic, with the real [`DriveShared`] and plan runner. The only stand-in is [`VecOutput`],
//! a sample output that keeps every block it is given.

use std::vec::Vec;

use chladni_shared::drive::dds::{DAC_MID, SAMPLE_RATE, SAMPLES_PER_MS};
use chladni_shared::drive::runner::{BLOCK_LEN, STOP_RAMP_MS};
use chladni_shared::icd::link::{
    self, Board, DriveError, DriveState, Envelope, LinkError, PROTOCOL_VERSION, Request, Response,
    SetpointError,
};
use chladni_shared::icd::plan::{Plan, PlanError, Step};
use embassy_futures::block_on;

use super::drive::{Command, DriveCore, DriveShared, SampleOutput, Underrun};
use super::link::{Identity, handle, respond};

const QEMU: Identity = Identity { board: Board::Qemu };

/// Keeps every block; reports an underrun for the block numbers in `dry`.
#[derive(Default)]
struct VecOutput {
    samples: Vec<u16>,
    blocks: usize,
    dry: Vec<usize>,
}

impl SampleOutput for VecOutput {
    async fn write_block(&mut self, block: &[u16]) -> Result<(), Underrun> {
        self.samples.extend_from_slice(block);
        self.blocks += 1;
        if self.dry.contains(&(self.blocks - 1)) { Err(Underrun) } else { Ok(()) }
    }
}

/// Plays `blocks` blocks through the real drive core into `out`.
fn play(core: &mut DriveCore<'_>, out: &mut VecOutput, blocks: usize) {
    let mut block = [0u16; BLOCK_LEN];
    for _ in 0..blocks {
        block_on(core.play_block(&mut block, out));
    }
}

fn plan(name: &str, steps: &[(u32, u16, u32, u32)]) -> Plan {
    let mut p = Plan { name: name.try_into().unwrap(), repeat: 1, steps: heapless::Vec::new() };
    for &(freq_mhz, amplitude_q15, duration_ms, ramp_ms) in steps {
        p.steps.push(Step { freq_mhz, amplitude_q15, duration_ms, ramp_ms }).unwrap();
    }
    p
}

#[test]
fn ping_gets_a_pong_with_its_nonce() {
    for nonce in [0, 0x5eed, u32::MAX] {
        let answer = handle(&QEMU, &DriveShared::new(), &Request::Ping { nonce });
        assert_eq!(answer, Response::Pong { nonce });
    }
}

#[test]
fn get_info_names_the_board() {
    for board in [Board::Qemu, Board::Stm32l475] {
        match handle(&Identity { board }, &DriveShared::new(), &Request::GetInfo) {
            Response::Info(info) => {
                assert_eq!(info.board, board);
                assert_eq!(info.protocol_version, PROTOCOL_VERSION);
                assert_eq!(info.firmware_version.as_str(), crate::FIRMWARE_VERSION);
                assert_eq!(info.build_id, crate::BUILD_ID);
            }
            other => panic!("expected Info, got {other:?}"),
        }
    }
}

#[test]
fn a_bad_setpoint_is_refused_with_its_typed_error() {
    let drive = DriveShared::new();
    let too_fast = Request::Drive { freq_mhz: 5_000_000, amplitude_q15: 100 };
    let refused = SetpointError::FrequencyOutOfRange {
        freq_mhz: 5_000_000,
        min_mhz: 1_000,
        max_mhz: 2_000_000,
    };
    assert_eq!(handle(&QEMU, &drive, &too_fast), Response::Rejected(DriveError::Setpoint(refused)));
    let message = std::format!("{}", DriveError::Setpoint(refused));
    assert_eq!(message, "invalid setpoint: frequency 5000.000 Hz outside 1.000..=2000.000 Hz");
    let too_loud = Request::Drive { freq_mhz: 440_000, amplitude_q15: 40_000 };
    assert_eq!(
        handle(&QEMU, &drive, &too_loud),
        Response::Rejected(DriveError::Setpoint(SetpointError::AmplitudeTooHigh {
            amplitude_q15: 40_000,
            max_q15: 32_767
        }))
    );
    // A bad plan names its step; nothing refused reached the drive.
    let bad = plan("bad", &[(100_000, 1_000, 10, 0), (999, 1_000, 10, 0)]);
    match handle(&QEMU, &drive, &Request::RunPlan(bad)) {
        Response::Rejected(DriveError::Plan(PlanError::FrequencyOutOfRange {
            step: 1, ..
        })) => {}
        other => panic!("expected a step-1 frequency error, got {other:?}"),
    }
    let mut core = DriveCore::new(&drive);
    let mut out = VecOutput::default();
    play(&mut core, &mut out, 2);
    assert_eq!(drive.status().commands, 0);
    assert!(out.samples.iter().all(|&c| c == DAC_MID));
}

#[test]
fn a_submitted_plan_shows_up_in_status_as_the_drive_runs_blocks() {
    let drive = DriveShared::new();
    let p = plan("two", &[(100_000, 10_000, 12, 2), (200_000, 8_000, 8, 2)]);
    assert_eq!(handle(&QEMU, &drive, &Request::RunPlan(p)), Response::Ack);
    // Queued, not yet applied: the drive core has not run.
    assert_eq!(drive.status().state, DriveState::Idle);

    let mut core = DriveCore::new(&drive);
    let mut out = VecOutput::default();
    play(&mut core, &mut out, 1); // 5 ms: inside step 0, past its 2 ms ramp
    let s = drive.status();
    assert_eq!((s.state, s.step, s.run, s.commands), (DriveState::Running, Some(0), 0, 1));
    assert_eq!((s.freq_mhz, s.amplitude_q15), (100_000, 10_000));
    assert_eq!((s.elapsed_samples, s.sample_rate), (BLOCK_LEN as u64, SAMPLE_RATE));
    assert_eq!(handle(&QEMU, &drive, &Request::Status), Response::Status(s));

    play(&mut core, &mut out, 2); // 15 ms: step 1, ramping down to its amplitude
    let s = drive.status();
    assert_eq!((s.step, s.freq_mhz), (Some(1), 200_000));

    // The plan's 20 ms, then the 20 ms ramp to zero: idle after 40 ms = 8 blocks.
    play(&mut core, &mut out, 5);
    let s = drive.status();
    assert_eq!((s.state, s.step), (DriveState::Idle, None));
    let total = (20 + STOP_RAMP_MS) * SAMPLES_PER_MS;
    assert_eq!(s.elapsed_samples, total as u64);
    assert_eq!(out.samples.len(), 8 * BLOCK_LEN);
    assert!(out.samples.iter().any(|&c| c != DAC_MID), "the plan drove the output");
    assert_eq!(*out.samples.last().unwrap(), DAC_MID, "ends at mid-scale");
}

#[test]
fn manual_drive_stop_underruns_and_a_full_queue() {
    let drive = DriveShared::new();
    let go = Request::Drive { freq_mhz: 440_500, amplitude_q15: 16_384 };
    assert_eq!(handle(&QEMU, &drive, &go), Response::Ack);
    assert_eq!(handle(&QEMU, &drive, &Request::Stop), Response::Ack);
    // The queue holds two commands until the drive core takes them.
    assert_eq!(handle(&QEMU, &drive, &go), Response::Rejected(DriveError::Busy));
    assert_eq!(drive.submit(Command::Stop), Err(DriveError::Busy));

    let mut core = DriveCore::new(&drive);
    let mut out = VecOutput { dry: std::vec![1, 2], ..Default::default() };
    play(&mut core, &mut out, 6); // drive, then stop: ramped to zero within 20 ms
    let s = drive.status();
    assert_eq!((s.state, s.commands, s.underruns), (DriveState::Idle, 2, 2));

    assert_eq!(handle(&QEMU, &drive, &go), Response::Ack);
    play(&mut core, &mut out, 10);
    let s = drive.status();
    assert_eq!((s.state, s.freq_mhz, s.amplitude_q15), (DriveState::Running, 440_500, 16_384));
}

#[test]
fn frames_are_answered_with_their_id_or_the_error() {
    let drive = DriveShared::new();
    let mut buf = [0u8; link::MAX_FRAME + 2];
    let request = Envelope { version: PROTOCOL_VERSION, id: 77, body: Request::Ping { nonce: 5 } };
    let wire = link::encode(&request, &mut buf).unwrap();
    // Without its two delimiters, as FrameReader::push hands it over.
    let mut frame = wire[1..wire.len() - 1].to_vec();
    let answer = respond(&QEMU, &drive, Ok(&mut frame));
    assert_eq!(
        answer,
        Envelope { version: PROTOCOL_VERSION, id: 77, body: Response::Pong { nonce: 5 } }
    );

    let old = Envelope { version: PROTOCOL_VERSION - 1, id: 78, body: Request::GetInfo };
    let wire = link::encode(&old, &mut buf).unwrap();
    let mut frame = wire[1..wire.len() - 1].to_vec();
    let answer = respond(&QEMU, &drive, Ok(&mut frame));
    let refused =
        LinkError::UnsupportedVersion { got: PROTOCOL_VERSION - 1, supported: PROTOCOL_VERSION };
    assert_eq!((answer.id, answer.body), (78, Response::Error(refused)));

    let answer = respond(&QEMU, &drive, Err(LinkError::BadCobs));
    assert_eq!((answer.id, answer.body), (0, Response::Error(LinkError::BadCobs)));
}
