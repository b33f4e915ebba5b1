//! How long the STM32L475's flash is busy, the one home of these figures: the mock flash
//! advances its simulated clock by them, the QEMU board's file flash waits them out, so the
//! tests see the chip's timing rather than a flash that is never busy.
//!
//! STM32L475xx datasheet (DS10969), "Flash memory characteristics" (RM0351 gives no times
//! and refers to it): t_prog, 64-bit (double word) programming time, 81.69 µs typical,
//! 90.76 µs maximum; t_ERASE, page (2 KB) erase time, 22.02 ms typical, 24.47 ms maximum.
//! The models use the typical figures; the watchdog margin (docs/store.md) is argued on the
//! maximum ones.

/// Programming one double word (8 bytes), µs (t_prog, typical).
pub const PROGRAM_DOUBLE_WORD_US: u64 = 82;
/// Erasing one 2 KiB page, µs (t_ERASE, typical).
pub const ERASE_PAGE_US: u64 = 22_020;
/// Erasing one page at the datasheet's maximum, µs (t_ERASE, maximum).
pub const ERASE_PAGE_MAX_US: u64 = 24_470;

/// Time to program `bytes` (whole double words), µs.
pub const fn program_us(bytes: usize) -> u64 {
    (bytes as u64).div_ceil(8) * PROGRAM_DOUBLE_WORD_US
}

/// Time to erase `pages` pages, µs.
pub const fn erase_us(pages: usize) -> u64 {
    pages as u64 * ERASE_PAGE_US
}
