//! Board support: the only place with registers and `unsafe`.
//!
//! Each board exposes the same surface to `main`: `init() -> Board`, a `Link` type for the host
//! link (an `embedded_io_async` byte stream) and the board's [`chladni_shared::link::Board`] id.

#[cfg(feature = "board-qemu")]
pub mod qemu;
#[cfg(feature = "board-qemu")]
pub use qemu::*;

#[cfg(feature = "board-stm32l475")]
pub mod stm32l475;
#[cfg(feature = "board-stm32l475")]
pub use stm32l475::*;
