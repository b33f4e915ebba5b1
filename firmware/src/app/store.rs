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
//! The area's first page holds the store's format marker ([`format`]): an area holding
//! anything else (bank 2 as the board comes from the factory) is never read as a store, and
//! never erased but by [`PlanStore::format`]. Every write and erase is read back
//! ([`verify`]): a flash that did not take the data is `StoreError::Verify`, not a plan that
//! goes missing later.
//!
//! Never run a store call under a timeout or `select`: sequential-storage repairs a cancelled
//! operation later, but the store's index would no longer match the flash.

pub mod chip;
pub mod format;
pub mod index;
pub mod layout;
#[cfg(any(test, feature = "mock-flash"))]
pub mod mock_flash;
mod upload;
pub mod verify;
pub mod yielding;

#[cfg(test)]
mod tests;

use core::ops::Range;

use chladni_shared::icd::link::Refusal;
use chladni_shared::icd::plan::{DeviceLimits, Plan, Step};
use chladni_shared::icd::store::{
    CHUNK_STEPS, DeviceConfig, MAX_CHUNKS, PLAN_SLOTS, PlanDigest, PlanPage, PlanRef, PlanSummary,
    SCRATCH_SLOT, StoreError, StoreInfo, StoreState, UploadBegin, UploadChunk, UploadError,
};
use embedded_storage_async::nor_flash::NorFlash;
use sequential_storage::cache::key_pointers::ArrayKeyPointers;
use sequential_storage::cache::page_states::ArrayPageStates;
use sequential_storage::cache::{Cache, CacheImpl, Uncached};
use sequential_storage::map::{MapConfig, MapStorage, Value};

use crate::app::watchdog::{Progress, Task};
use format::Found;
use index::{Index, StoredConfig};
use layout::{BANKS, ChunkItem, Encoded, Geometry, ItemKey, PlanItem};
use upload::Upload;
use verify::{Verified, VerifyError};

/// Most pages the store uses (the caches are sized for them): 512 KiB of 2 KiB pages, the
/// first of them the marker page. A larger range is cut to this.
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

/// The cache the store is built with by default.
fn store_cache() -> StoreCache {
    Cache::new(ArrayPageStates::new(), Uncached, ArrayKeyPointers::new())
}

/// The flash a store is built on, when its range is usable.
enum Backend<F: NorFlash, C: CacheImpl<u16>> {
    Map(MapStorage<u16, Verified<F>, C>),
    /// The range does not fit the flash's pages; every request fails with `Flash`.
    Unusable(F),
    /// Only inside [`PlanStore::restart_map`], which puts the map back before it returns.
    Restarting,
}

/// What the store's area was found to hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    /// Not looked at yet (or it could not be read).
    Unknown,
    /// The store's own (marked).
    Ours,
    /// Data the store did not write.
    Foreign,
}

/// Item buffer, aligned for flash drivers that write from it directly.
#[repr(align(8))]
struct ItemBuffer([u8; ITEM_BUFFER]);

/// A chunk's value as encoded once for storing, sizing and the plan CRC.
struct ChunkBuffer([u8; layout::MAX_VALUE]);

/// A checked chunk, encoded in the chunk buffer.
#[derive(Debug, Clone, Copy)]
struct Staged {
    bank: u8,
    index: u8,
    /// Bytes of its encoding.
    len: usize,
    /// Its steps, and their duration in all, ms.
    steps: u16,
    ms: u64,
}

/// The plan store. See the module documentation.
pub struct PlanStore<F: NorFlash, C: CacheImpl<u16> = StoreCache> {
    backend: Backend<F, C>,
    buf: ItemBuffer,
    chunk: ChunkBuffer,
    index: Index,
    upload: Option<Upload>,
    /// The index does not describe the flash (not read yet, or a write failed).
    stale: bool,
    /// The whole area: the marker page, then the map.
    area: Range<u32>,
    format: Format,
    /// Live bytes uploads may fill: what the map is sure to hold (`Geometry::capacity`) less
    /// the room kept so that a delete or a configuration change always fits
    /// (`Geometry::reserve`). Fixed by the flash, so computed once.
    room: u32,
    /// Flash a commit's plan header may take (`Geometry::max_record_size`), held free by
    /// every chunk of an upload.
    max_record: u32,
    geometry: Geometry,
    /// Makes an empty cache (a format starts the map over).
    new_cache: fn() -> C,
    /// A chunk accepted by [`PlanStore::chunk_deferred`] and not yet written.
    pending: Option<Staged>,
    /// Why a deferred chunk write failed, for the upload's next request.
    failed: Option<StoreError>,
}

