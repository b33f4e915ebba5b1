//! USART1 for QEMU's STM32L4x5 USART model.
//!
//! Why not embassy-stm32's driver: QEMU's USART accepts only 32-bit register accesses (the
//! embassy driver writes TDR as a byte and faults), writing status bits to ICR also clears TXE,
//! and IDLE is never raised. This driver uses 32-bit accesses only and never touches ICR.
//!
//! RX is interrupt-driven into a pipe. When the pipe is full the interrupt masks itself and
//! leaves the byte in RDR; QEMU then holds further input back (it only delivers while RXNE is
//! clear), so no byte is ever lost, and the next read re-enables the interrupt. TX writes a
//! byte whenever TXE is set, which QEMU does as soon as its chardev has taken the previous one.
//! When the host does not read the socket the chardev takes nothing and TXE stays clear until
//! it does; `write` then awaits the TXE interrupt (TXEIE, masked again by the handler) instead
//! of spinning, so the sense and watchdog tasks run meanwhile, and the link's bounded write
//! (`app::link`) can give up on the frame.
//!
//! Speed: QEMU hands the model one byte per pass of its main loop and is not told when RDR is
//! read, so without help the link gets one byte per SysTick period (1 kB/s). After each read
//! the handler wakes QEMU's main loop ([`super::time_driver::wake_host_loop`]), so the next
//! byte comes as soon as the core has taken this one.

use core::sync::atomic::{AtomicBool, Ordering};

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_sync::waitqueue::AtomicWaker;
use stm32_metapac::{self as pac, interrupt};

const RX_CAPACITY: usize = 512;
static RX: Pipe<CriticalSectionRawMutex, RX_CAPACITY> = Pipe::new();
/// The handler masked itself (back-pressure): `read` must unmask it. Kept so that a read in
/// the common case touches no USART register (each access is an exit from QEMU's translated
/// code, and `read` runs once per byte in a burst).
static MASKED: AtomicBool = AtomicBool::new(false);
/// The writer waiting for TXE (woken by the handler, which masks TXEIE again).
static TX_WAKER: AtomicWaker = AtomicWaker::new();

/// The USART1 link (PB6 TX, PB7 RX on the board; a host chardev in QEMU).
pub struct Usart1 {
    _owned: (),
}

impl Usart1 {
    /// Clocks and configures USART1 at 115200 8N1 with the RX interrupt on.
    pub(super) fn new() -> Self {
        pac::RCC.apb2enr().modify(|w| w.set_usart1en(true));
        pac::RCC.ahb2enr().modify(|w| w.set_gpioben(true));
        // PB6/PB7 to alternate function 7 (USART1), as on the real board.
        let gpiob = pac::GPIOB;
        for pin in [6, 7] {
            gpiob.moder().modify(|w| w.set_moder(pin, pac::gpio::vals::Moder::ALTERNATE));
            gpiob.afr(0).modify(|w| w.set_afr(pin, 7));
        }
        let usart = pac::USART1;
        usart.brr().write(|w| w.set_brr((4_000_000u32 / 115_200) as u16));
        usart.cr1().write(|w| {
            w.set_ue(true);
            w.set_te(true);
            w.set_re(true);
            w.set_rxneie(true);
        });
        // SAFETY: the handler below only touches USART1 registers and the RX pipe.
        unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1) };
        Self { _owned: () }
    }
}

#[interrupt]
fn USART1() {
    let usart = pac::USART1;
    let isr = usart.isr().read();
    if isr.txe() && usart.cr1().read().txeie() {
        // TXE stays set until the next byte is written: mask it, or it fires again at once.
        usart.cr1().modify(|w| w.set_txeie(false));
        TX_WAKER.wake();
    }
    if isr.rxne() {
        if RX.is_full() {
            // Back-pressure: leave the byte in RDR; `read` unmasks us once there is room.
            usart.cr1().modify(|w| w.set_rxneie(false));
            MASKED.store(true, Ordering::Release);
        } else {
            let byte = usart.rdr().read().dr() as u8;
            super::time_driver::wake_host_loop();
            let _ = RX.try_write(&[byte]);
        }
    }
}

/// Until TXE is set: registers the waker, then unmasks TXEIE (the handler masks it and wakes
/// us); cancel-safe (a dropped wait leaves at most one spurious interrupt).
async fn txe() {
    core::future::poll_fn(|cx| {
        TX_WAKER.register(cx.waker());
        if pac::USART1.isr().read().txe() {
            return core::task::Poll::Ready(());
        }
        cortex_m::interrupt::free(|_| pac::USART1.cr1().modify(|w| w.set_txeie(true)));
        core::task::Poll::Pending
    })
    .await
}

/// Never fails: QEMU's USART has no line errors.
impl embedded_io_async::ErrorType for Usart1 {
    type Error = core::convert::Infallible;
}

impl embedded_io_async::Read for Usart1 {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let n = RX.read(buf).await;
        if MASKED.swap(false, Ordering::AcqRel) {
            // CR1 is shared with the handler (TXEIE): modified with the handler held off.
            cortex_m::interrupt::free(|_| pac::USART1.cr1().modify(|w| w.set_rxneie(true)));
            // The byte the handler left in RDR when the pipe was full is still there: raise
            // the interrupt for it by hand rather than count on the USART model raising it
            // again when RXNEIE is set while RXNE already is.
            if pac::USART1.isr().read().rxne() {
                cortex_m::peripheral::NVIC::pend(pac::Interrupt::USART1);
            }
        }
        Ok(n)
    }
}

impl embedded_io_async::Write for Usart1 {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        let usart = pac::USART1;
        for &byte in buf {
            if !usart.isr().read().txe() {
                txe().await;
            }
            usart.tdr().write(|w| w.set_dr(byte as u16));
        }
        Ok(buf.len())
    }

    /// Bytes leave as they are written: nothing is buffered.
    async fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}
