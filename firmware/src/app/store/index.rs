//! The store's picture of the flash, kept in RAM: which slot holds which plan, which chunk
//! items are live, and how much flash every live item takes.
//!
//! It is rebuilt from one scan of the map when the store opens (and after a flash error), and
//! kept in step with every item the store writes after that. With it, listing plans, finding a
//! name or a free slot, and accounting free space need no flash reads; only `load` reads chunks.

use chladni_shared::icd::store::{
    DeviceConfig, MAX_CHUNKS, PLAN_SLOTS, PlanPage, PlanSummary, SCRATCH_SLOT,
};

use super::layout::{BANKS, Geometry, ItemKey, PlanItem, PlanRecord, decode};

/// What the scan found under the configuration key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoredConfig {
    /// Nothing stored yet.
    Missing,
    /// An item that does not decode as a configuration (another layout).
    Unreadable,
    /// A configuration, not yet validated.
    Stored(DeviceConfig),
}

/// The newest items of one bank.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Bank {
    /// Chunks whose newest item holds steps (bit per chunk).
    live: u8,
    /// Flash taken by each chunk's newest item (steps or tombstone), bytes; 0: none.
    sizes: [u16; MAX_CHUNKS],
}

/// The index. About 5 KiB on the controller.
#[derive(Debug, PartialEq, Eq)]
pub struct Index {
    plans: [Option<PlanRecord>; PLAN_SLOTS as usize],
    /// Flash taken by each slot's newest header item (a plan or a tombstone), bytes; 0: none.
    header_sizes: [u16; PLAN_SLOTS as usize],
    banks: [Bank; BANKS as usize],
    config: StoredConfig,
    config_size: u16,
}

impl Index {
    /// An index of an empty store.
    pub const fn new() -> Self {
        Self {
            plans: [const { None }; PLAN_SLOTS as usize],
            header_sizes: [0; PLAN_SLOTS as usize],
            banks: [Bank { live: 0, sizes: [0; MAX_CHUNKS] }; BANKS as usize],
            config: StoredConfig::Missing,
            config_size: 0,
        }
    }

    /// Forgets everything (before a scan).
    pub fn clear(&mut self) {
        self.plans.iter_mut().for_each(|p| *p = None);
        self.header_sizes = [0; PLAN_SLOTS as usize];
        self.banks = [Bank::default(); BANKS as usize];
        self.config = StoredConfig::Missing;
        self.config_size = 0;
    }

    /// Takes in one item met by the scan (oldest first, so a newer item of a key replaces what
    /// an older one said).
    pub fn note(&mut self, key: ItemKey, value: &[u8], geometry: &Geometry) {
        let size = geometry.item_size(value.len()) as u16;
        match key {
            ItemKey::Config => {
                self.config = decode::<DeviceConfig>(value)
                    .map_or(StoredConfig::Unreadable, StoredConfig::Stored);
                self.config_size = size;
            }
            ItemKey::Plan(slot) => {
                let record = decode::<PlanItem>(value).flatten().filter(plausible);
                if record.is_none() && value.first() != Some(&0) {
                    defmt::warn!("plan store: slot {} has an unreadable header; ignored", slot);
                }
                self.set_plan(slot, record, size);
            }
            ItemKey::Chunk { bank, index } => {
                // Postcard's option tag: 1 is `Some` (steps), 0 a tombstone.
                self.set_chunk(bank, index, value.first() == Some(&1), size);
            }
        }
    }

    /// Records a slot's newest header item: a plan, or `None` (tombstone or unreadable).
    pub fn set_plan(&mut self, slot: u8, record: Option<PlanRecord>, size: u16) {
        self.plans[slot as usize] = record;
        self.header_sizes[slot as usize] = size;
    }

    /// Records a chunk's newest item.
    pub fn set_chunk(&mut self, bank: u8, index: u8, live: bool, size: u16) {
        let bank = &mut self.banks[bank as usize];
        bank.sizes[index as usize] = size;
        if live {
            bank.live |= 1 << index;
        } else {
            bank.live &= !(1 << index);
        }
    }

    /// Records the configuration item.
    pub fn set_config(&mut self, config: DeviceConfig, size: u16) {
        self.config = StoredConfig::Stored(config);
        self.config_size = size;
    }

    /// The stored configuration, as found.
    pub fn config(&self) -> StoredConfig {
        self.config
    }

    /// The plan in `slot`.
    pub fn plan(&self, slot: u8) -> Option<&PlanRecord> {
        self.plans.get(slot as usize)?.as_ref()
    }

