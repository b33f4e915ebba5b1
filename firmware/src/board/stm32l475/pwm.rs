//! The PWM drive option (cargo feature `drive-pwm`): the drive stream as the duty of TIM3
//! channel 3 on PB0 (Arduino D3 of the B-L475E-IOT01A), instead of DAC1 on PA4.
//!
//! The arithmetic is `chladni_shared::drive::pwm`: carrier = the sample rate, 50 kHz
//! (80 MHz / 1600, ARR = 1599, PSC = 0), one PWM period per sample, duty = code / 4096 of the
//! period, 1601 duty values (≈ 10.6 bits). An external RC filter turns the pulses into the
//! drive voltage (docs/pwm.md).
//!
//! Sample transport, as for the DAC ([`super::dac`]): a circular DMA ring of two blocks,
//! refilled half by half by the drive task (embassy-stm32's `WritableRingBuffer`; its one-shot
//! timer DMA helpers cannot be refilled). DMA1 channel 2, request 5 is TIM3_CH3 (RM0351
//! DMA1 request map); with TIM3_CR2.CCDS = 1 that request fires on every update event instead
//! of on the compare match, so the DMA writes the next duty into CCR3 once per PWM period.
//! CCR3 is preloaded (OC3PE): the value written during period n takes effect at the start of
//! period n + 1, so a write never lands in the middle of a pulse. Half-word transfers: TIM3's
//! registers take 16-bit accesses, and a duty fits in 16 bits.
//!
//! Why TIM3 ch3 on PB0: TIM2 is embassy's time driver; PB0 reaches the Arduino header (D3,
//! marked PWM) and has no other use on this board; DMA1 ch2 is free (the DAC's channel 3 is
//! TIM3_UP's too, and ch4/ch5 serve I2C2, the on-board sensors' bus). Alternatives on the
//! header: TIM3 ch1 on PB4 (D5, DMA1 ch6) or ch4 on PB1 (D6, DMA1 ch3).
//!
//! Hardware status: built and checked against the embassy-stm32 0.6.0 sources and RM0351, not
//! yet run on a board; docs/pwm.md lists what a bring-up must check.

use chladni_shared::drive::pwm::{self as maths, PLAN};
use chladni_shared::drive::runner::BLOCK_LEN;
use embassy_stm32::dma::{self, TransferOptions, WritableRingBuffer};
use embassy_stm32::gpio::OutputType;
use embassy_stm32::peripherals;
use embassy_stm32::timer::low_level::{OutputCompareMode, Timer};
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{self, Channel};
use static_cell::StaticCell;
use stm32_metapac as pac;

use super::Irqs;
use crate::app::drive::{SampleOutput, Underrun};

/// The timer channel carrying the drive.
const CHANNEL: Channel = Channel::Ch3;
/// Its index in the metapac's per-channel registers (CCR3, CCxDE, OCxPE).
const CH_INDEX: usize = 2;
/// DMA1 channel 2 (index 1): TIM3_CH3, request 5.
const DMA_CH: usize = 1;

/// TIM3 ch3 PWM on PB0, its duty fed by circular DMA over two blocks.
pub struct PwmOutput {
    ring: WritableRingBuffer<'static, u16>,
    _pin: PwmPin<'static, peripherals::TIM3, timer::Ch3>,
    _timer: Timer<'static, peripherals::TIM3>,
}

