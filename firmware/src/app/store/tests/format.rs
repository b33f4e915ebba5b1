//! The format marker (blank areas marked, foreign data refused and left alone, formatting
//! safe against power cuts), every write read back (dropped writes and erases are `Verify`),
//! and the flash's busy time between the store's progress reports.

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use chladni_shared::icd::store::{StoreError, StoreInfo, StoreState};

use super::super::format::{self, LAYOUT, MARKER_LEN};
use super::*;
use crate::app::watchdog::{Progress, Task};

fn info(s: &mut PlanStore<MockFlash>) -> StoreInfo {
    block_on(s.info())
}

fn state(s: &mut PlanStore<MockFlash>) -> StoreState {
    info(s).state
}

/// A flash of `pages` pages with a factory demo's leftovers: pseudo-random bytes over pages
/// 1..4 (not the first), and the rest erased.
fn foreign_flash(pages: usize) -> MockFlash {
    let mut flash = MockFlash::new(pages);
    let mut x = 0x1234_5678u32;
    for b in &mut flash.bytes_mut()[PAGE_SIZE..4 * PAGE_SIZE] {
        x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        *b = (x >> 24) as u8;
    }
    flash
}

#[test]
fn a_blank_area_is_marked_at_first_use_and_opens_as_the_stores() {
    let mut s = store(8);
    assert_eq!(
        info(&mut s),
        StoreInfo { state: StoreState::Ready, layout: LAYOUT, area_bytes: 8 * PAGE_SIZE as u32 }
    );
    let flash = s.into_flash();
    assert_eq!(flash.bytes()[..MARKER_LEN], format::marker());
    assert!(flash.bytes()[MARKER_LEN..].iter().all(|b| *b == 0xff), "nothing else written");
    let mut s = PlanStore::new(flash.revive(), range(8));
    let p = plan("p", 40, 1);
    upload(&mut s, &p, None).unwrap();
    let mut s = reopen(s, 8);
    assert_eq!(load(&mut s, slot_of(&p)).unwrap(), p);
}

#[test]
fn foreign_data_is_refused_left_alone_and_erased_only_by_a_format() {
    let flash = foreign_flash(8);
    let before = flash.bytes().to_vec();
    let mut s = PlanStore::new(flash, range(8));
    let foreign = Err(Refusal::Store(StoreError::Foreign));
    assert_eq!(state(&mut s), StoreState::Foreign);
    assert_eq!(block_on(s.list(0)).map(|_| ()), foreign);
    assert_eq!(upload(&mut s, &plan("p", 5, 1), None).map(|_| ()), foreign);
    assert_eq!(load(&mut s, PlanRef::Slot(0)).map(|_| ()), foreign);
    assert_eq!(block_on(s.load_config()), chladni_shared::icd::store::DeviceConfig::DEFAULT);
    let flash = s.into_flash();
    assert_eq!(flash.bytes(), &before[..], "not one byte changed");
    assert_eq!(flash.stats().mutations(), 0);

    let mut s = PlanStore::new(flash.revive(), range(8));
    assert_eq!(block_on(s.format()).map(|i| i.state), Ok(StoreState::Ready));
    let p = plan("after", 100, 2);
    upload(&mut s, &p, None).unwrap();
    let mut s = reopen(s, 8);
    assert_eq!(list_all(&mut s).unwrap().0.len(), 1);
    assert_eq!(load(&mut s, slot_of(&p)).unwrap(), p);
    // A marker of another layout is foreign too.
    let mut flash = s.into_flash();
    flash.bytes_mut()[8] ^= 0x02;
    let mut s = PlanStore::new(flash.revive(), range(8));
    assert_eq!(state(&mut s), StoreState::Foreign);
}

#[test]
fn a_format_erases_every_plan_and_the_configuration() {
    let mut s = store(8);
    upload(&mut s, &plan("gone", 200, 3), None).unwrap();
    let mut config = chladni_shared::icd::store::DeviceConfig::DEFAULT;
    config.limits.max_steps = 17;
    block_on(s.set_config(config)).unwrap();
    let formatted = block_on(s.format()).unwrap();
    assert_eq!(formatted.state, StoreState::Ready);
    assert_eq!(list_all(&mut s).unwrap().0, []);
    let mut s = reopen(s, 8);
    assert_eq!(list_all(&mut s).unwrap().0, []);
    assert_eq!(block_on(s.load_config()), chladni_shared::icd::store::DeviceConfig::DEFAULT);
}

