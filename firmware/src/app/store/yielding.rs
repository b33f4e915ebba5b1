//! A flash that lets other tasks run between its operations.
//!
//! The drive has its own interrupt executor above the link, so a store request can no
//! longer make a refill late; but the link still shares the thread-mode executor with the
//! sense task (the accelerometer's FIFO), the watchdog's feeding and, on the board, the USB
//! device. A store request can cost thousands of flash reads (the first uploads after boot,
//! while sequential-storage's garbage collection learns where old items are; docs/store.md has
//! the counts), each followed by sequential-storage's item CRC, and neither the QEMU file
//! flash (a semihosting call per operation) nor memory-mapped reads on the board ever wait. So
//! [`Yielding`] yields to the executor every [`OPS_PER_YIELD`] operations: a yield only lets
//! other ready tasks run first, it never cancels the operation (no timeout is ever put around a
//! store call: a cancelled sequential-storage operation leaves the map to repair).

use embassy_futures::yield_now;
use embedded_storage_async::nor_flash::{ErrorType, NorFlash, ReadNorFlash};

/// Flash operations between two yields (each a few microseconds in QEMU, less on the board).
pub const OPS_PER_YIELD: u32 = 8;

/// `F`, yielding to the executor every [`OPS_PER_YIELD`] operations.
pub struct Yielding<F> {
    flash: F,
    ops: u32,
}

impl<F> Yielding<F> {
    /// Wraps `flash`.
    pub const fn new(flash: F) -> Self {
        Self { flash, ops: 0 }
    }

    /// Counts one operation and yields when it is the turn.
    async fn turn(&mut self) {
        self.ops = self.ops.wrapping_add(1);
        if self.ops.is_multiple_of(OPS_PER_YIELD) {
            yield_now().await;
        }
    }
}

impl<F: ErrorType> ErrorType for Yielding<F> {
    type Error = F::Error;
}

impl<F: ReadNorFlash> ReadNorFlash for Yielding<F> {
    const READ_SIZE: usize = F::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.turn().await;
        self.flash.read(offset, bytes).await
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: NorFlash> NorFlash for Yielding<F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.turn().await;
        self.flash.erase(from, to).await
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.turn().await;
        self.flash.write(offset, bytes).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::store::mock_flash::MockFlash;
    use core::future::Future;
    use core::pin::pin;
    use core::task::{Context, Poll, Waker};

    /// Polls `f` to completion; returns how many times it was pending (yielded).
    fn polls<T>(f: impl Future<Output = T>) -> (T, u32) {
        let mut f = pin!(f);
        let mut cx = Context::from_waker(Waker::noop());
        let mut pending = 0;
        loop {
            match f.as_mut().poll(&mut cx) {
                Poll::Ready(v) => return (v, pending),
                Poll::Pending => pending += 1,
            }
        }
    }

    #[test]
    fn yields_every_few_operations_and_changes_nothing() {
        let mut flash = Yielding::new(MockFlash::new(4));
        let data = [0x5au8; 16];
        let ((), pending) = polls(async {
            for i in 0..32u32 {
                flash.write(i * 16, &data).await.unwrap();
            }
        });
        assert_eq!(pending, 32 / OPS_PER_YIELD);
        let mut back = [0u8; 16];
        let (r, _) = polls(flash.read(31 * 16, &mut back));
        assert!(r.is_ok());
        assert_eq!(back, data);
    }
}
