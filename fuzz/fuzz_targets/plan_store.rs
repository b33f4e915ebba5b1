//! The plan store with power cuts: arbitrary sequences of uploads (begin, chunks, commit),
//! deletes, lists, loads and configuration changes on the firmware's `app::store::PlanStore`
//! over the store's NOR flash model (`app::store::mock_flash`, the L4's programming rule, cuts
//! per word), with the power cut at an arbitrary word write or page erase, then a reboot (a
//! new store over the same bytes).
//!
//! A model holds what the store acknowledged. Asserts, for every input:
//! - nothing panics, and the store never makes a program the L4 refuses (PROGERR);
//! - an acknowledged commit stores exactly the plan sent (load gives it back, its summary has
//!   its name, step count, repeat and CRC), a commit with a wrong CRC is refused;
//! - list, load (by slot and by name) and delete agree with the model while the power is on;
//! - after a power cut and a reboot the store opens, every slot reads back whole (never
//!   `Corrupt`), and holds what the model held before the operation, except the plan being
//!   committed or deleted when the power failed: that slot holds the old plan or the new
//!   state, whole. A cut before the commit was sent changes nothing. The configuration is the
//!   old or the new one the same way;
//! - a clean reboot changes nothing.
//!
//! The input is a program of at most [`MAX_OPS`] operations, each chosen by one byte `op`: `op % 6` picks upload,
//! delete, list, load, configuration or reboot; bit 7 plans a power cut inside it (two bytes:
//! after how many flash operations; one byte of noise for the torn word or page).
#![no_main]

use std::collections::BTreeMap;

use chladni_firmware::app::store::PlanStore;
use chladni_fuzz::Choices;
use chladni_fuzz::flash::{PAGE_SIZE, SharedFlash, fuzz_flash};
use chladni_shared::icd::link::Refusal;
use chladni_shared::icd::plan::{DeviceLimits, MAX_STEPS, Plan, Step};
use chladni_shared::icd::sense::ControlConfig;
use chladni_shared::icd::store::{
    CHUNK_STEPS, DeviceConfig, PLAN_SLOTS, PlanRef, PlanSummary, StoreError, UploadBegin,
    UploadChunk, plan_crc,
};
use libfuzzer_sys::fuzz_target;

/// Flash pages the store gets: the marker page and 3 for the map, room for a plan of about 200
/// steps or a few short ones, so "full" happens often. (8 before issue 42: a reboot reads back
/// all the flash holds, so a smaller flash makes executions cheaper.)
const PAGES: usize = 4;

/// Operations read from one input, at most (bytes past them are ignored): an execution's cost
/// grows with its program (every reboot reads the map back and checks every slot), and
/// libFuzzer grows inputs to 4 KB, hundreds of operations that mostly repeat what short
/// programs do. Each execution starts from erased flash; 16 operations still fill the pages
/// (a few uploads of up to 256 steps) and drive garbage collection and "full". (24 before
/// issue 42: the cost of an execution grows faster than linearly with its operations, as
/// every reboot reads back all that the earlier ones wrote.)
const MAX_OPS: usize = 16;

/// Plan names, few so that they collide.
const NAMES: [&str; 4] = ["a", "b", "square-45", ""];

fuzz_target!(|data: &[u8]| {
    embassy_futures::block_on(run(data));
    chladni_fuzz::discard_logs();
});

/// What the store acknowledged.
#[derive(Debug, Clone, Default, PartialEq)]
struct Model {
    plans: BTreeMap<u8, Plan>,
    /// The plan CRC of each plan in `plans`, computed once when it was uploaded (the summaries
    /// the store gives are checked against it; computing it again for every check was a tenth
    /// of an execution).
    crcs: BTreeMap<u8, u32>,
    config: DeviceConfig,
}

/// What an interrupted operation may have done: the slot and its new content (`None`: deleted),
/// or the new configuration.
#[derive(Debug, Clone, PartialEq)]
enum InFlight {
    Nothing,
    Slot(u8, Option<(Box<Plan>, u32)>),
    Config(DeviceConfig),
}

struct Harness {
    flash: SharedFlash,
    store: PlanStore<SharedFlash>,
    model: Model,
}