/// A power cut at every write and erase of a format (over foreign data, and over a store with
/// plans) and of the first marking of a blank area: the next boot finds the area foreign (a
/// format was cut: the old contents are never read as a store) or the store's and empty, and a
/// format then always gives an empty store that takes an upload.
#[test]
fn a_cut_format_never_reads_as_a_store_with_old_contents() {
    let mut with_plans = store(8);
    upload(&mut with_plans, &plan("old", 256, 4), None).unwrap();
    let starts: [(&str, MockFlash); 3] = [
        ("foreign", foreign_flash(8)),
        ("a store", with_plans.into_flash().revive()),
        ("blank", MockFlash::new(8)),
    ];
    let mut runs = 0;
    for (what, flash) in starts {
        let op = |s: &mut PlanStore<MockFlash>| match what {
            "blank" => block_on(s.info()).state == StoreState::Ready,
            _ => block_on(s.format()).is_ok(),
        };
        let total = {
            let mut s = PlanStore::new(flash.clone(), range(8));
            assert!(op(&mut s), "{what}: uncut");
            s.into_flash().stats().mutations()
        };
        for cut in 0..total {
            for seed in [0, 1, 7] {
                let mut f = flash.clone();
                f.cut_after(cut, seed);
                let mut s = PlanStore::new(f, range(8));
                let _ = op(&mut s);
                let mut s = reopen(s, 8);
                match state(&mut s) {
                    StoreState::Ready => {
                        assert_eq!(list_all(&mut s).unwrap().0, [], "{what}, cut {cut}")
                    }
                    StoreState::Foreign => {
                        assert_ne!(what, "blank", "cut {cut}: a blank area stays blank")
                    }
                    StoreState::Unavailable => panic!("{what}, cut {cut}: unreadable"),
                }
                assert_eq!(block_on(s.format()).map(|i| i.state), Ok(StoreState::Ready));
                upload(&mut s, &plan("new", 64, 5), None).unwrap();
                runs += 1;
            }
        }
    }
    std::println!("{runs} cut formats");
}

/// A write the flash drops silently (reported done, nothing programmed), anywhere in an upload
/// that replaces a plan: the request fails with `Verify`, a retry succeeds, nothing else is
/// lost, and the index matches the flash.
#[test]
fn a_dropped_write_or_erase_is_a_verify_error_and_loses_nothing() {
    let mut s = store(16);
    let (keep, old) = (plan("keep", 100, 1), plan("target", 256, 2));
    upload(&mut s, &keep, Some(0)).unwrap();
    upload(&mut s, &old, Some(1)).unwrap();
    for k in 0..40 {
        upload(&mut s, &plan("churn", 200, 100 + k), Some(2)).unwrap();
    }
    let flash = s.into_flash().revive();
    let new = plan("target", 256, 3);
    let (writes, erases) = {
        let mut s = PlanStore::new(flash.clone(), range(16));
        upload(&mut s, &new, Some(1)).unwrap();
        let stats = s.into_flash().stats();
        (stats.writes, stats.erases)
    };
    assert!(erases > 0, "the upload collects garbage");
    let mut verify_errors = 0;
    let drops = (0..writes).map(|k| (k, true)).chain((0..erases).map(|k| (k, false)));
    for (k, write) in drops {
        let mut f = flash.clone();
        if write {
            f.drop_write_after(k)
        } else {
            f.drop_erase_after(k)
        }
        let mut s = PlanStore::new(f, range(16));
        if let Err(e) = upload(&mut s, &new, Some(1)) {
            assert!(
                matches!(e, Refusal::Store(StoreError::Verify { .. })),
                "drop {k} (write {write}): {e:?}"
            );
            verify_errors += 1;
            upload(&mut s, &new, Some(1)).unwrap();
        }
        assert!(block_on(s.index_matches_flash()), "drop {k} (write {write})");
        assert_eq!(load(&mut s, PlanRef::Slot(1)).unwrap(), new, "drop {k} (write {write})");
        assert_eq!(load(&mut s, PlanRef::Slot(0)).unwrap(), keep, "drop {k} (write {write})");
        let mut s = reopen(s, 16);
        assert_eq!(load(&mut s, PlanRef::Slot(1)).unwrap(), new, "drop {k} after a reboot");
    }
    assert!(verify_errors > 0);
    std::println!("{writes} dropped writes and {erases} dropped erases: {verify_errors} Verify");
}

