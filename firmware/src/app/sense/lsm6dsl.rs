//! An async driver for the ST LSM6DSL accelerometer (the gyroscope stays off), over any
//! `embedded_hal_async::i2c::I2c` bus: the sensor on the feeder's plate.
//!
//! The accelerometer writes its samples into the chip's FIFO (continuous mode, XL only, no
//! decimation, FIFO rate = accelerometer rate), and INT1 rises when the FIFO holds at least the
//! configured threshold; [`Lsm6dsl::read_z`] then drains whole X, Y, Z sets and keeps Z, the
//! axis the plate moves along.
//!
//! Register map and bit fields: ST's `lsm6dsl_reg.h` (register names below are ST's). The FIFO
//! read relies on two documented behaviours: with CTRL3_C.IF_INC set, a burst read from
//! FIFO_STATUS1 returns the four status registers in one transaction; and a burst read from
//! FIFO_DATA_OUT_L keeps returning FIFO words because the address pointer rolls back from
//! FIFO_DATA_OUT_H to FIFO_DATA_OUT_L (what the Linux st_lsm6dsx driver also relies on when
//! it bulk-reads whole patterns from 0x3E). FIFO_PATTERN (FIFO_STATUS3/4) says which axis the
//! next word is; the driver skips to the next X before reading so a set is never split.
//! docs/sensor.md has the sequence and what is verified only against the simulation
//! ([`super::sim`]).

use chladni_shared::icd::sense::SensorFault;
use embedded_hal_async::i2c::{ErrorKind, I2c};

/// 7-bit I2C address of the LSM6DSL on the B-L475E-IOT01A (SA0/SDO low).
pub const ADDRESS: u8 = 0x6A;
/// WHO_AM_I's value on an LSM6DSL.
pub const WHO_AM_I_ID: u8 = 0x6A;
/// FIFO capacity in 16-bit words (4 KiB).
pub const FIFO_WORDS: u16 = 2048;
/// Words per accelerometer sample set (X, Y, Z).
pub const WORDS_PER_SET: u16 = 3;
/// Largest FIFO threshold, in sample sets: FIFO_CTRL1/2's FTH is 11 bits of words.
pub const MAX_THRESHOLD_SETS: u16 = 0x7FF / WORDS_PER_SET;

/// Standard gravity, m/s² per g.
pub const STANDARD_GRAVITY: f32 = 9.80665;

/// Register addresses and bits (ST's names).
pub mod reg {
    pub const FIFO_CTRL1: u8 = 0x06;
    pub const FIFO_CTRL2: u8 = 0x07;
    pub const FIFO_CTRL3: u8 = 0x08;
    pub const FIFO_CTRL4: u8 = 0x09;
    pub const FIFO_CTRL5: u8 = 0x0A;
    pub const INT1_CTRL: u8 = 0x0D;
    pub const WHO_AM_I: u8 = 0x0F;
    pub const CTRL1_XL: u8 = 0x10;
    pub const CTRL2_G: u8 = 0x11;
    pub const CTRL3_C: u8 = 0x12;
    pub const OUTX_L_XL: u8 = 0x28;
    pub const OUTZ_L_XL: u8 = 0x2C;
    pub const OUTZ_H_XL: u8 = 0x2D;
    pub const FIFO_STATUS1: u8 = 0x3A;
    pub const FIFO_STATUS2: u8 = 0x3B;
    pub const FIFO_STATUS3: u8 = 0x3C;
    pub const FIFO_STATUS4: u8 = 0x3D;
    pub const FIFO_DATA_OUT_L: u8 = 0x3E;
    pub const FIFO_DATA_OUT_H: u8 = 0x3F;

    /// CTRL3_C: software reset (self-clearing).
    pub const CTRL3_SW_RESET: u8 = 1 << 0;
    /// CTRL3_C: register address auto-increment on multi-byte access (1 after reset).
    pub const CTRL3_IF_INC: u8 = 1 << 2;
    /// CTRL3_C: block data update (output registers not updated until both bytes are read).
    pub const CTRL3_BDU: u8 = 1 << 6;
    /// CTRL3_C after reset.
    pub const CTRL3_DEFAULT: u8 = CTRL3_IF_INC;

