//! The JSON shapes of the controller's answers: info, pings, status, telemetry, stored plans,
//! drive, runs and the `{run}` of stop and clear-fault, as `chladni device --json` prints them
//! and `chladni serve` answers them (keys in alphabetical order; documented in docs/device.md).
//! One home, so the CLI and the cell's HTTP API never disagree. The other outputs of the
//! controller commands live here too: the serial ports (`device list`), a sweep, a deleted
//! plan, the configuration (`device config`), the emulator's ready line (`chladni emulator`)
//! and a flash summary (`chladni flash`).

use chladni_shared::icd::link::{DeviceInfo, RunNumber, StatusReport, Telemetry};
use chladni_shared::icd::plan::Level;
use chladni_shared::icd::sense::Fault;
use chladni_shared::icd::store::{PlanSummary, StoreInfo, StoreState};
use chladni_shared::icd::units::{MilliDeg, MilliHz, MmPerS2, Q15, s_from_samples};
use serde::Serialize;
use serialport::{SerialPortInfo, SerialPortType};

use crate::config_keys::ConfigKey;
use crate::flash::{CheckedImage, FlashReport};
use crate::ports;
use crate::sweep::{Resonance, SweepSample};
use chladni_shared::icd::store::DeviceConfig;

/// The `status --json` object: the keys of protocol v1's status; `fault`, `plan`,
/// `remaining_ms`, `run` (v3); the sensing and control keys `accel_mps2`, `phase_deg`,
/// `effort`, `target_accel_mps2`, `warning`, `reset_cause` (v4; `fault` became an object).
#[derive(Debug, Clone, Serialize)]
pub struct StatusJson {
    /// Measured acceleration amplitude, m/s² (null without a measurement).
    pub accel_mps2: Option<f64>,
    pub amplitude: f64,
    /// The drive output (the control effort in closed loop), fraction of full scale.
    pub effort: f64,
    pub elapsed_ms: f64,
    pub fault: Option<FaultJson>,
    pub freq_hz: f64,
    /// The least refill slack since the controller started, µs (null before the first block).
    pub least_slack_us: Option<u32>,
    /// Measured phase against the drive, degrees (null without a measurement).
    pub phase_deg: Option<f64>,
    pub plan: Option<String>,
    pub remaining_ms: f64,
    pub reset_cause: &'static str,
    pub run: u32,
    /// The most stack the controller has used, bytes (0: not measured).
    pub stack_high_water: u32,
    pub state: &'static str,
    pub step: Option<u16>,
    /// The closed-loop target as ramped so far, m/s² (null in open loop or idle).
    pub target_accel_mps2: Option<f64>,
    pub underruns: u32,
    pub warning: bool,
}

/// The documented keys of `status --json` (docs/device.md), in the order printed: what
/// [`StatusJson`] serialises to (the CLI's and the end-to-end tests check it).
pub const STATUS_KEYS: [&str; 18] = [
    "accel_mps2",
    "amplitude",
    "effort",
    "elapsed_ms",
    "fault",
    "freq_hz",
    "least_slack_us",
    "phase_deg",
    "plan",
    "remaining_ms",
    "reset_cause",
    "run",
    "stack_high_water",
    "state",
    "step",
    "target_accel_mps2",
    "underruns",
    "warning",
];

/// A latched fault: `{"cause", "value", "unit", "at_s"}`.
#[derive(Debug, Clone, Serialize)]
pub struct FaultJson {
    pub at_s: f64,
    pub cause: &'static str,
    pub unit: &'static str,
    pub value: i32,
}

impl FaultJson {
    pub fn of(f: &Fault, sample_rate: u32) -> Self {
        FaultJson {
            at_s: s_from_samples(f.at_sample, sample_rate),
            cause: f.cause.name(),
            unit: f.cause.unit(),
            value: f.value,
        }
    }

    /// For people: cause, value with its unit, time, and the fix.
    pub fn text(&self) -> String {
        let value = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {} {}", self.value, self.unit)
        };
        format!(
            "{}{value} at {:.3} s (`chladni device clear-fault` clears it)",
            self.cause, self.at_s
        )
    }
}

impl From<&StatusReport> for StatusJson {
    fn from(s: &StatusReport) -> Self {
        StatusJson {
            accel_mps2: s.measured.map(|m| MmPerS2(m.accel_mmps2).to_mps2()),
            amplitude: Q15(s.amplitude_q15).to_fraction(),
            effort: Q15(s.amplitude_q15).to_fraction(),
            elapsed_ms: s.elapsed_ms(),
            fault: s.fault.map(|f| FaultJson::of(&f, s.sample_rate)),
            freq_hz: MilliHz(s.freq_mhz).to_hz(),
            least_slack_us: s.least_slack_us,
            phase_deg: s.measured.map(|m| MilliDeg(m.phase_mdeg).to_deg()),
            plan: s.plan.as_ref().map(|p| p.to_string()),
            remaining_ms: s.remaining_ms(),
            reset_cause: s.reset_cause.name(),
            run: s.run.0,
            stack_high_water: s.stack_high_water,
            state: s.state.name(),
            step: s.step,
            target_accel_mps2: s.level.and_then(Level::accel_mmps2).map(|a| MmPerS2(a).to_mps2()),
            underruns: s.underruns,
            warning: s.warning,
        }
    }
}

