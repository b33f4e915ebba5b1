//! Fail-safe in QEMU: the firmware's `failsafe` image drives the simulated DAC through the real
//! drive task, then panics, takes a HardFault or overflows its stack; the board's handlers
//! must park the output at mid-scale before anything else, report the parked code and end
//! QEMU with the exit code that says "fault, output parked" (101 panic, 102 HardFault; 103
//! would mean NOT parked). After a stack overflow the watchdog must reset the machine and the
//! second boot read the cause `Watchdog` and find the drive idle (exit 0).

use std::process::Command;
use std::sync::OnceLock;

use chladni_e2e::root;
use chladni_shared::drive::dds::DAC_MID;

/// Exit codes of the QEMU board's fault handlers (firmware/src/board/qemu/failsafe.rs).
const EXIT_PANIC_PARKED: i32 = 101;
const EXIT_HARD_FAULT_PARKED: i32 = 102;

/// Builds the image once per test binary; returns its path.
fn image() -> &'static str {
    static IMAGE: OnceLock<String> = OnceLock::new();
    IMAGE.get_or_init(|| {
        let out = Command::new(root().join("scripts/firmware.sh"))
            .args(["build-bin", "qemu", "failsafe"])
            .current_dir(root())
            .output()
            .expect("run scripts/firmware.sh build-bin qemu failsafe");
        assert!(
            out.status.success(),
            "building the failsafe image failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap().trim().to_string()
    })
}

/// Boots the image with `crash=<crash>`; returns QEMU's exit code and the decoded log.
fn run(crash: &str) -> (Option<i32>, String) {
    let out = Command::new(root().join("scripts/qemu-run.sh"))
        .arg(image())
        .env("QEMU_TIMEOUT", "120")
        .env("QEMU_EXTRA", format!("-semihosting-config arg=crash={crash}"))
        .current_dir(root())
        .output()
        .expect("run scripts/qemu-run.sh");
    let log =
        format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.code(), log)
}

/// Checks that `lines` appear in `log` in this order.
fn assert_in_order(log: &str, lines: &[&str]) {
    let mut at = 0;
    for line in lines {
        let found =
            log[at..].find(line).unwrap_or_else(|| panic!("no '{line}' (in order):\n{log}"));
        at += found + line.len();
    }
}

/// The number after `prefix` on the first log line that has it.
fn code_after(log: &str, prefix: &str) -> Option<u16> {
    let rest = &log[log.find(prefix)? + prefix.len()..];
    rest.split(|c: char| !c.is_ascii_digit()).next()?.parse().ok()
}

/// Checks one crash: driven before, the fault logged, parked at mid-scale after, exit code.
fn assert_parks(crash: &str, fault_line: &str, exit_code: i32) {
    let (code, log) = run(crash);
    let before = code_after(&log, "failsafe: driving, output at code ")
        .unwrap_or_else(|| panic!("the drive never ran before the crash:\n{log}"));
    assert!(before.abs_diff(DAC_MID) >= 256, "output {before} was not driven before the crash");
    assert!(log.contains(fault_line), "no '{fault_line}' in the log:\n{log}");
    assert_eq!(code, Some(exit_code), "exit code (101/102 parked, 103 NOT parked):\n{log}");
    assert_eq!(
        code_after(&log, "fault: output parked at code "),
        Some(DAC_MID),
        "the handler did not report the output parked at mid-scale:\n{log}"
    );
    println!("crash={crash}: output {before} -> parked at {DAC_MID}, exit code {exit_code}");
}

#[test]
fn a_panic_parks_the_output_at_mid_scale() {
    assert_parks("panic", "panic: panicked at", EXIT_PANIC_PARKED);
}

#[test]
fn a_hard_fault_parks_the_output_at_mid_scale() {
    assert_parks("hardfault", "hard fault at pc", EXIT_HARD_FAULT_PARKED);
}

/// Real recursion runs the stack off the bottom of SRAM2: the core cannot push its exception
/// frame, and a HardFault handler that used that stack would lock the core up (QEMU:
/// "Lockup: can't escalate"), the output still driven. The entry code moves to the fault
/// stack first; the handler parks, the watchdog resets, the next boot reads `Watchdog`.
#[test]
fn a_stack_overflow_parks_the_output_and_the_watchdog_resets() {
    let (code, log) = run("stack-overflow");
    let before = code_after(&log, "failsafe: driving, output at code ")
        .unwrap_or_else(|| panic!("the drive never ran before the crash:\n{log}"));
    assert!(before.abs_diff(DAC_MID) >= 256, "output {before} was not driven before the crash");
    assert!(!log.contains("Lockup"), "the core locked up in the fault handler:\n{log}");
    assert_in_order(
        &log,
        &[
            "failsafe: boot, reset cause PowerOn",
            "crash by StackOverflow",
            "hard fault: stack overflow",
            "fault: output parked at code 2048",
            "watchdog: not fed for 1000 ms: reset",
            "failsafe: boot, reset cause Watchdog",
            "after the reset: state Idle, amplitude 0, output code 2048",
        ],
    );
    let used = code_after(&log, "failsafe: the fault handler used ")
        .unwrap_or_else(|| panic!("no fault stack figure:\n{log}"));
    // The handler must leave a margin on its own stack (2048 B): a deeper path would
    // overflow it into the statics below.
    assert!((1..=1536).contains(&used), "the fault handler used {used} B of 2048:\n{log}");
    assert_eq!(
        code,
        Some(0),
        "exit code (0 idle after the reset; 11 not idle, 4 no overflow, 102/103 no reset):\n{log}"
    );
    println!(
        "crash=stack-overflow: output {before} -> parked at {DAC_MID}, reset cause Watchdog, \
         fault stack {used} B of 2048"
    );
}
