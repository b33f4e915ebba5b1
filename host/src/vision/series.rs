//! Observations for the speed fit from a series of timestamped photos of one part moving on the
//! plate (`chladni plate calibrate-speed --photos DIR`, docs/plate.md "Calibrating from
//! photos").
//!
//! Each photo's time is read from its file name ([`time_from_name`]); each photo is searched
//! with [`crate::vision::locate`] for the one part; the earliest photo gives the start pose and
//! every later one a pose after a time, `t − t₀`. That is valid because the motion model is
//! autonomous (the velocity depends on the pose alone): a run from the pose seen at t₀ is the
//! run from wherever the part was when the mode was switched on, shifted by t₀. So the drive
//! only has to be on by the first photo; the camera's clock needs no relation to it.

use std::path::{Path, PathBuf};

use crate::model::part::Part;
use crate::motion::sim::Pose;
use crate::plate::photo::input::{self, PhotoError};
use crate::vision::{self, LocateError, Located, Template};

use crate::model::observations::{Measured, Observation};

/// Why a photo series gives no observations.
#[derive(Debug, thiserror::Error)]
pub enum PhotoSeriesError {
    /// The directory cannot be listed.
    #[error("--photos {dir}: cannot list the directory: {reason}")]
    Dir {
        /// The directory.
        dir: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// No PNG files in it.
    #[error(
        "--photos {0}: no photos (*.png) in the directory; name each photo with its time, e.g. \
         t012.500.png or run_12500ms.png (docs/plate.md)"
    )]
    NoPhotos(PathBuf),
    /// A file name that holds no time.
    #[error("{file}: {reason}")]
    UnreadableTime {
        /// The photo.
        file: PathBuf,
        /// What is wrong with its name.
        reason: String,
    },
    /// Two photos at the same time.
    #[error("{a} and {b} both carry the time {t_s} s: each photo needs its own time")]
    DuplicateTime {
        /// One photo.
        a: PathBuf,
        /// The other.
        b: PathBuf,
        /// The time (s).
        t_s: f64,
    },
    /// Only one photo.
    #[error(
        "--photos {0}: only one photo; the fit needs at least 2 (the first gives the start, \
         each later one a pose after a time), better 5–10 while the part moves"
    )]
    TooFew(PathBuf),
    /// The photo cannot be read.
    #[error("{0}")]
    Photo(#[from] PhotoError),
    /// The photo cannot be searched (no plate, bad corners, …).
    #[error("{file}: {source}")]
    Locate {
        /// The photo.
        file: PathBuf,
        /// Why.
        source: LocateError,
    },
    /// The part is not located in a photo.
    #[error(
        "{file}: part {part} not found on the plate ({seen}); every photo must show the whole \
         part, alone, not touching the rim or another part"
    )]
    PartNotFound {
        /// The photo.
        file: PathBuf,
        /// Part name.
        part: String,
        /// What was seen instead.
        seen: String,
    },
    /// Several copies of the part in a photo.
    #[error(
        "{file}: {count} copies of part {part} on the plate; calibrate with one part at a time"
    )]
    SeveralParts {
        /// The photo.
        file: PathBuf,
        /// Part name.
        part: String,
        /// How many were located.
        count: usize,
    },
    /// The part lies on another face than in the first photo.
    #[error(
        "{file}: part {part} lies on its other face than in {first}; a part that turns over \
         between photos cannot be fitted (the model never flips a part): start the series again"
    )]
    FaceChanged {
        /// The photo.
        file: PathBuf,
        /// The first photo.
        first: PathBuf,
        /// Part name.
        part: String,
    },
}

