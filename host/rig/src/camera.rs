//! The rig's camera: photos of the parts at their poses rendered by
//! [`chladni_media::vision::synth`] (perspective, lens blur, uneven light, sensor noise from a
//! seed), encoded as PNG or JPEG.

use std::io::Cursor;

use chladni_core::model::part::Part;
use chladni_media::vision::synth::{Photo, Placed, render};
use image::GrayImage;
use image::codecs::jpeg::JpegEncoder;

use crate::RigError;

/// JPEG quality of a frame (as a snapshot camera's default).
pub const JPEG_QUALITY: u8 = 90;

/// How a frame is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// PNG (lossless).
    Png,
    /// JPEG at [`JPEG_QUALITY`].
    Jpeg,
}

impl Format {
    /// The HTTP content type.
    pub fn content_type(self) -> &'static str {
        match self {
            Format::Png => "image/png",
            Format::Jpeg => "image/jpeg",
        }
    }
}

/// What the camera sees that does not move: the plate's size and where its corners lie in
/// the picture, and the part kinds.
#[derive(Debug, Clone)]
pub struct Camera {
    /// Plate size [W, H] (mm).
    pub size_mm: [f64; 2],
    /// The plate's corners in the picture (px; bottom-left, bottom-right, top-right,
    /// top-left).
    pub corners: [[f64; 2]; 4],
    /// The part kinds ([`Placed::part`] indexes them).
    pub kinds: Vec<Part>,
}

impl Camera {
    /// The camera of [`Photo::standard`] (1280 × 900 px, its perspective) over a plate of
    /// `size_mm`: the standard corners for a 3:2 plate, shrunk about their centre along the
    /// long side for any other shape.
    pub fn standard(size_mm: [f64; 2], kinds: Vec<Part>) -> Camera {
        let standard = Photo::standard(Vec::new(), Vec::new(), 0);
        let (ref_aspect, aspect) =
            (standard.size_mm[0] / standard.size_mm[1], size_mm[0] / size_mm[1]);
        let (sx, sy) = if aspect < ref_aspect {
            (aspect / ref_aspect, 1.0)
        } else {
            (1.0, ref_aspect / aspect)
        };
        let c = standard.corners;
        let centre =
            [c.iter().map(|p| p[0]).sum::<f64>() / 4.0, c.iter().map(|p| p[1]).sum::<f64>() / 4.0];
        let corners =
            c.map(|p| [centre[0] + sx * (p[0] - centre[0]), centre[1] + sy * (p[1] - centre[1])]);
        Camera { size_mm, corners, kinds }
    }

    /// The photo of the parts `placed`, its sensor noise from `seed`.
    pub fn photo(&self, placed: Vec<Placed>, seed: u64) -> GrayImage {
        let mut photo = Photo::standard(self.kinds.clone(), placed, seed);
        photo.size_mm = self.size_mm;
        photo.corners = self.corners;
        render(&photo)
    }

    /// [`Camera::photo`] encoded.
    pub fn frame(
        &self,
        placed: Vec<Placed>,
        seed: u64,
        format: Format,
    ) -> Result<Vec<u8>, RigError> {
        encode(&self.photo(placed, seed), format)
    }
}

/// A photo encoded as `format`.
pub fn encode(img: &GrayImage, format: Format) -> Result<Vec<u8>, RigError> {
    let mut out = Cursor::new(Vec::new());
    let done = match format {
        Format::Png => img.write_to(&mut out, image::ImageFormat::Png),
        Format::Jpeg => {
            img.write_with_encoder(JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY))
        }
    };
    done.map_err(|e| RigError::Encode(e.to_string()))?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plate_keeps_its_shape_in_the_picture() {
        let kinds = Vec::new();
        let standard = Camera::standard([300.0, 200.0], kinds.clone());
        assert_eq!(standard.corners, Photo::standard(Vec::new(), Vec::new(), 0).corners);
        // A square plate: the quadrilateral narrows; its mean width/height ratio is the
        // standard's divided by 1.5.
        let ratio = |c: &[[f64; 2]; 4]| {
            let w = 0.5 * ((c[1][0] - c[0][0]) + (c[2][0] - c[3][0]));
            let h = 0.5 * ((c[0][1] - c[3][1]) + (c[1][1] - c[2][1]));
            w / h
        };
        let square = Camera::standard([200.0, 200.0], kinds.clone());
        assert!((ratio(&square.corners) * 1.5 - ratio(&standard.corners)).abs() < 1e-9);
        let wide = Camera::standard([400.0, 100.0], kinds);
        assert!((ratio(&wide.corners) / (4.0 / 1.5) - ratio(&standard.corners)).abs() < 1e-9);
        for c in wide.corners.iter().chain(&square.corners) {
            assert!((0.0..1280.0).contains(&c[0]) && (0.0..900.0).contains(&c[1]), "{c:?}");
        }
    }
}
