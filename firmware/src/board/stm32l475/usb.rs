//! The host link on the B-L475E-IOT01A: a USB CDC-ACM device on USB OTG FS (PA11 DM, PA12 DP:
//! the board's USB OTG connector, not the ST-LINK one), built with embassy-usb.
//!
//! Two halves:
//! - [`UsbLink`] is the byte stream the app reads and writes (`embedded_io_async::Read` and
//!   `Write`) over the CDC data interface's two bulk endpoints;
//! - [`UsbDevice`] is the device side of the USB protocol (enumeration, control requests,
//!   suspend/resume), which must be polled all the time: [`run`] in a task of its own.
//!
//! Stream rules, and why:
//! - **Reads** return the bytes of one received packet at a time; a caller with a small buffer
//!   gets the rest of the packet on its next reads. Before the host has configured the device
//!   (cable out, not enumerated yet) a read *waits* for that instead of failing, so an idle link
//!   costs nothing. A read that was waiting when the bus went away (unplug, bus reset, host
//!   deconfigured the device) returns [`UsbLinkError::Disconnected`] once, so the app can drop a
//!   half-received frame; the next read waits again. Zero-length packets from the host are not
//!   an end of stream (there is none) and are skipped.
//! - **Writes** take the whole buffer, in packets of at most [`PACKET_SIZE`] bytes. A write that
//!   ends with a full packet is followed by a zero-length packet: a bulk IN transfer ends only
//!   at a short packet, so without it the host's USB stack keeps those bytes (the end of a
//!   reply) until the next write comes, perhaps never (embassy-usb's CDC class never sends a
//!   ZLP itself). Each packet waits until the host has taken the one before it; when no program
//!   has the port open, hosts stop asking for data and a write waits until one does (like a UART
//!   with flow control); it does not time out here: the app's link gives each frame
//!   `app::link::WRITE_LIMIT` and drops it after (docs/firmware.md, "A host that stops
//!   reading"). Writing before the device is configured fails at once with
//!   [`UsbLinkError::Disconnected`].
//! - **DTR** ([`UsbLink::host_port_open`]) is reported, never used to gate data: Linux and macOS
//!   raise it when a program opens the port, but the `serialport` crate leaves it low on
//!   Windows, so a gate would lock Windows hosts out. Frames already survive a client change:
//!   every frame starts with a delimiter (`chladni_shared::icd::frame`).

use embassy_stm32::peripherals::{PA11, PA12, USB_OTG_FS};
use embassy_stm32::{Peri, usb};
use embassy_usb::class::cdc_acm::{self, CdcAcmClass, Receiver, Sender};
use embassy_usb::driver::EndpointError;
use static_cell::StaticCell;

use chladni_shared::icd::link::{USB_PID, USB_PRODUCT, USB_VID};

use super::Irqs;

/// Largest packet of the CDC data endpoints (full speed bulk maximum), bytes.
pub const PACKET_SIZE: usize = 64;

/// Packet buffer of the OTG driver: one [`PACKET_SIZE`] slot per OUT endpoint, i.e. the
/// control endpoint 0 and the CDC data OUT endpoint (the driver refuses to allocate an OUT
/// endpoint that does not fit, and embassy-usb then panics at boot).
const EP_OUT_BUFFER: usize = 2 * PACKET_SIZE;
/// Room for the configuration descriptor: about 75 bytes for one CDC-ACM function with its
/// interface association; generous because a short buffer is a panic at boot.
const CONFIG_DESCRIPTOR: usize = 256;
/// Room for the BOS descriptor (USB 2.1 devices have one: 12 bytes here).
const BOS_DESCRIPTOR: usize = 64;
/// Control transfer buffer (CDC-ACM needs 7 bytes for its line coding).
const CONTROL_BUFFER: usize = 64;

/// The embassy-stm32 driver of USB OTG FS.
pub type UsbDriver = usb::Driver<'static, USB_OTG_FS>;

/// The USB device: enumeration and control requests. Keep [`run`] running.
pub type UsbDevice = embassy_usb::UsbDevice<'static, UsbDriver>;

/// Why a read or write on the USB link failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum UsbLinkError {
    /// The host has not configured the device, or the bus went away during the read.
    Disconnected,
    /// A packet longer than [`PACKET_SIZE`] arrived (the endpoint is declared with that size,
    /// so a host cannot send one).
    PacketTooLong,
}

impl core::fmt::Display for UsbLinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Disconnected => "USB host not connected",
            Self::PacketTooLong => "USB packet longer than the endpoint's maximum",
        })
    }
}

impl core::error::Error for UsbLinkError {}

impl embedded_io_async::Error for UsbLinkError {
    fn kind(&self) -> embedded_io_async::ErrorKind {
        match self {
            Self::Disconnected => embedded_io_async::ErrorKind::NotConnected,
            Self::PacketTooLong => embedded_io_async::ErrorKind::InvalidData,
        }
    }
}

impl From<EndpointError> for UsbLinkError {
    fn from(error: EndpointError) -> Self {
        match error {
            EndpointError::Disabled => Self::Disconnected,
            EndpointError::BufferOverflow => Self::PacketTooLong,
        }
    }
}

