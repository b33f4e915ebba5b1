//! The true plate: the plate the rig's parts really move on, which differs from the plate file
//! the user gives (as a real plate differs from its model). Either a plate file of its own, or
//! the given plate warped: each mode's nodes shifted by a random distance in a random direction
//! and its settle speed multiplied by a random factor (seeded).

use chladni_core::model::modes_file;
use chladni_core::model::plate::{PlateModel, SAME_FREQ_HZ};
use chladni_core::model::plate_file::{ModeEntry, PlateFile};
use chladni_core::rng::Rng;
use serde::Serialize;

use crate::RigError;

/// How the given plate is warped into the true one when no true plate file is given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Warp {
    /// The distance each mode's nodes move, drawn uniformly in [min, max] (mm), in a
    /// direction drawn uniformly.
    pub shift_mm: [f64; 2],
    /// The factor each mode's `speed_mm_s` is multiplied by, drawn log-uniformly in
    /// [min, max].
    pub speed_factor: [f64; 2],
}

/// The warp of the benchmarks: nodes 4–8 mm away, speeds off by ×0.4–×2.5.
pub const DEFAULT_WARP: Warp = Warp { shift_mm: [4.0, 8.0], speed_factor: [0.4, 2.5] };

/// One mode of the true plate, as `/truth` and the listening line report it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModeTruth {
    /// Drive frequency (Hz).
    pub freq_hz: f64,
    /// The mode's name.
    pub name: String,
    /// Its `shift_mm` (mm, plate frame): how far its nodes lie from where its node entry puts
    /// them (for a warp, the given plate's shift plus the one drawn).
    pub shift_mm: [f64; 2],
    /// The true settle speed (mm/s).
    pub speed_mm_s: f64,
    /// The true speed over the given plate's (`None`: a true plate file was given).
    pub speed_factor: Option<f64>,
}

/// The plate the parts move on.
#[derive(Debug, Clone)]
pub struct TruePlate {
    /// As a plate file (what `--write-true-plate` writes).
    pub file: PlateFile,
    /// Typed, as the motion model runs it.
    pub model: PlateModel,
    /// Each mode of `model`, with how it differs from the given plate.
    pub modes: Vec<ModeTruth>,
}

/// Moves an entry's nodes by `shift` (mm) more than it says: its `shift_mm`, which the mode's
/// field applies.
fn add_shift(entry: &mut ModeEntry, shift: [f64; 2]) {
    let [x, y] = entry.shift_mm.unwrap_or([0.0, 0.0]);
    entry.shift_mm = Some([round4(x + shift[0]), round4(y + shift[1])]);
}

