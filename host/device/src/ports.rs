//! The serial ports of this machine and what each is to Chladni, from its USB ids
//! (`chladni device list`; the JSON shape is [`crate::json::PortJson`]).
//!
//! The controller's USB CDC port has the ids in [`USB_VID`]:[`USB_PID`]; the board's ST-LINK
//! virtual COM port (0483:374B, the firmware's USART1) is its debug console, not the link.

use chladni_shared::icd::link::{USB_PID, USB_VID};
use serialport::SerialPortInfo;

/// USB ids of the ST-LINK/V2-1 virtual COM port of the B-L475E-IOT01A.
pub(crate) const STLINK_VCP: (u16, u16) = (0x0483, 0x374b);

/// What a port is to Chladni, from its USB ids.
pub fn role(vid: u16, pid: u16) -> Option<&'static str> {
    match (vid, pid) {
        (USB_VID, USB_PID) => Some("controller"),
        STLINK_VCP => Some("debug_console"),
        _ => None,
    }
}

/// The serial ports, none where the OS offers no list.
pub fn available() -> Result<Vec<SerialPortInfo>, serialport::Error> {
    // Without libudev, serialport scans /sys/class/tty and panics if it is missing
    // (containers): no such directory means no serial ports to list.
    if cfg!(target_os = "linux") && !std::path::Path::new("/sys/class/tty").is_dir() {
        return Ok(Vec::new());
    }
    serialport::available_ports()
}
