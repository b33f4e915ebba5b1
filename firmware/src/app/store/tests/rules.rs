//! The store's request rules: slots and names, every upload refusal, delete, list paging,
//! configuration, and what a reboot keeps.

use chladni_shared::icd::link::Refusal;
use chladni_shared::icd::plan::{DeviceLimits, PlanError, Step};
use chladni_shared::icd::store::{
    DeviceConfig, PAGE_PLANS, PLAN_SLOTS, PlanRef, SCRATCH_SLOT, StoreError, UploadChunk,
    UploadError,
};
use embassy_futures::block_on;

use super::super::layout::{Encoded, ItemKey};
use super::*;

fn upload_err(e: UploadError) -> Result<PlanSummary, Refusal> {
    Err(Refusal::Upload(e))
}

#[test]
fn plans_round_trip_whole() {
    let mut s = store(16);
    for (slot, steps) in [1usize, 31, 32, 33, 255, 256].into_iter().enumerate() {
        let p = plan(&std::format!("p{steps}"), steps, slot as u32);
        let summary = upload(&mut s, &p, None).unwrap();
        assert_eq!(summary.slot, slot as u8, "lowest free slot");
        assert_eq!(
            (summary.steps, summary.repeat, summary.crc),
            (steps as u16, p.repeat, plan_crc(&p))
        );
        assert_eq!(summary.total_ms, p.total_ms());
        assert!(summary.bytes > 0);
        assert_eq!(load(&mut s, PlanRef::Slot(slot as u8)).unwrap(), p);
        assert_eq!(load(&mut s, slot_of(&p)).unwrap(), p);
    }
    let (listed, _) = list_all(&mut s).unwrap();
    let mut s = reopen(s, 16);
    assert_eq!(list_all(&mut s).unwrap().0, listed, "a reboot keeps every plan");
    assert_eq!(load(&mut s, PlanRef::Slot(5)).unwrap().steps.len(), 256);
}

#[test]
fn slots_and_names() {
    let mut s = store(16);
    let a = plan("a", 3, 1);
    assert_eq!(upload(&mut s, &a, Some(7)).unwrap().slot, 7);
    // By name without a slot: the slot holding that name.
    let a2 = plan("a", 5, 2);
    assert_eq!(upload(&mut s, &a2, None).unwrap().slot, 7);
    assert_eq!(load(&mut s, PlanRef::Slot(7)).unwrap(), a2);
    // Another slot below the scratch slot may not take the name.
    assert_eq!(upload(&mut s, &a, Some(3)), upload_err(UploadError::NameTaken { slot: 7 }));
    // A plan is run and deleted by name: a blank one is refused.
    assert_eq!(upload(&mut s, &plan(" ", 1, 1), None), upload_err(UploadError::EmptyName));
    // The scratch slot may, and a lookup by name finds the other slot first.
    let scratch = plan("a", 2, 3);
    assert_eq!(upload(&mut s, &scratch, Some(SCRATCH_SLOT)).unwrap().slot, SCRATCH_SLOT);
    assert_eq!(load(&mut s, slot_of(&a)).unwrap(), a2);
    block_on(s.delete(&PlanRef::Slot(7))).unwrap();
    assert_eq!(load(&mut s, slot_of(&a)).unwrap(), scratch, "then the scratch slot");
    // A new name without a slot: the lowest free slot, never the scratch one.
    assert_eq!(upload(&mut s, &plan("b", 1, 4), None).unwrap().slot, 0);
    assert_eq!(
        upload(&mut s, &a, Some(PLAN_SLOTS)),
        upload_err(UploadError::BadSlot { slot: PLAN_SLOTS })
    );
    assert_eq!(
        load(&mut s, PlanRef::Slot(PLAN_SLOTS)),
        Err(Refusal::Store(StoreError::NotFound(PlanRef::Slot(PLAN_SLOTS))))
    );
}

