//! The plan store: plans and the device configuration in flash, safe against power cuts.
//!
//! A [`PlanStore`] keeps a sequential-storage map in a flash range (bank 2 on the board, 512
//! KiB of 2 KiB pages). A plan is a header item in its slot and up to [`MAX_CHUNKS`] chunk
//! items of [`CHUNK_STEPS`] steps in a *bank*; the layout is in [`layout`] and in
//! `docs/store.md`, with the argument for why it is safe.
//!
//! In short: an upload writes its chunks, as they arrive, into a bank no stored plan uses; the
//! commit then writes the slot's header naming that bank. That one item write is the switch: a
//! map item is whole or absent after a power cut (it carries a CRC), so the slot holds either
//! the old header (old bank, old steps, untouched) or the new one (all of whose chunks were
//! already written). Afterwards the old bank is cleared with tombstones — which may be cut
//! too; leftovers are cleared when the store next opens. Deleting writes a tombstone header
//! first, then clears the bank the same way. Every plan carries its CRC, checked on `load`.
//!
//! The store reads the whole map once when first used ([`index`]: slots, names, item sizes
//! in RAM), so listing and slot choice cost no flash reads. When writing a header or the
//! configuration fails (it may have landed all the same) it reads the map again before the
//! next request, and an upload in progress is then dropped.
//!
//! Never run a store call under a timeout or `select`: sequential-storage repairs a cancelled
//! operation later, but the store's index would no longer match the flash.

pub mod index;
pub mod layout;
#[cfg(any(test, feature = "mock-flash"))]
pub mod mock_flash;
mod upload;
pub mod yielding;

#[cfg(test)]
mod tests;

use core::ops::Range;

use chladni_shared::icd::link::Refusal;
use chladni_shared::icd::plan::{DeviceLimits, Plan, Step};
use chladni_shared::icd::store::{
    CHUNK_STEPS, DeviceConfig, MAX_CHUNKS, PLAN_SLOTS, PlanDigest, PlanPage, PlanRef, PlanSummary,
    SCRATCH_SLOT, StoreError, UploadBegin, UploadChunk, UploadError,
};
use embedded_storage_async::nor_flash::NorFlash;
use sequential_storage::cache::key_pointers::ArrayKeyPointers;
use sequential_storage::cache::page_states::ArrayPageStates;
use sequential_storage::cache::{Cache, CacheImpl, Uncached};
use sequential_storage::map::{MapConfig, MapStorage, Value};

use index::{Index, StoredConfig};
use layout::{BANKS, ChunkItem, Encoded, Geometry, ItemKey, PlanItem};
use upload::Upload;

/// Most pages the store uses (the caches are sized for them): 512 KiB of 2 KiB pages. A larger
/// range is cut to this.
pub const MAX_PAGES: usize = 256;

/// The buffer items are read and written through, bytes: the longest item the layout writes
/// (a full chunk, [`layout::MAX_VALUE`] and its key) rounded up.
pub const ITEM_BUFFER: usize = 1024;

/// Every key the layout uses: the configuration, a header per slot, the chunks of every bank.
const KEYS: usize = 1 + PLAN_SLOTS as usize + BANKS as usize * MAX_CHUNKS;

/// The sequential-storage cache the store uses by default: the state of every page (so
/// finding the open page reads no flash) and the address of every key (so reading a chunk, and
/// moving an item during garbage collection, does not scan the map once the key was met since
/// boot). About 5 KiB. A cache of each page's free spot would save some 120 reads per upload
/// for 2 KiB more; docs/store.md has the numbers.
pub type StoreCache = Cache<ArrayPageStates<MAX_PAGES>, Uncached, ArrayKeyPointers<u16, KEYS>, u16>;

/// The flash a store is built on, when its range is usable.
enum Backend<F: NorFlash, C: CacheImpl<u16>> {
    Map(MapStorage<u16, F, C>),
    /// The range does not fit the flash's pages; every request fails with `Flash`.
    Unusable(F),
}

