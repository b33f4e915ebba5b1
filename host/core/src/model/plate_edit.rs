//! Editing one value of a plate file in place, keeping everything else as written (comments,
//! order, spacing): `toml_edit` parses the file into a document that prints back byte for
//! byte, and only the value set changes. Used by `chladni plate calibrate-speed` to write a
//! fitted `speed_mm_s`.

use toml_edit::{DocumentMut, Item, Value};

use crate::model::plate::{PlateModel, SAME_FREQ_HZ};

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
        match entry.get_mut("speed_mm_s").and_then(Item::as_value_mut) {
            // In place: the key, its position and the value's comment stay.
            Some(old) => {
                let decor = old.decor().clone();
                *old = Value::from(speed);
                *old.decor_mut() = decor;
            }
            None => {
                entry.insert("speed_mm_s", Item::Value(Value::from(speed)));
            }
        }
    }
    if found == 0 {
        return Err(PlateEditError::NoEntry { freq_hz });
    }
    let out = doc.to_string();
    let back = PlateModel::parse(&out, "edited plate")
        .map_err(|e| PlateEditError::ReadBack { speed, why: e.to_string() })?;
    let ok = back
        .modes
        .iter()
        .any(|m| (m.freq_hz - freq_hz).abs() < SAME_FREQ_HZ && m.speed_mm_s == speed);
    if !ok {
        return Err(PlateEditError::ReadBack { speed, why: "the mode's speed differs".into() });
    }
    Ok(out)
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
}
