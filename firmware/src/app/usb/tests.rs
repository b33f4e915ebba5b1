//! The USB stream against fake endpoints and a fake host: packet splitting and the ZLP rule,
//! a host that stops reading, an unplug (a suspend, without VBUS sensing) and a re-plug.

use std::boxed::Box;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::pin::pin;
use std::rc::Rc;
use std::task::{Context, Poll, Waker};
use std::vec;
use std::vec::Vec;

use embassy_futures::block_on;
use embedded_io_async::{Read, Write};

use super::*;

/// The host and the bus, as the fake endpoints see them.
#[derive(Default)]
struct Host {
    /// The host's program reads (takes IN packets).
    reading: bool,
    /// The endpoints are enabled (configured, no bus reset since).
    enabled: bool,
    /// IN packets the host took, in order.
    received: Vec<Vec<u8>>,
    /// OUT packets the host has queued for the device.
    outgoing: VecDeque<Vec<u8>>,
}

impl Host {
    fn bytes(&self) -> Vec<u8> {
        self.received.concat()
    }
}

struct FakeIn(Rc<RefCell<Host>>);
struct FakeOut(Rc<RefCell<Host>>);

impl InEndpoint for FakeIn {
    async fn write_packet(&mut self, data: &[u8]) -> Result<(), EndpointError> {
        assert!(data.len() <= PACKET_SIZE, "a packet of {} bytes", data.len());
        core::future::poll_fn(|_| {
            let mut host = self.0.borrow_mut();
            if !host.enabled {
                Poll::Ready(Err(EndpointError::Disabled))
            } else if host.reading {
                host.received.push(data.to_vec());
                Poll::Ready(Ok(()))
            } else {
                Poll::Pending
            }
        })
        .await
    }
}

impl OutEndpoint for FakeOut {
    async fn wait_connection(&mut self) {
        core::future::poll_fn(
            |_| if self.0.borrow().enabled { Poll::Ready(()) } else { Poll::Pending },
        )
        .await
    }

    async fn read_packet(&mut self, buf: &mut [u8]) -> Result<usize, EndpointError> {
        core::future::poll_fn(|_| {
            let mut host = self.0.borrow_mut();
            if !host.enabled {
                return Poll::Ready(Err(EndpointError::Disabled));
            }
            match host.outgoing.pop_front() {
                Some(p) if p.len() > buf.len() => Poll::Ready(Err(EndpointError::BufferOverflow)),
                Some(p) => {
                    buf[..p.len()].copy_from_slice(&p);
                    Poll::Ready(Ok(p.len()))
                }
                None => Poll::Pending,
            }
        })
        .await
    }
}

/// A configured device, a reading host, and the stream.
fn plugged() -> (Rc<RefCell<Host>>, &'static BusState, PacketStream<FakeIn, FakeOut>) {
    let host = Rc::new(RefCell::new(Host { reading: true, enabled: true, ..Host::default() }));
    let bus: &'static BusState = Box::leak(Box::new(BusState::new()));
    bus.configured(true);
    let stream = PacketStream::new(FakeIn(host.clone()), FakeOut(host.clone()), bus);
    (host, bus, stream)
}

fn poll_once<F: Future>(f: core::pin::Pin<&mut F>) -> Poll<F::Output> {
    f.poll(&mut Context::from_waker(Waker::noop()))
}

fn frame(len: usize) -> Vec<u8> {
    (0..len).map(|i| (i * 7 + 1) as u8).collect()
}

#[test]
fn writes_split_into_64_byte_packets_and_exact_multiples_end_with_a_zlp() {
    for len in [1, 63, 64, 65, 127, 128, 129, 192, 200, 640] {
        let (host, _, mut stream) = plugged();
        let data = frame(len);
        assert_eq!(block_on(stream.write(&data)), Ok(len));
        let host = host.borrow();
        let sizes: Vec<usize> = host.received.iter().map(Vec::len).collect();
        let mut want = vec![PACKET_SIZE; len / PACKET_SIZE];
        // A short last packet ends the transfer; after a full one, a ZLP does.
        want.push(len % PACKET_SIZE);
        assert_eq!(sizes, want, "packet sizes of a {len}-byte write");
        assert_eq!(host.bytes(), data, "{len} bytes, in order");
    }
    let (host, _, mut stream) = plugged();
    assert_eq!(block_on(stream.write(&[])), Ok(0));
    assert!(host.borrow().received.is_empty(), "an empty write sends nothing, not a ZLP");
}

#[test]
fn reads_give_one_packet_at_a_time_and_skip_zero_length_packets() {
    let (host, _, mut stream) = plugged();
    host.borrow_mut().outgoing.extend([frame(64), vec![], frame(3)]);
    let mut got = Vec::new();
    let mut buf = [0u8; 10];
    while got.len() < 67 {
        let n = block_on(stream.read(&mut buf)).unwrap();
        assert!(n > 0 && n <= 10);
        got.extend_from_slice(&buf[..n]);
        // Never more than one packet's rest per read: the 64-byte packet ends at 64.
        assert!(got.len() <= 64 || got.len() == 67, "a read crossed a packet: {}", got.len());
    }
    assert_eq!(got, [frame(64), frame(3)].concat());
}

