//! The host link's byte stream over a USB CDC-ACM data interface, board-independent: packet
//! splitting, the zero-length-packet rule and what an unplug does, over two small endpoint
//! traits the board implements ([`InEndpoint`], [`OutEndpoint`]) and the bus state its USB
//! device task keeps ([`BusState`]). Tested on the host against fake endpoints.
//!
//! Rules, and why:
//! - **Reads** return the bytes of one received packet at a time; a caller with a small buffer
//!   gets the rest of the packet on its next reads. Before the host has configured the device
//!   a read *waits* for that instead of failing, so an idle link costs nothing. A read that was
//!   waiting when the bus went away (bus reset, host deconfigured the device) returns
//!   [`UsbLinkError::Disconnected`] once, so the app can drop a half-received frame; the next
//!   read waits again. Zero-length packets from the host are not an end of stream (there is
//!   none) and are skipped. Reads are cancel-safe (the link races them against its telemetry
//!   timer): a packet is taken out of the endpoint only in the poll that returns it.
//! - **Writes** take the whole buffer, in packets of at most [`PACKET_SIZE`] bytes. A write
//!   that ends with a full packet is followed by a zero-length packet: a bulk IN transfer ends
//!   only at a short packet, so without it the host's USB stack keeps those bytes (the end of a
//!   reply) until the next write comes, perhaps never. Each packet waits until the host has
//!   taken the one before; a host that stops reading (no program has the port open) holds the
//!   write, and the app's link gives each frame `app::link::WRITE_LIMIT`, then drops it.
//! - **Unplug without VBUS sensing.** The board does not sense VBUS, so pulling the cable looks
//!   to the device like a suspend (the bus goes idle), not a disconnect; only the bus reset of
//!   the next plug-in ends the session. A suspended host takes no data, so a write that starts
//!   while the bus is not [`Bus::Configured`], or whose bus leaves that state while it waits,
//!   fails at once with [`UsbLinkError::Disconnected`] instead of holding the link for its
//!   whole write limit on every frame. Reads keep waiting through a suspend: after a resume
//!   the same session goes on; after a re-plug the bus reset makes the pending read return
//!   `Disconnected` once and the next one waits for the new configuration.

use core::cell::Cell;
use core::future::Future;

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;

/// Largest packet of the CDC data endpoints (full-speed bulk maximum), bytes.
pub const PACKET_SIZE: usize = 64;

/// An endpoint's failure, as embassy-usb's driver reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum EndpointError {
    /// The endpoint is not enabled: the host has not configured the device, or a bus reset
    /// disabled it.
    Disabled,
    /// A packet did not fit the buffer.
    BufferOverflow,
}

/// The data IN endpoint (device to host).
pub trait InEndpoint {
    /// Sends one packet of at most [`PACKET_SIZE`] bytes (empty: a zero-length packet); done
    /// when the host has taken it.
    fn write_packet(&mut self, data: &[u8]) -> impl Future<Output = Result<(), EndpointError>>;
}

/// The data OUT endpoint (host to device).
pub trait OutEndpoint {
    /// Waits until the host has configured the device (at once if it has).
    fn wait_connection(&mut self) -> impl Future<Output = ()>;
    /// Receives one packet into `buf`; returns its length (0: a zero-length packet).
    fn read_packet(&mut self, buf: &mut [u8])
    -> impl Future<Output = Result<usize, EndpointError>>;
}

/// The USB bus as the device sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Bus {
    /// Not configured: no cable since boot, or a bus reset since the last configuration.
    Detached,
    /// Configured by the host and not suspended: data can flow.
    Configured,
    /// Configured, but the bus is idle: the host suspended the device, or (no VBUS sensing)
    /// the cable was pulled.
    Suspended,
}

/// The bus state, written by the board's USB device task (its embassy-usb handler), read by
/// the stream's writes. A critical-section cell plus a signal, so it may be set from any
/// context.
pub struct BusState {
    state: Mutex<CriticalSectionRawMutex, Cell<Bus>>,
    changed: Signal<CriticalSectionRawMutex, ()>,
}

impl Default for BusState {
    fn default() -> Self {
        Self::new()
    }
}

