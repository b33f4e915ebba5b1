//! Plan and simulation figures (PNG or SVG, by the file's extension): the step-by-step plan figure like the paper's Fig. 10
//! (rows = example start poses, columns = steps; each panel shows the plate, the step's node,
//! the part before the step in white and after it in dark), and motion traces like Figs. 8d
//! and 9 (centroid paths with the part drawn along them, and θ(t)).

use chladni_core::model::angle::wrap_deg;
use std::path::{Path, PathBuf};

use plotters::prelude::*;

use std::ops::Range;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;

use super::{Figure, PlotError, text, write_chart};

use chladni_core::model::feed_region::FeedRegion;
use chladni_core::model::part::Part;
use chladni_core::model::plate::{Mode, Node, PlateModel};
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::montecarlo::{self, Setup, Trials};
use chladni_core::motion::steps::SimStep;
use chladni_core::motion::steps::simulate_plan;
use chladni_core::planner::Synthesis;
use chladni_core::plate::contour;
use chladni_core::rng::Rng;

fn err<E: std::fmt::Display>(e: E) -> String {
    text(e)
}

/// Polylines of a mode's node inside the plate (mm).
pub(crate) fn node_polylines(mode: &Mode, plate: &PlateModel) -> Vec<Vec<(f64, f64)>> {
    let [w, h] = plate.size_mm;
    let inside = |p: [f64; 2]| p[0] >= 0.0 && p[0] <= w && p[1] >= 0.0 && p[1] <= h;
    let runs = |pts: Vec<[f64; 2]>| {
        let mut out = vec![Vec::new()];
        for p in pts {
            if inside(p) {
                if let Some(r) = out.last_mut() {
                    r.push((p[0], p[1]));
                }
            } else if !out.last().is_some_and(Vec::is_empty) {
                out.push(Vec::new());
            }
        }
        out.retain(|r| r.len() > 1);
        out
    };
    let line_runs = |angle_deg: f64, offset_mm: f64| {
        let (s, c) = angle_deg.to_radians().sin_cos();
        let ctr = plate.center();
        let base = [ctr[0] - s * offset_mm, ctr[1] + c * offset_mm];
        let d = w.hypot(h);
        runs(
            (0..=800)
                .map(|i| {
                    let t = -d + 2.0 * d * i as f64 / 800.0;
                    [base[0] + t * c, base[1] + t * s]
                })
                .collect(),
        )
    };
    match &mode.node {
        Node::Line { angle_deg, offset_mm } => line_runs(*angle_deg, *offset_mm),
        Node::Lines(lines) => {
            lines.iter().flat_map(|l| line_runs(l.angle_deg, l.offset_mm)).collect()
        }
        Node::Hyperbola { center_mm, angle_deg, a_mm, b_mm } => {
            let (s, c) = angle_deg.to_radians().sin_cos();
            runs(
                (0..=800)
                    .map(|i| {
                        let t = -5.0 + 10.0 * i as f64 / 800.0;
                        let (u, v) = (a_mm * t.cosh(), b_mm * t.sinh());
                        [center_mm[0] + c * u - s * v, center_mm[1] + s * u + c * v]
                    })
                    .collect(),
            )
        }
        Node::Grid(g) => contour::node_lines(g)
            .into_iter()
            .map(|l| l.into_iter().map(|p| (p[0], p[1])).collect())
            .collect(),
    }
}

/// Draws the part at `pose`: its outline filled with `fill`, holes white, edges black.
pub(crate) fn draw_part<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    body: &Body,
    pose: Pose,
    fill: RGBColor,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    for (i, ring) in body.placed(pose).into_iter().enumerate() {
        let pts: Vec<(f64, f64)> = ring.iter().map(|p| (p[0], p[1])).collect();
        let f = if i == 0 { fill } else { WHITE };
        chart.draw_series(std::iter::once(Polygon::new(pts.clone(), f.filled()))).map_err(err)?;
        let mut closed = pts;
        closed.push(closed[0]);
        chart
            .draw_series(std::iter::once(PathElement::new(closed, BLACK.stroke_width(1))))
            .map_err(err)?;
    }
    Ok(())
}

