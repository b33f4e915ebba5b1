//! The one in-memory NOR flash model, shaped like the STM32L475's bank 2, with power cuts: the
//! store's tests and the plan-store fuzz target (through the `mock-flash` feature) both run on
//! it.
//!
//! What it keeps of the real part: 2 KiB erase pages, 8-byte (double-word) programming, reads
//! of any length, erase sets every bit, programming only clears bits. Which programs are
//! allowed is a [`Rule`]:
//! - [`Rule::Stm32l4`], the default: RM0351 (STM32L4x5/L4x6 reference manual), FLASH_SR bit
//!   PROGERR: "set by hardware when a double-word address to be programmed contains a value
//!   different from '0xFFFF FFFF' before programming, except if the data to write is
//!   '0x0000 0000'", and its programming section: programming a previously programmed address
//!   is not allowed except if the data to write is full zero. Here: a double word may be
//!   programmed when all its 64 bits read as ones, or when the new data is all zeros (over
//!   anything); anything else is refused as the chip refuses it (PROGERR: the double word is
//!   left as it was, and so are the ones after it in the same call; those before it landed).
//!   The manual's wording is about the word's contents, so a double word programmed with all
//!   ones reads erased and may be programmed again; the chip's hidden ECC bits are not modelled.
//! - [`Rule::OncePerErase`]: stricter, each double word is programmed at most once between
//!   erases, zeros included (for checking that code does not rely on the zeros exception).
//!
//! A refused program is also counted as a *violation* ([`MockFlash::violation`]): sequential-
//! storage and the store are meant never to do one, so tests and the fuzz target assert that.
//!
//! Power cuts: [`MockFlash::cut_after`] arms a cut after a number of further operations,
//! counted as [`Cuts`] says: per call ([`Cuts::PerCall`]: one write or erase call, the store
//! tests' exhaustive cut enumeration) or per word ([`Cuts::PerWord`]: each double word
//! programmed and each page erased, so a cut can fall at any word of a long write; the fuzz
//! target). The cut operation is left partial: a write lands a prefix of its double words and
//! tears the one where it stopped (some of the bits it should clear stay set), an erase erases a
//! prefix of its words and garbles the word where it stopped (some bits raised towards the
//! erased state) leaving the rest as it was; the call reports an error, and from then on every
//! operation, reads included, fails: the controller is off. [`MockFlash::revive`] (or
//! [`MockFlash::reboot`] in place) gives the flash as the next boot finds it.
//!
//! Erases progress from the start of the range, as in sequential-storage's own shutoff model:
//! its page markers (first and last word of a page) are how it recognises a page whose erase was
//! cut. A real interrupted erase may leave any bits anywhere in the page; that is not modelled
//! (see docs/store.md).
//!
//! A glitch ([`MockFlash::glitch_after`]) is a write or erase call that fails and changes
//! nothing, with the power staying on, like a transient programming error. A dropped write
//! ([`MockFlash::drop_write_after`]) or erase ([`MockFlash::drop_erase_after`]) reports
//! success and changes nothing: what a driver that loses the chip's error flags returns for a
//! refused program (embassy-stm32 0.6 on the L4), which only reading back can catch.
//!
//! Time is simulated, never slept: each program and erase adds the chip's time
//! ([`super::chip`]: 82 µs a double word, 22 ms a page) to [`FlashStats::busy_us`], and a
//! [`MockFlash::clock`] handle reads the total, so a test can tell how long a request would
//! keep the flash busy (the fuzz targets run this model millions of times).
//!
//! Every operation is counted ([`FlashStats`]) so tests can report what an upload costs.

use std::cell::RefCell;
use std::rc::Rc;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::vec;
use std::vec::Vec;

use super::chip;
use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// Erase page, bytes (STM32L475 bank 2).
pub const PAGE_SIZE: usize = 2048;
/// Programming unit, bytes (a double word).
pub const WORD_SIZE: usize = 8;
/// Pages in the store's real range (512 KiB).
pub const BANK_PAGES: usize = 256;

/// Which programs of a double word the flash allows (module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rule {
    /// RM0351's PROGERR rule: into a double word reading all ones, or all zeros over anything.
    Stm32l4,
    /// Each double word at most once between erases, zeros included.
    OncePerErase,
}

