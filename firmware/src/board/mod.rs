//! Board support: the only place with registers and `unsafe`.
//!
//! Each board exposes the same surface to `main`: `init() -> Board`, a `Link` type for the host
//! link (an `embedded_io_async` byte stream) and the board's [`chladni_shared::icd::link::Board`] id.

#[cfg(feature = "board-qemu")]
pub mod qemu;
#[cfg(feature = "board-qemu")]
pub use qemu::*;

#[cfg(feature = "board-stm32l475")]
pub mod stm32l475;
#[cfg(feature = "board-stm32l475")]
pub use stm32l475::*;

/// Length of [`CHLADNI_BOARD`].
pub const BOARD_TAG_LEN: usize = 16;

/// The board this image was built for, as a NUL-padded name in a symbol of its own, so host
/// tools can tell the images apart from the ELF alone: `chladni flash` refuses a QEMU image,
/// and the QEMU runner refuses a real-board image.
#[used]
#[unsafe(no_mangle)]
pub static CHLADNI_BOARD: [u8; BOARD_TAG_LEN] = board_tag(BOARD.name());

/// `name` as NUL-padded bytes (a compile error if it does not fit).
const fn board_tag(name: &str) -> [u8; BOARD_TAG_LEN] {
    let bytes = name.as_bytes();
    assert!(bytes.len() < BOARD_TAG_LEN, "board name too long for CHLADNI_BOARD");
    let mut tag = [0u8; BOARD_TAG_LEN];
    let mut i = 0;
    while i < bytes.len() {
        tag[i] = bytes[i];
        i += 1;
    }
    tag
}

pub mod fault_entry;
pub mod stack;
