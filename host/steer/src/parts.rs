//! The parts the loop follows: which given part each located one is, from frame to frame.
//!
//! The first frame names them: the parts of each kind, as many as were given of it (fewer is
//! [`LoopError::MissingParts`]). Later frames keep each part's identity by nearness: a part is
//! the located part of its kind nearest where it was (bursts move parts by millimetres, parts
//! lie tens apart); none of its kind within [`LOST_MM`] is [`LoopError::LostPart`].

use chladni_core::model::part::Part;
use chladni_core::model::pose::Pose;
use chladni_core::steer::cost::Piece;
use chladni_media::vision::Located;

use crate::LoopError;

/// A part not found within this distance (mm) of where it was is lost.
pub const LOST_MM: f64 = 60.0;

/// One part kind: both faces prepared for the motion model.
#[derive(Debug, Clone)]
pub struct Kind {
    /// The part as given.
    pub part: Part,
    /// Face up.
    pub up: Piece,
    /// On its other face ([`Part::mirrored`]).
    pub flipped: Piece,
}

impl Kind {
    /// Both faces of `part`.
    pub fn new(part: Part) -> Kind {
        let flipped = Piece::new(&part.mirrored());
        Kind { up: Piece::new(&part), flipped, part }
    }

    /// The piece of the face a part lies on.
    pub fn piece(&self, flipped: bool) -> &Piece {
        if flipped { &self.flipped } else { &self.up }
    }
}

/// A followed part: its kind and where it was last seen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tracked {
    /// Index into the kinds.
    pub kind: usize,
    /// Pose (mm, rad).
    pub pose: Pose,
    /// Lies on its other face.
    pub flipped: bool,
}

/// A located part as a pose (mm, rad).
pub fn pose_of(l: &Located) -> Pose {
    Pose { x: l.x_mm, y: l.y_mm, theta: l.theta_deg.to_radians() }
}

/// The parts named in a first frame: for each given part (its kind), a located part of that
/// kind, in the frame's order (bottom to top, then left to right).
pub fn first(kinds: &[Kind], given: &[usize], seen: &[Located]) -> Result<Vec<Tracked>, LoopError> {
    let mut taken = vec![false; seen.len()];
    let mut out = Vec::with_capacity(given.len());
    for &kind in given {
        let Some(k) = (0..seen.len()).find(|&k| !taken[k] && seen[k].kind == kind) else {
            let count = |list: &mut dyn Iterator<Item = usize>| list.filter(|&k| k == kind).count();
            return Err(LoopError::MissingParts {
                part: kinds[kind].part.name.clone(),
                given: count(&mut given.iter().copied()),
                seen: count(&mut seen.iter().map(|l| l.kind)),
            });
        };
        taken[k] = true;
        out.push(Tracked { kind, pose: pose_of(&seen[k]), flipped: seen[k].flipped });
    }
    Ok(out)
}

/// The followed parts in a new frame: each the nearest located part of its kind, parts
/// nearest their last pose claimed first.
pub fn follow(
    kinds: &[Kind],
    last: &[Tracked],
    seen: &[Located],
) -> Result<Vec<Tracked>, LoopError> {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, t) in last.iter().enumerate() {
        for (k, l) in seen.iter().enumerate().filter(|(_, l)| l.kind == t.kind) {
            pairs.push(((l.x_mm - t.pose.x).hypot(l.y_mm - t.pose.y), i, k));
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut now: Vec<Option<Tracked>> = vec![None; last.len()];
    let mut taken = vec![false; seen.len()];
    for (d, i, k) in pairs {
        if d <= LOST_MM && now[i].is_none() && !taken[k] {
            taken[k] = true;
            now[i] = Some(Tracked {
                kind: last[i].kind,
                pose: pose_of(&seen[k]),
                flipped: seen[k].flipped,
            });
        }
    }
    now.into_iter()
        .zip(last)
        .enumerate()
        .map(|(index, (n, t))| {
            n.ok_or_else(|| LoopError::LostPart {
                index,
                part: kinds[t.kind].part.name.clone(),
                x_mm: t.pose.x,
                y_mm: t.pose.y,
            })
        })
        .collect()
}
