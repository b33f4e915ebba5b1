//! End to end: sensing and control on the QEMU controller — the simulated plate, its
//! accelerometer read over (simulated) I2C by the real LSM6DSL driver, the lock-in and the PI
//! loop in the drive task — driven from the host over the link.
//!
//! One controller for the whole file (QEMU boots once); each test heals the simulated rig,
//! clears faults and takes what it needs. Assertions are on what the controller reports
//! (measurements, sample counts), never on wall time.

use std::time::Duration;

use chladni::controller::client::DeviceClient;
use chladni_e2e::{Controller, poll_until};
use chladni_shared::icd::link::{DriveState, StatusReport, TestFault};
use chladni_shared::icd::plan::Level;

fn client(c: &Controller, name: &str) -> DeviceClient {
    let mut client = c.connect(&format!("e2e control {name}")).expect("connect");
    client.set_timeout(Duration::from_secs(10));
    client
}

fn accel(s: &StatusReport) -> f64 {
    s.measured.map_or(0.0, |m| m.accel_mmps2 as f64 / 1000.0)
}

/// The scenarios share one controller (QEMU boots once) and run in order.
#[test]
fn sensing_and_control() {
    let _ = std::fs::remove_file(chladni_e2e::flash_path("control"));
    let controller = Controller::start("control");
    closed_loop_holds_the_target(&controller);
}

fn closed_loop_holds_the_target(controller: &Controller) {
    let mut client = client(controller, "hold");
    let run = client.drive(180_000, Level::Accel(20_000)).expect("closed-loop drive accepted");
    let seen = poll_until(&mut client, Duration::from_secs(30), |s| {
        s.run == run && s.elapsed_samples > 100_000
    });
    for s in seen.iter().filter(|s| s.run == run) {
        eprintln!(
            "{:>8} {:?} accel {:7.3} effort {:5} fault {:?}",
            s.elapsed_samples,
            s.state,
            accel(s),
            s.amplitude_q15,
            s.fault.map(|f| f.cause)
        );
    }
    let last = seen.last().unwrap();
    assert!(last.fault.is_none(), "{:?}", last.fault);
    assert!((accel(last) - 20.0).abs() < 0.4, "measured {}", accel(last));
    client.stop().expect("stop");
    poll_until(&mut client, Duration::from_secs(10), |s| s.state == DriveState::Idle);
    let _ = TestFault::Heal;
}