async fn run(data: &[u8]) {
    let flash = SharedFlash::new(fuzz_flash(PAGES));
    let store = open(&flash);
    let mut h = Harness { flash, store, model: Model::default() };
    let mut c = Choices::new(data);
    for _ in 0..MAX_OPS {
        if c.is_empty() {
            break;
        }
        let op = c.u8();
        let cut = op & 0x80 != 0;
        if cut {
            let (after, noise) = (c.u16() as u64 % 2048, c.u8() as u32);
            h.flash.with(|f| f.cut_after(after, noise));
        }
        let in_flight = match op % 6 {
            0 => h.upload(&mut c).await,
            1 => h.delete(&mut c).await,
            2 => {
                h.list().await;
                InFlight::Nothing
            }
            3 => {
                h.load(&mut c).await;
                InFlight::Nothing
            }
            4 => h.configure(&mut c).await,
            _ => InFlight::Nothing,
        };
        let violation = h.flash.with(|f| f.violation());
        assert_eq!(violation, None, "a program the L4 refuses (PROGERR) at this address");
        if cut || op % 6 == 5 {
            // What the store acknowledged is in the model; what failed with the power is in
            // flight. (The reboot builds the model anew: moved, not copied with every plan.)
            let acknowledged = std::mem::take(&mut h.model);
            h.reboot(acknowledged, in_flight).await;
        }
    }
    let model = std::mem::take(&mut h.model);
    h.reboot(model, InFlight::Nothing).await;
}

/// A store over the whole RAM flash, as the firmware opens it at boot.
fn open(flash: &SharedFlash) -> PlanStore<SharedFlash> {
    PlanStore::new(flash.clone(), 0..(PAGES * PAGE_SIZE) as u32)
}

/// A plan from the input: name, repeat, steps from a seed (valid unless asked otherwise).
fn plan_from(c: &mut Choices<'_>) -> Plan {
    let name = NAMES[c.u8() as usize % NAMES.len()];
    let repeat = 1 + c.u8() as u16 % 3;
    let size = c.u8();
    let count = if size & 0x80 != 0 { 1 + c.u8() as usize } else { 1 + size as usize % 40 };
    let mut seed = c.u32() | 1;
    let invalid = c.u8() == 0xff;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 17;
        seed ^= seed << 5;
        seed
    };
    let steps = (0..count.min(MAX_STEPS))
        .map(|i| {
            let duration_ms = 1 + next() % 500;
            Step {
                freq_mhz: if invalid && i == count / 2 { 0 } else { 1_000 + next() % 1_999_000 },
                level: chladni_shared::icd::plan::Level::Drive((next() % 32_768) as u16),
                duration_ms,
                ramp_ms: next() % (duration_ms + 1),
            }
        })
        .collect();
    Plan { name: heapless::String::try_from(name).unwrap_or_default(), repeat, steps }
}

impl Harness {
    fn power_is_on(&self) -> bool {
        !self.flash.with(|f| f.is_off())
    }

    /// Begin, chunks (perhaps out of order, repeated or missing), commit.
    async fn upload(&mut self, c: &mut Choices<'_>) -> InFlight {
        let plan = plan_from(c);
        let slot = match c.u8() % 4 {
            0 => None,
            _ => Some(c.u8() % (PLAN_SLOTS + 1)),
        };
        let mischief = c.u8();
        let true_crc = plan_crc(&plan);
        let crc = true_crc ^ u32::from(mischief == 0xff);
        let limits = DeviceLimits::DEFAULT;
        let begin = UploadBegin {
            slot,
            name: plan.name.clone(),
            repeat: plan.repeat,
            steps: plan.steps.len() as u16,
            crc,
        };
        let Ok(slot) = self.store.begin(begin, &limits).await else { return InFlight::Nothing };
        let mut chunks: Vec<UploadChunk> = plan
            .steps
            .chunks(CHUNK_STEPS)
            .enumerate()
            .map(|(i, s)| UploadChunk { index: i as u16, steps: s.iter().copied().collect() })
            .collect();
        match mischief % 8 {
            1 if chunks.len() > 1 => chunks.swap(0, 1),
            2 => {
                let again = chunks[0].clone();
                chunks.insert(1, again);
            }
            3 if chunks.len() > 1 => {
                chunks.remove(chunks.len() / 2);
            }
            _ => {}
        }
        for chunk in chunks {
            if self.store.chunk(chunk, &limits).await.is_err() && !self.power_is_on() {
                // The commit was never sent: the slot must keep its old plan.
                return InFlight::Nothing;
            }
        }
        match self.store.commit(&limits).await {
            Ok(summary) => {
                // (The power may have failed after the switch, while old chunks were cleared.)
                assert_ne!(mischief, 0xff, "a commit with a wrong CRC was accepted");
                check_summary(&summary, slot, &plan, true_crc);
                self.model.plans.insert(slot, plan);
                self.model.crcs.insert(slot, true_crc);
                InFlight::Nothing
            }
            Err(_) if !self.power_is_on() => InFlight::Slot(slot, Some((Box::new(plan), true_crc))),
            Err(_) => InFlight::Nothing,
        }
    }

