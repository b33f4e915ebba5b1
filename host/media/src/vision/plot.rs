//! `chladni locate --plot`: the rectified photo with each located part's outline drawn at its
//! pose (green face up, blue flipped) and each unknown blob marked by a red cross.

use image::{GrayImage, Rgb, RgbImage};
use imageproc::drawing::draw_line_segment_mut;

use super::{Report, Template};
use chladni_core::model::part::Part;

/// The rings of `part` placed at centroid `c` (mm) and orientation `theta_deg`.
pub fn placed(part: &Part, c: [f64; 2], theta_deg: f64) -> Vec<Vec<[f64; 2]>> {
    let pc = part.centroid();
    let (s, co) = theta_deg.to_radians().sin_cos();
    part.rings()
        .map(|r| {
            r.iter()
                .map(|p| {
                    let (x, y) = (p[0] - pc[0], p[1] - pc[1]);
                    [c[0] + co * x - s * y, c[1] + s * x + co * y]
                })
                .collect()
        })
        .collect()
}

/// The figure: the rectified view `img` (pixel size `pix` mm, plate height `h_mm`) with the
/// report drawn over it.
pub fn draw(img: &GrayImage, report: &Report, templates: &[Template], h_mm: f64) -> RgbImage {
    let pix = report.pixel_mm;
    let mut out = RgbImage::from_fn(img.width(), img.height(), |x, y| {
        let g = img.get_pixel(x, y)[0];
        Rgb([g, g, g])
    });
    let px = |q: [f64; 2]| ((q[0] / pix) as f32, ((h_mm - q[1]) / pix) as f32);
    for l in &report.parts {
        let t = &templates[l.kind];
        let part = if l.flipped { t.mirrored.as_ref().unwrap_or(&t.part) } else { &t.part };
        let colour = if l.flipped { Rgb([40, 120, 255]) } else { Rgb([0, 200, 60]) };
        for ring in placed(part, [l.x_mm, l.y_mm], l.theta_deg) {
            for k in 0..ring.len() {
                draw_line_segment_mut(
                    &mut out,
                    px(ring[k]),
                    px(ring[(k + 1) % ring.len()]),
                    colour,
                );
            }
        }
    }
    for u in &report.unknown {
        let (x, y) = px([u.x_mm, u.y_mm]);
        let red = Rgb([230, 30, 30]);
        draw_line_segment_mut(&mut out, (x - 8.0, y - 8.0), (x + 8.0, y + 8.0), red);
        draw_line_segment_mut(&mut out, (x - 8.0, y + 8.0), (x + 8.0, y - 8.0), red);
    }
    out
}