#[test]
fn a_full_store_refuses_a_new_name() {
    let mut s = store(24);
    for slot in 0..SCRATCH_SLOT {
        upload(&mut s, &plan(&std::format!("n{slot}"), 1, slot as u32), None).unwrap();
    }
    assert_eq!(upload(&mut s, &plan("new", 1, 0), None), upload_err(UploadError::StoreFull));
    // A named slot, an existing name and the scratch slot still work.
    assert_eq!(upload(&mut s, &plan("new", 1, 0), Some(4)).unwrap().slot, 4);
    assert_eq!(upload(&mut s, &plan("n9", 2, 0), None).unwrap().slot, 9);
    assert_eq!(upload(&mut s, &plan("x", 2, 0), Some(SCRATCH_SLOT)).unwrap().slot, SCRATCH_SLOT);
    assert_eq!(list_all(&mut s).unwrap().0.len(), PLAN_SLOTS as usize);
}

#[test]
fn begin_checks_the_header() {
    let mut s = store(4);
    let p = plan("h", 4, 1);
    let refused = |s: &mut PlanStore<MockFlash>, begin, limits: &DeviceLimits| {
        block_on(s.begin(begin, limits)).unwrap_err()
    };
    let mut b = begin_of(&p, None);
    b.steps = 0;
    assert_eq!(refused(&mut s, b, &LIMITS), Refusal::Upload(UploadError::Plan(PlanError::Empty)));
    let mut b = begin_of(&p, None);
    b.repeat = 0;
    assert_eq!(
        refused(&mut s, b, &LIMITS),
        Refusal::Upload(UploadError::Plan(PlanError::ZeroRepeat))
    );
    let small = DeviceLimits { max_steps: 3, ..LIMITS };
    assert_eq!(
        refused(&mut s, begin_of(&p, None), &small),
        Refusal::Upload(UploadError::Plan(PlanError::TooManySteps { count: 4, max: 3 }))
    );
    let mut b = begin_of(&p, None);
    b.steps = 257;
    assert!(matches!(
        refused(&mut s, b, &LIMITS),
        Refusal::Upload(UploadError::Plan(PlanError::TooManySteps { count: 257, .. }))
    ));
}

/// Begins an upload of `p`, sends chunks `sent`; the store and the chunks.
fn started(p: &Plan, sent: usize) -> (PlanStore<MockFlash>, std::vec::Vec<UploadChunk>) {
    let mut s = store(8);
    block_on(s.begin(begin_of(p, None), &LIMITS)).unwrap();
    let chunks = chunks_of(p);
    for c in &chunks[..sent] {
        block_on(s.chunk(c.clone(), &LIMITS)).unwrap();
    }
    (s, chunks)
}

#[test]
fn chunks_must_come_in_order_whole_and_valid() {
    let p = plan("c", 70, 5); // chunks of 32, 32, 6
    let (mut s, chunks) = started(&p, 1);
    let send = |s: &mut PlanStore<MockFlash>, c: UploadChunk| block_on(s.chunk(c, &LIMITS));
    let up = |e| Err(Refusal::Upload(e));
    assert_eq!(send(&mut s, chunks[0].clone()), up(UploadError::Duplicate { index: 0 }));
    assert_eq!(
        send(&mut s, chunks[2].clone()),
        up(UploadError::OutOfOrder { expected: 1, got: 2 })
    );
    let mut short = chunks[1].clone();
    short.steps.pop();
    assert_eq!(
        send(&mut s, short),
        up(UploadError::BadChunkLength { index: 1, steps: 31, expected: 32 })
    );
    let mut bad = chunks[1].clone();
    bad.steps[5].freq_mhz = 5;
    assert!(matches!(
        send(&mut s, bad),
        Err(Refusal::Upload(UploadError::Plan(PlanError::FrequencyOutOfRange { step: 37, .. })))
    ));
    let mut bad = chunks[1].clone();
    bad.steps[0].ramp_ms = bad.steps[0].duration_ms + 1;
    assert!(matches!(
        send(&mut s, bad),
        Err(Refusal::Upload(UploadError::Plan(PlanError::RampLongerThanStep { step: 32, .. })))
    ));
    // None of that disturbed the upload.
    assert_eq!(send(&mut s, chunks[1].clone()), Ok(64));
    let mut long = chunks[2].clone();
    long.steps.push(long.steps[0]).unwrap();
    assert_eq!(
        send(&mut s, long),
        up(UploadError::BadChunkLength { index: 2, steps: 7, expected: 6 })
    );
    assert_eq!(send(&mut s, chunks[2].clone()), Ok(70));
    // One more chunk than announced.
    assert_eq!(
        send(&mut s, UploadChunk { index: 3, steps: chunks[2].steps.clone() }),
        up(UploadError::BadChunkLength { index: 3, steps: 6, expected: 0 })
    );
    assert_eq!(block_on(s.commit(&LIMITS)).unwrap().steps, 70);
    assert_eq!(load(&mut s, PlanRef::Slot(0)).unwrap(), p);
}

