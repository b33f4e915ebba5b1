//! Observations for the speed fit from a series of timestamped photos of one part moving on the
//! plate (`chladni plate calibrate-speed --photos DIR`, docs/plate.md "Calibrating from
//! photos").
//!
//! Each photo's time is read from its file name ([`time_from_name`]) or, when the names hold
//! none, from its EXIF `DateTimeOriginal` + `SubSecTimeOriginal` ([`exif_time`], JPEG and PNG
//! eXIf); one source for the whole series, since the two are different clocks. Each photo is
//! searched
//! with [`crate::vision::locate`] for the one part; the earliest photo gives the start pose and
//! every later one a pose after a time, `t − t₀`. That is valid because the motion model is
//! autonomous (the velocity depends on the pose alone): a run from the pose seen at t₀ is the
//! run from wherever the part was when the mode was switched on, shifted by t₀. So the drive
//! only has to be on by the first photo; the camera's clock needs no relation to it.

use std::path::{Path, PathBuf};

use crate::vision::{self, LocateError, Located, Template};
use chladni_core::model::part::Part;
use chladni_core::model::pose::Pose;
use chladni_core::plate::photo::input::{self, PhotoError};

use chladni_core::model::observations::{Measured, Observation};

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
    /// No photo files in it.
    #[error(
        "--photos {0}: no photos (*.png, *.jpg, *.jpeg) in the directory; name each photo with \
         its time, e.g. t012.500.png or run_12500ms.png, or keep the camera's EXIF times \
         (docs/plate.md)"
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

/// Where a series' times come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeSource {
    /// The file names ([`time_from_name`]).
    FileName,
    /// The EXIF `DateTimeOriginal` (+ `SubSecTimeOriginal`) of each photo ([`exif_time`]).
    Exif,
}

/// The photos of a series with their times (s), earliest first, and where the times come from.
#[derive(Debug, Clone)]
pub struct Listing {
    /// Each photo and its time.
    pub photos: Vec<(PathBuf, f64)>,
    /// The times' source.
    pub source: TimeSource,
    /// When every photo has both times and their intervals disagree: which is used, by how
    /// much they differ.
    pub note: Option<String>,
}

/// Days from 1970-01-01 to the civil date (proleptic Gregorian).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The first ASCII value of EXIF field `tag`, if present.
fn ascii(exif: &exif::Exif, tag: exif::Tag) -> Option<Vec<u8>> {
    match &exif.get_field(tag, exif::In::PRIMARY)?.value {
        exif::Value::Ascii(v) => v.first().cloned(),
        _ => None,
    }
}

/// The time a photo was taken from its EXIF `DateTimeOriginal` and `SubSecTimeOriginal` (s on
/// the camera's clock, from 1970 in its own time zone) and that time's resolution (1 s without
/// the sub-second field); `Err` says why there is none.
pub fn exif_time(path: &Path) -> Result<(f64, f64), String> {
    let file = std::fs::File::open(path).map_err(|e| format!("cannot open it: {e}"))?;
    let exif = exif::Reader::new()
        .read_from_container(&mut std::io::BufReader::new(file))
        .map_err(|e| format!("no EXIF data ({e})"))?;
    let raw = ascii(&exif, exif::Tag::DateTimeOriginal).ok_or("no EXIF DateTimeOriginal")?;
    let mut dt = exif::DateTime::from_ascii(&raw)
        .map_err(|e| format!("EXIF DateTimeOriginal {:?}: {e}", String::from_utf8_lossy(&raw)))?;
    let mut resolution = 1.0;
    if let Some(sub) = ascii(&exif, exif::Tag::SubSecTimeOriginal) {
        let digits = sub.iter().take_while(|c| c.is_ascii_digit()).count().min(9);
        dt.parse_subsec(&sub).map_err(|e| format!("EXIF SubSecTimeOriginal: {e}"))?;
        if digits > 0 {
            resolution = 10f64.powi(-(digits as i32));
        }
    }
    let ok = (1..=12).contains(&dt.month)
        && (1..=31).contains(&dt.day)
        && dt.hour < 24
        && dt.minute < 60
        && dt.second <= 60;
    if !ok {
        return Err(format!("EXIF DateTimeOriginal {dt} is not a valid date and time"));
    }
    let days = days_from_civil(i64::from(dt.year), i64::from(dt.month), i64::from(dt.day));
    let secs = days * 86_400
        + i64::from(dt.hour) * 3600
        + i64::from(dt.minute) * 60
        + i64::from(dt.second);
    Ok((secs as f64 + f64::from(dt.nanosecond.unwrap_or(0)) * 1e-9, resolution))
}