impl<F: NorFlash> PlanStore<F> {
    /// A store in `range` of `flash` (page-aligned, at least three pages: the marker page and
    /// two for the map; more than [`MAX_PAGES`] pages are cut to that). Nothing is read until
    /// the first request.
    pub fn new(flash: F, range: Range<u32>) -> Self {
        Self::with_cache(flash, range, store_cache)
    }
}

impl<F: NorFlash, C: CacheImpl<u16>> PlanStore<F, C> {
    /// A store with another sequential-storage cache, made by `new_cache` (e.g.
    /// `Cache::new_uncached`, to measure what the cache saves).
    pub fn with_cache(flash: F, range: Range<u32>, new_cache: fn() -> C) -> Self {
        let max_len = (MAX_PAGES * F::ERASE_SIZE) as u32;
        let area = range.start..range.end.min(range.start.saturating_add(max_len));
        let map = map_range(&area, F::ERASE_SIZE);
        let map_pages = map.end.saturating_sub(map.start) / F::ERASE_SIZE as u32;
        let geometry = Geometry {
            overhead: MapStorage::<u16, Verified<F>, C>::item_overhead_size(),
            word: F::WRITE_SIZE.max(F::READ_SIZE) as u32,
        };
        let capacity = geometry.capacity(map_pages, F::ERASE_SIZE as u32);
        let backend = match MapConfig::<Verified<F>>::try_new(map) {
            Ok(config) => Backend::Map(MapStorage::new(Verified::new(flash), config, new_cache())),
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
            area,
            format: Format::Unknown,
            room: capacity.saturating_sub(geometry.reserve()),
            max_record: geometry.max_record_size(),
            geometry,
            new_cache,
            pending: None,
            failed: None,
        }
    }

    /// The flash back.
    pub fn into_flash(self) -> F {
        match self.backend {
            Backend::Map(map) => map.destroy().0.into_inner(),
            Backend::Unusable(flash) => flash,
            Backend::Restarting => unreachable!("restart_map always puts the map back"),
        }
    }

    /// Reports every flash operation that completes to `progress` as progress of `task` (the
    /// task the store runs in), so a long request keeps checking in with the watchdog.
    pub fn set_progress(&mut self, progress: &'static dyn Progress, task: Task) {
        if let Backend::Map(map) = &mut self.backend {
            map.flash().set_progress(progress, task);
        }
    }

    /// What the store's area holds (looked at now if it was not yet).
    pub async fn info(&mut self) -> StoreInfo {
        let state = match self.ensure_open().await {
            Ok(()) => StoreState::Ready,
            Err(StoreError::Foreign) => StoreState::Foreign,
            Err(_) => StoreState::Unavailable,
        };
        let area_bytes = match self.backend {
            Backend::Map(_) => self.area.end - self.area.start,
            Backend::Unusable(_) | Backend::Restarting => 0,
        };
        StoreInfo { state, layout: format::LAYOUT, area_bytes }
    }

    /// Erases the whole area (every plan, the configuration, or whatever else it held) and
    /// writes the marker: an empty store. What the area then holds.
    pub async fn format(&mut self) -> Result<StoreInfo, Refusal> {
        self.upload = None;
        self.pending = None;
        self.failed = None;
        self.index.clear();
        self.stale = true;
        self.format = Format::Unknown;
        let area = self.area.clone();
        let Backend::Map(map) = &mut self.backend else {
            return Err(Refusal::Store(StoreError::Flash));
        };
        defmt::warn!("plan store: formatting (erasing the whole area)");
        let formatted = format::format(map.flash(), area.clone()).await;
        // The map's cache described the old contents: start the map over with an empty one.
        self.restart_map();
        formatted.map_err(|e| Refusal::Store(flash_error(&e, area.start)))?;
        Ok(self.info().await)
    }

    /// Rebuilds the map over the same flash with an empty cache (sequential-storage has no
    /// call that clears a cache after the flash changed under it).
    fn restart_map(&mut self) {
        if !matches!(self.backend, Backend::Map(_)) {
            return;
        }
        let Backend::Map(old) = core::mem::replace(&mut self.backend, Backend::Restarting) else {
            return;
        };
        let (flash, _) = old.destroy();
        let range = map_range(&self.area, F::ERASE_SIZE);
        self.backend = match MapConfig::<Verified<F>>::try_new(range) {
            Ok(config) => Backend::Map(MapStorage::new(flash, config, (self.new_cache)())),
            Err(_) => Backend::Unusable(flash.into_inner()),
        };
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
        self.open().await.map_err(Refusal::Store)?;
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
        self.open().await.map_err(Refusal::Store)?;
        // A failed deferred chunk ended the upload this one replaces.
        self.failed = None;
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
        let staged = self.stage(chunk, limits).await?;
        let stored = self.write_staged(&staged).await;
        // On an error the upload stays where it was and the chunk may be sent again (a chunk
        // refused `Full` in `stage` ended it).
        stored.map_err(Refusal::Store)?;
        Ok(self.accept_staged(&staged))
    }

