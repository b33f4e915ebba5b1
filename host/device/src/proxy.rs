//! A frame-aware TCP proxy in front of QEMU's serial socket: many clients, one serial line.
//!
//! QEMU's `-chardev socket,server=on` serves one TCP client at a time. A second client's
//! connect succeeds (the kernel's listen backlog takes it) but QEMU does not read its bytes
//! until the first client leaves; then they run, seconds late (measured: see docs/drive.md,
//! "Several clients"). A real serial port behaves differently: every program that opens it
//! writes into the same line at once, and the controller's sessions tell them apart.
//!
//! The proxy makes the emulator behave like that serial line. It owns the public port and is
//! QEMU's only client. Each client's bytes are cut into frames at the `0x00` delimiters and
//! forwarded whole, one frame at a time, so two clients' frames never interleave; a client
//! that leaves mid-frame has its partial frame dropped. Everything QEMU writes goes to every
//! client (each keeps the answers of its own session). Threads and blocking std sockets: a
//! handful of clients at most.

use std::io::{ErrorKind, Read, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU16, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use chladni_shared::icd::link::MAX_FRAME;

/// Longest frame the proxy holds, bytes: longer frames are cut to this (still longer than
/// any frame the controller accepts, so it refuses them as too long, as it would have).
pub const FRAME_CAP: usize = 2 * MAX_FRAME;
/// How often blocked threads look at the stop flag.
const POLL: Duration = Duration::from_millis(50);
/// A client that does not take QEMU's output within this long is dropped (it would stall
/// every other client).
const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

/// Cuts a byte stream into frames at `0x00`, holding at most [`FRAME_CAP`] bytes of one.
#[derive(Debug, Default)]
pub struct FrameSplitter {
    buf: Vec<u8>,
}

impl FrameSplitter {
    /// Feeds `bytes`; calls `frame` with each complete non-empty frame (without delimiters).
    pub fn push(&mut self, bytes: &[u8], mut frame: impl FnMut(&[u8])) {
        for &byte in bytes {
            if byte != 0 {
                if self.buf.len() < FRAME_CAP {
                    self.buf.push(byte);
                }
            } else if !self.buf.is_empty() {
                frame(&self.buf);
                self.buf.clear();
            }
        }
    }
}

/// `frame` with its delimiters, ready to write.
fn delimited(frame: &[u8]) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(frame.len() + 2);
    bytes.push(0);
    bytes.extend_from_slice(frame);
    bytes.push(0);
    bytes
}

/// State shared by the proxy's threads.
#[derive(Default)]
struct Shared {
    stop: AtomicBool,
    /// QEMU's port (0: none yet); changes when QEMU restarts.
    upstream_port: AtomicU16,
    /// The connection to QEMU, for writing, and the frames waiting for it while QEMU is not
    /// connected: QEMU's socket is sometimes reset under a burst of input (seen in the
    /// garbage test: "connection reset by peer" on the proxy's side), and a client's request
    /// sent in that instant must reach the firmware after the reconnection, not vanish.
    upstream: Mutex<Upstream>,
    /// Connected clients, for writing QEMU's output to.
    clients: Mutex<Vec<(u64, TcpStream)>>,
    next_client: AtomicU64,
    /// Bytes read from clients and from QEMU so far: what the proxy has taken in, for tests
    /// that must know a byte reached it before sending the next.
    from_clients: AtomicU64,
    from_qemu: AtomicU64,
}

/// The proxy's side of QEMU's socket.
#[derive(Default)]
struct Upstream {
    stream: Option<TcpStream>,
    waiting: std::collections::VecDeque<(std::time::Instant, Vec<u8>)>,
}

/// Frames kept while QEMU is not connected (beyond that the oldest are dropped).
const WAITING_FRAMES: usize = 64;
/// A waiting frame older than this is dropped, not sent: its client has given up on it by
/// then or soon will (clients wait 3 s by default), and a request a client gave up on must
/// never run later.
const WAIT_LIMIT: Duration = Duration::from_secs(1);

