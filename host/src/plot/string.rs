//! The particle on a vibrating string (PNG): x(t) with the lines where bouncing ends, and
//! the averaged force with its `−c·sin 2x` fit (the paper's Fig. 12).

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{PlotError, text, write_figure};
use crate::motion::string::Experiment;

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// Writes the figure of an experiment (PNG): x(t) with the lines where bouncing ends, and
/// the averaged force with its `−c sin 2x` fit.
pub fn string_figure(path: &Path, ex: &Experiment) -> Result<(), PlotError> {
    write_figure(path, |tmp| {
        let root = BitMapBackend::new(tmp, (900, 360)).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let (left, right) = root.split_horizontally(450);
        draw_trajectory(&left, ex)?;
        draw_force(&right, ex)?;
        root.present().map_err(text)
    })
}

fn draw_trajectory(area: &Area<'_>, ex: &Experiment) -> Result<(), String> {
    let (p, traj) = (&ex.params, &ex.trajectory);
    let t_end = traj.samples.last().map_or(1.0, |s| s.0);
    let mut c = ChartBuilder::on(area)
        .caption(
            format!("particle on a string, e = {}, Γ = {:.2}", p.e, p.gamma()),
            ("sans-serif", 16),
        )
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(40)
        .build_cartesian_2d(0.0..t_end, 0.0..std::f64::consts::PI)
        .map_err(text)?;
    c.configure_mesh()
        .x_desc("time (s)")
        .y_desc("x")
        .label_style(("sans-serif", 11))
        .draw()
        .map_err(text)?;
    c.draw_series(LineSeries::new(traj.samples.iter().copied(), BLUE.stroke_width(2)))
        .map_err(text)?;
    // Where bouncing ends (Γ sin x = π(1−e)/(1+e)): the drift stops on these lines.
    for x in ex.stop_x.into_iter().flat_map(|x| [x, std::f64::consts::PI - x]) {
        c.draw_series(DashedLineSeries::new(
            [(0.0, x), (t_end, x)],
            6,
            4,
            RGBColor(120, 120, 120).stroke_width(1),
        ))
        .map_err(text)?;
    }
    Ok(())
}

fn draw_force(area: &Area<'_>, ex: &Experiment) -> Result<(), String> {
    let (profile, fit) = (&ex.profile, &ex.fit);
    let fmax = profile.iter().map(|(_, f)| f.abs()).fold(fit.c.abs(), f64::max).max(1e-9) * 1.1;
    let mut c = ChartBuilder::on(area)
        .caption(
            format!("avg force, fit -c sin 2x: c = {:.3}, R² = {:.2}", fit.c, fit.r2),
            ("sans-serif", 14),
        )
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..std::f64::consts::PI, -fmax..fmax)
        .map_err(text)?;
    c.configure_mesh()
        .x_desc("x")
        .y_desc("F (m/s²)")
        .label_style(("sans-serif", 11))
        .draw()
        .map_err(text)?;
    c.draw_series(profile.iter().map(|&(x, f)| Circle::new((x, f), 4, RED.filled())))
        .map_err(text)?;
    c.draw_series(LineSeries::new(
        (0..=100).map(|k| {
            let x = std::f64::consts::PI * k as f64 / 100.0;
            (x, -fit.c * (2.0 * x).sin())
        }),
        BLACK.stroke_width(2),
    ))
    .map_err(text)?;
    Ok(())
}
