//! Resonance finding on synthetic second-order responses with known f₀ and Q.

use super::*;
use chladni_core::rng::Rng;

/// A mode driven by a force, seen by an accelerometer: complex acceleration per unit force,
/// `gain · r² / (1 − r² + 2iζr)` with r = f/f₀ (peak gain ≈ gain/(2ζ) at f₀/√(1−2ζ²)).
fn mode(f: f64, f0: f64, zeta: f64, gain: f64) -> (f64, f64) {
    let r = f / f0;
    let (re, im) = (1.0 - r * r, 2.0 * zeta * r);
    let d = re * re + im * im;
    (gain * r * r * re / d, -gain * r * r * im / d)
}

/// A sweep as the controller spaces it, of the sum of `modes` (f₀, ζ, gain), with relative
/// noise `noise` (uniform, that standard deviation) on the amplitude.
fn sweep(
    from: f64,
    to: f64,
    points: u16,
    modes: &[(f64, f64, f64)],
    noise: f64,
) -> Vec<SweepSample> {
    let s = sweep_request(from, to, points, 0.1, 100).unwrap();
    let mut rng = Rng::seeded(0x5eed);
    (0..points)
        .map(|i| {
            let f = MilliHz(s.freq_mhz(i)).to_hz();
            let (re, im) = modes.iter().fold((0.0, 0.0), |(re, im), &(f0, z, g)| {
                let (r, i) = mode(f, f0, z, g);
                (re + r, im + i)
            });
            let jitter = 1.0 + noise * rng.range(-3f64.sqrt(), 3f64.sqrt());
            SweepSample {
                freq_hz: f,
                accel_mps2: Some(re.hypot(im) * jitter),
                phase_deg: Some(im.atan2(re).to_degrees()),
            }
        })
        .collect()
}

/// Peak frequency of the acceleration response of one mode.
fn peak_of(f0: f64, zeta: f64) -> f64 {
    f0 / (1.0 - 2.0 * zeta * zeta).sqrt()
}

#[test]
fn one_mode_frequency_and_q_over_the_damping_range() {
    for (zeta, q_tol) in [(0.01, 0.03), (0.02, 0.03), (0.05, 0.04), (0.1, 0.08)] {
        let f0 = 181.5;
        // Wide enough for both half-power points, fine enough for ~6 points across them.
        let span = 1.0 + 8.0 * zeta;
        let s = sweep(f0 / span, f0 * span, 200, &[(f0, zeta, 1.0)], 0.0);
        let r = find_resonances(&s);
        assert_eq!(r.len(), 1, "ζ {zeta}: {r:?}");
        let (f, q) = (r[0].freq_hz, r[0].q.expect("both crossings inside"));
        let truth = peak_of(f0, zeta);
        assert!((f - truth).abs() / truth < 0.001, "ζ {zeta}: f {f} vs {truth}");
        let q_true = 1.0 / (2.0 * zeta);
        assert!((q - q_true).abs() / q_true < q_tol, "ζ {zeta}: Q {q} vs {q_true}");
        assert!((r[0].accel_mps2 * 2.0 * zeta - 1.0).abs() < 0.02, "ζ {zeta}: {r:?}");
    }
}

#[test]
fn noise_makes_no_false_peaks_and_moves_the_estimates_little() {
    let f0 = 95.0;
    for seed_noise in [0.01, 0.03] {
        let s = sweep(60.0, 150.0, 200, &[(f0, 0.02, 2.0)], seed_noise);
        let r = find_resonances(&s);
        assert_eq!(r.len(), 1, "noise {seed_noise}: {r:?}");
        assert!((r[0].freq_hz - peak_of(f0, 0.02)).abs() / f0 < 0.003, "{r:?}");
        let q = r[0].q.unwrap();
        assert!((q - 25.0).abs() / 25.0 < 0.15, "noise {seed_noise}: Q {q}");
    }
}

