//! The controller's configuration keys in user units (`chladni device config get|set`, the
//! limits and the fault monitors' thresholds, docs/device.md): each key's name, its unit (Hz,
//! fraction of full scale, m/s², dB, ms) and the one conversion to and from the wire's, through
//! [`chladni_shared::icd::units`]. Each refusal names the key, the value and what would be
//! accepted.

use chladni_shared::icd::plan::DeviceLimits;
use chladni_shared::icd::store::{ConfigError, ControlField, DeviceConfig};
use chladni_shared::icd::units::{MilliDb, MilliHz, MmPerS2, Q15};

/// A value a key cannot take, or a key that does not exist.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigValueError {
    /// Not a value of the key's kind (a number; a whole number in range).
    #[error("{key} must be {what}, got '{value}'")]
    NotA {
        /// The key.
        key: &'static str,
        /// What it takes.
        what: String,
        /// The value as typed.
        value: String,
    },
    /// A number its unit cannot carry (the unit's own error, e.g. a negative level).
    #[error("{key}: {reason}")]
    Unit {
        /// The key.
        key: &'static str,
        /// The unit's refusal.
        reason: String,
    },
    /// No such key.
    #[error("unknown configuration key '{key}': the keys are {names}")]
    UnknownKey {
        /// The name given.
        key: String,
        /// Every key's name, comma separated.
        names: String,
    },
}

/// A key of the controller's configuration, in the CLI's units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConfigKey {
    /// Lowest drive frequency, Hz.
    MinFreqHz,
    /// Highest drive frequency, Hz.
    MaxFreqHz,
    /// Highest amplitude, fraction of full scale.
    MaxAmplitude,
    /// Highest closed-loop acceleration target, m/s².
    MaxAccelMps2,
    /// Most steps per plan.
    MaxSteps,
    /// Longest plan (all repeats), ms.
    MaxTotalMs,
    /// Response below which the loop counts as open (`open_loop_mmps2`), m/s².
    OpenLoopMps2,
    /// Least response of the loop check (`check_min_mmps2`), m/s².
    CheckMinMps2,
    /// A threshold of the fault monitors named by the device's [`ControlField`].
    Control(ControlField),
}

/// Every key, in the order `config get` prints them.
pub const CONFIG_KEYS: [ConfigKey; 18] = [
    ConfigKey::MinFreqHz,
    ConfigKey::MaxFreqHz,
    ConfigKey::MaxAmplitude,
    ConfigKey::MaxAccelMps2,
    ConfigKey::MaxSteps,
    ConfigKey::MaxTotalMs,
    ConfigKey::OpenLoopMps2,
    ConfigKey::Control(ControlField::OpenLoopEffort),
    ConfigKey::Control(ControlField::OpenLoopMs),
    ConfigKey::Control(ControlField::WarnBand),
    ConfigKey::Control(ControlField::AbortBand),
    ConfigKey::Control(ControlField::BandMs),
    ConfigKey::Control(ControlField::MaxAccel),
    ConfigKey::Control(ControlField::NoDataMs),
    ConfigKey::Control(ControlField::SaturationMs),
    ConfigKey::Control(ControlField::CheckEffort),
    ConfigKey::Control(ControlField::CheckMs),
    ConfigKey::CheckMinMps2,
];

/// A configuration key by name.
pub fn config_key(s: &str) -> Result<ConfigKey, ConfigValueError> {
    CONFIG_KEYS.into_iter().find(|k| k.name() == s).ok_or_else(|| {
        let names: Vec<&str> = CONFIG_KEYS.iter().map(|k| k.name()).collect();
        ConfigValueError::UnknownKey { key: s.to_string(), names: names.join(", ") }
    })
}

/// A configuration value in the unit the CLI shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ConfigValue {
    /// Hz, m/s², dB or a fraction: a number with decimals.
    Real(f64),
    /// Steps or milliseconds.
    Count(u64),
}

impl ConfigValue {
    /// As JSON.
    pub fn to_json(self) -> serde_json::Value {
        match self {
            ConfigValue::Real(v) => serde_json::json!(v),
            ConfigValue::Count(v) => serde_json::json!(v),
        }
    }
}