/// The node of the running step in the plan figure and the animation.
pub(crate) const NODE_COLOR: RGBColor = RGBColor(200, 60, 40);

/// The chart's x and y ranges for a plate: the plate with a margin of 2 % of its longer side
/// on every side, so that a part resting against the rim is drawn whole, on the plate's edge,
/// instead of cut by the chart's frame (the wall holds parts flush with the edge: on the
/// hyperbola plate the node runs on past the edge, and parts drawn to it settle there).
pub(crate) fn plate_ranges(plate: &PlateModel) -> (Range<f64>, Range<f64>) {
    let [w, h] = plate.size_mm;
    let pad = 0.02 * w.max(h);
    (-pad..w + pad, -pad..h + pad)
}

/// The plate: a light fill and its rim as a black line.
pub(crate) fn draw_plate<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    plate: &PlateModel,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let [w, h] = plate.size_mm;
    let fill = Rectangle::new([(0.0, 0.0), (w, h)], RGBColor(245, 245, 240).mix(0.8).filled());
    chart.draw_series(std::iter::once(fill)).map_err(err)?;
    let rim = Rectangle::new([(0.0, 0.0), (w, h)], BLACK.stroke_width(2));
    chart.draw_series(std::iter::once(rim)).map_err(err)?;
    Ok(())
}

/// One example start: the pose before each step and after the last.
pub(crate) type Example = Vec<Pose>;

/// The plan figure: `examples[r][k]` is the pose before step k (and `[steps]` the end).
/// PNG or SVG by the extension of `path` (see `plot::write_chart`).
pub fn plan_figure(
    path: &Path,
    title: &str,
    body: &Body,
    plate: &PlateModel,
    modes: &[usize],
    examples: &[Example],
) -> Result<(), PlotError> {
    write_chart(path, &PlanFigure { title, body, plate, modes, examples })
}

/// What [`plan_figure`] draws.
struct PlanFigure<'a> {
    title: &'a str,
    body: &'a Body,
    plate: &'a PlateModel,
    modes: &'a [usize],
    examples: &'a [Example],
}

impl Figure for PlanFigure<'_> {
    fn size(&self) -> (u32, u32) {
        let [w, h] = self.plate.size_mm;
        let cols = self.modes.len().max(1) as u32;
        let rows = self.examples.len().max(1) as u32;
        let pw = 300u32;
        let ph = ((pw as f64 - 20.0) * h / w + 40.0) as u32;
        (pw * cols, ph * rows + 40)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(self.title, ("sans-serif", 15)).map_err(err)?;
        let cols = self.modes.len().max(1);
        let panels = root.split_evenly((self.examples.len().max(1), cols));
        for (r, ex) in self.examples.iter().enumerate() {
            for (k, &m) in self.modes.iter().enumerate() {
                draw_plan_panel(&panels[r * cols + k], self, k, m, ex)?;
            }
        }
        Ok(())
    }
}

/// One panel of the plan figure: step `k` (mode `m`) of example `ex`.
fn draw_plan_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    fig: &PlanFigure<'_>,
    k: usize,
    m: usize,
    ex: &Example,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let mode = &fig.plate.modes[m];
    let (xr, yr) = plate_ranges(fig.plate);
    let mut chart = ChartBuilder::on(area)
        .caption(format!("step {}: {} ({} Hz)", k + 1, mode.name, mode.freq_hz), ("sans-serif", 13))
        .margin(6)
        .build_cartesian_2d(xr, yr)
        .map_err(err)?;
    draw_plate(&mut chart, fig.plate)?;
    for line in node_polylines(mode, fig.plate) {
        chart
            .draw_series(std::iter::once(PathElement::new(line, NODE_COLOR.stroke_width(2))))
            .map_err(err)?;
    }
    draw_part(&mut chart, fig.body, ex[k], WHITE)?;
    draw_part(&mut chart, fig.body, ex[k + 1], RGBColor(60, 60, 90))?;
    let path: Vec<(f64, f64)> = vec![(ex[k].x, ex[k].y), (ex[k + 1].x, ex[k + 1].y)];
    chart
        .draw_series(std::iter::once(PathElement::new(
            path,
            RGBColor(120, 120, 200).stroke_width(1),
        )))
        .map_err(err)?;
    Ok(())
}