    /// [`PlanStore::chunk`], answered before the chunk is written: the chunk is checked and
    /// counted now, and written by [`PlanStore::flush`] (which the link calls once the answer
    /// is sent, so the flash programs while the next chunk's bytes arrive) or first thing by
    /// the next request. A write that fails then ends the upload, and the next `chunk` or
    /// `commit` is refused with its error (the client begins again). The switch is still the
    /// commit's header write, after every chunk was written: a power cut before it keeps the
    /// slot's old plan, whatever was acknowledged.
    pub async fn chunk_deferred(
        &mut self,
        chunk: UploadChunk,
        limits: &DeviceLimits,
    ) -> Result<u16, Refusal> {
        let staged = self.stage(chunk, limits).await?;
        let received = self.accept_staged(&staged);
        self.pending = Some(staged);
        Ok(received)
    }

    /// Writes the chunk [`PlanStore::chunk_deferred`] accepted, if one waits. On an error the
    /// upload ends, and the error is kept for its next `chunk` or `commit`.
    pub async fn flush(&mut self) -> Result<(), StoreError> {
        let Some(staged) = self.pending.take() else { return Ok(()) };
        let stored = self.write_staged(&staged).await;
        if let Err(e) = &stored {
            defmt::warn!("plan store: a chunk written after its answer failed; upload ended");
            self.upload = None;
            self.failed = Some(e.clone());
        }
        stored
    }

    /// Opens the store, writes a deferred chunk, and checks the next chunk against the upload
    /// and `limits`; encodes it into the chunk buffer, once (the same bytes are stored, sized
    /// and added to the plan's CRC).
    async fn stage(
        &mut self,
        chunk: UploadChunk,
        limits: &DeviceLimits,
    ) -> Result<Staged, Refusal> {
        self.settle().await.map_err(Refusal::Store)?;
        let upload = self.upload.as_ref().ok_or(Refusal::Upload(UploadError::NotStarted))?;
        let index = upload.check(&chunk, limits).map_err(Refusal::Upload)?;
        let steps = chunk.steps.len() as u16;
        let ms = chunk.steps.iter().map(|s| s.duration_ms as u64).sum();
        let item: ChunkItem = Some(chunk.steps);
        // (The buffer holds the longest chunk: `layout::MAX_VALUE`.)
        let encoded = postcard::to_slice(&item, &mut self.chunk.0);
        let len = encoded.map_err(|_| Refusal::Store(StoreError::Flash))?.len();
        let bank = upload.bank;
        // The chunk and the commit's header must leave the reserve free: a full store can
        // still delete. Refused, the upload ends and its chunks are cleared at once.
        let growth = self.geometry.item_size(len) + self.max_record;
        if growth > self.free_bytes() {
            self.upload = None;
            self.tidy().await;
            return Err(Refusal::Store(StoreError::Full));
        }
        Ok(Staged { bank, index, len, steps, ms })
    }

    /// Writes the staged chunk from the chunk buffer.
    async fn write_staged(&mut self, staged: &Staged) -> Result<(), StoreError> {
        let encoded = &self.chunk.0[..staged.len];
        let key = ItemKey::Chunk { bank: staged.bank, index: staged.index };
        let stored = put(&mut self.backend, &mut self.buf.0, key, &encoded).await;
        if stored != Err(StoreError::Full) {
            // Written, or maybe written: counted, and cleared by a sweep if the upload is
            // abandoned.
            let size = self.geometry.item_size(staged.len) as u16;
            self.index.set_chunk(staged.bank, staged.index, true, size);
        }
        stored
    }

    /// Counts the staged chunk (in the chunk buffer) into the upload; steps received so far.
    fn accept_staged(&mut self, staged: &Staged) -> u16 {
        let Some(upload) = self.upload.as_mut() else { return 0 };
        // The step bytes follow the option tag and the one-byte length (as `append_chunk`).
        let step_bytes = self.chunk.0.get(2..staged.len).unwrap_or_default();
        upload.accept(staged.steps, staged.ms, step_bytes)
    }

    /// Opens the store and writes a deferred chunk (a failure is kept for the upload's next
    /// request).
    async fn open(&mut self) -> Result<(), StoreError> {
        self.ensure_open().await?;
        let _ = self.flush().await;
        Ok(())
    }

