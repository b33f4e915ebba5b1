//! embassy-time driver on SysTick, for QEMU where no TIM/LPTIM ticks.
//!
//! SysTick interrupts at 1 kHz (embassy-time is built with `tick-hz-1_000` for this board).
//! The core clock is left at its reset value, MSI 4 MHz, which QEMU's RCC model honours, so
//! the reload is 4000 cycles. QEMU's virtual clock follows the host clock, so time slips under
//! load: tests count samples, not milliseconds.
//!
//! The same interrupt also counts down the simulated watchdog ([`super::watchdog::on_tick`]).

use core::cell::{Cell, RefCell};
use core::task::Waker;

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use critical_section::Mutex;
use embassy_time_driver::Driver;
use embassy_time_queue_utils::Queue;

/// Core clock after reset (MSI range 6).
const CORE_CLOCK_HZ: u32 = 4_000_000;
/// embassy-time ticks per second (the `tick-hz-1_000` feature).
const TICK_HZ: u32 = 1_000;

struct SysTickDriver {
    ticks: Mutex<Cell<u64>>,
    next_alarm: Mutex<Cell<u64>>,
    queue: Mutex<RefCell<Queue>>,
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    ticks: Mutex::new(Cell::new(0)),
    next_alarm: Mutex::new(Cell::new(u64::MAX)),
    queue: Mutex::new(RefCell::new(Queue::new())),
});

impl Driver for SysTickDriver {
    fn now(&self) -> u64 {
        critical_section::with(|cs| self.ticks.borrow(cs).get())
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            let mut queue = self.queue.borrow(cs).borrow_mut();
            if queue.schedule_wake(at, waker) {
                let now = self.ticks.borrow(cs).get();
                self.next_alarm.borrow(cs).set(queue.next_expiration(now));
            }
        })
    }
}

impl SysTickDriver {
    fn on_tick(&self) {
        critical_section::with(|cs| {
            let now = self.ticks.borrow(cs).get() + 1;
            self.ticks.borrow(cs).set(now);
            if now >= self.next_alarm.borrow(cs).get() {
                let next = self.queue.borrow(cs).borrow_mut().next_expiration(now);
                self.next_alarm.borrow(cs).set(next);
            }
        })
    }
}

/// Time since boot in ns, to a SysTick count (250 ns at 4 MHz): the ticks plus SysTick's
/// current count. Under QEMU's `-icount shift=0` (1 ns per instruction) it counts
/// instructions, which is what the drive's benchmark measures with.
pub fn now_ns() -> u64 {
    const NS_PER_CYCLE: u64 = 1_000_000_000 / CORE_CLOCK_HZ as u64;
    const RELOAD: u32 = CORE_CLOCK_HZ / TICK_HZ - 1;
    critical_section::with(|cs| {
        // SAFETY: reads of SysTick's current value and of SCB's ICSR only.
        let (syst, scb) = unsafe { (&*SYST::PTR, &*cortex_m::peripheral::SCB::PTR) };
        let mut ticks = DRIVER.ticks.borrow(cs).get();
        let mut cvr = syst.cvr.read() & 0x00ff_ffff;
        // The counter wrapped but the handler has not run (interrupts are off): one more tick,
        // and the count read again (it may have been read just before the wrap).
        if scb.icsr.read() & (1 << 26) != 0 {
            ticks += 1;
            cvr = syst.cvr.read() & 0x00ff_ffff;
        }
        let in_tick = u64::from(RELOAD.saturating_sub(cvr));
        ticks * (1_000_000_000 / TICK_HZ as u64) + in_tick * NS_PER_CYCLE
    })
}

/// [`now_ns`] in µs.
pub fn now_us() -> u64 {
    now_ns() / 1_000
}

/// Starts SysTick; call once, before anything waits on time.
pub fn start(mut syst: SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(CORE_CLOCK_HZ / TICK_HZ - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

#[cortex_m_rt::exception]
fn SysTick() {
    DRIVER.on_tick();
    // The simulated watchdog counts in the same 1 kHz ticks (QEMU has no IWDG).
    super::watchdog::on_tick();
}