#[test]
fn two_modes_are_found_in_order_with_their_own_q() {
    let modes = [(60.0, 0.02, 1.0), (181.5, 0.01, 0.8)];
    let s = sweep(40.0, 300.0, 200, &modes, 0.01);
    let r = find_resonances(&s);
    assert_eq!(r.len(), 2, "{r:?}");
    for (found, &(f0, zeta, _)) in r.iter().zip(&modes) {
        assert!((found.freq_hz - f0).abs() / f0 < 0.005, "{found:?} vs {f0}");
        let q_true = 1.0 / (2.0 * zeta);
        let q = found.q.unwrap();
        assert!((q - q_true).abs() / q_true < 0.25, "{found:?} vs Q {q_true}");
    }
}

#[test]
fn a_peak_at_the_sweeps_edge_has_no_q_and_flat_noise_has_no_peak() {
    // The sweep stops just above the peak: no upper half-power crossing.
    let f0 = 100.0;
    let s = sweep(80.0, 100.8, 150, &[(f0, 0.02, 1.0)], 0.0);
    let r = find_resonances(&s);
    assert_eq!(r.len(), 1, "{r:?}");
    assert_eq!(r[0].q, None);
    // Noise alone on a flat response.
    let mut rng = Rng::seeded(7);
    let flat: Vec<SweepSample> = (0..200)
        .map(|i| SweepSample {
            freq_hz: 50.0 + i as f64,
            accel_mps2: Some(1.0 + 0.05 * rng.range(-1.0, 1.0)),
            phase_deg: Some(0.0),
        })
        .collect();
    assert_eq!(find_resonances(&flat), []);
}

#[test]
fn missing_measurements_are_skipped() {
    let mut s = sweep(80.0, 125.0, 120, &[(100.0, 0.03, 1.0)], 0.0);
    for p in s.iter_mut().step_by(7) {
        p.accel_mps2 = None;
        p.phase_deg = None;
    }
    let r = find_resonances(&s);
    assert_eq!(r.len(), 1, "{r:?}");
    assert!((r[0].freq_hz - peak_of(100.0, 0.03)).abs() < 0.2, "{r:?}");
    let csv = to_csv(&s);
    assert!(csv.starts_with("freq_hz,accel_mps2,phase_deg\n80.000,"), "{csv}");
    assert_eq!(csv.lines().count(), 121);
    assert_eq!(csv.lines().filter(|l| l.ends_with(",,")).count(), 18);
}

#[test]
fn requests_are_checked_in_user_units() {
    let s = sweep_request(20.0, 400.0, 100, 0.1, 150).unwrap();
    assert_eq!((s.from_mhz, s.to_mhz, s.amplitude_q15), (20_000, 400_000, 3277));
    assert_eq!(sweep_ms(&s), 15_000);
    let err = sweep_request(0.5, 400.0, 100, 0.1, 150).unwrap_err();
    assert!(err.to_string().starts_with("--from: frequency 0.5 Hz is outside"), "{err}");
    assert!(matches!(
        sweep_request(20.0, 4000.0, 100, 0.1, 150),
        Err(SweepInputError::Frequency { flag: "--to", .. })
    ));
    assert_eq!(
        sweep_request(400.0, 20.0, 100, 0.1, 150).unwrap_err().to_string(),
        "sweep from 400.000 Hz to 20.000 Hz: the start must be below the end"
    );
    assert!(
        sweep_request(20.0, 400.0, 1, 0.1, 150).unwrap_err().to_string().contains("give 2..=200")
    );
    assert!(
        sweep_request(20.0, 400.0, 100, 1.5, 150)
            .unwrap_err()
            .to_string()
            .starts_with("--amplitude: amplitude 1.5")
    );
    assert!(
        sweep_request(20.0, 400.0, 100, 0.1, 5).unwrap_err().to_string().contains("10..=10000 ms")
    );
}

#[test]
fn points_convert_from_the_wire_once() {
    use chladni_shared::icd::link::Measurement;
    let p = SweepPoint {
        freq_mhz: 181_500,
        measured: Some(Measurement { accel_mmps2: 12_345, phase_mdeg: -90_250 }),
    };
    let s = SweepSample::from(&p);
    assert_eq!((s.freq_hz, s.accel_mps2, s.phase_deg), (181.5, Some(12.345), Some(-90.25)));
    let none = SweepSample::from(&SweepPoint { freq_mhz: 1_000, measured: None });
    assert_eq!((none.accel_mps2, none.phase_deg), (None, None));
}
