//! The host link on the B-L475E-IOT01A: a USB CDC-ACM device on USB OTG FS (PA11 DM, PA12 DP:
//! the board's USB OTG connector, not the ST-LINK one), built with embassy-usb.
//!
//! Two halves:
//! - [`UsbLink`] is the byte stream the app reads and writes (`embedded_io_async::Read` and
//!   `Write`) over the CDC data interface's two bulk endpoints;
//! - [`UsbDevice`] is the device side of the USB protocol (enumeration, control requests,
//!   suspend/resume), which must be polled all the time: [`run`] in a task of its own.
//!
//! The stream's rules (packets, the zero-length-packet rule, what an unplug does without VBUS
//! sensing) are board-independent, in `app::usb` ([`PacketStream`], tested on the host); this
//! module adapts embassy-usb's CDC-ACM endpoints to its traits and keeps its [`BusState`]
//! through an embassy-usb [`Handler`](embassy_usb::Handler) on the device.
//! - **DTR** ([`UsbLink::host_port_open`]) is reported, never used to gate data: Linux and macOS
//!   raise it when a program opens the port, but the `serialport` crate leaves it low on
//!   Windows, so a gate would lock Windows hosts out. Frames already survive a client change:
//!   every frame starts with a delimiter (`chladni_shared::icd::frame`).

use embassy_stm32::peripherals::{PA11, PA12, USB_OTG_FS};
use embassy_stm32::{Peri, usb};
use embassy_usb::class::cdc_acm::{self, CdcAcmClass, Receiver, Sender};
use static_cell::StaticCell;

use chladni_shared::icd::link::{USB_PID, USB_PRODUCT, USB_VID};

use super::Irqs;
use crate::app::usb::{BusState, EndpointError, InEndpoint, OutEndpoint, PacketStream};
pub use crate::app::usb::{PACKET_SIZE, UsbLinkError};

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

/// The bus state the device's handler keeps and the link's writes read.
static BUS: BusState = BusState::new();

/// embassy-usb's endpoint error in `app::usb`'s terms.
fn endpoint_error(error: embassy_usb::driver::EndpointError) -> EndpointError {
    match error {
        embassy_usb::driver::EndpointError::Disabled => EndpointError::Disabled,
        embassy_usb::driver::EndpointError::BufferOverflow => EndpointError::BufferOverflow,
    }
}

impl InEndpoint for Sender<'static, UsbDriver> {
    async fn write_packet(&mut self, data: &[u8]) -> Result<(), EndpointError> {
        Sender::write_packet(self, data).await.map_err(endpoint_error)
    }
}

impl OutEndpoint for Receiver<'static, UsbDriver> {
    async fn wait_connection(&mut self) {
        Receiver::wait_connection(self).await
    }

    async fn read_packet(&mut self, buf: &mut [u8]) -> Result<usize, EndpointError> {
        // Cancel-safe: the driver copies a packet out (and re-arms the endpoint) only in the
        // poll that returns it.
        Receiver::read_packet(self, buf).await.map_err(endpoint_error)
    }
}

/// The host link: the CDC-ACM data interface as `app::usb`'s byte stream.
pub type UsbLink = PacketStream<Sender<'static, UsbDriver>, Receiver<'static, UsbDriver>>;

impl UsbLink {
    /// Whether the host holds DTR high, i.e. (on Linux and macOS) a program has the port open.
    /// Informational: see the module documentation for why data never waits for it.
    pub fn host_port_open(&self) -> bool {
        self.out_endpoint().dtr()
    }
}

/// Keeps [`BUS`] from the device's events (embassy-usb calls these from [`run`]).
struct BusHandler;

impl embassy_usb::Handler for BusHandler {
    fn enabled(&mut self, enabled: bool) {
        if !enabled {
            BUS.reset();
        }
    }

    fn reset(&mut self) {
        BUS.reset();
    }

    fn configured(&mut self, configured: bool) {
        BUS.configured(configured);
    }

    fn suspended(&mut self, suspended: bool) {
        BUS.suspended(suspended);
        defmt::info!("usb: bus {} (an unplug looks the same: no VBUS sensing)", BUS.get());
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
    static HANDLER: StaticCell<BusHandler> = StaticCell::new();

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
    builder.handler(HANDLER.init(BusHandler));
    let class =
        CdcAcmClass::new(&mut builder, CDC_STATE.init(cdc_acm::State::new()), PACKET_SIZE as u16);
    let (sender, receiver) = class.split();
    (PacketStream::new(sender, receiver, &BUS), builder.build())
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