    /// FIFO_CTRL3: accelerometer in the FIFO, no decimation (DEC_FIFO_XL = 001).
    pub const FIFO_CTRL3_XL_NO_DECIMATION: u8 = 0b001;
    /// FIFO_CTRL5 FIFO_MODE: bypass (FIFO off and emptied).
    pub const FIFO_MODE_BYPASS: u8 = 0b000;
    /// FIFO_CTRL5 FIFO_MODE: FIFO (stops when full).
    pub const FIFO_MODE_FIFO: u8 = 0b001;
    /// FIFO_CTRL5 FIFO_MODE: continuous (oldest overwritten when full).
    pub const FIFO_MODE_CONTINUOUS: u8 = 0b110;
    /// FIFO_CTRL5: FIFO_MODE field.
    pub const FIFO_MODE_MASK: u8 = 0b111;
    /// FIFO_CTRL5: ODR_FIFO field position (bits 6:3, same codes as ODR_XL).
    pub const FIFO_ODR_SHIFT: u8 = 3;

    /// INT1_CTRL: FIFO threshold on INT1.
    pub const INT1_FTH: u8 = 1 << 3;

    /// FIFO_STATUS2: DIFF_FIFO bits 10:8.
    pub const STATUS2_DIFF_HIGH_MASK: u8 = 0b111;
    /// FIFO_STATUS2: FIFO empty.
    pub const STATUS2_EMPTY: u8 = 1 << 4;
    /// FIFO_STATUS2: FIFO full at the next sample (FIFO_FULL_SMART).
    pub const STATUS2_FULL_SMART: u8 = 1 << 5;
    /// FIFO_STATUS2: FIFO overrun (at least one word overwritten).
    pub const STATUS2_OVER_RUN: u8 = 1 << 6;
    /// FIFO_STATUS2: FIFO level at or above the threshold (WaterM).
    pub const STATUS2_WATERM: u8 = 1 << 7;

    /// CTRL1_XL: ODR_XL field position (bits 7:4).
    pub const ODR_XL_SHIFT: u8 = 4;
    /// CTRL1_XL: FS_XL field position (bits 3:2).
    pub const FS_XL_SHIFT: u8 = 2;
}

/// Accelerometer full scale (CTRL1_XL.FS_XL).
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Range {
    /// ±2 g, 0.061 mg/LSB.
    G2,
    /// ±4 g, 0.122 mg/LSB.
    G4,
    /// ±8 g, 0.244 mg/LSB.
    G8,
    /// ±16 g, 0.488 mg/LSB.
    G16,
}

impl Range {
    /// Every range, smallest first.
    pub const ALL: [Range; 4] = [Range::G2, Range::G4, Range::G8, Range::G16];

    /// FS_XL code (note the datasheet's order: 00 = 2 g, 01 = 16 g, 10 = 4 g, 11 = 8 g).
    pub const fn code(self) -> u8 {
        match self {
            Range::G2 => 0b00,
            Range::G16 => 0b01,
            Range::G4 => 0b10,
            Range::G8 => 0b11,
        }
    }

    /// The range with FS_XL code `code` (its two low bits).
    pub const fn from_code(code: u8) -> Range {
        match code & 0b11 {
            0b00 => Range::G2,
            0b01 => Range::G16,
            0b10 => Range::G4,
            _ => Range::G8,
        }
    }

    /// Full scale, g.
    pub const fn full_scale_g(self) -> u8 {
        match self {
            Range::G2 => 2,
            Range::G4 => 4,
            Range::G8 => 8,
            Range::G16 => 16,
        }
    }

    /// Full scale, m/s².
    pub fn full_scale(self) -> f32 {
        f32::from(self.full_scale_g()) * STANDARD_GRAVITY
    }

    /// Datasheet sensitivity, mg per LSB.
    pub const fn mg_per_lsb(self) -> f32 {
        match self {
            Range::G2 => 0.061,
            Range::G4 => 0.122,
            Range::G8 => 0.244,
            Range::G16 => 0.488,
        }
    }

    /// Sensitivity, m/s² per LSB.
    pub fn sensitivity(self) -> f32 {
        self.mg_per_lsb() * 1e-3 * STANDARD_GRAVITY
    }
}

/// Accelerometer output data rate, high-performance mode (CTRL1_XL.ODR_XL); the FIFO runs at
/// the same rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Odr {
    /// 12.5 Hz.
    Hz12_5,
    /// 26 Hz.
    Hz26,
    /// 52 Hz.
    Hz52,
    /// 104 Hz.
    Hz104,
    /// 208 Hz.
    Hz208,
    /// 416 Hz.
    Hz416,
    /// 833 Hz.
    Hz833,
    /// 1.66 kHz.
    Hz1660,
    /// 3.33 kHz.
    Hz3330,
    /// 6.66 kHz.
    Hz6660,
}

