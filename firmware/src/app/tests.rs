//! Host unit tests of the application: the link's answers and the drive's command and status
//! logic, with the real [`DriveShared`] and plan runner. The only stand-in is [`VecOutput`],
//! a sample output that keeps every block it is given.

use std::vec::Vec;

use chladni_shared::drive::dds::DAC_MID;
use chladni_shared::drive::runner::{BLOCK_LEN, STOP_RAMP_MS};
use chladni_shared::icd::link::{
    self, DriveError, DriveState, OWNER_LEASE_MS, Refusal, Request, RunNumber, SetpointError,
};
use chladni_shared::icd::plan::{DeviceLimits, Level, Plan, PlanError, Step};
use chladni_shared::icd::units::{SAMPLE_RATE, SAMPLES_PER_MS};
use embassy_futures::block_on;
use embassy_time::Instant;

use super::drive::{Command, DriveCore, DriveShared, SampleOutput, Underrun};
use super::link::Sessions;

/// Keeps every block; reports an underrun for the block numbers in `dry`.
#[derive(Default)]
struct VecOutput {
    samples: Vec<u16>,
    blocks: usize,
    dry: Vec<usize>,
}

impl SampleOutput for VecOutput {
    async fn write_block(&mut self, block: &[u16]) -> Result<Option<u32>, Underrun> {
        self.samples.extend_from_slice(block);
        self.blocks += 1;
        if self.dry.contains(&(self.blocks - 1)) {
            Err(Underrun)
        } else {
            // A slack that shrinks block by block, so the least is the last one's.
            Ok(Some(5_000 - 10 * self.blocks as u32))
        }
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
        p.steps
            .push(Step { freq_mhz, level: Level::Drive(amplitude_q15), duration_ms, ramp_ms })
            .unwrap();
    }
    p
}

#[test]
fn a_bad_setpoint_or_plan_is_refused_with_its_typed_error_and_never_queued() {
    let drive = DriveShared::new();
    let refused = SetpointError::FrequencyOutOfRange {
        freq_mhz: 5_000_000,
        min_mhz: 1_000,
        max_mhz: 2_000_000,
    };
    let too_fast =
        Command::Drive { freq_mhz: 5_000_000, level: chladni_shared::icd::plan::Level::Drive(100) };
    assert_eq!(drive.submit(too_fast), Err(DriveError::Setpoint(refused)));
    let message = std::format!("{}", DriveError::Setpoint(refused));
    assert_eq!(message, "invalid setpoint: frequency 5000.000 Hz outside 1.000..=2000.000 Hz");
    let too_loud = Command::Drive {
        freq_mhz: 440_000,
        level: chladni_shared::icd::plan::Level::Drive(40_000),
    };
    assert_eq!(
        drive.submit(too_loud),
        Err(DriveError::Setpoint(SetpointError::AmplitudeTooHigh {
            amplitude_q15: 40_000,
            max_q15: 32_767
        }))
    );
    // A bad plan names its step; nothing refused reached the drive.
    let bad = plan("bad", &[(100_000, 1_000, 10, 0), (999, 1_000, 10, 0)]);
    assert!(matches!(
        drive.run_plan(&bad),
        Err(DriveError::Plan(PlanError::FrequencyOutOfRange { step: 1, .. }))
    ));
    let mut core = DriveCore::new(&drive);
    let mut out = VecOutput::default();
    play(&mut core, &mut out, 2);
    assert_eq!((drive.status().commands, drive.status().run), (0, RunNumber(0)));
    assert!(out.samples.iter().all(|&c| c == DAC_MID));
}

