//! A NOR flash in RAM with the rules of the controller's (STM32L4 bank 2, and QEMU's file flash):
//! 2 KiB pages, 8-byte words, erase sets every bit, a write only clears bits and only into an
//! erased word, except that zeros may be written over anything (the L4's PROGERR rule); a store
//! that breaks it fails on the chip, so here it panics. Power can be cut at any numbered
//! operation.
//!
//! Power cut, within what `embedded_storage_async::nor_flash::NorFlash` allows: the word being
//! written holds undefined bits (here: some of the bits that should clear stay set; the words
//! after it in the same write are not written); the page being erased is undefined (here, as in
//! sequential-storage's shutoff model, which recognises a cut erase by its page markers: the
//! erase progressed from the start of the page, so a prefix of words is erased, the word where
//! it stopped is garbled and the rest is as it was). Every operation after the cut, reads
//! included, fails until [`RamFlash::reboot`]. Each word written and each page erased counts as
//! one operation.

use std::cell::RefCell;
use std::rc::Rc;

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

impl RamFlash {
    fn read_now(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), RamFlashError> {
        if self.off {
            return Err(RamFlashError::PowerCut);
        }
        let at = self.check(offset, bytes.len(), 1)?;
        bytes.copy_from_slice(&self.bytes[at..at + bytes.len()]);
        Ok(())
    }

    fn erase_now(&mut self, from: u32, to: u32) -> Result<(), RamFlashError> {
        if to < from {
            return Err(RamFlashError::Request(NorFlashErrorKind::OutOfBounds));
        }
        let at = self.check(from, (to - from) as usize, PAGE)?;
        for start in (at..to as usize).step_by(PAGE) {
            let torn = self.step()?;
            let page = &mut self.bytes[start..start + PAGE];
            if let Some(noise) = torn {
                // Torn erase: the words before the cut erased, the cut word garbled (some bits
                // raised), the rest as it was.
                let split = noise as usize * (PAGE / WORD) / 256 * WORD;
                page[..split].fill(0xff);
                let garbled = &mut page[split..split + WORD];
                for (j, b) in garbled.iter_mut().enumerate() {
                    *b |= noise.rotate_left(j as u32 + 1);
                }
                return Err(RamFlashError::PowerCut);
            }
            page.fill(0xff);
        }
        Ok(())
    }

    fn write_now(&mut self, offset: u32, bytes: &[u8]) -> Result<(), RamFlashError> {
        let at = self.check(offset, bytes.len(), WORD)?;
        for (i, data) in bytes.chunks(WORD).enumerate() {
            let start = at + i * WORD;
            let word = &self.bytes[start..start + WORD];
            // The L4 programs a double word only when it is erased, or when the data is all
            // zeros (RM0351, PROGERR); anything else fails on the chip.
            assert!(
                word.iter().all(|&b| b == 0xff) || data.iter().all(|&b| b == 0),
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

impl ErrorType for RamFlash {
    type Error = RamFlashError;
}

impl ReadNorFlash for RamFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.read_now(offset, bytes)
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl NorFlash for RamFlash {
    const WRITE_SIZE: usize = WORD;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.erase_now(from, to)
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.write_now(offset, bytes)
    }
}

/// A [`RamFlash`] shared between the store that owns a handle and the harness that cuts the
/// power and looks at the bytes (single-threaded; no borrow is held across an await).
#[derive(Debug, Clone)]
pub struct SharedFlash(pub Rc<RefCell<RamFlash>>);

impl SharedFlash {
    /// `pages` erased pages.
    pub fn new(pages: usize) -> Self {
        Self(Rc::new(RefCell::new(RamFlash::new(pages))))
    }

    /// The flash itself, for a moment.
    pub fn with<R>(&self, f: impl FnOnce(&mut RamFlash) -> R) -> R {
        f(&mut self.0.borrow_mut())
    }
}

impl ErrorType for SharedFlash {
    type Error = RamFlashError;
}

impl ReadNorFlash for SharedFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.0.borrow_mut().read_now(offset, bytes)
    }

    fn capacity(&self) -> usize {
        self.0.borrow().bytes.len()
    }
}

impl NorFlash for SharedFlash {
    const WRITE_SIZE: usize = WORD;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.0.borrow_mut().erase_now(from, to)
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.0.borrow_mut().write_now(offset, bytes)
    }
}