impl PwmOutput {
    pub(super) fn new(
        tim3: embassy_stm32::Peri<'static, peripherals::TIM3>,
        pb0: embassy_stm32::Peri<'static, peripherals::PB0>,
        dma_ch: embassy_stm32::Peri<'static, peripherals::DMA1_CH2>,
    ) -> Self {
        static BUF: StaticCell<[u16; 2 * BLOCK_LEN]> = StaticCell::new();
        let buf = BUF.init([PLAN.mid(); 2 * BLOCK_LEN]);

        let pin = PwmPin::new(pb0, OutputType::PushPull);
        let timer = Timer::new(tim3);
        if timer.get_clock_frequency().0 != PLAN.timer_clock_hz {
            // The carrier and the sample rate would both be off: say so loudly.
            defmt::error!(
                "drive: TIM3 clock {=u32} Hz, the PWM plan assumes {=u32} Hz",
                timer.get_clock_frequency().0,
                PLAN.timer_clock_hz
            );
        }
        // The period straight from the plan (PSC = 0, ARR = 1599), not rounded by a frequency.
        let regs = timer.regs_gp16();
        regs.psc().write_value(0);
        regs.arr().write(|w| w.set_arr(PLAN.arr));
        timer.set_autoreload_preload(true);
        timer.set_output_compare_mode(CHANNEL, OutputCompareMode::PwmMode1);
        timer.set_output_compare_preload(CHANNEL, true);
        timer.set_compare_value(CHANNEL, PLAN.mid());
        // Load PSC, ARR and CCR3 from their preload registers before the first period.
        timer.generate_update_event();
        timer.enable_channel(CHANNEL, true);
        timer.set_cc_dma_selection(pac::timer::vals::Ccds::ON_UPDATE);
        timer.set_cc_dma_enable_state(CHANNEL, true);

        let request =
            <peripherals::DMA1_CH2 as timer::Dma<peripherals::TIM3, timer::Ch3>>::request(&dma_ch);
        let channel = dma::Channel::new(dma_ch, Irqs);
        let ccr = pac::TIM3.ccr(CH_INDEX).as_ptr() as *mut u16;
        // SAFETY: `ccr` is TIM3's CCR3, which takes half-word writes (the duty, 0..=1600);
        // `buf` is 'static and owned by the ring from here on.
        let mut ring = unsafe {
            WritableRingBuffer::new(channel, request, ccr, buf, TransferOptions::default())
        };
        ring.start();
        timer.start();
        defmt::info!(
            "drive: TIM3 ch3 PWM on PB0, carrier {=u32} Hz, {=u16} duty steps",
            PLAN.carrier_hz(),
            PLAN.period()
        );
        Self { ring, _pin: pin, _timer: timer }
    }
}

/// Duties converted per ring write: a small stack buffer (it lives in the drive task's future
/// across the await) instead of a whole block.
const DUTIES_PER_WRITE: usize = 50;

impl SampleOutput for PwmOutput {
    async fn write_block(&mut self, block: &[u16]) -> Result<Option<u32>, Underrun> {
        let mut result = Ok(super::slack_us(self.ring.capacity(), self.ring.len()));
        let mut duties = [0u16; DUTIES_PER_WRITE];
        for codes in block.chunks(DUTIES_PER_WRITE) {
            let duties = &mut duties[..codes.len()];
            // Same lengths by construction: the error cannot happen.
            let _ = maths::duties_of_block(codes, duties, &PLAN);
            if self.ring.write_exact(duties).await.is_err() {
                // The DMA overtook the writer; the ring has reset itself (see `super::dac`).
                let _ = self.ring.write_exact(duties).await;
                result = Err(Underrun);
            }
        }
        result
    }
}

/// Stops the PWM drive and holds 50 % duty (mid-scale: zero signal after the filter).
/// Idempotent, needs no state: raw register writes, safe from any fault handler.
///
/// Order: disable the DMA channel and TIM3's CC3 DMA request (nothing writes CCR3 any more),
/// clear OC3PE so the next CCR3 write takes effect at once instead of at the next update, then
/// write the mid duty. TIM3 keeps running: a stopped timer would freeze PB0 high or low, a
/// full-scale step after the filter. Before `init` the clocks are off and nothing changes.
pub fn park() {
    pac::DMA1.ch(DMA_CH).cr().modify(|w| w.set_en(false));
    let tim = pac::TIM3;
    tim.dier().modify(|w| w.set_ccde(CH_INDEX, false));
    tim.ccmr_output(CH_INDEX / 2).modify(|w| w.set_ocpe(CH_INDEX % 2, false));
    tim.ccr(CH_INDEX).write(|w| w.set_ccr(PLAN.mid()));
}

/// Whether the PWM is parked: CCR3 at the mid duty and its DMA off (for the fault report).
pub fn parked_duty() -> (u16, bool) {
    let duty = pac::TIM3.ccr(CH_INDEX).read().ccr();
    let dma_off = !pac::DMA1.ch(DMA_CH).cr().read().en();
    (duty, duty == PLAN.mid() && dma_off)
}
