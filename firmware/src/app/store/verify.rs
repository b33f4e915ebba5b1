//! Every program and erase read back and compared.
//!
//! A flash driver may report success for a write that did not land: embassy-stm32 0.6's L4
//! flash interrupt clears the error flags (PROGERR, PGSERR, …) before its `wait_ready` reads
//! them, so a refused program comes back `Ok(())`; a worn page may keep bits it should have
//! cleared. sequential-storage trusts the driver, so such a write would only show later, as a
//! missing or corrupt item. [`Verified`] reads back every byte a write programmed and every
//! page an erase cleared, and fails the operation with [`VerifyError::Mismatch`] (reaching the
//! link as `Refusal::Store(StoreError::Verify)`) the moment the flash disagrees.
//!
//! It also tells the watchdog the store is making progress ([`Progress`]): each flash
//! operation that completes is progress of the task running the store, so a long request (a
//! garbage collection moving a full page and erasing it) keeps checking in, while a flash
//! operation that never completes does not.

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

use crate::app::watchdog::{Progress, Task};

/// Bytes read back at a time (on the stack of the task running the store).
const READ_BACK: usize = 128;

/// A failed operation of a [`Verified`] flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VerifyError<E> {
    /// The flash driver reported an error.
    Flash(E),
    /// The operation reported success but the flash reads back different.
    Mismatch {
        /// Offset (in the flash's own addressing) of the first byte that differs.
        offset: u32,
    },
}

impl<E: NorFlashError> NorFlashError for VerifyError<E> {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            VerifyError::Flash(e) => e.kind(),
            VerifyError::Mismatch { .. } => NorFlashErrorKind::Other,
        }
    }
}

/// `F` with every write and erase read back (module documentation).
pub struct Verified<F> {
    flash: F,
    progress: Option<(&'static dyn Progress, Task)>,
}

impl<F> Verified<F> {
    /// Wraps `flash`.
    pub const fn new(flash: F) -> Self {
        Self { flash, progress: None }
    }

    /// Reports each completed operation to `progress` as progress of `task` (the task the
    /// store runs in).
    pub fn set_progress(&mut self, progress: &'static dyn Progress, task: Task) {
        self.progress = Some((progress, task));
    }

    /// The flash itself.
    pub fn inner(&mut self) -> &mut F {
        &mut self.flash
    }

    /// The flash back.
    pub fn into_inner(self) -> F {
        self.flash
    }

    fn done(&self) {
        if let Some((progress, task)) = self.progress {
            progress.progress(task);
        }
    }
}

impl<F: ReadNorFlash> Verified<F> {
    /// Reads `from..from + len` back in pieces and compares each byte with `expected(i)`.
    async fn compare(
        &mut self,
        from: u32,
        len: usize,
        expected: impl Fn(usize) -> u8,
    ) -> Result<(), VerifyError<F::Error>> {
        let mut buf = [0u8; READ_BACK];
        let mut at = 0;
        while at < len {
            let n = READ_BACK.min(len - at);
            let piece = &mut buf[..n];
            self.flash.read(from + at as u32, piece).await.map_err(VerifyError::Flash)?;
            if let Some(i) = piece.iter().enumerate().position(|(i, b)| *b != expected(at + i)) {
                return Err(VerifyError::Mismatch { offset: from + (at + i) as u32 });
            }
            at += n;
        }
        Ok(())
    }
}

impl<F: ErrorType> ErrorType for Verified<F> {
    type Error = VerifyError<F::Error>;
}

impl<F: ReadNorFlash> ReadNorFlash for Verified<F> {
    const READ_SIZE: usize = F::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.flash.read(offset, bytes).await.map_err(VerifyError::Flash)
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: NorFlash> NorFlash for Verified<F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.flash.erase(from, to).await.map_err(VerifyError::Flash)?;
        let len = to.saturating_sub(from) as usize;
        let checked = self.compare(from, len, |_| 0xff).await;
        self.done();
        checked
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.flash.write(offset, bytes).await.map_err(VerifyError::Flash)?;
        let checked = self.compare(offset, bytes.len(), |i| bytes[i]).await;
        self.done();
        checked
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::store::mock_flash::MockFlash;
    use embassy_futures::block_on;

    #[test]
    fn a_dropped_write_and_a_refused_program_are_caught_by_reading_back() {
        let mut flash = Verified::new(MockFlash::new(2));
        block_on(async {
            flash.write(16, &[0x5a; 24]).await.unwrap();
            flash.inner().drop_write_after(0);
            // The driver says yes, nothing landed: the first byte differs.
            assert_eq!(flash.write(64, &[1; 16]).await, Err(VerifyError::Mismatch { offset: 64 }));
            flash.write(64, &[1; 16]).await.unwrap();
            // A program the chip refuses is a driver error, not a mismatch.
            let refused = flash.write(16, &[0x0f; 8]).await;
            assert!(matches!(refused, Err(VerifyError::Flash(_))), "{refused:?}");
            flash.erase(0, 2048).await.unwrap();
            flash.write(16, &[0x0f; 8]).await.unwrap();
        });
    }

    #[test]
    fn an_erase_that_leaves_a_bit_is_caught() {
        let mut flash = Verified::new(MockFlash::new(2));
        block_on(async {
            flash.write(2048 + 400, &[0; 8]).await.unwrap();
            flash.inner().drop_erase_after(0);
            assert_eq!(flash.erase(2048, 4096).await, Err(VerifyError::Mismatch { offset: 2448 }));
            flash.erase(2048, 4096).await.unwrap();
        });
    }
}