/// One trial's trace: (t, pose) over the whole plan.
pub type Trace = Vec<(f64, Pose)>;

/// The traces figure: what [`traces_figure`] draws.
#[derive(Debug, Clone, Copy)]
pub struct TracesFigure<'a> {
    /// Title line.
    pub title: &'a str,
    /// The part.
    pub body: &'a Body,
    /// The plate.
    pub plate: &'a PlateModel,
    /// The mode of each step.
    pub modes: &'a [usize],
    /// The trials' traces.
    pub traces: &'a [Trace],
    /// End time of each step.
    pub step_ends: &'a [f64],
    /// Predicted final orientation and its period (degrees).
    pub target: Option<(f64, f64)>,
}

/// The trials' colours (figures and the animation).
pub(crate) const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// Traces: the plate with every step's node, centroid paths with the part drawn along them;
/// θ(t) with step boundaries and the target orientation. PNG or SVG by the extension.
pub fn traces_figure(path: &Path, fig: &TracesFigure<'_>) -> Result<(), PlotError> {
    write_chart(path, fig)
}

impl Figure for TracesFigure<'_> {
    fn size(&self) -> (u32, u32) {
        (1300, 560)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(self.title, ("sans-serif", 18)).map_err(err)?;
        let (left, right) = root.split_horizontally(680);
        draw_paths(&left, self)?;
        draw_orientation(&right, self)
    }
}

/// Left panel of the traces figure: nodes, centroid paths, the part along them.
fn draw_paths<DB: DrawingBackend>(
    left: &DrawingArea<DB, Shift>,
    fig: &TracesFigure<'_>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let TracesFigure { body, plate, modes, traces, .. } = *fig;
    let [w, h] = plate.size_mm;
    let palette = PALETTE;
    let (xr, yr) = plate_ranges(plate);
    let mut chart = ChartBuilder::on(left)
        .caption("part motion (white: start, dark: end of plan)", ("sans-serif", 14))
        .margin(10)
        .margin_right(24)
        .x_label_area_size(34)
        .y_label_area_size(56)
        .build_cartesian_2d(xr, yr)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .x_label_formatter(&|v| super::tick(*v, w))
        .y_label_formatter(&|v| super::tick(*v, h))
        .light_line_style(WHITE)
        .draw()
        .map_err(err)?;
    draw_plate(&mut chart, plate)?;
    // Nodes in their own colours (not the traces'), dashed, one legend entry per step.
    for (k, &m) in modes.iter().enumerate() {
        let c = NODE_PALETTE[k % NODE_PALETTE.len()];
        for (j, line) in node_polylines(&plate.modes[m], plate).into_iter().enumerate() {
            let s = chart
                .draw_series(DashedLineSeries::new(line, 8, 5, c.stroke_width(2)))
                .map_err(err)?;
            if j == 0 {
                s.label(format!("node, step {}", k + 1)).legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 18, y)], c.stroke_width(2))
                });
            }
        }
    }
    for (i, tr) in traces.iter().enumerate() {
        let col = palette[i % palette.len()];
        let pts: Vec<(f64, f64)> = tr.iter().map(|(_, p)| (p.x, p.y)).collect();
        chart
            .draw_series(std::iter::once(PathElement::new(pts, col.stroke_width(2))))
            .map_err(err)?;
        // Snapshots: start, a few along the way, end.
        let n = tr.len();
        let picks = [0, n / 8, n / 4, n / 2];
        for &j in &picks[1..] {
            if j > 0 && j < n - 1 {
                for ring in body.placed(tr[j].1).into_iter().take(1) {
                    let mut pts: Vec<(f64, f64)> = ring.iter().map(|p| (p[0], p[1])).collect();
                    pts.push(pts[0]);
                    chart
                        .draw_series(std::iter::once(PathElement::new(
                            pts,
                            col.mix(0.5).stroke_width(1),
                        )))
                        .map_err(err)?;
                }
            }
        }
        draw_part(&mut chart, body, tr[0].1, WHITE)?;
        draw_part(&mut chart, body, tr[n - 1].1, col)?;
    }
    super::draw_legend(&mut chart, 12, SeriesLabelPosition::UpperRight)
}

