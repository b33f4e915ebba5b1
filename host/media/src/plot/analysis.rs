//! Plots of a rest analysis like the paper's Fig. 8: the part at rest on the node, the turn
//! function t(θ) with its roots, and the alignment function a(θ). PNG or SVG by extension.
//!
//! The font and the error type are the module's ([`crate::plot`]).

use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use chladni_shared::analysis::rest::{Analysis, Analyzer};

use super::{Figure, PlotError, check_extension, text, write_chart};
use chladni_core::analysis::samples;
use chladni_core::model::part::Part;

/// What to draw.
#[derive(Debug, Clone)]
pub struct PlotData {
    /// Title line (part and field).
    pub title: String,
    /// Rings of the part in its rest pose, plate frame (mm): outline first.
    pub rest_pose: Vec<Vec<[f64; 2]>>,
    /// θ of the rest pose shown (degrees).
    pub rest_pose_deg: f64,
    /// Samples of t(θ): (degrees, t), normalised so max |t| = 1.
    pub turn: Vec<(f64, f64)>,
    /// Samples of a(θ): (degrees, degrees).
    pub align: Vec<(f64, f64)>,
    /// Rest orientations: (degrees, stable).
    pub rests: Vec<(f64, bool)>,
    /// Every orientation is at rest.
    pub neutral: bool,
}

impl PlotData {
    /// The figure of a rest analysis: t(θ) and a(θ) every 0.5° and the part posed at its first
    /// stable rest ([`chladni_core::analysis::samples`]), under `title`.
    pub fn of(part: &Part, an: &Analyzer<'_>, a: &Analysis, title: String) -> PlotData {
        let samples = samples::turn_samples(an, a, 721);
        let (rest_pose, rest_pose_deg) = samples::rest_pose(part, an, a);
        PlotData {
            title,
            rest_pose,
            rest_pose_deg,
            turn: samples.iter().map(|s| (s.theta_deg, s.turn)).collect(),
            align: samples.iter().map(|s| (s.theta_deg, s.alignment_deg)).collect(),
            rests: a.rests.iter().map(|r| (samples::deg(r.angle), r.stable)).collect(),
            neutral: a.neutral,
        }
    }
}

/// Writes the plot; the format follows the extension (`.png` or `.svg`, checked first).
pub fn write(path: &Path, data: &PlotData) -> Result<(), PlotError> {
    check_extension("--plot", path, &EXTENSIONS)?;
    write_chart(path, data)
}

/// The file types [`write()`] can draw.
pub const EXTENSIONS: [&str; 2] = super::FIGURE_EXTENSIONS;

impl Figure for PlotData {
    fn size(&self) -> (u32, u32) {
        (1200, 420)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        draw(root, self)
    }
}

fn err<E: std::fmt::Display>(e: E) -> String {
    text(e)
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, data: &PlotData) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(&data.title, ("sans-serif", 20)).map_err(err)?;
    let panels = root.split_evenly((1, 3));
    draw_rest(&panels[0], data)?;
    draw_turn(&panels[1], data)?;
    draw_align(&panels[2], data)?;
    Ok(())
}

const STABLE: RGBColor = RGBColor(0, 120, 60);
const UNSTABLE: RGBColor = RGBColor(200, 40, 40);

/// (a) The part at rest on the node.
fn draw_rest<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    data: &PlotData,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    // (a) The part at rest on the node.
    let all = data.rest_pose.iter().flatten();
    let r = all.fold(1e-9f64, |m, p| m.max(p[0].abs()).max(p[1].abs())) * 1.15;
    let mut part = ChartBuilder::on(area)
        .caption(format!("part at rest, θ = {:.1}°", data.rest_pose_deg), ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(40)
        .build_cartesian_2d(-r..r, -r..r)
        .map_err(err)?;
    part.configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .x_label_formatter(&|v| super::tick(*v, 2.0 * r))
        .y_label_formatter(&|v| super::tick(*v, 2.0 * r))
        .light_line_style(WHITE)
        .draw()
        .map_err(err)?;
    for (i, ring) in data.rest_pose.iter().enumerate() {
        let pts: Vec<(f64, f64)> = ring.iter().map(|p| (p[0], p[1])).collect();
        let fill = if i == 0 { RGBColor(170, 190, 220).filled() } else { WHITE.filled() };
        part.draw_series(std::iter::once(Polygon::new(pts.clone(), fill))).map_err(err)?;
        let mut closed = pts;
        closed.push(closed[0]);
        part.draw_series(std::iter::once(PathElement::new(closed, BLACK.stroke_width(2))))
            .map_err(err)?;
    }
    part.draw_series(std::iter::once(PathElement::new(
        vec![(0.0, -r), (0.0, r)],
        RGBColor(120, 120, 120).stroke_width(1),
    )))
    .map_err(err)?;

    Ok(())
}