#[test]
fn nothing_without_a_begin() {
    let mut s = store(4);
    let c = chunks_of(&plan("n", 1, 0)).remove(0);
    let not_started = Refusal::Upload(UploadError::NotStarted);
    assert_eq!(block_on(s.chunk(c.clone(), &LIMITS)), Err(not_started.clone()));
    assert_eq!(block_on(s.commit(&LIMITS)), Err(not_started.clone()));
    upload(&mut s, &plan("n", 1, 0), None).unwrap();
    // A commit ends the upload.
    assert_eq!(block_on(s.commit(&LIMITS)), Err(not_started.clone()));
    assert_eq!(block_on(s.chunk(c, &LIMITS)), Err(not_started));
}

#[test]
fn commit_checks_the_whole_plan() {
    let p = plan("m", 40, 6);
    let (mut s, chunks) = started(&p, 1);
    assert_eq!(
        block_on(s.commit(&LIMITS)),
        upload_err(UploadError::Missing { received: 32, expected: 40 })
    );
    // The upload goes on after `Missing`.
    block_on(s.chunk(chunks[1].clone(), &LIMITS)).unwrap();
    assert_eq!(block_on(s.commit(&LIMITS)).unwrap().crc, plan_crc(&p));

    // A wrong CRC stores nothing and ends the upload.
    let mut other = p.clone();
    other.steps[39].duration_ms ^= 1;
    let mut begin = begin_of(&other, None);
    begin.crc = plan_crc(&p) ^ 0x55;
    block_on(s.begin(begin, &LIMITS)).unwrap();
    for c in chunks_of(&other) {
        block_on(s.chunk(c, &LIMITS)).unwrap();
    }
    assert_eq!(
        block_on(s.commit(&LIMITS)),
        upload_err(UploadError::CrcMismatch {
            expected: plan_crc(&p) ^ 0x55,
            got: plan_crc(&other)
        })
    );
    assert_eq!(block_on(s.commit(&LIMITS)), upload_err(UploadError::NotStarted));
    assert_eq!(load(&mut s, slot_of(&p)).unwrap(), p, "the old plan is kept");

    // Too long in all: refused at the commit, when the length is known.
    let mut long = plan("long", 2, 7);
    long.steps.iter_mut().for_each(|st| st.duration_ms = 1_000_000);
    long.repeat = 2;
    assert_eq!(
        upload(&mut s, &long, None),
        upload_err(UploadError::Plan(PlanError::TooLong {
            total_ms: 4_000_000,
            max_ms: 3_600_000
        }))
    );
    let (listed, free) = list_all(&mut s).unwrap();
    assert_eq!(listed.len(), 1);
    let mut s = reopen(s, 8);
    assert_eq!(list_all(&mut s).unwrap(), (listed, free), "refused uploads leave nothing");
}