#[test]
fn narrower_limits_apply_to_the_next_command() {
    let drive = DriveShared::new();
    let narrow = DeviceLimits { max_freq_mhz: 300_000, ..DeviceLimits::DEFAULT };
    drive.set_limits(narrow);
    let err = drive
        .submit(Command::Drive {
            freq_mhz: 400_000,
            level: chladni_shared::icd::plan::Level::Drive(1),
        })
        .unwrap_err();
    assert!(matches!(
        err,
        DriveError::Setpoint(SetpointError::FrequencyOutOfRange { max_mhz: 300_000, .. })
    ));
    assert_eq!(
        drive.submit(Command::Drive {
            freq_mhz: 250_000,
            level: chladni_shared::icd::plan::Level::Drive(1)
        }),
        Ok(RunNumber(1))
    );
}

#[test]
fn a_submitted_plan_shows_up_in_status_with_its_run_number_and_remaining_time() {
    let drive = DriveShared::new();
    let p = plan("two", &[(100_000, 10_000, 12, 2), (200_000, 8_000, 8, 2)]);
    let run = drive.run_plan(&p).unwrap();
    assert_eq!(run, RunNumber(1));
    // Queued, not yet applied: the drive core has not run, and status still names run 0.
    assert_eq!((drive.status().state, drive.status().run), (DriveState::Idle, RunNumber(0)));

    let mut core = DriveCore::new(&drive);
    let mut out = VecOutput::default();
    play(&mut core, &mut out, 1); // 5 ms: inside step 0, past its 2 ms ramp
    let s = drive.status();
    assert_eq!((s.state, s.step, s.repetition, s.commands), (DriveState::Running, Some(0), 0, 1));
    assert_eq!((s.run, s.plan.as_deref()), (run, Some("two")));
    assert_eq!((s.freq_mhz, s.amplitude_q15), (100_000, 10_000));
    assert_eq!((s.elapsed_samples, s.sample_rate), (BLOCK_LEN as u64, SAMPLE_RATE));
    assert_eq!(s.remaining_samples, (20 * SAMPLES_PER_MS) as u64 - BLOCK_LEN as u64);

    play(&mut core, &mut out, 2); // 15 ms: step 1, ramping down to its amplitude
    let s = drive.status();
    assert_eq!((s.step, s.freq_mhz), (Some(1), 200_000));
    assert_eq!(s.remaining_samples, (5 * SAMPLES_PER_MS) as u64);

    // The plan's 20 ms, then the 20 ms ramp to zero: idle after 40 ms = 8 blocks.
    play(&mut core, &mut out, 5);
    let s = drive.status();
    assert_eq!((s.state, s.step, s.run, s.plan), (DriveState::Idle, None, run, None));
    let total = (20 + STOP_RAMP_MS) * SAMPLES_PER_MS;
    assert_eq!(s.elapsed_samples, total as u64);
    assert_eq!(out.samples.len(), 8 * BLOCK_LEN);
    assert!(out.samples.iter().any(|&c| c != DAC_MID), "the plan drove the output");
    assert_eq!(*out.samples.last().unwrap(), DAC_MID, "ends at mid-scale");
}

/// Plans change hands through the two plan buffers: a second plan staged while the first runs
/// starts at the next block; a third before the drive took the second is refused, and once
/// taken, the first's buffer is free again for the next. The status keeps the least slack.
#[test]
fn plans_switch_through_two_buffers_and_the_least_slack_is_kept() {
    let drive = DriveShared::new();
    let mut core = DriveCore::new(&drive);
    let mut out = VecOutput::default();
    assert_eq!(drive.status().least_slack_us, None);
    let a = plan("a", &[(100_000, 10_000, 1_000, 2)]);
    let b = plan("b", &[(150_000, 9_000, 1_000, 2), (160_000, 9_000, 500, 2)]);
    let c = plan("c", &[(170_000, 8_000, 1_000, 2)]);
    drive.run_plan(&a).unwrap();
    play(&mut core, &mut out, 2);
    assert_eq!(drive.status().plan.as_deref(), Some("a"));
    let run_b = drive.run_plan(&b).unwrap();
    assert_eq!(drive.run_plan(&c), Err(DriveError::QueueFull), "b still waits");
    play(&mut core, &mut out, 1);
    let s = drive.status();
    assert_eq!((s.plan.as_deref(), s.run, s.freq_mhz), (Some("b"), run_b, 150_000));
    assert_eq!(s.remaining_samples, (1_500 * SAMPLES_PER_MS) as u64 - BLOCK_LEN as u64);
    // a's buffer was released when b started: c goes into it and runs.
    drive.run_plan(&c).unwrap();
    play(&mut core, &mut out, 1);
    assert_eq!(drive.status().plan.as_deref(), Some("c"));
    // VecOutput reports 5000 - 10·n µs for its n-th block: the least is the last one's.
    assert_eq!(drive.status().least_slack_us, Some(5_000 - 10 * out.blocks as u32));
}

