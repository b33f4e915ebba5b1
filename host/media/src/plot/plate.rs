//! Chladni figures of plate modes (PNG or SVG, by the file's extension): the sign of the mode
//! shape, node lines, supports.

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

use chladni_core::model::grid::Grid;
use chladni_core::model::plate_file::{Boundary, Plate};
use chladni_core::plate::contour::Polyline;

use super::{Figure, PlotError, text, write_chart};

/// Draws a Chladni figure: the sign of φ as two light tints, node lines in black, the supports
/// (clamped edge, hinge line, rod point) in red. PNG or SVG by the extension of `path`.
pub fn chladni_figure(
    path: &Path,
    title: &str,
    plate: &Plate,
    grid: &Grid,
    lines: &[Polyline],
) -> Result<(), PlotError> {
    write_chart(path, &ChladniFigure { title, plate, grid, lines })
}

/// What [`chladni_figure`] draws.
struct ChladniFigure<'a> {
    title: &'a str,
    plate: &'a Plate,
    grid: &'a Grid,
    lines: &'a [Polyline],
}

impl Figure for ChladniFigure<'_> {
    fn size(&self) -> (u32, u32) {
        let [w, h] = self.plate.size_mm;
        let px_w = 520u32;
        // The plot area is 520 − 82 px wide; 96 px for the caption and the x labels.
        (px_w, ((px_w as f64 - 82.0) * h / w + 96.0).clamp(200.0, 900.0) as u32)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        draw(root, self)
    }
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &ChladniFigure<'_>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let ChladniFigure { title, plate, grid, lines } = *fig;
    let [w, h] = plate.size_mm;
    root.fill(&WHITE).map_err(text)?;
    // The right margin holds half of the last x tick's label ("300"), which is centred on
    // the plate's right edge.
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 16))
        .margin(8)
        .margin_right(22)
        .x_label_area_size(34)
        .y_label_area_size(52)
        .build_cartesian_2d(0.0..w, 0.0..h)
        .map_err(text)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .label_style(("sans-serif", 12))
        .x_label_formatter(&|v| super::tick(*v, w))
        .y_label_formatter(&|v| super::tick(*v, h))
        .draw()
        .map_err(text)?;
    let pos = RGBColor(214, 228, 246);
    let neg = RGBColor(248, 222, 206);
    let cells = sign_runs(grid, [w, h]).into_iter().map(|(lo, hi, positive)| {
        Rectangle::new([lo, hi], if positive { pos } else { neg }.filled())
    });
    chart.draw_series(cells).map_err(text)?;
    for l in lines {
        chart
            .draw_series(LineSeries::new(l.iter().map(|p| (p[0], p[1])), BLACK.stroke_width(3)))
            .map_err(text)?;
    }
    draw_supports(&mut chart, plate)
}

/// A rectangle of one sign of φ: lower-left and upper-right corners (mm), φ ≥ 0.
type SignCell = ((f64, f64), (f64, f64), bool);

/// The sign of φ as rectangles (plate mm: lower-left, upper-right, φ ≥ 0): each grid point's
/// cell, with the runs of one sign along a row merged (an SVG of a few hundred rectangles
/// instead of one per grid point).
fn sign_runs(grid: &Grid, [w, h]: [f64; 2]) -> Vec<SignCell> {
    let (dx, dy) = (w / (grid.nx - 1) as f64, h / (grid.ny - 1) as f64);
    let mut out = Vec::new();
    for j in 0..grid.ny {
        let y = grid.point(0, j)[1];
        let (y0, y1) = ((y - dy / 2.0).max(0.0), (y + dy / 2.0).min(h));
        let mut start = 0;
        for i in 1..=grid.nx {
            let sign = grid.at(start, j) >= 0.0;
            if i < grid.nx && (grid.at(i, j) >= 0.0) == sign {
                continue;
            }
            let x0 = (grid.point(start, j)[0] - dx / 2.0).max(0.0);
            let x1 = (grid.point(i - 1, j)[0] + dx / 2.0).min(w);
            out.push(((x0, y0), (x1, y1), sign));
            start = i;
        }
    }
    out
}

/// The supports in red: the clamped edge, or the hinge line (dashed) and the rod's point.
fn draw_supports<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    plate: &Plate,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let h = plate.size_mm[1];
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
    Ok(())
}
