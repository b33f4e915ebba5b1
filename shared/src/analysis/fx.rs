//! Fixed-point numbers for the physics core: signed Q31.32 in an `i64`, plus binary angles.
//!
//! # Why our own Q31.32 and not the `fixed` crate
//! The rest analysis must give identical bits on x86-64 and on Cortex-M (QEMU), so the whole
//! path is integer arithmetic. One format suffices because [`crate::analysis::rest`] first normalises
//! every part by a power of two (an exact shift) so that all coordinates lie in (−1, 1):
//! areas, moments and turn-function values are then O(1) and a single Q31.32 covers them with
//! 2⁻³² ≈ 2.3·10⁻¹⁰ resolution and ±2·10⁹ headroom. What we need beyond `+ − × ÷` are
//! sin/cos of binary angles and `sinc`/`j1`, which `fixed` does not provide, so we would
//! write them anyway. Owning the type makes the rounding rule explicit and uniform
//! (products round half away from zero, so `(−a)·b == −(a·b)` bit for bit and mirrored
//! parts give mirrored bits), keeps the crate dependency-free, and keeps every operation
//! a one-line integer expression that is easy to audit for determinism. Products widen to
//! `i128` (one `mul` on x86-64, a compiler-rt call on Cortex-M: slower but exact).
//!
//! Angles are *binary angles* ([`Bam`]): a `u32` where 2³² is one full turn, so wrapping
//! arithmetic is the circle and 90° = 2³⁰ is exact.

use core::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

/// Signed fixed-point number, Q31.32 (`value = raw / 2³²`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Fx(pub i64);

/// Number of fractional bits of [`Fx`].
pub const FRAC: u32 = 32;

impl Fx {
    /// 0.
    pub const ZERO: Fx = Fx(0);
    /// 1.
    pub const ONE: Fx = Fx(1 << FRAC);
    /// ½.
    pub const HALF: Fx = Fx(1 << (FRAC - 1));
    /// π, rounded to nearest.
    pub const PI: Fx = Fx(13_493_037_705);
    /// 2π, rounded to nearest.
    pub const TWO_PI: Fx = Fx(26_986_075_409);
    /// 1/(2π), rounded to nearest.
    pub const INV_TWO_PI: Fx = Fx(683_565_276);
    /// Smallest positive value, 2⁻³².
    pub const EPS: Fx = Fx(1);
    /// Largest value.
    pub const MAX: Fx = Fx(i64::MAX);

    /// From an integer.
    pub const fn from_int(v: i32) -> Fx {
        Fx((v as i64) << FRAC)
    }
    /// From the ratio `num/den` (rounded toward zero). `den` must not be 0.
    pub const fn ratio(num: i64, den: i64) -> Fx {
        Fx((((num as i128) << FRAC) / den as i128) as i64)
    }
    /// The raw bits.
    pub const fn raw(self) -> i64 {
        self.0
    }
    /// Absolute value.
    pub const fn abs(self) -> Fx {
        Fx(self.0.wrapping_abs())
    }
    /// −1, 0 or 1.
    pub const fn signum(self) -> i32 {
        self.0.signum() as i32
    }
    /// Is it zero?
    pub const fn is_zero(self) -> bool {
        self.0 == 0
    }
    /// Multiplies by 2^`sh` (negative `sh` shifts right, rounding toward −∞).
    pub const fn shl(self, sh: i32) -> Fx {
        if sh >= 0 { Fx(self.0 << sh) } else { Fx(self.0 >> (-sh)) }
    }
    /// Halves (toward −∞).
    pub const fn half(self) -> Fx {
        Fx(self.0 >> 1)
    }
    /// Product rounded half away from zero.
    #[inline]
    pub const fn mul(self, rhs: Fx) -> Fx {
        let p = self.0 as i128 * rhs.0 as i128;
        // Branch-free round half away from zero: for p < 0, (p + ½ − 1) >> 32 equals
        // −((−p + ½) >> 32).
        Fx(((p + (1i128 << (FRAC - 1)) + (p >> 127)) >> FRAC) as i64)
    }
    /// Divides by a positive integer, rounding half away from zero.
    pub const fn div_int(self, d: i64) -> Fx {
        let r = (self.0.unsigned_abs() + (d as u64 >> 1)) / d as u64;
        if self.0 < 0 { Fx(-(r as i64)) } else { Fx(r as i64) }
    }
    /// Quotient rounded toward zero; `None` if `rhs` is zero or the result overflows.
    pub const fn checked_div(self, rhs: Fx) -> Option<Fx> {
        if rhs.0 == 0 {
            return None;
        }
        let q = ((self.0 as i128) << FRAC) / rhs.0 as i128;
        if q > i64::MAX as i128 || q < i64::MIN as i128 { None } else { Some(Fx(q as i64)) }
    }
    /// Square root of a non-negative value (rounded down); 0 for negative input.
    pub const fn sqrt(self) -> Fx {
        if self.0 <= 0 {
            return Fx::ZERO;
        }
        Fx(((self.0 as u128) << FRAC).isqrt() as i64)
    }
    /// Minimum.
    pub fn min(self, o: Fx) -> Fx {
        if o < self { o } else { self }
    }
    /// Maximum.
    pub fn max(self, o: Fx) -> Fx {
        if o > self { o } else { self }
    }
}