/// Polls `f` to completion; its output and how many times it was pending (yielded).
fn polls<T>(f: impl core::future::Future<Output = T>) -> (T, u32) {
    let mut f = core::pin::pin!(f);
    let mut cx = core::task::Context::from_waker(core::task::Waker::noop());
    let mut pending = 0;
    loop {
        match f.as_mut().poll(&mut cx) {
            core::task::Poll::Ready(v) => return (v, pending),
            core::task::Poll::Pending => pending += 1,
        }
    }
}

#[test]
fn the_links_plan_check_yields_every_64_steps_and_agrees_with_validate() {
    use super::drive::STEPS_PER_YIELD;
    let drive = DriveShared::new();
    let limits = drive.limits();
    let steps: Vec<_> = (0..256).map(|_| (100_000, 10_000, 1_000, 2)).collect();
    let good = plan("long", &steps);
    let (checked, pending) = polls(drive.check_plan(&good));
    assert_eq!(pending, (256 / STEPS_PER_YIELD) as u32);
    let run = drive.stage_plan(checked.unwrap()).unwrap();
    assert_eq!(drive.run_plan(&good), Err(DriveError::QueueFull), "one plan waits: {run:?}");
    // Each kind of refusal is the one Plan::validate gives.
    let mut bad_step = good.clone();
    bad_step.steps[200].ramp_ms = 5_000;
    let mut too_long = good.clone();
    too_long.repeat = 20;
    let mut no_steps = good.clone();
    no_steps.steps.clear();
    for bad in [bad_step, too_long, no_steps] {
        let (checked, _) = polls(drive.check_plan(&bad));
        let expected = bad.validate(&limits).unwrap_err();
        assert_eq!(checked.err(), Some(DriveError::Plan(expected)));
    }
}

#[test]
fn manual_drive_stop_underruns_and_a_full_queue() {
    let drive = DriveShared::new();
    let go = Command::Drive {
        freq_mhz: 440_500,
        level: chladni_shared::icd::plan::Level::Drive(16_384),
    };
    assert_eq!(drive.submit(go.clone()), Ok(RunNumber(1)));
    assert_eq!(drive.submit(Command::Stop), Ok(RunNumber(2)));
    // The queue holds two commands until the drive core takes them; a refused one takes
    // no number.
    assert_eq!(drive.submit(go.clone()), Err(DriveError::QueueFull));
    assert_eq!(drive.submit(Command::Stop), Err(DriveError::QueueFull));

    let mut core = DriveCore::new(&drive);
    let mut out = VecOutput { dry: std::vec![1, 2], ..Default::default() };
    play(&mut core, &mut out, 6); // drive, then stop: ramped to zero within 20 ms
    let s = drive.status();
    assert_eq!((s.state, s.commands, s.underruns, s.run), (DriveState::Idle, 2, 2, RunNumber(2)));

    assert_eq!(drive.submit(go), Ok(RunNumber(3)));
    play(&mut core, &mut out, 10);
    let s = drive.status();
    assert_eq!((s.state, s.freq_mhz, s.amplitude_q15), (DriveState::Running, 440_500, 16_384));
}