#[test]
fn a_new_begin_replaces_an_abandoned_upload() {
    let a = plan("a", 100, 1);
    let (mut s, chunks) = started(&a, 2);
    let b = plan("b", 50, 2);
    upload(&mut s, &b, None).unwrap();
    assert_eq!(block_on(s.chunk(chunks[2].clone(), &LIMITS)), upload_err_u16());
    // Abandoned again, this time into the same slot, then finished.
    block_on(s.begin(begin_of(&a, None), &LIMITS)).unwrap();
    block_on(s.chunk(chunks[0].clone(), &LIMITS)).unwrap();
    upload(&mut s, &a, Some(1)).unwrap();
    assert_eq!(load(&mut s, PlanRef::Slot(0)).unwrap(), b);
    assert_eq!(load(&mut s, PlanRef::Slot(1)).unwrap(), a);
    let (_, free) = list_all(&mut s).unwrap();
    let mut s = reopen(s, 8);
    assert_eq!(list_all(&mut s).unwrap().1, free, "abandoned chunks were cleared");
}

fn upload_err_u16() -> Result<u16, Refusal> {
    Err(Refusal::Upload(UploadError::NotStarted))
}

#[test]
fn delete_by_slot_or_name() {
    let mut s = store(8);
    let (a, b) = (plan("a", 40, 1), plan("b", 3, 2));
    upload(&mut s, &a, None).unwrap();
    upload(&mut s, &b, None).unwrap();
    let (_, free_before) = list_all(&mut s).unwrap();
    let gone = block_on(s.delete(&slot_of(&a))).unwrap();
    assert_eq!((gone.slot, gone.crc), (0, plan_crc(&a)));
    let not_found = |r: PlanRef| Refusal::Store(StoreError::NotFound(r));
    assert_eq!(load(&mut s, slot_of(&a)), Err(not_found(slot_of(&a))));
    assert_eq!(block_on(s.delete(&PlanRef::Slot(0))), Err(not_found(PlanRef::Slot(0))));
    assert_eq!(block_on(s.delete(&PlanRef::Slot(1))).unwrap().name, b.name);
    assert_eq!(block_on(s.delete(&PlanRef::Slot(200))), Err(not_found(PlanRef::Slot(200))));
    let (listed, free) = list_all(&mut s).unwrap();
    assert!(listed.is_empty());
    assert!(free > free_before, "deleting frees flash: {free} > {free_before}");
    // The tombstones stay: a reboot sees the same.
    let mut s = reopen(s, 8);
    assert_eq!(list_all(&mut s).unwrap(), (listed, free));
    assert_eq!(upload(&mut s, &b, None).unwrap().slot, 0);
}

#[test]
fn the_list_comes_in_pages() {
    let mut s = store(16);
    let slots: std::vec::Vec<u8> = (0..PLAN_SLOTS).filter(|s| s % 3 == 1).collect();
    for &slot in &slots {
        upload(&mut s, &plan(&std::format!("s{slot}"), 2, slot as u32), Some(slot)).unwrap();
    }
    let first = block_on(s.list(0)).unwrap();
    assert_eq!(first.plans.len(), PAGE_PLANS);
    assert_eq!(first.next, Some(slots[PAGE_PLANS]));
    let (all, free) = list_all(&mut s).unwrap();
    assert_eq!(all.iter().map(|p| p.slot).collect::<std::vec::Vec<_>>(), slots);
    assert_eq!(free, first.free_bytes);
    let tail = block_on(s.list(SCRATCH_SLOT)).unwrap();
    assert_eq!((tail.plans.len(), tail.next), (1, None));
    let past = block_on(s.list(PLAN_SLOTS)).unwrap();
    assert!(past.plans.is_empty() && past.next.is_none());
    let exact = block_on(s.list(slots[slots.len() - PAGE_PLANS])).unwrap();
    assert_eq!((exact.plans.len(), exact.next), (PAGE_PLANS, None));
}

