//! An in-memory NOR flash shaped like the STM32L475's bank 2, with power cuts.
//!
//! What it keeps of the real part: 2 KiB erase pages, 8-byte (double-word) programming, reads
//! of any length, and the NOR rules — programming only clears bits, and a double word that was
//! programmed since its last erase cannot be programmed again (the L4 refuses it with PROGERR;
//! here it is [`MockFlashError::NotErased`]), even with the same value.
//!
//! Power cuts: [`MockFlash::cut_after`] arms a cut after a number of further *mutating*
//! operations (writes and erases; a read changes nothing, so a cut during one is the same as a
//! cut before the next write). The cut operation is left partial — a write lands a prefix of
//! its double words, an erase erases a prefix of its words and leaves the word where it stopped
//! garbled (some bits raised towards the erased state) — and reports an error, and from then on
//! every operation, reads included, fails: the controller is off. [`MockFlash::revive`] gives
//! the flash as the next boot finds it.
//!
//! Erases progress from the start of the range, as in sequential-storage's own shutoff model:
//! its page markers (first and last word of a page) are how it recognises a page whose erase was
//! cut. A real interrupted erase may leave any bits anywhere in the page; that is not modelled
//! (see docs/store.md).
//!
//! A glitch ([`MockFlash::glitch_after`]) is a write or erase that fails and changes nothing,
//! with the power staying on, like a transient programming error.
//!
//! Every operation is counted ([`FlashStats`]) so tests can report what an upload costs.

use std::vec;
use std::vec::Vec;

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// Erase page, bytes (STM32L475 bank 2).
pub const PAGE_SIZE: usize = 2048;
/// Programming unit, bytes (a double word).
pub const WORD_SIZE: usize = 8;
/// Pages in the store's real range (512 KiB).
pub const BANK_PAGES: usize = 256;

/// Operation counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FlashStats {
    /// Read calls.
    pub reads: u64,
    /// Bytes read.
    pub bytes_read: u64,
    /// Write (program) calls.
    pub writes: u64,
    /// Bytes written.
    pub bytes_written: u64,
    /// Pages erased.
    pub erases: u64,
}

impl FlashStats {
    /// Mutating operations: writes and page erases (what a power cut can interrupt).
    pub fn mutations(&self) -> u64 {
        self.writes + self.erases
    }

    /// The operations done since `earlier`.
    pub fn since(&self, earlier: &FlashStats) -> FlashStats {
        FlashStats {
            reads: self.reads - earlier.reads,
            bytes_read: self.bytes_read - earlier.bytes_read,
            writes: self.writes - earlier.writes,
            bytes_written: self.bytes_written - earlier.bytes_written,
            erases: self.erases - earlier.erases,
        }
    }
}

impl core::fmt::Display for FlashStats {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{} reads ({} B), {} writes ({} B), {} page erases",
            self.reads, self.bytes_read, self.writes, self.bytes_written, self.erases
        )
    }
}

/// Why a mock flash operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MockFlashError {
    /// Outside the flash.
    OutOfBounds,
    /// Offset or length not a multiple of the write or erase size.
    NotAligned,
    /// The double word at this address was programmed since its last erase.
    NotErased {
        /// Its address.
        address: u32,
    },
    /// The power is off (this operation was cut, or came after the cut).
    PowerCut,
    /// A glitch: this write or erase failed and changed nothing.
    Glitch,
}

impl NorFlashError for MockFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            MockFlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            MockFlashError::NotAligned => NorFlashErrorKind::NotAligned,
            MockFlashError::NotErased { .. }
            | MockFlashError::PowerCut
            | MockFlashError::Glitch => NorFlashErrorKind::Other,
        }
    }
}

/// Where the armed power cut falls.
#[derive(Debug, Clone, Copy)]
struct Cut {
    /// Mutating operations that still complete before the cut one.
    remaining: u64,
    /// Chooses how much of the cut operation lands.
    seed: u32,
}

/// The flash. Cloning it copies its contents (and its armed cut, if any).
#[derive(Debug, Clone)]
pub struct MockFlash {
    data: Vec<u8>,
    /// Per double word: programmed since its last erase.
    programmed: Vec<bool>,
    stats: FlashStats,
    cut: Option<Cut>,
    /// Writes or erases until the glitch.
    glitch: Option<u64>,
    off: bool,
}

