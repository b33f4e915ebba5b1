//! The B-L475E-IOT01A: embassy-stm32 drivers, flashed with probe-rs.
//!
//! The host link is USART1 on the ST-LINK virtual COM port (PB6 TX / PB7 RX), 115200 8N1.
//!
//! The drive is DAC1 channel 1 on PA4, converting on every TIM6 TRGO (update event at the
//! sample rate). DMA1 channel 3 (request 6) moves samples from a circular buffer of two
//! blocks into DHR12R1, one 32-bit word per sample (RM0351 asks for word accesses to the DAC
//! registers; the 12-bit code sits in bits 11:0); its half-transfer and transfer-complete
//! interrupts wake the drive task, which refills the half just played (embassy-stm32's
//! `WritableRingBuffer`, which starts full of the mid-scale codes it was given). If the DMA
//! catches up with the writer (a refill missed its half period) the ring reports an overrun
//! and resets itself: counted as an underrun.
//!
//! A panic or HardFault parks the output at mid-scale first ([`failsafe`]).
//!
//! Clocks: the 32.768 kHz crystal (LSE, X3) trims MSI continuously (MSI PLL mode), so the
//! 80 MHz system clock and the 50 kS/s sample rate are as accurate as the crystal (see
//! [`clocks`]).

pub mod failsafe;

use chladni_shared::drive::dds::SAMPLE_RATE;
use chladni_shared::drive::runner::BLOCK_LEN;
use defmt_rtt as _;
use embassy_stm32::dac::{self, DacChannel};
use embassy_stm32::dma::{self, TransferOptions, WritableRingBuffer};
use embassy_stm32::mode::Blocking;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::{MasterMode, RoundTo, Timer};
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::{bind_interrupts, peripherals};
use static_cell::StaticCell;
use stm32_metapac as pac;

use crate::app::drive::{SampleOutput, Underrun};

/// This board's identity on the link.
pub const BOARD: chladni_shared::icd::link::Board = chladni_shared::icd::link::Board::Stm32l475;

/// The host link: USART1 through the ST-LINK virtual COM port.
pub type Link = BufferedUart<'static>;

/// The drive output: DAC1 ch1 fed by circular DMA, paced by TIM6.
pub type DriveOutput = DacOutput;

/// The initialised board.
pub struct Board {
    /// Host link.
    pub link: Link,
    /// Drive output.
    pub drive: DriveOutput,
}

bind_interrupts!(struct Irqs {
    USART1 => usart::BufferedInterruptHandler<peripherals::USART1>;
    DMA1_CHANNEL3 => dma::InterruptHandler<peripherals::DMA1_CH3>;
});

/// DAC1 channel 1 on PA4, triggered by TIM6 TRGO, fed by circular DMA over two blocks.
pub struct DacOutput {
    ring: WritableRingBuffer<'static, u32>,
    _dac: DacChannel<'static, Blocking>,
    _timer: Timer<'static, peripherals::TIM6>,
}

impl DacOutput {
    fn new(
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
    async fn write_block(&mut self, block: &[u16]) -> Result<(), Underrun> {
        let mut result = Ok(());
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

/// 80 MHz from MSI 4 MHz through PLL1 (×40 /2): TIM6 then divides exactly to 50 kS/s.
///
/// Untrimmed, MSI is only good to about ±1 % (RM0351/datasheet), which would put every drive
/// frequency off by as much. With the LSE crystal running, MSI PLL mode (RCC_CR.MSIPLLEN)
/// locks MSI to 32.768 kHz × N. embassy-stm32 0.6.0 sets MSIPLLEN itself in `rcc::init` when
/// `ls.lse` is a 32 768 Hz crystal, after LSERDY (rcc/l.rs: `if config.ls.lse ... ==
/// Some(Hertz(32_768)) { msipllen = true }`), which is the order RM0351 asks for; `init` checks
/// it afterwards. `default_lse` also clocks the (unused) RTC from LSE instead of LSI.
fn clocks() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    config.rcc.ls = LsConfig::default_lse();
    config.rcc.msi = Some(MSIRange::RANGE4M);
    config.rcc.pll = Some(Pll {
        source: PllSource::MSI,
        prediv: PllPreDiv::DIV1,
        mul: PllMul::MUL40,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    config
}

/// Brings the board up: 80 MHz system clock, the link, the drive output.
pub fn init() -> Board {
    let p = embassy_stm32::init(clocks());
    check_clocks();
    // A debugger halting the core (breakpoint, or a fault caught before its handler runs)
    // also stops TIM6, so the DAC holds one code instead of the DMA replaying the ring.
    pac::DBGMCU.apb1fzr1().modify(|w| w.set_tim6(true));
    static TX: StaticCell<[u8; 1024]> = StaticCell::new();
    static RX: StaticCell<[u8; 1024]> = StaticCell::new();
    let mut config = usart::Config::default();
    config.baudrate = 115_200;
    let link = BufferedUart::new(
        p.USART1,
        p.PB7,
        p.PB6,
        TX.init([0; 1024]),
        RX.init([0; 1024]),
        Irqs,
        config,
    )
    .expect("USART1 config");
    let drive = DacOutput::new(p.DAC1, p.PA4, p.DMA1_CH3, p.TIM6);
    Board { link, drive }
}

/// Logs the clock tree's trim state: LSE ready and MSI in PLL mode, or why not.
fn check_clocks() {
    let lse_ready = pac::RCC.bdcr().read().lserdy();
    let msi_pll = pac::RCC.cr().read().msipllen();
    if lse_ready && msi_pll {
        defmt::info!("clocks: 80 MHz from MSI 4 MHz locked to LSE 32.768 kHz (MSI PLL mode)");
    } else {
        defmt::warn!("clocks: MSI untrimmed (LSE ready {}, MSIPLLEN {})", lse_ready, msi_pll);
    }
}

/// Runs embassy's thread-mode executor forever; `init` spawns the first tasks.
pub fn run(init: impl FnOnce(embassy_executor::Spawner)) -> ! {
    static EXECUTOR: StaticCell<embassy_executor::Executor> = StaticCell::new();
    EXECUTOR.init(embassy_executor::Executor::new()).run(init)
}
