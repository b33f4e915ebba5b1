//! Fixed-point analysis (chladni_shared::analysis::rest) against the independent f64 reference
//! (chladni::analysis::reference): rest orientations agree within 0.05° on every test part.

use std::path::Path;

use chladni::analysis::reference::{Law, RefField, Reference};
use chladni::model::part::Part;
use chladni_shared::analysis::field::{Field, FieldKind};
use chladni_shared::analysis::fx::Fx;
use chladni_shared::analysis::geometry::Pt;
use chladni_shared::analysis::rest::Analyzer;
use chladni_shared::icd::units::deg_from_bam;

const TOL_DEG: f64 = 0.05;

fn adist(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

/// Max disagreement (degrees) between the two analyses; panics if the lists differ.
fn compare(part: &Part, law: Law, gl: f64, gr: f64) -> f64 {
    let kind = match law {
        Law::Sign => FieldKind::Sign,
        Law::Linear => FieldKind::Linear,
        Law::Sine { wavelength_mm: w } => FieldKind::Sine { wavelength: Fx::from_f64(w) },
    };
    let rings = part.to_fixed();
    let slices: Vec<&[Pt]> = rings.iter().map(Vec::as_slice).collect();
    let field = Field { kind, gain_left: Fx::from_f64(gl), gain_right: Fx::from_f64(gr) };
    let fixed = Analyzer::new(&slices, field).unwrap().analyze().unwrap();
    let reference = Reference::new(part, RefField { law, gain_left: gl, gain_right: gr });
    let (rests, neutral) = reference.rests();
    let ctx = format!("{} {law:?} {gl}/{gr}", part.name);
    assert_eq!(fixed.neutral, neutral, "{ctx}: neutral");
    assert_eq!(fixed.rests.len(), rests.len(), "{ctx}: {:?} vs {rests:?}", fixed.rests);
    let mut worst: f64 = 0.0;
    for (f, r) in fixed.rests.iter().zip(&rests) {
        let d = adist(deg_from_bam(f.angle), r.deg);
        assert_eq!(f.stable, r.stable, "{ctx}");
        assert!(d < TOL_DEG, "{ctx}: {d}° apart");
        worst = worst.max(d);
    }
    worst
}

fn diameter(part: &Part) -> f64 {
    let pts: Vec<[f64; 2]> = part.rings().flatten().copied().collect();
    let mut d: f64 = 0.0;
    for p in &pts {
        for q in &pts {
            d = d.max((p[0] - q[0]).hypot(p[1] - q[1]));
        }
    }
    d
}

fn check(part: &Part) -> f64 {
    let w = 1.3 * diameter(part);
    let mut worst: f64 = 0.0;
    for (law, gl, gr) in [
        (Law::Sign, 1.0, 1.0),
        (Law::Linear, 1.0, 1.0),
        (Law::Sine { wavelength_mm: w }, 1.0, 1.0),
        (Law::Sign, 1.0, 2.5),
        (Law::Linear, 3.0, 1.0),
    ] {
        worst = worst.max(compare(part, law, gl, gr));
    }
    worst
}

#[test]
fn example_parts_agree_with_the_f64_reference() {
    // The example parts (the ordinary parts in examples/parts/ordinary/ are not in this test
    // yet: the crank lever under the sign law disagrees on a rest's stability, an open finding).
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/parts");
    let mut worst: f64 = 0.0;
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            continue;
        }
        let part = Part::load(&path).unwrap();
        worst = worst.max(check(&part));
        count += 1;
    }
    assert!(count >= 6);
    println!("example parts: max fixed-vs-f64 disagreement {worst:.2e}°");
}

#[test]
fn random_polygons_agree_with_the_f64_reference() {
    // Deterministic pseudo-random star polygons, 5–15 vertices.
    let mut rng = chladni::rng::Rng::seeded(0x2545_f491_4f6c_dd1d);
    let mut rnd = || rng.uniform();
    let mut worst: f64 = 0.0;
    for case in 0..6 {
        let n = 5 + (rnd() * 10.0) as usize;
        let outline: Vec<[f64; 2]> = (0..n)
            .map(|i| {
                let a = (i as f64 + 0.7 * rnd()) / n as f64 * std::f64::consts::TAU;
                let r = 10.0 + 25.0 * rnd();
                [r * a.cos() + 100.0, r * a.sin() - 30.0]
            })
            .collect();
        let part = Part::new(format!("random {case}"), outline, vec![]).unwrap();
        worst = worst.max(check(&part));
    }
    println!("random parts: max fixed-vs-f64 disagreement {worst:.2e}°");
}