/// What one step of the power-cut count is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cuts {
    /// One write or erase call; the cut one is done up to a point its seed picks.
    PerCall,
    /// One double word programmed, or one page erased.
    PerWord,
}

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
    /// Simulated time the chip was busy programming and erasing, µs ([`super::chip`]).
    pub busy_us: u64,
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
            busy_us: self.busy_us - earlier.busy_us,
        }
    }
}

impl core::fmt::Display for FlashStats {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{} reads ({} B), {} writes ({} B), {} page erases, {:.1} ms busy",
            self.reads,
            self.bytes_read,
            self.writes,
            self.bytes_written,
            self.erases,
            self.busy_us as f64 / 1e3
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
    /// The [`Rule`] refuses programming the double word at this address (the L4's PROGERR).
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
    /// Operations (as [`Cuts`] counts them) that still complete before the cut one.
    remaining: u64,
    /// Chooses how much of the cut operation lands, and the torn word's bits.
    seed: u32,
}

/// The flash. Cloning it copies its contents (and its armed cut, if any).
#[derive(Debug, Clone)]
pub struct MockFlash {
    data: Vec<u8>,
    /// Per double word: programmed since its last erase (for [`Rule::OncePerErase`]).
    programmed: Vec<bool>,
    rule: Rule,
    cuts: Cuts,
    stats: FlashStats,
    cut: Option<Cut>,
    /// Writes or erases until the glitch.
    glitch: Option<u64>,
    /// Writes until the one silently dropped.
    drop_write: Option<u64>,
    /// Erases until the one silently dropped.
    drop_erase: Option<u64>,
    /// Simulated time since the flash was made, µs (kept across reboots).
    clock: Arc<AtomicU64>,
    off: bool,
    /// The first program the rule refused: its address.
    violation: Option<u32>,
}

/// Counts down an armed one-shot fault; true (and disarmed) when it is its turn.
fn take_turn(armed: &mut Option<u64>) -> bool {
    match armed {
        Some(0) => {
            *armed = None;
            true
        }
        Some(n) => {
            *n -= 1;
            false
        }
        None => false,
    }
}

/// A word of noise from `seed`: which bits a torn or garbled word gets wrong.
fn noise(seed: u32) -> [u8; WORD_SIZE] {
    0x9e37_79b9_7f4a_7c15u64.rotate_left(seed % 64).to_le_bytes()
}

impl MockFlash {
    /// An erased flash of `pages` pages, the L4's rule, a cut per call.
    pub fn new(pages: usize) -> Self {
        Self::with(pages, Rule::Stm32l4, Cuts::PerCall)
    }

    /// An erased flash of `pages` pages with the given programming rule and cut granularity.
    pub fn with(pages: usize, rule: Rule, cuts: Cuts) -> Self {
        let bytes = pages * PAGE_SIZE;
        Self {
            data: vec![0xff; bytes],
            programmed: vec![false; bytes / WORD_SIZE],
            rule,
            cuts,
            stats: FlashStats::default(),
            cut: None,
            glitch: None,
            drop_write: None,
            drop_erase: None,
            clock: Arc::new(AtomicU64::new(0)),
            off: false,
            violation: None,
        }
    }

    /// The simulated clock, µs: advanced by every program and erase, never by reads (a read
    /// takes nanoseconds on the chip). The handle stays valid while the store owns the flash.
    pub fn clock(&self) -> Arc<AtomicU64> {
        self.clock.clone()
    }

    /// Arms a dropped write: `ops` more write calls complete, the next one reports success and
    /// changes nothing.
    pub fn drop_write_after(&mut self, ops: u64) {
        self.drop_write = Some(ops);
    }

    /// Arms a dropped erase: `ops` more erase calls complete, the next one reports success and
    /// changes nothing.
    pub fn drop_erase_after(&mut self, ops: u64) {
        self.drop_erase = Some(ops);
    }

    /// Counts the chip's busy time.
    fn busy(&mut self, us: u64) {
        self.stats.busy_us += us;
        self.clock.fetch_add(us, Ordering::Relaxed);
    }

    /// The operations counted so far.
    pub fn stats(&self) -> FlashStats {
        self.stats
    }

    /// Arms a power cut: `ops` more operations (calls or words, as [`Cuts`] says) complete,
    /// the next one is cut (partly done, as `seed` picks), and everything after fails.
    pub fn cut_after(&mut self, ops: u64, seed: u32) {
        self.cut = Some(Cut { remaining: ops, seed });
    }