impl BusState {
    /// [`Bus::Detached`].
    pub const fn new() -> Self {
        Self { state: Mutex::new(Cell::new(Bus::Detached)), changed: Signal::new() }
    }

    /// The state now.
    pub fn get(&self) -> Bus {
        self.state.lock(Cell::get)
    }

    /// A bus reset (or the device disabled): [`Bus::Detached`].
    pub fn reset(&self) {
        self.set(Bus::Detached);
    }

    /// The host configured (`true`) or deconfigured the device.
    pub fn configured(&self, configured: bool) {
        self.set(if configured { Bus::Configured } else { Bus::Detached });
    }

    /// The bus was suspended (`true`) or resumed. A resume returns to [`Bus::Configured`]
    /// only from [`Bus::Suspended`] (a device suspended before configuration stays detached).
    pub fn suspended(&self, suspended: bool) {
        let now = self.get();
        match (suspended, now) {
            (true, Bus::Configured) => self.set(Bus::Suspended),
            (false, Bus::Suspended) => self.set(Bus::Configured),
            _ => {}
        }
    }

    fn set(&self, bus: Bus) {
        self.state.lock(|s| s.set(bus));
        self.changed.signal(());
    }

    /// Waits until the bus is no longer [`Bus::Configured`] (at once if it is not).
    async fn left_configured(&self) {
        while self.get() == Bus::Configured {
            self.changed.wait().await;
        }
    }
}

/// Why a read or write on the USB link failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum UsbLinkError {
    /// The host has not configured the device, the bus went away during the read, or (writes)
    /// the bus is suspended or was pulled.
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
pub struct PacketStream<I, O> {
    tx: I,
    rx: O,
    bus: &'static BusState,
    /// The last packet received; `packet[start..end]` has not been read yet.
    packet: [u8; PACKET_SIZE],
    start: usize,
    end: usize,
}

impl<I: InEndpoint, O: OutEndpoint> PacketStream<I, O> {
    /// The stream over the two data endpoints, with the bus state the device task keeps.
    pub fn new(tx: I, rx: O, bus: &'static BusState) -> Self {
        Self { tx, rx, bus, packet: [0; PACKET_SIZE], start: 0, end: 0 }
    }

    /// The OUT endpoint (for what the board reads beside data, such as DTR).
    pub fn out_endpoint(&self) -> &O {
        &self.rx
    }

    /// Waits for the next non-empty packet into `self.packet`.
    async fn receive(&mut self) -> Result<(), UsbLinkError> {
        loop {
            self.rx.wait_connection().await;
            // `start`/`end` are set in the poll that returns the packet (cancel-safe).
            let len = self.rx.read_packet(&mut self.packet).await?;
            if len > 0 {
                self.start = 0;
                self.end = len;
                return Ok(());
            }
        }
    }

    /// Sends one packet unless the bus leaves [`Bus::Configured`] first.
    async fn send(&mut self, packet: &[u8]) -> Result<(), UsbLinkError> {
        if self.bus.get() != Bus::Configured {
            return Err(UsbLinkError::Disconnected);
        }
        match select(self.tx.write_packet(packet), self.bus.left_configured()).await {
            Either::First(sent) => Ok(sent?),
            Either::Second(()) => Err(UsbLinkError::Disconnected),
        }
    }
}

impl<I, O> embedded_io_async::ErrorType for PacketStream<I, O> {
    type Error = UsbLinkError;
}

impl<I: InEndpoint, O: OutEndpoint> embedded_io_async::Read for PacketStream<I, O> {
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

impl<I: InEndpoint, O: OutEndpoint> embedded_io_async::Write for PacketStream<I, O> {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        for packet in buf.chunks(PACKET_SIZE) {
            self.send(packet).await?;
        }
        if !buf.is_empty() && buf.len().is_multiple_of(PACKET_SIZE) {
            // The last packet was full: end the transfer (see the module documentation).
            self.send(&[]).await?;
        }
        Ok(buf.len())
    }

    /// Every written byte is already with the USB core (sent at the host's next IN token).
    async fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

#[cfg(all(test, not(target_os = "none")))]
mod tests;
