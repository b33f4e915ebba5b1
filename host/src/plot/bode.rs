//! The Bode plot of a frequency sweep (PNG or SVG, by the file's extension): the measured
//! acceleration amplitude on a log-frequency axis, the phase below it on the same axis, and
//! each resonance marked by a dashed line labelled with its frequency and Q.

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::prelude::*;

use super::{Figure, PlotError, text, write_chart};
use crate::controller::sweep::{Resonance, SweepSample};

const MARK: RGBColor = RGBColor(200, 40, 40);

/// Writes the Bode plot of `samples` with `resonances` marked (points without a measurement
/// are left out; a sweep with none draws empty axes).
pub fn bode_figure(
    path: &Path,
    title: &str,
    samples: &[SweepSample],
    resonances: &[Resonance],
) -> Result<(), PlotError> {
    write_chart(path, &BodeFigure { title, samples, resonances })
}

/// What [`bode_figure`] draws.
struct BodeFigure<'a> {
    title: &'a str,
    samples: &'a [SweepSample],
    resonances: &'a [Resonance],
}

impl Figure for BodeFigure<'_> {
    fn size(&self) -> (u32, u32) {
        (900, 620)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE).map_err(text)?;
        let root = root.titled(self.title, ("sans-serif", 18)).map_err(text)?;
        let (top, bottom) = root.split_vertically(330);
        let range = freq_range(self.samples);
        draw_magnitude(&top, range.clone(), self.samples, self.resonances)?;
        draw_phase(&bottom, range, self.samples, self.resonances)
    }
}

/// The frequency axis: the sweep's span (a decade around 1 Hz when there is nothing to show).
fn freq_range(samples: &[SweepSample]) -> Range<f64> {
    let lo = samples.iter().map(|s| s.freq_hz).filter(|f| *f > 0.0).fold(f64::INFINITY, f64::min);
    let hi = samples.iter().map(|s| s.freq_hz).fold(0.0, f64::max);
    if lo.is_finite() && hi > lo { lo..hi } else { 1.0..10.0 }
}

/// Frequency ticks: 1, 1.5, 2, 3, 5, 7 × 10ⁿ inside `range` (plotters' log axis labels only
/// powers of ten, i.e. nothing inside the decade or so a sweep spans).
fn ticks(range: &Range<f64>) -> Vec<f64> {
    let mut out = Vec::new();
    let mut decade = 10f64.powf(range.start.max(1e-3).log10().floor());
    while decade <= range.end {
        for m in [1.0, 1.5, 2.0, 3.0, 5.0, 7.0] {
            let f = m * decade;
            if range.contains(&f) {
                out.push(f);
            }
        }
        decade *= 10.0;
    }
    out
}

/// A frequency tick's label: whole hertz (tenths below 10 Hz).
fn hz_label(f: &f64) -> String {
    if *f >= 10.0 { format!("{f:.0}") } else { format!("{f:.1}") }
}

/// Dashed vertical lines at each resonance, from `y.start` to `y.end`.
fn mark_resonances<DB: DrawingBackend, X, Y>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<X, Y>>,
    resonances: &[Resonance],
    y: Range<f64>,
) -> Result<(), String>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
    DB::ErrorType: 'static,
{
    for r in resonances {
        let line = [(r.freq_hz, y.start), (r.freq_hz, y.end)];
        chart.draw_series(DashedLineSeries::new(line, 6, 4, MARK.stroke_width(1))).map_err(text)?;
    }
    Ok(())
}

fn draw_magnitude<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    range: Range<f64>,
    samples: &[SweepSample],
    resonances: &[Resonance],
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let top = samples.iter().filter_map(|s| s.accel_mps2).fold(0.0, f64::max).max(1e-3) * 1.15;
    let mut c = ChartBuilder::on(area)
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(range.clone().log_scale().with_key_points(ticks(&range)), 0.0..top)
        .map_err(text)?;
    c.configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc("acceleration (m/s²)")
        .x_label_formatter(&hz_label)
        .label_style(("sans-serif", 12))
        .draw()
        .map_err(text)?;
    let points = samples.iter().filter_map(|s| s.accel_mps2.map(|a| (s.freq_hz, a)));
    c.draw_series(LineSeries::new(points, BLUE.stroke_width(2))).map_err(text)?;
    mark_resonances(&mut c, resonances, 0.0..top)?;
    for r in resonances {
        let q = r.q.map_or("Q ?".to_string(), |q| format!("Q {q:.0}"));
        let label = format!("{:.1} Hz, {q}", r.freq_hz);
        let y = (r.accel_mps2 * 1.03).min(top * 0.97);
        c.draw_series([Text::new(
            label,
            (r.freq_hz, y),
            ("sans-serif", 13).into_font().color(&MARK),
        )])
        .map_err(text)?;
    }
    Ok(())
}

fn draw_phase<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    range: Range<f64>,
    samples: &[SweepSample],
    resonances: &[Resonance],
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let mut c = ChartBuilder::on(area)
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(range.clone().log_scale().with_key_points(ticks(&range)), -180.0..180.0)
        .map_err(text)?;
    c.configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc("phase (°)")
        .x_label_formatter(&hz_label)
        .label_style(("sans-serif", 12))
        .draw()
        .map_err(text)?;
    let points = samples.iter().filter_map(|s| s.phase_deg.map(|p| (s.freq_hz, p)));
    c.draw_series(points.map(|p| Circle::new(p, 2, BLUE.filled()))).map_err(text)?;
    mark_resonances(&mut c, resonances, -180.0..180.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bode_plot_is_written_as_png_and_svg_with_and_without_measurements() {
        let dir = std::env::temp_dir().join(format!("chladni-bode-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let samples: Vec<SweepSample> = (0..50)
            .map(|i| {
                let f = 50.0 * 1.04f64.powi(i);
                let r = f / 181.5;
                let a = r * r / ((1.0 - r * r).powi(2) + (0.04 * r).powi(2)).sqrt();
                let phase = (-(0.04 * r)).atan2(1.0 - r * r).to_degrees();
                SweepSample {
                    freq_hz: f,
                    accel_mps2: (i % 9 != 0).then_some(a),
                    phase_deg: (i % 9 != 0).then_some(phase),
                }
            })
            .collect();
        let res = [Resonance { freq_hz: 181.6, q: Some(25.0), accel_mps2: 25.0 }];
        let path = dir.join("bode.png");
        bode_figure(&path, "sweep", &samples, &res).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        // The same figure as SVG: a document usvg reads, with both axes, the curve and the
        // resonance's label.
        let svg = dir.join("bode.svg");
        bode_figure(&svg, "sweep", &samples, &res).unwrap();
        let text = std::fs::read_to_string(&svg).unwrap();
        let tree = usvg::Tree::from_str(&text, &usvg::Options::default()).unwrap();
        assert!(tree.root().has_children());
        let doc = roxmltree::Document::parse(&text).unwrap();
        let texts: Vec<&str> = doc
            .descendants()
            .filter(|n| n.has_tag_name("text"))
            .filter_map(|n| n.text().map(str::trim))
            .collect();
        for want in ["frequency (Hz)", "acceleration (m/s²)", "phase (°)", "181.6 Hz, Q 25"] {
            assert!(texts.contains(&want), "{want} not in {texts:?}");
        }
        assert!(doc.descendants().any(|n| n.has_tag_name("polyline")), "no magnitude curve");
        let empty = dir.join("empty.png");
        bode_figure(&empty, "nothing measured", &[], &[]).unwrap();
        assert!(std::fs::metadata(&empty).unwrap().len() > 1000);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
