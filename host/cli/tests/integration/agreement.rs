//! Fixed-point analysis (chladni_shared::analysis::rest) against the independent f64 reference
//! (chladni_core::analysis::reference): rest orientations agree within 0.05° on every test part.

use std::path::Path;

use chladni_core::analysis::reference::{RefField, RefRest, Reference};
use chladni_core::model::field::Law;
use chladni_core::model::part::Part;
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

/// Both lists are sorted on [0°, 360°), which is a circle: a rest at the wrap can come
/// first in one (0.000°, the fixed-point analysis's exact root on a binary angle) and last in
/// the other (359.99999°, the reference's bisection from below). The rotation `k` of the
/// reference list that pairs each fixed rest with the reference rest nearest it on the circle
/// (the smallest largest distance).
fn pairing(fixed: &[f64], reference: &[RefRest]) -> usize {
    let n = reference.len();
    let worst = |k: usize| {
        (fixed.iter().enumerate())
            .map(|(i, &f)| adist(f, reference[(i + k) % n].deg))
            .fold(0.0, f64::max)
    };
    (0..n).min_by(|&a, &b| worst(a).total_cmp(&worst(b))).unwrap_or(0)
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
    let k = pairing(&fixed.rests.iter().map(|f| deg_from_bam(f.angle)).collect::<Vec<_>>(), &rests);
    let mut worst: f64 = 0.0;
    for (f, r) in fixed.rests.iter().zip(rests.iter().cycle().skip(k)) {
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

/// The fields every part is checked in: three laws at equal gains, two at unequal ones.
fn fields(part: &Part) -> [(Law, f64, f64); 5] {
    let w = 1.3 * diameter(part);
    [
        (Law::Sign, 1.0, 1.0),
        (Law::Linear, 1.0, 1.0),
        (Law::Sine { wavelength_mm: w }, 1.0, 1.0),
        (Law::Sign, 1.0, 2.5),
        (Law::Linear, 3.0, 1.0),
    ]
}

/// Max disagreement over the fields of [`fields`] numbered in `which`.
fn check_in(part: &Part, which: &[usize]) -> f64 {
    let all = fields(part);
    which
        .iter()
        .map(|&i| all[i])
        .map(|(law, gl, gr)| compare(part, law, gl, gr))
        .fold(0.0, f64::max)
}

fn check(part: &Part) -> f64 {
    check_in(part, &[0, 1, 2, 3, 4])
}

/// The part files of one folder of examples/parts (`""`: the top one), sub-folders skipped.
fn parts_in(folder: &str) -> Vec<Part> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/parts").join(folder);
    let mut paths: Vec<_> = (std::fs::read_dir(&dir).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e != "py"))
        .collect();
    paths.sort();
    paths.iter().map(|p| Part::load(p).unwrap()).collect()
}

#[test]
fn example_parts_agree_with_the_f64_reference() {
    let mut worst: f64 = 0.0;
    let parts = parts_in("");
    assert!(parts.len() >= 6);
    for part in &parts {
        worst = worst.max(check(part));
    }
    println!("example parts: max fixed-vs-f64 disagreement {worst:.2e}°");
}

#[test]
fn ordinary_parts_agree_with_the_f64_reference() {
    // examples/parts/ordinary/: ten parts with holes, slots and teeth (generate.py there),
    // 8–132 vertices each. Every part under the sign law at equal gains (where the crank
    // lever has a rest at 0°, the wrap of the circle: `pairing`), and one more field each, in
    // turn, so that every field meets two of them at two fifths of the whole grid's time.
    let mut worst: f64 = 0.0;
    let parts = parts_in("ordinary");
    assert!(parts.len() >= 10);
    assert!(parts.iter().any(|p| p.name == "crank lever"));
    for (i, part) in parts.iter().enumerate() {
        worst = worst.max(check_in(part, &[0, 1 + i % 4]));
    }
    println!("ordinary parts: max fixed-vs-f64 disagreement {worst:.2e}°");
}

#[test]
fn random_polygons_agree_with_the_f64_reference() {
    // Deterministic pseudo-random star polygons, 5–15 vertices.
    let mut rng = chladni_core::rng::Rng::seeded(0x2545_f491_4f6c_dd1d);
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
