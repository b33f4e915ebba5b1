//! Host tests of the plan store, on the mock flash: the request rules ([`rules`]), power cuts
//! at every write and erase ([`power_cut`]), and capacity and flash operation counts
//! ([`capacity`]).

mod capacity;
mod format;
mod power_cut;
mod rules;

use std::vec::Vec;

use chladni_shared::icd::link::Refusal;
use chladni_shared::icd::plan::{DeviceLimits, Plan, Step};
use chladni_shared::icd::store::{
    CHUNK_STEPS, PlanRef, PlanSummary, UploadBegin, UploadChunk, plan_crc,
};
use embassy_futures::block_on;

use super::PlanStore;
use super::mock_flash::{MockFlash, PAGE_SIZE};
use chladni_shared::icd::store::SCRATCH_SLOT;

const LIMITS: DeviceLimits = DeviceLimits::DEFAULT;

/// A store over a fresh mock flash of `pages` pages.
fn store(pages: usize) -> PlanStore<MockFlash> {
    PlanStore::new(MockFlash::new(pages), range(pages))
}

fn range(pages: usize) -> core::ops::Range<u32> {
    0..(pages * PAGE_SIZE) as u32
}

/// The same flash after a reboot (power on, nothing armed).
fn reopen(store: PlanStore<MockFlash>, pages: usize) -> PlanStore<MockFlash> {
    PlanStore::new(store.into_flash().revive(), range(pages))
}

/// Step `i` of a plan made from `seed`: valid under the default limits (also in a plan of 256
/// steps repeated 3 times), and different for every seed.
fn step(i: usize, seed: u32) -> Step {
    let x = (i as u32).wrapping_mul(2_654_435_761) ^ seed.wrapping_mul(40_503);
    Step {
        freq_mhz: 1_000 + x % 1_999_000,
        level: chladni_shared::icd::plan::Level::Drive((x >> 7) as u16 % 32_768),
        duration_ms: 1 + x % 4_000,
        ramp_ms: (x % 7).min(1 + x % 4_000),
    }
}

/// A plan of `steps` steps made from `seed`.
fn plan(name: &str, steps: usize, seed: u32) -> Plan {
    Plan {
        name: name.try_into().unwrap(),
        repeat: 1 + (seed % 3) as u16,
        steps: (0..steps).map(|i| step(i, seed)).collect(),
    }
}

/// A 256-step plan whose steps take the longest encoding the default limits allow (about
/// 3 KiB): 219 steps of 16 384 ms with 16 384 ms ramps and 37 of 128 ms, all at 1999 Hz and
/// full amplitude (3-byte varints), within the one-hour limit.
fn longest_plan(name: &str, seed: u32) -> Plan {
    let step = |i: usize| {
        let long = i < 219;
        let ms = if long { 16_384 } else { 128 };
        Step {
            freq_mhz: 1_999_000 - (i as u32 + seed) % 500,
            level: chladni_shared::icd::plan::Level::Drive(32_767 - (seed % 16) as u16),
            duration_ms: ms,
            ramp_ms: ms,
        }
    };
    let p = Plan { name: name.try_into().unwrap(), repeat: 1, steps: (0..256).map(step).collect() };
    assert_eq!(p.validate(&LIMITS), Ok(()));
    p
}

fn begin_of(plan: &Plan, slot: Option<u8>) -> UploadBegin {
    UploadBegin::of(plan, slot)
}

fn chunks_of(plan: &Plan) -> Vec<UploadChunk> {
    plan.steps
        .chunks(CHUNK_STEPS)
        .enumerate()
        .map(|(i, s)| UploadChunk { index: i as u16, steps: heapless::Vec::from_slice(s).unwrap() })
        .collect()
}

/// Begin, every chunk, commit.
fn upload<C: sequential_storage::cache::CacheImpl<u16>>(
    store: &mut PlanStore<MockFlash, C>,
    plan: &Plan,
    slot: Option<u8>,
) -> Result<PlanSummary, Refusal> {
    block_on(async {
        store.begin(begin_of(plan, slot), &LIMITS).await?;
        for chunk in chunks_of(plan) {
            store.chunk(chunk, &LIMITS).await?;
        }
        store.commit(&LIMITS).await
    })
}

fn load<C: sequential_storage::cache::CacheImpl<u16>>(
    store: &mut PlanStore<MockFlash, C>,
    plan: PlanRef,
) -> Result<Plan, Refusal> {
    let mut out = Plan { name: Default::default(), repeat: 0, steps: heapless::Vec::new() };
    block_on(store.load(&plan, &mut out)).map(|_| out)
}

fn slot_of(plan: &Plan) -> PlanRef {
    PlanRef::Name(plan.name.clone())
}

/// Every plan listed, following the pages.
fn list_all<C: sequential_storage::cache::CacheImpl<u16>>(
    store: &mut PlanStore<MockFlash, C>,
) -> Result<(Vec<PlanSummary>, u32), Refusal> {
    let (mut all, mut from) = (Vec::new(), 0);
    loop {
        let page = block_on(store.list(from))?;
        all.extend(page.plans.iter().cloned());
        match page.next {
            Some(next) => from = next,
            None => return Ok((all, page.free_bytes)),
        }
    }
}