/// How far the angle axes reach beyond 0° and 360° (degrees).
const ANGLE_PAD: f64 = 6.0;

/// A chart over θ in [0°, 360°) with its caption, the y range and the axis names
/// ([x, y]); the turn and alignment panels share it.
fn angle_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    y: std::ops::Range<f64>,
    [x_desc, y_desc]: [&str; 2],
) -> Result<ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>, String>
where
    DB::ErrorType: 'static,
{
    let y_labels = if y.end > 100.0 { 9 } else { 10 };
    let y_span = y.end - y.start;
    // 6° beyond each end: a rest at 0° or 359.9° is drawn whole, not cut by the frame.
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(10)
        .margin_right(16)
        .x_label_area_size(30)
        .y_label_area_size(45)
        .build_cartesian_2d(-ANGLE_PAD..360.0 + ANGLE_PAD, y)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_labels(9)
        .y_labels(y_labels)
        .x_label_formatter(&|v| super::tick(*v, 360.0))
        .y_label_formatter(&|v| super::tick(*v, y_span))
        .light_line_style(WHITE)
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// (b) The turn function.
fn draw_turn<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    data: &PlotData,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let mut turn = angle_chart(area, "turn function t(θ)", -1.1..1.1, ["θ (deg)", "t / max|t|"])?;
    turn.draw_series(LineSeries::new(vec![(0.0, 0.0), (360.0, 0.0)], RGBColor(150, 150, 150)))
        .map_err(err)?;
    turn.draw_series(LineSeries::new(data.turn.iter().copied(), BLUE.stroke_width(2)))
        .map_err(err)?;
    // Stable and unstable rests as two series, so the legend names each marker.
    for (stable, name) in [(true, "stable rest"), (false, "unstable rest")] {
        let c = if stable { STABLE } else { UNSTABLE };
        let style = if stable { c.filled() } else { c.stroke_width(2) };
        let rests = data.rests.iter().filter(move |r| r.1 == stable);
        turn.draw_series(rests.map(move |&(d, _)| Circle::new((d, 0.0), 5, style)))
            .map_err(err)?
            .label(name)
            .legend(move |(x, y)| Circle::new((x + 8, y), 5, style));
    }
    if !data.rests.is_empty() {
        super::draw_legend(&mut turn, 11, SeriesLabelPosition::LowerLeft)?;
    }
    if data.neutral {
        turn.draw_series(std::iter::once(Text::new(
            "neutral: every orientation is at rest",
            (20.0, 0.6),
            ("sans-serif", 16),
        )))
        .map_err(err)?;
    }

    Ok(())
}

/// (c) The alignment function.
fn draw_align<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    data: &PlotData,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let mut align = angle_chart(
        area,
        "alignment function a(θ)",
        -ANGLE_PAD..360.0 + ANGLE_PAD,
        ["start θ (deg)", "final θ (deg)"],
    )?;
    align
        .draw_series(LineSeries::new(vec![(0.0, 0.0), (360.0, 360.0)], RGBColor(190, 190, 190)))
        .map_err(err)?;
    // Continuous pieces only: break the line where a(θ) jumps (unstable rests).
    let mut piece: Vec<(f64, f64)> = Vec::new();
    let mut pieces = Vec::new();
    for &(x, y) in &data.align {
        if let Some(&(_, py)) = piece.last()
            && (y - py).abs() > 1.0
        {
            pieces.push(std::mem::take(&mut piece));
        }
        piece.push((x, y));
    }
    pieces.push(piece);
    for p in pieces {
        align.draw_series(LineSeries::new(p, STABLE.stroke_width(3))).map_err(err)?;
    }
    align
        .draw_series(data.rests.iter().map(|&(d, stable)| {
            let c = if stable { STABLE } else { UNSTABLE };
            Circle::new((d, d), 5, if stable { c.filled() } else { c.stroke_width(2) })
        }))
        .map_err(err)?;
    Ok(())
}