/// The CLI's unit of a key: how a value is read, and the one conversion to the wire's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Unit {
    /// Hz ↔ mHz.
    Hz,
    /// Fraction of full scale ↔ Q15.
    Fraction,
    /// m/s² ↔ mm/s².
    Mps2,
    /// dB ↔ mdB.
    Db,
    /// Whole milliseconds or steps, as on the wire.
    Count,
}

impl ConfigKey {
    /// The key's name.
    pub const fn name(self) -> &'static str {
        use ControlField as F;
        match self {
            ConfigKey::MinFreqHz => "min_freq_hz",
            ConfigKey::MaxFreqHz => "max_freq_hz",
            ConfigKey::MaxAmplitude => "max_amplitude",
            ConfigKey::MaxAccelMps2 => "max_accel_mps2",
            ConfigKey::MaxSteps => "max_steps",
            ConfigKey::MaxTotalMs => "max_total_ms",
            ConfigKey::OpenLoopMps2 => "open_loop_mps2",
            ConfigKey::CheckMinMps2 => "check_min_mps2",
            ConfigKey::Control(field) => match field {
                F::WarnBand => "warn_band_db",
                F::AbortBand => "abort_band_db",
                F::MaxAccel => "fault_accel_mps2",
                F::OpenLoopMs => "open_loop_ms",
                F::OpenLoopEffort => "open_loop_effort",
                F::BandMs => "band_ms",
                F::NoDataMs => "no_data_ms",
                F::SaturationMs => "saturation_ms",
                F::CheckMs => "check_ms",
                F::CheckEffort => "check_effort",
            },
        }
    }

    /// The key that shows `field` (the device names a refused threshold by its field).
    pub(crate) fn of_field(field: ControlField) -> ConfigKey {
        ConfigKey::Control(field)
    }

    fn unit(self) -> Unit {
        use ControlField as F;
        match self {
            ConfigKey::MinFreqHz | ConfigKey::MaxFreqHz => Unit::Hz,
            ConfigKey::MaxAmplitude => Unit::Fraction,
            ConfigKey::MaxAccelMps2 => Unit::Mps2,
            ConfigKey::MaxSteps | ConfigKey::MaxTotalMs => Unit::Count,
            ConfigKey::OpenLoopMps2 | ConfigKey::CheckMinMps2 => Unit::Mps2,
            ConfigKey::Control(field) => match field {
                F::WarnBand | F::AbortBand => Unit::Db,
                F::MaxAccel => Unit::Mps2,
                F::OpenLoopEffort | F::CheckEffort => Unit::Fraction,
                _ => Unit::Count,
            },
        }
    }

    /// The key's value on the wire (mHz, Q15, mm/s², mdB, ms, steps) in `config`, widened.
    fn raw(self, config: &DeviceConfig) -> u64 {
        use ControlField as F;
        let (l, c) = (&config.limits, &config.control);
        match self {
            ConfigKey::MinFreqHz => u64::from(l.min_freq_mhz),
            ConfigKey::MaxFreqHz => u64::from(l.max_freq_mhz),
            ConfigKey::MaxAmplitude => u64::from(l.max_amplitude_q15),
            ConfigKey::MaxAccelMps2 => u64::from(l.max_accel_mmps2),
            ConfigKey::MaxSteps => u64::from(l.max_steps),
            ConfigKey::MaxTotalMs => l.max_total_ms,
            ConfigKey::OpenLoopMps2 => u64::from(c.open_loop_mmps2),
            ConfigKey::CheckMinMps2 => u64::from(c.check_min_mmps2),
            ConfigKey::Control(field) => match field {
                F::WarnBand => u64::from(c.warn_band_mdb),
                F::AbortBand => u64::from(c.abort_band_mdb),
                F::MaxAccel => u64::from(c.max_accel_mmps2),
                F::OpenLoopMs => u64::from(c.open_loop_ms),
                F::OpenLoopEffort => u64::from(c.open_loop_effort_q15),
                F::BandMs => u64::from(c.band_ms),
                F::NoDataMs => u64::from(c.no_data_ms),
                F::SaturationMs => u64::from(c.saturation_ms),
                F::CheckMs => u64::from(c.check_ms),
                F::CheckEffort => u64::from(c.check_effort_q15),
            },
        }
    }

    /// Writes `raw` (already within the field's type, see [`Self::parse`]) into `config`.
    fn store(self, config: &mut DeviceConfig, raw: u64) {
        use ControlField as F;
        // `parse` bounds each value by its field's type; the casts cannot truncate.
        let (l, c) = (&mut config.limits, &mut config.control);
        let (w32, w16) = (raw as u32, raw as u16);
        match self {
            ConfigKey::MinFreqHz => l.min_freq_mhz = w32,
            ConfigKey::MaxFreqHz => l.max_freq_mhz = w32,
            ConfigKey::MaxAmplitude => l.max_amplitude_q15 = w16,
            ConfigKey::MaxAccelMps2 => l.max_accel_mmps2 = w32,
            ConfigKey::MaxSteps => l.max_steps = w16,
            ConfigKey::MaxTotalMs => l.max_total_ms = raw,
            ConfigKey::OpenLoopMps2 => c.open_loop_mmps2 = w32,
            ConfigKey::CheckMinMps2 => c.check_min_mmps2 = w32,
            ConfigKey::Control(field) => match field {
                F::WarnBand => c.warn_band_mdb = w32,
                F::AbortBand => c.abort_band_mdb = w32,
                F::MaxAccel => c.max_accel_mmps2 = w32,
                F::OpenLoopMs => c.open_loop_ms = w32,
                F::OpenLoopEffort => c.open_loop_effort_q15 = w16,
                F::BandMs => c.band_ms = w32,
                F::NoDataMs => c.no_data_ms = w32,
                F::SaturationMs => c.saturation_ms = w32,
                F::CheckMs => c.check_ms = w32,
                F::CheckEffort => c.check_effort_q15 = w16,
            },
        }
    }

    /// The key's value in `config`, in the CLI's unit.
    pub fn get(self, config: &DeviceConfig) -> ConfigValue {
        self.value_of(self.raw(config))
    }

    /// A wire value of this key in the CLI's unit (the one conversion back).
    pub(crate) fn value_of(self, raw: u64) -> ConfigValue {
        let r32 = u32::try_from(raw).unwrap_or(u32::MAX);
        match self.unit() {
            Unit::Hz => ConfigValue::Real(MilliHz(r32).to_hz()),
            Unit::Fraction => {
                ConfigValue::Real(Q15(u16::try_from(raw).unwrap_or(u16::MAX)).to_fraction())
            }
            Unit::Mps2 => ConfigValue::Real(MmPerS2(r32).to_mps2()),
            Unit::Db => ConfigValue::Real(MilliDb(r32).to_db()),
            Unit::Count => ConfigValue::Count(raw),
        }
    }

    /// The value as typed, converted to the wire's unit (the one conversion there); ranges
    /// that depend on other keys are left to [`DeviceConfig::validate`].
    fn parse(self, value: &str) -> Result<u64, ConfigValueError> {
        let name = self.name();
        let bad = |what: &str| ConfigValueError::NotA {
            key: name,
            what: what.to_string(),
            value: value.to_string(),
        };
        let named =
            |e: &dyn std::fmt::Display| ConfigValueError::Unit { key: name, reason: e.to_string() };
        let hw = DeviceLimits::DEFAULT;
        let real = |what: &str| value.trim().parse::<f64>().map_err(|_| bad(what));
        Ok(match (self, self.unit()) {
            (_, Unit::Hz) => {
                u64::from(MilliHz::from_hz(real("a frequency in Hz")?).map_err(|e| named(&e))?.0)
            }
            (_, Unit::Fraction) => u64::from(
                Q15::from_fraction(real("a fraction of full scale")?).map_err(|e| named(&e))?.0,
            ),
            (_, Unit::Mps2) => u64::from(
                MmPerS2::from_mps2(real("an acceleration in m/s²")?).map_err(|e| named(&e))?.0,
            ),
            (_, Unit::Db) => {
                u64::from(MilliDb::from_db(real("a level in dB")?).map_err(|e| named(&e))?.0)
            }
            (ConfigKey::MaxSteps, _) => {
                let what = format!("a whole number in 1..={}", hw.max_steps);
                match value.trim().parse::<u16>() {
                    Ok(v) if (1..=hw.max_steps).contains(&v) => u64::from(v),
                    _ => return Err(bad(&what)),
                }
            }
            (ConfigKey::MaxTotalMs, _) => {
                let what = format!("whole milliseconds in 1..={}", hw.max_total_ms);
                match value.trim().parse::<u64>() {
                    Ok(v) if (1..=hw.max_total_ms).contains(&v) => v,
                    _ => return Err(bad(&what)),
                }
            }
            (_, Unit::Count) => match value.trim().parse::<u32>() {
                Ok(v) => u64::from(v),
                _ => return Err(bad("whole milliseconds")),
            },
        })
    }

    /// Sets the key in `config` from `value` as typed; the whole configuration is checked
    /// afterwards ([`DeviceConfig::validate`], [`config_refusal`]).
    pub fn set(self, config: &mut DeviceConfig, value: &str) -> Result<(), ConfigValueError> {
        let raw = self.parse(value)?;
        self.store(config, raw);
        Ok(())
    }
}

