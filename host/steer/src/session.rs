//! The hardware side of the loop: bursts on the controller and frames from the camera.
//!
//! A burst is a manual drive (`Drive` at the mode's frequency and amplitude) stopped by the
//! host after the burst's length, then waited for until the controller reports it idle: the
//! length the plate really shook is the controller's count of samples, not the host's clock
//! (`Driven::driven_s`). Manual drive rather than a stored one-step plan: a plan would be
//! written to the controller's flash on every burst, thousands a session. A frame counts only
//! if taken after the drive stopped and the parts settled (`settle`, after the controller said
//! idle); the camera proves its frame's time (docs/camera.md). Every exit path stops the
//! drive: errors stop it before they return, and dropping the session stops it.

use std::time::{Duration, Instant, SystemTime};

use crate::camera::{Camera, Frame};
use chladni_core::model::part::Part;
use chladni_core::model::plate::Mode;
use chladni_device::client::DeviceClient;
use chladni_media::vision::track::{Near, track};
use chladni_media::vision::{self, Levels, Located, Template};
use chladni_shared::icd::link::{DriveState, StatusReport};
use chladni_shared::icd::sense::Level;
use chladni_shared::icd::units::{MilliHz, Q15, s_from_samples};

use crate::LoopError;

/// How long the host waits for the controller to report idle after a stop.
const STOP_WITHIN: Duration = Duration::from_secs(3);
/// How often the host looks at the clock and the interrupt flag during a burst.
const TICK: Duration = Duration::from_millis(5);
/// How often the controller's status is asked while waiting for the stop.
const STATUS_POLL: Duration = Duration::from_millis(10);

/// What a session needs besides its link and camera.
#[derive(Debug, Clone)]
pub struct SessionConfig {
    /// Plate size (mm).
    pub size_mm: [f64; 2],
    /// The plate's corners in the frame (px), when given; found in the first frame otherwise
    /// and kept (the camera is fixed over the plate).
    pub corners: Option<[[f64; 2]; 4]>,
    /// How long the parts take to come to rest after the drive stopped (bouncing, sliding).
    pub settle: Duration,
}

/// One burst as it happened.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Driven {
    /// The burst length asked for (s).
    pub commanded_s: f64,
    /// The drive's own count of the samples it output for this burst, ramps included (s).
    pub driven_s: f64,
}

/// The parts seen in one frame.
#[derive(Debug, Clone)]
pub struct Sighting {
    /// When the frame was taken.
    pub taken: SystemTime,
    /// How long the frame took to arrive and the parts to be located.
    pub took: Duration,
    /// Every part found, in no particular order.
    pub parts: Vec<Located>,
}

/// Whether the user asked to stop (Ctrl-C): asked at every wait.
pub type Interrupted = Box<dyn Fn() -> bool + Send>;

/// A controller link, a camera, the part kinds to look for and the plate's corners.
pub struct Session {
    client: DeviceClient,
    camera: Camera,
    templates: Vec<Template>,
    config: SessionConfig,
    interrupted: Interrupted,
    /// Frames must be taken at or after this time.
    settled_at: SystemTime,
    /// A drive command may be in effect (a stop is owed).
    driving: bool,
    /// The grey levels of the last full locate and every part it found: what the next frame
    /// is tracked from.
    last: Option<(Levels, Vec<Located>)>,
}

impl Session {
    /// A session over `client` and `camera` looking for the part kinds `kinds`; once
    /// `interrupted()` (Ctrl-C), any wait ends with [`LoopError::Interrupted`] after stopping
    /// the drive.
    pub fn new(
        client: DeviceClient,
        camera: Camera,
        kinds: &[Part],
        config: SessionConfig,
        interrupted: Interrupted,
    ) -> Session {
        let templates = kinds.iter().map(Template::new).collect();
        let settled_at = SystemTime::now();
        Session {
            client,
            camera,
            templates,
            config,
            interrupted,
            settled_at,
            driving: false,
            last: None,
        }
    }

    /// The part kinds' templates, in the order given.
    pub fn templates(&self) -> &[Template] {
        &self.templates
    }

    /// The plate's corners in the frame, once known.
    pub fn corners(&self) -> Option<[[f64; 2]; 4]> {
        self.config.corners
    }

