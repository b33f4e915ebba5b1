//! Power cuts: an upload replacing a plan, or a delete, is cut after every possible write or
//! erase (and, in the property tests, cut again while the store recovers). The flash is then
//! booted again and must open, hold in the slot either the old plan or the new one exactly
//! (never a mix, never a read error), keep every other plan intact, and take new uploads.
//!
//! Small flash ranges (16 pages) filled with churn make sequential-storage close pages, move
//! items and erase pages during the operation, so cuts land in its garbage collection too.

use std::vec::Vec;

use chladni_shared::icd::link::Refusal;
use chladni_shared::icd::plan::Plan;
use chladni_shared::icd::store::{PlanRef, SCRATCH_SLOT, StoreError};
use embassy_futures::block_on;
use proptest::prelude::*;

use super::*;

/// What the cut operation does.
#[derive(Debug, Clone)]
enum Op {
    /// Uploads `plan` into `slot` (begin, chunks, commit).
    Replace { slot: u8, plan: Plan },
    /// Deletes the plan in `slot`.
    Delete { slot: u8 },
}

/// A flash holding plans, and an operation on one of them.
struct Case {
    pages: usize,
    /// The flash before the operation.
    flash: MockFlash,
    /// Every plan stored before the operation, by slot.
    plans: Vec<(u8, Plan)>,
    op: Op,
}

/// What a slot held after a cut.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Held {
    Old,
    New,
}

impl Case {
    /// Stores `plans`, then replaces a churn plan in slot 10 `churn` times (moving the map's
    /// write position round the range and leaving garbage to collect).
    fn new(pages: usize, plans: Vec<(u8, Plan)>, churn: u32, op: Op) -> Self {
        let mut s = store(pages);
        for (slot, p) in &plans {
            upload(&mut s, p, Some(*slot)).unwrap();
        }
        let mut case = Self { pages, flash: MockFlash::new(0), plans, op };
        for k in 0..churn {
            case.churn(&mut s, k);
        }
        case.flash = s.into_flash().revive();
        case
    }

    /// Like [`Case::new`], with as much churn as it takes for the operation to erase a page
    /// (sequential-storage collecting garbage while it runs).
    fn collecting(pages: usize, plans: Vec<(u8, Plan)>, op: Op) -> Self {
        let mut case = Self::new(pages, plans, 0, op);
        for k in 0..500 {
            if case.stats().erases > 0 {
                return case;
            }
            let mut s = PlanStore::new(case.flash.clone(), range(pages));
            case.churn(&mut s, k);
            case.flash = s.into_flash().revive();
        }
        panic!("the operation never collects garbage");
    }

    /// Replaces the churn plan in slot 10 (the `k`th time).
    fn churn(&mut self, s: &mut PlanStore<MockFlash>, k: u32) {
        let p = plan("churn", 1 + (k as usize * 97) % 256, 1000 + k);
        upload(s, &p, Some(10)).unwrap();
        self.plans.retain(|(slot, _)| *slot != 10);
        self.plans.push((10, p));
    }

    fn old(&self, slot: u8) -> Option<&Plan> {
        self.plans.iter().find(|(s, _)| *s == slot).map(|(_, p)| p)
    }

    /// Runs the operation on `flash` until it finishes or fails.
    fn run(&self, flash: MockFlash) -> MockFlash {
        let mut s = PlanStore::new(flash, range(self.pages));
        let _ = match &self.op {
            Op::Replace { slot, plan } => upload(&mut s, plan, Some(*slot)).map(drop),
            Op::Delete { slot } => block_on(s.delete(&PlanRef::Slot(*slot))).map(drop),
        };
        s.into_flash()
    }

    /// Writes and erases the operation does when nothing is cut.
    fn mutations(&self) -> u64 {
        self.stats().mutations()
    }

    /// What the operation does to the flash when nothing is cut.
    fn stats(&self) -> super::super::mock_flash::FlashStats {
        let flash = self.run(self.flash.clone());
        assert!(!flash.is_off());
        flash.stats()
    }

    /// Runs the operation with a power cut after `cut` writes or erases (`seed`: how much of
    /// the cut one lands), boots again, checks the store, and says what the slot holds.
    fn cut(&self, cut: u64, seed: u32) -> Held {
        let mut flash = self.flash.clone();
        flash.cut_after(cut, seed);
        self.check(self.run(flash).revive())
    }

