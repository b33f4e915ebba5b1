//! A NOR flash in RAM with the rules of the controller's (STM32L4 bank 2, and QEMU's file flash):
//! 2 KiB pages, 8-byte words, erase sets every bit, a write only clears bits and only into an
//! erased word (the trait's "not twice"; a store that breaks it fails on the chip, so here it
//! panics). Power can be cut at any numbered operation.
//!
//! Power cut, as `embedded_storage_async::nor_flash::NorFlash` allows: the word being written
//! holds undefined bits (here: some of the bits that should clear stay set), the page being
//! erased holds undefined bytes (here: a prefix erased, the rest as it was, with noise); every
//! operation after the cut fails until [`RamFlash::reboot`].

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// Bytes per write word.
pub const WORD: usize = 8;
/// Bytes per erase page.
pub const PAGE: usize = 2048;

/// Why an operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RamFlashError {
    /// Misaligned or out of bounds.
    Request(NorFlashErrorKind),
    /// The power is off (cut at an earlier operation, or this one).
    PowerCut,
}

impl NorFlashError for RamFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            RamFlashError::Request(kind) => *kind,
            RamFlashError::PowerCut => NorFlashErrorKind::Other,
        }
    }
}

/// A planned power cut: at which operation (word write or page erase, counted from the last
/// boot), and the noise it leaves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cut {
    /// Operations that complete before the cut.
    pub after: u32,
    /// Drives what the torn word or page holds.
    pub noise: u8,
}

/// The flash, its operation counter and the power.
#[derive(Debug, Clone)]
pub struct RamFlash {
    bytes: Vec<u8>,
    ops: u32,
    cut: Option<Cut>,
    off: bool,
}

impl RamFlash {
    /// `pages` erased pages.
    pub fn new(pages: usize) -> Self {
        Self { bytes: vec![0xff; pages * PAGE], ops: 0, cut: None, off: false }
    }

    /// Cuts the power at the operation `cut.after` from now.
    pub fn cut_at(&mut self, cut: Cut) {
        self.cut = Some(Cut { after: self.ops.saturating_add(cut.after), ..cut });
    }

    /// Whether the power was cut.
    pub fn is_off(&self) -> bool {
        self.off
    }

    /// Power back on: no cut planned, counting from 0 again.
    pub fn reboot(&mut self) {
        self.off = false;
        self.cut = None;
        self.ops = 0;
    }

    /// Word writes and page erases since boot.
    pub fn ops(&self) -> u32 {
        self.ops
    }

    /// The contents.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// Counts one operation; `Some(noise)` if the power fails during it.
    fn step(&mut self) -> Result<Option<u8>, RamFlashError> {
        if self.off {
            return Err(RamFlashError::PowerCut);
        }
        let torn = self.cut.filter(|c| c.after == self.ops).map(|c| c.noise);
        self.ops += 1;
        if torn.is_some() {
            self.off = true;
        }
        Ok(torn)
    }

    fn check(&self, offset: u32, len: usize, align: usize) -> Result<usize, RamFlashError> {
        let at = offset as usize;
        if !at.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(RamFlashError::Request(NorFlashErrorKind::NotAligned));
        }
        if at.checked_add(len).is_none_or(|end| end > self.bytes.len()) {
            return Err(RamFlashError::Request(NorFlashErrorKind::OutOfBounds));
        }
        Ok(at)
    }
}

impl ErrorType for RamFlash {
    type Error = RamFlashError;
}

impl ReadNorFlash for RamFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        if self.off {
            return Err(RamFlashError::PowerCut);
        }
        let at = self.check(offset, bytes.len(), 1)?;
        bytes.copy_from_slice(&self.bytes[at..at + bytes.len()]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl NorFlash for RamFlash {
    const WRITE_SIZE: usize = WORD;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if to < from {
            return Err(RamFlashError::Request(NorFlashErrorKind::OutOfBounds));
        }
        let at = self.check(from, (to - from) as usize, PAGE)?;
        for start in (at..to as usize).step_by(PAGE) {
            let torn = self.step()?;
            let page = &mut self.bytes[start..start + PAGE];
            if let Some(noise) = torn {
                // Torn erase: a prefix erased, the rest as it was with some bits set.
                let split = noise as usize * PAGE / 256;
                page[..split].fill(0xff);
                page[split..].iter_mut().for_each(|b| *b |= noise.rotate_left(3));
                return Err(RamFlashError::PowerCut);
            }
            page.fill(0xff);
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let at = self.check(offset, bytes.len(), WORD)?;
        for (i, data) in bytes.chunks(WORD).enumerate() {
            let start = at + i * WORD;
            let word = &self.bytes[start..start + WORD];
            assert!(
                word.iter().all(|&b| b == 0xff),
                "write into a word that is not erased at {start:#x}: {word:02x?} <- {data:02x?}"
            );
            let torn = self.step()?;
            let word = &mut self.bytes[start..start + WORD];
            match torn {
                Some(noise) => {
                    // Torn write: some of the bits that should clear stay set.
                    for (j, (w, d)) in word.iter_mut().zip(data).enumerate() {
                        *w &= d | noise.rotate_left(j as u32);
                    }
                    return Err(RamFlashError::PowerCut);
                }
                None => word.iter_mut().zip(data).for_each(|(w, d)| *w &= d),
            }
        }
        Ok(())
    }
}