impl PhotoSeriesError {
    /// The error's name in `--json` output.
    pub fn name(&self) -> &'static str {
        match self {
            PhotoSeriesError::Dir { .. } => "bad_photos_dir",
            PhotoSeriesError::NoPhotos(_) => "no_photos",
            PhotoSeriesError::UnreadableTime { .. } => "unreadable_time",
            PhotoSeriesError::DuplicateTime { .. } => "duplicate_time",
            PhotoSeriesError::TooFew(_) => "too_few_photos",
            PhotoSeriesError::Photo(PhotoError::TooLarge { .. }) => "too_large",
            PhotoSeriesError::Photo(_) => "not_a_photo",
            PhotoSeriesError::Locate { source, .. } => source.name(),
            PhotoSeriesError::PartNotFound { .. } => "part_not_found",
            PhotoSeriesError::SeveralParts { .. } => "several_parts",
            PhotoSeriesError::FaceChanged { .. } => "face_changed",
        }
    }
}

/// A decimal number of digits with at most one point (no sign, no exponent).
fn decimal(s: &str) -> Option<f64> {
    let ok = !s.is_empty()
        && s.chars().all(|c| c.is_ascii_digit() || c == '.')
        && s.chars().filter(|&c| c == '.').count() <= 1
        && s.chars().any(|c| c.is_ascii_digit());
    ok.then(|| s.parse().ok()).flatten()
}

/// The time (s) one name token gives: `12500ms`, `t12.5`, `t012.500`, `12.5s` or `t12.5s`.
fn token_time(tok: &str) -> Option<f64> {
    if let Some(ms) = tok.strip_suffix("ms") {
        return decimal(ms).map(|v| v / 1000.0);
    }
    let (body, t) = tok.strip_prefix('t').map_or((tok, false), |b| (b, true));
    let (body, s) = body.strip_suffix('s').map_or((body, false), |b| (b, true));
    if t || s { decimal(body) } else { None }
}

/// The time (s) in a photo's file name: the stem (the name without its extension) split at
/// `_`, `-` and spaces must hold exactly one time token, `<N>ms` (milliseconds), or `t<N>`,
/// `<N>s`, `t<N>s` (seconds), N a decimal number: `t012.500.png`, `run_12500ms.png`,
/// `cam-3_t12.5s.png`.
pub fn time_from_name(path: &Path) -> Result<f64, PhotoSeriesError> {
    let fail = |reason: String| PhotoSeriesError::UnreadableTime { file: path.into(), reason };
    let stem = path.file_stem().and_then(|s| s.to_str()).ok_or_else(|| {
        fail("the file name is not valid UTF-8; rename it, e.g. t012.500.png".into())
    })?;
    let times: Vec<f64> = stem.split(['_', '-', ' ']).filter_map(token_time).collect();
    match times[..] {
        [t] if t.is_finite() => Ok(t),
        [] | [_] => Err(fail(format!(
            "no time in the file name `{stem}`: name it t<seconds> or <milliseconds>ms, e.g. \
             t012.500.png or run_12500ms.png"
        ))),
        _ => Err(fail(format!(
            "{} times in the file name `{stem}`: keep exactly one (t<seconds> or <ms>ms)",
            times.len()
        ))),
    }
}

/// The photos (`*.png`, any case) in `dir` with their times, earliest first.
pub fn list(dir: &Path) -> Result<Vec<(PathBuf, f64)>, PhotoSeriesError> {
    let fail = |e: std::io::Error| PhotoSeriesError::Dir { dir: dir.into(), reason: e.to_string() };
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(fail)? {
        let path = entry.map_err(fail)?.path();
        let png = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
        let hidden = path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with('.'));
        if png && !hidden && path.is_file() {
            let t = time_from_name(&path)?;
            out.push((path, t));
        }
    }
    out.sort_by(|a, b| a.1.total_cmp(&b.1).then_with(|| a.0.cmp(&b.0)));
    if out.is_empty() {
        return Err(PhotoSeriesError::NoPhotos(dir.into()));
    }
    if let Some(w) = out.windows(2).find(|w| w[0].1 == w[1].1) {
        let (a, b, t_s) = (w[0].0.clone(), w[1].0.clone(), w[0].1);
        return Err(PhotoSeriesError::DuplicateTime { a, b, t_s });
    }
    if out.len() < 2 {
        return Err(PhotoSeriesError::TooFew(dir.into()));
    }
    Ok(out)
}

