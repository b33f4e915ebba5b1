//! `chladni device list`: the serial ports of this machine, with USB vendor:product ids.
//!
//! The controller's USB CDC port has the ids in [`USB_VID`]:[`USB_PID`]; the board's ST-LINK
//! virtual COM port (0483:374B, the firmware's USART1) is its debug console, not the link.

use std::process::ExitCode;

use chladni_shared::icd::link::{USB_PID, USB_VID};
use serde::Serialize;
use serialport::{SerialPortInfo, SerialPortType};

use super::render::print_json;

/// USB ids of the ST-LINK/V2-1 virtual COM port of the B-L475E-IOT01A.
pub const STLINK_VCP: (u16, u16) = (0x0483, 0x374b);

/// What a port is to Chladni, from its USB ids.
pub fn role(vid: u16, pid: u16) -> Option<&'static str> {
    match (vid, pid) {
        (USB_VID, USB_PID) => Some("controller"),
        STLINK_VCP => Some("debug_console"),
        _ => None,
    }
}

/// One port as `list --json` prints it.
#[derive(Debug, Serialize)]
pub struct PortJson {
    kind: &'static str,
    manufacturer: Option<String>,
    name: String,
    /// USB product id, 4 hex digits.
    pid: Option<String>,
    product: Option<String>,
    /// `controller` (the link), `debug_console` (the ST-LINK VCP), or null.
    role: Option<&'static str>,
    serial_number: Option<String>,
    /// USB vendor id, 4 hex digits.
    vid: Option<String>,
}

impl PortJson {
    /// A port of kind `kind` with no USB details.
    fn plain(name: &str, kind: &'static str) -> Self {
        PortJson {
            kind,
            manufacturer: None,
            name: name.to_string(),
            pid: None,
            product: None,
            role: None,
            serial_number: None,
            vid: None,
        }
    }

    /// A USB port: ids, their role, and the strings the device gives.
    fn usb(name: &str, vid: u16, pid: u16, strings: [Option<String>; 3]) -> Self {
        let [manufacturer, product, serial_number] = strings;
        PortJson {
            vid: Some(format!("{vid:04x}")),
            pid: Some(format!("{pid:04x}")),
            role: role(vid, pid),
            manufacturer,
            product,
            serial_number,
            ..Self::plain(name, "usb")
        }
    }
}

impl From<&SerialPortInfo> for PortJson {
    fn from(p: &SerialPortInfo) -> Self {
        let name = p.port_name.as_str();
        match &p.port_type {
            SerialPortType::UsbPort(usb) => {
                let strings =
                    [usb.manufacturer.clone(), usb.product.clone(), usb.serial_number.clone()];
                PortJson::usb(name, usb.vid, usb.pid, strings)
            }
            SerialPortType::PciPort => PortJson::plain(name, "pci"),
            SerialPortType::BluetoothPort => PortJson::plain(name, "bluetooth"),
            SerialPortType::Unknown => PortJson::plain(name, "unknown"),
        }
    }
}

/// The serial ports, none where the OS offers no list.
fn available() -> anyhow::Result<Vec<SerialPortInfo>> {
    // Without libudev, serialport scans /sys/class/tty and panics if it is missing
    // (containers): no such directory means no serial ports to list.
    if cfg!(target_os = "linux") && !std::path::Path::new("/sys/class/tty").is_dir() {
        return Ok(Vec::new());
    }
    Ok(serialport::available_ports()?)
}

/// `list`.
pub fn list(json: bool) -> anyhow::Result<ExitCode> {
    let ports: Vec<PortJson> = available()?.iter().map(PortJson::from).collect();
    if json {
        print_json(&serde_json::json!({ "ports": ports }))?;
        return Ok(ExitCode::SUCCESS);
    }
    if ports.is_empty() {
        println!(
            "no serial ports found (the emulator's link is tcp://…, printed by `chladni emulator`)"
        );
    }
    for p in &ports {
        let ids = match (&p.vid, &p.pid) {
            (Some(v), Some(d)) => format!("{v}:{d}"),
            _ => "-".to_string(),
        };
        let product = p.product.as_deref().unwrap_or("");
        let note = match p.role {
            Some("controller") => format!("  <- controller: --port {}", p.name),
            Some(_) => "  <- ST-LINK console (firmware log; not the link)".to_string(),
            None => String::new(),
        };
        println!("{:<20} {:<9} {:<9} {product}{note}", p.name, p.kind, ids);
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn usb(name: &str, vid: u16, pid: u16) -> PortJson {
        let strings = [Some("Chladni".into()), Some("Chladni feeder controller".into()), None];
        PortJson::usb(name, vid, pid, strings)
    }

    #[test]
    fn ours_and_the_stlink_console_are_marked() {
        let ours = serde_json::to_value(usb("/dev/ttyACM0", 0x1209, 0x0001)).unwrap();
        assert_eq!(ours["role"], "controller");
        assert_eq!((ours["vid"].as_str(), ours["pid"].as_str()), (Some("1209"), Some("0001")));
        assert_eq!(
            (ours["kind"].as_str(), ours["name"].as_str()),
            (Some("usb"), Some("/dev/ttyACM0"))
        );
        assert_eq!(ours.as_object().unwrap().len(), 8);
        assert_eq!(usb("/dev/ttyACM1", 0x0483, 0x374b).role, Some("debug_console"));
        assert_eq!(usb("/dev/ttyUSB0", 0x0403, 0x6001).role, None);
        let pci = PortJson::from(&SerialPortInfo {
            port_name: "/dev/ttyS0".into(),
            port_type: SerialPortType::PciPort,
        });
        assert_eq!((pci.kind, pci.vid), ("pci", None));
    }
}