impl MockFlash {
    /// An erased flash of `pages` pages.
    pub fn new(pages: usize) -> Self {
        let bytes = pages * PAGE_SIZE;
        Self {
            data: vec![0xff; bytes],
            programmed: vec![false; bytes / WORD_SIZE],
            stats: FlashStats::default(),
            cut: None,
            glitch: None,
            off: false,
        }
    }

    /// The operations counted so far.
    pub fn stats(&self) -> FlashStats {
        self.stats
    }

    /// Arms a power cut: `ops` more writes or erases complete, the next one is cut (partly
    /// done, as `seed` picks), and everything after fails.
    pub fn cut_after(&mut self, ops: u64, seed: u32) {
        self.cut = Some(Cut { remaining: ops, seed });
    }

    /// Whether the power has been cut.
    pub fn is_off(&self) -> bool {
        self.off
    }

    /// The flash as the next boot finds it: same contents, power on, no cut armed, counters
    /// from zero.
    pub fn revive(&self) -> MockFlash {
        MockFlash {
            data: self.data.clone(),
            programmed: self.programmed.clone(),
            stats: FlashStats::default(),
            cut: None,
            glitch: None,
            off: false,
        }
    }

    /// Arms a glitch: `ops` more writes or erases complete, the next one fails and changes
    /// nothing, and the flash goes on working.
    pub fn glitch_after(&mut self, ops: u64) {
        self.glitch = Some(ops);
    }

    /// The raw contents.
    pub fn bytes(&self) -> &[u8] {
        &self.data
    }

    /// The raw contents, to corrupt on purpose (the programmed flags stay as they are).
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        &mut self.data
    }

    /// Counts a mutating operation; `Some(seed)` if it is the one the power cut interrupts.
    fn next_mutation(&mut self) -> Result<Option<u32>, MockFlashError> {
        if self.off {
            return Err(MockFlashError::PowerCut);
        }
        match &mut self.glitch {
            Some(0) => {
                self.glitch = None;
                return Err(MockFlashError::Glitch);
            }
            Some(n) => *n -= 1,
            None => {}
        }
        match &mut self.cut {
            Some(cut) if cut.remaining == 0 => {
                let seed = cut.seed;
                self.cut = None;
                self.off = true;
                Ok(Some(seed))
            }
            Some(cut) => {
                cut.remaining -= 1;
                Ok(None)
            }
            None => Ok(None),
        }
    }

    fn check(&self, offset: u32, len: usize, align: usize) -> Result<usize, MockFlashError> {
        let offset = offset as usize;
        if !offset.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(MockFlashError::NotAligned);
        }
        if offset.checked_add(len).is_none_or(|end| end > self.data.len()) {
            return Err(MockFlashError::OutOfBounds);
        }
        Ok(offset)
    }

    fn program_word(&mut self, at: usize, word: &[u8]) -> Result<(), MockFlashError> {
        let index = at / WORD_SIZE;
        if self.programmed[index] {
            return Err(MockFlashError::NotErased { address: at as u32 });
        }
        self.programmed[index] = true;
        self.data[at..at + WORD_SIZE].iter_mut().zip(word).for_each(|(d, b)| *d &= b);
        self.stats.bytes_written += WORD_SIZE as u64;
        Ok(())
    }

    fn erase_word(&mut self, at: usize) {
        self.data[at..at + WORD_SIZE].fill(0xff);
        self.programmed[at / WORD_SIZE] = false;
    }

    /// The word an erase was cut in: some of its zero bits raised (deterministic in `seed`),
    /// neither the old value nor erased, and not programmable until erased again.
    fn garble_word(&mut self, at: usize, seed: u32) {
        let pattern = 0x9e37_79b9_7f4a_7c15u64.rotate_left(seed % 64).to_le_bytes();
        self.data[at..at + WORD_SIZE].iter_mut().zip(pattern).for_each(|(d, p)| *d |= p);
        self.programmed[at / WORD_SIZE] = true;
    }
}

impl ErrorType for MockFlash {
    type Error = MockFlashError;
}

impl ReadNorFlash for MockFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        if self.off {
            return Err(MockFlashError::PowerCut);
        }
        let at = self.check(offset, bytes.len(), Self::READ_SIZE)?;
        bytes.copy_from_slice(&self.data[at..at + bytes.len()]);
        self.stats.reads += 1;
        self.stats.bytes_read += bytes.len() as u64;
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.data.len()
    }
}

