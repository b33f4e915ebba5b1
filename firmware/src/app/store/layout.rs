//! What the store keeps in flash: the keys of its items and the records they hold.
//!
//! The map's key is a `u16`:
//! - `0x0001`: the device configuration (`DeviceConfig`).
//! - `0x0100 | slot`: the plan header of `slot` (a [`PlanRecord`], or `None`: a tombstone,
//!   the slot was deleted).
//! - `0x8000 | bank << 3 | chunk`: chunk `chunk` (up to [`CHUNK_STEPS`] steps) of the plan in
//!   `bank`, or `None`: a tombstone. Banks are a pool of [`BANKS`], one more than there are
//!   slots: a header names the bank its steps are in, and an upload writes into a bank no header
//!   names, so a plan's steps are never written over while it is stored.
//!
//! Values are postcard encodings. sequential-storage keeps the newest item of each key; an
//! item carries its own CRC, so a write cut by a power failure leaves the older item in effect.

use chladni_shared::icd::plan::{DeviceLimits, Step};
use chladni_shared::icd::sense::ControlConfig;
use chladni_shared::icd::store::{CHUNK_STEPS, DeviceConfig, MAX_CHUNKS, PLAN_SLOTS, PlanName};
use sequential_storage::map::{SerializationError, Value};
use serde::{Deserialize, Serialize};

/// Step banks: one per slot and one spare, so that an upload always has a bank no stored plan
/// uses.
pub const BANKS: u8 = PLAN_SLOTS + 1;

// The key packs the chunk number in 3 bits and the bank in 7.
const _: () = assert!(MAX_CHUNKS <= 8 && BANKS as usize <= 128);

const CONFIG_KEY: u16 = 0x0001;
const PLAN_KEY: u16 = 0x0100;
const CHUNK_KEY: u16 = 0x8000;

/// What an item of the map is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ItemKey {
    /// The device configuration.
    Config,
    /// The header of a plan slot.
    Plan(u8),
    /// One chunk of steps in a bank.
    Chunk {
        /// The bank, `0..BANKS`.
        bank: u8,
        /// The chunk number, `0..MAX_CHUNKS`.
        index: u8,
    },
}

impl ItemKey {
    /// The map key.
    pub const fn raw(self) -> u16 {
        match self {
            ItemKey::Config => CONFIG_KEY,
            ItemKey::Plan(slot) => PLAN_KEY | slot as u16,
            ItemKey::Chunk { bank, index } => CHUNK_KEY | (bank as u16) << 3 | index as u16,
        }
    }

    /// The item a map key names; `None` for keys this layout does not use (left alone).
    pub fn from_raw(raw: u16) -> Option<Self> {
        if raw == CONFIG_KEY {
            return Some(ItemKey::Config);
        }
        if raw & 0xff00 == PLAN_KEY && (raw & 0xff) < PLAN_SLOTS as u16 {
            return Some(ItemKey::Plan(raw as u8));
        }
        if raw & 0xfc00 == CHUNK_KEY {
            let (bank, index) = ((raw >> 3 & 0x7f) as u8, (raw & 7) as u8);
            if bank < BANKS && (index as usize) < MAX_CHUNKS {
                return Some(ItemKey::Chunk { bank, index });
            }
        }
        None
    }
}

/// A stored plan's header: what the slot holds and where its steps are.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PlanRecord {
    /// The plan's name.
    pub name: PlanName,
    /// How many times its steps run.
    pub repeat: u16,
    /// Steps.
    pub steps: u16,
    /// `plan_crc` of the plan.
    pub crc: u32,
    /// Length of all repeats, ms.
    pub total_ms: u64,
    /// The bank holding the steps.
    pub bank: u8,
}

impl PlanRecord {
    /// Chunks holding its steps.
    pub fn chunks(&self) -> u8 {
        chunks_for(self.steps)
    }
}

/// Chunks for `steps` steps.
pub fn chunks_for(steps: u16) -> u8 {
    (steps as usize).div_ceil(CHUNK_STEPS) as u8
}

/// The steps of one chunk.
pub type ChunkSteps = heapless::Vec<Step, CHUNK_STEPS>;

/// A plan header item's value.
pub type PlanItem = Option<PlanRecord>;
/// A chunk item's value.
pub type ChunkItem = Option<ChunkSteps>;

/// A value written in its postcard encoding. Write-only: the store reads items raw (`&[u8]`)
/// and decodes them itself with [`decode`], so one scan can read items of every kind.
pub struct Encoded<'v, T>(pub &'v T);

impl<'a, T: Serialize> Value<'a> for Encoded<'_, T> {
    fn serialize_into(&self, buffer: &mut [u8]) -> Result<usize, SerializationError> {
        postcard::to_slice(self.0, buffer)
            .map(|bytes| bytes.len())
            .map_err(|_| SerializationError::BufferTooSmall)
    }

    fn deserialize_from(_: &'a [u8]) -> Result<(Self, usize), SerializationError> {
        Err(SerializationError::InvalidFormat)
    }
}

/// Decodes an item's value (as read raw by a scan), `None` if it does not decode.
pub fn decode<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Option<T> {
    postcard::from_bytes(bytes).ok()
}

/// Bytes of postcard encoding of `value`.
pub fn encoded_len<T: Serialize>(value: &T) -> usize {
    postcard::serialize_with_flavor(value, postcard::ser_flavors::Size::default())
        .unwrap_or(usize::MAX)
}

