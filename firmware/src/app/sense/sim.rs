//! A simulated LSM6DSL: its register map behind an `embedded_hal_async::i2c::I2c` device at
//! 0x6A, so the driver ([`super::lsm6dsl`]) runs unchanged against it in host tests and on the
//! QEMU board (QEMU models no I2C).
//!
//! What is modelled is what the driver uses: WHO_AM_I, the control registers (stored as
//! written; CTRL3_C.SW_RESET restores the reset values), register auto-increment
//! (CTRL3_C.IF_INC, with FIFO_DATA_OUT_H rolling back to FIFO_DATA_OUT_L), the output
//! registers OUTX..OUTZ_XL (the last sample), and the 2048-word FIFO: bypass, FIFO and
//! continuous modes, the threshold (FIFO_STATUS2.WaterM and INT1 when INT1_CTRL.INT1_FTH is
//! set), overrun (continuous mode drops the oldest word and latches OVER_RUN until the FIFO is
//! restarted through bypass), DIFF_FIFO and FIFO_PATTERN. A FIFO word is popped when its high
//! byte (FIFO_DATA_OUT_H) is read.
//!
//! Samples do not appear by themselves: whoever plays the plant calls [`SimLsm6dsl::push`]
//! (raw LSB) or [`SimLsm6dsl::push_accel`] (m/s², scaled and saturated at the configured
//! range) at the configured rate ([`SimLsm6dsl::odr`]; [`OdrPacer`] turns a faster sample
//! clock into that rate). Faults ([`Fault`]) make it answer with a wrong id, NACK everything,
//! or stay silent (no new samples).
//!
//! The struct is plain (`&mut self` methods) so a blocking context can push while the sense
//! task reads: the QEMU board shares it as a [`SharedSim`] (a critical-section mutex).

use core::cell::RefCell;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embedded_hal_async::i2c::{
    ErrorKind, ErrorType, I2c, NoAcknowledgeSource, Operation, SevenBitAddress,
};

use super::lsm6dsl::{ADDRESS, FIFO_WORDS, Odr, Range, WHO_AM_I_ID, WORDS_PER_SET, reg};

/// An injected fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, defmt::Format)]
pub enum Fault {
    /// Behaves as an LSM6DSL.
    #[default]
    None,
    /// WHO_AM_I reads this instead of 0x6A (another chip at the address).
    WrongId(u8),
    /// Nothing acknowledges (sensor absent, unpowered or dead).
    Nack,
    /// Answers, but produces no new samples: the FIFO never fills.
    Silent,
}

/// What the simulated bus reports: only NACKs (a simulated bus never loses arbitration).
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum SimError {
    /// No acknowledge of the address.
    Nack,
}

impl embedded_hal_async::i2c::Error for SimError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address)
    }
}

/// Number of register addresses modelled (0x00..=0x7F).
const REGS: usize = 0x80;

/// The simulated LSM6DSL (about 4.2 KiB: the FIFO is 2048 words).
pub struct SimLsm6dsl {
    /// Registers, stored as their difference (XOR) from the reset values: a fresh sensor is
    /// all zeros, so a `static` one lands in .bss rather than costing 4 KiB of initialiser
    /// in flash.
    regs: [u8; REGS],
    /// Register pointer, kept between transactions as the chip does.
    pointer: u8,
    fifo: [i16; FIFO_WORDS as usize],
    /// Index of the oldest word in `fifo`.
    head: usize,
    /// Words in the FIFO.
    level: usize,
    /// Words written since the FIFO was last started, mod 3: the axis of the next word in.
    written: u64,
    /// Words read since the FIFO was last started: the pattern of the next word out.
    read: u64,
    overrun: bool,
    fault: Fault,
}

impl Default for SimLsm6dsl {
    fn default() -> Self {
        Self::new()
    }
}

impl SimLsm6dsl {
    /// A chip just powered up: reset values, FIFO in bypass, accelerometer off.
    pub const fn new() -> Self {
        Self {
            regs: [0; REGS],
            pointer: 0,
            fifo: [0; FIFO_WORDS as usize],
            head: 0,
            level: 0,
            written: 0,
            read: 0,
            overrun: false,
            fault: Fault::None,
        }
    }