#[test]
fn free_bytes_is_the_sure_capacity_less_live_items_and_the_reserve() {
    let mut s = store(8);
    let empty = block_on(s.list(0)).unwrap().free_bytes;
    // 8 pages: the marker page, one page kept erased for garbage collection, and 6 pages
    // that each may waste a largest item (8 + 680 bytes) besides their two marker words; less
    // the reserve: a tombstone (16 bytes) and the longest configuration (8 + 96).
    assert_eq!(empty, 6 * (PAGE_SIZE as u32 - 2 * 8 - 688) - (16 + 104));
    let summary = upload(&mut s, &plan("f", 256, 1), None).unwrap();
    let free = block_on(s.list(0)).unwrap().free_bytes;
    assert_eq!(free, empty - summary.bytes);
    // 8 chunks of 32 steps and the header; each item 8 bytes of header, data 8-aligned.
    assert!(summary.bytes as usize > 256 * 7 && summary.bytes % 8 == 0);
}

/// Found by the `plan_store` fuzz target: plans filled a small store to the last byte, and
/// then a delete (its tombstone) and a configuration change were refused `Full`; the only
/// way out would have been a format. Uploads now stop short of the reserve.
#[test]
fn a_store_filled_by_uploads_still_deletes_and_configures() {
    for pages in [4, 5, 6] {
        let mut s = store(pages);
        let mut stored = std::vec::Vec::new();
        // Packed to the last byte: plans of falling sizes, each size until the store refuses.
        for steps in [200, 90, 40, 17, 8, 3, 1] {
            loop {
                let k = stored.len() as u32;
                let p = plan(&std::format!("p{k}"), steps, k);
                match upload(&mut s, &p, None) {
                    Ok(summary) => stored.push((summary.slot, p)),
                    Err(r) => {
                        assert_eq!(r, Refusal::Store(StoreError::Full), "{pages} pages");
                        break;
                    }
                }
            }
        }
        assert!(stored.len() >= 2, "{pages} pages: {} plans", stored.len());
        // The refused upload ended and left nothing behind: the store still fills the same.
        assert!(block_on(s.index_matches_flash()));
        let mut c = DeviceConfig::DEFAULT;
        c.limits.max_freq_mhz = 800_000;
        assert_eq!(block_on(s.set_config(c)), Ok(c), "{pages} pages");
        for (slot, p) in &stored {
            assert_eq!(load(&mut s, PlanRef::Slot(*slot)).as_ref(), Ok(p));
            let deleted = block_on(s.delete(&PlanRef::Slot(*slot))).map(|d| d.slot);
            assert_eq!(deleted, Ok(*slot), "{pages} pages");
        }
        let mut s = reopen(s, pages);
        assert_eq!(list_all(&mut s).unwrap().0, std::vec::Vec::new());
        assert_eq!(block_on(s.load_config()), c);
    }
}

#[test]
fn config_round_trips_and_is_checked_on_load() {
    let mut s = store(4);
    assert_eq!(block_on(s.load_config()), DeviceConfig::DEFAULT, "nothing stored");
    let mut c = DeviceConfig::DEFAULT;
    c.limits.max_freq_mhz = 800_000;
    c.limits.max_steps = 100;
    assert_eq!(block_on(s.set_config(c)), Ok(c));
    let mut s = reopen(s, 4);
    assert_eq!(block_on(s.load_config()), c);
    let mut bad = c;
    bad.limits.min_freq_mhz = 900_000;
    assert!(matches!(block_on(s.set_config(bad)), Err(Refusal::Config(_))));
    assert_eq!(block_on(s.load_config()), c, "a refused configuration is not stored");
    // An invalid configuration on flash (written past the checks) loads as the default.
    block_on(s.put(ItemKey::Config, &Encoded(&bad))).unwrap();
    assert_eq!(block_on(reopen(s, 4).load_config()), DeviceConfig::DEFAULT);
}

#[test]
fn an_unreadable_config_loads_as_the_default() {
    let mut s = store(4);
    block_on(s.set_config(DeviceConfig::DEFAULT)).unwrap();
    block_on(s.put(ItemKey::Config, &Encoded(&[0xffu8; 3]))).unwrap();
    assert_eq!(block_on(reopen(s, 4).load_config()), DeviceConfig::DEFAULT);
}

