//! The `plate from-photo` job as library calls: check the request before any work, rectify or
//! check the aspect ratio, scale the photo to the working size, find the nodes, refuse an
//! unconvincing result, and describe the nodes as plate-file `[[mode]]` entries.

use chladni_shared::icd::units::MilliHz;
use image::GrayImage;

use super::{Found, PhotoParams, find_lines, input, rectify};
use crate::model::modes_file;
use crate::model::part::MAX_COORD_MM;
use crate::model::plate_file::{ModeEntry, is_plate_side};
use crate::plate::node_field::{self, FieldError, NodeField};
use crate::plate::solver::{GRID_X_POINTS, grid_dims};

/// What to find in a photo and how to describe it.
#[derive(Debug, Clone)]
pub struct PhotoRequest {
    /// Plate size [W, H] (mm).
    pub size_mm: [f64; 2],
    /// The plate's corners in the photo (px), bottom-left first, counter-clockwise.
    pub corners: Option<[[f64; 2]; 4]>,
    /// Coarse grain diameter (mm); 0 for sand.
    pub grain_mm: f64,
    /// Drive frequency the photo was taken at (Hz).
    pub freq_hz: Option<f64>,
    /// One grid entry even if all nodes are straight.
    pub as_grid: bool,
    /// Grid points along x of a grid entry.
    pub grid: usize,
}

/// The grid entry's φ, or why there is none.
pub type PhotoGrid = Result<NodeField, FieldError>;

/// What the job found.
#[derive(Debug)]
pub struct PhotoOutcome {
    /// Lines and curves.
    pub found: Found,
    /// The grid node, when one is made (curves found, or `as_grid`).
    pub grid: Option<PhotoGrid>,
    /// The square-on view, when `corners` were given (full resolution).
    pub rectified: Option<GrayImage>,
}

impl PhotoRequest {
    /// Checks the numbers before any work: an `Err` names the value and the fix (bad input).
    pub fn check(&self) -> Result<(), String> {
        let size = self.size_mm;
        if !size.iter().all(|&v| is_plate_side(v)) {
            return Err(format!(
                "--size-mm must be two positive numbers of at most {MAX_COORD_MM} mm, got {size:?}"
            ));
        }
        // The drive's range, through the one frequency conversion and its message.
        if let Some(f) = self.freq_hz {
            MilliHz::from_hz(f).map_err(|e| format!("--freq-hz: {e}"))?;
        }
        if !GRID_X_POINTS.contains(&self.grid) {
            return Err(format!("--grid must be in {GRID_X_POINTS:?}, got {}", self.grid));
        }
        let short = size[0].min(size[1]);
        if !(self.grain_mm.is_finite() && self.grain_mm >= 0.0 && self.grain_mm < 0.1 * short) {
            return Err(format!(
                "--grain-mm must be in [0, {:.1}) (a tenth of the plate's short side), got {}",
                0.1 * short,
                self.grain_mm
            ));
        }
        if let Some(c) = &self.corners
            && !c.iter().flatten().all(|v| v.is_finite())
        {
            return Err(format!("--corners must be 8 finite numbers, got {c:?}"));
        }
        Ok(())
    }

    /// Runs the pipeline on a photo read by [`input::read`]. `Err` is bad input (corners,
    /// aspect ratio).
    pub fn run(&self, img: GrayImage) -> Result<PhotoOutcome, String> {
        let size = self.size_mm;
        let (img, rectified) = match self.corners {
            Some(corners) => {
                let r = rectify::rectify(&img, corners).map_err(|e| format!("--corners: {e}"))?;
                (r.clone(), Some(r))
            }
            None => {
                input::check_aspect(size, img.width(), img.height())?;
                (img, None)
            }
        };
        let img = input::working_size(img);
        // Grain size in pixels of the (rectified, scaled) photo.
        let mm_per_px = 0.5 * (size[0] / img.width() as f64 + size[1] / img.height() as f64);
        let params = PhotoParams { grain_px: self.grain_mm / mm_per_px, ..Default::default() };
        let found = find_lines(&img, size, &params);
        let grid = (self.as_grid || !found.curves.is_empty()).then(|| {
            let (nx, ny) = grid_dims(self.grid, size);
            node_field::node_field(&found.nodes(super::DEFAULT_SNAP), size, nx, ny)
        });
        Ok(PhotoOutcome { found, grid, rectified })
    }

    /// A mode name that tells photos of different frequencies apart in one plate file.
    fn entry_name(&self, what: &str) -> String {
        match self.freq_hz {
            Some(f) => format!("photo {f} Hz {what}"),
            None => format!("photo {what}"),
        }
    }

    /// The `[[mode]]` entries: one grid entry if there is a grid, else one entry with all the
    /// straight lines (a photo is taken at one drive frequency: one mode).
    pub fn entries(&self, out: &PhotoOutcome) -> Vec<ModeEntry> {
        match &out.grid {
            Some(Ok(field)) => {
                vec![modes_file::sampled_mode(&self.entry_name("nodes"), self.freq_hz, &field.grid)]
            }
            Some(Err(_)) => Vec::new(),
            None if out.found.lines.is_empty() => Vec::new(),
            None => {
                let lines: Vec<(f64, f64)> =
                    out.found.lines.iter().map(|l| (l.angle_deg, l.offset_mm)).collect();
                let what =
                    if lines.len() == 1 { "line".into() } else { format!("{} lines", lines.len()) };
                vec![modes_file::lines_mode(&self.entry_name(&what), self.freq_hz, &lines)]
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::PhotoRequest;

    fn request(size_mm: [f64; 2]) -> PhotoRequest {
        let grid = *crate::plate::solver::GRID_X_POINTS.start();
        PhotoRequest { size_mm, corners: None, grain_mm: 0.0, freq_hz: None, as_grid: false, grid }
    }

    #[test]
    fn the_plate_size_takes_the_plate_files_rule() {
        assert_eq!(request([300.0, 200.0]).check(), Ok(()));
        for bad in [[1e308, 200.0], [300.0, 0.0], [f64::NAN, 200.0], [100_001.0, 200.0]] {
            let e = request(bad).check().unwrap_err();
            assert!(e.contains("at most 100000 mm") && e.contains("--size-mm"), "{bad:?}: {e}");
        }
    }
}
