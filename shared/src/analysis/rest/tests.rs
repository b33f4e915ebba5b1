extern crate std;
use std::vec::Vec as StdVec;

use proptest::prelude::*;

use super::*;
use crate::analysis::geometry::{HalfPlane, clip_ring, ring_moments};

fn q(x: f64) -> Fx {
    Fx((x * 4294967296.0).round() as i64)
}
fn f(x: Fx) -> f64 {
    x.raw() as f64 / 4294967296.0
}
fn deg(a: Bam) -> f64 {
    a as f64 * 360.0 / 4294967296.0
}
fn bam(d: f64) -> Bam {
    ((d.rem_euclid(360.0)) / 360.0 * 4294967296.0).round() as u64 as u32
}
fn ring(pts: &[(f64, f64)]) -> StdVec<Pt> {
    pts.iter().map(|&(x, y)| Pt::new(q(x), q(y))).collect()
}
/// Angular distance in degrees.
fn adist(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}
fn field(kind: FieldKind) -> Field {
    Field::symmetric(kind)
}
fn run(rings: &[&[Pt]], fld: Field) -> Analysis {
    Analyzer::new(rings, fld).unwrap().analyze().unwrap()
}
fn angles(a: &Analysis, stable: bool) -> StdVec<f64> {
    a.rests.iter().filter(|r| r.stable == stable).map(|r| deg(r.angle)).collect()
}
fn assert_angles(got: &[f64], want: &[f64], tol: f64) {
    assert_eq!(got.len(), want.len(), "got {got:?}, want {want:?}");
    for (g, w) in got.iter().zip(want) {
        assert!(adist(*g, *w) < tol, "got {got:?}, want {want:?}");
    }
}

fn rect(w: f64, h: f64) -> StdVec<Pt> {
    ring(&[(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)])
}

#[test]
fn rectangle_rests_with_long_side_along_the_node() {
    let r = rect(4.0, 1.0);
    for kind in [
        FieldKind::Sign,
        FieldKind::Linear,
        FieldKind::Sine { wavelength: q(10.0) },
        FieldKind::Sine { wavelength: q(4.2) },
    ] {
        let a = run(&[&r], field(kind));
        assert!(!a.neutral);
        assert_angles(&angles(&a, true), &[90.0, 270.0], 1e-6);
        assert_angles(&angles(&a, false), &[0.0, 180.0], 1e-6);
        assert_eq!(a.order, 2, "{kind:?}");
    }
}

#[test]
fn square_sign_field_rests_on_a_diagonal() {
    let s = rect(3.0, 3.0);
    let a = run(&[&s], field(FieldKind::Sign));
    assert_angles(&angles(&a, true), &[45.0, 135.0, 225.0, 315.0], 1e-6);
    assert_angles(&angles(&a, false), &[0.0, 90.0, 180.0, 270.0], 1e-6);
    assert_eq!(a.order, 4);
}

#[test]
fn square_linear_field_is_neutral() {
    let s = rect(3.0, 3.0);
    let a = run(&[&s], field(FieldKind::Linear));
    assert!(a.neutral);
    assert!(a.rests.is_empty());
    // ... but not a rectangle.
    assert!(!run(&[&rect(3.0, 2.9)], field(FieldKind::Linear)).neutral);
}

#[test]
fn sign_field_balances_equal_areas_and_linear_field_centroid_on_node() {
    let tri = ring(&[(0.0, 0.0), (5.0, 0.0), (1.0, 3.0)]);
    let rings = [&tri[..]];
    let an = Analyzer::new(&rings, field(FieldKind::Sign)).unwrap();
    for theta in [0u32, 123_456_789, 3_000_000_000] {
        let b = an.balance(theta, Fx::ZERO);
        let (r, l) = an.side_sums(theta, b.offset);
        assert!((f(r.p) - f(l.p)).abs() < 1e-7, "areas {} {}", f(r.p), f(l.p));
    }
    let rings = [&tri[..]];
    let an = Analyzer::new(&rings, field(FieldKind::Linear)).unwrap();
    let b = an.balance(987_654_321, Fx::ONE);
    assert!(f(b.offset).abs() < 1e-7);
}

