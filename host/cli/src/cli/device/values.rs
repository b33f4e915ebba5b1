//! Value parsers of `chladni device`: plan names and slots (the configuration keys and their
//! values in user units are the library's, [`chladni_device::config_keys`]).
//! Each refusal names the value and what would be accepted (clap then exits with code 2).

use chladni_shared::icd::plan::MAX_NAME;
use chladni_shared::icd::store::{PLAN_SLOTS, PlanName, PlanRef};

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
}