    /// Reset value of register `addr`.
    const fn reset_value(addr: u8) -> u8 {
        if addr == reg::CTRL3_C { reg::CTRL3_DEFAULT } else { 0 }
    }

    /// Register `addr`'s value.
    fn reg(&self, addr: u8) -> u8 {
        let addr = addr % REGS as u8;
        self.regs[usize::from(addr)] ^ Self::reset_value(addr)
    }

    fn set_reg(&mut self, addr: u8, value: u8) {
        let addr = addr % REGS as u8;
        self.regs[usize::from(addr)] = value ^ Self::reset_value(addr);
    }

    /// Injects `fault` (or clears it with [`Fault::None`]).
    pub fn set_fault(&mut self, fault: Fault) {
        self.fault = fault;
    }

    /// The injected fault.
    pub fn fault(&self) -> Fault {
        self.fault
    }

    /// A register's value as last written (or its reset value).
    pub fn register(&self, addr: u8) -> u8 {
        self.reg(addr)
    }

    /// The accelerometer's rate, or `None` while it is powered down.
    pub fn odr(&self) -> Option<Odr> {
        Odr::from_code(self.reg(reg::CTRL1_XL) >> reg::ODR_XL_SHIFT)
    }

    /// The accelerometer's full scale.
    pub fn range(&self) -> Range {
        Range::from_code(self.reg(reg::CTRL1_XL) >> reg::FS_XL_SHIFT)
    }

    /// The FIFO threshold in words (FIFO_CTRL1/2 FTH).
    pub fn threshold_words(&self) -> u16 {
        let low = self.reg(reg::FIFO_CTRL1);
        let high = self.reg(reg::FIFO_CTRL2) & 0b111;
        u16::from_le_bytes([low, high])
    }

    /// The FIFO threshold in whole sample sets.
    pub fn threshold_sets(&self) -> u16 {
        self.threshold_words() / WORDS_PER_SET
    }

    /// The FIFO's mode bits (FIFO_CTRL5.FIFO_MODE).
    pub fn fifo_mode(&self) -> u8 {
        self.reg(reg::FIFO_CTRL5) & reg::FIFO_MODE_MASK
    }

    /// Words in the FIFO.
    pub fn fifo_level(&self) -> usize {
        self.level
    }

    /// Whether the FIFO has lost words since it was last restarted.
    pub fn overrun(&self) -> bool {
        self.overrun
    }

    /// FIFO level at or above a non-zero threshold (FIFO_STATUS2.WaterM).
    pub fn at_threshold(&self) -> bool {
        let fth = usize::from(self.threshold_words());
        fth != 0 && self.level >= fth
    }

    /// The INT1 line: the threshold flag, when routed to INT1 (INT1_CTRL.INT1_FTH).
    pub fn int1(&self) -> bool {
        self.reg(reg::INT1_CTRL) & reg::INT1_FTH != 0 && self.at_threshold()
    }

    /// A new accelerometer sample, raw LSB: it goes to the output registers and, when the
    /// FIFO is running with the accelerometer in it, into the FIFO. Ignored while the
    /// accelerometer is powered down or the sensor is [`Fault::Silent`].
    pub fn push(&mut self, x: i16, y: i16, z: i16) {
        if self.fault == Fault::Silent || self.odr().is_none() {
            return;
        }
        for (i, v) in [x, y, z].into_iter().enumerate() {
            let [l, h] = v.to_le_bytes();
            self.set_reg(reg::OUTX_L_XL + 2 * i as u8, l);
            self.set_reg(reg::OUTX_L_XL + 2 * i as u8 + 1, h);
        }
        if self.fifo_collects() {
            for v in [x, y, z] {
                self.fifo_put(v);
            }
        }
    }

    /// A new sample in m/s², converted at the configured range (rounded, saturated at the
    /// full scale as the chip's output is); X and Y read 0.
    pub fn push_accel(&mut self, z: f32) {
        let lsb = self.to_lsb(z);
        self.push(0, 0, lsb);
    }

