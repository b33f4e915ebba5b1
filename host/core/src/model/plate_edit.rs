//! Editing one value of a plate file in place, keeping everything else as written (comments,
//! order, spacing): `toml_edit` parses the file into a document that prints back byte for
//! byte, and only the value set changes. Used by `chladni plate calibrate-speed` to write a
//! fitted `speed_mm_s`, and by `chladni plate learn` to write each mode's measured speed and
//! node shift with the `[learned]` table that says where they come from.

use toml_edit::{DocumentMut, Item, Value};

use crate::model::plate::{PlateModel, SAME_FREQ_HZ};
use crate::model::plate_file::Learned;

/// Why the value could not be written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlateEditError {
    /// Not TOML (the plate reader would have said so first).
    #[error("the plate file is not TOML: {0}")]
    Toml(String),
    /// The modes are not written as `[[mode]]` tables.
    #[error(
        "the plate file's modes are not `[[mode]]` tables: write speed_mm_s = {speed} into the \
         mode at {freq_hz} Hz by hand"
    )]
    NotTables {
        /// The value to write.
        speed: f64,
        /// The mode's frequency.
        freq_hz: f64,
    },
    /// No `[[mode]]` entry at the mode's frequency.
    #[error("no [[mode]] entry at {freq_hz} Hz in the plate file")]
    NoEntry {
        /// The mode's frequency.
        freq_hz: f64,
    },
    /// The edited file does not read back with the new value.
    #[error("the edited plate file does not read back with speed_mm_s = {speed}: {why}")]
    ReadBack {
        /// The value written.
        speed: f64,
        /// What the reader said.
        why: String,
    },
}

/// A `freq_hz` value as a number (TOML integer or float).
fn as_number(item: &Item) -> Option<f64> {
    item.as_float().or_else(|| item.as_integer().map(|i| i as f64))
}

/// `text` with `speed_mm_s = speed` in every `[[mode]]` entry at `freq_hz` (within
/// [`SAME_FREQ_HZ`]: the entries of one merged mode), the value's comments kept; checked by
/// reading the result back as a plate whose mode at `freq_hz` has that speed.
pub fn set_speed(text: &str, freq_hz: f64, speed: f64) -> Result<String, PlateEditError> {
    let mut doc: DocumentMut = text.parse().map_err(|e| PlateEditError::Toml(format!("{e}")))?;
    set_in_modes(&mut doc, freq_hz, speed, "speed_mm_s", Value::from(speed))?;
    let out = doc.to_string();
    read_back(&out, speed, |m| {
        (m.freq_hz - freq_hz).abs() < SAME_FREQ_HZ && m.speed_mm_s == speed
    })?;
    Ok(out)
}

/// `text` with each mode that `learned` measured corrected (its `speed_mm_s` the given one
/// times the measured factor, its `shift_mm` the measured shift) and the `[learned]` table
/// set to `learned`; checked by reading the result back.
pub fn set_learned(text: &str, learned: &Learned) -> Result<String, PlateEditError> {
    let given =
        PlateModel::parse(text, "given plate").map_err(|e| PlateEditError::Toml(e.to_string()))?;
    let mut doc: DocumentMut = text.parse().map_err(|e| PlateEditError::Toml(format!("{e}")))?;
    let mut expected = Vec::new();
    for m in &learned.mode {
        let Some(mode) = given.modes.iter().find(|g| (g.freq_hz - m.freq_hz).abs() < SAME_FREQ_HZ)
        else {
            return Err(PlateEditError::NoEntry { freq_hz: m.freq_hz });
        };
        let speed = mode.speed_mm_s * m.speed_factor;
        set_in_modes(&mut doc, m.freq_hz, speed, "speed_mm_s", Value::from(speed))?;
        let shift = toml_edit::Array::from_iter(m.shift_mm);
        set_in_modes(&mut doc, m.freq_hz, speed, "shift_mm", Value::Array(shift))?;
        expected.push((m.freq_hz, speed, m.shift_mm));
    }
    let table = toml::to_string(learned).map_err(|e| PlateEditError::Toml(e.to_string()))?;
    let table: DocumentMut = table.parse().map_err(|e| PlateEditError::Toml(format!("{e}")))?;
    doc.insert("learned", Item::Table(table.as_table().clone()));
    let out = doc.to_string();
    for (freq_hz, speed, shift) in expected {
        read_back(&out, speed, |m| {
            (m.freq_hz - freq_hz).abs() < SAME_FREQ_HZ
                && m.speed_mm_s == speed
                && m.shift_mm == shift
        })?;
    }
    Ok(out)
}

