//! Flash bank 2 for QEMU, backed by a host file through semihosting file I/O.
//!
//! QEMU's STM32L4 flash interface reports success for erase and program and changes nothing,
//! so plans and configuration would vanish at every restart. This driver keeps the bank in a
//! host file instead (`chladni emulator --flash-file FILE` creates it, 512 KiB of 0xFF) and
//! behaves like the real bank: 2 KiB erase pages, 8-byte program units, and programming can
//! only clear bits (new = old AND data), so code that works here respects NOR rules there.
//!
//! The file's path reaches the firmware on the semihosting command line as `flash=PATH`.
//!
//! The plan store takes an async NorFlash: the async traits below run the blocking file
//! operation to completion (a semihosting call is a few microseconds of host I/O), then wait
//! out the time the real chip would be busy ([`crate::app::store::chip`]: 82 µs a double
//! word, 22 ms a page erase) on a timer, as embassy-stm32's async flash waits for the end of
//! operation interrupt: other tasks run meanwhile, and the emulated firmware sees the chip's
//! timing. The time driver ticks in milliseconds, so the waits are owed in microseconds and
//! paid in whole ticks: over a request the total matches the chip's.

use cortex_m_semihosting::{nr, syscall};

use crate::app::store::chip;
use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash, check_erase, check_read,
    check_write,
};

/// Size of the bank (STM32L475VG bank 2).
pub const CAPACITY: usize = 512 * 1024;
/// Erase page size.
pub const PAGE_SIZE: usize = 2048;

/// What went wrong with the backing file or the request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileFlashError {
    /// Offset or length out of the bank, or not aligned to the program/erase unit.
    Request(NorFlashErrorKind),
    /// A semihosting file operation failed.
    Io,
}

impl defmt::Format for FileFlashError {
    fn format(&self, f: defmt::Formatter) {
        match self {
            FileFlashError::Request(NorFlashErrorKind::NotAligned) => {
                defmt::write!(f, "not aligned")
            }
            FileFlashError::Request(NorFlashErrorKind::OutOfBounds) => {
                defmt::write!(f, "out of bounds")
            }
            FileFlashError::Request(_) => defmt::write!(f, "bad request"),
            FileFlashError::Io => defmt::write!(f, "host file I/O failed"),
        }
    }
}

impl NorFlashError for FileFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FileFlashError::Request(kind) => *kind,
            FileFlashError::Io => NorFlashErrorKind::Other,
        }
    }
}

/// The flash bank, kept in a host file.
pub struct FileFlash {
    fd: usize,
    /// Chip time not yet waited out, µs.
    owed_us: u64,
}

impl FileFlash {
    /// Opens the file read/write (it must exist and be exactly [`CAPACITY`] bytes).
    pub fn open(path: &str) -> Result<Self, FileFlashError> {
        let mut name = [0u8; 256];
        let bytes = path.as_bytes();
        if bytes.len() >= name.len() {
            return Err(FileFlashError::Io);
        }
        name[..bytes.len()].copy_from_slice(bytes); // NUL-terminated for the host
        // SAFETY: semihosting OPEN reads `len` bytes of `name`, which lives across the call.
        let fd = unsafe { syscall!(OPEN, name.as_ptr(), nr::open::RW_BINARY, bytes.len()) };
        if fd as isize == -1 {
            return Err(FileFlashError::Io);
        }
        // SAFETY: FLEN only reads the handle.
        let len = unsafe { syscall!(FLEN, fd) };
        if len != CAPACITY {
            // SAFETY: CLOSE only reads the handle.
            unsafe { syscall!(CLOSE, fd) };
            return Err(FileFlashError::Io);
        }
        Ok(Self { fd, owed_us: 0 })
    }

    fn seek(&mut self, offset: u32) -> Result<(), FileFlashError> {
        // SAFETY: SEEK only reads its two word arguments.
        match unsafe { syscall!(SEEK, self.fd, offset as usize) } {
            0 => Ok(()),
            _ => Err(FileFlashError::Io),
        }
    }