#[test]
fn side_sums_equal_explicit_clipping() {
    // L-shape with a hole: clip every ring by x ≥ 0 / x ≤ 0 explicitly and compare.
    let outline = ring(&[(0.0, 0.0), (6.0, 0.0), (6.0, 2.0), (2.0, 2.0), (2.0, 5.0), (0.0, 5.0)]);
    let hole = ring(&[(0.5, 0.5), (0.5, 1.5), (1.5, 1.5), (1.5, 0.5)]);
    let rings: [&[Pt]; 2] = [&outline, &hole];
    let an = Analyzer::new(&rings, field(FieldKind::Sign)).unwrap();
    for (theta, s) in [(0u32, q(0.1)), (1_000_000_000, q(-0.05)), (2_500_000_000, q(0.2))] {
        let (sn, cs) = fx::sincos(theta);
        let mut right = geometry::Moments::default();
        let mut left = geometry::Moments::default();
        for r in rings {
            let moved: StdVec<Pt> = r
                .iter()
                .map(|p| {
                    let n = an.normalized(*p);
                    Pt::new(cs * n.x - sn * n.y + s, sn * n.x + cs * n.y)
                })
                .collect();
            let mut buf = [Pt::default(); 32];
            let hp = HalfPlane { nx: Fx::ONE, ny: Fx::ZERO, d: Fx::ZERO };
            let k = clip_ring(&moved, hp, &mut buf).unwrap();
            right = right + ring_moments(&buf[..k]);
            let hp = HalfPlane { nx: -Fx::ONE, ny: Fx::ZERO, d: Fx::ZERO };
            let k = clip_ring(&moved, hp, &mut buf).unwrap();
            left = left + ring_moments(&buf[..k]);
        }
        let (r, l) = an.side_sums(theta, s);
        assert!((f(r.p) - f(right.area)).abs() < 1e-8);
        assert!((f(l.p) - f(left.area)).abs() < 1e-8);
        assert!((f(r.q) - f(right.sy)).abs() < 1e-8);
        assert!((f(l.q) - f(left.sy)).abs() < 1e-8);
        // Linear law: ∫∫ x dA and ∫∫ xy dA per side.
        let lin = Analyzer::new(&rings, field(FieldKind::Linear)).unwrap();
        let (r, l) = lin.side_sums(theta, s);
        assert!((f(r.p) - f(right.sx)).abs() < 1e-8);
        assert!((f(l.p) - f(left.sx)).abs() < 1e-8);
        assert!((f(r.q) - f(right.sxy)).abs() < 1e-8);
        assert!((f(l.q) - f(left.sxy)).abs() < 1e-8);
    }
}

#[test]
fn symmetric_fields_have_period_180() {
    let tri = ring(&[(0.0, 0.0), (5.0, 0.0), (1.0, 3.0)]);
    for kind in [FieldKind::Sign, FieldKind::Linear, FieldKind::Sine { wavelength: q(12.0) }] {
        let rings = [&tri[..]];
        let an = Analyzer::new(&rings, field(kind)).unwrap();
        for i in 0..16u32 {
            let th = i.wrapping_mul(268_435_399);
            let a = an.turn(th);
            let b = an.turn(th.wrapping_add(HALF_TURN));
            assert!((f(a) - f(b)).abs() < 1e-8, "{kind:?} {i}: {} vs {}", f(a), f(b));
        }
        let res = an.analyze().unwrap();
        for r in &res.rests {
            let opposite = r.angle.wrapping_add(HALF_TURN);
            assert!(res.rests.iter().any(|o| o.angle == opposite && o.stable == r.stable));
        }
    }
}