/// Node colours: dark and saturated, none of them in [`PALETTE`] (the traces' colours).
const NODE_PALETTE: [RGBColor; 4] =
    [RGBColor(0, 0, 0), RGBColor(0, 139, 139), RGBColor(199, 21, 133), RGBColor(128, 128, 0)];

/// θ(t) of a trace in degrees, unwrapped (no 360° → 0° jumps), shifted by whole turns so that
/// it ends in [0°, 360°).
fn unwrapped_deg(tr: &Trace) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(tr.len());
    for &(t, p) in tr {
        let d = p.theta.to_degrees();
        let d = match out.last() {
            Some(&(_, prev)) => prev + chladni_core::model::angle::signed_diff(d, prev, 360.0),
            None => d,
        };
        out.push((t, d));
    }
    let shift = out.last().map_or(0.0, |&(_, d)| wrap_deg(d) - d);
    out.iter_mut().for_each(|p| p.1 += shift);
    out
}

/// Right panel of the traces figure: θ(t) with step boundaries and the target orientation.
fn draw_orientation<DB: DrawingBackend>(
    right: &DrawingArea<DB, Shift>,
    fig: &TracesFigure<'_>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let TracesFigure { traces, step_ends, target, .. } = *fig;
    let palette = PALETTE;
    let t_end = step_ends.last().copied().unwrap_or(1.0).max(1e-6);
    let curves: Vec<Vec<(f64, f64)>> = traces.iter().map(unwrapped_deg).collect();
    let (lo, hi) = curves
        .iter()
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| (l.min(p.1), h.max(p.1)));
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 360.0) };
    let pad = ((hi - lo) * 0.05).max(5.0);
    let (lo, hi) = (lo - pad, hi + pad);
    let mut th = ChartBuilder::on(right)
        .caption("orientation θ(t), unwrapped", ("sans-serif", 14))
        .margin(10)
        .margin_right(24)
        .x_label_area_size(34)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..t_end, lo..hi)
        .map_err(err)?;
    th.configure_mesh()
        .x_desc("t (s)")
        .y_desc("θ (deg)")
        .x_label_formatter(&|v| super::tick(*v, t_end))
        .y_label_formatter(&|v| super::tick(*v, hi - lo))
        .y_labels(9)
        .light_line_style(WHITE)
        .draw()
        .map_err(err)?;
    for &t in &step_ends[..step_ends.len().saturating_sub(1)] {
        th.draw_series(std::iter::once(PathElement::new(
            vec![(t, lo), (t, hi)],
            RGBColor(160, 160, 160),
        )))
        .map_err(err)?;
    }
    if let Some((target, period)) = target {
        let mut v = target + ((lo - target) / period).ceil() * period;
        let mut first = true;
        while v <= hi {
            let s = th
                .draw_series(DashedLineSeries::new(
                    [(0.0, v), (t_end, v)],
                    8,
                    5,
                    BLACK.stroke_width(1),
                ))
                .map_err(err)?;
            if first {
                s.label("predicted θ").legend(|(x, y)| {
                    PathElement::new([(x, y), (x + 18, y)], BLACK.stroke_width(1))
                });
                first = false;
            }
            v += period;
        }
    }
    for (i, curve) in curves.into_iter().enumerate() {
        let col = palette[i % palette.len()];
        let s = th.draw_series(LineSeries::new(curve, col.stroke_width(2))).map_err(err)?;
        if i == 0 {
            s.label("trials")
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], col.stroke_width(2)));
        }
    }
    super::draw_legend(&mut th, 12, SeriesLabelPosition::UpperRight)
}