#[test]
fn a_host_that_stops_reading_holds_a_write_until_the_link_drops_it_then_frames_flow_again() {
    let (host, _, mut stream) = plugged();
    host.borrow_mut().reading = false;
    let first = frame(150);
    {
        let mut write = pin!(stream.write(&first));
        for _ in 0..3 {
            assert!(poll_once(write.as_mut()).is_pending(), "the write waits for the host");
        }
        // The link's write limit ran out: the write is dropped where it was.
    }
    host.borrow_mut().reading = true;
    let second = frame(128);
    assert_eq!(block_on(stream.write(&second)), Ok(128));
    let host = host.borrow();
    assert!(host.bytes().ends_with(&second), "the next frame arrives whole");
    assert_eq!(host.received.last().map(Vec::len), Some(0), "and ends with its ZLP");
}

#[test]
fn an_unplug_seen_as_a_suspend_fails_writes_at_once_and_reads_wait() {
    let (host, bus, mut stream) = plugged();
    host.borrow_mut().reading = false;
    let data = frame(100);
    {
        let mut write = pin!(stream.write(&data));
        assert!(poll_once(write.as_mut()).is_pending());
        // The cable is pulled: without VBUS sensing the device sees the bus suspend.
        bus.suspended(true);
        assert_eq!(poll_once(write.as_mut()), Poll::Ready(Err(UsbLinkError::Disconnected)));
    }
    assert_eq!(bus.get(), Bus::Suspended);
    {
        let mut write = pin!(stream.write(&data));
        assert_eq!(
            poll_once(write.as_mut()),
            Poll::Ready(Err(UsbLinkError::Disconnected)),
            "a write while suspended fails on its first poll"
        );
    }
    let mut buf = [0u8; 8];
    let mut read = pin!(stream.read(&mut buf));
    assert!(poll_once(read.as_mut()).is_pending(), "a read waits through a suspend");
}

#[test]
fn a_re_plug_ends_the_pending_read_once_then_the_new_session_flows() {
    let (host, bus, mut stream) = plugged();
    let mut buf = [0u8; 64];
    {
        let mut read = pin!(stream.read(&mut buf));
        assert!(poll_once(read.as_mut()).is_pending());
        // Unplug (a suspend), then plug in: the bus reset disables the endpoints.
        bus.suspended(true);
        assert!(poll_once(read.as_mut()).is_pending(), "still waiting while suspended");
        host.borrow_mut().enabled = false;
        bus.reset();
        assert_eq!(poll_once(read.as_mut()), Poll::Ready(Err(UsbLinkError::Disconnected)));
    }
    {
        let mut read = pin!(stream.read(&mut buf));
        assert!(poll_once(read.as_mut()).is_pending(), "the next read waits for the host");
        assert_eq!(block_on(stream_write_while_detached(bus)), Err(UsbLinkError::Disconnected));
        // The host configures the device again and sends a request.
        host.borrow_mut().enabled = true;
        bus.configured(true);
        host.borrow_mut().outgoing.push_back(frame(5));
        assert_eq!(poll_once(read.as_mut()), Poll::Ready(Ok(5)));
    }
    assert_eq!(&buf[..5], frame(5));
    assert_eq!(block_on(stream.write(&frame(64))), Ok(64), "answers flow on the new session");
    assert_eq!(host.borrow().received.len(), 2, "one full packet and its ZLP");
}

/// A write on a second stream over the same (detached) bus: refused at once.
async fn stream_write_while_detached(bus: &'static BusState) -> Result<usize, UsbLinkError> {
    let host = Rc::new(RefCell::new(Host { reading: true, enabled: true, ..Host::default() }));
    PacketStream::new(FakeIn(host.clone()), FakeOut(host), bus).write(&frame(3)).await
}

#[test]
fn a_write_before_the_host_configured_the_device_fails_at_once() {
    let (host, bus, mut stream) = plugged();
    host.borrow_mut().enabled = false;
    bus.reset();
    let data = frame(10);
    let mut write = pin!(stream.write(&data));
    assert_eq!(poll_once(write.as_mut()), Poll::Ready(Err(UsbLinkError::Disconnected)));
    assert!(host.borrow().received.is_empty());
}

#[test]
fn a_resume_returns_to_configured_and_a_suspend_before_configuration_stays_detached() {
    let bus = BusState::new();
    bus.suspended(true);
    assert_eq!(bus.get(), Bus::Detached);
    bus.configured(true);
    bus.suspended(true);
    bus.suspended(false);
    assert_eq!(bus.get(), Bus::Configured);
    bus.configured(false);
    assert_eq!(bus.get(), Bus::Detached);
}