#[test]
fn unequal_gains_break_the_180_degree_ambiguity() {
    // A triangle is not centrally symmetric: with k₊ ≠ k₋ its rests lose the 180° period.
    let tri = ring(&[(0.0, 0.0), (5.0, 0.0), (1.0, 3.0)]);
    let fld = Field { kind: FieldKind::Sign, gain_left: Fx::ONE, gain_right: Fx::from_int(3) };
    let rings = [&tri[..]];
    let an = Analyzer::new(&rings, fld).unwrap();
    let a = an.analyze().unwrap();
    assert_eq!(a.order, 1);
    let st = angles(&a, true);
    assert!(!st.iter().all(|s| st.iter().any(|o| adist(*o, s + 180.0) < 0.1)), "{st:?}");
    // F = 0 at the balance with unequal gains: 3·A₊ = A₋.
    let b = an.balance(bam(33.0), Fx::ZERO);
    let (r, l) = an.side_sums(bam(33.0), b.offset);
    assert!((3.0 * f(r.p) - f(l.p)).abs() < 1e-7);
}

fn transform(r: &[Pt], rot_deg: f64, dx: f64, dy: f64) -> StdVec<Pt> {
    let (s, c) = rot_deg.to_radians().sin_cos();
    r.iter()
        .map(|p| {
            let (x, y) = (f(p.x), f(p.y));
            Pt::new(q(c * x - s * y + dx), q(s * x + c * y + dy))
        })
        .collect()
}

#[test]
fn translation_and_rotation_of_the_input() {
    let trap = ring(&[(0.0, 0.0), (8.0, 0.0), (6.0, 3.0), (1.0, 3.0)]);
    for kind in [FieldKind::Sign, FieldKind::Linear, FieldKind::Sine { wavelength: q(20.0) }] {
        let base = run(&[&trap], field(kind));
        let moved = transform(&trap, 0.0, 137.25, -48.5);
        let a = run(&[&moved], field(kind));
        assert_angles(&angles(&a, true), &angles(&base, true), 1e-5);
        assert_angles(&angles(&a, false), &angles(&base, false), 1e-5);
        // Input turned by φ: orientations shift by −φ.
        let phi = 37.0;
        let turned = transform(&trap, phi, 3.0, 4.0);
        let a = run(&[&turned], field(kind));
        let mut want: StdVec<f64> =
            angles(&base, true).iter().map(|x| (x - phi).rem_euclid(360.0)).collect();
        want.sort_by(f64::total_cmp);
        assert_angles(&angles(&a, true), &want, 1e-4);
    }
}

fn regular(n: usize, r: f64) -> StdVec<Pt> {
    let pts: StdVec<(f64, f64)> = (0..n)
        .map(|i| {
            let a = i as f64 / n as f64 * core::f64::consts::TAU + 0.1;
            (r * a.cos() + 7.0, r * a.sin() - 2.0)
        })
        .collect();
    ring(&pts)
}

#[test]
fn regular_polygons_show_their_rotational_symmetry() {
    for n in [3usize, 5, 6, 7] {
        let p = regular(n, 10.0);
        let a = run(&[&p], field(FieldKind::Sign));
        let m = if n % 2 == 0 { n } else { 2 * n };
        assert_eq!(a.order as usize, m, "n = {n}");
        let st = angles(&a, true);
        assert_eq!(st.len(), m, "n = {n}: {st:?}");
        for w in st.windows(2) {
            assert!((w[1] - w[0] - 360.0 / m as f64).abs() < 1e-4, "n = {n}: {st:?}");
        }
        // Isotropic second moment: neutral under the linear field.
        assert!(run(&[&p], field(FieldKind::Linear)).neutral, "n = {n}");
    }
}

#[test]
fn alignment_function_goes_downhill() {
    let r = rect(4.0, 1.0);
    let rings = [&r[..]];
    let an = Analyzer::new(&rings, field(FieldKind::Sign)).unwrap();
    let a = an.analyze().unwrap();
    for (from, to) in [(10.0, 90.0), (170.0, 90.0), (200.0, 270.0), (350.0, 270.0), (95.0, 90.0)] {
        assert!(adist(deg(an.align(&a, bam(from))), to) < 1e-5, "{from}");
    }
    // Unstable rests are fixed points too.
    assert_eq!(an.align(&a, 0), 0);
}

