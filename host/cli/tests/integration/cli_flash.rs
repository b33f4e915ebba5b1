//! `chladni flash` end to end, up to the probe: every check that runs before a probe is touched,
//! and the no-probe path (skipped, without flashing, if a probe is attached).

use std::path::PathBuf;

use chladni_shared::icd::link::Board;
use support::elf::{EM_ARM, Segment, elf};

use crate::support;
use support::cli::{chladni, tmp, write_tmp};

/// Runs `chladni flash ARGS` and checks its exit code; returns stderr.
fn flash_fails(args: &[&str], code: i32) -> String {
    let mut all = vec!["flash"];
    all.extend_from_slice(args);
    let out = chladni(&all);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(code), "{all:?}: {stderr}");
    assert!(out.stdout.is_empty(), "{all:?} printed {}", String::from_utf8_lossy(&out.stdout));
    stderr
}

fn board_elf(name: &str) -> String {
    write_tmp("flash", name, elf(EM_ARM, Some("stm32l475"), &[Segment::at(0x0800_0000, 256)]))
}

/// Builds a firmware image, one board at a time: scripts/firmware.sh links both boards to the
/// same path and copies it after cargo releases its lock, so two concurrent builds can swap the
/// images.
fn build(board: Board) -> PathBuf {
    static BUILD: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    chladni_device::firmware::build(board).unwrap()
}

/// Whether a probe is attached (then the tests that would reach it must not run).
fn probe_attached() -> bool {
    let probes = chladni_device::flash::list_probes().descs;
    if !probes.is_empty() {
        eprintln!("skipping: a debug probe is attached ({probes:?}) and this test must not flash");
    }
    !probes.is_empty()
}

#[test]
fn a_missing_elf_is_bad_input() {
    let path = tmp("flash", "no-such.elf").display().to_string();
    let err = flash_fails(&["--elf", &path], 2);
    assert!(err.contains(&format!("firmware image {path} does not exist")), "{err}");
}

#[test]
fn a_file_that_is_not_an_elf_is_bad_input() {
    let path = write_tmp("flash", "firmware.bin", [0x00, 0x80, 0x01, 0x20, 0xc1, 0x01, 0x00, 0x08]);
    let err = flash_fails(&["--elf", &path], 2);
    assert!(err.contains(&format!("{path} is not an ELF file")), "{err}");
}

#[test]
fn an_untagged_arm_elf_is_bad_input() {
    let path =
        write_tmp("flash", "untagged.elf", elf(EM_ARM, None, &[Segment::at(0x0800_0000, 64)]));
    let err = flash_fails(&["--elf", &path], 2);
    assert!(err.contains("has no CHLADNI_BOARD symbol"), "{err}");
}

#[test]
fn a_qemu_image_is_refused_with_a_pointer_to_the_emulator() {
    let qemu = build(Board::Qemu);
    let path = qemu.display().to_string();
    let err = flash_fails(&["--elf", &path], 2);
    assert!(err.contains("was built for the QEMU board"), "{err}");
    assert!(err.contains(&format!("chladni emulator --firmware {path}")), "{err}");
}

#[test]
fn an_image_outside_flash_is_bad_input() {
    let in_ram = [Segment::at(0x0800_0000, 64), Segment::at(0x2000_0000, 64)];
    let path = write_tmp("flash", "ram.elf", elf(EM_ARM, Some("stm32l475"), &in_ram));
    let err = flash_fails(&["--elf", &path], 2);
    assert!(
        err.contains("0x20000000..0x20000040 lies outside FLASH 0x08000000..0x08080000"),
        "{err}"
    );
}

#[test]
fn an_unknown_chip_is_bad_input_with_close_names() {
    let path = board_elf("chip.elf");
    let err = flash_fails(&["--elf", &path, "--chip", "STM32L475ZZ"], 2);
    assert!(err.contains("chip 'STM32L475ZZ' is unknown to probe-rs"), "{err}");
    assert!(err.contains("close names:") && err.contains("STM32L475VGTx"), "{err}");
}

#[test]
fn a_malformed_probe_selector_is_bad_input() {
    let path = board_elf("selector.elf");
    for bad in ["stlink", "0483", "0483:zz", "0483:374b:"] {
        let err = flash_fails(&["--elf", &path, "--probe", bad], 2);
        assert!(err.contains(&format!("'{bad}' is not a probe selector")), "{err}");
    }
}

#[test]
fn without_a_probe_the_error_says_what_was_looked_for_and_what_to_check() {
    if probe_attached() {
        return;
    }
    let path = board_elf("noprobe.elf");
    let err = flash_fails(&["--elf", &path], 1);
    assert!(
        err.starts_with("error: no debug probe found (any CMSIS-DAP, ST-Link or J-Link USB probe)"),
        "{err}"
    );
    for needle in
        ["USB cable", "ST-LINK jumpers", "69-probe-rs.rules in /etc/udev/rules.d/", "plugdev"]
    {
        assert!(err.contains(needle), "{needle} missing: {err}");
    }
    let err = flash_fails(&["--elf", &path, "--probe", "0483:374b:066D"], 1);
    assert!(err.contains("no debug probe found (--probe 0483:374b:066D)"), "{err}");
}

#[test]
fn the_real_board_image_passes_the_checks() {
    let image = build(Board::Stm32l475);
    let flash = chladni_device::flash::flash_region().unwrap();
    let checked = chladni_device::flash::check_image(&image, &flash).unwrap();
    assert_eq!(checked.board, "stm32l475");
    assert!(checked.bytes() > 1024, "{checked:?}");
    assert!(checked.segments.iter().any(|&(addr, _)| addr == flash.origin), "{checked:?}");
    if probe_attached() {
        return;
    }
    let err = flash_fails(&["--elf", &image.display().to_string()], 1);
    assert!(err.contains("no debug probe found"), "{err}");
}
