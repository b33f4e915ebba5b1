//! Writes a synthetic Chladni photo for trying `chladni plate from-photo`:
//! `cargo run -p chladni-core --example synthetic_photo -- OUT.png` draws sand on two known
//! straight node lines, (angle 90°, offset 40 mm) and (angle 20°, offset −30 mm);
//! `... -- OUT.png --curved [OVERLAY.png]` draws the nodes of mode 5 of the free 300 × 200 mm
//! plate (examples/plate-free.toml: two curved arcs and a straight line) at 360 × 240 px and,
//! with OVERLAY,
//! also writes the photo with the nodes `plate::photo` recovers from it drawn in white.

use chladni_core::model::plate_file::PlateFile;
use chladni_core::plate::contour::node_lines;
use chladni_core::plate::photo::synth::{Scene, render};
use chladni_core::plate::photo::{self, DEFAULT_SNAP, PhotoParams};
use chladni_core::plate::solver;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = args.first().cloned().unwrap_or_else(|| "synthetic-photo.png".into());
    let curved = args.get(1).is_some_and(|a| a == "--curved");
    let mut scene = Scene {
        px: if curved { (360, 240) } else { (450, 300) },
        size_mm: [300.0, 200.0],
        lines: vec![(90.0, 40.0), (20.0, -30.0)],
        curves: vec![],
        sand_sigma_mm: 3.0,
        density: 0.6,
        stray: 0.03,
        noise: 30.0,
        dark_sand: false,
        seed: 7,
        grain_mm: 0.0,
    };
    if curved {
        let file = PlateFile::parse(include_str!("../../../examples/plate-free.toml"), "free")?;
        let sol = solver::solve(&file.plate.mechanics()?, 5, 10);
        scene.lines.clear();
        scene.curves = node_lines(&sol.sample(4, 121, 81));
    }
    let img = render(&scene);
    img.save(&out)?;
    println!("{out}");
    if let Some(overlay) = args.get(2).filter(|_| curved) {
        let found = photo::find_lines(&img, scene.size_mm, &PhotoParams::default());
        // Side by side: the photo, and the recovered nodes drawn over it (dimmed).
        let drawn = photo::overlay(&img, &found.nodes(DEFAULT_SNAP), scene.size_mm);
        let (w, h) = img.dimensions();
        let gap = 8;
        let both = image::GrayImage::from_fn(2 * w + gap, h, |x, y| match x {
            x if x < w => *img.get_pixel(x, y),
            x if x < w + gap => image::Luma([255]),
            x => *drawn.get_pixel(x - w - gap, y),
        });
        both.save(overlay)?;
        println!("{overlay}: {} lines, {} curves", found.lines.len(), found.curves.len());
    }
    Ok(())
}