fn at(ms: u64) -> Instant {
    Instant::from_millis(1_000_000 + ms)
}

fn hello(name: &str) -> heapless::String<{ link::MAX_CLIENT_NAME }> {
    name.try_into().unwrap()
}

#[test]
fn one_session_owns_the_controller_and_others_are_told_who_at_once() {
    let mut sessions = Sessions::new();
    let drive = Request::Drive(link::Drive {
        freq_mhz: 100_000,
        level: chladni_shared::icd::plan::Level::Drive(1),
    });
    let stop = Request::Stop(link::Stop);
    let status = Request::Status(link::GetStatus);
    sessions.hello(0xa, hello("run --wait (pid 1)"));
    sessions.hello(0xb, hello("drive (pid 2)"));
    assert_eq!(sessions.admit(0xa, &drive, at(0)), Ok(()));
    // B may read and stop, not drive.
    assert_eq!(sessions.admit(0xb, &status, at(10)), Ok(()));
    assert_eq!(sessions.admit(0xb, &stop, at(20)), Ok(()));
    assert_eq!(
        sessions.admit(0xb, &drive, at(500)),
        Err(Refusal::Busy { owner: hello("run --wait (pid 1)"), idle_ms: 500 })
    );
    // A's requests renew its lease, so B stays out while A is active.
    assert_eq!(sessions.admit(0xa, &status, at(2_900)), Ok(()));
    assert!(sessions.admit(0xb, &drive, at(5_000)).is_err());
    // A released: B gets it.
    sessions.release(0xa);
    assert_eq!(sessions.admit(0xb, &drive, at(5_001)), Ok(()));
    assert!(matches!(sessions.admit(0xa, &drive, at(5_002)), Err(Refusal::Busy { .. })));
}

#[test]
fn a_silent_owner_loses_the_controller_after_its_lease() {
    let mut sessions = Sessions::new();
    let drive = Request::Drive(link::Drive {
        freq_mhz: 100_000,
        level: chladni_shared::icd::plan::Level::Drive(1),
    });
    assert_eq!(sessions.admit(1, &drive, at(0)), Ok(()));
    let lease = OWNER_LEASE_MS as u64;
    assert!(sessions.admit(2, &drive, at(lease)).is_err());
    assert_eq!(sessions.admit(2, &drive, at(lease + 1)), Ok(()));
    // A nameless owner is still named as such.
    let err = sessions.admit(1, &drive, at(lease + 2)).unwrap_err();
    assert_eq!(
        std::format!("{err}"),
        "the controller is busy: another client holds it (last request 1 ms ago)"
    );
}

// ---- The link, with a real plan store on the mock flash ----

use super::link::{Identity, Link};
use super::store::PlanStore;
use super::store::mock_flash::MockFlash;
use chladni_shared::icd::link::{Board, Endpoint, Envelope, LinkError, PROTOCOL_VERSION, Response};
use chladni_shared::icd::store::{PlanRef, UploadBegin, UploadChunk, UploadError, plan_crc};

/// A link over a store of 16 pages of mock flash.
fn link_over(drive: &DriveShared) -> Link<'_, MockFlash> {
    let store = PlanStore::new(MockFlash::new(16), 0..16 * 2048);
    let mut link = Link::new(Identity { board: Board::Qemu, inject: None }, drive, Some(store));
    block_on(link.load_config());
    link
}

/// Sends `request` from `session` (id 1) and takes the typed reply, or the response back.
fn call<E: Endpoint>(
    link: &mut Link<'_, MockFlash>,
    session: u32,
    request: E,
) -> Result<E::Reply, Response> {
    E::reply(block_on(link.handle(session, 1, request.into_request(), at(0))))
}