/// The CDC-ACM data interface as a byte stream (see the module documentation for its rules).
pub struct UsbLink {
    sender: Sender<'static, UsbDriver>,
    receiver: Receiver<'static, UsbDriver>,
    /// The last packet received; `packet[start..end]` has not been read yet.
    packet: [u8; PACKET_SIZE],
    start: usize,
    end: usize,
}

impl UsbLink {
    /// Whether the host holds DTR high, i.e. (on Linux and macOS) a program has the port open.
    /// Informational: see the module documentation for why data never waits for it.
    pub fn host_port_open(&self) -> bool {
        self.receiver.dtr()
    }

    /// Waits for the next non-empty packet into `self.packet`.
    async fn receive(&mut self) -> Result<(), UsbLinkError> {
        loop {
            // Returns at once when the host has configured the device.
            self.receiver.wait_connection().await;
            // Cancel-safe: the driver copies a packet out (and re-arms the endpoint) only in
            // the poll that returns it, and `start`/`end` are set in that same poll.
            let len = self.receiver.read_packet(&mut self.packet).await?;
            if len > 0 {
                self.start = 0;
                self.end = len;
                return Ok(());
            }
        }
    }
}

impl embedded_io_async::ErrorType for UsbLink {
    type Error = UsbLinkError;
}

impl embedded_io_async::Read for UsbLink {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        if self.start == self.end {
            self.receive().await?;
        }
        let len = buf.len().min(self.end - self.start);
        buf[..len].copy_from_slice(&self.packet[self.start..self.start + len]);
        self.start += len;
        Ok(len)
    }
}

impl embedded_io_async::Write for UsbLink {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        for packet in buf.chunks(PACKET_SIZE) {
            self.sender.write_packet(packet).await?;
        }
        if !buf.is_empty() && buf.len().is_multiple_of(PACKET_SIZE) {
            // The last packet was full: end the transfer (see the module documentation).
            self.sender.write_packet(&[]).await?;
        }
        Ok(buf.len())
    }

    /// Every written byte is already with the USB core (sent at the host's next IN token).
    async fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// Builds the USB device (VID/PID/product from `chladni_shared::icd::link`, serial number =
/// the chip's 96-bit unique id as 24 hex digits) with one CDC-ACM function; returns the link
/// and the device, which [`run`] must drive.
pub fn new(
    otg: Peri<'static, USB_OTG_FS>,
    dp: Peri<'static, PA12>,
    dm: Peri<'static, PA11>,
) -> (UsbLink, UsbDevice) {
    static EP_OUT: StaticCell<[u8; EP_OUT_BUFFER]> = StaticCell::new();
    static CONFIG: StaticCell<[u8; CONFIG_DESCRIPTOR]> = StaticCell::new();
    static BOS: StaticCell<[u8; BOS_DESCRIPTOR]> = StaticCell::new();
    static CONTROL: StaticCell<[u8; CONTROL_BUFFER]> = StaticCell::new();
    static CDC_STATE: StaticCell<cdc_acm::State<'static>> = StaticCell::new();

    // No VBUS sensing (embassy's default, and it would need VBUS wired to PA9): the device pulls
    // DP up as soon as the USB task runs, and a host sees it whenever a cable is in. (Strictly,
    // a self-powered device should sense VBUS; with no cable, the pull-up goes nowhere.)
    let mut otg_config = usb::Config::default();
    otg_config.vbus_detection = false;
    let driver =
        usb::Driver::new_fs(otg, Irqs, dp, dm, EP_OUT.init([0; EP_OUT_BUFFER]), otg_config);

    let mut config = embassy_usb::Config::new(USB_VID, USB_PID);
    config.product = Some(USB_PRODUCT);
    config.serial_number = Some(embassy_stm32::uid::uid_hex());
    // Defaults kept: USB 2.1; composite with an interface association descriptor grouping the
    // two CDC interfaces (Windows then binds its built-in usbser.sys, no .inf); bus-powered,
    // 100 mA.

    let mut builder = embassy_usb::Builder::new(
        driver,
        config,
        CONFIG.init([0; CONFIG_DESCRIPTOR]),
        BOS.init([0; BOS_DESCRIPTOR]),
        &mut [], // no Microsoft OS descriptors
        CONTROL.init([0; CONTROL_BUFFER]),
    );
    let class =
        CdcAcmClass::new(&mut builder, CDC_STATE.init(cdc_acm::State::new()), PACKET_SIZE as u16);
    let (sender, receiver) = class.split();
    let link = UsbLink { sender, receiver, packet: [0; PACKET_SIZE], start: 0, end: 0 };
    (link, builder.build())
}

/// Runs the USB device for ever: answers the host's enumeration and control requests, and
/// follows suspend and resume. Spawned by [`super::spawn_tasks`].
#[embassy_executor::task]
pub async fn run(mut device: UsbDevice) -> ! {
    defmt::info!(
        "usb: CDC-ACM {=u16:04x}:{=u16:04x} serial {=str}",
        USB_VID,
        USB_PID,
        embassy_stm32::uid::uid_hex()
    );
    device.run().await
}