#[test]
fn a_damaged_chunk_reads_as_corrupt() {
    let mut s = store(8);
    let p = plan("d", 64, 9);
    upload(&mut s, &p, None).unwrap();
    let mut flash = s.into_flash();
    // Flip a bit in the second chunk's last step, found by its encoding.
    let chunk: Option<heapless::Vec<Step, 32>> = Some(chunks_of(&p)[1].steps.clone());
    let mut buf = [0u8; 600];
    let encoded = postcard::to_slice(&chunk, &mut buf).unwrap();
    let at = flash.bytes().windows(encoded.len()).position(|w| w == &encoded[..]).unwrap();
    flash.bytes_mut()[at + encoded.len() - 1] ^= 0x01;
    let mut s = PlanStore::new(flash.revive(), range(8));
    assert_eq!(list_all(&mut s).unwrap().0.len(), 1, "the header is intact");
    assert_eq!(
        load(&mut s, PlanRef::Slot(0)),
        Err(Refusal::Store(StoreError::Corrupt { slot: 0 }))
    );
}

#[test]
fn an_unusable_range_fails_every_request() {
    let mut s = PlanStore::new(MockFlash::new(4), 100..4096);
    assert_eq!(block_on(s.list(0)), Err(Refusal::Store(StoreError::Flash)));
    assert_eq!(block_on(s.load_config()), DeviceConfig::DEFAULT);
    assert_eq!(upload(&mut s, &plan("u", 1, 0), None), Err(Refusal::Store(StoreError::Flash)));
}

/// A write or erase that fails once (the flash goes on working), anywhere in an upload that
/// replaces a plan: the request fails with `Flash` (or succeeds, if it was only the clearing of
/// the old chunks that failed), a client starting the upload over succeeds, nothing else is
/// lost, and the store's index matches the flash.
#[test]
fn a_glitch_fails_one_request_and_loses_nothing() {
    let mut s = store(16);
    let (keep, old) = (plan("keep", 100, 1), plan("target", 256, 2));
    upload(&mut s, &keep, Some(0)).unwrap();
    upload(&mut s, &old, Some(1)).unwrap();
    for k in 0..40 {
        upload(&mut s, &plan("churn", 200, 100 + k), Some(2)).unwrap();
    }
    let flash = s.into_flash().revive();
    let new = plan("target", 256, 3);
    let total = {
        let mut s = PlanStore::new(flash.clone(), range(16));
        upload(&mut s, &new, Some(1)).unwrap();
        s.into_flash().stats().mutations()
    };
    for glitch in 0..total {
        let mut f = flash.clone();
        f.glitch_after(glitch);
        let mut s = PlanStore::new(f, range(16));
        if let Err(e) = upload(&mut s, &new, Some(1)) {
            assert_eq!(e, Refusal::Store(StoreError::Flash), "glitch {glitch}");
            upload(&mut s, &new, Some(1)).unwrap();
        }
        assert!(block_on(s.index_matches_flash()), "glitch {glitch}");
        let (listed, free) = list_all(&mut s).unwrap();
        assert_eq!(load(&mut s, PlanRef::Slot(1)).unwrap(), new, "glitch {glitch}");
        assert_eq!(load(&mut s, PlanRef::Slot(0)).unwrap(), keep, "glitch {glitch}");
        // A reboot sees the same plans, and clears what a failed sweep left.
        let mut s = reopen(s, 16);
        let (relisted, refree) = list_all(&mut s).unwrap();
        assert_eq!(relisted, listed, "glitch {glitch}");
        assert!(refree >= free, "glitch {glitch}");
    }
}

