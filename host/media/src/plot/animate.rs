//! The animation of a simulated plan (`chladni simulate --animate run.gif`): the plate, the
//! node of the step running at each instant, the first trials' parts moving along their
//! traces (each with the path it has covered so far), a clock (s) and the step number
//! (1-based, as `plan` prints it).
//!
//! Each frame is drawn by plotters into an RGB buffer at one instant of the plan's time
//! (frames evenly spaced from 0 to the end of the last step, at most [`MAX_FRAMES`]); the
//! `image` crate's GIF encoder writes them. The last frame is held longer so the end pose
//! can be read before the loop restarts.

use std::io::BufWriter;
use std::path::Path;

use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, Frame, RgbaImage};
use plotters::prelude::*;

use super::plan::{
    PALETTE, Trace, TracesFigure, draw_part, draw_plate, node_polylines, plate_ranges,
};
use super::{PlotError, text, write_figure};
use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::montecarlo::{Setup, TRACED_TRIALS, Trials};

/// The most frames an animation has (keeps the file small: the README's is well under 1 MB).
pub const MAX_FRAMES: usize = 120;
/// Width of every frame (pixels); the height follows the plate's aspect ratio.
pub const WIDTH: u32 = 480;
/// Time each frame is shown (ms), and the last one.
const FRAME_MS: u32 = 100;
const LAST_FRAME_MS: u32 = 2000;
/// The node's colour: none of the trials' [`PALETTE`] (whose red is the plan figure's node).
const NODE_COLOR: RGBColor = RGBColor(0, 139, 139);
/// Height of the caption band above the plate (pixels).
const CAPTION_PX: u32 = 44;

/// Frame size (pixels) for a plate: [`WIDTH`] wide, the plate's aspect below the caption.
pub fn frame_size(plate: &PlateModel) -> (u32, u32) {
    let [w, h] = plate.size_mm;
    let plate_px = f64::from(WIDTH - 16) * h / w.max(1e-9);
    (WIDTH, CAPTION_PX + 16 + plate_px.clamp(40.0, 2000.0) as u32)
}

/// The instants drawn: `frames` (≥ 2) evenly spaced from 0 to `t_end`.
fn instants(t_end: f64, frames: usize) -> Vec<f64> {
    let n = frames.max(2);
    (0..n).map(|i| t_end * i as f64 / (n - 1) as f64).collect()
}

/// The 0-based step running at time `t` (the last step at and after its end).
fn step_at(step_ends: &[f64], t: f64) -> usize {
    step_ends.iter().position(|&e| t <= e).unwrap_or(step_ends.len().saturating_sub(1))
}

/// How many samples of `trace` lie at or before `t` (at least 1: the start pose).
fn samples_until(trace: &Trace, t: f64) -> usize {
    trace.partition_point(|&(ts, _)| ts <= t).max(1).min(trace.len())
}

/// Writes the animation of `anim` (the traces figure's data; its title is the first caption
/// line, its target unused) to `path` (GIF, atomically) with at most [`MAX_FRAMES`]
/// frames; returns the number of frames written.
pub fn animation(path: &Path, anim: &TracesFigure<'_>, frames: usize) -> Result<usize, PlotError> {
    let t_end = anim.step_ends.last().copied().unwrap_or(0.0).max(0.0);
    let times = instants(t_end, frames.clamp(2, MAX_FRAMES));
    // One node drawing per step, computed once (a grid mode's contour is not cheap).
    let nodes: Vec<Vec<Vec<(f64, f64)>>> =
        anim.modes.iter().map(|&m| node_polylines(&anim.plate.modes[m], anim.plate)).collect();
    let size = frame_size(anim.plate);
    write_figure(path, |tmp| -> Result<(), String> {
        let file = std::fs::File::create(tmp).map_err(text)?;
        let mut gif = GifEncoder::new_with_speed(BufWriter::new(file), 10);
        gif.set_repeat(Repeat::Infinite).map_err(text)?;
        for (i, &t) in times.iter().enumerate() {
            let mut rgb = vec![255u8; (size.0 * size.1 * 3) as usize];
            {
                let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
                draw_frame(&root, anim, &nodes, t)?;
                root.present().map_err(text)?;
            }
            let rgba: Vec<u8> = rgb.chunks_exact(3).flat_map(|p| [p[0], p[1], p[2], 255]).collect();
            let img = RgbaImage::from_raw(size.0, size.1, rgba).ok_or("frame buffer size")?;
            let ms = if i + 1 == times.len() { LAST_FRAME_MS } else { FRAME_MS };
            let frame = Frame::from_parts(img, 0, 0, Delay::from_numer_denom_ms(ms, 1));
            gif.encode_frame(frame).map_err(text)?;
        }
        Ok(())
    })?;
    Ok(times.len())
}