/// A refused configuration, for people: a threshold is named by its field
/// ([`ControlField::name`]), its value on the wire and its rule, then by the key that sets it
/// and the value in the CLI's unit.
pub fn config_refusal(e: &ConfigError) -> String {
    match *e {
        ConfigError::Control { field, value } => {
            let key = ConfigKey::of_field(field);
            let shown = match key.value_of(u64::from(value)) {
                ConfigValue::Real(v) => format!("{v}"),
                ConfigValue::Count(v) => format!("{v}"),
            };
            format!(
                "{e} (`config set {} {shown}`: change it, or the key it depends on)",
                key.name()
            )
        }
        _ => e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_keys_round_trip_through_their_units() {
        let mut c = DeviceConfig::DEFAULT;
        for (key, value) in [
            ("min_freq_hz", "20.5"),
            ("max_freq_hz", "400"),
            ("max_amplitude", "0.5"),
            ("max_steps", "100"),
            ("max_total_ms", "60000"),
        ] {
            config_key(key).unwrap().set(&mut c, value).unwrap();
        }
        let l = c.limits;
        assert_eq!((l.min_freq_mhz, l.max_freq_mhz), (20_500, 400_000));
        assert_eq!((l.max_amplitude_q15, l.max_steps, l.max_total_ms), (16384, 100, 60_000));
        assert_eq!(c.validate(), Ok(()));
        assert_eq!(ConfigKey::MinFreqHz.get(&c), ConfigValue::Real(20.5));
        assert_eq!(ConfigKey::MaxAmplitude.get(&c).to_json(), serde_json::json!(16384.0 / 32767.0));
        assert_eq!(ConfigKey::MaxSteps.get(&c).to_json(), serde_json::json!(100));
    }

    #[test]
    fn control_keys_take_user_units_and_convert_once() {
        let mut c = DeviceConfig::DEFAULT;
        for (key, value) in [
            ("max_accel_mps2", "80"),
            ("open_loop_mps2", "0.25"),
            ("open_loop_effort", "0.05"),
            ("open_loop_ms", "120"),
            ("warn_band_db", "1.5"),
            ("abort_band_db", "4"),
            ("band_ms", "400"),
            ("fault_accel_mps2", "120.5"),
            ("no_data_ms", "60"),
            ("saturation_ms", "250"),
            ("check_effort", "0.1"),
            ("check_ms", "80"),
            ("check_min_mps2", "0.5"),
        ] {
            config_key(key).unwrap().set(&mut c, value).unwrap();
            // Back in the same unit, to the wire's resolution (fractions: one Q15 step).
            let back = config_key(key).unwrap().get(&c).to_json().as_f64().unwrap();
            let want: f64 = value.parse().unwrap();
            assert!((back - want).abs() <= 0.5 / 32767.0, "{key}: {back} vs {want}");
        }
        let k = c.control;
        assert_eq!(c.limits.max_accel_mmps2, 80_000);
        assert_eq!((k.open_loop_mmps2, k.open_loop_effort_q15, k.open_loop_ms), (250, 1638, 120));
        assert_eq!((k.warn_band_mdb, k.abort_band_mdb, k.band_ms), (1_500, 4_000, 400));
        assert_eq!((k.max_accel_mmps2, k.no_data_ms, k.saturation_ms), (120_500, 60, 250));
        assert_eq!((k.check_effort_q15, k.check_ms, k.check_min_mmps2), (3277, 80, 500));
        assert_eq!(c.validate(), Ok(()));
        // Every key of the device's configuration is reachable, each once.
        let mut names: Vec<&str> = CONFIG_KEYS.iter().map(|k| k.name()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), CONFIG_KEYS.len());
    }

    #[test]
    fn a_refused_threshold_names_the_field_its_rule_and_the_key() {
        let mut c = DeviceConfig::DEFAULT;
        ConfigKey::Control(ControlField::WarnBand).set(&mut c, "5").unwrap();
        let e = c.validate().unwrap_err();
        assert_eq!(e, ConfigError::Control { field: ControlField::WarnBand, value: 5_000 });
        assert_eq!(
            config_refusal(&e),
            "warn_band_mdb = 5000 must be above 0 and below abort_band_mdb (`config set \
             warn_band_db 5`: change it, or the key it depends on)"
        );
        let mut c = DeviceConfig::DEFAULT;
        ConfigKey::Control(ControlField::MaxAccel).set(&mut c, "90").unwrap();
        let e = c.validate().unwrap_err();
        assert!(config_refusal(&e).contains("fault_accel_mps2 90`"), "{}", config_refusal(&e));
        let mut bad =
            |k: &str, v: &str| config_key(k).unwrap().set(&mut c, v).unwrap_err().to_string();
        assert_eq!(bad("warn_band_db", "loud"), "warn_band_db must be a level in dB, got 'loud'");
        assert!(bad("warn_band_db", "-1").starts_with("warn_band_db: -1 dB is not"));
        assert!(bad("max_accel_mps2", "-2").contains("acceleration -2 m/s²"));
        assert_eq!(bad("band_ms", "0.5"), "band_ms must be whole milliseconds, got '0.5'");
        assert!(bad("check_effort", "1.2").contains("amplitude 1.2 outside 0..=1"));
    }

    #[test]
    fn bad_config_keys_and_values_are_named() {
        assert_eq!(
            config_key("max_freq").unwrap_err().to_string(),
            "unknown configuration key 'max_freq': the keys are min_freq_hz, max_freq_hz, \
             max_amplitude, max_accel_mps2, max_steps, max_total_ms, open_loop_mps2, \
             open_loop_effort, open_loop_ms, warn_band_db, abort_band_db, band_ms, \
             fault_accel_mps2, no_data_ms, saturation_ms, check_effort, check_ms, check_min_mps2"
        );
        let mut c = DeviceConfig::DEFAULT;
        let err =
            |key: ConfigKey, v: &str, c: &mut DeviceConfig| key.set(c, v).unwrap_err().to_string();
        assert_eq!(
            err(ConfigKey::MaxFreqHz, "fast", &mut c),
            "max_freq_hz must be a frequency in Hz, got 'fast'"
        );
        assert!(err(ConfigKey::MaxFreqHz, "5000", &mut c).contains("frequency 5000 Hz is outside"));
        assert!(err(ConfigKey::MaxAmplitude, "2", &mut c).contains("amplitude 2"));
        assert_eq!(
            err(ConfigKey::MaxSteps, "0", &mut c),
            "max_steps must be a whole number in 1..=256, got '0'"
        );
        assert_eq!(
            err(ConfigKey::MaxTotalMs, "1.5", &mut c),
            "max_total_ms must be whole milliseconds in 1..=3600000, got '1.5'"
        );
        assert_eq!(c, DeviceConfig::DEFAULT, "a refused value changes nothing");
        // A value fine alone but not with the rest is caught by the whole check.
        ConfigKey::MinFreqHz.set(&mut c, "1500").unwrap();
        ConfigKey::MaxFreqHz.set(&mut c, "1000").unwrap();
        assert!(c.validate().is_err());
    }
}