/// The same for a delete: after a glitch the plan is there or not, and a retry deletes it.
#[test]
fn a_glitch_in_a_delete_loses_nothing_else() {
    let mut s = store(8);
    let (keep, target) = (plan("keep", 100, 1), plan("target", 256, 2));
    upload(&mut s, &keep, Some(0)).unwrap();
    upload(&mut s, &target, Some(1)).unwrap();
    let flash = s.into_flash().revive();
    let total = {
        let mut s = PlanStore::new(flash.clone(), range(8));
        block_on(s.delete(&PlanRef::Slot(1))).unwrap();
        s.into_flash().stats().mutations()
    };
    for glitch in 0..total {
        let mut f = flash.clone();
        f.glitch_after(glitch);
        let mut s = PlanStore::new(f, range(8));
        if block_on(s.delete(&PlanRef::Slot(1))).is_err() {
            // Deleted or not: a retry finds out.
            match block_on(s.delete(&PlanRef::Slot(1))) {
                Ok(_) | Err(Refusal::Store(StoreError::NotFound(_))) => {}
                Err(e) => panic!("glitch {glitch}: {e:?}"),
            }
        }
        assert!(block_on(s.index_matches_flash()), "glitch {glitch}");
        assert_eq!(list_all(&mut s).unwrap().0.len(), 1, "glitch {glitch}");
        assert_eq!(load(&mut s, PlanRef::Slot(0)).unwrap(), keep, "glitch {glitch}");
    }
}

/// The link answers a chunk before writing it (`chunk_deferred`, then `flush` once the answer
/// is out): the plan stored is the same, a request in between writes the chunk first, and a
/// write that fails ends the upload and is the answer to its next chunk (or commit).
#[test]
fn a_deferred_chunk_is_written_before_the_next_request_and_its_failure_answered_there() {
    use super::super::mock_flash::SharedFlash;
    let flash = SharedFlash::new(MockFlash::new(16));
    let mut s = PlanStore::new(flash.clone(), range(16));
    let p = plan("deferred", 100, 7);
    let chunks = chunks_of(&p);
    block_on(async {
        s.begin(begin_of(&p, None), &LIMITS).await.unwrap();
        for (i, c) in chunks.iter().enumerate() {
            let before = flash.with(|f| f.stats().writes);
            s.chunk_deferred(c.clone(), &LIMITS).await.unwrap();
            let written = flash.with(|f| f.stats().writes) - before;
            // The chunk before this one was written first (unless the list below wrote it);
            // this one waits.
            assert_eq!(written > 0, i > 0 && i != 2, "chunk {i}: {written} writes");
            if i == 1 {
                // A list in between writes the waiting chunk and counts it.
                let free = s.list(0).await.unwrap().free_bytes;
                assert!(free < 14 * PAGE_SIZE as u32);
            }
        }
        s.commit(&LIMITS).await.unwrap();
        let mut out = Plan { name: Default::default(), repeat: 0, steps: heapless::Vec::new() };
        s.load(&slot_of(&p), &mut out).await.unwrap();
        assert_eq!(out, p);
        assert!(s.index_matches_flash().await);

        // The deferred write of chunk 0 fails: the next chunk is refused with it, then the
        // upload is gone; a new begin starts over and stores the plan.
        let q = plan("deferred", 100, 8);
        let chunks = chunks_of(&q);
        s.begin(begin_of(&q, None), &LIMITS).await.unwrap();
        s.chunk_deferred(chunks[0].clone(), &LIMITS).await.unwrap();
        flash.with(|f| f.glitch_after(0));
        assert_eq!(s.flush().await, Err(StoreError::Flash));
        let next = s.chunk_deferred(chunks[1].clone(), &LIMITS).await;
        assert_eq!(next, Err(Refusal::Store(StoreError::Flash)));
        let again = s.chunk_deferred(chunks[1].clone(), &LIMITS).await;
        assert_eq!(again, Err(Refusal::Upload(UploadError::NotStarted)));
        s.begin(begin_of(&q, None), &LIMITS).await.unwrap();
        for c in &chunks {
            s.chunk_deferred(c.clone(), &LIMITS).await.unwrap();
        }
        s.commit(&LIMITS).await.unwrap();
        s.load(&slot_of(&q), &mut out).await.unwrap();
        assert_eq!(out, q);
        assert!(s.index_matches_flash().await);
    });
}
