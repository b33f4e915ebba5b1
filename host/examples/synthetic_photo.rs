//! Writes a synthetic Chladni photo (sand on known straight node lines) for trying
//! `chladni plate from-photo`: `cargo run -p chladni-host --example synthetic_photo -- OUT.png`.
//! The plate is 300 × 200 mm; the nodes are (angle 90°, offset 40 mm) and (angle 20°, offset −30 mm).

use chladni::plate::photo::synth::{Scene, render};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1).unwrap_or_else(|| "synthetic-photo.png".into());
    let scene = Scene {
        px: (450, 300),
        size_mm: [300.0, 200.0],
        lines: vec![(90.0, 40.0), (20.0, -30.0)],
        curves: vec![],
        sand_sigma_mm: 3.0,
        density: 0.6,
        stray: 0.03,
        noise: 30.0,
        dark_sand: false,
        seed: 7,
    };
    render(&scene).save(&out)?;
    println!("{out}");
    Ok(())
}
