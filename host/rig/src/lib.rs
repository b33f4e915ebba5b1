//! A virtual rig (`chladni rig`, docs/rig.md): a snapshot camera over a simulated plate whose
//! parts move by the project's motion model under whatever the controller drives, so camera
//! learning and steering can be tried without hardware.
//!
//! - [`truth`]: the true plate, which differs from the plate file the user gives (a plate file
//!   of its own, or the given plate with each mode's nodes shifted and speed scaled).
//! - [`drive`]: what the controller drove between two polls of its status, on its sample
//!   clock.
//! - [`rig`]: the parts on the true plate, moved for each stretch of drive, with bouncing
//!   noise; what `/truth` reports.
//! - [`camera`]: frames rendered by `chladni_media::vision::synth`.
//! - [`mod@serve`]: the follower thread and the HTTP server ([`serve()`]).

use std::net::SocketAddr;

use chladni_core::model::plate::ModelError;
use chladni_core::model::pose::Pose;
use chladni_core::motion::bulk::CannotPlace;
use chladni_device::client::DeviceError;
use serde::Serialize;

pub mod camera;
pub mod drive;
pub mod rig;
pub mod serve;
pub mod truth;

pub use rig::{DEFAULT_NOISE, Noise, Rig, RigConfig, Truth};
pub use serve::{DEFAULT_PICK_TIME, Fail, FailMode, PickRequest, ServeOptions, serve};
pub use truth::{DEFAULT_WARP, ModeTruth, TruePlate, Warp};

/// Everything that stops a rig.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// The given plate does not type.
    #[error("the given plate: {0}")]
    GivenPlate(ModelError),
    /// The true plate does not type.
    #[error("the true plate: {0}")]
    TruePlate(ModelError),
    /// A true plate of another size than the given one.
    #[error(
        "the true plate is {} × {} mm, the given plate {} × {} mm: they are one plate, so give \
         them one size",
        .truth[0], .truth[1], .given[0], .given[1]
    )]
    SizeMismatch {
        /// The given plate's size (mm).
        given: [f64; 2],
        /// The true plate's.
        truth: [f64; 2],
    },
    /// A range option that is no range.
    #[error("{flag} {min}..{max}: give {what}")]
    BadRange {
        /// The option.
        flag: &'static str,
        /// Its lower end.
        min: f64,
        /// Its upper end.
        max: f64,
        /// What it must be.
        what: &'static str,
    },
    /// No part to put on the plate.
    #[error("no part on the plate: give at least one --part")]
    NoParts,
    /// A part of a kind that is not among the kinds given.
    #[error("part {part} is of kind {kind}, but only {kinds} kinds are given")]
    NoSuchKind {
        /// The part (1-based).
        part: usize,
        /// Its kind (0-based index).
        kind: usize,
        /// Kinds given.
        kinds: usize,
    },
    /// `--at` poses that are not one per part.
    #[error(
        "--at gives {given} poses for {parts} parts: give one per part (in the order of --part, \
         each part's copies together), or none for random drops"
    )]
    AtCount {
        /// Poses given.
        given: usize,
        /// Parts on the plate.
        parts: usize,
    },
    /// An `--at` pose with the part over the plate's edge.
    #[error(
        "--at of part {part} ({}, {}, {}°): the part reaches over the {} × {} mm plate's edge; \
         move it inside",
        .at.x, .at.y, .at.theta.to_degrees(), .size_mm[0], .size_mm[1]
    )]
    AtOffPlate {
        /// The part (1-based).
        part: usize,
        /// The pose given.
        at: Pose,
        /// The plate's size.
        size_mm: [f64; 2],
    },
    /// Two `--at` poses that overlap.
    #[error("--at of parts {first} and {second}: the parts overlap; move one of them")]
    AtOverlap {
        /// The first part (1-based).
        first: usize,
        /// The second.
        second: usize,
    },
    /// The random drops found no room.
    #[error(transparent)]
    Place(#[from] CannotPlace),
    /// The true plate's file could not be written.
    #[error("writing the true plate: {0}")]
    WriteTruePlate(String),
    /// A frame could not be encoded.
    #[error("encoding a frame: {0}")]
    Encode(String),
    /// The controller could not be reached.
    #[error("cannot follow the controller at {port}: {reason}")]
    Link {
        /// The link.
        port: String,
        /// Why.
        reason: DeviceError,
    },
    /// The controller's link was lost while serving.
    #[error(
        "the controller link at {port} was lost: {reason}; the rig's camera stopped (start the \
         controller again, then the rig)"
    )]
    LinkLost {
        /// The link.
        port: String,
        /// Why.
        reason: DeviceError,
    },
    /// The address to listen on cannot be bound.
    #[error("cannot listen on {addr} (--listen): {reason}; choose another address or port 0")]
    Listen {
        /// The address.
        addr: SocketAddr,
        /// Why.
        reason: std::io::Error,
    },
    /// The async runtime or the terminal failed.
    #[error("{0}")]
    Runtime(std::io::Error),
}

impl RigError {
    /// The user's input is wrong (exit code 2), not the run.
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            RigError::GivenPlate(_)
                | RigError::TruePlate(_)
                | RigError::SizeMismatch { .. }
                | RigError::BadRange { .. }
                | RigError::NoParts
                | RigError::NoSuchKind { .. }
                | RigError::AtCount { .. }
                | RigError::AtOffPlate { .. }
                | RigError::AtOverlap { .. }
                | RigError::Place(_)
        )
    }
}

/// The line `chladni rig --json` prints once it listens (keys in alphabetical order).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ListeningJson {
    /// Parts on the plate.
    pub parts: usize,
    /// The true plate.
    pub true_plate: TruePlateJson,
    /// The frame's URL (`…/frame.png`; `…/frame.jpg` and `…/truth` beside it).
    pub url: String,
}

/// The true plate in [`ListeningJson`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TruePlateJson {
    /// Its modes and how they differ from the given plate's.
    pub modes: Vec<ModeTruth>,
    /// `"file"` (`--true-plate`) or `"warp"` (the given plate warped).
    pub source: &'static str,
    /// Where it was written (`--write-true-plate`).
    pub written: Option<String>,
}
