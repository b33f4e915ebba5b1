//! Reading a photo safely: the format is taken from the file's content (not its name), the
//! pixel count from its header is checked against [`MAX_PIXELS`] before any pixel is decoded,
//! and a photo over [`WORK_PIXELS`] is scaled down before the node finder sees it.

use std::path::{Path, PathBuf};

use image::{GrayImage, ImageReader};

/// Most pixels a photo may have: 50 MP (8000 × 6000 is 48 MP, the largest phone and most
/// camera sensors). Decoding is linear in pixels but holds the whole picture, up to 8 bytes a
/// pixel (RGBA16) before the grey conversion, so this bounds memory at about 400 MB; a
/// 20 000 × 20 000 PNG (a few hundred kB compressed) would need 3.2 GB.
pub const MAX_PIXELS: u64 = 50_000_000;

/// Photos with more pixels than this (2 MP, e.g. 1730 × 1150) are scaled down before the node
/// finder runs. Its cost grows faster than the pixel count (the skeleton thinning takes as many
/// passes as the sand bands are pixels wide, and the Hough accumulator grows with the side), and
/// 2 MP of a 300 mm plate is 5.8 px/mm: a sand band (σ ≈ 3 mm) is still 35 px wide and a 4 mm
/// lentil 23 px across.
pub const WORK_PIXELS: u64 = 2_000_000;

/// Why a photo cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum PhotoError {
    /// The file cannot be opened or decoded.
    #[error("cannot read image {path}: {reason}")]
    Read {
        /// The photo.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// Its header announces more pixels than [`MAX_PIXELS`].
    #[error(
        "image {path} is {w}×{h} px ({mp:.0} MP), over the limit of {limit} MP; scale it \
         down first (the node finder works at about {work} MP anyway)",
        mp = *w as f64 * *h as f64 / 1e6,
        limit = MAX_PIXELS / 1_000_000,
        work = WORK_PIXELS / 1_000_000
    )]
    TooLarge {
        /// The photo.
        path: PathBuf,
        /// Width (px).
        w: u32,
        /// Height (px).
        h: u32,
    },
}

fn reader(path: &Path) -> Result<ImageReader<std::io::BufReader<std::fs::File>>, PhotoError> {
    let fail = |e: std::io::Error| PhotoError::Read { path: path.into(), reason: e.to_string() };
    ImageReader::open(path).map_err(fail)?.with_guessed_format().map_err(fail)
}

/// Reads a photo as grey levels: the format from the content, the size checked on the header
/// before decoding.
pub fn read(path: &Path) -> Result<GrayImage, PhotoError> {
    decode_checked(path, || reader(path))
}

/// The same for a photo in memory (one posted to the cell), named `name` in errors.
pub fn read_bytes(bytes: &[u8], name: &Path) -> Result<GrayImage, PhotoError> {
    let fail = |e: std::io::Error| PhotoError::Read { path: name.into(), reason: e.to_string() };
    decode_checked(name, || {
        ImageReader::new(std::io::Cursor::new(bytes)).with_guessed_format().map_err(fail)
    })
}

/// Decodes what `open` reads (called twice: once for the header, once for the pixels), the
/// header's pixel count checked against [`MAX_PIXELS`] first.
fn decode_checked<R: std::io::BufRead + std::io::Seek>(
    path: &Path,
    open: impl Fn() -> Result<ImageReader<R>, PhotoError>,
) -> Result<GrayImage, PhotoError> {
    let fail = |e: image::ImageError| PhotoError::Read { path: path.into(), reason: e.to_string() };
    let (w, h) = open()?.into_dimensions().map_err(fail)?;
    if u64::from(w) * u64::from(h) > MAX_PIXELS {
        return Err(PhotoError::TooLarge { path: path.into(), w, h });
    }
    let mut r = open()?;
    // The header was checked above; these limits hold the decoder to it.
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    r.limits(limits);
    Ok(r.decode().map_err(fail)?.to_luma8())
}

/// The photo scaled down (area-averaging) to at most [`WORK_PIXELS`], or as it is.
pub(crate) fn working_size(img: GrayImage) -> GrayImage {
    let (w, h) = img.dimensions();
    let px = u64::from(w) * u64::from(h);
    if px <= WORK_PIXELS {
        return img;
    }
    let s = (WORK_PIXELS as f64 / px as f64).sqrt();
    let (nw, nh) = (((w as f64 * s).floor() as u32).max(1), ((h as f64 * s).floor() as u32).max(1));
    image::imageops::resize(&img, nw, nh, image::imageops::FilterType::Triangle)
}

/// Refuses a plate size whose aspect ratio contradicts a photo cropped to the plate: the
/// ratios W/H of `size_mm` and of the `w`×`h` px photo must agree within 15 % (cropping by eye
/// and lens distortion are a few %), else the message names both and the likely swap.
pub(crate) fn check_aspect(size_mm: [f64; 2], w: u32, h: u32) -> Result<(), String> {
    let plate = size_mm[0] / size_mm[1];
    let photo = w as f64 / h as f64;
    if (plate / photo).ln().abs() <= 1.15f64.ln() {
        return Ok(());
    }
    let swap = if (1.0 / plate / photo).ln().abs() <= 1.15f64.ln() {
        format!("; did you mean --size-mm {} {}?", size_mm[1], size_mm[0])
    } else {
        "; crop the photo to the plate's edges, or give --corners".to_string()
    };
    Err(format!(
        "--size-mm {} {} has aspect ratio W/H = {plate:.3}, but the {w}×{h} px photo (cropped to \
         the plate) has {photo:.3}{swap}",
        size_mm[0], size_mm[1]
    ))
}