impl NorFlash for MockFlash {
    const WRITE_SIZE: usize = WORD_SIZE;
    const ERASE_SIZE: usize = PAGE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if to < from {
            return Err(MockFlashError::OutOfBounds);
        }
        let start = self.check(from, (to - from) as usize, PAGE_SIZE)?;
        let words = (to - from) as usize / WORD_SIZE;
        let cut = self.next_mutation()?;
        self.stats.erases += ((to - from) as usize / PAGE_SIZE) as u64;
        let done = cut.map_or(words, |seed| seed as usize % (words + 1));
        (0..done).for_each(|w| self.erase_word(start + w * WORD_SIZE));
        match cut {
            None => Ok(()),
            Some(seed) => {
                if done < words {
                    self.garble_word(start + done * WORD_SIZE, seed);
                }
                Err(MockFlashError::PowerCut)
            }
        }
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let start = self.check(offset, bytes.len(), WORD_SIZE)?;
        let cut = self.next_mutation()?;
        self.stats.writes += 1;
        let words = bytes.len() / WORD_SIZE;
        let landed = cut.map_or(words, |seed| seed as usize % (words + 1));
        for (i, word) in bytes.chunks_exact(WORD_SIZE).take(landed).enumerate() {
            self.program_word(start + i * WORD_SIZE, word)?;
        }
        match cut {
            None => Ok(()),
            Some(_) => Err(MockFlashError::PowerCut),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embassy_futures::block_on;

    #[test]
    fn nor_rules_hold() {
        let mut f = MockFlash::new(2);
        block_on(async {
            f.write(8, &[0x0f; 8]).await.unwrap();
            // A programmed double word cannot be programmed again, even to clear more bits.
            assert_eq!(f.write(8, &[0x00; 8]).await, Err(MockFlashError::NotErased { address: 8 }));
            assert_eq!(f.write(4, &[0; 8]).await, Err(MockFlashError::NotAligned));
            assert_eq!(f.write(4096, &[0; 8]).await, Err(MockFlashError::OutOfBounds));
            assert_eq!(f.erase(0, 100).await, Err(MockFlashError::NotAligned));
            let mut b = [0u8; 3];
            f.read(9, &mut b).await.unwrap();
            assert_eq!(b, [0x0f; 3]);
            f.erase(0, 2048).await.unwrap();
            f.write(8, &[0x00; 8]).await.unwrap();
        });
        assert_eq!(f.stats().writes, 3);
        assert_eq!(f.stats().erases, 1);
    }

    #[test]
    fn a_cut_write_lands_a_prefix_then_the_power_is_off() {
        let mut f = MockFlash::new(1);
        f.cut_after(1, 2);
        block_on(async {
            f.write(0, &[0; 8]).await.unwrap();
            assert_eq!(f.write(8, &[0; 32]).await, Err(MockFlashError::PowerCut));
            let mut b = [0u8; 1];
            assert_eq!(f.read(0, &mut b).await, Err(MockFlashError::PowerCut));
        });
        assert!(f.is_off());
        // Seed 2 of 4 words: two land.
        assert_eq!(&f.bytes()[..24], &[0; 24]);
        assert_eq!(&f.bytes()[24..40], &[0xff; 16]);
        let mut next = f.revive();
        block_on(async {
            let mut b = [0u8; 8];
            next.read(0, &mut b).await.unwrap();
            // The landed words stay programmed; the rest can be written.
            assert!(next.write(16, &[1; 8]).await.is_err());
            next.write(24, &[1; 8]).await.unwrap();
        });
    }

    #[test]
    fn a_cut_erase_leaves_a_garbled_word() {
        let mut f = MockFlash::new(1);
        block_on(async {
            f.write(0, &[0; PAGE_SIZE]).await.unwrap();
            f.cut_after(0, 10);
            assert_eq!(f.erase(0, PAGE_SIZE as u32).await, Err(MockFlashError::PowerCut));
        });
        let bytes = f.bytes();
        assert!(bytes[..80].iter().all(|b| *b == 0xff));
        let garbled = &bytes[80..88];
        assert!(garbled != [0xff; 8] && garbled != [0; 8]);
        assert!(bytes[88..].iter().all(|b| *b == 0));
    }
}