/// One line of `monitor --json`: the sample's number, how many are still to come, and the
/// status keys of `status --json`.
#[derive(Debug, Clone, Serialize)]
pub struct TelemetryJson {
    pub left: u32,
    pub seq: u32,
    #[serde(flatten)]
    pub status: StatusJson,
}

impl From<&Telemetry> for TelemetryJson {
    fn from(t: &Telemetry) -> Self {
        TelemetryJson { left: t.left, seq: t.seq, status: StatusJson::from(&t.status) }
    }
}

/// One stored plan, as `plans --json`, `upload --json` and `delete --json` print it.
#[derive(Debug, Clone, Serialize)]
pub struct PlanJson {
    pub bytes: u32,
    /// The plan CRC (CRC-32/ISO-HDLC), as a number; the tables print it as 8 hex digits.
    pub crc: u32,
    pub name: String,
    /// How many times the steps run (the plan's `repeat`).
    pub repeat: u16,
    pub slot: u8,
    pub steps: u16,
    pub total_ms: u64,
}

impl From<&PlanSummary> for PlanJson {
    fn from(p: &PlanSummary) -> Self {
        PlanJson {
            bytes: p.bytes,
            crc: p.crc,
            name: p.name.to_string(),
            repeat: p.repeat,
            slot: p.slot,
            steps: p.steps,
            total_ms: p.total_ms,
        }
    }
}

/// The `plans --json` object.
#[derive(Debug, Clone, Serialize)]
pub struct PlansJson {
    pub free_bytes: u32,
    pub plans: Vec<PlanJson>,
}

/// The `info --json` object.
#[derive(Debug, Clone, Serialize)]
pub struct InfoJson {
    pub board: &'static str,
    /// The build id as 8 hex digits.
    pub build_id: String,
    pub firmware_version: String,
    pub protocol_version: u16,
}

impl From<&DeviceInfo> for InfoJson {
    fn from(info: &DeviceInfo) -> Self {
        InfoJson {
            board: info.board.name(),
            build_id: format!("{:08x}", info.build_id),
            firmware_version: info.firmware_version.to_string(),
            protocol_version: info.protocol_version,
        }
    }
}

/// The plan store's state (`store --json`; `info` prints its text): `state` is `ready`,
/// `foreign` (holds data the controller did not write: `chladni device store --format`) or
/// `unavailable` (no flash).
#[derive(Debug, Clone, Serialize)]
pub struct StoreJson {
    pub area_bytes: u32,
    pub layout: u16,
    pub state: &'static str,
}

impl StoreJson {
    /// The state's name.
    pub fn state_name(state: StoreState) -> &'static str {
        match state {
            StoreState::Ready => "ready",
            StoreState::Foreign => "foreign",
            StoreState::Unavailable => "unavailable",
        }
    }

    /// The store line for people.
    pub fn text(&self) -> String {
        match self.state {
            "foreign" => format!(
                "foreign: {} KiB of flash hold data this firmware did not write; nothing is stored \
                 until `chladni device store --format` erases it",
                self.area_bytes / 1024
            ),
            "ready" => format!("ready ({} KiB, layout {})", self.area_bytes / 1024, self.layout),
            other => other.to_string(),
        }
    }
}

impl From<&StoreInfo> for StoreJson {
    fn from(info: &StoreInfo) -> Self {
        StoreJson {
            area_bytes: info.area_bytes,
            layout: info.layout,
            state: StoreJson::state_name(info.state),
        }
    }
}

/// The `ping --json` object: how many round trips, the longest and the mean (ms).
#[derive(Debug, Clone, Serialize)]
pub struct PingsJson {
    pub count: usize,
    pub max_ms: f64,
    pub mean_ms: f64,
}

impl PingsJson {
    /// Of round-trip times in ms.
    pub fn of(rtts: &[f64]) -> Self {
        let mean_ms = rtts.iter().sum::<f64>() / rtts.len().max(1) as f64;
        let max_ms = rtts.iter().cloned().fold(0.0, f64::max);
        PingsJson { count: rtts.len(), max_ms, mean_ms }
    }
}

/// The `drive --json` object: the frequency, the level (the one not given null) and the run
/// number the controller gave the command.
#[derive(Debug, Clone, Serialize)]
pub struct DriveJson {
    pub accel_mps2: Option<f64>,
    pub amplitude: Option<f64>,
    pub freq_hz: f64,
    pub run: u32,
}

