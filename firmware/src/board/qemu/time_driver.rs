//! embassy-time driver on SysTick, for QEMU where no TIM/LPTIM ticks.
//!
//! SysTick interrupts at 1 kHz (embassy-time is built with `tick-hz-1_000` for this board).
//! The core clock is left at its reset value, MSI 4 MHz, which QEMU's RCC model honours, so
//! the reload is 4000 cycles. QEMU's virtual clock follows the host clock, so time slips under
//! load: tests count samples, not milliseconds.
//!
//! The same interrupt also counts down the simulated watchdog ([`super::watchdog::on_tick`]).
//!
//! [`wake_host_loop`] restarts SysTick's count on purpose, to make QEMU service its host
//! sockets now (see there); the cycles the interrupted period had run are carried over, so the
//! clock keeps its rate.

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

/// Core clock cycles per embassy-time tick (one full SysTick period).
const CYCLES_PER_TICK: u32 = CORE_CLOCK_HZ / TICK_HZ;

struct SysTickDriver {
    ticks: Mutex<Cell<u64>>,
    /// Cycles of a tick that [`wake_host_loop`] cut short and that no interrupt counted.
    carry: Mutex<Cell<u32>>,
    next_alarm: Mutex<Cell<u64>>,
    queue: Mutex<RefCell<Queue>>,
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    ticks: Mutex::new(Cell::new(0)),
    carry: Mutex::new(Cell::new(0)),
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
        critical_section::with(|cs| self.advance(cs, CYCLES_PER_TICK));
    }

    /// Counts `cycles` more core cycles: whole ticks advance the clock (and the alarm).
    /// Returns the whole ticks counted.
    fn advance(&self, cs: critical_section::CriticalSection<'_>, cycles: u32) -> u32 {
        let carry = self.carry.borrow(cs);
        let total = carry.get() + cycles;
        carry.set(total % CYCLES_PER_TICK);
        let whole = total / CYCLES_PER_TICK;
        if whole == 0 {
            return 0;
        }
        let now = self.ticks.borrow(cs).get() + u64::from(whole);
        self.ticks.borrow(cs).set(now);
        if now >= self.next_alarm.borrow(cs).get() {
            let next = self.queue.borrow(cs).borrow_mut().next_expiration(now);
            self.next_alarm.borrow(cs).set(next);
        }
        whole
    }
}

/// Makes QEMU's main loop run once now, so it hands the USART the next byte from the socket.
///
/// Why: QEMU's STM32L4x5 USART model takes one byte at a time (while RXNE is clear) and does
/// not tell its chardev when the guest reads RDR, so QEMU polls the link's socket again only
/// when its main loop wakes for another reason, which is SysTick's timer: one byte per
/// millisecond. Writing SYST_CVR re-arms that timer, and re-arming QEMU's earliest timer
/// wakes the main loop, which then finds RXNE clear and reads the next byte at once.
///
/// The write restarts the SysTick period; the cycles it had already run are carried into the
/// clock, so time keeps its rate (it loses only the few cycles between the read and the write),
/// and the simulated watchdog counts the ticks completed here as it counts interrupts.
pub fn wake_host_loop() {
    let ticks = critical_section::with(|cs| {
        // The reload `start` set (not read back: each register access costs QEMU an exit).
        let reload = CYCLES_PER_TICK - 1;
        let current = SYST::get_current();
        // SAFETY: a write to SYST_CVR only restarts the count (any value clears it); this
        // critical section keeps the SysTick interrupt from running in between.
        unsafe { (*SYST::PTR).cvr.write(0) };
        // A wrap already pended is counted by its interrupt; a period that ran out without
        // pending (QEMU had not fired its timer yet) is cancelled by the write and counted here.
        // Cycles since the last wrap: the reload edge, then `reload - current` decrements.
        let elapsed = match current {
            0 if cortex_m::peripheral::SCB::is_pendst_pending() => 0,
            0 => reload + 1,
            _ => reload - current + 1,
        };
        DRIVER.advance(cs, elapsed)
    });
    for _ in 0..ticks {
        super::watchdog::on_tick();
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
        // Cycles of a period that `wake_host_loop` cut short count too, or the clock would
        // step back by them at every wake.
        let carry = DRIVER.carry.borrow(cs).get();
        let in_tick = u64::from(carry) + u64::from(RELOAD.saturating_sub(cvr));
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
    syst.set_reload(CYCLES_PER_TICK - 1);
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