    /// Deletes by slot or by name.
    async fn delete(&mut self, c: &mut Choices<'_>) -> InFlight {
        let target = self.plan_ref(c);
        let expected = self.find(&target);
        match self.store.delete(&target).await {
            Ok(summary) => {
                let slot = summary.slot;
                assert_eq!(Some(slot), expected, "delete of {target:?} took slot {slot}");
                let plan = self.model.plans.remove(&slot);
                let plan =
                    plan.unwrap_or_else(|| panic!("deleted slot {slot}, empty in the model"));
                let crc = self.model.crcs.remove(&slot).expect("a CRC for every model plan");
                check_summary(&summary, slot, &plan, crc);
                InFlight::Nothing
            }
            Err(_) if !self.power_is_on() => match expected {
                Some(slot) => InFlight::Slot(slot, None),
                None => InFlight::Nothing,
            },
            Err(r) => {
                assert!(expected.is_none(), "delete of {target:?} refused: {r:?}");
                assert_eq!(r, Refusal::Store(StoreError::NotFound(target)));
                InFlight::Nothing
            }
        }
    }

    /// A reference to a plan: a slot (sometimes past the last), or a name.
    fn plan_ref(&self, c: &mut Choices<'_>) -> PlanRef {
        if c.u8() & 1 == 0 {
            PlanRef::Slot(c.u8() % (PLAN_SLOTS + 1))
        } else {
            let name = NAMES[c.u8() as usize % NAMES.len()];
            PlanRef::Name(heapless::String::try_from(name).unwrap_or_default())
        }
    }

    /// The slot the model says `target` names: by name, the lowest slot below the scratch
    /// slot, then the scratch slot.
    fn find(&self, target: &PlanRef) -> Option<u8> {
        match target {
            PlanRef::Slot(slot) => self.model.plans.contains_key(slot).then_some(*slot),
            PlanRef::Name(name) => {
                self.model.plans.iter().find(|(_, p)| p.name == *name).map(|(s, _)| *s)
            }
        }
    }

    /// Every page of the list agrees with the model.
    async fn list(&mut self) {
        let mut listed = BTreeMap::new();
        let mut from = 0;
        loop {
            let page = match self.store.list(from).await {
                Ok(page) => page,
                Err(r) => {
                    assert!(!self.power_is_on(), "list refused: {r:?}");
                    return;
                }
            };
            for s in &page.plans {
                assert!(listed.insert(s.slot, s.clone()).is_none(), "slot {} listed twice", s.slot);
            }
            match page.next {
                Some(next) => {
                    assert!(next > from, "the list goes back from {from} to {next}");
                    from = next;
                }
                None => break,
            }
        }
        let slots: Vec<u8> = listed.keys().copied().collect();
        let model: Vec<u8> = self.model.plans.keys().copied().collect();
        assert_eq!(slots, model, "the list is not the model");
        for (slot, summary) in &listed {
            check_summary(summary, *slot, &self.model.plans[slot], self.model.crcs[slot]);
        }
    }

    /// Loads by slot or name; agrees with the model.
    async fn load(&mut self, c: &mut Choices<'_>) {
        let target = self.plan_ref(c);
        let expected = self.find(&target);
        let mut plan =
            Plan { name: heapless::String::new(), repeat: 0, steps: heapless::Vec::new() };
        match self.store.load(&target, &mut plan).await {
            Ok(summary) => {
                let slot =
                    expected.unwrap_or_else(|| panic!("{target:?} loaded, not in the model"));
                assert_eq!(plan, self.model.plans[&slot], "{target:?} loaded another plan");
                check_summary(&summary, slot, &plan, self.model.crcs[&slot]);
            }
            Err(_) if !self.power_is_on() => {}
            Err(r) => {
                assert!(expected.is_none(), "load of {target:?} refused: {r:?}");
                assert_eq!(r, Refusal::Store(StoreError::NotFound(target)));
            }
        }
    }

