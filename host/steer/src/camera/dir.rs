//! A folder a camera writes images to: the newest `*.png`, `*.jpg` or `*.jpeg` by modification
//! time is the current frame, and its modification time is when it was taken.

use std::fs;
use std::io::ErrorKind;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use super::{CameraError, CameraOptions, Fetched, Frame, POLL};

/// How long to wait before reading a file that failed to decode once more: a camera may still
/// be writing it (50 ms is a few times the write of a 1–5 MB frame to a local disk).
const REREAD: Duration = Duration::from_millis(50);

pub(super) struct Folder {
    path: PathBuf,
    /// The file and modification time of the last frame returned.
    last: Option<(PathBuf, SystemTime)>,
}

impl Folder {
    /// Checks that `path` is a folder.
    pub(super) fn open(path: &Path) -> Result<Folder, CameraError> {
        let meta = fs::metadata(path)
            .map_err(|e| CameraError::NotAFolder { path: path.into(), reason: e.to_string() })?;
        if !meta.is_dir() {
            return Err(CameraError::NotAFolder { path: path.into(), reason: "a file".into() });
        }
        Ok(Folder { path: path.into(), last: None })
    }

    /// The newest image modified at or after `not_before`, by `deadline`.
    pub(super) fn frame_after(
        &mut self,
        not_before: SystemTime,
        deadline: Instant,
        options: &CameraOptions,
    ) -> Result<Fetched, CameraError> {
        loop {
            let newest = self.newest()?;
            if let Some((file, mtime)) = &newest
                && *mtime >= not_before
                && let Some(fetched) = self.read(file, *mtime)?
            {
                return Ok(fetched);
            }
            if Instant::now() + POLL > deadline {
                let seconds = options.timeout.as_secs_f64();
                return Err(match newest {
                    None => CameraError::EmptyFolder { path: self.path.clone(), seconds },
                    Some((_, mtime)) => CameraError::Stale {
                        camera: format!("dir:{}", self.path.display()),
                        newest_s: super::unix_s(mtime),
                        wanted_s: super::unix_s(not_before),
                        seconds,
                    },
                });
            }
            std::thread::sleep(POLL);
        }
    }

    /// The newest image file and its modification time (ties: the last name), if any. Files
    /// that vanish while listed are skipped: cameras rotate their files.
    fn newest(&self) -> Result<Option<(PathBuf, SystemTime)>, CameraError> {
        let entries = fs::read_dir(&self.path).map_err(|e| CameraError::NotAFolder {
            path: self.path.clone(),
            reason: e.to_string(),
        })?;
        let mut best: Option<(PathBuf, SystemTime)> = None;
        for entry in entries.flatten() {
            let file = entry.path();
            if !is_image_name(&file) {
                continue;
            }
            let Ok(meta) = entry.metadata() else { continue };
            let Ok(mtime) = meta.modified() else { continue };
            if meta.is_file() && best.as_ref().is_none_or(|(f, t)| (mtime, &file) > (*t, f)) {
                best = Some((file, mtime));
            }
        }
        Ok(best)
    }

    /// Reads and decodes `file`; one that fails to decode is read once more after [`REREAD`]
    /// (it may be half-written) before it is called broken. `None` when it vanished.
    fn read(&mut self, file: &Path, mtime: SystemTime) -> Result<Option<Fetched>, CameraError> {
        let from = file.display().to_string();
        let t0 = Instant::now();
        let Some(mut bytes) = read_file(file)? else { return Ok(None) };
        let mut fetch = t0.elapsed();
        let mut taken = mtime;
        let image = match super::decode(&from, &bytes) {
            Ok(image) => image,
            Err(e @ CameraError::TooLarge { .. }) => return Err(e),
            Err(_) => {
                std::thread::sleep(REREAD);
                let t0 = Instant::now();
                let Some(again) = read_file(file)? else { return Ok(None) };
                fetch = t0.elapsed();
                bytes = again;
                // Finishing the write moves the modification time on.
                taken = fs::metadata(file).and_then(|m| m.modified()).unwrap_or(mtime);
                super::decode(&from, &bytes)?
            }
        };
        let new = self.last.as_ref() != Some(&(file.to_path_buf(), taken));
        self.last = Some((file.into(), taken));
        let digest = super::digest(&bytes);
        let frame = Frame { image, taken, digest, bytes: bytes.len(), fetch };
        Ok(Some(Fetched { frame, new }))
    }
}

/// The file's bytes, `None` when it is gone.
fn read_file(file: &Path) -> Result<Option<Vec<u8>>, CameraError> {
    match fs::read(file) {
        Ok(bytes) => Ok(Some(bytes)),
        Err(e) if e.kind() == ErrorKind::NotFound => Ok(None),
        Err(e) => Err(CameraError::UnreadableFile { path: file.into(), reason: e.to_string() }),
    }
}

/// Whether the name ends in .png, .jpg or .jpeg (any case).
fn is_image_name(file: &Path) -> bool {
    file.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["png", "jpg", "jpeg"].iter().any(|x| e.eq_ignore_ascii_case(x)))
}
