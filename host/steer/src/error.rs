//! Every way the loop fails, each with a name for `--json` and a message naming the value and
//! the fix. Whatever the failure, the drive was stopped before it is reported.

use crate::camera::CameraError;
use chladni_device::client::DeviceError;
use chladni_media::vision::LocateError;

/// A failure of the closed loop.
#[derive(Debug, thiserror::Error)]
pub enum LoopError {
    /// The camera failed (timeout, broken or frozen frames, an HTTP error).
    #[error("camera: {0}; the drive was stopped")]
    Camera(#[from] CameraError),
    /// The controller's link failed or refused a command.
    #[error("controller: {0}; the drive was stopped")]
    Device(#[from] DeviceError),
    /// The parts could not be located in a frame.
    #[error("locating the parts: {0}; the drive was stopped")]
    Locate(#[from] LocateError),
    /// A part seen before is not in the frame any more.
    #[error(
        "part {index} ({part}) is no longer seen (last at x {x_mm:.1} mm, y {y_mm:.1} mm): it \
         left the camera's view, fell off the plate or lies under another; the drive was \
         stopped. Put it back and start again"
    )]
    LostPart {
        /// Index of the part among those given.
        index: usize,
        /// Part name.
        part: String,
        /// Where it was last seen.
        x_mm: f64,
        /// Where it was last seen.
        y_mm: f64,
    },
    /// Fewer parts of a kind are on the plate than were given.
    #[error(
        "{seen} of the {given} parts {part} given are seen on the plate: put the others on the \
         plate, or give --part as many times as there are parts"
    )]
    MissingParts {
        /// Part name.
        part: String,
        /// How many were given.
        given: usize,
        /// How many the frame shows.
        seen: usize,
    },
    /// The drive did not come to rest after a stop.
    #[error(
        "the drive did not stop within {within_s} s after the burst (state {state}): check the controller"
    )]
    NoStop {
        /// How long the loop waited (s).
        within_s: f64,
        /// The drive's state at the end.
        state: String,
    },
    /// The controller latched a fault.
    #[error(
        "the controller faulted: {0}; clear it with `chladni device clear-fault` once the cause is fixed"
    )]
    Fault(String),
    /// The steering algorithms refused their input (a bug or a bad option).
    #[error("steering: {0}; the drive was stopped")]
    Steer(#[from] chladni_core::steer::SteerError),
    /// Ctrl-C.
    #[error("interrupted: the drive was stopped")]
    Interrupted,
}

impl LoopError {
    /// The failure's name in `--json` output.
    pub fn name(&self) -> &'static str {
        match self {
            LoopError::Camera(e) => e.name(),
            LoopError::Device(_) => "controller",
            LoopError::Locate(e) => e.name(),
            LoopError::LostPart { .. } => "lost_part",
            LoopError::MissingParts { .. } => "missing_parts",
            LoopError::NoStop { .. } => "no_stop",
            LoopError::Fault(_) => "fault",
            LoopError::Steer(_) => "steer",
            LoopError::Interrupted => "interrupted",
        }
    }
}