    /// Whether the power has been cut.
    pub fn is_off(&self) -> bool {
        self.off
    }

    /// The first program the [`Rule`] refused since this flash was made (its address).
    pub fn violation(&self) -> Option<u32> {
        self.violation
    }

    /// The flash as the next boot finds it: same contents, power on, no cut or glitch armed,
    /// counters from zero.
    pub fn revive(&self) -> MockFlash {
        let mut next = self.clone();
        next.reboot();
        next
    }

    /// [`MockFlash::revive`] in place.
    pub fn reboot(&mut self) {
        self.stats = FlashStats::default();
        self.cut = None;
        self.glitch = None;
        self.drop_write = None;
        self.drop_erase = None;
        self.off = false;
    }

    /// Arms a glitch: `ops` more write or erase calls complete, the next one fails and
    /// changes nothing, and the flash goes on working.
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

    /// Starts a write or erase call of `units` cut units (words or pages): fails if the power
    /// is off or a glitch is due; else `Some((done, seed))` if the armed cut falls inside it
    /// (`done` units complete, the next one is torn; `done == units`: all landed, then the
    /// power failed).
    fn begin(&mut self, units: usize) -> Result<Option<(usize, u32)>, MockFlashError> {
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
        let Some(cut) = &mut self.cut else { return Ok(None) };
        let (step, done) = match self.cuts {
            Cuts::PerCall => (1, cut.seed as usize % (units + 1)),
            Cuts::PerWord => (units as u64, cut.remaining as usize),
        };
        if cut.remaining >= step {
            cut.remaining -= step;
            return Ok(None);
        }
        let seed = cut.seed;
        self.cut = None;
        self.off = true;
        Ok(Some((done, seed)))
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

    /// Whether the rule lets `word` be programmed at `at`.
    fn may_program(&self, at: usize, word: &[u8]) -> bool {
        match self.rule {
            Rule::Stm32l4 => {
                self.data[at..at + WORD_SIZE].iter().all(|&b| b == 0xff)
                    || word.iter().all(|&b| b == 0)
            }
            Rule::OncePerErase => !self.programmed[at / WORD_SIZE],
        }
    }

    /// Programs one double word (bits only clear), or refuses it by the rule.
    fn program_word(&mut self, at: usize, word: &[u8]) -> Result<(), MockFlashError> {
        if !self.may_program(at, word) {
            self.violation.get_or_insert(at as u32);
            return Err(MockFlashError::NotErased { address: at as u32 });
        }
        self.programmed[at / WORD_SIZE] = true;
        self.data[at..at + WORD_SIZE].iter_mut().zip(word).for_each(|(d, b)| *d &= b);
        self.stats.bytes_written += WORD_SIZE as u64;
        Ok(())
    }

    /// The word a cut write stopped in: some of the bits it should clear stay set.
    fn tear_word(&mut self, at: usize, word: &[u8], seed: u32) {
        let pattern = noise(seed);
        let cells = self.data[at..at + WORD_SIZE].iter_mut().zip(word).zip(pattern);
        cells.for_each(|((d, b), p)| *d &= b | p);
        self.programmed[at / WORD_SIZE] = true;
    }

    fn erase_word(&mut self, at: usize) {
        self.data[at..at + WORD_SIZE].fill(0xff);
        self.programmed[at / WORD_SIZE] = false;
    }

    /// The word an erase was cut in: some of its zero bits raised (deterministic in `seed`),
    /// neither the old value nor erased, and not programmable until erased again.
    fn garble_word(&mut self, at: usize, seed: u32) {
        let pattern = noise(seed);
        self.data[at..at + WORD_SIZE].iter_mut().zip(pattern).for_each(|(d, p)| *d |= p);
        self.programmed[at / WORD_SIZE] = true;
    }

    fn read_now(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), MockFlashError> {
        if self.off {
            return Err(MockFlashError::PowerCut);
        }
        let at = self.check(offset, bytes.len(), 1)?;
        bytes.copy_from_slice(&self.data[at..at + bytes.len()]);
        self.stats.reads += 1;
        self.stats.bytes_read += bytes.len() as u64;
        Ok(())
    }

    fn erase_now(&mut self, from: u32, to: u32) -> Result<(), MockFlashError> {
        if to < from {
            return Err(MockFlashError::OutOfBounds);
        }
        let start = self.check(from, (to - from) as usize, PAGE_SIZE)?;
        let pages = (to - from) as usize / PAGE_SIZE;
        if self.off {
            return Err(MockFlashError::PowerCut);
        }
        if take_turn(&mut self.drop_erase) {
            self.busy(chip::erase_us(pages));
            return Ok(());
        }
        let words = pages * (PAGE_SIZE / WORD_SIZE);
        let cut = self.begin(match self.cuts {
            Cuts::PerCall => words,
            Cuts::PerWord => pages,
        })?;
        // Per word, the cut names a page; how far into it the erase got comes from the seed.
        let cut = cut.map(|(done, seed)| match self.cuts {
            Cuts::PerCall => (done, seed),
            Cuts::PerWord => (done * (PAGE_SIZE / WORD_SIZE) + seed as usize % 256, seed),
        });
        let done = cut.map_or(words, |(done, _)| done.min(words));
        let erased_pages = done.div_ceil(PAGE_SIZE / WORD_SIZE);
        self.stats.erases += erased_pages as u64;
        self.busy(chip::erase_us(erased_pages));
        (0..done).for_each(|w| self.erase_word(start + w * WORD_SIZE));
        match cut {
            None => Ok(()),
            Some((_, seed)) => {
                if done < words {
                    self.garble_word(start + done * WORD_SIZE, seed);
                }
                Err(MockFlashError::PowerCut)
            }
        }
    }

    fn write_now(&mut self, offset: u32, bytes: &[u8]) -> Result<(), MockFlashError> {
        let start = self.check(offset, bytes.len(), WORD_SIZE)?;
        let words = bytes.len() / WORD_SIZE;
        if self.off {
            return Err(MockFlashError::PowerCut);
        }
        if take_turn(&mut self.drop_write) {
            self.stats.writes += 1;
            self.busy(chip::program_us(bytes.len()));
            return Ok(());
        }
        let cut = self.begin(words)?;
        self.stats.writes += 1;
        let landed = cut.map_or(words, |(done, _)| done);
        self.busy(chip::program_us(landed * WORD_SIZE));
        for (i, word) in bytes.chunks_exact(WORD_SIZE).take(landed).enumerate() {
            self.program_word(start + i * WORD_SIZE, word)?;
        }
        match cut {
            None => Ok(()),
            Some((done, seed)) => {
                if done < words {
                    let at = start + done * WORD_SIZE;
                    let word = &bytes[done * WORD_SIZE..(done + 1) * WORD_SIZE];
                    if self.may_program(at, word) {
                        self.tear_word(at, word, seed);
                    }
                }
                Err(MockFlashError::PowerCut)
            }
        }
    }
}

impl ErrorType for MockFlash {
    type Error = MockFlashError;
}

impl ReadNorFlash for MockFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.read_now(offset, bytes)
    }

    fn capacity(&self) -> usize {
        self.data.len()
    }
}