    /// `accel` (m/s²) as raw LSB at the configured range, saturated to i16.
    pub fn to_lsb(&self, accel: f32) -> i16 {
        let lsb = accel / self.range().sensitivity();
        // `as` saturates a float into i16's range (NaN gives 0).
        (if lsb >= 0.0 { lsb + 0.5 } else { lsb - 0.5 }) as i16
    }

    /// Whether pushed samples enter the FIFO: a FIFO mode, a FIFO rate, and the accelerometer
    /// in the FIFO (DEC_FIFO_XL not 0).
    fn fifo_collects(&self) -> bool {
        let mode = self.fifo_mode();
        let fifo_odr = self.reg(reg::FIFO_CTRL5) >> reg::FIFO_ODR_SHIFT;
        let xl_in_fifo = self.reg(reg::FIFO_CTRL3) & 0b111 != 0;
        matches!(mode, reg::FIFO_MODE_FIFO | reg::FIFO_MODE_CONTINUOUS)
            && fifo_odr != 0
            && xl_in_fifo
    }

    fn fifo_put(&mut self, v: i16) {
        let capacity = self.fifo.len();
        if self.level == capacity {
            if self.fifo_mode() == reg::FIFO_MODE_FIFO {
                return; // FIFO mode stops when full.
            }
            // Continuous: the oldest word goes.
            self.head = (self.head + 1) % capacity;
            self.level -= 1;
            self.read += 1;
            self.overrun = true;
        }
        self.fifo[(self.head + self.level) % capacity] = v;
        self.level += 1;
        self.written += 1;
    }

    fn fifo_clear(&mut self) {
        self.head = 0;
        self.level = 0;
        self.written = 0;
        self.read = 0;
        self.overrun = false;
    }

    /// Software reset: registers to their reset values, FIFO emptied (in place: no 4 KiB
    /// temporary on the stack).
    fn reset(&mut self) {
        self.regs = [0; REGS];
        self.pointer = 0;
        self.fifo_clear();
    }

    /// FIFO_STATUS1..4 as the chip computes them.
    fn status(&self) -> [u8; 4] {
        // DIFF_FIFO has 11 bits: a completely full FIFO (2048) reads 2047.
        let diff = self.level.min(0x7FF) as u16;
        let [d_low, d_high] = diff.to_le_bytes();
        let mut s2 = d_high & reg::STATUS2_DIFF_HIGH_MASK;
        if self.level == 0 {
            s2 |= reg::STATUS2_EMPTY;
        }
        if self.level + usize::from(WORDS_PER_SET) > self.fifo.len() {
            s2 |= reg::STATUS2_FULL_SMART;
        }
        if self.overrun {
            s2 |= reg::STATUS2_OVER_RUN;
        }
        if self.at_threshold() {
            s2 |= reg::STATUS2_WATERM;
        }
        let pattern = (self.read % u64::from(WORDS_PER_SET)) as u16;
        let [p_low, p_high] = pattern.to_le_bytes();
        [d_low, s2, p_low, p_high]
    }

    fn read_byte(&mut self, addr: u8) -> u8 {
        match addr {
            reg::WHO_AM_I => match self.fault {
                Fault::WrongId(id) => id,
                _ => WHO_AM_I_ID,
            },
            reg::FIFO_STATUS1..=reg::FIFO_STATUS4 => {
                self.status()[usize::from(addr - reg::FIFO_STATUS1)]
            }
            reg::FIFO_DATA_OUT_L => self.fifo_peek().to_le_bytes()[0],
            reg::FIFO_DATA_OUT_H => {
                let high = self.fifo_peek().to_le_bytes()[1];
                if self.level > 0 {
                    self.head = (self.head + 1) % self.fifo.len();
                    self.level -= 1;
                    self.read += 1;
                }
                high
            }
            _ => self.reg(addr),
        }
    }

    /// The oldest FIFO word (0 when empty).
    fn fifo_peek(&self) -> i16 {
        if self.level == 0 { 0 } else { self.fifo[self.head] }
    }