/// One frame: caption (part, step, mode, clock), plate, the running step's node, each
/// trial's path so far and its part at time `t`.
fn draw_frame<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    anim: &TracesFigure<'_>,
    nodes: &[Vec<Vec<(f64, f64)>>],
    t: f64,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(text)?;
    let k = step_at(anim.step_ends, t);
    let caption = match anim.modes.get(k).map(|&m| &anim.plate.modes[m]) {
        Some(mode) => {
            format!("step {}/{}: {} ({} Hz)", k + 1, anim.modes.len(), mode.name, mode.freq_hz)
        }
        None => "no steps".to_string(),
    };
    let style = ("sans-serif", 15).into_font().color(&BLACK);
    root.draw_text(&format!("{} on {}", anim.title, anim.plate.name), &style, (8, 4))
        .map_err(text)?;
    root.draw_text(&caption, &style, (8, 24)).map_err(text)?;
    let clock = format!("t = {t:6.1} s");
    let cw = root.estimate_text_size(&clock, &style).map_err(text)?.0 as i32;
    root.draw_text(&clock, &style, (WIDTH as i32 - cw - 8, 4)).map_err(text)?;
    let (_, area) = root.split_vertically(CAPTION_PX);
    let (xr, yr) = plate_ranges(anim.plate);
    let mut chart = ChartBuilder::on(&area).margin(8).build_cartesian_2d(xr, yr).map_err(text)?;
    draw_plate(&mut chart, anim.plate)?;
    for line in nodes.get(k).into_iter().flatten() {
        let node = PathElement::new(line.clone(), NODE_COLOR.stroke_width(3));
        chart.draw_series(std::iter::once(node)).map_err(text)?;
    }
    for (i, tr) in anim.traces.iter().enumerate().filter(|(_, tr)| !tr.is_empty()) {
        let col = PALETTE[i % PALETTE.len()];
        let n = samples_until(tr, t);
        let covered: Vec<(f64, f64)> = tr[..n].iter().map(|(_, p)| (p.x, p.y)).collect();
        chart
            .draw_series(std::iter::once(PathElement::new(covered, col.mix(0.7).stroke_width(2))))
            .map_err(text)?;
        let pose: Pose = tr[n - 1].1;
        draw_part(&mut chart, anim.body, pose, col)?;
    }
    Ok(())
}

/// The animation of a Monte Carlo run (`chladni simulate --animate`): the first
/// [`TRACED_TRIALS`] trials' traces; returns the number of frames.
pub fn trials_animation(
    path: &Path,
    part: &Part,
    setup: &Setup<'_>,
    trials: &Trials,
) -> Result<usize, PlotError> {
    let modes: Vec<usize> = setup.steps.iter().map(|s| s.mode).collect();
    let shown = &trials.traces[..trials.traces.len().min(TRACED_TRIALS)];
    let anim = TracesFigure {
        title: &part.name,
        body: setup.body,
        plate: setup.plate,
        modes: &modes,
        traces: shown,
        step_ends: &trials.step_ends,
        target: None,
    };
    animation(path, &anim, MAX_FRAMES)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instants_span_the_plan_and_steps_are_found_at_their_ends() {
        let ts = instants(10.0, 5);
        assert_eq!(ts, vec![0.0, 2.5, 5.0, 7.5, 10.0]);
        let ends = [4.0, 10.0];
        let steps: Vec<usize> = ts.iter().map(|&t| step_at(&ends, t)).collect();
        assert_eq!(steps, vec![0, 0, 1, 1, 1]);
        assert_eq!(step_at(&ends, 99.0), 1);
    }

    #[test]
    fn a_trace_is_cut_at_the_instant_and_keeps_its_start() {
        let p = Pose { x: 0.0, y: 0.0, theta: 0.0 };
        let tr: Trace = vec![(0.0, p), (1.0, p), (2.0, p)];
        assert_eq!(samples_until(&tr, -1.0), 1);
        assert_eq!(samples_until(&tr, 1.0), 2);
        assert_eq!(samples_until(&tr, 5.0), 3);
    }
}