/// Rounds to 4 decimals: the written file is the plate the rig runs.
fn round4(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

impl TruePlate {
    /// A true plate given as a plate file (its shifts as written; no speed factors), for the
    /// plate `given`: both must type, and be one size.
    pub fn from_file(file: PlateFile, given: &PlateFile) -> Result<TruePlate, RigError> {
        let typed = PlateModel::from_file(given).map_err(RigError::GivenPlate)?;
        let model = PlateModel::from_file(&file).map_err(RigError::TruePlate)?;
        if model.size_mm != typed.size_mm {
            return Err(RigError::SizeMismatch { given: typed.size_mm, truth: model.size_mm });
        }
        let modes = truths(&model, &[]);
        Ok(TruePlate { file, model, modes })
    }

    /// The given plate warped by `warp`, drawn from `seed`: entries at one frequency (one mode,
    /// several node lines) share one shift and one factor.
    pub fn warped(given: &PlateFile, warp: &Warp, seed: u64) -> Result<TruePlate, RigError> {
        check_warp(warp)?;
        let typed = PlateModel::from_file(given).map_err(RigError::GivenPlate)?;
        let mut rng = Rng::seeded(seed);
        let mut drawn: Vec<(f64, [f64; 2], f64)> = Vec::new();
        let mut file = given.clone();
        for entry in &mut file.mode {
            let freq = entry.freq_hz.unwrap_or(f64::NAN);
            let draw = match drawn.iter().find(|d| (d.0 - freq).abs() < SAME_FREQ_HZ) {
                Some(d) => *d,
                None => {
                    let d = (freq, draw_shift(&mut rng, warp), draw_factor(&mut rng, warp));
                    drawn.push(d);
                    d
                }
            };
            let speed = typed.modes.iter().find(|m| (m.freq_hz - freq).abs() < SAME_FREQ_HZ);
            // Every entry has a mode: the typed plate merged entries, it dropped none.
            let speed = speed.map_or(f64::NAN, |m| m.speed_mm_s);
            entry.speed_mm_s = Some(round4(speed * draw.2));
            add_shift(entry, draw.1);
        }
        let model = PlateModel::from_file(&file).map_err(RigError::TruePlate)?;
        let factors: Vec<(f64, f64)> = drawn.iter().map(|d| (d.0, d.2)).collect();
        let modes = truths(&model, &factors);
        Ok(TruePlate { file, model, modes })
    }

    /// The plate file's text (the schema every command reads).
    pub fn to_toml(&self) -> Result<String, RigError> {
        modes_file::render(&self.file.plate, self.file.mode.clone())
            .map_err(|e| RigError::WriteTruePlate(e.to_string()))
    }
}

/// A warp's ranges: finite, min ≤ max, shifts ≥ 0, factors > 0.
fn check_warp(w: &Warp) -> Result<(), RigError> {
    let [a, b] = w.shift_mm;
    if !(a.is_finite() && b.is_finite() && 0.0 <= a && a <= b) {
        return Err(RigError::BadRange {
            flag: "--warp-mm",
            min: a,
            max: b,
            what: "0 ≤ MIN ≤ MAX",
        });
    }
    let [a, b] = w.speed_factor;
    if !(a.is_finite() && b.is_finite() && 0.0 < a && a <= b) {
        let what = "0 < MIN ≤ MAX";
        return Err(RigError::BadRange { flag: "--speed-factor", min: a, max: b, what });
    }
    Ok(())
}

/// A shift of length uniform in the warp's range, direction uniform.
fn draw_shift(rng: &mut Rng, w: &Warp) -> [f64; 2] {
    let r = rng.range(w.shift_mm[0], w.shift_mm[1]);
    let a = rng.range(0.0, std::f64::consts::TAU);
    [round4(r * a.cos()), round4(r * a.sin())]
}

/// A factor log-uniform in the warp's range.
fn draw_factor(rng: &mut Rng, w: &Warp) -> f64 {
    let [a, b] = w.speed_factor;
    rng.range(a.ln(), b.ln()).exp()
}

/// Each typed mode with its factor (`factors`: (freq, factor) as drawn; none for a plate given
/// as a file).
fn truths(model: &PlateModel, factors: &[(f64, f64)]) -> Vec<ModeTruth> {
    model
        .modes
        .iter()
        .map(|m| ModeTruth {
            freq_hz: m.freq_hz,
            name: m.name.clone(),
            shift_mm: m.shift_mm,
            speed_mm_s: m.speed_mm_s,
            speed_factor: factors
                .iter()
                .find(|f| (f.0 - m.freq_hz).abs() < SAME_FREQ_HZ)
                .map(|f| f.1),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use chladni_core::model::plate::Node;

    const GIVEN: &str = "[plate]\nname = \"t\"\nsize_mm = [300.0, 200.0]\n\
        [[mode]]\nfreq_hz = 60.0\nnode = { kind = \"line\", angle_deg = 90.0 }\n\
        [[mode]]\nfreq_hz = 60.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n\
        [[mode]]\nfreq_hz = 100.0\nspeed_mm_s = 20.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n";

    #[test]
    fn a_warp_draws_each_modes_factor_in_its_range_from_the_seed_and_writes_what_it_runs() {
        let given = PlateFile::parse(GIVEN, "t").unwrap();
        let warp = Warp { shift_mm: [4.0, 8.0], speed_factor: [0.4, 2.5] };
        let a = TruePlate::warped(&given, &warp, 7).unwrap();
        assert_eq!(a.modes.len(), 2, "the two 60 Hz lines are one mode");
        for (m, given_speed) in a.modes.iter().zip([10.0, 20.0]) {
            let f = m.speed_factor.unwrap();
            assert!((0.4..=2.5).contains(&f), "{f}");
            assert!((m.speed_mm_s - round4(given_speed * f)).abs() < 1e-9, "{m:?}");
        }
        // The two entries of the 60 Hz mode got the same speed and shift; each mode's nodes
        // moved by 4–8 mm.
        assert_eq!(a.file.mode[0].speed_mm_s, a.file.mode[1].speed_mm_s);
        assert_eq!(a.file.mode[0].shift_mm, a.file.mode[1].shift_mm);
        for m in &a.modes {
            let r = m.shift_mm[0].hypot(m.shift_mm[1]);
            assert!((4.0 - 1e-3..=8.0 + 1e-3).contains(&r), "{m:?}");
        }
        assert_ne!(a.modes[0].shift_mm, a.modes[1].shift_mm);
        // The 100 Hz line (angle 0, through the centre) moved by the shift's y.
        let Node::Line { offset_mm, .. } = a.model.modes[1].node else { panic!() };
        assert!((offset_mm - a.modes[1].shift_mm[1]).abs() < 1e-9, "{offset_mm}");
        // Reproducible from the seed, another seed draws otherwise.
        let b = TruePlate::warped(&given, &warp, 7).unwrap();
        assert_eq!(a.modes, b.modes);
        let c = TruePlate::warped(&given, &warp, 8).unwrap();
        assert_ne!(a.modes, c.modes);
        // The file written is the plate run.
        let back = PlateModel::parse(&a.to_toml().unwrap(), "back").unwrap();
        assert_eq!(back, a.model);
    }

    #[test]
    fn a_shift_the_given_plate_holds_is_added_to() {
        let text = GIVEN.replace("speed_mm_s = 20.0", "speed_mm_s = 20.0\nshift_mm = [1.0, 2.0]");
        let given = PlateFile::parse(&text, "t").unwrap();
        let warp = Warp { shift_mm: [5.0, 5.0], speed_factor: [1.0, 1.0] };
        let a = TruePlate::warped(&given, &warp, 7).unwrap();
        let drawn = [a.modes[1].shift_mm[0] - 1.0, a.modes[1].shift_mm[1] - 2.0];
        assert!((drawn[0].hypot(drawn[1]) - 5.0).abs() < 1e-3, "{:?}", a.modes[1]);
        assert_eq!(a.modes[1].speed_factor, Some(1.0));
        // A true plate from a file reports its own shifts, no factors.
        let b = TruePlate::from_file(given.clone(), &given).unwrap();
        assert_eq!((b.modes[1].shift_mm, b.modes[1].speed_factor), ([1.0, 2.0], None));
    }

    #[test]
    fn draws_cover_their_ranges_and_bad_ranges_are_refused() {
        let warp = Warp { shift_mm: [4.0, 8.0], speed_factor: [0.4, 2.5] };
        let mut rng = Rng::seeded(1);
        let (mut lo, mut hi, mut below_one) = (f64::INFINITY, 0.0f64, 0);
        for _ in 0..2000 {
            let s = draw_shift(&mut rng, &warp);
            let r = s[0].hypot(s[1]);
            assert!((4.0 - 1e-3..=8.0 + 1e-3).contains(&r), "{r}");
            let f = draw_factor(&mut rng, &warp);
            assert!((0.4..=2.5).contains(&f));
            (lo, hi) = (lo.min(f), hi.max(f));
            below_one += usize::from(f < 1.0);
        }
        assert!(lo < 0.45 && hi > 2.3, "{lo} {hi}");
        // Log-uniform over 0.4..2.5: half the draws are below 1 (ln 0.4 = −ln 2.5).
        assert!((900..1100).contains(&below_one), "{below_one}");
        let given = PlateFile::parse(GIVEN, "t").unwrap();
        for bad in [
            Warp { shift_mm: [8.0, 4.0], ..warp },
            Warp { shift_mm: [-1.0, 4.0], ..warp },
            Warp { speed_factor: [0.0, 2.0], ..warp },
            Warp { speed_factor: [f64::NAN, 2.0], ..warp },
        ] {
            let e = TruePlate::warped(&given, &bad, 1).unwrap_err();
            assert!(matches!(e, RigError::BadRange { .. }), "{e}");
        }
    }
}
