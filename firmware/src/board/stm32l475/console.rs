//! The debug console: USART1 on the ST-LINK virtual COM port (PB6 TX), 115200 8N1, transmit
//! only. The host link moved to USB ([`super::usb`]); this port now only tells a person at a
//! terminal what is running and where the link is. defmt logs go over RTT, as before.

use core::fmt::Write as _;

use embassy_stm32::Peri;
use embassy_stm32::mode::Blocking;
use embassy_stm32::peripherals::{PB6, USART1};
use embassy_stm32::usart::{self, UartTx};
use static_cell::StaticCell;

use chladni_shared::icd::link::{USB_PID, USB_VID};

/// Debug console baud rate (what the ST-LINK virtual COM port is usually opened at).
pub const BAUD: u32 = 115_200;

/// Brings USART1 up and writes the boot banner, blocking (about 13 ms for its ~150 bytes at
/// 115200 baud: call it before the drive starts, never from a running task). The port stays
/// configured for ever (a dropped `UartTx` would disable USART1 and let PB6 float).
pub fn start(usart1: Peri<'static, USART1>, tx: Peri<'static, PB6>) {
    static CONSOLE: StaticCell<UartTx<'static, Blocking>> = StaticCell::new();
    let mut config = usart::Config::default();
    config.baudrate = BAUD;
    let console = match UartTx::new_blocking(usart1, tx, config) {
        Ok(console) => CONSOLE.init(console),
        Err(e) => {
            defmt::warn!("console: USART1 config refused: {}", e);
            return;
        }
    };
    let banner = banner();
    if console.blocking_write(banner.as_bytes()).and_then(|()| console.blocking_flush()).is_err() {
        defmt::warn!("console: banner not written");
    }
}

/// The boot banner: firmware version, board, build id, and where the host link is.
fn banner() -> heapless::String<192> {
    let mut text = heapless::String::new();
    // The text is well under the capacity, so this cannot fail; if it ever did, the banner
    // would only be cut short.
    let _ = write!(
        text,
        "\r\nchladni firmware {} ({}) build {:08x}\r\n\
         host link on USB CDC-ACM ({:04x}:{:04x}, serial {}); this port is the debug console\r\n",
        crate::FIRMWARE_VERSION,
        super::BOARD.name(),
        crate::BUILD_ID,
        USB_VID,
        USB_PID,
        embassy_stm32::uid::uid_hex(),
    );
    text
}