/// Item buffer, aligned for flash drivers that write from it directly.
#[repr(align(8))]
struct ItemBuffer([u8; ITEM_BUFFER]);

/// A chunk's value as encoded once for storing, sizing and the plan CRC.
struct ChunkBuffer([u8; layout::MAX_VALUE]);

/// The plan store. See the module documentation.
pub struct PlanStore<F: NorFlash, C: CacheImpl<u16> = StoreCache> {
    backend: Backend<F, C>,
    buf: ItemBuffer,
    chunk: ChunkBuffer,
    index: Index,
    upload: Option<Upload>,
    /// The index does not describe the flash (not read yet, or a write failed).
    stale: bool,
    /// Bytes in the range.
    range_len: u32,
    geometry: Geometry,
}

impl<F: NorFlash> PlanStore<F> {
    /// A store in `range` of `flash` (page-aligned, at least two pages; more than
    /// [`MAX_PAGES`] pages are cut to that). Nothing is read until the first request.
    pub fn new(flash: F, range: Range<u32>) -> Self {
        let cache = Cache::new(ArrayPageStates::new(), Uncached, ArrayKeyPointers::new());
        Self::with_cache(flash, range, cache)
    }
}

impl<F: NorFlash, C: CacheImpl<u16>> PlanStore<F, C> {
    /// A store with another sequential-storage cache (e.g. `Cache::new_uncached()`, to
    /// measure what the cache saves).
    pub fn with_cache(flash: F, range: Range<u32>, cache: C) -> Self {
        let max_len = (MAX_PAGES * F::ERASE_SIZE) as u32;
        let range = range.start..range.end.min(range.start.saturating_add(max_len));
        let range_len = range.end.saturating_sub(range.start);
        let backend = match MapConfig::<F>::try_new(range) {
            Ok(config) => Backend::Map(MapStorage::new(flash, config, cache)),
            Err(_) => {
                defmt::error!("plan store: the flash range does not fit the flash's pages");
                Backend::Unusable(flash)
            }
        };
        Self {
            backend,
            buf: ItemBuffer([0; ITEM_BUFFER]),
            chunk: ChunkBuffer([0; layout::MAX_VALUE]),
            index: Index::new(),
            upload: None,
            stale: true,
            range_len,
            geometry: Geometry {
                overhead: MapStorage::<u16, F, C>::item_overhead_size(),
                word: F::WRITE_SIZE.max(F::READ_SIZE) as u32,
            },
        }
    }

    /// The flash back.
    pub fn into_flash(self) -> F {
        match self.backend {
            Backend::Map(map) => map.destroy().0,
            Backend::Unusable(flash) => flash,
        }
    }

    /// The stored configuration; [`DeviceConfig::DEFAULT`] when there is none, or it cannot
    /// be read, or it does not validate (each logged).
    pub async fn load_config(&mut self) -> DeviceConfig {
        if self.ensure_open().await.is_err() {
            defmt::warn!("plan store: flash unreadable; using the default configuration");
            return DeviceConfig::DEFAULT;
        }
        match self.index.config() {
            StoredConfig::Missing => {
                defmt::warn!("plan store: no configuration stored; using the default");
                DeviceConfig::DEFAULT
            }
            StoredConfig::Unreadable => {
                defmt::warn!("plan store: stored configuration unreadable; using the default");
                DeviceConfig::DEFAULT
            }
            StoredConfig::Stored(config) => match config.validate() {
                Ok(()) => config,
                Err(e) => {
                    defmt::warn!("plan store: stored configuration invalid ({}); default", e);
                    DeviceConfig::DEFAULT
                }
            },
        }
    }

    /// Checks and stores `config`; the configuration now stored.
    pub async fn set_config(&mut self, config: DeviceConfig) -> Result<DeviceConfig, Refusal> {
        config.validate().map_err(Refusal::Config)?;
        self.ensure_open().await.map_err(Refusal::Store)?;
        let size = self.geometry.size_of(&config);
        self.put_switch(ItemKey::Config, &Encoded(&config)).await.map_err(Refusal::Store)?;
        self.index.set_config(config, size as u16);
        Ok(config)
    }