impl Add for Fx {
    type Output = Fx;
    #[inline]
    fn add(self, rhs: Fx) -> Fx {
        Fx(self.0 + rhs.0)
    }
}
impl AddAssign for Fx {
    #[inline]
    fn add_assign(&mut self, rhs: Fx) {
        self.0 += rhs.0;
    }
}
impl Sub for Fx {
    type Output = Fx;
    #[inline]
    fn sub(self, rhs: Fx) -> Fx {
        Fx(self.0 - rhs.0)
    }
}
impl SubAssign for Fx {
    #[inline]
    fn sub_assign(&mut self, rhs: Fx) {
        self.0 -= rhs.0;
    }
}
impl Neg for Fx {
    type Output = Fx;
    #[inline]
    fn neg(self) -> Fx {
        Fx(-self.0)
    }
}
impl Mul for Fx {
    type Output = Fx;
    #[inline]
    fn mul(self, rhs: Fx) -> Fx {
        Fx::mul(self, rhs)
    }
}
impl Div for Fx {
    type Output = Fx;
    /// Panics on division by zero (callers check); see [`Fx::checked_div`].
    fn div(self, rhs: Fx) -> Fx {
        match self.checked_div(rhs) {
            Some(q) => q,
            None => panic!("Fx division by zero or overflow"),
        }
    }
}

/// Binary angle: 2³² is one turn, counter-clockwise.
pub type Bam = u32;
/// 90° as a [`Bam`].
pub const QUARTER_TURN: Bam = 1 << 30;
/// 180° as a [`Bam`].
pub const HALF_TURN: Bam = 1 << 31;

/// Turns a [`Bam`] into radians in [0, 2π).
pub fn bam_to_rad(a: Bam) -> Fx {
    Fx(a as i64) * Fx::TWO_PI
}

/// The [`Bam`] of an angle in radians (any range; wraps).
pub fn rad_to_bam(x: Fx) -> Bam {
    // Low 32 bits of the Q32 value in turns are the fraction of a turn.
    (x * Fx::INV_TWO_PI).0 as u32
}

/// Taylor kernel for |x| ≤ π/4: (sin x, cos x). Truncation error < 10⁻¹¹.
fn sincos_kernel(x: Fx) -> (Fx, Fx) {
    let x2 = x * x;
    // sin: x(1 − x²/6(1 − x²/20(1 − x²/42(1 − x²/72(1 − x²/110)))))
    let mut s = Fx::ONE - x2 * Fx::ratio(1, 110);
    s = Fx::ONE - x2 * Fx::ratio(1, 72) * s;
    s = Fx::ONE - x2 * Fx::ratio(1, 42) * s;
    s = Fx::ONE - x2 * Fx::ratio(1, 20) * s;
    s = Fx::ONE - x2 * Fx::ratio(1, 6) * s;
    let s = x * s;
    // cos: 1 − x²/2(1 − x²/12(1 − x²/30(1 − x²/56(1 − x²/90(1 − x²/132)))))
    let mut c = Fx::ONE - x2 * Fx::ratio(1, 132);
    c = Fx::ONE - x2 * Fx::ratio(1, 90) * c;
    c = Fx::ONE - x2 * Fx::ratio(1, 56) * c;
    c = Fx::ONE - x2 * Fx::ratio(1, 30) * c;
    c = Fx::ONE - x2 * Fx::ratio(1, 12) * c;
    c = Fx::ONE - x2.half() * c;
    (s, c)
}