    /// A frame taken after the last burst settled, and the parts in it.
    pub fn look(&mut self) -> Result<(Sighting, Frame), LoopError> {
        self.check_interrupt()?;
        let start = Instant::now();
        let frame = match self.camera.frame_after(self.settled_at) {
            Ok(f) => f,
            Err(e) => return Err(self.stopped(e.into())),
        };
        let parts = match self.parts_in(&frame.image) {
            Ok(p) => p,
            Err(e) => return Err(self.stopped(e)),
        };
        let sighting = Sighting { taken: frame.taken, took: start.elapsed(), parts };
        Ok((sighting, frame))
    }

    /// The parts in a frame: tracked near where the last frame showed them (a window around
    /// each, `vision::track`), or, on the first frame and whenever a part is not found in its
    /// window, located in the whole frame (which also finds the corners once and the grey
    /// levels tracking thresholds by).
    fn parts_in(&mut self, image: &image::GrayImage) -> Result<Vec<Located>, LoopError> {
        let size = self.config.size_mm;
        if let (Some((levels, last)), Some(corners)) = (&self.last, self.config.corners) {
            let near: Vec<Near> = last.iter().map(Near::from).collect();
            let tracked = track(image, &self.templates, size, corners, levels, &near);
            if let Some(found) = tracked.ok().and_then(|t| t.all_found()) {
                self.last = Some((*levels, found.clone()));
                return Ok(found);
            }
        }
        let (report, _) = vision::locate(image, &self.templates, size, self.config.corners)?;
        self.config.corners.get_or_insert(report.corners);
        self.last = Some((report.levels, report.parts.clone()));
        Ok(report.parts)
    }

    /// Drives `mode` for `secs` seconds, stops, waits for the controller to be idle, and
    /// notes when the parts will have settled.
    pub fn burst(&mut self, mode: &Mode, secs: f64) -> Result<Driven, LoopError> {
        self.check_interrupt()?;
        let freq = MilliHz::rounded(mode.freq_hz).map(|f| f.0).unwrap_or(0);
        let level = Level::Drive(Q15::from_fraction(mode.amplitude).map(|q| q.0).unwrap_or(0));
        self.driving = true;
        if let Err(e) = self.client.drive(freq, level) {
            return Err(self.stopped(e.into()));
        }
        let until = Instant::now() + Duration::from_secs_f64(secs.max(0.0));
        while Instant::now() < until {
            if (self.interrupted)() {
                return Err(self.stopped(LoopError::Interrupted));
            }
            std::thread::sleep(TICK.min(until.saturating_duration_since(Instant::now())));
        }
        let status = self.stop_and_wait()?;
        let driven_s = s_from_samples(status.elapsed_samples, status.sample_rate);
        self.settled_at = SystemTime::now() + self.config.settle;
        Ok(Driven { commanded_s: secs, driven_s })
    }

    /// Stops the drive and waits until the controller reports it idle; a fault is an error.
    pub fn stop_and_wait(&mut self) -> Result<StatusReport, LoopError> {
        let stop = self.client.stop();
        self.driving = false;
        stop?;
        let asked = Instant::now();
        loop {
            let status = self.client.status()?;
            if let Some(fault) = status.fault {
                return Err(LoopError::Fault(format!("{fault:?}")));
            }
            if status.state == DriveState::Idle {
                return Ok(status);
            }
            if asked.elapsed() > STOP_WITHIN {
                let state = format!("{:?}", status.state);
                return Err(LoopError::NoStop { within_s: STOP_WITHIN.as_secs_f64(), state });
            }
            std::thread::sleep(STATUS_POLL);
        }
    }

    /// `Err(Interrupted)` (the drive stopped) once Ctrl-C was pressed.
    fn check_interrupt(&mut self) -> Result<(), LoopError> {
        if (self.interrupted)() {
            return Err(self.stopped(LoopError::Interrupted));
        }
        Ok(())
    }

    /// `error`, after stopping the drive if a command may be in effect.
    fn stopped(&mut self, error: LoopError) -> LoopError {
        if self.driving {
            let _ = self.stop_and_wait();
        }
        error
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        if self.driving {
            let _ = self.client.stop();
        }
    }
}
