//! # chladni-firmware
//!
//! The controller of the Chladni parts feeder: a thin `no_std` layer that moves data between
//! peripherals and `chladni-shared`. One application ([`app`]), two boards ([`board`]):
//! - `board-stm32l475`: the B-L475E-IOT01A, through embassy-stm32.
//! - `board-qemu`: the same application on `qemu-system-arm -M b-l475e-iot01a`, with small
//!   drivers of its own for what QEMU models (SysTick, USART1) and fakes for what it doesn't.
//!
//! Unsafe code is allowed only in [`board`], where registers are touched.
//!
//! Like quartiq/stabilizer, the hardware stays out of host builds: `board` (and the image in
//! `main.rs`) exist only for `target_os = "none"`, while [`app`] builds and unit-tests on the
//! host too (`cargo test -p chladni-firmware --lib`), its defmt logs in defmt's host mode there.
#![no_std]

#[cfg(all(target_os = "none", not(any(feature = "board-qemu", feature = "board-stm32l475"))))]
compile_error!("select a board: --features board-qemu or --features board-stm32l475");
#[cfg(all(feature = "board-qemu", feature = "board-stm32l475"))]
compile_error!("select exactly one board feature");

#[cfg(all(any(test, feature = "mock-flash"), not(target_os = "none")))]
extern crate std;

pub mod app;
#[cfg(target_os = "none")]
pub mod board;

/// Firmware version, from the crate's manifest.
pub const FIRMWARE_VERSION: &str = env!("CARGO_PKG_VERSION");

/// First 32 bits of the git commit this image was built from (0 if unknown).
pub const BUILD_ID: u32 = match u32::from_str_radix(env!("CHLADNI_BUILD_ID"), 10) {
    Ok(id) => id,
    Err(_) => 0,
};