    /// [`PlanStore::open`], then the error of a deferred chunk write, once: what the upload's
    /// next request (`chunk`, `commit`) answers.
    async fn settle(&mut self) -> Result<(), StoreError> {
        self.open().await?;
        match self.failed.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// Checks the upload whole and stores it: the plan stored.
    pub async fn commit(&mut self, limits: &DeviceLimits) -> Result<PlanSummary, Refusal> {
        self.settle().await.map_err(Refusal::Store)?;
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
        self.open().await.map_err(Refusal::Store)?;
        Ok(self.index.page(from_slot, self.free_bytes()))
    }

    /// Flash left for plans: the room uploads may fill, less the newest item of every key.
    fn free_bytes(&self) -> u32 {
        self.room.saturating_sub(self.index.live_bytes())
    }

    /// Deletes a plan; what was deleted.
    pub async fn delete(&mut self, plan: &PlanRef) -> Result<PlanSummary, Refusal> {
        self.open().await.map_err(Refusal::Store)?;
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
        self.open().await.map_err(Refusal::Store)?;
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
        // A deferred chunk of the upload dropped here is not written.
        self.pending = None;
        self.index.clear();
        self.check_format().await?;
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
            return Err(store_error(&e, self.area.start));
        }
        self.stale = false;
        self.tidy().await;
        Ok(())
    }

    /// Looks at the marker once (module `format`): the store's own area opens; a blank one is
    /// marked; anything else is `Foreign` until [`PlanStore::format`].
    async fn check_format(&mut self) -> Result<(), StoreError> {
        let area = self.area.clone();
        let Backend::Map(map) = &mut self.backend else {
            return Err(StoreError::Flash);
        };
        if self.format == Format::Unknown {
            let flash = map.flash();
            let found = format::examine(flash, area.clone()).await;
            self.format = match found {
                Ok(Found::Marked) => Format::Ours,
                Ok(Found::Blank) => {
                    defmt::info!("plan store: blank area, writing the format marker");
                    let start = area.start;
                    format::mark(flash, area).await.map_err(|e| flash_error(&e, start))?;
                    Format::Ours
                }
                Ok(Found::Foreign) => {
                    defmt::warn!(
                        "plan store: the area holds data the store did not write; \
                         nothing is stored until it is formatted"
                    );
                    Format::Foreign
                }
                Err(e) => return Err(flash_error(&e, area.start)),
            };
        }
        match self.format {
            Format::Foreign => Err(StoreError::Foreign),
            _ => Ok(()),
        }
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
        if matches!(stored, Err(StoreError::Flash | StoreError::Verify { .. })) {
            self.stale = true;
        }
        stored
    }

    /// Reads the newest item of `key`, raw.
    async fn get(&mut self, key: ItemKey) -> Result<Option<&[u8]>, StoreError> {
        let Backend::Map(map) = &mut self.backend else {
            return Err(StoreError::Flash);
        };
        let area_start = self.area.start;
        map.fetch_item::<&[u8]>(&mut self.buf.0, &key.raw()).await.map_err(|e| {
            defmt::warn!("plan store: reading failed: {}", describe(&e));
            store_error(&e, area_start)
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
    let area_start = map.flash_range().start.saturating_sub(F::ERASE_SIZE as u32);
    match map.store_item(buf, &key.raw(), value).await {
        Ok(()) => Ok(()),
        // Nothing was written: the map had no room.
        Err(sequential_storage::Error::FullStorage) => Err(StoreError::Full),
        Err(e) => {
            defmt::warn!("plan store: writing failed: {}", describe(&e));
            Err(store_error(&e, area_start))
        }
    }
}

/// The map's range in the store's `area`: every page after the marker page.
fn map_range(area: &Range<u32>, page: usize) -> Range<u32> {
    area.start.saturating_add(page as u32)..area.end
}

/// The store error for a failed flash operation: a read-back mismatch is `Verify` (its offset
/// in the area, which starts at `area_start`), anything else `Flash`.
fn flash_error<E>(e: &VerifyError<E>, area_start: u32) -> StoreError {
    match e {
        VerifyError::Mismatch { offset } => {
            defmt::warn!("plan store: the flash reads back different at {=u32:#x}", offset);
            StoreError::Verify { offset: offset.saturating_sub(area_start) }
        }
        VerifyError::Flash(_) => StoreError::Flash,
    }
}

/// The store error for a failed sequential-storage call.
fn store_error<E>(e: &sequential_storage::Error<VerifyError<E>>, area_start: u32) -> StoreError {
    match e {
        sequential_storage::Error::Storage { value, .. } => flash_error(value, area_start),
        _ => StoreError::Flash,
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
