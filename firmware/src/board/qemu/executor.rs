//! A thread-mode executor that sleeps with WFI.
//!
//! embassy's Cortex-M thread executor sleeps with WFE, which QEMU implements as a yield: the
//! vCPU spins at 100 % of a host core and holds QEMU's big lock, so the link's socket is
//! serviced late (≈ 50 ms per ping). WFI halts the vCPU until an interrupt, as on silicon.
//!
//! Race-free sleep: the "work pending" flag is tested with interrupts masked, and WFI still
//! wakes on an interrupt that becomes pending while masked.

use core::sync::atomic::{AtomicBool, Ordering};

use embassy_executor::{Spawner, raw};
use static_cell::StaticCell;

static WORK_PENDING: AtomicBool = AtomicBool::new(true);

#[unsafe(export_name = "__pender")]
fn pender(_context: *mut ()) {
    WORK_PENDING.store(true, Ordering::Release);
}

/// Runs the executor forever; `init` spawns the first tasks.
pub fn run(init: impl FnOnce(Spawner)) -> ! {
    run_until(init, || false);
    unreachable!("run_until returned although `done` never holds")
}

/// Runs the executor until `done()` holds after a poll (on-target tests use it).
/// Only one executor may ever be started: a second call panics.
pub fn run_until(init: impl FnOnce(Spawner), done: impl Fn() -> bool) {
    static EXECUTOR: StaticCell<raw::Executor> = StaticCell::new();
    let executor: &'static raw::Executor = EXECUTOR.init(raw::Executor::new(core::ptr::null_mut()));
    init(executor.spawner());
    while !done() {
        if WORK_PENDING.swap(false, Ordering::AcqRel) {
            // SAFETY: `poll` is only ever called from this loop, never re-entrantly.
            unsafe { executor.poll() };
        }
        cortex_m::interrupt::free(|_| {
            if !WORK_PENDING.load(Ordering::Acquire) {
                cortex_m::asm::wfi();
            }
        });
    }
}