/// Sets `key = value` in every `[[mode]]` entry at `freq_hz`, in place when the key is there
/// (its position and comment kept); `speed` only names the value in errors.
fn set_in_modes(
    doc: &mut DocumentMut,
    freq_hz: f64,
    speed: f64,
    key: &str,
    value: Value,
) -> Result<(), PlateEditError> {
    let Some(modes) = doc.get_mut("mode").and_then(Item::as_array_of_tables_mut) else {
        return Err(PlateEditError::NotTables { speed, freq_hz });
    };
    let mut found = 0;
    for entry in modes.iter_mut() {
        let at = entry.get("freq_hz").and_then(as_number);
        if !at.is_some_and(|f| (f - freq_hz).abs() < SAME_FREQ_HZ) {
            continue;
        }
        found += 1;
        match entry.get_mut(key).and_then(Item::as_value_mut) {
            // In place: the key, its position and the value's comment stay.
            Some(old) => {
                let decor = old.decor().clone();
                *old = value.clone();
                *old.decor_mut() = decor;
            }
            None => {
                entry.insert(key, Item::Value(value.clone()));
            }
        }
    }
    if found == 0 {
        return Err(PlateEditError::NoEntry { freq_hz });
    }
    Ok(())
}

/// Reads `out` back as a plate; some mode must pass `ok`.
fn read_back(
    out: &str,
    speed: f64,
    ok: impl Fn(&crate::model::plate::Mode) -> bool,
) -> Result<(), PlateEditError> {
    let back = PlateModel::parse(out, "edited plate")
        .map_err(|e| PlateEditError::ReadBack { speed, why: e.to_string() })?;
    if !back.modes.iter().any(ok) {
        return Err(PlateEditError::ReadBack { speed, why: "the mode's values differ".into() });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const PLATE: &str = "# my plate\n[plate]\nname = \"t\"   # keep me\nsize_mm = [300.0, 200.0]\n\n\
        [[mode]]\nname = \"a\"\nfreq_hz = 60\nspeed_mm_s = 10.0   # guessed\nnode = { kind = \"line\", angle_deg = 90.0 }\n\n\
        [[mode]]\nname = \"b\"\nfreq_hz = 80.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n";

    #[test]
    fn only_the_speed_changes() {
        let out = set_speed(PLATE, 60.0, 12.3457).unwrap();
        assert_eq!(
            out,
            PLATE.replace("speed_mm_s = 10.0   # guessed", "speed_mm_s = 12.3457   # guessed")
        );
        // A mode without the key gets one; the other mode is untouched.
        let out = set_speed(PLATE, 80.0, 4.5).unwrap();
        let m = PlateModel::parse(&out, "t").unwrap();
        assert_eq!((m.modes[0].speed_mm_s, m.modes[1].speed_mm_s), (10.0, 4.5));
        assert!(out.starts_with("# my plate\n[plate]\nname = \"t\"   # keep me\n"));
        assert_eq!(set_speed(PLATE, 70.0, 1.0), Err(PlateEditError::NoEntry { freq_hz: 70.0 }));
        let inline = "[plate]\nsize_mm = [1.0, 1.0]\nmode = []\n";
        assert!(matches!(set_speed(inline, 60.0, 1.0), Err(PlateEditError::NotTables { .. })));
    }

    #[test]
    fn a_learned_plate_is_the_given_one_corrected_and_says_so() {
        let learned = Learned {
            given: "plate.toml".into(),
            at: "2026-12-07T19:00:00Z".into(),
            camera: "http://127.0.0.1:9/frame.png".into(),
            bursts: 30,
            held_out: 10,
            mode: vec![LearnedModeRow::row(60.0, 2.0, [4.0, -3.0])],
        };
        let out = set_learned(PLATE, &learned).unwrap();
        assert!(out.contains("speed_mm_s = 20.0   # guessed"), "{out}");
        let m = PlateModel::parse(&out, "t").unwrap();
        assert_eq!(m.modes[0].shift_mm, [4.0, -3.0]);
        assert_eq!((m.modes[1].speed_mm_s, m.modes[1].shift_mm), (10.0, [0.0, 0.0]));
        let file = crate::model::plate_file::PlateFile::parse(&out, "t").unwrap();
        assert_eq!(file.learned, Some(learned.clone()));
        // Learning again replaces the table and the values, never stacks them.
        let again = set_learned(&out, &learned).unwrap();
        assert_eq!(again.matches("[learned]").count(), 1, "{again}");
        let bad = Learned { mode: vec![LearnedModeRow::row(70.0, 1.0, [0.0, 0.0])], ..learned };
        assert_eq!(set_learned(PLATE, &bad), Err(PlateEditError::NoEntry { freq_hz: 70.0 }));
    }

    /// A learned mode row for the tests.
    struct LearnedModeRow;
    impl LearnedModeRow {
        fn row(
            freq_hz: f64,
            speed_factor: f64,
            shift_mm: [f64; 2],
        ) -> crate::model::plate_file::LearnedMode {
            crate::model::plate_file::LearnedMode {
                freq_hz,
                bursts: 10,
                held_out: 3,
                speed_factor,
                shift_mm,
                before_mm: 3.0,
                after_mm: 0.5,
                before_deg: 9.0,
                after_deg: 2.0,
            }
        }
    }
}
