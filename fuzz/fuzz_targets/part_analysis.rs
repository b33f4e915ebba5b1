//! The part analysis (`chladni_shared::analysis::rest`): arbitrary outlines, holes, gains and
//! field laws through `Analyzer::new` and `Analyzer::analyze`.
//!
//! Asserts, for every input:
//! - nothing panics (no overflow or division by zero either: built with debug assertions);
//!   a bad part or field is an `AnalysisError`;
//! - an analysis holds at most `MAX_RESTS` rests, sorted by angle; a neutral one none;
//! - the analysis is deterministic (a second run gives the same value), when the input asks
//!   for the check (below): it doubles an execution's cost, and `analyze` takes `&self` with
//!   no interior state, so the fuzzer spends most executions on new parts instead;
//! - `align` maps a start to a stable rest (or leaves it where it is when there is none).
//!
//! How the input is read (`chladni_fuzz::Choices`, missing bytes read as 0):
//! - byte 0: the law (`% 3`: sign, linear, sine); then 4 bytes and a shift byte, the sine's
//!   wavelength as raw Q31.32 bits (`u32 << (shift % 40)`, 0 included; read for every law);
//! - the gains: for each side 4 bytes and a shift byte (`u32 << (shift % 36)`), then a byte
//!   whose low bit makes the left gain negative; a byte whose low bits pick exact 1:2, 2:1 or
//!   1:1 gains over those (the ratio that once divided by zero);
//! - a mode byte: even, *raw rings*: up to 3 rings of up to [`MAX_RING`] points, each
//!   coordinate an `i32` shifted left by a per-ring shift (`% 33`): crossing, tiny, huge,
//!   degenerate; odd, *a valid part*: a star-shaped outline (3 to 10 vertices, radii from the
//!   bytes) and maybe a star-shaped hole well inside it (3 to 6), scaled by
//!   2^(byte % 48 − 24) mm;
//! - 4 bytes, the start angle given to `align`; then a byte that asks for the determinism
//!   check when it is 7 modulo 8 (an eighth of the inputs the fuzzer makes).
//!
//! Rings are kept short because an execution costs about 300 passes over every edge (128
//! samples, each balanced by Newton steps, then the roots refined): the edge cases are in the
//! shapes and numbers, not in the vertex count. An input reads at most about 230 bytes;
//! scripts/fuzz.sh caps it at 256.
#![no_main]

use chladni_fuzz::Choices;
use chladni_shared::analysis::field::{Field, FieldKind};
use chladni_shared::analysis::fx::Fx;
use chladni_shared::analysis::geometry::Pt;
use chladni_shared::analysis::rest::{Analyzer, MAX_RESTS};
use libfuzzer_sys::fuzz_target;

/// Points in a raw ring, at most.
const MAX_RING: usize = 8;

fuzz_target!(|data: &[u8]| {
    let mut c = Choices::new(data);
    let field = field(&mut c);
    let rings = if c.u8().is_multiple_of(2) { raw_rings(&mut c) } else { valid_part(&mut c) };
    let slices: Vec<&[Pt]> = rings.iter().map(Vec::as_slice).collect();
    let (start, recheck) = (c.u32(), c.u8() % 8 == 7);
    let Ok(an) = Analyzer::new(&slices, field) else { return };
    let Ok(a) = an.analyze() else { return };
    assert!(a.rests.len() <= MAX_RESTS);
    assert!(a.rests.windows(2).all(|w| w[0].angle <= w[1].angle), "{:?}", a.rests);
    assert!(!a.neutral || a.rests.is_empty());
    if recheck {
        assert_eq!(an.analyze().as_ref(), Ok(&a), "not deterministic");
    }
    let end = an.align(&a, start);
    if a.rests.iter().any(|r| r.stable) && !an.turn(start).is_zero() {
        assert!(a.rests.iter().any(|r| r.stable && r.angle == end), "{end} not a stable rest");
    }
});

fn field(c: &mut Choices<'_>) -> Field {
    let law = c.u8() % 3;
    let mut raw = |max_shift: u8| {
        let v = c.u32() as i64;
        Fx(v << (c.u8() % max_shift))
    };
    let wavelength = raw(40);
    let kind = match law {
        0 => FieldKind::Sign,
        1 => FieldKind::Linear,
        _ => FieldKind::Sine { wavelength },
    };
    let (mut gl, mut gr) = (raw(36), raw(36));
    if c.u8() & 1 == 1 {
        gl = Fx(gl.raw().wrapping_neg());
    }
    match c.u8() % 4 {
        1 => (gl, gr) = (Fx::ONE, Fx::from_int(2)),
        2 => (gl, gr) = (Fx::from_int(2), Fx::ONE),
        3 => (gl, gr) = (Fx::ONE, Fx::ONE),
        _ => {}
    }
    Field { kind, gain_left: gl, gain_right: gr }
}

fn raw_rings(c: &mut Choices<'_>) -> Vec<Vec<Pt>> {
    let n = c.u8() as usize % 4;
    (0..n)
        .map(|_| {
            let (len, shift) = (c.u8() as usize % (MAX_RING + 1), c.u8() as u32 % 33);
            let mut coord = || Fx(i64::from(c.u32() as i32) << shift);
            (0..len).map(|_| Pt::new(coord(), coord())).collect()
        })
        .collect()
}

/// A star-shaped ring: `n` vertices at increasing angles, radius `r0 · (0.25 + byte/340)`.
fn star(c: &mut Choices<'_>, n: usize, r0: f64, clockwise: bool) -> Vec<Pt> {
    let mut ring: Vec<Pt> = (0..n)
        .map(|i| {
            let t = (i as f64 + f64::from(c.u8()) / 320.0) / n as f64 * std::f64::consts::TAU;
            let r = r0 * (0.25 + f64::from(c.u8()) / 340.0);
            Pt::new(Fx::from_f64(r * t.cos()), Fx::from_f64(r * t.sin()))
        })
        .collect();
    if clockwise {
        ring.reverse();
    }
    ring
}

fn valid_part(c: &mut Choices<'_>) -> Vec<Vec<Pt>> {
    let scale = f64::from(c.u8() % 48).exp2() / 16_777_216.0;
    let n = 3 + c.u8() as usize % 8;
    let mut rings = vec![star(c, n, scale, false)];
    let holes = c.u8();
    if holes % 2 == 1 {
        // Radii of the outline are ≥ 0.25 · scale; the hole's ≤ 0.2 · scale.
        let m = 3 + (holes as usize / 2) % 4;
        rings.push(star(c, m, scale * 0.2, true));
    }
    rings
}