/// The photos (`*.png`, `*.jpg`, `*.jpeg`, any case; not hidden) in `dir`.
fn photo_files(dir: &Path) -> Result<Vec<PathBuf>, PhotoSeriesError> {
    let fail = |e: std::io::Error| PhotoSeriesError::Dir { dir: dir.into(), reason: e.to_string() };
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(fail)? {
        let path = entry.map_err(fail)?.path();
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        let photo = matches!(ext.as_deref(), Some("png" | "jpg" | "jpeg"));
        let hidden = path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with('.'));
        if photo && !hidden && path.is_file() {
            out.push(path);
        }
    }
    out.sort();
    Ok(out)
}

/// The times of `files` from one source: the file names when every name holds a time (a note
/// when every photo's EXIF time is there too and its intervals disagree), else the EXIF times
/// when every photo has one, else the first photo with neither (or whose name alone lacks a
/// time) is refused.
fn choose_times(files: Vec<PathBuf>) -> Result<Listing, PhotoSeriesError> {
    let names: Vec<Result<f64, PhotoSeriesError>> =
        files.iter().map(|f| time_from_name(f)).collect();
    let exifs: Vec<Result<(f64, f64), String>> = files.iter().map(|f| exif_time(f)).collect();
    if names.iter().all(Result::is_ok) {
        let t: Vec<f64> = names.into_iter().flatten().collect();
        let note = exifs.iter().all(Result::is_ok).then(|| disagreement(&t, &exifs)).flatten();
        let photos = files.into_iter().zip(t).collect();
        return Ok(Listing { photos, source: TimeSource::FileName, note });
    }
    if exifs.iter().all(Result::is_ok) {
        let photos = files.into_iter().zip(exifs.into_iter().flatten().map(|e| e.0)).collect();
        return Ok(Listing { photos, source: TimeSource::Exif, note: None });
    }
    let k = names.iter().position(Result::is_err).unwrap_or(0);
    let exif = match &exifs[k] {
        Err(why) => format!("and {why}"),
        Ok(_) => "and its EXIF time cannot stand in: other photos have no EXIF time, and a \
                  series needs every time from one clock"
            .into(),
    };
    match names.into_iter().nth(k) {
        Some(Err(PhotoSeriesError::UnreadableTime { file, reason })) => {
            Err(PhotoSeriesError::UnreadableTime { file, reason: format!("{reason}; {exif}") })
        }
        Some(Err(e)) => Err(e),
        _ => Err(PhotoSeriesError::NoPhotos(PathBuf::new())),
    }
}

/// When the names' times `t` and the EXIF times disagree on some photo's interval from the
/// first by more than the EXIF resolution (plus the names' millisecond): the note saying so.
fn disagreement(t: &[f64], exifs: &[Result<(f64, f64), String>]) -> Option<String> {
    let e: Vec<(f64, f64)> = exifs.iter().filter_map(|x| x.as_ref().ok().copied()).collect();
    let first = (0..t.len()).min_by(|&a, &b| t[a].total_cmp(&t[b]))?;
    let resolution = e.iter().map(|x| x.1).fold(0.0, f64::max) + 1e-3;
    let worst =
        (0..t.len()).map(|i| ((t[i] - t[first]) - (e[i].0 - e[first].0)).abs()).fold(0.0, f64::max);
    (worst > resolution).then(|| {
        format!(
            "times from the file names; the photos' EXIF times (DateTimeOriginal) disagree with \
             them by up to {worst:.3} s between photos: rename the photos from the camera's \
             times to use those"
        )
    })
}

/// The photos in `dir` with their times, earliest first, and where the times come from.
pub fn list(dir: &Path) -> Result<Listing, PhotoSeriesError> {
    let mut listing = choose_times(photo_files(dir)?)?;
    let out = &mut listing.photos;
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
    Ok(listing)
}

/// The part as located in one photo.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Sighting {
    /// The photo.
    pub file: PathBuf,
    /// Its time (s, from the file name or the EXIF: `time_source`).
    pub t_s: f64,
    /// Where that time comes from.
    pub time_source: TimeSource,
    /// The pose found.
    pub located: Located,
}