fn upload(link: &mut Link<'_, MockFlash>, session: u32, p: &Plan) -> Result<(), Response> {
    call(link, session, UploadBegin::of(p, None))?;
    let steps = heapless::Vec::from_slice(&p.steps).unwrap();
    call(link, session, UploadChunk { index: 0, steps })?;
    call(link, session, link::UploadCommit).map(|_| ())
}

#[test]
fn a_stored_plan_runs_by_name_with_its_run_number() {
    let drive = DriveShared::new();
    let mut link = link_over(&drive);
    let p = plan("square", &[(100_000, 10_000, 12, 2), (200_000, 8_000, 8, 2)]);
    upload(&mut link, 7, &p).unwrap();
    let page = call(&mut link, 7, link::ListPlans { from_slot: 0 }).unwrap();
    assert_eq!(page.plans.len(), 1);
    assert_eq!((page.plans[0].name.as_str(), page.plans[0].crc), ("square", plan_crc(&p)));
    let by_name = PlanRef::Name("square".try_into().unwrap());
    let run = call(&mut link, 7, link::RunPlan { plan: by_name, repeat: Some(2) }).unwrap();
    assert_eq!(run, RunNumber(1));
    let mut core = DriveCore::new(&drive);
    play(&mut core, &mut VecOutput::default(), 1);
    let s = call(&mut link, 7, link::GetStatus).unwrap();
    assert_eq!((s.run, s.plan.as_deref(), s.state), (run, Some("square"), DriveState::Running));
    assert_eq!(s.remaining_samples, (2 * 20 * SAMPLES_PER_MS) as u64 - BLOCK_LEN as u64);
}

#[test]
fn another_session_is_refused_while_the_owner_uploads_but_may_stop() {
    let drive = DriveShared::new();
    let mut link = link_over(&drive);
    call(&mut link, 1, link::Hello { client: hello("uploader") }).unwrap();
    let p = plan("p", &[(100_000, 10_000, 12, 2)]);
    call(&mut link, 1, UploadBegin::of(&p, None)).unwrap();
    let drive_req =
        link::Drive { freq_mhz: 150_000, level: chladni_shared::icd::plan::Level::Drive(100) };
    match call(&mut link, 2, drive_req) {
        Err(Response::Refused(Refusal::Busy { owner, .. })) => assert_eq!(owner, "uploader"),
        other => panic!("expected Busy, got {other:?}"),
    }
    // The refused command never reached the drive; a stop from anyone does.
    assert_eq!(call(&mut link, 2, link::Stop), Ok(RunNumber(1)));
    // The owner's upload goes on.
    let steps = heapless::Vec::from_slice(&p.steps).unwrap();
    assert_eq!(call(&mut link, 1, UploadChunk { index: 0, steps }), Ok(1));
    assert!(call(&mut link, 1, link::UploadCommit).is_ok());
    call(&mut link, 1, link::Release).unwrap();
    assert_eq!(call(&mut link, 2, drive_req), Ok(RunNumber(2)));
}

#[test]
fn an_upload_error_is_named_and_leaves_the_store_as_it_was() {
    let drive = DriveShared::new();
    let mut link = link_over(&drive);
    let p = plan("keep", &[(100_000, 10_000, 12, 2)]);
    upload(&mut link, 3, &p).unwrap();
    let bad = UploadChunk { index: 1, steps: heapless::Vec::new() };
    assert_eq!(
        call(&mut link, 3, bad),
        Err(Response::Refused(Refusal::Upload(UploadError::NotStarted)))
    );
    let mut zero = p.clone();
    zero.steps[0].freq_mhz = 0;
    match upload(&mut link, 3, &zero) {
        Err(Response::Refused(Refusal::Upload(UploadError::Plan(
            PlanError::FrequencyOutOfRange { step: 0, .. },
        )))) => {}
        other => panic!("expected a frequency error, got {other:?}"),
    }
    let page = call(&mut link, 3, link::ListPlans { from_slot: 0 }).unwrap();
    assert_eq!(page.plans[0].crc, plan_crc(&p));
}