    /// Boots `flash` and checks it: it opens, the operation's slot holds the old or the new
    /// plan, every other plan is whole, the list agrees, and the store takes a new upload.
    fn check(&self, flash: MockFlash) -> Held {
        let mut s = PlanStore::new(flash, range(self.pages));
        let (listed, _) = list_all(&mut s).expect("the store opens after a cut");
        let slot = match &self.op {
            Op::Replace { slot, .. } | Op::Delete { slot } => *slot,
        };
        for (other, p) in self.plans.iter().filter(|(s, _)| *s != slot) {
            assert_eq!(load(&mut s, PlanRef::Slot(*other)).as_ref(), Ok(p), "slot {other}");
        }
        let got = load(&mut s, PlanRef::Slot(slot));
        let held = match (&self.op, got) {
            (_, Ok(p)) if Some(&p) == self.old(slot) => Held::Old,
            (Op::Replace { plan, .. }, Ok(p)) if p == *plan => Held::New,
            (Op::Replace { .. }, Err(Refusal::Store(StoreError::NotFound(_))))
                if self.old(slot).is_none() =>
            {
                Held::Old
            }
            (Op::Delete { .. }, Err(Refusal::Store(StoreError::NotFound(_)))) => Held::New,
            (_, other) => panic!("slot {slot} holds neither plan: {other:?}"),
        };
        let summary = listed.iter().find(|p| p.slot == slot);
        let expect = match held {
            Held::Old => self.old(slot),
            Held::New => match &self.op {
                Op::Replace { plan, .. } => Some(plan),
                Op::Delete { .. } => None,
            },
        };
        assert_eq!(summary.map(|p| p.crc), expect.map(plan_crc), "the list agrees");
        self.still_works(s);
        held
    }

    /// The store takes a new plan and keeps everything.
    fn still_works(&self, mut s: PlanStore<MockFlash>) {
        let probe = plan("probe", 40, 77);
        upload(&mut s, &probe, Some(SCRATCH_SLOT)).expect("an upload after the cut");
        let mut s = reopen(s, self.pages);
        assert_eq!(load(&mut s, PlanRef::Slot(SCRATCH_SLOT)).unwrap(), probe);
    }

    /// Cuts after every write and erase, with `seeds` for the cut operation; the slot must
    /// switch from old to new once and hold the new plan when nothing was cut.
    fn every_cut(&self, seeds: &[u32]) {
        let total = self.mutations();
        std::println!("{total} writes and erases ({} erases), each cut", self.stats().erases);
        for &seed in seeds {
            let held: Vec<Held> = (0..=total).map(|cut| self.cut(cut, seed)).collect();
            assert_eq!(held[total as usize], Held::New, "no cut: the operation happened");
            let switch = held.iter().position(|h| *h == Held::New).unwrap();
            assert!(
                held[switch..].iter().all(|h| *h == Held::New),
                "seed {seed}: old after new in {held:?}"
            );
        }
    }
}

const SEEDS: [u32; 3] = [0, 1, u32::MAX];

fn others() -> Vec<(u8, Plan)> {
    std::vec![(0, longest_plan("long", 1)), (3, plan("mid", 100, 2)), (20, plan("tiny", 1, 3))]
}

#[test]
fn replace_a_long_plan_during_garbage_collection() {
    let mut plans = others();
    plans.push((5, longest_plan("target", 4)));
    let new = plan("target", 256, 5);
    let case = Case::collecting(16, plans, Op::Replace { slot: 5, plan: new });
    case.every_cut(&SEEDS);
}

#[test]
fn replace_a_short_plan_with_a_long_one() {
    let mut plans = others();
    plans.push((5, plan("target", 3, 4)));
    let case = Case::collecting(16, plans, Op::Replace { slot: 5, plan: longest_plan("new", 5) });
    case.every_cut(&SEEDS);
}

#[test]
fn upload_into_an_empty_slot_on_fresh_flash() {
    let case = Case::new(16, others(), 0, Op::Replace { slot: 7, plan: plan("fresh", 70, 6) });
    case.every_cut(&SEEDS);
}

#[test]
fn delete_a_long_plan_during_garbage_collection() {
    let mut plans = others();
    plans.push((5, longest_plan("target", 4)));
    let case = Case::collecting(16, plans, Op::Delete { slot: 5 });
    case.every_cut(&SEEDS);
}

#[test]
fn delete_on_fresh_flash() {
    let mut plans = others();
    plans.push((SCRATCH_SLOT, plan("scratch", 33, 8)));
    let case = Case::new(16, plans, 0, Op::Delete { slot: SCRATCH_SLOT });
    case.every_cut(&SEEDS);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Random plans and churn, one cut anywhere in the operation, then a second cut anywhere
    /// in the recovery (opening the store and running the operation again).
    #[test]
    fn cut_then_cut_again_while_recovering(
        old_steps in 1usize..=256,
        new_steps in 1usize..=256,
        churn in 0u32..40,
        delete in any::<bool>(),
        cut in any::<u64>(),
        seed in any::<u32>(),
        cut2 in any::<u64>(),
        seed2 in any::<u32>(),
    ) {
        let mut plans = std::vec![(3, plan("mid", 100, 2)), (20, plan("tiny", 1, 3))];
        plans.push((5, plan("target", old_steps, seed)));
        let op = if delete {
            Op::Delete { slot: 5 }
        } else {
            Op::Replace { slot: 5, plan: plan("target", new_steps, seed ^ 1) }
        };
        let case = Case::new(10, plans, churn, op);
        let mut flash = case.flash.clone();
        flash.cut_after(cut % (case.mutations() + 1), seed);
        let mut flash = case.run(flash).revive();
        // The recovery: open, list, run the operation again; its writes counted for the cut.
        let recovery = case.run(flash.clone()).stats().mutations();
        flash.cut_after(cut2 % (recovery + 1), seed2);
        let flash = case.run(flash).revive();
        case.check(flash);
    }
}
