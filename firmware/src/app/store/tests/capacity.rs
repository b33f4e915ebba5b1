//! Capacity on the real range (512 KiB of 2 KiB pages), and what requests cost in flash
//! operations there, with the store's cache and without one. `cargo test -p chladni-firmware
//! --lib capacity -- --nocapture` prints the numbers docs/store.md quotes.

use chladni_shared::icd::store::{PLAN_SLOTS, PlanRef};
use embassy_futures::block_on;
use sequential_storage::cache::{Cache, CacheImpl};

use super::super::mock_flash::{BANK_PAGES, FlashStats};
use super::*;

/// A store on the full bank, with `cache`.
fn bank_store<C: CacheImpl<u16>>(flash: MockFlash, cache: fn() -> C) -> PlanStore<MockFlash, C> {
    PlanStore::with_cache(flash, range(BANK_PAGES), cache)
}

/// The flash operations `f` does on `s`.
fn cost<C: CacheImpl<u16>, T>(
    s: &mut PlanStore<MockFlash, C>,
    f: impl FnOnce(&mut PlanStore<MockFlash, C>) -> T,
) -> (T, FlashStats) {
    let before = s.flash_stats();
    let out = f(s);
    (out, s.flash_stats().since(&before))
}

impl<C: CacheImpl<u16>> PlanStore<MockFlash, C> {
    fn flash_stats(&mut self) -> FlashStats {
        match &mut self.backend {
            super::super::Backend::Map(map) => map.flash().inner().stats(),
            super::super::Backend::Unusable(flash) => flash.stats(),
            super::super::Backend::Restarting => FlashStats::default(),
        }
    }
}

/// Every slot holding a longest plan, then `churn` replacements (slot by slot, round and round);
/// the flash and the plans stored.
fn full_bank(churn: usize) -> (MockFlash, std::vec::Vec<Plan>) {
    let mut s = store(BANK_PAGES);
    let mut plans: std::vec::Vec<Plan> = (0..PLAN_SLOTS)
        .map(|slot| longest_plan(&std::format!("plan{slot}"), slot as u32))
        .collect();
    for (slot, p) in plans.iter().enumerate() {
        upload(&mut s, p, Some(slot as u8)).unwrap();
    }
    for k in 0..churn {
        let slot = k % PLAN_SLOTS as usize;
        plans[slot] = longest_plan(&std::format!("plan{slot}"), 1000 + k as u32);
        upload(&mut s, &plans[slot], Some(slot as u8)).unwrap();
    }
    (s.into_flash(), plans)
}

#[test]
fn every_slot_takes_a_longest_plan_through_two_rounds_of_the_flash() {
    // Enough replacements to write the whole range twice over.
    let (flash, plans) = full_bank(2 * BANK_PAGES * PAGE_SIZE / 3_000);
    assert!(flash.stats().erases >= BANK_PAGES as u64, "the map wrapped: {}", flash.stats());
    let mut s = PlanStore::new(flash.revive(), range(BANK_PAGES));
    let (listed, free) = list_all(&mut s).unwrap();
    assert_eq!(listed.len(), PLAN_SLOTS as usize);
    for (slot, p) in plans.iter().enumerate() {
        assert_eq!(load(&mut s, PlanRef::Slot(slot as u8)).as_ref(), Ok(p));
    }
    let plan_bytes = listed.iter().map(|p| p.bytes).max().unwrap();
    let empty = block_on(PlanStore::new(MockFlash::new(BANK_PAGES), range(BANK_PAGES)).list(0))
        .unwrap()
        .free_bytes;
    std::println!(
        "capacity: {PLAN_SLOTS} slots of longest plans, {plan_bytes} B each; {free} B free with \
         all of them stored; free_bytes of an empty bank ({empty} B) holds {} such plans",
        empty / plan_bytes,
    );
    // (119 088 B when the store began to keep its reserve: 34 more such plans.)
    assert!(free > 100 * 1024, "{free} B free");
}

/// Some of what [`costs`] measured.
struct Costs {
    warm_upload: FlashStats,
    warm_load: FlashStats,
}

/// Prints the cost of each request on a full, wrapped bank with cache `C`.
fn costs<C: CacheImpl<u16>>(
    label: &str,
    flash: &MockFlash,
    plans: &[Plan],
    cache: fn() -> C,
) -> Costs {
    let mut s = bank_store(flash.revive(), cache);
    let (listed, open) = cost(&mut s, |s| list_all(s).unwrap());
    assert_eq!(listed.0.len(), PLAN_SLOTS as usize);
    let (_, list) = cost(&mut s, |s| list_all(s).unwrap());
    assert_eq!(list.reads + list.mutations(), 0, "listing reads no flash");
    let (_, cold) = cost(&mut s, |s| load(s, PlanRef::Slot(0)).unwrap());
    let (_, warm) = cost(&mut s, |s| load(s, PlanRef::Slot(0)).unwrap());
    let (after_boot_mean, after_boot_worst) = replacements(&mut s, plans, 0, 24);
    // A full round of the flash later, garbage collection has met (and cached) every key.
    replacements(&mut s, plans, 24, 160);
    let (warm_mean, warm_worst) = replacements(&mut s, plans, 184, 24);
    std::println!("--- {label}, full wrapped bank ({PLAN_SLOTS} slots of 256-step plans)");
    std::println!("open (scan + sweep):           {open}");
    std::println!("list 65 plans (9 pages):       {list}");
    std::println!("load 256 steps, first:         {cold}");
    std::println!("load 256 steps, again:         {warm}");
    std::println!(
        "upload+commit, after boot:     mean {after_boot_mean}; worst {after_boot_worst}"
    );
    std::println!("upload+commit, a round later:  mean {warm_mean}; worst {warm_worst}");
    Costs { warm_upload: warm_worst, warm_load: warm }
}