/// Locks `mutex`, also after a thread panicked while holding it (the data stays usable).
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl Shared {
    /// Writes one client's frame to QEMU whole; while QEMU is not connected it waits for
    /// the reconnection (at most [`WAITING_FRAMES`] frames).
    fn forward(&self, frame: &[u8]) {
        let mut upstream = lock(&self.upstream);
        let bytes = delimited(frame);
        if let Some(stream) = upstream.stream.as_mut() {
            if stream.write_all(&bytes).is_ok() {
                return;
            }
            upstream.stream = None;
        }
        if upstream.waiting.len() == WAITING_FRAMES {
            upstream.waiting.pop_front();
        }
        upstream.waiting.push_back((std::time::Instant::now(), bytes));
    }

    /// Takes a new connection to QEMU and sends it the frames that waited for it.
    fn connected(&self, mut stream: TcpStream) {
        let mut upstream = lock(&self.upstream);
        while let Some((since, bytes)) = upstream.waiting.pop_front() {
            if since.elapsed() > WAIT_LIMIT {
                continue;
            }
            if stream.write_all(&bytes).is_err() {
                return;
            }
        }
        upstream.stream = Some(stream);
    }

    /// Writes one frame from QEMU to every client; drops clients that cannot take it.
    fn broadcast(&self, frame: &[u8]) {
        let bytes = delimited(frame);
        lock(&self.clients).retain_mut(|(_, stream)| {
            let ok = stream.write_all(&bytes).is_ok();
            if !ok {
                let _ = stream.shutdown(std::net::Shutdown::Both);
            }
            ok
        });
    }
}

/// The proxy: a public port for clients, one connection to QEMU.
pub struct Proxy {
    port: u16,
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
}

impl Proxy {
    /// Binds the public port on 127.0.0.1 (`None`: a free one) and starts accepting clients.
    /// Fails at once if the port is taken, before anything else is started.
    pub fn bind(port: Option<u16>) -> std::io::Result<Proxy> {
        let listener = TcpListener::bind((Ipv4Addr::LOCALHOST, port.unwrap_or(0)))?;
        listener.set_nonblocking(true)?;
        let port = listener.local_addr()?.port();
        let shared = Arc::new(Shared::default());
        let accept = {
            let shared = Arc::clone(&shared);
            std::thread::spawn(move || accept_loop(listener, shared))
        };
        let pump = {
            let shared = Arc::clone(&shared);
            std::thread::spawn(move || upstream_loop(shared))
        };
        Ok(Proxy { port, shared, threads: vec![accept, pump] })
    }

    /// The public port.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// Connects (and after a restart, reconnects) to QEMU's serial socket on `port`.
    pub(crate) fn set_upstream(&self, port: u16) {
        self.shared.upstream_port.store(port, Ordering::SeqCst);
        // Drop a connection to an old QEMU at once rather than at its end of file, and what
        // was sent for it: a new controller never gets requests meant for the old one.
        let mut upstream = lock(&self.shared.upstream);
        upstream.waiting.clear();
        if let Some(stream) = upstream.stream.take() {
            let _ = stream.shutdown(std::net::Shutdown::Both);
        }
    }

    /// Clients connected right now.
    pub fn clients(&self) -> usize {
        lock(&self.shared.clients).len()
    }

    #[cfg(test)]
    /// Whether the proxy holds a connection to QEMU right now.
    pub(crate) fn upstream_connected(&self) -> bool {
        lock(&self.shared.upstream).stream.is_some()
    }

    #[cfg(test)]
    /// Bytes the proxy has read from its clients (all of them) and from QEMU so far.
    pub(crate) fn bytes_in(&self) -> (u64, u64) {
        (
            self.shared.from_clients.load(Ordering::SeqCst),
            self.shared.from_qemu.load(Ordering::SeqCst),
        )
    }

