//! The Bode plot of a frequency sweep (PNG or SVG, by the file's extension): the measured
//! acceleration amplitude on a log-frequency axis, the phase below it on the same axis, and
//! each resonance marked by a dashed line labelled with its frequency and Q.

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::prelude::*;

use super::{Figure, PlotError, text, write_chart};
use chladni_device::sweep::{Resonance, SweepSample};

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

/// Frequency ticks inside `range`, both ends included (plotters' log axis labels only powers
/// of ten, i.e. nothing inside the decade or so a sweep spans): 1, 1.5, 2, 3, 5, 7 × 10ⁿ,
/// or finer steps when the sweep spans less than a factor of 4 (100–300 Hz: every 20 Hz to
/// 200, then 250 and 300).
fn ticks(range: &Range<f64>) -> Vec<f64> {
    let coarse = [1.0, 1.5, 2.0, 3.0, 5.0, 7.0];
    let fine = [1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
    let steps: &[f64] = if range.end / range.start <= 4.0 { &fine } else { &coarse };
    // A hair of slack so an end given as 300 Hz keeps its 300 tick.
    let (lo, hi) = (range.start * (1.0 - 1e-9), range.end * (1.0 + 1e-9));
    let mut out = Vec::new();
    let mut decade = 10f64.powf(range.start.max(1e-3).log10().floor());
    while decade <= range.end {
        for &m in steps {
            let f = m * decade;
            if (lo..=hi).contains(&f) {
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
        .margin_right(24)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(range.clone().log_scale().with_key_points(ticks(&range)), 0.0..top)
        .map_err(text)?;
    c.configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc("acceleration (m/s²)")
        .x_label_formatter(&hz_label)
        .y_label_formatter(&|v| super::tick(*v, top))
        .label_style(("sans-serif", 12))
        .draw()
        .map_err(text)?;
    let points = samples.iter().filter_map(|s| s.accel_mps2.map(|a| (s.freq_hz, a)));
    c.draw_series(LineSeries::new(points, BLUE.stroke_width(2))).map_err(text)?;
    mark_resonances(&mut c, resonances, 0.0..top)?;
    for r in resonances {
        // A low Q with a decimal (the CLI's table prints 9.5, not 9).
        let q = r.q.map_or("Q ?".to_string(), |q| {
            if q < 20.0 { format!("Q {q:.1}") } else { format!("Q {q:.0}") }
        });
        let label = format!("{:.1} Hz, {q}", r.freq_hz);
        let y = (r.accel_mps2 * 1.03).min(top * 0.97);
        // 6 px right of the dashed line, so the label does not sit on it.
        let font = ("sans-serif", 13).into_font().color(&MARK);
        c.draw_series([EmptyElement::at((r.freq_hz, y)) + Text::new(label, (6, 0), font)])
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
    let phases = phase_range(&unwrapped_phase(samples));
    let mut c = ChartBuilder::on(area)
        .margin(10)
        .margin_right(24)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(
            range.clone().log_scale().with_key_points(ticks(&range)),
            phases.clone(),
        )
        .map_err(text)?;
    c.configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc("phase (°)")
        .x_label_formatter(&hz_label)
        .y_label_formatter(&|v| super::tick(*v, 360.0))
        .label_style(("sans-serif", 12))
        .draw()
        .map_err(text)?;
    let points = unwrapped_phase(samples);
    c.draw_series(points.into_iter().map(|p| Circle::new(p, 2, BLUE.filled()))).map_err(text)?;
    mark_resonances(&mut c, resonances, phases)
}

/// The measured phases (Hz, °) unwrapped along the sweep: no ±180° jumps between neighbours
/// (the phase of a resonance swings through 180°), shifted by whole turns so that the
/// last (highest-frequency) phase lies in (−180°, 180°].
fn unwrapped_phase(samples: &[SweepSample]) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    for (f, p) in samples.iter().filter_map(|s| s.phase_deg.map(|p| (s.freq_hz, p))) {
        let p = match out.last() {
            Some(&(_, prev)) => prev + chladni_core::model::angle::signed_diff(p, prev, 360.0),
            None => p,
        };
        out.push((f, p));
    }
    if let Some(&(_, last)) = out.last() {
        let shift = chladni_core::model::angle::signed_diff(last, 0.0, 360.0) - last;
        out.iter_mut().for_each(|p| p.1 += shift);
    }
    out
}

/// The phase axis: the phases and 10° around them in whole 30° steps (−180..180° when
/// nothing was measured).
fn phase_range(points: &[(f64, f64)]) -> Range<f64> {
    let (lo, hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| (l.min(p.1), h.max(p.1)));
    if !lo.is_finite() {
        return -180.0..180.0;
    }
    let lo = ((lo - 10.0) / 30.0).floor() * 30.0;
    let hi = ((hi + 10.0) / 30.0).ceil() * 30.0;
    lo..hi.max(lo + 30.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_include_both_ends_and_are_finer_on_a_short_sweep() {
        assert_eq!(
            ticks(&(100.0..300.0)),
            [100.0, 120.0, 140.0, 160.0, 180.0, 200.0, 250.0, 300.0]
        );
        assert_eq!(ticks(&(40.0..300.0)), [50.0, 70.0, 100.0, 150.0, 200.0, 300.0]);
        assert_eq!(phase_range(&[(1.0, 2.0), (2.0, 172.0)]), -30.0..210.0);
        assert_eq!(phase_range(&[]), -180.0..180.0);
        // A sweep whose phase crosses ±180°: one continuous curve.
        let p = |ph: f64| SweepSample { freq_hz: 1.0, accel_mps2: None, phase_deg: Some(ph) };
        let u = unwrapped_phase(&[p(-130.0), p(-175.0), p(175.0), p(20.0)]);
        let d: Vec<f64> = u.iter().map(|q| q.1).collect();
        assert_eq!(d, [230.0, 185.0, 175.0, 20.0]);
    }

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