    /// Begins an upload (replacing any in progress); the slot it will store into.
    pub async fn begin(
        &mut self,
        begin: UploadBegin,
        limits: &DeviceLimits,
    ) -> Result<u8, Refusal> {
        self.ensure_open().await.map_err(Refusal::Store)?;
        if let Some(slot) = begin.slot.filter(|&s| s >= PLAN_SLOTS) {
            return Err(Refusal::Upload(UploadError::BadSlot { slot }));
        }
        if begin.name.trim().is_empty() {
            // A plan is run and deleted by name: one without a visible name could not be.
            return Err(Refusal::Upload(UploadError::EmptyName));
        }
        limits
            .check_plan_header(begin.repeat, begin.steps)
            .map_err(|e| Refusal::Upload(UploadError::Plan(e)))?;
        let slot = self.upload_slot(begin.slot, &begin.name).map_err(Refusal::Upload)?;
        let bank = self.index.free_bank();
        let abandoned = self.upload.replace(Upload::new(slot, bank, &begin));
        if abandoned.is_some_and(|a| a.bank != bank) {
            // The abandoned upload's chunks are in a bank this upload will not overwrite.
            self.tidy().await;
        }
        Ok(slot)
    }

    /// The slot an upload goes to: the named one, or the one holding a plan of this name, or
    /// the lowest free one (the scratch slot only when named).
    fn upload_slot(&self, slot: Option<u8>, name: &str) -> Result<u8, UploadError> {
        let holder = self.index.named(name, 0..SCRATCH_SLOT);
        match slot {
            None => holder.or_else(|| self.index.free_slot()).ok_or(UploadError::StoreFull),
            Some(SCRATCH_SLOT) => Ok(SCRATCH_SLOT),
            Some(slot) => match holder {
                Some(other) if other != slot => Err(UploadError::NameTaken { slot: other }),
                _ => Ok(slot),
            },
        }
    }

    /// Stores the next chunk of the upload; steps received so far.
    pub async fn chunk(
        &mut self,
        chunk: UploadChunk,
        limits: &DeviceLimits,
    ) -> Result<u16, Refusal> {
        self.ensure_open().await.map_err(Refusal::Store)?;
        let upload = self.upload.as_ref().ok_or(Refusal::Upload(UploadError::NotStarted))?;
        let index = upload.check(&chunk, limits).map_err(Refusal::Upload)?;
        let bank = upload.bank;
        // Encoded once: the same bytes are stored, sized and added to the plan's CRC.
        let item: ChunkItem = Some(chunk.steps);
        // (The buffer holds the longest chunk: `layout::MAX_VALUE`.)
        let encoded = postcard::to_slice(&item, &mut self.chunk.0);
        let len = encoded.map_err(|_| Refusal::Store(StoreError::Flash))?.len();
        let encoded = &self.chunk.0[..len];
        let size = self.geometry.item_size(len);
        let key = ItemKey::Chunk { bank, index };
        let stored = put(&mut self.backend, &mut self.buf.0, key, &encoded).await;
        if stored != Err(StoreError::Full) {
            // Written, or maybe written: counted, and cleared by a sweep if the upload is
            // abandoned. On an error the upload stays where it was; the chunk may be sent again.
            self.index.set_chunk(bank, index, true, size as u16);
        }
        stored.map_err(Refusal::Store)?;
        let steps = item.as_deref().unwrap_or_default();
        // The step bytes follow the option tag and the one-byte length (as `append_chunk`).
        let step_bytes = encoded.get(2..).unwrap_or_default();
        // The upload is still there: only `ensure_open` and `commit` drop it.
        Ok(self.upload.as_mut().map_or(0, |u| u.accept(steps, step_bytes)))
    }

