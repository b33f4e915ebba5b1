use std::path::PathBuf;

use chladni_shared::icd::link::{DriveState, Fault, FaultCause, RunNumber, StatusReport};
use chladni_shared::icd::plan::{Level, Plan, Step};

use super::run::{StartClock, timing};
use super::*;
use chladni_device::client::RunOutcome;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("chladni-demo-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn config(out: PathBuf) -> DemoConfig {
    DemoConfig {
        part: root().join(DEFAULT_PART),
        plate: root().join(DEFAULT_PLATE),
        out,
        port: None,
        accel_mps2: 2.0,
        fast: true,
    }
}

fn file_of(durations: &[u32]) -> PlanFile {
    PlanFile {
        name: "t".into(),
        repeat: 1,
        steps: durations.iter().map(|&d| StepJson::open_loop(60.0, d, 0.5, 20)).collect(),
        ..PlanFile::default()
    }
}

#[test]
fn fast_divides_by_the_least_whole_factor_that_fits() {
    let plan = file_of(&[35_380, 35_530]);
    assert_eq!(time_scale(&plan, false), 1);
    assert_eq!(time_scale(&plan, true), 3, "70.9 s into at most 25 s");
    assert_eq!(time_scale(&file_of(&[20_000, 5_000]), true), 1, "already short enough");
    assert_eq!(time_scale(&file_of(&[20_000, 5_001]), true), 2);
    assert_eq!(scaled_ms(35_380, 3), 11_793);
    assert_eq!(scaled_ms(35_530, 3), 11_843);
    assert_eq!(scaled_ms(35_530, 1), 35_530);
    assert_eq!(scaled_ms(1_200, 3), MIN_FAST_STEP_MS, "no step shorter than the floor");
    assert_eq!(scaled_ms(800, 3), 800, "nor longer than it was");
}