    /// Closes the public port and every connection; waits for the threads.
    pub(crate) fn shutdown(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        for (_, stream) in lock(&self.shared.clients).drain(..) {
            let _ = stream.shutdown(std::net::Shutdown::Both);
        }
        if let Some(stream) = lock(&self.shared.upstream).stream.take() {
            let _ = stream.shutdown(std::net::Shutdown::Both);
        }
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

impl Drop for Proxy {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Accepts clients until the proxy stops; one reader thread per client.
fn accept_loop(listener: TcpListener, shared: Arc<Shared>) {
    while !shared.stop.load(Ordering::SeqCst) {
        match listener.accept() {
            // A client whose socket cannot be set up is dropped: it sees the link closed.
            Ok((stream, _)) => drop(add_client(stream, &shared)),
            Err(e) if e.kind() == ErrorKind::WouldBlock => std::thread::sleep(POLL / 5),
            Err(_) => std::thread::sleep(POLL),
        }
    }
}

/// Registers a client for QEMU's output and starts forwarding its frames.
fn add_client(stream: TcpStream, shared: &Arc<Shared>) -> std::io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    stream.set_read_timeout(Some(POLL))?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    let id = shared.next_client.fetch_add(1, Ordering::SeqCst);
    lock(&shared.clients).push((id, stream.try_clone()?));
    let shared = Arc::clone(shared);
    std::thread::spawn(move || client_loop(id, stream, shared));
    Ok(())
}

/// Forwards one client's frames to QEMU until it leaves; its partial frame is dropped then.
fn client_loop(id: u64, mut stream: TcpStream, shared: Arc<Shared>) {
    let mut splitter = FrameSplitter::default();
    let mut buf = [0u8; 4096];
    while !shared.stop.load(Ordering::SeqCst) {
        match stream.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                shared.from_clients.fetch_add(n as u64, Ordering::SeqCst);
                splitter.push(&buf[..n], |frame| shared.forward(frame));
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(_) => break,
        }
    }
    lock(&shared.clients).retain(|(other, _)| *other != id);
}

/// Keeps a connection to QEMU (reconnecting after a restart) and sends its frames to all.
fn upstream_loop(shared: Arc<Shared>) {
    while !shared.stop.load(Ordering::SeqCst) {
        let port = shared.upstream_port.load(Ordering::SeqCst);
        let addr = SocketAddr::from((Ipv4Addr::LOCALHOST, port));
        let stream = match (port != 0).then(|| TcpStream::connect_timeout(&addr, POLL * 4)) {
            Some(Ok(stream)) => stream,
            _ => {
                std::thread::sleep(POLL);
                continue;
            }
        };
        // QEMU ends its side when it stops or restarts (a reset connection is one way to end):
        // either way, connect again to whatever port QEMU is on then.
        let _ = pump(stream, &shared);
        lock(&shared.upstream).stream = None;
    }
}

/// Reads QEMU's output until it closes (or the proxy stops), sending whole frames to all.
fn pump(mut stream: TcpStream, shared: &Shared) -> std::io::Result<()> {
    stream.set_nodelay(true)?;
    stream.set_read_timeout(Some(POLL))?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    shared.connected(stream.try_clone()?);
    let mut splitter = FrameSplitter::default();
    let mut buf = [0u8; 4096];
    while !shared.stop.load(Ordering::SeqCst) {
        match stream.read(&mut buf) {
            Ok(0) => return Ok(()),
            Ok(n) => {
                shared.from_qemu.fetch_add(n as u64, Ordering::SeqCst);
                splitter.push(&buf[..n], |frame| shared.broadcast(frame));
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    /// Frames in `bytes`, split at delimiters.
    fn frames_of(bytes: &[u8]) -> Vec<Vec<u8>> {
        let mut frames = Vec::new();
        FrameSplitter::default().push(bytes, |f| frames.push(f.to_vec()));
        frames
    }

    /// Reads from `stream` until `frames` whole frames arrived (or 5 s passed).
    fn read_frames(stream: &mut TcpStream, frames: usize) -> Vec<Vec<u8>> {
        read_frames_within(stream, frames, Duration::from_secs(5))
    }

    /// Reads from `stream` until `frames` whole frames arrived (or `within` passed).
    fn read_frames_within(stream: &mut TcpStream, frames: usize, within: Duration) -> Vec<Vec<u8>> {
        stream.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
        let (mut bytes, mut buf) = (Vec::new(), [0u8; 256]);
        let deadline = Instant::now() + within;
        while frames_of(&bytes).len() < frames && Instant::now() < deadline {
            if let Ok(n) = stream.read(&mut buf) {
                bytes.extend_from_slice(&buf[..n]);
            }
        }
        frames_of(&bytes)
    }

    /// A proxy in front of a listener that plays QEMU; returns both ends.
    fn proxy_and_upstream() -> (Proxy, TcpStream) {
        let qemu = TcpListener::bind("127.0.0.1:0").unwrap();
        let proxy = Proxy::bind(None).unwrap();
        proxy.set_upstream(qemu.local_addr().unwrap().port());
        let (upstream, _) = qemu.accept().unwrap();
        (proxy, upstream)
    }

    /// Polls `condition` until it holds; panics naming `what` after 5 s.
    fn wait_until(what: &str, mut condition: impl FnMut() -> bool) {
        let deadline = Instant::now() + Duration::from_secs(5);
        while !condition() {
            assert!(Instant::now() < deadline, "gave up waiting for {what}");
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// A new client, once the proxy has `expect_clients` clients.
    fn client(proxy: &Proxy, expect_clients: usize) -> TcpStream {
        let stream = TcpStream::connect(("127.0.0.1", proxy.port())).unwrap();
        wait_until("the client to be taken on", || proxy.clients() >= expect_clients);
        stream
    }

    /// Waits until the proxy has read `n` bytes from its clients in all.
    fn taken_from_clients(proxy: &Proxy, n: u64) {
        wait_until(&format!("{n} bytes from the clients"), || proxy.bytes_in().0 >= n);
    }

    /// Waits until the proxy has read `n` bytes from QEMU in all.
    fn taken_from_qemu(proxy: &Proxy, n: u64) {
        wait_until(&format!("{n} bytes from QEMU"), || proxy.bytes_in().1 >= n);
    }

    #[test]
    fn splitter_cuts_at_zeros_skips_empty_frames_and_caps_long_ones() {
        assert_eq!(frames_of(&[0, 1, 2, 0, 0, 0, 3, 0, 4]), [vec![1, 2], vec![3]]);
        let mut long = vec![0u8];
        long.extend(std::iter::repeat_n(7u8, FRAME_CAP + 100));
        long.push(0);
        let frames = frames_of(&long);
        assert_eq!(frames.len(), 1);
        assert_eq!(frames[0].len(), FRAME_CAP, "cut, and still longer than any valid frame");
        const { assert!(FRAME_CAP > MAX_FRAME) };
    }

    #[test]
    fn two_clients_frames_reach_qemu_whole_and_never_interleaved() {
        let (proxy, mut upstream) = proxy_and_upstream();
        let mut a = client(&proxy, 1);
        let mut b = client(&proxy, 2);
        a.write_all(&[0, 1, 2, 3]).unwrap(); // half a frame
        taken_from_clients(&proxy, 4);
        b.write_all(&[0, 9, 9, 0]).unwrap(); // a whole frame meanwhile
        // B's frame goes on at once, while A's half waits for its end.
        assert_eq!(read_frames(&mut upstream, 1), [vec![9, 9]]);
        a.write_all(&[4, 5, 0]).unwrap(); // the rest of a's
        assert_eq!(read_frames(&mut upstream, 1), [vec![1, 2, 3, 4, 5]]);
    }

    #[test]
    fn a_client_that_leaves_mid_frame_has_its_partial_frame_dropped() {
        let (proxy, mut upstream) = proxy_and_upstream();
        let mut a = client(&proxy, 1);
        a.write_all(&[0, 7, 7, 7]).unwrap();
        taken_from_clients(&proxy, 4);
        drop(a);
        wait_until("A to be gone", || proxy.clients() == 0);
        let mut b = client(&proxy, 1);
        b.write_all(&[0, 8, 0]).unwrap();
        // An absence: A's partial frame must never reach QEMU. Bounded: 1 s for a second
        // frame to come (a forwarded frame takes well under a millisecond here).
        assert_eq!(read_frames_within(&mut upstream, 2, Duration::from_secs(1)), [vec![8]]);
    }

    #[test]
    fn qemus_output_goes_to_every_client_whole() {
        let (proxy, mut upstream) = proxy_and_upstream();
        let mut a = client(&proxy, 1);
        let mut b = client(&proxy, 2);
        upstream.write_all(&[0, 5, 5]).unwrap();
        taken_from_qemu(&proxy, 3); // the frame's first part read on its own
        upstream.write_all(&[5, 0, 0, 6, 0]).unwrap();
        for stream in [&mut a, &mut b] {
            assert_eq!(read_frames(stream, 2), [vec![5, 5, 5], vec![6]]);
        }
        // A client that arrives while a frame is on its way gets it whole, never a tail.
        upstream.write_all(&[0, 1, 1]).unwrap();
        taken_from_qemu(&proxy, 11);
        let mut c = client(&proxy, 3);
        upstream.write_all(&[1, 0, 0, 2, 0]).unwrap();
        assert_eq!(read_frames(&mut c, 2), [vec![1, 1, 1], vec![2]]);
    }

    #[test]
    fn after_a_restart_the_proxy_talks_to_the_new_qemu() {
        let (proxy, first) = proxy_and_upstream();
        let mut a = client(&proxy, 1);
        let second = TcpListener::bind("127.0.0.1:0").unwrap();
        proxy.set_upstream(second.local_addr().unwrap().port());
        drop(first);
        let (mut upstream, _) = second.accept().unwrap();
        wait_until("the connection to the new QEMU", || proxy.upstream_connected());
        a.write_all(&[0, 3, 0]).unwrap();
        assert_eq!(read_frames(&mut upstream, 1), [vec![3]]);
    }

    #[test]
    fn a_busy_port_is_refused_at_bind() {
        let taken = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = taken.local_addr().unwrap().port();
        let err = Proxy::bind(Some(port)).err().unwrap();
        assert_eq!(err.kind(), ErrorKind::AddrInUse);
    }

    #[test]
    fn shutdown_closes_clients_and_the_port() {
        let (mut proxy, _upstream) = proxy_and_upstream();
        let port = proxy.port();
        let mut a = client(&proxy, 1);
        proxy.shutdown();
        // Closed: end of file or a reset, never the read timeout (still open).
        a.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        match a.read(&mut [0u8; 8]) {
            Ok(0) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::ConnectionReset | ErrorKind::ConnectionAborted
                ) => {}
            other => panic!("the client was not closed: {other:?}"),
        }
        // The port is free again.
        drop(TcpListener::bind(("127.0.0.1", port)).unwrap());
    }
}
