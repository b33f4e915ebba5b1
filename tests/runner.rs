//! The cargo runner for the firmware target (`scripts/qemu-run.sh`, named in
//! `.cargo/config.toml`) serves every image built for thumbv7em-none-eabihf, so it must refuse
//! what QEMU cannot run instead of booting it into a hang: a real-board image, or an ELF that
//! is no Chladni image at all.

use std::process::{Command, Output};

use chladni_device::firmware;
use chladni_e2e::root;
use chladni_shared::icd::link::Board;

fn run(elf: &str) -> Output {
    Command::new(root().join("scripts/qemu-run.sh"))
        .arg(elf)
        .env("QEMU_TIMEOUT", "20")
        .current_dir(root())
        .output()
        .expect("run scripts/qemu-run.sh")
}

#[test]
fn the_runner_refuses_a_real_board_image_and_says_what_to_run() {
    let elf = firmware::build(Board::Stm32l475).expect("build the stm32l475 image");
    let out = run(elf.to_str().unwrap());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "exit code; stderr:\n{stderr}");
    assert!(stderr.contains("is a 'stm32l475' image, not a QEMU-board image"), "{stderr}");
    assert!(stderr.contains("scripts/firmware.sh run stm32l475"), "{stderr}");
    assert!(stderr.contains("chladni flash --elf"), "{stderr}");
}

#[test]
fn the_runner_refuses_an_elf_that_is_no_chladni_image() {
    // Any ELF will do: this test's own executable has no CHLADNI_BOARD symbol.
    let me = std::env::current_exe().unwrap();
    let out = run(me.to_str().unwrap());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "exit code; stderr:\n{stderr}");
    assert!(stderr.contains("no CHLADNI_BOARD symbol"), "{stderr}");
}