#[test]
fn prepare_plans_simulates_and_writes_a_closed_loop_plan() {
    let out = out_dir("prepare");
    let config = config(out.clone());
    let p = prepare(&config).unwrap();
    for path in [&p.files.plan, &p.files.device_plan, &p.files.plan_figure, &p.files.traces] {
        assert!(path.is_file(), "{} written", path.display());
    }
    assert!(p.files.traces_plan.is_file());
    // The stored plan is the planner's, in closed loop, a third as long.
    assert_eq!(p.time_scale, 3);
    assert_eq!(p.device_plan.name.as_str(), STORED_NAME);
    assert_eq!(p.device_plan.steps.len(), p.steps.len());
    let text = std::fs::read_to_string(&p.files.plan).unwrap();
    let plan_file = chladni_core::model::plan_file::PlanFile::parse(&text).unwrap();
    for (step, planned) in p.device_plan.steps.iter().zip(&plan_file.steps) {
        let accel = (planned.amplitude.unwrap() * 2000.0).round() as u32;
        assert_eq!(step.level, Level::Accel(accel));
        assert_eq!(step.duration_ms, scaled_ms(planned.duration_ms, 3));
        assert_eq!(step.ramp_ms, planned.ramp_ms);
    }
    let text = std::fs::read_to_string(&p.files.device_plan).unwrap();
    let back = PlanFile::parse(&text).unwrap().to_plan(&DeviceLimits::DEFAULT).unwrap();
    assert_eq!(back, p.device_plan, "device-plan.json holds what is stored");
    let text = std::fs::read_to_string(&p.files.plan).unwrap();
    let planned = PlanFile::parse(&text).unwrap();
    // The file rounds to 1e-4°.
    let written = planned.final_orientation_deg.unwrap();
    assert!((written - p.syn.final_orientation_deg).abs() < 1e-4, "{written}");
    assert_eq!(p.simulation.claimed_success_rate, 1.0, "straight nodes: every start");
    assert!(p.simulation.success_rate >= p.simulation.claimed_success_rate);

    // A port that does not answer is named, with the fix.
    let unreachable = DemoConfig { port: Some("tcp://127.0.0.1:1".into()), ..config };
    let err = connect(&unreachable, &p).err().expect("nothing listens on port 1");
    assert_eq!((err.name(), err.exit_code()), ("port_unreachable", 1));
    assert!(err.to_string().contains("leave out --port"), "{err}");
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn bad_inputs_are_named_and_exit_2() {
    let out = out_dir("bad");
    let zero = DemoConfig { accel_mps2: 0.0, ..config(out.clone()) };
    let err = prepare(&zero).unwrap_err();
    assert_eq!((err.name(), err.exit_code()), ("bad_input", 2));
    let missing = DemoConfig { part: out.join("nope.json"), ..config(out.clone()) };
    assert_eq!(prepare(&missing).unwrap_err().exit_code(), 2);
    // An output that would overwrite an input.
    std::fs::create_dir_all(&out).unwrap();
    let part = out.join("plan.json");
    std::fs::copy(root().join(DEFAULT_PART), &part).unwrap();
    let over = DemoConfig { part, ..config(out.clone()) };
    let err = prepare(&over).unwrap_err();
    assert_eq!(err.exit_code(), 2, "{err}");
    // Too much acceleration for the device limits: the fix is named.
    let strong = DemoConfig { accel_mps2: 1000.0, ..config(out.clone()) };
    let err = prepare(&strong).unwrap_err();
    assert_eq!(err.name(), "device_plan");
    assert!(err.to_string().contains("lower --accel"), "{err}");
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn missing_programs_are_found_missing() {
    assert!(find_program("sh").is_some());
    assert!(find_program("chladni-no-such-program").is_none());
    let err = DemoError::QemuMissing { program: "qemu-system-arm" };
    assert_eq!((err.name(), err.exit_code()), ("qemu_missing", 1));
    assert!(err.to_string().contains("scripts/install-deps.sh"), "{err}");
    // With a port, nothing local is needed.
    let remote = DemoConfig { port: Some("/dev/ttyACM0".into()), ..config(out_dir("pre")) };
    assert!(preflight(&remote).is_ok());
}

fn plan() -> Plan {
    let step = |duration_ms, ramp_ms| Step {
        freq_mhz: 60_000,
        level: Level::Accel(1_500),
        duration_ms,
        ramp_ms,
    };
    Plan {
        name: "demo".try_into().unwrap(),
        repeat: 1,
        steps: heapless::Vec::from_slice(&[step(1_000, 20), step(500, 30)]).unwrap(),
    }
}

fn status(run: u32, state: DriveState, clock: u64, elapsed: u64) -> StatusReport {
    StatusReport {
        state,
        run: RunNumber(run),
        clock,
        elapsed_samples: elapsed,
        ..StatusReport::IDLE
    }
}

#[test]
fn timing_is_counted_in_samples_from_the_run_start() {
    let run = RunNumber(4);
    let mut clock = StartClock::default();
    // Before the run, and idle: no start.
    clock.see(run, &status(3, DriveState::Running, 5_000, 4_000));
    clock.see(run, &status(4, DriveState::Idle, 9_000, 0));
    assert_eq!(clock.start, None);
    clock.see(run, &status(4, DriveState::Running, 12_000, 2_000));
    clock.see(run, &status(4, DriveState::Running, 40_000, 30_000));
    assert_eq!(clock, StartClock { start: Some(10_000), disagreements: 0 });
    // 1.5 s of steps at 50 000/s, then the final ramp: max(30, 20) ms = 1500 samples.
    let done = status(4, DriveState::Idle, 200_000, 75_000 + 1_500);
    let r = timing(&plan(), run, &RunOutcome::Done(done), clock);
    assert_eq!((r.planned_samples, r.final_ramp_samples), (75_000, 1_500));
    assert_eq!((r.executed_samples, r.difference_samples), (75_000, 0));
    assert_eq!((r.start_clock, r.end_clock), (Some(10_000), Some(86_500)));
    assert_eq!((r.planned_ms, r.executed_ms, r.outcome), (1500.0, 1500.0, "done"));
    // A run cut short by a fault: every sample it ran, short of the plan, and the fault.
    clock.see(run, &status(4, DriveState::Running, 50_000, 39_999));
    assert_eq!(clock.disagreements, 1, "a status one sample off is counted");
    let fault = Fault { cause: FaultCause::LoopOpen, value: 9, at_sample: 60_000 };
    let faulted =
        StatusReport { fault: Some(fault), ..status(4, DriveState::Faulted, 90_000, 51_000) };
    let r = timing(&plan(), run, &RunOutcome::Faulted(faulted), clock);
    assert_eq!((r.executed_samples, r.difference_samples), (51_000, -24_000));
    assert_eq!((r.fault, r.outcome), (Some(fault), "faulted"));
    // Superseded by another run: none of its samples are this run's.
    let other = status(5, DriveState::Running, 90_000, 1_000);
    let r = timing(&plan(), run, &RunOutcome::Superseded(other), clock);
    assert_eq!((r.executed_samples, r.end_clock, r.fault), (0, None, None));
}