/// Flash geometry, for item sizes: what sequential-storage adds to an item's data.
#[derive(Debug, Clone, Copy)]
pub struct Geometry {
    /// Item header, bytes (`MapStorage::item_overhead_size`).
    pub overhead: u32,
    /// Alignment of item data, bytes (the larger of the flash's write and read sizes).
    pub word: u32,
}

impl Geometry {
    /// Flash taken by an item whose value encodes to `value_len` bytes (with its `u16` key).
    pub const fn item_size(&self, value_len: usize) -> u32 {
        self.overhead + (2 + value_len as u32).next_multiple_of(self.word)
    }

    /// Flash taken by a tombstone (`None`).
    pub const fn tombstone_size(&self) -> u32 {
        self.item_size(1)
    }

    /// Flash taken by the item holding `value`.
    pub fn size_of<T: Serialize>(&self, value: &T) -> u32 {
        self.item_size(encoded_len(value))
    }

    /// Live bytes (the newest item of every key, with the one being written) that a map of
    /// `pages` pages of `page` bytes is sure to hold. sequential-storage keeps one page erased
    /// for its garbage collection, writes items whole into a page between a start and an end
    /// marker word, and closes a page when the next item does not fit, so each page may
    /// waste up to one largest item; it answers `FullStorage` only after moving the live items
    /// of every page, so below this sum a write always finds room.
    pub const fn capacity(&self, pages: u32, page: u32) -> u32 {
        let per_page = page.saturating_sub(2 * self.word + self.item_size(MAX_VALUE));
        pages.saturating_sub(1) * per_page
    }

    /// Room kept for the writes that must not fail for space: a delete's tombstone and a new
    /// configuration (each replaces an item, so neither grows the store for long).
    pub fn reserve(&self) -> u32 {
        self.tombstone_size() + self.size_of(&WORST_CONFIG)
    }

    /// Flash a commit's plan header may take.
    pub fn max_record_size(&self) -> u32 {
        let mut name = PlanName::new();
        while name.push('x').is_ok() {}
        let record = PlanRecord {
            name,
            repeat: u16::MAX,
            steps: u16::MAX,
            crc: u32::MAX,
            total_ms: u64::MAX,
            bank: u8::MAX,
        };
        self.size_of(&Some(record))
    }
}

/// The configuration with every field at its longest encoding (a struct literal, so a new
/// field must be added here).
const WORST_CONFIG: DeviceConfig = DeviceConfig {
    limits: DeviceLimits {
        min_freq_mhz: u32::MAX,
        max_freq_mhz: u32::MAX,
        max_amplitude_q15: u16::MAX,
        max_accel_mmps2: u32::MAX,
        max_steps: u16::MAX,
        max_total_ms: u64::MAX,
    },
    control: ControlConfig {
        open_loop_mmps2: u32::MAX,
        open_loop_effort_q15: u16::MAX,
        open_loop_ms: u32::MAX,
        warn_band_mdb: u32::MAX,
        abort_band_mdb: u32::MAX,
        band_ms: u32::MAX,
        max_accel_mmps2: u32::MAX,
        no_data_ms: u32::MAX,
        saturation_ms: u32::MAX,
        check_effort_q15: u16::MAX,
        check_ms: u32::MAX,
        check_min_mmps2: u32::MAX,
    },
};

/// Largest value the store writes or reads: a full chunk of steps at their longest encoding
/// (frequency, duration and ramp as varints of at most 5 bytes; the level a variant tag and a
/// varint of at most 5), with the option tag and the vector length.
pub const MAX_VALUE: usize = 1 + 1 + CHUNK_STEPS * 21;

const _: () = assert!(MAX_VALUE + 2 <= super::ITEM_BUFFER);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_round_trip_and_stay_apart() {
        let mut seen = std::collections::BTreeSet::new();
        let keys = core::iter::once(ItemKey::Config)
            .chain((0..PLAN_SLOTS).map(ItemKey::Plan))
            .chain((0..BANKS).flat_map(|bank| {
                (0..MAX_CHUNKS as u8).map(move |index| ItemKey::Chunk { bank, index })
            }));
        for key in keys {
            assert_eq!(ItemKey::from_raw(key.raw()), Some(key));
            assert!(seen.insert(key.raw()), "{key:?} collides");
        }
        assert_eq!(ItemKey::from_raw(0x0000), None);
        assert_eq!(ItemKey::from_raw(PLAN_KEY | PLAN_SLOTS as u16), None);
        assert_eq!(ItemKey::from_raw(CHUNK_KEY | (BANKS as u16) << 3), None);
    }

    #[test]
    fn the_longest_chunk_fits_the_buffer() {
        let worst = Step {
            freq_mhz: u32::MAX,
            level: chladni_shared::icd::plan::Level::Accel(u32::MAX),
            duration_ms: u32::MAX,
            ramp_ms: u32::MAX,
        };
        let chunk: ChunkItem = Some(ChunkSteps::from_slice(&[worst; CHUNK_STEPS]).unwrap());
        assert_eq!(encoded_len(&chunk), MAX_VALUE);
        let tomb: ChunkItem = None;
        assert_eq!(encoded_len(&tomb), 1);
    }
}