impl NorFlash for MockFlash {
    const WRITE_SIZE: usize = WORD_SIZE;
    const ERASE_SIZE: usize = PAGE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.erase_now(from, to)
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.write_now(offset, bytes)
    }
}

/// A [`MockFlash`] shared between the store that owns a handle and a harness that cuts the
/// power and looks at the bytes (single-threaded; no borrow is held across an await).
#[derive(Debug, Clone)]
pub struct SharedFlash(pub Rc<RefCell<MockFlash>>);

impl SharedFlash {
    /// Shares `flash`.
    pub fn new(flash: MockFlash) -> Self {
        Self(Rc::new(RefCell::new(flash)))
    }

    /// The flash itself, for a moment.
    pub fn with<R>(&self, f: impl FnOnce(&mut MockFlash) -> R) -> R {
        f(&mut self.0.borrow_mut())
    }
}

impl ErrorType for SharedFlash {
    type Error = MockFlashError;
}

impl ReadNorFlash for SharedFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.0.borrow_mut().read_now(offset, bytes)
    }

    fn capacity(&self) -> usize {
        self.0.borrow().data.len()
    }
}

impl NorFlash for SharedFlash {
    const WRITE_SIZE: usize = WORD_SIZE;
    const ERASE_SIZE: usize = PAGE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.0.borrow_mut().erase_now(from, to)
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.0.borrow_mut().write_now(offset, bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embassy_futures::block_on;

    #[test]
    fn the_l4_rule_allows_erased_words_and_zeros_over_anything() {
        let mut f = MockFlash::new(2);
        block_on(async {
            f.write(8, &[0x0f; 8]).await.unwrap();
            // A double word that does not read all ones takes only zeros (RM0351 PROGERR).
            assert_eq!(f.write(8, &[0x07; 8]).await, Err(MockFlashError::NotErased { address: 8 }));
            assert_eq!(f.violation(), Some(8));
            f.write(8, &[0x00; 8]).await.unwrap();
            // All ones programmed reads erased: the manual's rule is about the contents.
            f.write(16, &[0xff; 8]).await.unwrap();
            f.write(16, &[0x12; 8]).await.unwrap();
            assert_eq!(f.write(4, &[0; 8]).await, Err(MockFlashError::NotAligned));
            assert_eq!(f.write(4096, &[0; 8]).await, Err(MockFlashError::OutOfBounds));
            assert_eq!(f.erase(0, 100).await, Err(MockFlashError::NotAligned));
            let mut b = [0u8; 3];
            f.read(17, &mut b).await.unwrap();
            assert_eq!(b, [0x12; 3]);
            f.erase(0, 2048).await.unwrap();
            f.write(8, &[0x5a; 8]).await.unwrap();
        });
        assert_eq!(f.stats().writes, 6);
        assert_eq!(f.stats().erases, 1);
    }

    #[test]
    fn once_per_erase_refuses_even_zeros() {
        let mut f = MockFlash::with(1, Rule::OncePerErase, Cuts::PerCall);
        block_on(async {
            f.write(0, &[0xff; 8]).await.unwrap();
            assert_eq!(f.write(0, &[0; 8]).await, Err(MockFlashError::NotErased { address: 0 }));
            f.erase(0, 2048).await.unwrap();
            f.write(0, &[0; 8]).await.unwrap();
        });
        assert_eq!(f.violation(), Some(0));
    }

    #[test]
    fn a_cut_write_lands_a_prefix_tears_a_word_then_the_power_is_off() {
        let mut f = MockFlash::new(1);
        f.cut_after(1, 2);
        block_on(async {
            f.write(0, &[0; 8]).await.unwrap();
            assert_eq!(f.write(8, &[0; 32]).await, Err(MockFlashError::PowerCut));
            let mut b = [0u8; 1];
            assert_eq!(f.read(0, &mut b).await, Err(MockFlashError::PowerCut));
        });
        assert!(f.is_off());
        // Seed 2 of 4 words: two land, the third is torn (some bits stay set), the fourth not.
        assert_eq!(&f.bytes()[..24], &[0; 24]);
        let torn = &f.bytes()[24..32];
        assert!(torn != [0; 8] && torn != [0xff; 8], "{torn:?}");
        assert_eq!(&f.bytes()[32..40], &[0xff; 8]);
        let mut next = f.revive();
        block_on(async {
            let mut b = [0u8; 8];
            next.read(0, &mut b).await.unwrap();
            // The torn word takes only zeros; the erased one anything.
            assert!(next.write(24, &[1; 8]).await.is_err());
            next.write(24, &[0; 8]).await.unwrap();
            next.write(32, &[1; 8]).await.unwrap();
        });
    }

    #[test]
    fn per_word_cuts_count_words_and_pages() {
        let mut f = MockFlash::with(2, Rule::Stm32l4, Cuts::PerWord);
        f.cut_after(5, 7);
        block_on(async {
            f.write(0, &[0; 24]).await.unwrap(); // words 0..3
            assert_eq!(f.write(24, &[0; 32]).await, Err(MockFlashError::PowerCut));
        });
        // Three more words complete (ops 3, 4), the sixth (at 40) is torn, the seventh untouched.
        assert_eq!(&f.bytes()[..40], &[0; 40]);
        assert_ne!(&f.bytes()[40..48], &[0; 8]);
        assert_eq!(&f.bytes()[48..56], &[0xff; 8]);
        let mut f = f.revive();
        f.cut_after(1, 3);
        let erased = block_on(f.erase(0, 2 * PAGE_SIZE as u32));
        assert_eq!(erased, Err(MockFlashError::PowerCut));
        // The first page erased whole; the second was as it was (erased).
        assert!(f.bytes()[..PAGE_SIZE].iter().all(|b| *b == 0xff));
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
