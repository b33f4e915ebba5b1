//! End to end: plans and manual drive sent from the host over the link to the firmware in QEMU,
//! or to the real board on `CHLADNI_PORT` (hardware in the loop).
//!
//! Timing assertions are on sample counts reported by the firmware, never on wall time: QEMU's
//! clock follows the host's and slips under load. Polling uses generous deadlines.

use std::time::Duration;

use chladni_device::client::{DeviceClient, DeviceError};
use chladni_e2e::{Controller, plan, poll_until};
use chladni_shared::drive::runner::{BLOCK_LEN, MANUAL_RAMP_MS};
use chladni_shared::icd::link::{DriveError, DriveState, Refusal, SetpointError};
use chladni_shared::icd::plan::Step;
use chladni_shared::icd::store::PlanRef;
use chladni_shared::icd::units::SAMPLES_PER_MS;

fn start(name: &str) -> (Controller, DeviceClient) {
    let _ = std::fs::remove_file(chladni_e2e::flash_path(&format!("drive-{name}")));
    let controller = Controller::start(&format!("drive-{name}"));
    let mut client = controller.connect(&format!("e2e drive {name}")).expect("connect");
    client.set_timeout(Duration::from_secs(10));
    (controller, client)
}

#[test]
fn plan_runs_step_by_step_to_idle() {
    let (_emulator, mut client) = start("plan");
    let steps = [
        Step {
            freq_mhz: 120_000,
            level: chladni_shared::icd::plan::Level::Drive(16_000),
            duration_ms: 600,
            ramp_ms: 20,
        },
        Step {
            freq_mhz: 181_500,
            level: chladni_shared::icd::plan::Level::Drive(24_000),
            duration_ms: 700,
            ramp_ms: 10,
        },
        Step {
            freq_mhz: 1_234_567,
            level: chladni_shared::icd::plan::Level::Drive(8_000),
            duration_ms: 600,
            ramp_ms: 30,
        },
    ];
    // Steps last ≥ 600 ms so that a poller stalled by a loaded host still sees each of them.
    let before = client.status().expect("status");
    assert_eq!(before.state, DriveState::Idle);
    client.upload(&plan("e2e", &steps, 1), None, |_, _| {}).expect("upload");
    let run = client.run(PlanRef::Name("e2e".try_into().unwrap()), None).expect("plan accepted");

    let seen = poll_until(&mut client, Duration::from_secs(90), |s| {
        s.run == run && s.state == DriveState::Idle
    });
    let seen: Vec<_> = seen.into_iter().filter(|s| s.run == run).collect();

    // Step windows in samples: step i covers [start_i, end_i).
    let mut bounds = Vec::new();
    let mut t = 0u64;
    for s in &steps {
        let n = (s.duration_ms * SAMPLES_PER_MS) as u64;
        bounds.push((t, t + n));
        t += n;
    }
    let mut last_step = 0u16;
    let mut steps_seen = std::collections::BTreeSet::new();
    for s in &seen {
        // Status is published once per block, and the plan started on a block boundary.
        assert_eq!(s.elapsed_samples % BLOCK_LEN as u64, 0, "{s:?}");
        if let Some(i) = s.step {
            let (lo, hi) = bounds[i as usize];
            assert!(
                (lo..hi).contains(&s.elapsed_samples),
                "step {i} reported at sample {} outside [{lo}, {hi})",
                s.elapsed_samples
            );
            assert!(i >= last_step, "steps went backwards: {seen:?}");
            assert_eq!(s.freq_mhz, steps[i as usize].freq_mhz);
            assert_eq!(s.plan.as_deref(), Some("e2e"));
            last_step = i;
            steps_seen.insert(i);
        }
    }
    assert_eq!(steps_seen.into_iter().collect::<Vec<_>>(), [0, 1, 2], "every step observed");
    let end = seen.last().unwrap();
    assert_eq!(end.state, DriveState::Idle);
    assert_eq!(end.step, None);
    assert_eq!(end.amplitude_q15, 0);
    // All steps, then the final ramp to zero (the last step's 30 ms ramp): to the sample.
    assert_eq!(end.elapsed_samples, t + (30 * SAMPLES_PER_MS) as u64);
}

#[test]
fn manual_drive_stop_and_refusals() {
    let (_emulator, mut client) = start("manual");

    // An invalid setpoint is refused by the controller itself with the typed error.
    match client.drive(440_000, chladni_shared::icd::plan::Level::Drive(40_000)) {
        Err(DeviceError::Refused(Refusal::Drive(DriveError::Setpoint(e)))) => {
            assert!(matches!(e, SetpointError::AmplitudeTooHigh { amplitude_q15: 40_000, .. }))
        }
        other => panic!("expected an amplitude error, got {other:?}"),
    }
    assert_eq!(client.status().unwrap().state, DriveState::Idle);

    let run = client
        .drive(440_500, chladni_shared::icd::plan::Level::Drive(16_384))
        .expect("drive accepted");
    let seen = poll_until(&mut client, Duration::from_secs(60), |s| {
        s.run == run && s.state == DriveState::Running && s.amplitude_q15 == 16_384
    });
    let s = seen.last().unwrap().clone();
    assert_eq!((s.freq_mhz, s.step, s.plan.clone()), (440_500, None, None));
    // The manual ramp takes MANUAL_RAMP_MS: running at full amplitude only after it.
    assert!(s.elapsed_samples >= (MANUAL_RAMP_MS * SAMPLES_PER_MS) as u64);

    let stop = client.stop().expect("stop accepted");
    let seen = poll_until(&mut client, Duration::from_secs(60), |t| {
        t.run == stop && t.state == DriveState::Idle
    });
    // The amplitude only ever falls while stopping: a ramp, not a cut.
    let amps: Vec<u16> = seen.iter().map(|s| s.amplitude_q15).collect();
    assert!(amps.windows(2).all(|w| w[1] <= w[0]), "amplitude rose while stopping: {amps:?}");
    assert_eq!(*amps.last().unwrap(), 0);
}
