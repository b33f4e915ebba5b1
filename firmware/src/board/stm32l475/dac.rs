//! The drive output: DAC1 channel 1 on PA4, converting on every TIM6 TRGO (update event at the
//! sample rate). DMA1 channel 3 (request 6) moves samples from a circular buffer of two blocks
//! into DHR12R1, one 32-bit word per sample (RM0351 asks for word accesses to the DAC
//! registers; the 12-bit code sits in bits 11:0); its half-transfer and transfer-complete
//! interrupts wake the drive task, which refills the half just played (embassy-stm32's
//! `WritableRingBuffer`, which starts full of the mid-scale codes it was given). If the DMA
//! catches up with the writer (a refill missed its half period) the ring reports an overrun
//! and resets itself: counted as an underrun.
//!
//! **Quiet boot.** embassy-stm32 0.6.0's `DacChannel::new_blocking` resets the DAC (DHR = 0)
//! and enables the channel in one call, with no hook in between: the output would step from
//! a floating pin to 0 V, then to mid-scale when the ring's first code arrives, a click into
//! the amplifier at every reset. So the channel is set up here by register, in an order that
//! never outputs anything but mid-scale: [`enable_at_mid_scale`].

use chladni_shared::drive::dds::DAC_MID;
use chladni_shared::drive::runner::BLOCK_LEN;
use chladni_shared::icd::units::SAMPLE_RATE;
use embassy_stm32::dac;
use embassy_stm32::dma::{self, TransferOptions, WritableRingBuffer};
use embassy_stm32::peripherals;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::{MasterMode, RoundTo, Timer};
use static_cell::StaticCell;
use stm32_metapac as pac;

use super::Irqs;
use crate::app::drive::{SampleOutput, Underrun};
/// DAC1 channel 1 on PA4, triggered by TIM6 TRGO, fed by circular DMA over two blocks.
pub struct DacOutput {
    ring: WritableRingBuffer<'static, u32>,
    // Held so that nothing else takes the DAC or its pin; they are driven by register.
    _dac: embassy_stm32::Peri<'static, peripherals::DAC1>,
    _pin: embassy_stm32::Peri<'static, peripherals::PA4>,
    _timer: Timer<'static, peripherals::TIM6>,
}

impl DacOutput {
    pub(super) fn new(
        dac1: embassy_stm32::Peri<'static, peripherals::DAC1>,
        pa4: embassy_stm32::Peri<'static, peripherals::PA4>,
        dma_ch: embassy_stm32::Peri<'static, peripherals::DMA1_CH3>,
        tim6: embassy_stm32::Peri<'static, peripherals::TIM6>,
    ) -> Self {
        static BUF: StaticCell<[u32; 2 * BLOCK_LEN]> = StaticCell::new();
        let buf = BUF.init([u32::from(DAC_MID); 2 * BLOCK_LEN]);

        let trigger = <embassy_stm32::triggers::TIM6_TRGO as dac::ChannelTrigger<
            peripherals::DAC1,
        >>::signal(&embassy_stm32::triggers::TIM6_TRGO);
        let code = enable_at_mid_scale(trigger);

        let request =
            <peripherals::DMA1_CH3 as dac::Dma<peripherals::DAC1, dac::Ch1>>::request(&dma_ch);
        let channel = dma::Channel::new(dma_ch, Irqs);
        let dhr = pac::DAC1.dhr12r(0).as_ptr() as *mut u32;
        // SAFETY: `dhr` is DAC1's 12-bit right-aligned data register for channel 1, written
        // one word at a time (bits 31:12 are reserved and get 0); `buf` is 'static and owned
        // by the ring from here on.
        let mut ring = unsafe {
            WritableRingBuffer::new(channel, request, dhr, buf, TransferOptions::default())
        };
        ring.start();

        // TIM6: update event at the sample rate (80 MHz / 1600 = 50 kHz), TRGO = update.
        let timer = Timer::new(tim6);
        timer.set_frequency(Hertz(SAMPLE_RATE), RoundTo::Slower);
        timer.regs_basic().cr2().modify(|w| w.set_mms(MasterMode::UPDATE));
        timer.start();
        defmt::info!(
            "drive: DAC1 ch1 at {} S/s (TIM6 {} Hz), enabled at code {=u16}",
            SAMPLE_RATE,
            update_rate(&timer),
            code
        );
        Self { ring, _dac: dac1, _pin: pa4, _timer: timer }
    }
}

