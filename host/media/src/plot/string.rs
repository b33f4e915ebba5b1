//! The particle on a vibrating string (PNG or SVG): x(t) with the lines where bouncing ends,
//! and the averaged drift with its `−c·sin 2x` fit (the paper's Fig. 12 and eq. 10).

use std::f64::consts::PI;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{Figure, PlotError, text, write_chart};
use chladni_core::motion::string::Experiment;

/// Writes the figure of an experiment (PNG or SVG by the extension): x(t) with the lines where
/// bouncing ends, and the averaged drift with its `−c sin 2x` fit.
pub fn string_figure(path: &Path, ex: &Experiment) -> Result<(), PlotError> {
    write_chart(path, &StringFigure(ex))
}

struct StringFigure<'a>(&'a Experiment);

impl Figure for StringFigure<'_> {
    fn size(&self) -> (u32, u32) {
        (900, 360)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE).map_err(text)?;
        let (left, right) = root.split_horizontally(450);
        draw_trajectory(&left, self.0)?;
        draw_drift(&right, self.0)
    }
}

const TRACE: RGBColor = RGBColor(31, 90, 180);
const STOP: RGBColor = RGBColor(120, 120, 120);

/// The stop lines on the halves of the string the trajectory visits (x_stop, π − x_stop).
fn stop_lines(ex: &Experiment) -> Vec<f64> {
    let xs = || ex.trajectory.samples.iter().map(|s| s.1);
    let mut lines = Vec::new();
    if let Some(x) = ex.stop_x {
        if xs().any(|v| v <= PI / 2.0) {
            lines.push(x);
        }
        if xs().any(|v| v > PI / 2.0) {
            lines.push(PI - x);
        }
    }
    lines
}

/// The y range of x(t): the samples and their stop lines, padded, inside [0, π].
fn x_range(ex: &Experiment) -> (f64, f64) {
    let xs = ex.trajectory.samples.iter().map(|s| s.1);
    let (lo, hi) = xs
        .chain(stop_lines(ex))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| (lo.min(x), hi.max(x)));
    let pad = ((hi - lo) * 0.1).max(0.05);
    ((lo - pad).max(0.0), (hi + pad).min(PI))
}

fn draw_trajectory<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    ex: &Experiment,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let (p, traj) = (&ex.params, &ex.trajectory);
    let t_end = traj.samples.last().map_or(1.0, |s| s.0).max(1e-9);
    let (lo, hi) = x_range(ex);
    let mut c = ChartBuilder::on(area)
        .caption(
            format!("particle on a string, e = {}, Γ = {:.2}", p.e, p.gamma()),
            ("sans-serif", 16),
        )
        .margin(8)
        .margin_right(20)
        .x_label_area_size(34)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..t_end, lo..hi)
        .map_err(text)?;
    c.configure_mesh()
        .x_desc("time (s)")
        .y_desc("x (m; nodes at 0 and π)")
        .label_style(("sans-serif", 11))
        .x_label_formatter(&|v| super::tick(*v, t_end))
        .y_label_formatter(&|v| super::tick(*v, hi - lo))
        .draw()
        .map_err(text)?;
    c.draw_series(LineSeries::new(traj.samples.iter().copied(), TRACE.stroke_width(2)))
        .map_err(text)?
        .label("x(t)")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], TRACE.stroke_width(2)));
    // Where bouncing ends (Γ sin x = π(1−e)/(1+e)): the drift stops on these lines.
    for (k, x) in stop_lines(ex).into_iter().enumerate() {
        let s = c
            .draw_series(DashedLineSeries::new([(0.0, x), (t_end, x)], 6, 4, STOP.stroke_width(1)))
            .map_err(text)?;
        if k == 0 {
            s.label("bouncing ends")
                .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], STOP.stroke_width(1)));
        }
    }
    super::draw_legend(&mut c, 11, SeriesLabelPosition::UpperRight)
}

fn draw_drift<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    ex: &Experiment,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let (profile, fit) = (&ex.profile, &ex.fit);
    // mm/s: the drift velocities are 10⁻⁵…10⁻² m/s, readable ticks in mm/s.
    let vmax = profile.iter().map(|(_, v)| v.abs()).fold(fit.c.abs(), f64::max).max(1e-9) * 1.1e3;
    let mut c = ChartBuilder::on(area)
        .caption(
            format!("avg drift, fit −c sin 2x: c = {:.2e} m/s, R² = {:.2}", fit.c, fit.r2),
            ("sans-serif", 14),
        )
        .margin(8)
        .margin_right(20)
        .x_label_area_size(34)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..PI, -vmax..vmax)
        .map_err(text)?;
    c.configure_mesh()
        .x_desc("x (m)")
        .y_desc("drift v (mm/s)")
        .label_style(("sans-serif", 11))
        .y_label_formatter(&|v| super::tick(*v, vmax))
        .draw()
        .map_err(text)?;
    c.draw_series(profile.iter().map(|&(x, v)| Circle::new((x, v * 1e3), 4, RED.filled())))
        .map_err(text)?
        .label("held particles (8 each)")
        .legend(|(x, y)| Circle::new((x + 8, y), 4, RED.filled()));
    c.draw_series(LineSeries::new(
        (0..=100).map(|k| {
            let x = PI * k as f64 / 100.0;
            (x, -fit.c * 1e3 * (2.0 * x).sin())
        }),
        BLACK.stroke_width(2),
    ))
    .map_err(text)?
    .label("fit −c sin 2x")
    .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], BLACK.stroke_width(2)));
    super::draw_legend(&mut c, 11, SeriesLabelPosition::UpperLeft)
}
