//! Chladni figures of plate modes (PNG): the sign of the mode shape, node lines, supports.

use plotters::prelude::*;
use std::path::Path;

use crate::model::plate_file::{Boundary, Plate};
use crate::plate::contour::Polyline;
use crate::plate::solver::Grid;

use super::{PlotError, text, write_figure};

/// Draws a Chladni figure: the sign of φ as two light tints, node lines in black, the supports
/// (clamped edge, hinge line, rod point) in red.
pub fn chladni_figure(
    path: &Path,
    title: &str,
    plate: &Plate,
    grid: &Grid,
    lines: &[Polyline],
) -> Result<(), PlotError> {
    write_figure(path, |tmp| draw(tmp, title, plate, grid, lines))
}

fn draw(
    path: &Path,
    title: &str,
    plate: &Plate,
    grid: &Grid,
    lines: &[Polyline],
) -> Result<(), String> {
    let [w, h] = plate.size_mm;
    let px_w = 520u32;
    let px_h = ((px_w as f64 - 60.0) * h / w + 90.0).clamp(200.0, 900.0) as u32;
    let root = BitMapBackend::new(path, (px_w, px_h)).into_drawing_area();
    root.fill(&WHITE).map_err(text)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 16))
        .margin(8)
        .x_label_area_size(28)
        .y_label_area_size(52)
        .build_cartesian_2d(0.0..w, 0.0..h)
        .map_err(text)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .label_style(("sans-serif", 11))
        .draw()
        .map_err(text)?;
    let (dx, dy) = (w / (grid.nx - 1) as f64, h / (grid.ny - 1) as f64);
    let pos = RGBColor(214, 228, 246);
    let neg = RGBColor(248, 222, 206);
    chart
        .draw_series((0..grid.ny).flat_map(|j| (0..grid.nx).map(move |i| (i, j))).map(|(i, j)| {
            let [x, y] = grid.point(i, j);
            let c = if grid.at(i, j) >= 0.0 { pos } else { neg };
            Rectangle::new(
                [
                    ((x - dx / 2.0).max(0.0), (y - dy / 2.0).max(0.0)),
                    ((x + dx / 2.0).min(w), (y + dy / 2.0).min(h)),
                ],
                c.filled(),
            )
        }))
        .map_err(text)?;
    for l in lines {
        chart
            .draw_series(LineSeries::new(l.iter().map(|p| (p[0], p[1])), BLACK.stroke_width(3)))
            .map_err(text)?;
    }
    let support = RED.stroke_width(4);
    match plate.boundary {
        Boundary::Cantilever => {
            chart.draw_series(LineSeries::new([(0.0, 0.0), (0.0, h)], support)).map_err(text)?;
        }
        Boundary::Free => {}
        Boundary::HingedRod => {
            let x = plate.hinge_x_mm;
            chart
                .draw_series(DashedLineSeries::new([(x, 0.0), (x, h)], 8, 6, RED.stroke_width(2)))
                .map_err(text)?;
            let [rx, ry] = plate.rod_mm;
            chart.draw_series([Circle::new((rx, ry), 6, RED.filled())]).map_err(text)?;
        }
    }
    root.present().map_err(text)?;
    Ok(())
}