impl Odr {
    /// Every rate, slowest first.
    pub const ALL: [Odr; 10] = [
        Odr::Hz12_5,
        Odr::Hz26,
        Odr::Hz52,
        Odr::Hz104,
        Odr::Hz208,
        Odr::Hz416,
        Odr::Hz833,
        Odr::Hz1660,
        Odr::Hz3330,
        Odr::Hz6660,
    ];

    /// ODR_XL (and ODR_FIFO) code: 1 (12.5 Hz) to 10 (6.66 kHz).
    pub const fn code(self) -> u8 {
        self as u8 + 1
    }

    /// The rate with code `code`, if it is one of these (0 is power-down; 11, 1.6 Hz, is a
    /// low-power-only rate this driver never sets).
    pub fn from_code(code: u8) -> Option<Odr> {
        Odr::ALL.iter().copied().find(|odr| odr.code() == code)
    }

    /// Nominal rate, mHz (the datasheet's values; the real rate is set by the chip's clock).
    pub const fn millihertz(self) -> u32 {
        match self {
            Odr::Hz12_5 => 12_500,
            Odr::Hz26 => 26_000,
            Odr::Hz52 => 52_000,
            Odr::Hz104 => 104_000,
            Odr::Hz208 => 208_000,
            Odr::Hz416 => 416_000,
            Odr::Hz833 => 833_000,
            Odr::Hz1660 => 1_660_000,
            Odr::Hz3330 => 3_330_000,
            Odr::Hz6660 => 6_660_000,
        }
    }

    /// Nominal rate, Hz.
    pub fn hz(self) -> f32 {
        self.millihertz() as f32 / 1000.0
    }
}

/// What [`Lsm6dsl::init`] sets up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct Config {
    /// Full scale.
    pub range: Range,
    /// Sample rate (accelerometer and FIFO).
    pub odr: Odr,
    /// INT1 rises when the FIFO holds at least this many sample sets (X, Y, Z);
    /// 1..=[`MAX_THRESHOLD_SETS`].
    pub fifo_threshold: u16,
}

/// Why the sensor could not be set up or read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum SensorError {
    /// Nothing acknowledged at the sensor's address (absent, unpowered or dead), or it
    /// refused a byte.
    Nack,
    /// A device answered, but WHO_AM_I is not the LSM6DSL's 0x6A: the value read.
    WrongId(u8),
    /// The FIFO overflowed since the last read: samples were lost. The FIFO has been emptied
    /// and restarted, so the next read returns fresh samples.
    Overrun,
    /// Any other bus failure (arbitration loss, bus error, timeout, ...).
    Bus,
    /// The configured FIFO threshold is 0 or above [`MAX_THRESHOLD_SETS`] sets.
    BadThreshold(u16),
    /// CTRL3_C.SW_RESET never cleared after a software reset.
    ResetStuck,
    /// An operation on the sensor did not finish within its time limit (the bus hung: a
    /// device holding SCL or SDA, or a driver waiting for an event that never comes). Set by
    /// the sense task, which bounds every operation (`task::OP_LIMIT`).
    Timeout,
}

impl SensorError {
    /// A short name for messages.
    pub const fn name(self) -> &'static str {
        match self {
            SensorError::Nack => "sensor not answering (NACK)",
            SensorError::WrongId(_) => "wrong WHO_AM_I (not an LSM6DSL)",
            SensorError::Overrun => "sensor FIFO overrun (samples lost)",
            SensorError::Bus => "I2C bus error",
            SensorError::BadThreshold(_) => "FIFO threshold out of range",
            SensorError::ResetStuck => "sensor software reset did not complete",
            SensorError::Timeout => "I2C operation timed out (bus hung)",
        }
    }

    /// The failure as the link reports it.
    pub const fn fault(self) -> SensorFault {
        match self {
            SensorError::Nack => SensorFault::Nack,
            SensorError::WrongId(id) => SensorFault::WrongId(id),
            SensorError::Overrun => SensorFault::Overrun,
            SensorError::Bus
            | SensorError::BadThreshold(_)
            | SensorError::ResetStuck
            | SensorError::Timeout => SensorFault::Bus,
        }
    }

    fn from_bus<E: embedded_hal_async::i2c::Error>(e: E) -> Self {
        match e.kind() {
            ErrorKind::NoAcknowledge(_) => SensorError::Nack,
            _ => SensorError::Bus,
        }
    }
}