    /// Stores a valid configuration from the input.
    async fn configure(&mut self, c: &mut Choices<'_>) -> InFlight {
        let hw = DeviceLimits::DEFAULT;
        let limits = DeviceLimits {
            min_freq_mhz: hw.min_freq_mhz + c.u16() as u32,
            max_freq_mhz: hw.max_freq_mhz - c.u16() as u32,
            max_amplitude_q15: c.u16() % (hw.max_amplitude_q15 + 1),
            max_steps: 1 + c.u16() % hw.max_steps,
            max_total_ms: 1 + c.u32() as u64 % hw.max_total_ms,
            max_accel_mmps2: 1 + c.u32() % hw.max_accel_mmps2,
        };
        // The loop check's drive must fit under the amplitude limit.
        let check_effort_q15 =
            ControlConfig::DEFAULT.check_effort_q15.min(limits.max_amplitude_q15);
        let control = ControlConfig { check_effort_q15, ..ControlConfig::DEFAULT };
        let config = DeviceConfig { limits, control };
        if config.validate().is_err() {
            return InFlight::Nothing;
        }
        match self.store.set_config(config).await {
            Ok(stored) => {
                assert_eq!(stored, config);
                self.model.config = config;
                InFlight::Nothing
            }
            Err(_) if !self.power_is_on() => InFlight::Config(config),
            Err(r) => panic!("a valid configuration was refused: {r:?}"),
        }
    }

    /// Power back on, a new store over the same flash; checks every slot and the
    /// configuration against what was acknowledged (`before`) and what was in flight.
    async fn reboot(&mut self, before: Model, in_flight: InFlight) {
        self.flash.with(|f| f.reboot());
        self.store = open(&self.flash);
        let mut now = Model::default();
        for slot in 0..PLAN_SLOTS {
            let mut plan =
                Plan { name: heapless::String::new(), repeat: 0, steps: heapless::Vec::new() };
            let found = match self.store.load(&PlanRef::Slot(slot), &mut plan).await {
                Ok(summary) => Some((plan, summary)),
                Err(Refusal::Store(StoreError::NotFound(_))) => None,
                Err(r) => panic!("slot {slot} does not read back after a reboot: {r:?}"),
            };
            let old = before.plans.get(&slot).map(|p| (p, before.crcs[&slot]));
            let new = match &in_flight {
                InFlight::Slot(s, new) if *s == slot => Some(new.as_ref().map(|(p, c)| (&**p, *c))),
                _ => None,
            };
            // The plan read back is the old one or the new one; its summary is checked against
            // that plan's CRC (known from its upload).
            let found_plan = found.as_ref().map(|(p, _)| p);
            let matched = if found_plan == old.map(|(p, _)| p) {
                old
            } else if new.is_some_and(|n| found_plan == n.map(|(p, _)| p)) {
                new.flatten()
            } else {
                panic!(
                    "slot {slot} after the reboot: {found_plan:?}, expected the old {:?} or the new {:?}",
                    old.map(|(p, _)| p),
                    new.map(|n| n.map(|(p, _)| p))
                );
            };
            if let (Some((plan, summary)), Some((_, crc))) = (found, matched) {
                check_summary(&summary, slot, &plan, crc);
                now.plans.insert(slot, plan);
                now.crcs.insert(slot, crc);
            }
        }
        let config = self.store.load_config().await;
        let new = match in_flight {
            InFlight::Config(new) => Some(new),
            _ => None,
        };
        assert!(
            config == before.config || Some(config) == new,
            "configuration after the reboot: {config:?}, expected {:?} or {new:?}",
            before.config
        );
        now.config = config;
        self.model = now;
        self.list().await;
    }
}

/// A summary names the plan stored in `slot`.
fn check_summary(summary: &PlanSummary, slot: u8, plan: &Plan, crc: u32) {
    assert_eq!(summary.slot, slot);
    assert_eq!(summary.name, plan.name);
    assert_eq!(summary.steps as usize, plan.steps.len());
    assert_eq!(summary.repeat, plan.repeat);
    assert_eq!(summary.crc, crc);
    assert_eq!(summary.total_ms, plan.total_ms());
}
