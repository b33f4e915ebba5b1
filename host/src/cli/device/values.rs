//! Value parsers of `chladni device`: plan names and slots, configuration keys and values.
//! Each refusal names the value and what would be accepted (clap then exits with code 2).

use chladni_shared::icd::plan::{DeviceLimits, MAX_NAME};
use chladni_shared::icd::store::{DeviceConfig, PLAN_SLOTS, PlanName, PlanRef};
use chladni_shared::icd::units::{MilliHz, Q15};

use crate::cli::InputError;

/// `--slot`: 0..PLAN_SLOTS.
pub fn slot(s: &str) -> Result<u8, String> {
    match s.trim().parse::<u8>() {
        Ok(slot) if slot < PLAN_SLOTS => Ok(slot),
        _ => Err(format!("slot {s} does not exist: slots are 0..={}", PLAN_SLOTS - 1)),
    }
}

/// A plan name: 1..=MAX_NAME bytes.
pub fn plan_name(s: &str) -> Result<PlanName, String> {
    if s.is_empty() {
        return Err("a plan name cannot be empty".into());
    }
    PlanName::try_from(s)
        .map_err(|_| format!("plan name '{s}' is {} bytes, at most {MAX_NAME} fit", s.len()))
}

/// `NAME|SLOT`: a value of digits only is a slot, anything else a name.
pub fn plan_target(s: &str) -> Result<PlanRef, String> {
    if !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()) {
        return slot(s).map(PlanRef::Slot);
    }
    plan_name(s).map(PlanRef::Name)
}

/// A key of the controller's configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConfigKey {
    /// Lowest drive frequency, Hz.
    MinFreqHz,
    /// Highest drive frequency, Hz.
    MaxFreqHz,
    /// Highest amplitude, fraction of full scale.
    MaxAmplitude,
    /// Most steps per plan.
    MaxSteps,
    /// Longest plan (all repeats), ms.
    MaxTotalMs,
}

/// Every key, in the order `config get` prints them.
pub const CONFIG_KEYS: [ConfigKey; 5] = [
    ConfigKey::MinFreqHz,
    ConfigKey::MaxFreqHz,
    ConfigKey::MaxAmplitude,
    ConfigKey::MaxSteps,
    ConfigKey::MaxTotalMs,
];

/// A configuration key by name.
pub fn config_key(s: &str) -> Result<ConfigKey, String> {
    CONFIG_KEYS.into_iter().find(|k| k.name() == s).ok_or_else(|| {
        let names: Vec<&str> = CONFIG_KEYS.iter().map(|k| k.name()).collect();
        format!("unknown configuration key '{s}': the keys are {}", names.join(", "))
    })
}

/// A configuration value in the unit the CLI shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ConfigValue {
    /// Hz or a fraction: a number with decimals.
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

impl ConfigKey {
    /// The key's name.
    pub const fn name(self) -> &'static str {
        match self {
            ConfigKey::MinFreqHz => "min_freq_hz",
            ConfigKey::MaxFreqHz => "max_freq_hz",
            ConfigKey::MaxAmplitude => "max_amplitude",
            ConfigKey::MaxSteps => "max_steps",
            ConfigKey::MaxTotalMs => "max_total_ms",
        }
    }

    /// The key's value in `config`.
    pub fn get(self, config: &DeviceConfig) -> ConfigValue {
        let l = &config.limits;
        match self {
            ConfigKey::MinFreqHz => ConfigValue::Real(MilliHz(l.min_freq_mhz).to_hz()),
            ConfigKey::MaxFreqHz => ConfigValue::Real(MilliHz(l.max_freq_mhz).to_hz()),
            ConfigKey::MaxAmplitude => ConfigValue::Real(Q15(l.max_amplitude_q15).to_fraction()),
            ConfigKey::MaxSteps => ConfigValue::Count(u64::from(l.max_steps)),
            ConfigKey::MaxTotalMs => ConfigValue::Count(l.max_total_ms),
        }
    }

    /// Sets the key in `config` from `value` as typed; the whole configuration is checked
    /// afterwards ([`DeviceConfig::validate`]).
    pub fn set(self, config: &mut DeviceConfig, value: &str) -> Result<(), InputError> {
        let name = self.name();
        let bad = |what: &str| InputError(format!("{name} must be {what}, got '{value}'"));
        let hw = DeviceLimits::DEFAULT;
        let l = &mut config.limits;
        match self {
            ConfigKey::MinFreqHz | ConfigKey::MaxFreqHz => {
                let hz: f64 = value.trim().parse().map_err(|_| bad("a frequency in Hz"))?;
                let mhz = MilliHz::from_hz(hz).map_err(|e| InputError(format!("{name}: {e}")))?.0;
                *if self == ConfigKey::MinFreqHz {
                    &mut l.min_freq_mhz
                } else {
                    &mut l.max_freq_mhz
                } = mhz;
            }
            ConfigKey::MaxAmplitude => {
                let a: f64 = value.trim().parse().map_err(|_| bad("a fraction of full scale"))?;
                l.max_amplitude_q15 =
                    Q15::from_fraction(a).map_err(|e| InputError(format!("{name}: {e}")))?.0;
            }
            ConfigKey::MaxSteps => {
                let what = format!("a whole number in 1..={}", hw.max_steps);
                l.max_steps = match value.trim().parse::<u16>() {
                    Ok(v) if (1..=hw.max_steps).contains(&v) => v,
                    _ => return Err(bad(&what)),
                };
            }
            ConfigKey::MaxTotalMs => {
                let what = format!("whole milliseconds in 1..={}", hw.max_total_ms);
                l.max_total_ms = match value.trim().parse::<u64>() {
                    Ok(v) if (1..=hw.max_total_ms).contains(&v) => v,
                    _ => return Err(bad(&what)),
                };
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_slots_and_other_values_names() {
        assert_eq!(plan_target("7"), Ok(PlanRef::Slot(7)));
        assert_eq!(plan_target("064"), Ok(PlanRef::Slot(64)));
        assert_eq!(plan_target("square-45"), Ok(PlanRef::Name("square-45".try_into().unwrap())));
        assert_eq!(plan_target("7b"), Ok(PlanRef::Name("7b".try_into().unwrap())));
        assert_eq!(plan_target("65").unwrap_err(), "slot 65 does not exist: slots are 0..=64");
        assert_eq!(plan_target("300").unwrap_err(), "slot 300 does not exist: slots are 0..=64");
        assert_eq!(plan_target("").unwrap_err(), "a plan name cannot be empty");
        let long = "x".repeat(33);
        assert_eq!(
            plan_target(&long).unwrap_err(),
            format!("plan name '{long}' is 33 bytes, at most 32 fit")
        );
        assert_eq!(slot("64"), Ok(64));
        assert!(slot("-1").is_err());
    }

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
    fn bad_config_keys_and_values_are_named() {
        assert_eq!(
            config_key("max_freq").unwrap_err(),
            "unknown configuration key 'max_freq': the keys are min_freq_hz, max_freq_hz, \
             max_amplitude, max_steps, max_total_ms"
        );
        let mut c = DeviceConfig::DEFAULT;
        let err = |key: ConfigKey, v: &str, c: &mut DeviceConfig| key.set(c, v).unwrap_err().0;
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