/// The part as located in one photo.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Sighting {
    /// The photo.
    pub file: PathBuf,
    /// Its time (s, from the file name).
    pub t_s: f64,
    /// The pose found.
    pub located: Located,
}

/// Locates the one `part` in each photo (times from [`list`]); `corners` as for
/// [`vision::locate`] (the same for every photo: a fixed camera), `None` to find them.
pub fn locate_all(
    photos: &[(PathBuf, f64)],
    part: &Part,
    size_mm: [f64; 2],
    corners: Option<[[f64; 2]; 4]>,
) -> Result<Vec<Sighting>, PhotoSeriesError> {
    let templates = [Template::new(part)];
    let mut out: Vec<Sighting> = Vec::new();
    for (file, t_s) in photos {
        let img = input::read(file)?;
        let (report, _) = vision::locate(&img, &templates, size_mm, corners)
            .map_err(|source| PhotoSeriesError::Locate { file: file.clone(), source })?;
        let located = match &report.parts[..] {
            [one] => one.clone(),
            [] => {
                let seen: Vec<String> = (report.unknown.iter())
                    .map(|u| format!("{:?} blob of {:.0} mm²", u.why, u.area_mm2).to_lowercase())
                    .collect();
                let seen = if seen.is_empty() { "nothing".into() } else { seen.join(", ") };
                let name = part.name.clone();
                return Err(PhotoSeriesError::PartNotFound {
                    file: file.clone(),
                    part: name,
                    seen,
                });
            }
            many => {
                let (part, count) = (part.name.clone(), many.len());
                return Err(PhotoSeriesError::SeveralParts { file: file.clone(), part, count });
            }
        };
        if let Some(first) = out.first().filter(|f| f.located.flipped != located.flipped) {
            return Err(PhotoSeriesError::FaceChanged {
                file: file.clone(),
                first: first.file.clone(),
                part: part.name.clone(),
            });
        }
        out.push(Sighting { file: file.clone(), t_s: *t_s, located });
    }
    Ok(out)
}

/// The fit's observations of part 0: the first sighting is the start, each later one a pose
/// after `t − t₀` (with its orientation); `line` is the photo's place in time order (1 =
/// the first). A flipped part is fitted as its mirror image ([`Part::mirrored`]), whose θ
/// `locate` reports.
pub fn observations(sightings: &[Sighting]) -> Vec<Observation> {
    let Some(first) = sightings.first() else { return Vec::new() };
    let f = &first.located;
    let start = Pose { x: f.x_mm, y: f.y_mm, theta: f.theta_deg.to_radians() };
    (sightings.iter().enumerate().skip(1))
        .map(|(k, s)| Observation {
            line: k + 1,
            part: 0,
            start,
            measured: Measured::PoseAfter {
                t_s: s.t_s - first.t_s,
                x_mm: s.located.x_mm,
                y_mm: s.located.y_mm,
                theta_deg: Some(s.located.theta_deg),
            },
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_are_read_from_file_names() {
        let t = |n: &str| time_from_name(Path::new(n));
        assert_eq!(t("t012.500.png").unwrap(), 12.5);
        assert_eq!(t("dir/run_12500ms.png").unwrap(), 12.5);
        assert_eq!(t("cam-3_t12.5s.PNG").unwrap(), 12.5);
        assert_eq!(t("shot 7s.png").unwrap(), 7.0);
        assert_eq!(t("t0.png").unwrap(), 0.0);
        for bad in ["photo.png", "t.png", "t1.2.3.png", "t-1.png", "a_1s_2s.png", "1e3ms.png"] {
            let e = t(bad).unwrap_err();
            assert_eq!(e.name(), "unreadable_time", "{bad}: {e}");
            assert!(e.to_string().contains(bad), "{e}");
        }
    }
}