impl DriveJson {
    /// Of the frequency (mHz) and level sent, and the answer's run number.
    pub fn of(freq_mhz: u32, level: Level, run: RunNumber) -> Self {
        let (amplitude, accel_mps2) = match level {
            Level::Drive(q15) => (Some(Q15(q15).to_fraction()), None),
            Level::Accel(mm) => (None, Some(MmPerS2(mm).to_mps2())),
        };
        DriveJson { accel_mps2, amplitude, freq_hz: MilliHz(freq_mhz).to_hz(), run: run.0 }
    }
}

/// The answer of stop and clear-fault (`chladni device stop|clear-fault --json`, `POST
/// /api/stop|clear-fault`): the controller's run number of the command.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct RunNumberJson {
    pub run: u32,
}

/// The `run`/`run-file --json` object.
#[derive(Debug, Clone, Serialize)]
pub struct RunJson {
    /// `started` without `--wait`; else how the run ended (`RunOutcome::name`).
    pub outcome: &'static str,
    /// The plan's name, when known (run by name, `run-file`).
    pub plan: Option<String>,
    pub run: u32,
    /// The plan's slot, when known (run by slot, `run-file`).
    pub slot: Option<u8>,
    /// The last status seen (with `--wait`).
    pub status: Option<StatusJson>,
}

/// The `delete --json` object: the plan removed.
#[derive(Debug, Clone, Serialize)]
pub struct DeletedJson {
    pub deleted: PlanJson,
}

/// The `config get|set --json` object: each key asked for with its value in user units
/// (keys in alphabetical order, as printed).
pub fn config_json(
    config: &DeviceConfig,
    keys: &[ConfigKey],
) -> serde_json::Map<String, serde_json::Value> {
    keys.iter().map(|k| (k.name().to_string(), k.get(config).to_json())).collect()
}

/// The `sweep --json` object: every point measured and the resonances found.
#[derive(Debug, Serialize)]
pub struct SweepJson<'a> {
    pub points: &'a [SweepSample],
    pub resonances: &'a [Resonance],
}

/// The ready line of `chladni emulator --json`: where the link listens, QEMU's process id, the
/// file holding the controller's flash and whether it outlives the emulator; with `--mips`,
/// the emulated speed and its `-icount` shift.
#[derive(Debug, Clone, Serialize)]
pub struct EmulatorJson {
    pub flash_file: String,
    /// `false`: the flash file is the emulator's own, removed when it stops.
    pub flash_kept: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub icount_shift: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mips: Option<f64>,
    pub pid: u32,
    pub port: String,
}

/// The `chladni flash --json` summary: what was written, where, and how long it took.
#[derive(Debug, Clone, Serialize)]
pub struct FlashJson {
    pub board: String,
    pub bytes: u64,
    pub chip: String,
    /// The ELF file's path.
    pub elf: String,
    pub probe: String,
    pub seconds: f64,
    /// Loadable segments written.
    pub segments: usize,
    pub verified: bool,
}

impl FlashJson {
    /// Of the image, the chip and probe named, and the flash's report.
    pub fn of(image: &CheckedImage, chip: &str, probe: &str, report: &FlashReport) -> Self {
        FlashJson {
            board: image.board.clone(),
            bytes: report.bytes,
            chip: chip.to_string(),
            elf: image.path.display().to_string(),
            probe: probe.to_string(),
            seconds: report.duration.as_secs_f64(),
            segments: image.segments.len(),
            verified: report.verified,
        }
    }
}

/// The `list --json` object: the serial ports.
#[derive(Debug, Clone, Serialize)]
pub struct PortsJson {
    pub ports: Vec<PortJson>,
}

/// One port as `list --json` prints it.
#[derive(Debug, Clone, Serialize)]
pub struct PortJson {
    pub kind: &'static str,
    pub manufacturer: Option<String>,
    pub name: String,
    /// USB product id, 4 hex digits.
    pub pid: Option<String>,
    pub product: Option<String>,
    /// `controller` (the link), `debug_console` (the ST-LINK VCP), or null.
    pub role: Option<&'static str>,
    pub serial_number: Option<String>,
    /// USB vendor id, 4 hex digits.
    pub vid: Option<String>,
}

impl PortJson {
    /// A port of kind `kind` with no USB details.
    pub fn plain(name: &str, kind: &'static str) -> Self {
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
    pub fn usb(name: &str, vid: u16, pid: u16, strings: [Option<String>; 3]) -> Self {
        let [manufacturer, product, serial_number] = strings;
        PortJson {
            vid: Some(format!("{vid:04x}")),
            pid: Some(format!("{pid:04x}")),
            role: ports::role(vid, pid),
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

#[cfg(test)]
mod tests {
    use super::*;
    use serialport::SerialPortType;

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