    /// Checks the upload whole and stores it: the plan stored.
    pub async fn commit(&mut self, limits: &DeviceLimits) -> Result<PlanSummary, Refusal> {
        self.ensure_open().await.map_err(Refusal::Store)?;
        let upload = self.upload.as_ref().ok_or(Refusal::Upload(UploadError::NotStarted))?;
        upload.check_complete().map_err(Refusal::Upload)?;
        let Some(upload) = self.upload.take() else {
            return Err(Refusal::Upload(UploadError::NotStarted));
        };
        let slot = upload.slot;
        let record = match upload.finish(limits) {
            Ok(record) => record,
            Err(e) => {
                // Nothing was stored; its chunks are strays now.
                self.tidy().await;
                return Err(Refusal::Upload(e));
            }
        };
        let item: PlanItem = Some(record);
        let size = self.geometry.size_of(&item);
        if let Err(e) = self.put_switch(ItemKey::Plan(slot), &Encoded(&item)).await {
            self.tidy().await;
            return Err(Refusal::Store(e));
        }
        self.index.set_plan(slot, item, size as u16);
        let summary = self.index.summary(slot);
        self.tidy().await;
        summary.ok_or(Refusal::Store(StoreError::Flash))
    }

    /// One page of the plan list, from `from_slot` on.
    pub async fn list(&mut self, from_slot: u8) -> Result<PlanPage, Refusal> {
        self.ensure_open().await.map_err(Refusal::Store)?;
        Ok(self.index.page(from_slot, self.free_bytes()))
    }

    /// Flash left for plans: the range, less the newest item of every key, less one page that
    /// sequential-storage keeps erased for garbage collection. (Items do not span pages, so
    /// the tail of each page may go unused: the last plans may not fit all of it.)
    fn free_bytes(&self) -> u32 {
        let reserve = F::ERASE_SIZE as u32 + self.index.live_bytes();
        self.range_len.saturating_sub(reserve)
    }

    /// Deletes a plan; what was deleted.
    pub async fn delete(&mut self, plan: &PlanRef) -> Result<PlanSummary, Refusal> {
        self.ensure_open().await.map_err(Refusal::Store)?;
        let slot = self.resolve(plan)?;
        let summary = self.index.summary(slot).ok_or(not_found(plan))?;
        let item: PlanItem = None;
        self.put_switch(ItemKey::Plan(slot), &Encoded(&item)).await.map_err(Refusal::Store)?;
        self.index.set_plan(slot, None, self.geometry.tombstone_size() as u16);
        self.tidy().await;
        Ok(summary)
    }

    /// Reads a whole plan into `out` and checks its CRC; its summary. On an error `out` holds
    /// no steps.
    pub async fn load(&mut self, plan: &PlanRef, out: &mut Plan) -> Result<PlanSummary, Refusal> {
        out.steps.clear();
        self.ensure_open().await.map_err(Refusal::Store)?;
        let slot = self.resolve(plan)?;
        let result = self.read_plan(slot, out).await;
        if result.is_err() {
            out.steps.clear();
        }
        result.map_err(Refusal::Store)?;
        self.index.summary(slot).ok_or(not_found(plan))
    }

    /// Reads the chunks of the plan in `slot` into `out`, checking the plan's CRC on the
    /// stored bytes as they are read (no step is encoded again for it).
    async fn read_plan(&mut self, slot: u8, out: &mut Plan) -> Result<(), StoreError> {
        let Some(record) = self.index.plan(slot).cloned() else {
            return Err(StoreError::NotFound(PlanRef::Slot(slot)));
        };
        out.name = record.name.clone();
        out.repeat = record.repeat;
        let mut digest = PlanDigest::new(&record.name, record.repeat, record.steps);
        for index in 0..record.chunks() {
            let key = ItemKey::Chunk { bank: record.bank, index };
            let expected = (record.steps as usize - index as usize * CHUNK_STEPS).min(CHUNK_STEPS);
            let raw = self.get(key).await?;
            if !raw.is_some_and(|raw| append_chunk(raw, expected, out, &mut digest)) {
                defmt::warn!("plan store: slot {} chunk {} missing or short", slot, index);
                return Err(StoreError::Corrupt { slot });
            }
        }
        if digest.finish() != record.crc {
            defmt::warn!("plan store: slot {} fails its CRC", slot);
            return Err(StoreError::Corrupt { slot });
        }
        Ok(())
    }