/// Records the longest simulated flash time between two progress reports.
struct GapMeter {
    clock: std::sync::Arc<AtomicU64>,
    state: Mutex<(u64, u64)>,
}

impl Progress for GapMeter {
    fn progress(&self, task: Task) {
        assert_eq!(task, Task::Link);
        let now = self.clock.load(Ordering::Relaxed);
        let mut state = self.state.lock().unwrap();
        state.1 = state.1.max(now - state.0);
        state.0 = now;
    }
}

impl GapMeter {
    /// The longest gap so far, µs, and starts a new measurement at now.
    fn take(&self) -> u64 {
        let mut state = self.state.lock().unwrap();
        let longest = state.1;
        *state = (self.clock.load(Ordering::Relaxed), 0);
        longest
    }
}

/// The chip's flash times (82 µs a double word, 22 ms a page erase, simulated) between the
/// store's progress reports, which the link forwards to the watchdog: through uploads,
/// deletes, and uploads into a full store (garbage collection moving whole pages of live
/// items), the longest gap stays far below the watchdog's 250 ms check-in period, while one
/// request keeps the flash busy longer than that.
#[test]
fn progress_is_reported_at_every_flash_operation_within_the_check_in_period() {
    const PAGES: usize = 64;
    let flash = MockFlash::new(PAGES);
    let meter: &'static GapMeter = std::boxed::Box::leak(std::boxed::Box::new(GapMeter {
        clock: flash.clock(),
        state: Mutex::new((0, 0)),
    }));
    let clock = flash.clock();
    let mut s = PlanStore::new(flash, range(PAGES));
    s.set_progress(meter, Task::Link);
    let mut longest_request = 0u64;
    let mut timed = |s: &mut PlanStore<MockFlash>, f: &mut dyn FnMut(&mut PlanStore<MockFlash>)| {
        let t0 = clock.load(Ordering::Relaxed);
        f(s);
        longest_request = longest_request.max(clock.load(Ordering::Relaxed) - t0);
    };
    // Fill the store with the longest plans, then replace and delete round and round.
    let mut stored = std::vec::Vec::new();
    for slot in 0..SCRATCH_SLOT {
        let p = longest_plan(&std::format!("p{slot}"), slot as u32);
        let mut ok = true;
        timed(&mut s, &mut |s| ok = upload(s, &p, Some(slot)).is_ok());
        if !ok {
            break;
        }
        stored.push(p);
    }
    // Room for a replacement to be written before the plan it replaces is cleared.
    for slot in [stored.len() - 1, stored.len() - 2] {
        timed(&mut s, &mut |s| {
            block_on(s.delete(&PlanRef::Slot(slot as u8))).unwrap();
        });
    }
    let fill_gap = meter.take();
    let n = stored.len() - 2;
    for k in 0..3 * n {
        let slot = (7 * k % n) as u8;
        if k % 5 == 4 {
            timed(&mut s, &mut |s| {
                block_on(s.delete(&PlanRef::Slot(slot))).unwrap();
            });
        }
        let p = longest_plan(&std::format!("p{slot}"), 1000 + k as u32);
        timed(&mut s, &mut |s| {
            upload(s, &p, Some(slot)).unwrap();
        });
    }
    let churn_gap = meter.take();
    let busy = clock.load(Ordering::Relaxed);
    std::println!(
        "{n} longest plans fill {PAGES} pages; longest flash time between progress reports: \
         filling {:.1} ms, replacing and deleting {:.1} ms; longest request {:.1} ms of flash \
         time; {:.1} s in all",
        fill_gap as f64 / 1e3,
        churn_gap as f64 / 1e3,
        longest_request as f64 / 1e3,
        busy as f64 / 1e6
    );
    let limit = 250_000;
    assert!(fill_gap < limit && churn_gap < limit);
    // The reports matter: without them one request would outlast the check-in period.
    assert!(longest_request > limit, "longest request {longest_request} us");
}
