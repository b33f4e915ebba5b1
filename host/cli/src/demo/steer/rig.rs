//! The virtual rig of `chladni demo --steer`: `chladni rig` in-process. The true plate is the
//! given one warped ([`DEFAULT_WARP`]) and the seeds are drawn as `chladni rig --seed S` draws
//! them, so the demo's rig is the one `chladni rig --seed 1` starts on the same plate. It serves
//! on its own thread (with its own async runtime, inside [`chladni_rig::serve`]) until dropped.

use std::net::SocketAddr;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

use chladni_core::model::part::Part;
use chladni_core::model::plate_file::PlateFile;
use chladni_core::model::pose::Pose;
use chladni_core::rng::Rng;
use chladni_rig::{
    DEFAULT_NOISE, DEFAULT_PICK_TIME, DEFAULT_WARP, ModeTruth, Rig, RigConfig, RigError,
    ServeOptions, TruePlate, serve,
};

use crate::demo::DemoError;

/// How long the rig may take to reach the controller and listen.
const LISTEN_WITHIN: Duration = Duration::from_secs(30);

/// A virtual rig serving its camera until dropped.
pub struct VirtualRig {
    /// The camera's frame URL (`http://127.0.0.1:PORT/frame.png`).
    pub url: String,
    /// The true plate's modes, and how they differ from the given plate's.
    pub modes: Vec<ModeTruth>,
    /// Sends the stop.
    stop: tokio::sync::mpsc::UnboundedSender<()>,
    /// The serving thread: its end says why the camera stopped.
    thread: Option<JoinHandle<Result<(), RigError>>>,
}

/// The rig's true plate: `given` warped by [`DEFAULT_WARP`] with the warp seed `chladni rig
/// --seed seed` draws; with the seeds of the drops (and noise) and of the frames.
pub fn true_plate(given: &PlateFile, seed: u64) -> Result<(TruePlate, u64, u64), DemoError> {
    let mut seeds = Rng::seeded(seed);
    let (warp_seed, rig_seed, frame_seed) = (seeds.next_u64(), seeds.next_u64(), seeds.next_u64());
    let plate = TruePlate::warped(given, &DEFAULT_WARP, warp_seed).map_err(DemoError::Rig)?;
    Ok((plate, rig_seed, frame_seed))
}

impl VirtualRig {
    /// Puts one part of kind `part` at each pose of `at` (x mm, y mm, θ deg) on `plate`, follows
    /// the controller at `port` and serves the camera on a free loopback port.
    pub fn start(
        plate: TruePlate,
        part: &Part,
        at: &[[f64; 3]],
        seeds: (u64, u64),
        port: &str,
    ) -> Result<VirtualRig, DemoError> {
        let modes = plate.modes.clone();
        let at: Vec<Pose> =
            at.iter().map(|a| Pose { x: a[0], y: a[1], theta: a[2].to_radians() }).collect();
        let rig = Rig::new(RigConfig {
            plate,
            kinds: vec![part.clone()],
            parts: vec![0; at.len()],
            at: Some(at),
            seed: seeds.0,
            noise: DEFAULT_NOISE,
        })
        .map_err(DemoError::Rig)?;
        let options = ServeOptions {
            port: port.to_string(),
            listen: SocketAddr::from(([127, 0, 0, 1], 0)),
            fail: None,
            seed: seeds.1,
            pick_time: DEFAULT_PICK_TIME,
        };
        let (addr_tx, addr_rx) = mpsc::channel();
        let (stop, stop_rx) = tokio::sync::mpsc::unbounded_channel();
        let thread = std::thread::spawn(move || {
            let announce = |addr: SocketAddr| addr_tx.send(addr).map_err(std::io::Error::other);
            serve(rig, &options, announce, stop_rx)
        });
        let mut rig = VirtualRig { url: String::new(), modes, stop, thread: Some(thread) };
        match addr_rx.recv_timeout(LISTEN_WITHIN) {
            Ok(addr) => {
                rig.url = format!("http://{addr}/frame.png");
                Ok(rig)
            }
            // The thread ended before it listened: its error says why.
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                Err(rig.stopped().err().unwrap_or(DemoError::RigEnded))
            }
            // Still trying to reach the controller: left to end with the demo, not waited for.
            Err(mpsc::RecvTimeoutError::Timeout) => {
                let _ = rig.stop.send(());
                rig.thread = None;
                Err(DemoError::RigSilent { within_s: LISTEN_WITHIN.as_secs() })
            }
        }
    }

    /// Stops the camera and waits for its thread; the error that ended it early, if any.
    pub fn stopped(&mut self) -> Result<(), DemoError> {
        let _ = self.stop.send(());
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(Err(e))) => Err(DemoError::Rig(e)),
            Some(Err(_)) => Err(DemoError::RigEnded),
            _ => Ok(()),
        }
    }
}

impl Drop for VirtualRig {
    fn drop(&mut self) {
        let _ = self.stopped();
    }
}
