//! End to end: plans kept on the controller (issue 11). Upload, list, restart, run by name with
//! the telemetry monitor, stop, refusals, and a power cut in the middle of an upload.

use std::time::Duration;

use chladni_device::client::{DeviceClient, DeviceError, Tamper};
use chladni_e2e::{Controller, plan, poll_until, pseudo_random_bytes, steps};
use chladni_shared::icd::link::{DeletePlan, DriveState, GetStatus, MAX_FRAME, Refusal, Telemetry};
use chladni_shared::icd::plan::{PlanError, Step};
use chladni_shared::icd::store::{PlanRef, PlanSummary, UploadBegin, UploadError, plan_crc};

const NAMES: [&str; 3] = ["short", "seventy", "longest"];

fn connect(controller: &Controller, name: &str) -> DeviceClient {
    let mut client = controller.connect(name).expect("connect");
    client.set_timeout(Duration::from_secs(10));
    client
}

/// Uploads the three test plans (5, 70 and 256 steps); returns their CRCs.
fn upload_three(client: &mut DeviceClient) -> Vec<u32> {
    let plans = [
        plan(NAMES[0], &steps(5, 100_000, 150), 1),
        plan(NAMES[1], &steps(70, 50_000, 20), 2),
        plan(NAMES[2], &steps(256, 20_000, 10), 1),
    ];
    plans
        .iter()
        .map(|p| {
            let stored = client.upload(p, None, |_, _| {}).expect("upload");
            assert_eq!((stored.name.as_str(), stored.crc), (p.name.as_str(), plan_crc(p)));
            stored.crc
        })
        .collect()
}

fn by_name(name: &str) -> PlanRef {
    PlanRef::Name(name.try_into().unwrap())
}

/// The stored test plans (a real controller may hold others: they are left alone).
fn summaries(client: &mut DeviceClient) -> Vec<PlanSummary> {
    let all = client.list_plans().expect("list").0;
    all.into_iter().filter(|p| NAMES.contains(&p.name.as_str())).collect()
}

#[test]
fn stored_plans_survive_a_restart_and_refuse_bad_uploads() {
    let name = "store-plans";
    let _ = std::fs::remove_file(chladni_e2e::flash_path(name));
    let mut controller = Controller::start(name);
    let mut client = connect(&controller, "e2e store");
    let crcs = upload_three(&mut client);
    let listed = summaries(&mut client);
    let listed_crcs: Vec<u32> = listed.iter().map(|p| p.crc).collect();
    assert_eq!(listed_crcs, crcs, "{listed:?}");
    drop(client);

    if let Some(emulator) = controller.emulator("restart") {
        emulator.restart().expect("restart QEMU");
    }
    let mut client = connect(&controller, "e2e store after restart");
    assert_eq!(summaries(&mut client), listed, "plans changed across the restart");
    // The longest reads back whole (the controller checks its CRC before it accepts a run).
    client.run(by_name(NAMES[2]), None).expect("the 256-step plan loads");
    let stop = client.stop().expect("stop");
    // The stop is queued when acknowledged; the noise below must start from a settled drive.
    poll_until(&mut client, Duration::from_secs(30), |s| {
        s.run == stop && s.state == DriveState::Idle
    });

    noise_changes_nothing(&mut client, &listed);
    bad_uploads_are_refused(&mut client, &listed);
}

#[test]
fn a_plan_run_by_name_shows_in_the_telemetry_and_stops_with_a_ramp() {
    let name = "store-run";
    let _ = std::fs::remove_file(chladni_e2e::flash_path(name));
    let controller = Controller::start(name);
    let mut client = connect(&controller, "e2e run by name");
    upload_three(&mut client);
    run_and_monitor(&mut client, NAMES[1]);
}

/// Runs `name`, watches the telemetry (steps advance, remaining time falls), then stops it
/// (the amplitude ramps down to idle).
fn run_and_monitor(client: &mut DeviceClient, name: &str) {
    let run = client.run(by_name(name), None).expect("run by name");
    client.subscribe(20, 30).expect("subscribe");
    let samples: Vec<Telemetry> =
        std::iter::from_fn(|| client.next_telemetry(Duration::from_secs(2)).expect("telemetry"))
            .filter(|t| t.status.run == run && t.status.step.is_some())
            .collect();
    assert!(samples.len() >= 10, "too few samples of the run: {}", samples.len());
    // (repetition, step): the plan runs twice, so the step number starts over once.
    let steps: Vec<(u16, u16)> =
        samples.iter().filter_map(|t| Some((t.status.repetition, t.status.step?))).collect();
    assert!(steps.windows(2).all(|w| w[1] >= w[0]), "steps went back: {steps:?}");
    assert!(steps.last() > steps.first(), "steps did not advance: {steps:?}");
    let remaining: Vec<u64> = samples.iter().map(|t| t.status.remaining_samples).collect();
    assert!(remaining.windows(2).all(|w| w[1] <= w[0]), "remaining rose: {remaining:?}");
    assert!(remaining.last() < remaining.first());
    assert!(samples.iter().all(|t| t.status.plan.as_deref() == Some(name)));

    let stop = client.stop().expect("stop");
    let seen = poll_until(client, Duration::from_secs(30), |s| {
        s.run == stop && s.state == DriveState::Idle
    });
    let amps: Vec<u16> = seen.iter().filter(|s| s.run == stop).map(|s| s.amplitude_q15).collect();
    assert!(amps.windows(2).all(|w| w[1] <= w[0]), "not a ramp down: {amps:?}");
}