/// Reads of CTRL3_C waiting for SW_RESET to clear (the reset takes about 50 µs; one read at
/// 400 kHz takes about 60 µs).
const RESET_POLLS: usize = 100;

/// Sample sets read per I2C transaction: 64 sets = 384 bytes on the stack, about 10 ms at
/// 400 kHz.
const SETS_PER_BURST: usize = 64;

/// The FIFO status registers FIFO_STATUS1..4, decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FifoStatus {
    /// Unread words (DIFF_FIFO).
    pub words: u16,
    /// FIFO empty.
    pub empty: bool,
    /// At least one word was overwritten.
    pub overrun: bool,
    /// At or above the threshold.
    pub threshold: bool,
    /// Index, within the pattern, of the next word to be read (0 = X with XL only).
    pub pattern: u16,
}

impl FifoStatus {
    /// Decodes FIFO_STATUS1..4 as read in one burst.
    pub fn from_bytes(b: [u8; 4]) -> Self {
        FifoStatus {
            words: u16::from(b[0]) | u16::from(b[1] & reg::STATUS2_DIFF_HIGH_MASK) << 8,
            empty: b[1] & reg::STATUS2_EMPTY != 0,
            overrun: b[1] & reg::STATUS2_OVER_RUN != 0,
            threshold: b[1] & reg::STATUS2_WATERM != 0,
            pattern: u16::from(b[2]) | u16::from(b[3] & 0b11) << 8,
        }
    }
}

/// The LSM6DSL on an I2C bus, at [`ADDRESS`].
pub struct Lsm6dsl<I> {
    i2c: I,
    config: Option<Config>,
}

impl<I: I2c> Lsm6dsl<I> {
    /// The driver; nothing is sent until [`Lsm6dsl::init`].
    pub fn new(i2c: I) -> Self {
        Self { i2c, config: None }
    }

    /// The bus back.
    pub fn release(self) -> I {
        self.i2c
    }

    /// The configuration of the last successful [`Lsm6dsl::init`].
    pub fn config(&self) -> Option<Config> {
        self.config
    }

    /// Checks the chip's identity, resets it, then sets up the accelerometer (gyroscope off),
    /// the FIFO (continuous, XL only, at the ODR) and INT1 on the FIFO threshold.
    pub async fn init(&mut self, cfg: Config) -> Result<(), SensorError> {
        self.config = None;
        if cfg.fifo_threshold == 0 || cfg.fifo_threshold > MAX_THRESHOLD_SETS {
            return Err(SensorError::BadThreshold(cfg.fifo_threshold));
        }
        // Identity first, so nothing is ever written to a device that is not an LSM6DSL.
        let id = self.read_reg(reg::WHO_AM_I).await?;
        if id != WHO_AM_I_ID {
            return Err(SensorError::WrongId(id));
        }
        self.reset().await?;
        self.write(&[reg::CTRL3_C, reg::CTRL3_BDU | reg::CTRL3_IF_INC]).await?;
        // Accelerometer on at the ODR and range; gyroscope (CTRL2_G) off.
        let ctrl1 = cfg.odr.code() << reg::ODR_XL_SHIFT | cfg.range.code() << reg::FS_XL_SHIFT;
        self.write(&[reg::CTRL1_XL, ctrl1, 0]).await?;
        // FIFO_CTRL1..5 in one auto-incremented write; the mode (CTRL5) comes last, once the
        // threshold and the data sets are in place.
        let fth = cfg.fifo_threshold * WORDS_PER_SET;
        let [fth_low, fth_high] = fth.to_le_bytes();
        let fifo_ctrl5 = Self::fifo_ctrl5(cfg.odr, reg::FIFO_MODE_CONTINUOUS);
        self.write(&[
            reg::FIFO_CTRL1,
            fth_low,
            fth_high & 0b111,
            reg::FIFO_CTRL3_XL_NO_DECIMATION,
            0,
            fifo_ctrl5,
        ])
        .await?;
        self.write(&[reg::INT1_CTRL, reg::INT1_FTH]).await?;
        self.config = Some(cfg);
        Ok(())
    }

    /// Reads WHO_AM_I again: `WrongId` if the device at the address is no longer an LSM6DSL
    /// (replaced, or answering garbage), so a running controller notices.
    pub async fn check_id(&mut self) -> Result<(), SensorError> {
        match self.read_reg(reg::WHO_AM_I).await? {
            WHO_AM_I_ID => Ok(()),
            id => Err(SensorError::WrongId(id)),
        }
    }