/// The step-by-step figure of a synthesised plan (`chladni plan --plot`, `chladni demo`):
/// three example starts drawn with seed 1 (from the feed region when given), run through the
/// plan's steps.
pub fn synthesis_figure(
    path: &Path,
    part: &Part,
    plate: &PlateModel,
    syn: &Synthesis,
    region: Option<&FeedRegion>,
) -> Result<(), PlotError> {
    let body = Body::new(part);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let steps: Vec<SimStep> = syn.sim_steps();
    let mut rng = Rng::seeded(1);
    let examples: Vec<Vec<Pose>> = (0..3)
        .map(|_| {
            let start = montecarlo::random_pose(&mut rng, &body, plate, region);
            simulate_plan(&body, plate, &fields, &steps, start).0
        })
        .collect();
    let modes: Vec<usize> = syn.steps.iter().map(|s| s.mode).collect();
    let title = format!(
        "{}: {}-step plan, final θ = {:.1}° (mod {}°)",
        part.name,
        modes.len(),
        syn.final_orientation_deg,
        syn.period_deg
    );
    plan_figure(path, &title, &body, plate, &modes, &examples)
}

/// The step-by-step figure written beside a traces figure `F.png` (`F.svg`): `F-plan.png`
/// (`F-plan.svg`, the same format).
pub fn trials_plan_path(traces: &Path) -> PathBuf {
    let ext = traces.extension().and_then(|e| e.to_str()).unwrap_or("png");
    PathBuf::from(format!("{}-plan.{ext}", traces.with_extension("").display()))
}

/// The figures of a Monte Carlo run (`chladni simulate --plot`, `chladni demo`): traces of the
/// first trials at `path`, and their step-by-step figure at [`trials_plan_path`]; returns the
/// latter's path. `target`: the predicted orientation and its period (deg).
pub fn trials_figures(
    path: &Path,
    part: &Part,
    setup: &Setup<'_>,
    trials: &Trials,
    target: Option<(f64, f64)>,
) -> Result<PathBuf, PlotError> {
    let modes: Vec<usize> = setup.steps.iter().map(|s| s.mode).collect();
    // The first few trials (the run may have kept every trial's trace for --traces).
    let shown =
        &trials.traces[..trials.traces.len().min(chladni_core::motion::montecarlo::TRACED_TRIALS)];
    let examples = &trials.examples
        [..trials.examples.len().min(chladni_core::motion::montecarlo::EXAMPLE_TRIALS)];
    let title = format!(
        "{} on {}: simulated plan ({} trials shown)",
        part.name,
        setup.plate.name,
        shown.len()
    );
    let fig = TracesFigure {
        title: &title,
        body: setup.body,
        plate: setup.plate,
        modes: &modes,
        traces: shown,
        step_ends: &trials.step_ends,
        target,
    };
    traces_figure(path, &fig)?;
    let fig = trials_plan_path(path);
    let title = format!("{}: plan step by step", part.name);
    plan_figure(&fig, &title, setup.body, setup.plate, &modes, examples)?;
    Ok(fig)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn theta_is_unwrapped_through_a_full_turn_and_ends_in_one_turn() {
        // 350° → 370° (stored as 10°) → 380°: no jump, and shifted so the end is 20°.
        let tr: Trace = [350.0f64, 5.0, 10.0, 20.0]
            .iter()
            .enumerate()
            .map(|(i, d)| (i as f64, Pose { x: 0.0, y: 0.0, theta: d.to_radians() }))
            .collect();
        let u = unwrapped_deg(&tr);
        let d: Vec<f64> = u.iter().map(|p| (p.1 * 1e6).round() / 1e6).collect();
        assert_eq!(d, vec![-10.0, 5.0, 10.0, 20.0]);
    }
}