#[test]
fn bad_inputs_are_rejected() {
    let r = rect(4.0, 1.0);
    let mut cw = r.clone();
    cw.reverse();
    assert_eq!(
        Analyzer::new(&[&cw[..]], field(FieldKind::Sign)).err(),
        Some(AnalysisError::Winding { ring: 0 })
    );
    assert_eq!(
        Analyzer::new(&[&r[..2]], field(FieldKind::Sign)).err(),
        Some(AnalysisError::TooFewVertices { ring: 0 })
    );
    let fld = Field { kind: FieldKind::Sign, gain_left: Fx::ZERO, gain_right: Fx::ONE };
    assert_eq!(Analyzer::new(&[&r[..]], fld).err(), Some(AnalysisError::BadGain));
    assert_eq!(
        Analyzer::new(&[&r[..]], field(FieldKind::Sine { wavelength: q(3.0) })).err(),
        Some(AnalysisError::WavelengthTooShort)
    );
}

/// A random simple (star-shaped) polygon: sorted angles, random radii.
fn star() -> impl Strategy<Value = StdVec<(f64, f64)>> {
    (3usize..24).prop_flat_map(|n| {
        (prop::collection::vec(0.0f64..1.0, n), prop::collection::vec(0.3f64..1.0, n), 0.5f64..50.0)
            .prop_map(|(mut ang, rad, scale)| {
                ang.sort_by(f64::total_cmp);
                let n = ang.len() as f64;
                ang.iter()
                    .enumerate()
                    .zip(rad)
                    .map(|((i, a), r)| {
                        // Keep the angles strictly increasing and spread.
                        let t = (i as f64 + 0.8 * a) / n * core::f64::consts::TAU;
                        (scale * r * t.cos(), scale * r * t.sin())
                    })
                    .collect()
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn random_polygons_balance_and_alternate(pts in star(), kind in 0u8..3, skew in 0u8..2) {
        let p = ring(&pts);
        let kind = match kind {
            0 => FieldKind::Sign,
            1 => FieldKind::Linear,
            _ => FieldKind::Sine { wavelength: q(120.0) },
        };
        let fld = Field {
            kind,
            gain_left: Fx::ONE,
            gain_right: if skew == 1 { q(1.7) } else { Fx::ONE },
        };
        let rings = [&p[..]];
        let an = Analyzer::new(&rings, fld).unwrap();
        // F = 0 at the balance offset.
        for th in [0u32, 700_000_000, 2_100_000_000, 3_900_000_000] {
            let b = an.balance(th, Fx::ZERO);
            let fm = an.force_moment(th, b.offset);
            prop_assert!(f(fm.force).abs() < 1e-6, "F = {}", f(fm.force));
            prop_assert_eq!(fm.moment, b.turn);
        }
        let a = an.analyze().unwrap();
        if a.neutral { return Ok(()); }
        let n = a.rests.len();
        prop_assert!(n >= 2 && n.is_multiple_of(2), "{:?}", a.rests);
        for i in 0..n {
            let (r, s) = (a.rests[i], a.rests[(i + 1) % n]);
            // Stable and unstable alternate, and t has the right sign in between.
            prop_assert_ne!(r.stable, s.stable);
            let gap = s.angle.wrapping_sub(r.angle);
            if gap < 1 << 16 { continue; }
            let mid = r.angle.wrapping_add(gap / 2);
            let t = an.turn(mid);
            prop_assert!(if r.stable { t < Fx::ZERO } else { t > Fx::ZERO },
                "t({}) = {} after {:?}", deg(mid), f(t), r);
        }
    }
}

#[test]
fn secant_of_two_zero_ends_is_the_midpoint() {
    // The Illinois halving took both ends to 0 with gains 1 and 2 (`analyze --gain-right 2`):
    // the secant divided by zero there.
    assert_eq!(secant(1 << 20, 0, 0), 1 << 19);
    assert_eq!(secant(1 << 20, 5, 5), 1 << 19);
    assert_eq!(secant(100, 1, -1), 50);
    assert_eq!(secant(100, 0, -7), 0);
    assert_eq!(secant(100, 7, 0), 100);
}

#[test]
fn crossing_rings_with_a_far_centroid_are_refused() {
    // A bow tie whose lobes almost cancel: the net area is tiny and the centroid far outside.
    let bow = ring(&[(0.0, 0.0), (10.0, 10.0), (10.0, 0.0), (0.0, 10.001)]);
    let rings = [&bow[..]];
    let got = Analyzer::new(&rings, field(FieldKind::Sign)).err();
    assert!(
        matches!(got, Some(AnalysisError::CentroidOutside | AnalysisError::Winding { .. })),
        "{got:?}"
    );
}

/// Any gain in (0, 10⁶], with exact ratios 1:2 and 2:1 (the old division by zero) often.
fn gain() -> impl Strategy<Value = Fx> {
    prop_oneof![
        Just(Fx::ONE),
        Just(Fx::from_int(2)),
        (1i64..=1_000_000i64 << 32).prop_map(Fx),
        (1i64..1 << 32).prop_map(Fx),
    ]
}

/// Any law: sign, linear, or sine with any positive wavelength (too short is an error).
fn kind() -> impl Strategy<Value = FieldKind> {
    prop_oneof![
        Just(FieldKind::Sign),
        Just(FieldKind::Linear),
        (1i64..i64::MAX).prop_map(|w| FieldKind::Sine { wavelength: Fx(w) }),
    ]
}

/// Raw rings: any coordinates, any count (mostly nonsense: crossing, tiny, huge).
fn raw_rings() -> impl Strategy<Value = StdVec<StdVec<Pt>>> {
    let coord = prop_oneof![any::<i64>(), -(1i64 << 40)..(1i64 << 40), -64i64..64];
    let pt = (coord.clone(), coord).prop_map(|(x, y)| Pt::new(Fx(x), Fx(y)));
    prop::collection::vec(prop::collection::vec(pt, 0..12), 0..4)
}

/// A star-shaped outline with a star-shaped hole inside it (possibly none), scaled.
fn part_with_hole() -> impl Strategy<Value = StdVec<StdVec<Pt>>> {
    (star(), star(), any::<bool>(), -20i32..20).prop_map(|(outer, inner, hole, exp)| {
        let s = 2f64.powi(exp);
        let mut rings =
            StdVec::from([outer.iter().map(|&(x, y)| Pt::new(q(x * s), q(y * s))).collect()]);
        if hole {
            // Radii of the outline are ≥ 0.3·scale about the origin: a hole of radius
            // < 0.25·(its scale) scaled to 0.3·outline/50 fits inside.
            let k = 0.005 * s * outer.iter().map(|p| p.0.hypot(p.1)).fold(f64::MAX, f64::min);
            rings.push(inner.iter().rev().map(|&(x, y)| Pt::new(q(x * k), q(y * k))).collect());
        }
        rings
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// No input panics (debug build: overflow and division are checked): an error or an
    /// analysis, nothing else.
    #[test]
    fn no_part_field_or_gain_panics(
        rings in prop_oneof![raw_rings(), part_with_hole()],
        kind in kind(), gl in gain(), gr in gain(), sign_l in any::<bool>(),
    ) {
        let slices: StdVec<&[Pt]> = rings.iter().map(StdVec::as_slice).collect();
        let gain_left = if sign_l { gl } else { -gl };
        let fld = Field { kind, gain_left, gain_right: gr };
        if let Ok(an) = Analyzer::new(&slices, fld)
            && let Ok(a) = an.analyze()
        {
            prop_assert!(a.rests.windows(2).all(|w| w[0].angle <= w[1].angle));
            let _ = an.align(&a, 12345);
        }
    }
}