    /// The slot a reference names, if it holds a plan.
    fn resolve(&self, plan: &PlanRef) -> Result<u8, Refusal> {
        let slot = match plan {
            PlanRef::Slot(slot) => Some(*slot).filter(|&s| self.index.plan(s).is_some()),
            PlanRef::Name(name) => self.index.lookup(name),
        };
        slot.ok_or_else(|| not_found(plan))
    }

    /// Reads the map into the index, unless it is up to date; then clears strays.
    async fn ensure_open(&mut self) -> Result<(), StoreError> {
        if !self.stale {
            return Ok(());
        }
        self.upload = None;
        self.index.clear();
        let Backend::Map(map) = &mut self.backend else {
            return Err(StoreError::Flash);
        };
        let mut scanned = scan(map, &mut self.buf.0, &mut self.index, &self.geometry).await;
        if matches!(scanned, Err(sequential_storage::Error::Corrupted { .. })) {
            // A page whose erase was cut. sequential-storage 8.0.2's `fetch_all_items` returns
            // that without repairing it (its `?` escapes its own auto-repair); `fetch_item`
            // meets the same page first and does repair it. Then read again.
            let _ = map.fetch_item::<&[u8]>(&mut self.buf.0, &ItemKey::Config.raw()).await;
            self.index.clear();
            scanned = scan(map, &mut self.buf.0, &mut self.index, &self.geometry).await;
        }
        if let Err(e) = scanned {
            defmt::warn!("plan store: reading the flash failed: {}", describe(&e));
            return Err(StoreError::Flash);
        }
        self.stale = false;
        self.tidy().await;
        Ok(())
    }

    /// Clears strays after a change, logging (not returning) a failure: the change itself
    /// happened, and the strays are tried again at the next change or boot.
    async fn tidy(&mut self) {
        if self.sweep().await.is_err() {
            defmt::warn!("plan store: clearing unused chunks failed; retried on the next request");
        }
    }

    /// Writes a tombstone over every chunk that holds steps but belongs to no plan and to no
    /// upload in progress (an old plan's bank after a commit or delete, an abandoned upload).
    async fn sweep(&mut self) -> Result<(), StoreError> {
        let upload_bank = self.upload.as_ref().map(|u| u.bank);
        let tomb: ChunkItem = None;
        let size = self.geometry.tombstone_size() as u16;
        if !self.index.any_strays(upload_bank) {
            return Ok(());
        }
        for bank in 0..BANKS {
            let strays = self.index.strays(bank, upload_bank);
            for index in (0..MAX_CHUNKS as u8).filter(|i| strays & 1 << i != 0) {
                self.put(ItemKey::Chunk { bank, index }, &Encoded(&tomb)).await?;
                self.index.set_chunk(bank, index, false, size);
            }
        }
        Ok(())
    }

    /// Stores one item.
    async fn put<'v, V: Value<'v>>(&mut self, key: ItemKey, value: &V) -> Result<(), StoreError> {
        put(&mut self.backend, &mut self.buf.0, key, value).await
    }

    /// Stores an item that changes what the store holds (a plan header, the configuration).
    /// A write that failed may still have landed, so then the index is read again before the
    /// next request (dropping an upload in progress).
    async fn put_switch<'v, V: Value<'v>>(
        &mut self,
        key: ItemKey,
        value: &V,
    ) -> Result<(), StoreError> {
        let stored = self.put(key, value).await;
        if stored == Err(StoreError::Flash) {
            self.stale = true;
        }
        stored
    }