/// Garbage, an oversized frame and a bad-CRC request between requests change nothing.
fn noise_changes_nothing(client: &mut DeviceClient, listed: &[PlanSummary]) {
    let before = client.status().unwrap();
    client.send_raw(&pseudo_random_bytes(7, 2048)).unwrap();
    client.send_raw(&vec![0x33; 4 * MAX_FRAME]).unwrap();
    client.send_raw(&[0]).unwrap();
    client.send_tampered(GetStatus, Tamper::CorruptCrc).unwrap();
    let delete = DeletePlan { plan: by_name(NAMES[0]) };
    client.send_tampered(delete, Tamper::CorruptCrc).unwrap();
    assert_eq!(summaries(client), listed);
    let after = client.status().unwrap();
    assert_eq!(
        (after.run, after.state, after.commands),
        (before.run, before.state, before.commands)
    );
}

/// A plan with a step at 0 Hz and one of 10 000 steps are refused with their named errors;
/// the stored plans stay as they were.
fn bad_uploads_are_refused(client: &mut DeviceClient, listed: &[PlanSummary]) {
    let mut zero = steps(3, 100_000, 10);
    zero[1].freq_mhz = 0;
    match client.upload(&plan(NAMES[0], &zero, 1), None, |_, _| {}) {
        Err(DeviceError::Refused(Refusal::Upload(UploadError::Plan(
            PlanError::FrequencyOutOfRange { step: 1, freq_mhz: 0, .. },
        )))) => {}
        other => panic!("expected a frequency error at step 1, got {other:?}"),
    }
    let huge = UploadBegin {
        slot: None,
        name: "huge".try_into().unwrap(),
        repeat: 1,
        steps: 10_000,
        crc: 0,
    };
    match client.call(huge) {
        Err(DeviceError::Refused(Refusal::Upload(UploadError::Plan(
            PlanError::TooManySteps { count: 10_000, max: 256 },
        )))) => {}
        other => panic!("expected too many steps, got {other:?}"),
    }
    assert_eq!(summaries(client), listed, "a refused upload changed the store");
}

#[test]
fn a_power_cut_in_the_middle_of_an_upload_keeps_the_old_plan_whole() {
    let name = "store-power-cut";
    let _ = std::fs::remove_file(chladni_e2e::flash_path(name));
    let mut controller = Controller::start(name);
    let Some(emulator) = controller.emulator("power cut (kills QEMU)") else { return };
    let mut client = emulator.connect("e2e power cut").expect("connect");
    client.set_timeout(Duration::from_secs(10));
    let old = plan("kept", &steps(100, 30_000, 10), 1);
    let stored = client.upload(&old, Some(0), |_, _| {}).expect("upload the old plan");

    // The new plan of the same name: begin and two chunks, then the power goes.
    let new: Vec<Step> = steps(200, 60_000, 10);
    let mut chunks_sent = 0;
    let new_plan = plan("kept", &new, 1);
    let cut = client.upload(&new_plan, Some(0), |done, _| {
        chunks_sent = done;
        if done >= 64 {
            emulator.kill();
        }
    });
    assert!(cut.is_err(), "the upload cannot finish without QEMU");
    drop(client);
    emulator.restart().expect("power back on");
    let mut client = emulator.connect("e2e after the power cut").expect("connect");
    // Every plan of this controller's own fresh flash: only the old one.
    let plans = client.list_plans().expect("list").0;
    assert_eq!(plans, [stored], "after a cut at {chunks_sent} steps: {plans:?}");
    // It reads back whole: the controller checks the plan's CRC before it accepts a run.
    client.run(PlanRef::Slot(0), None).expect("the old plan loads");
    client.stop().unwrap();
}

/// Bank 2 holding another program's data (the factory demo's leftovers, here pseudo-random
/// bytes in pages 1–3 of the flash file): the controller names it foreign, refuses to store,
/// leaves every byte alone, and stores again only after an explicit format.
#[test]
fn foreign_data_in_the_store_is_named_refused_and_erased_only_by_a_format() {
    use chladni_shared::icd::link::{FormatStore, GetStore};
    use chladni_shared::icd::store::{StoreError, StoreState};
    let name = "store-foreign";
    if chladni_e2e::real_port().is_some() {
        println!("skipped on the real board: it would format the board's store");
        return;
    }
    let path = chladni_e2e::flash_path(name);
    let mut bytes = vec![0xffu8; 512 * 1024];
    bytes[2048..4 * 2048].copy_from_slice(&pseudo_random_bytes(42, 3 * 2048));
    std::fs::write(&path, &bytes).expect("write the flash file");
    let controller = Controller::start(name);
    let mut client = connect(&controller, "e2e foreign store");
    let info = client.call(GetStore).expect("store info");
    assert_eq!(info.state, StoreState::Foreign, "{info:?}");
    match client.upload(&plan("p", &steps(5, 100_000, 10), 1), None, |_, _| {}) {
        Err(DeviceError::Refused(Refusal::Store(StoreError::Foreign))) => {}
        other => panic!("expected Store(Foreign), got {other:?}"),
    }
    assert_eq!(std::fs::read(&path).unwrap(), bytes, "the foreign data was changed");
    let formatted = client.call(FormatStore).expect("format");
    assert_eq!(formatted.state, StoreState::Ready, "{formatted:?}");
    let stored = client.upload(&plan("p", &steps(5, 100_000, 10), 1), None, |_, _| {});
    assert_eq!(stored.expect("upload after the format").slot, 0);
    assert_eq!(client.call(GetStore).expect("store info").state, StoreState::Ready);
}