    /// Reads the Z samples waiting in the FIFO, oldest first: as many whole sets as are there
    /// and fit in `out`; returns how many were written. `Overrun` if the FIFO overflowed since
    /// the last read (it is emptied and restarted, so the next call recovers).
    pub async fn read_z(&mut self, out: &mut [i16]) -> Result<usize, SensorError> {
        let status = self.fifo_status().await?;
        if status.overrun {
            self.restart_fifo().await?;
            return Err(SensorError::Overrun);
        }
        if status.empty || out.is_empty() {
            return Ok(0);
        }
        let mut words = status.words;
        // Mid-set (a set was split by an earlier partial read): drop the rest of it so every
        // burst starts at an X word.
        let pattern = status.pattern % WORDS_PER_SET;
        if pattern != 0 {
            let skip = (WORDS_PER_SET - pattern).min(words);
            let mut discard = [0u8; 2 * WORDS_PER_SET as usize];
            self.read_fifo(&mut discard[..2 * usize::from(skip)]).await?;
            words -= skip;
        }
        let sets = usize::from(words / WORDS_PER_SET).min(out.len());
        let mut buf = [0u8; 2 * WORDS_PER_SET as usize * SETS_PER_BURST];
        let mut done = 0;
        while done < sets {
            let n = (sets - done).min(SETS_PER_BURST);
            let bytes = &mut buf[..n * 2 * usize::from(WORDS_PER_SET)];
            self.read_fifo(bytes).await?;
            for (z, set) in out[done..done + n].iter_mut().zip(bytes.chunks_exact(6)) {
                *z = i16::from_le_bytes([set[4], set[5]]);
            }
            done += n;
        }
        Ok(sets)
    }

    /// FIFO_STATUS1..4 in one burst.
    pub async fn fifo_status(&mut self) -> Result<FifoStatus, SensorError> {
        let mut b = [0u8; 4];
        self.i2c
            .write_read(ADDRESS, &[reg::FIFO_STATUS1], &mut b)
            .await
            .map_err(SensorError::from_bus)?;
        Ok(FifoStatus::from_bytes(b))
    }

    /// Empties the FIFO and restarts it (bypass, then continuous again), which also clears
    /// the overrun flag.
    async fn restart_fifo(&mut self) -> Result<(), SensorError> {
        let odr = self.config.map_or(Odr::Hz12_5, |c| c.odr);
        self.write(&[reg::FIFO_CTRL5, Self::fifo_ctrl5(odr, reg::FIFO_MODE_BYPASS)]).await?;
        self.write(&[reg::FIFO_CTRL5, Self::fifo_ctrl5(odr, reg::FIFO_MODE_CONTINUOUS)]).await
    }

    /// Software reset, then waits (bounded) for SW_RESET to clear.
    async fn reset(&mut self) -> Result<(), SensorError> {
        self.write(&[reg::CTRL3_C, reg::CTRL3_DEFAULT | reg::CTRL3_SW_RESET]).await?;
        for _ in 0..RESET_POLLS {
            if self.read_reg(reg::CTRL3_C).await? & reg::CTRL3_SW_RESET == 0 {
                return Ok(());
            }
        }
        Err(SensorError::ResetStuck)
    }

    fn fifo_ctrl5(odr: Odr, mode: u8) -> u8 {
        odr.code() << reg::FIFO_ODR_SHIFT | mode
    }

    /// Burst read from FIFO_DATA_OUT_L: the address rolls back from _H to _L, so `buf.len()
    /// / 2` consecutive FIFO words, little-endian.
    async fn read_fifo(&mut self, buf: &mut [u8]) -> Result<(), SensorError> {
        self.i2c
            .write_read(ADDRESS, &[reg::FIFO_DATA_OUT_L], buf)
            .await
            .map_err(SensorError::from_bus)
    }

    async fn read_reg(&mut self, reg: u8) -> Result<u8, SensorError> {
        let mut b = [0u8];
        self.i2c.write_read(ADDRESS, &[reg], &mut b).await.map_err(SensorError::from_bus)?;
        Ok(b[0])
    }

    async fn write(&mut self, bytes: &[u8]) -> Result<(), SensorError> {
        self.i2c.write(ADDRESS, bytes).await.map_err(SensorError::from_bus)
    }
}