#[test]
fn frames_are_answered_with_their_session_and_id_and_corrupt_ones_never_act() {
    let drive = DriveShared::new();
    let mut link = link_over(&drive);
    let mut buf = [0u8; link::ENCODE_BUF];
    let go = Request::Drive(link::Drive {
        freq_mhz: 123_000,
        level: chladni_shared::icd::plan::Level::Drive(100),
    });
    let env = Envelope { version: PROTOCOL_VERSION, session: 9, id: 77, body: go };
    let wire = link::encode(&env, &mut buf).unwrap().to_vec();
    // A flipped bit in the frequency: the CRC catches it, nothing is queued.
    let mut raw = cobs_decode(&wire[1..wire.len() - 1]);
    raw[5] ^= 0x04; // version, session, id, variant, then the frequency varint from byte 4
    let mut frame = cobs_encode(&raw);
    let answer = block_on(link.respond(Ok(&mut frame), at(0)));
    assert_eq!(answer.body, Response::Error(LinkError::BadCrc));
    assert_eq!(drive.submit(Command::Stop), Ok(RunNumber(1)), "the corrupt drive took no number");
    // The intact frame is answered with its session and id.
    let mut frame = wire[1..wire.len() - 1].to_vec();
    let answer = block_on(link.respond(Ok(&mut frame), at(0)));
    assert_eq!((answer.session, answer.id, answer.body), (9, 77, Response::Drive(RunNumber(2))));
    let answer = block_on(link.respond(Err(LinkError::BadCobs), at(0)));
    assert_eq!((answer.session, answer.id), (0, 0));
}

fn cobs_decode(bytes: &[u8]) -> Vec<u8> {
    let mut out = std::vec![0u8; bytes.len()];
    let n = cobs::decode(bytes, &mut out).unwrap().frame_size();
    out.truncate(n);
    out
}

fn cobs_encode(bytes: &[u8]) -> Vec<u8> {
    let mut out = std::vec![0u8; cobs::max_encoding_length(bytes.len())];
    let n = cobs::encode(bytes, &mut out);
    out.truncate(n);
    out
}

#[test]
fn telemetry_streams_the_asked_count_at_the_asked_rate() {
    let drive = DriveShared::new();
    let mut link = link_over(&drive);
    assert_eq!(
        call(&mut link, 4, link::Subscribe { rate_hz: 500, count: 3 }),
        Err(Response::Refused(Refusal::TelemetryRate { rate_hz: 500 }))
    );
    block_on(link.handle(
        4,
        11,
        Request::Subscribe(link::Subscribe { rate_hz: 10, count: 3 }),
        at(0),
    ));
    let mut seen = Vec::new();
    for ms in (0..1000).step_by(10) {
        if let Some(env) = link.sample(at(ms)) {
            assert_eq!((env.session, env.id), (4, 11));
            match env.body {
                Response::Telemetry(t) => seen.push((ms, t.seq, t.left)),
                other => panic!("expected telemetry, got {other:?}"),
            }
        }
    }
    assert_eq!(seen, [(0, 0, 2), (100, 1, 1), (200, 2, 0)]);
    assert_eq!(link.next_sample_at(), None);
}

#[test]
fn refill_cost_reports_mean_and_most_every_2000_blocks_then_starts_again() {
    use super::drive::RefillCost;
    let mut cost = RefillCost::new();
    for i in 0..RefillCost::BLOCKS - 1 {
        assert_eq!(cost.note(10_000 + i % 3), None);
    }
    // 1999 blocks of 10 000..10 002 and one of 40 000.
    let (mean, max) = cost.note(40_000).expect("a report at the 2000th block");
    assert_eq!(max, 40_000);
    assert_eq!(mean, (10_001 * 1_999 - 1 + 40_000) / 2_000);
    assert_eq!(cost.note(5), None, "counting starts again");
}