/// (sin a, cos a) of a binary angle. Exact symmetries: quadrant shifts only swap and negate.
pub fn sincos(a: Bam) -> (Fx, Fx) {
    let quadrant = a >> 30;
    let within = a & (QUARTER_TURN - 1);
    // Reduce to [−45°, 45°] about 0° or 90° of the quadrant.
    let (s, c) = if within <= QUARTER_TURN / 2 {
        sincos_kernel(bam_to_rad(within))
    } else {
        let (s, c) = sincos_kernel(bam_to_rad(QUARTER_TURN - within));
        (c, s)
    };
    match quadrant {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// (sin x, cos x) of an angle in radians.
pub fn sincos_rad(x: Fx) -> (Fx, Fx) {
    sincos(rad_to_bam(x))
}

/// sinc z = sin z / z (1 at 0).
pub fn sinc(z: Fx) -> Fx {
    let small = Fx::ratio(1, 4);
    if z.abs() <= small {
        let z2 = z * z;
        // 1 − z²/6(1 − z²/20(1 − z²/42(1 − z²/72)))
        let mut p = Fx::ONE - z2 * Fx::ratio(1, 72);
        p = Fx::ONE - z2 * Fx::ratio(1, 42) * p;
        p = Fx::ONE - z2 * Fx::ratio(1, 20) * p;
        Fx::ONE - z2 * Fx::ratio(1, 6) * p
    } else {
        sincos_rad(z).0 / z
    }
}

/// Spherical Bessel j₁(z) = (sin z − z cos z)/z² (0 at 0, ≈ z/3 near 0).
pub fn j1(z: Fx) -> Fx {
    let small = Fx::HALF;
    if z.abs() <= small {
        let z2 = z * z;
        // z/3 (1 − z²/10 (1 − z²/28 (1 − z²/54 (1 − z²/88))))
        let mut p = Fx::ONE - z2 * Fx::ratio(1, 88);
        p = Fx::ONE - z2 * Fx::ratio(1, 54) * p;
        p = Fx::ONE - z2 * Fx::ratio(1, 28) * p;
        p = Fx::ONE - z2 * Fx::ratio(1, 10) * p;
        z * Fx::ratio(1, 3) * p
    } else {
        let (s, c) = sincos_rad(z);
        (s - z * c) / (z * z)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn f(x: Fx) -> f64 {
        x.0 as f64 / 4294967296.0
    }
    fn q(x: f64) -> Fx {
        Fx((x * 4294967296.0).round() as i64)
    }

    #[test]
    fn branch_free_mul_rounds_half_away_from_zero() {
        let reference = |a: i64, b: i64| {
            let p = a as i128 * b as i128;
            let r = ((p.unsigned_abs() + (1u128 << 31)) >> 32) as i64;
            if p < 0 { -r } else { r }
        };
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        for i in 0..20_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let a = (x as i64) >> (i % 40);
            let b = ((x.rotate_left(17)) as i64) >> (20 + i % 30);
            assert_eq!((Fx(a) * Fx(b)).0, reference(a, b), "{a} {b}");
        }
        for (a, b) in [(1i64 << 31, 1i64), (-(1i64 << 31), 1), (3, 1 << 31), (-3, 1 << 31)] {
            assert_eq!((Fx(a) * Fx(b)).0, reference(a, b), "{a} {b}");
        }
    }

    #[test]
    fn constants() {
        assert!((f(Fx::PI) - core::f64::consts::PI).abs() < 1e-9);
        assert!((f(Fx::TWO_PI) - core::f64::consts::TAU).abs() < 1e-9);
        assert!((f(Fx::INV_TWO_PI) - 1.0 / core::f64::consts::TAU).abs() < 1e-9);
    }

    #[test]
    fn mul_rounds_symmetrically() {
        let a = Fx(3);
        let b = Fx::HALF;
        assert_eq!((-a) * b, -(a * b));
        assert_eq!(Fx::from_int(3) * Fx::from_int(-2), Fx::from_int(-6));
        assert_eq!(Fx::from_int(7) / Fx::from_int(2), q(3.5));
        assert_eq!(Fx::from_int(2).sqrt(), q(core::f64::consts::SQRT_2) - Fx(1));
    }

    #[test]
    fn sincos_matches_f64() {
        let mut worst: f64 = 0.0;
        for i in 0..4096u32 {
            let a = i.wrapping_mul(1_048_573).wrapping_add(i * 7);
            let (s, c) = sincos(a);
            let x = a as f64 / 4294967296.0 * core::f64::consts::TAU;
            worst = worst.max((f(s) - x.sin()).abs()).max((f(c) - x.cos()).abs());
        }
        assert!(worst < 3e-9, "worst {worst}");
        assert_eq!(sincos(0), (Fx::ZERO, Fx::ONE));
        assert_eq!(sincos(QUARTER_TURN), (Fx::ONE, Fx::ZERO));
        assert_eq!(sincos(HALF_TURN), (Fx::ZERO, -Fx::ONE));
    }

    #[test]
    fn sinc_and_j1_match_f64() {
        for i in -400..=400 {
            let z = i as f64 * 0.01;
            let sz = if z == 0.0 { 1.0 } else { z.sin() / z };
            let jz = if z == 0.0 { 0.0 } else { (z.sin() - z * z.cos()) / (z * z) };
            assert!((f(sinc(q(z))) - sz).abs() < 1e-8, "sinc {z}");
            assert!((f(j1(q(z))) - jz).abs() < 1e-8, "j1 {z}: {} vs {jz}", f(j1(q(z))));
        }
    }
}
