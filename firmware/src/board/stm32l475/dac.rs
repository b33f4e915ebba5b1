//! The drive output: DAC1 channel 1 on PA4, converting on every TIM6 TRGO (update event at the
//! sample rate). DMA1 channel 3 (request 6) moves samples from a circular buffer of two blocks
//! into DHR12R1, one 32-bit word per sample (RM0351 asks for word accesses to the DAC
//! registers; the 12-bit code sits in bits 11:0); its half-transfer and transfer-complete
//! interrupts wake the drive task, which refills the half just played (embassy-stm32's
//! `WritableRingBuffer`, which starts full of the mid-scale codes it was given). If the DMA
//! catches up with the writer (a refill missed its half period) the ring reports an overrun
//! and resets itself: counted as an underrun.

use chladni_shared::drive::runner::BLOCK_LEN;
use chladni_shared::icd::units::SAMPLE_RATE;
use embassy_stm32::dac::{self, DacChannel};
use embassy_stm32::dma::{self, TransferOptions, WritableRingBuffer};
use embassy_stm32::mode::Blocking;
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
    _dac: DacChannel<'static, Blocking>,
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
        let buf = BUF.init([u32::from(chladni_shared::drive::dds::DAC_MID); 2 * BLOCK_LEN]);

        // The DAC channel (clock, analog pin); then trigger and DMA request by register, since
        // the ring buffer owns the DMA channel rather than the DAC driver.
        let dac_ch = DacChannel::new_blocking(dac1, pa4);
        let trigger = <embassy_stm32::triggers::TIM6_TRGO as dac::ChannelTrigger<
            peripherals::DAC1,
        >>::signal(&embassy_stm32::triggers::TIM6_TRGO);
        pac::DAC1.cr().modify(|w| {
            w.set_en(0, false);
            w.set_tsel(0, trigger);
            w.set_ten(0, true);
            w.set_dmaen(0, true);
        });
        pac::DAC1.cr().modify(|w| w.set_en(0, true));

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
        defmt::info!("drive: DAC1 ch1 at {} S/s (TIM6 {} Hz)", SAMPLE_RATE, update_rate(&timer));
        Self { ring, _dac: dac_ch, _timer: timer }
    }
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