    fn read_raw(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FileFlashError> {
        self.seek(offset)?;
        // SAFETY: READ writes at most `len` bytes into `bytes`, which is borrowed mutably.
        match unsafe { syscall!(READ, self.fd, bytes.as_mut_ptr(), bytes.len()) } {
            0 => Ok(()),
            _ => Err(FileFlashError::Io),
        }
    }

    fn write_raw(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FileFlashError> {
        self.seek(offset)?;
        // SAFETY: WRITE reads `len` bytes of `bytes`.
        match unsafe { syscall!(WRITE, self.fd, bytes.as_ptr(), bytes.len()) } {
            0 => Ok(()),
            _ => Err(FileFlashError::Io),
        }
    }
}

impl ErrorType for FileFlash {
    type Error = FileFlashError;
}

impl ReadNorFlash for FileFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        check_read(self, offset, bytes.len()).map_err(FileFlashError::Request)?;
        self.read_raw(offset, bytes)
    }

    fn capacity(&self) -> usize {
        CAPACITY
    }
}

impl NorFlash for FileFlash {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = PAGE_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        check_erase(self, from, to).map_err(FileFlashError::Request)?;
        let erased = [0xffu8; 256];
        let mut at = from;
        while at < to {
            self.write_raw(at, &erased)?;
            at += erased.len() as u32;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        check_write(self, offset, bytes.len()).map_err(FileFlashError::Request)?;
        // NOR programming only clears bits.
        let mut chunk = [0u8; 256];
        for (i, data) in bytes.chunks(chunk.len()).enumerate() {
            let at = offset + (i * chunk.len()) as u32;
            let old = &mut chunk[..data.len()];
            self.read_raw(at, old)?;
            old.iter_mut().zip(data).for_each(|(o, d)| *o &= d);
            self.write_raw(at, old)?;
        }
        Ok(())
    }
}

/// The value of `key=` on the semihosting command line, copied into `out`.
pub fn cmdline_arg<'a>(key: &str, out: &'a mut [u8; 256]) -> Option<&'a str> {
    let mut block = [out.as_mut_ptr() as usize, out.len()];
    // SAFETY: GET_CMDLINE writes at most `block[1]` bytes into `out` and the length into block.
    if unsafe { cortex_m_semihosting::syscall1(nr::GET_CMDLINE, block.as_mut_ptr() as usize) } != 0
    {
        return None;
    }
    let line = core::str::from_utf8(&out[..block[1].min(out.len())]).ok()?;
    line.split(' ').find_map(|word| word.strip_prefix(key)?.strip_prefix('='))
}

impl embedded_storage_async::nor_flash::ReadNorFlash for FileFlash {
    const READ_SIZE: usize = <Self as ReadNorFlash>::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        ReadNorFlash::read(self, offset, bytes)
    }

    fn capacity(&self) -> usize {
        CAPACITY
    }
}

impl embedded_storage_async::nor_flash::NorFlash for FileFlash {
    const WRITE_SIZE: usize = <Self as NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize = <Self as NorFlash>::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        NorFlash::erase(self, from, to)?;
        self.busy(chip::erase_us((to - from) as usize / PAGE_SIZE)).await;
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        NorFlash::write(self, offset, bytes)?;
        self.busy(chip::program_us(bytes.len())).await;
        Ok(())
    }
}

impl FileFlash {
    /// Waits out `us` of chip time, in whole time-driver ticks (the rest is owed to the next
    /// operation).
    async fn busy(&mut self, us: u64) {
        self.owed_us += us;
        let tick_us = 1_000_000 / embassy_time::TICK_HZ;
        let ticks = self.owed_us / tick_us;
        if ticks > 0 {
            self.owed_us -= ticks * tick_us;
            embassy_time::Timer::after_ticks(ticks).await;
        }
    }
}