    /// The lowest slot in `slots` holding a plan named `name`.
    pub fn named(&self, name: &str, slots: core::ops::Range<u8>) -> Option<u8> {
        slots.into_iter().find(|&s| self.plan(s).is_some_and(|p| p.name == name))
    }

    /// The slot a lookup by name finds: the other slots first, then the scratch slot.
    pub fn lookup(&self, name: &str) -> Option<u8> {
        self.named(name, 0..SCRATCH_SLOT).or_else(|| self.named(name, SCRATCH_SLOT..PLAN_SLOTS))
    }

    /// The lowest slot below the scratch slot that holds no plan.
    pub fn free_slot(&self) -> Option<u8> {
        (0..SCRATCH_SLOT).find(|&s| self.plan(s).is_none())
    }

    /// The lowest bank no stored plan uses (there is always one: one bank more than slots).
    pub fn free_bank(&self) -> u8 {
        (0..BANKS).find(|&b| self.plans.iter().flatten().all(|p| p.bank != b)).unwrap_or(0)
    }

    /// Chunks of `bank` that hold steps but belong to no plan, as a bit mask. A bank an upload
    /// is writing into (`upload_bank`) is its own: nothing in it is a stray until the upload
    /// ends.
    pub fn strays(&self, bank: u8, upload_bank: Option<u8>) -> u8 {
        if upload_bank == Some(bank) {
            return 0;
        }
        let keep = self
            .plans
            .iter()
            .flatten()
            .find(|p| p.bank == bank)
            .map_or(0, |p| (((1u16 << p.chunks()) - 1) & 0xff) as u8);
        self.banks[bank as usize].live & !keep
    }

    /// Whether any bank has strays ([`Index::strays`]), in one pass over the plans and the
    /// banks: most sweeps find none, and looking each bank's owner up among the slots (66 × 65
    /// steps) was a tenth of the plan-store fuzz target's time.
    pub fn any_strays(&self, upload_bank: Option<u8>) -> bool {
        let mut strays = [0u8; BANKS as usize];
        for (mask, bank) in strays.iter_mut().zip(&self.banks) {
            *mask = bank.live;
        }
        for p in self.plans.iter().flatten() {
            if let Some(mask) = strays.get_mut(p.bank as usize) {
                *mask &= !((((1u16 << p.chunks()) - 1) & 0xff) as u8);
            }
        }
        if let Some(mask) = upload_bank.and_then(|b| strays.get_mut(b as usize)) {
            *mask = 0;
        }
        strays.iter().any(|&m| m != 0)
    }

    /// What the store says about the plan in `slot`.
    pub fn summary(&self, slot: u8) -> Option<PlanSummary> {
        let p = self.plan(slot)?;
        let sizes = &self.banks[p.bank as usize].sizes[..p.chunks() as usize];
        let bytes =
            self.header_sizes[slot as usize] as u32 + sizes.iter().map(|&s| s as u32).sum::<u32>();
        Some(PlanSummary {
            slot,
            name: p.name.clone(),
            steps: p.steps,
            repeat: p.repeat,
            total_ms: p.total_ms,
            crc: p.crc,
            bytes,
        })
    }

    /// Flash taken by the newest item of every key (plans, tombstones, configuration, the
    /// chunks of an upload in progress), bytes.
    pub fn live_bytes(&self) -> u32 {
        let headers: u32 = self.header_sizes.iter().map(|&s| s as u32).sum();
        let chunks: u32 = self.banks.iter().flat_map(|b| b.sizes.iter()).map(|&s| s as u32).sum();
        headers + chunks + self.config_size as u32
    }

    /// The page of the plan list from `from_slot` on; `free_bytes` is passed through.
    pub fn page(&self, from_slot: u8, free_bytes: u32) -> PlanPage {
        let mut page = PlanPage { plans: heapless::Vec::new(), next: None, free_bytes };
        for slot in from_slot..PLAN_SLOTS {
            let Some(summary) = self.summary(slot) else { continue };
            if page.plans.push(summary).is_err() {
                page.next = Some(slot);
                break;
            }
        }
        page
    }
}

impl Default for Index {
    fn default() -> Self {
        Self::new()
    }
}

/// Whether a decoded header can be a plan this store wrote (a bank that exists, a step count
/// the chunks can hold); anything else is treated as unreadable.
fn plausible(record: &PlanRecord) -> bool {
    let max_steps = (MAX_CHUNKS * chladni_shared::icd::store::CHUNK_STEPS) as u16;
    record.bank < BANKS && (1..=max_steps).contains(&record.steps)
}