/// Replaces `n` plans (longest ones, slots spread), from the `k0`th replacement on; the mean and
/// the worst (most reads) flash operations of one upload with its commit.
fn replacements<C: CacheImpl<u16>>(
    s: &mut PlanStore<MockFlash, C>,
    plans: &[Plan],
    k0: usize,
    n: usize,
) -> (FlashStats, FlashStats) {
    let (mut worst, mut sum) = (FlashStats::default(), FlashStats::default());
    for k in k0..k0 + n {
        let slot = (7 * k) % PLAN_SLOTS as usize;
        let p = longest_plan(&plans[slot].name, 5000 + k as u32);
        let (_, c) = cost(s, |s| upload(s, &p, Some(slot as u8)).unwrap());
        if c.reads > worst.reads {
            worst = c;
        }
        sum = FlashStats {
            reads: sum.reads + c.reads,
            bytes_read: sum.bytes_read + c.bytes_read,
            writes: sum.writes + c.writes,
            bytes_written: sum.bytes_written + c.bytes_written,
            erases: sum.erases + c.erases,
            busy_us: sum.busy_us + c.busy_us,
        };
    }
    let n = n as u64;
    let mean = FlashStats {
        reads: sum.reads / n,
        bytes_read: sum.bytes_read / n,
        writes: sum.writes / n,
        bytes_written: sum.bytes_written / n,
        erases: sum.erases.div_ceil(n),
        busy_us: sum.busy_us / n,
    };
    (mean, worst)
}

#[test]
fn flash_operations_per_request() {
    // An empty bank: the first upload.
    let mut s = store(BANK_PAGES);
    let (_, open) = cost(&mut s, |s| block_on(s.list(0)).unwrap());
    let p = plan("typical", 256, 1);
    let (summary, first) = cost(&mut s, |s| upload(s, &p, None).unwrap());
    std::println!(
        "--- empty bank: open {open}; upload+commit 256 steps ({} B): {first}",
        summary.bytes
    );
    assert_eq!(first.erases, 0);

    let (flash, plans) = full_bank(200);
    let stats = costs("store cache (default)", &flash, &plans, default_cache);
    assert!(stats.warm_upload.reads < 300, "a warm upload reads little: {}", stats.warm_upload);
    assert!(stats.warm_load.reads <= 2 * 8 + 8, "a warm load reads its items: {}", stats.warm_load);
}

fn default_cache() -> super::super::StoreCache {
    use sequential_storage::cache::Uncached;
    use sequential_storage::cache::key_pointers::ArrayKeyPointers;
    use sequential_storage::cache::page_states::ArrayPageStates;
    Cache::new(ArrayPageStates::new(), Uncached, ArrayKeyPointers::new())
}

/// The same with other caches, to see what each part of a cache saves (slow:
/// `cargo test -p chladni-firmware --lib capacity -- --ignored --nocapture`).
#[test]
#[ignore]
fn flash_operations_with_other_caches() {
    use sequential_storage::cache::Uncached;
    use sequential_storage::cache::page_pointers::ArrayPagePointers;
    use sequential_storage::cache::page_states::ArrayPageStates;
    let (flash, plans) = full_bank(200);
    costs("the store's cache and page pointers (2 KiB more)", &flash, &plans, || {
        use sequential_storage::cache::key_pointers::ArrayKeyPointers;
        Cache::new(
            ArrayPageStates::<{ super::super::MAX_PAGES }>::new(),
            ArrayPagePointers::<{ super::super::MAX_PAGES }>::new(),
            ArrayKeyPointers::<u16, { super::super::KEYS }>::new(),
        )
    });
    costs("page states and page pointers, no key cache", &flash, &plans, || {
        Cache::new(
            ArrayPageStates::<{ super::super::MAX_PAGES }>::new(),
            ArrayPagePointers::<{ super::super::MAX_PAGES }>::new(),
            Uncached,
        )
    });
    costs("page states only", &flash, &plans, || {
        Cache::new(ArrayPageStates::<{ super::super::MAX_PAGES }>::new(), Uncached, Uncached)
    });
    costs("uncached", &flash, &plans, Cache::new_uncached);
}