/// DAC1 channel 1 (index 0 in the metapac's per-channel fields) and its pin, PA4.
const CH1: usize = 0;
const PA4: usize = 4;

/// Clocks and resets DAC1, then enables channel 1 so that the first thing on PA4 is
/// mid-scale; returns DOR1 as read just before the enable (2048 when all went as planned).
///
/// Order (RM0351, DAC): with TEN1 = 0 a DHR12R1 write reaches DOR1 one APB clock later, so
/// DOR1 holds [`DAC_MID`] before anything else; TSEL1, TEN1 and DMAEN1 may be written only
/// while EN1 = 0, and with TEN1 = 1 DOR1 changes only at a trigger (TIM6 has not started),
/// so when EN1 goes to 1 the buffer drives DOR1 = mid-scale, and the ring (full of mid-scale
/// codes) takes over at the first trigger. Mode: normal, buffer on, external pin (MCR = 0,
/// its reset value, as embassy's `new_blocking` sets it).
fn enable_at_mid_scale(trigger: u8) -> u16 {
    pac::RCC.apb1enr1().modify(|w| w.set_dac1en(true));
    pac::RCC.apb1rstr1().modify(|w| w.set_dac1rst(true));
    pac::RCC.apb1rstr1().modify(|w| w.set_dac1rst(false));
    pac::GPIOA.moder().modify(|w| w.set_moder(PA4, pac::gpio::vals::Moder::ANALOG));
    pac::DAC1.dhr12r(CH1).write(|w| w.set_dhr(DAC_MID));
    // DOR1 follows one APB clock after the write; this read is later than that.
    let code = pac::DAC1.dor(CH1).read().dor();
    pac::DAC1.cr().modify(|w| {
        w.set_tsel(CH1, trigger);
        w.set_ten(CH1, true);
        w.set_dmaen(CH1, true);
    });
    pac::DAC1.cr().modify(|w| w.set_en(CH1, true));
    code
}

/// The timer's update rate as the hardware makes it: clock / (PSC + 1) / (ARR + 1), rounded.
/// (embassy-stm32 0.6.0's `get_frequency()` divides by ARR, not ARR + 1: it says 50 031 Hz for
/// the 50 000 Hz that PSC = 0, ARR = 1599 give at 80 MHz.)
fn update_rate(timer: &Timer<'static, peripherals::TIM6>) -> u32 {
    let regs = timer.regs_basic();
    let divider = (u64::from(regs.psc().read()) + 1) * (u64::from(regs.arr().read().arr()) + 1);
    let clock = u64::from(timer.get_clock_frequency().0);
    ((clock + divider / 2) / divider) as u32
}

/// Samples widened to 32-bit words per ring write: a small stack buffer (it lives in the drive
/// task's future across the await) instead of a whole block.
const WORDS_PER_WRITE: usize = 50;

impl SampleOutput for DacOutput {
    async fn write_block(&mut self, block: &[u16]) -> Result<Option<u32>, Underrun> {
        let mut result = Ok(super::slack_us(self.ring.capacity(), self.ring.len()));
        let mut words = [0u32; WORDS_PER_WRITE];
        for codes in block.chunks(WORDS_PER_WRITE) {
            let words = &mut words[..codes.len()];
            words.iter_mut().zip(codes).for_each(|(w, &code)| *w = u32::from(code));
            if self.ring.write_exact(words).await.is_err() {
                // The DMA overtook the writer (some old samples were played again). The ring
                // has reset itself to a full buffer's lead; queue these samples behind it.
                let _ = self.ring.write_exact(words).await;
                result = Err(Underrun);
            }
        }
        result
    }
}
