//! The QEMU board's two executors: a thread-mode executor that sleeps with WFI, and the drive's
//! interrupt executor above it.
//!
//! embassy's Cortex-M thread executor sleeps with WFE, which QEMU implements as a yield: the
//! vCPU spins at 100 % of a host core and holds QEMU's big lock, so the link's socket is
//! serviced late (≈ 50 ms per ping). WFI halts the vCPU until an interrupt, as on silicon.
//!
//! Race-free sleep: the "work pending" flag is tested with interrupts masked, and WFI still
//! wakes on an interrupt that becomes pending while masked.
//!
//! The drive runs on an interrupt executor polled from [`DRIVE_IRQ`] (UART4's vector: QEMU
//! models a UART4 but nothing here enables it, so only the executor pends it), at
//! [`DRIVE_PRIORITY`]: above thread mode (link, store, sense, watchdog), below SysTick and
//! USART1 (priority 0), whose handlers are short. It is embassy's `InterruptExecutor` in
//! substance; this board needs its own because embassy's comes with a `__pender` that would
//! clash with the WFI executor's, so one pender here serves both: a null context is the thread
//! executor, any other is the drive's interrupt.

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m::interrupt::InterruptNumber;
use cortex_m::peripheral::NVIC;
use embassy_executor::{SendSpawner, Spawner, raw};
use static_cell::StaticCell;
use stm32_metapac::{Interrupt, interrupt};

static WORK_PENDING: AtomicBool = AtomicBool::new(true);

/// The interrupt the drive's executor is polled from.
pub const DRIVE_IRQ: Interrupt = Interrupt::UART4;
/// Its NVIC priority (STM32L4: 4 priority bits, the high nibble; 0 is the most urgent).
pub const DRIVE_PRIORITY: u8 = 0xe0;

#[unsafe(export_name = "__pender")]
fn pender(context: *mut ()) {
    if context.is_null() {
        WORK_PENDING.store(true, Ordering::Release);
    } else {
        // The only other executor is the drive's, whose context is its IRQ number.
        NVIC::pend(DRIVE_IRQ);
    }
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

/// The drive's executor, written once by [`start_drive_executor`].
struct DriveExecutor {
    started: AtomicBool,
    executor: UnsafeCell<MaybeUninit<raw::Executor>>,
}

// SAFETY: `executor` is written once, before `started` is set and the interrupt unmasked, and
// afterwards only read (polled from the one interrupt handler).
unsafe impl Sync for DriveExecutor {}

static DRIVE_EXECUTOR: DriveExecutor = DriveExecutor {
    started: AtomicBool::new(false),
    executor: UnsafeCell::new(MaybeUninit::uninit()),
};

/// Starts the drive's interrupt executor (at [`DRIVE_PRIORITY`]) and returns its spawner.
/// Call once: a second call panics.
pub fn start_drive_executor() -> SendSpawner {
    assert!(!DRIVE_EXECUTOR.started.load(Ordering::Acquire), "drive executor started twice");
    let context = DRIVE_IRQ.number() as usize as *mut ();
    // SAFETY: not started yet, so nothing else reads the cell (the interrupt is masked).
    let executor = unsafe {
        (*DRIVE_EXECUTOR.executor.get()).write(raw::Executor::new(context));
        (*DRIVE_EXECUTOR.executor.get()).assume_init_ref()
    };
    DRIVE_EXECUTOR.started.store(true, Ordering::Release);
    // SAFETY: the priority is set before the interrupt is unmasked, and never again; the
    // handler only polls the executor, which was written above.
    unsafe {
        let mut core = cortex_m::Peripherals::steal();
        core.NVIC.set_priority(DRIVE_IRQ, DRIVE_PRIORITY);
        NVIC::unmask(DRIVE_IRQ);
    }
    executor.spawner().make_send()
}

#[interrupt]
fn UART4() {
    if DRIVE_EXECUTOR.started.load(Ordering::Acquire) {
        // SAFETY: started, so written; polled only from this handler, which does not nest.
        unsafe { (*DRIVE_EXECUTOR.executor.get()).assume_init_ref().poll() };
    }
}
