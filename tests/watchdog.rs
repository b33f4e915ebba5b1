//! Watchdog in QEMU: the firmware's `watchdog_reset` image feeds the board's simulated
//! watchdog through the real check-in supervisor while the drive plays, then lets the drive's
//! check-ins stop. The watchdog must park the output, record the cause and reset the machine
//! (SYSRESETREQ, which QEMU turns into a reset that keeps RAM); the second boot must read the
//! reset cause `Watchdog` and come up idle at mid-scale (exit code 0).

use std::process::Command;

use chladni_e2e::root;

#[test]
fn a_task_that_stops_checking_in_gets_the_controller_reset_and_it_comes_back_idle() {
    let out = Command::new(root().join("scripts/firmware.sh"))
        .args(["build-bin", "qemu", "watchdog_reset"])
        .current_dir(root())
        .output()
        .expect("run scripts/firmware.sh build-bin qemu watchdog_reset");
    assert!(
        out.status.success(),
        "building the watchdog_reset image failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let image = String::from_utf8(out.stdout).unwrap().trim().to_string();
    let out = Command::new(root().join("scripts/qemu-run.sh"))
        .arg(&image)
        .env("QEMU_TIMEOUT", "120")
        .current_dir(root())
        .output()
        .expect("run scripts/qemu-run.sh");
    let log =
        format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    // In this order: a cold boot, fed while all checked in, the hang, the reset, the warm boot.
    let lines = [
        "watchdog_reset: boot, reset cause PowerOn",
        "the drive stops checking in",
        "watchdog: not fed, tasks missing 010",
        "watchdog: not fed for 1000 ms: reset",
        "watchdog_reset: boot, reset cause Watchdog",
        "after the watchdog reset: state Idle, amplitude 0, output code 2048",
    ];
    let mut at = 0;
    for line in lines {
        let found =
            log[at..].find(line).unwrap_or_else(|| panic!("no '{line}' (in order):\n{log}"));
        at += found + line.len();
    }
    assert_eq!(
        out.status.code(),
        Some(0),
        "exit code (0 idle after a watchdog reset; 11 not idle, 12/13 other cause, 3 no reset):\n{log}"
    );
    assert_eq!(log.matches("reset cause PowerOn").count(), 1, "booted cold more than once:\n{log}");
}