/// Locates the one `part` in each photo of `listing` ([`list`]); `corners` as for
/// [`vision::locate`] (the same for every photo: a fixed camera), `None` to find them.
pub fn locate_all(
    listing: &Listing,
    part: &Part,
    size_mm: [f64; 2],
    corners: Option<[[f64; 2]; 4]>,
) -> Result<Vec<Sighting>, PhotoSeriesError> {
    let templates = [Template::new(part)];
    let mut out: Vec<Sighting> = Vec::new();
    for (file, t_s) in &listing.photos {
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
        // A face the photo cannot tell (`face_certain` false) is no evidence of a turn-over.
        let certain = located.face_certain;
        let turned = |f: &&Sighting| {
            certain && f.located.face_certain && f.located.flipped != located.flipped
        };
        if let Some(first) = out.first().filter(turned) {
            return Err(PhotoSeriesError::FaceChanged {
                file: file.clone(),
                first: first.file.clone(),
                part: part.name.clone(),
            });
        }
        let time_source = listing.source;
        out.push(Sighting { file: file.clone(), t_s: *t_s, time_source, located });
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
    use image::ImageEncoder;

    /// TIFF-structured EXIF holding `DateTimeOriginal` (and `SubSecTimeOriginal`).
    fn exif_bytes(when: &str, sub: Option<&str>) -> Vec<u8> {
        let field = |tag, v: &str| exif::Field {
            tag,
            ifd_num: exif::In::PRIMARY,
            value: exif::Value::Ascii(vec![v.as_bytes().to_vec()]),
        };
        let dt = field(exif::Tag::DateTimeOriginal, when);
        let ss = sub.map(|v| field(exif::Tag::SubSecTimeOriginal, v));
        let mut w = exif::experimental::Writer::new();
        w.push_field(&dt);
        if let Some(ss) = &ss {
            w.push_field(ss);
        }
        let mut buf = std::io::Cursor::new(Vec::new());
        w.write(&mut buf, false).unwrap();
        buf.into_inner()
    }

    /// A small grey photo at `path` (JPEG or PNG by its extension) carrying `exif`.
    fn write_photo(path: &Path, exif: Option<Vec<u8>>) {
        let img = image::GrayImage::from_pixel(32, 24, image::Luma([128]));
        let mut out = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
        let jpeg = path.extension().is_some_and(|e| e == "jpg");
        let (w, h, c) = (32, 24, image::ExtendedColorType::L8);
        if jpeg {
            let mut e = image::codecs::jpeg::JpegEncoder::new(&mut out);
            if let Some(x) = exif {
                e.set_exif_metadata(x).unwrap();
            }
            e.write_image(img.as_raw(), w, h, c).unwrap();
        } else {
            let mut e = image::codecs::png::PngEncoder::new(&mut out);
            if let Some(x) = exif {
                e.set_exif_metadata(x).unwrap();
            }
            e.write_image(img.as_raw(), w, h, c).unwrap();
        }
    }

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("chladni-series-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn exif_times_are_read_from_jpeg_and_png_and_names_still_win() {
        // JPEG and PNG (eXIf) mixed, over midnight into a new year: the EXIF clock alone.
        let d = scratch("exif");
        let shots = [
            ("a.jpg", "2025:12:31 23:59:58", Some("250")),
            ("b.png", "2026:01:01 00:00:00", Some("75")),
            ("c.jpg", "2026:01:01 00:00:02", None),
        ];
        for (name, when, sub) in shots {
            write_photo(&d.join(name), Some(exif_bytes(when, sub)));
        }
        let l = list(&d).unwrap();
        assert_eq!(l.source, TimeSource::Exif);
        let t: Vec<f64> = l.photos.iter().map(|p| p.1 - l.photos[0].1).collect();
        assert!((t[1] - 2.5).abs() < 1e-6 && (t[2] - 3.75).abs() < 1e-6, "{t:?}");
        assert_eq!(exif_time(&d.join("a.jpg")).unwrap().1, 0.001);
        assert_eq!(exif_time(&d.join("c.jpg")).unwrap().1, 1.0);
        // Names holding times win; agreeing EXIF says nothing, disagreeing EXIF is named.
        std::fs::rename(d.join("a.jpg"), d.join("t0.jpg")).unwrap();
        std::fs::rename(d.join("b.png"), d.join("t2.5.png")).unwrap();
        std::fs::rename(d.join("c.jpg"), d.join("t3.75.jpg")).unwrap();
        let l = list(&d).unwrap();
        assert_eq!((l.source, l.note.as_deref()), (TimeSource::FileName, None));
        std::fs::rename(d.join("t3.75.jpg"), d.join("t6.jpg")).unwrap();
        let l = list(&d).unwrap();
        let note = l.note.unwrap();
        assert!(note.contains("from the file names") && note.contains("2.250 s"), "{note}");
        // A photo with neither time is refused, naming both reasons.
        write_photo(&d.join("shot.png"), None);
        let e = list(&d).unwrap_err();
        assert_eq!(e.name(), "unreadable_time");
        assert!(e.to_string().contains("shot.png") && e.to_string().contains("no EXIF"), "{e}");
        // A bad date in the EXIF is no time.
        write_photo(&d.join("shot.png"), Some(exif_bytes("2026:13:01 00:00:00", None)));
        assert!(exif_time(&d.join("shot.png")).unwrap_err().contains("not a valid date"));
        let _ = std::fs::remove_dir_all(&d);
    }

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