    fn write_byte(&mut self, addr: u8, value: u8) {
        match addr {
            // Read-only: identity, outputs, status and FIFO data.
            reg::WHO_AM_I | 0x1E..=0x3F => {}
            reg::CTRL3_C if value & reg::CTRL3_SW_RESET != 0 => self.reset(),
            reg::FIFO_CTRL5 => {
                self.set_reg(addr, value);
                if value & reg::FIFO_MODE_MASK == reg::FIFO_MODE_BYPASS {
                    self.fifo_clear();
                }
            }
            _ => self.set_reg(addr, value),
        }
    }

    /// The next register address after an access at `addr`.
    fn next(&self, addr: u8) -> u8 {
        if self.reg(reg::CTRL3_C) & reg::CTRL3_IF_INC == 0 {
            addr
        } else if addr == reg::FIFO_DATA_OUT_H {
            reg::FIFO_DATA_OUT_L
        } else {
            addr.wrapping_add(1) % REGS as u8
        }
    }

    /// One I2C transaction: a write sets the register pointer (its first byte) and writes the
    /// rest; a read reads from the pointer; both auto-increment as CTRL3_C.IF_INC says.
    pub fn transaction_sync(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), SimError> {
        if address != ADDRESS || self.fault == Fault::Nack {
            return Err(SimError::Nack);
        }
        for op in operations {
            match op {
                Operation::Write(bytes) => {
                    let Some((&first, rest)) = bytes.split_first() else { continue };
                    self.pointer = first % REGS as u8;
                    for &b in rest {
                        self.write_byte(self.pointer, b);
                        self.pointer = self.next(self.pointer);
                    }
                }
                Operation::Read(buf) => {
                    for b in buf.iter_mut() {
                        *b = self.read_byte(self.pointer);
                        self.pointer = self.next(self.pointer);
                    }
                }
            }
        }
        Ok(())
    }
}

impl ErrorType for SimLsm6dsl {
    type Error = SimError;
}

/// For host tests: `&mut SimLsm6dsl` is a bus too (embedded-hal-async's blanket impl).
impl I2c<SevenBitAddress> for SimLsm6dsl {
    async fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        self.transaction_sync(address, operations)
    }
}

/// A simulated sensor shared between a blocking producer (pushing samples) and the sense task.
pub type SimCell = Mutex<CriticalSectionRawMutex, RefCell<SimLsm6dsl>>;

/// The bus to a [`SimCell`]: each transaction runs inside the critical section, so a push
/// never lands in the middle of one.
#[derive(Clone, Copy)]
pub struct SharedSim(pub &'static SimCell);

impl SharedSim {
    /// Runs `f` on the simulated sensor, inside the critical section.
    pub fn with<R>(&self, f: impl FnOnce(&mut SimLsm6dsl) -> R) -> R {
        self.0.lock(|sim| f(&mut sim.borrow_mut()))
    }
}

impl ErrorType for SharedSim {
    type Error = SimError;
}

impl I2c<SevenBitAddress> for SharedSim {
    async fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        self.with(|sim| sim.transaction_sync(address, operations))
    }
}

/// Turns a sample clock of `source_hz` into the sensor's rate: [`OdrPacer::advance`] says how
/// many sensor samples fall within the next `n` source samples (a phase accumulator in mHz,
/// exact over any run: no drift).
#[derive(Debug, Clone, Copy)]
pub struct OdrPacer {
    source_hz: u32,
    /// Phase, in mHz × source samples, below `source_hz * 1000`.
    phase: u64,
}

impl OdrPacer {
    /// A pacer for a source clocked at `source_hz` (at least 1).
    pub fn new(source_hz: u32) -> Self {
        Self { source_hz: source_hz.max(1), phase: 0 }
    }

    /// How many samples at `odr` are due after `n` more source samples.
    pub fn advance(&mut self, n: u32, odr: Odr) -> u32 {
        let period = u64::from(self.source_hz) * 1000;
        self.phase += u64::from(n) * u64::from(odr.millihertz());
        let due = self.phase / period;
        self.phase %= period;
        due as u32
    }
}