    /// Reads the newest item of `key`, raw.
    async fn get(&mut self, key: ItemKey) -> Result<Option<&[u8]>, StoreError> {
        let Backend::Map(map) = &mut self.backend else {
            return Err(StoreError::Flash);
        };
        map.fetch_item::<&[u8]>(&mut self.buf.0, &key.raw()).await.map_err(|e| {
            defmt::warn!("plan store: reading failed: {}", describe(&e));
            StoreError::Flash
        })
    }
}

#[cfg(test)]
impl<F: NorFlash, C: CacheImpl<u16>> PlanStore<F, C> {
    /// Whether the index is what reading the map now would give.
    async fn index_matches_flash(&mut self) -> bool {
        let Backend::Map(map) = &mut self.backend else { return false };
        let mut fresh = Index::new();
        let scanned = scan(map, &mut self.buf.0, &mut fresh, &self.geometry).await;
        scanned.is_ok() && fresh == self.index
    }
}

/// Stores one item through `buf` (a function of the fields it needs, so that a value may be
/// borrowed from another field of the store).
async fn put<'v, F: NorFlash, C: CacheImpl<u16>, V: Value<'v>>(
    backend: &mut Backend<F, C>,
    buf: &mut [u8],
    key: ItemKey,
    value: &V,
) -> Result<(), StoreError> {
    let Backend::Map(map) = backend else {
        return Err(StoreError::Flash);
    };
    match map.store_item(buf, &key.raw(), value).await {
        Ok(()) => Ok(()),
        // Nothing was written: the map had no room.
        Err(sequential_storage::Error::FullStorage) => Err(StoreError::Full),
        Err(e) => {
            defmt::warn!("plan store: writing failed: {}", describe(&e));
            Err(StoreError::Flash)
        }
    }
}

/// Reads every item of the map into `index`, oldest first.
async fn scan<F: NorFlash, C: CacheImpl<u16>>(
    map: &mut MapStorage<u16, F, C>,
    buf: &mut [u8],
    index: &mut Index,
    geometry: &Geometry,
) -> Result<(), sequential_storage::Error<F::Error>> {
    let mut items = map.fetch_all_items(buf).await?;
    while let Some((key, value)) = items.next::<&[u8]>(buf).await? {
        if let Some(key) = ItemKey::from_raw(key) {
            index.note(key, value, geometry);
        }
    }
    Ok(())
}

/// Appends the steps of one stored chunk (the item's raw value) to `out`, decoding them in
/// place, and adds their bytes to the plan's `digest`; false unless the value is a chunk of
/// exactly `expected` steps with nothing after them.
fn append_chunk(raw: &[u8], expected: usize, out: &mut Plan, digest: &mut PlanDigest) -> bool {
    // postcard's `Some(steps)`: the tag 1, the length as a varint (one byte: at most
    // CHUNK_STEPS), then the steps, whose bytes are what the plan CRC covers.
    const _: () = assert!(CHUNK_STEPS < 128);
    let [1, len, steps @ ..] = raw else { return false };
    if *len as usize != expected {
        return false;
    }
    let mut rest = steps;
    for _ in 0..expected {
        let Ok((step, tail)) = postcard::take_from_bytes::<Step>(rest) else { return false };
        if out.steps.push(step).is_err() {
            return false;
        }
        rest = tail;
    }
    digest.step_bytes(steps);
    rest.is_empty()
}

fn not_found(plan: &PlanRef) -> Refusal {
    Refusal::Store(StoreError::NotFound(plan.clone()))
}

/// A sequential-storage error, for the log.
fn describe<E>(e: &sequential_storage::Error<E>) -> &'static str {
    use sequential_storage::Error;
    match e {
        Error::Storage { .. } => "flash driver error",
        Error::FullStorage => "flash full",
        Error::Corrupted { .. } => "corrupted beyond repair",
        Error::ItemTooBig => "item too big",
        Error::BufferTooSmall(_) | Error::BufferTooBig => "item buffer too small",
        Error::SerializationError(_) => "item encoding",
        _ => "internal error",
    }
}
