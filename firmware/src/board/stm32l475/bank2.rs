//! Flash bank 2 (0x0808_0000, 512 KiB) as the plan store's `NorFlash`: embassy-stm32's async
//! bank 2 region, plus two things the L4 needs that embassy-stm32 0.6.0 does not do.
//!
//! - **Data cache off while programming or erasing.** STM32L47x/L48x erratum "Data cache might
//!   be corrupted during Flash memory read-while-write operation" (ES0250): while bank 2 is
//!   programmed or erased, the code keeps running from bank 1 and its literal loads go through
//!   the ART data cache, which can be corrupted (reported on these chips as bus and alignment
//!   faults in interrupt handlers that ran during a bank 2 write). ST's workaround, also what
//!   ST's HAL and Zephyr do, and what embassy-stm32 added after 0.6.0: clear FLASH_ACR.DCEN for
//!   the operation, then reset the data cache (DCRST) and enable it again. The reset also drops
//!   any bank 2 bytes cached before the erase or write, so reads see the new contents. The
//!   instruction cache stays on: no code lives in bank 2.
//! - **Uncorrectable ECC errors are data, not crashes.** Every 64-bit flash word carries ECC; a
//!   word whose programming was cut short by a power loss can read back with two bad bits, and
//!   the L4 raises an NMI for that (FLASH_ECCR.ECCD). The plan store is built to survive power
//!   cuts: it reads such words like any other garbage and rejects them by CRC. So the NMI handler
//!   ([`super::failsafe`]) asks [`absorb_ecc_error`] first: an error in bank 2 is cleared and
//!   counted, and the read goes on with the bits as read; any other NMI parks the drive.
//!
//! What it does not do: report a refused program. embassy-stm32 0.6's flash interrupt clears
//! every error flag (PROGERR, PGSERR, …) before its `wait_ready` reads the status, so a program
//! the chip refused comes back `Ok(())`. The plan store reads back every write and erase
//! (`app::store::verify`) and refuses the request with `Store(Verify)` when the flash
//! disagrees, so such an error is caught there, on every board, rather than here.

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_stm32::flash;
use embedded_storage_async::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use stm32_metapac as pac;

/// embassy-stm32's async bank 2 region (offsets relative to 0x0808_0000).
type Region = flash::Bank2Region<'static, flash::Async>;

/// Uncorrectable ECC errors met in bank 2 since boot (written by the NMI handler).
static ECC_ERRORS: AtomicU32 = AtomicU32::new(0);

/// Flash bank 2 for the plan store (see the module documentation).
pub struct Bank2 {
    region: Region,
}

impl Bank2 {
    /// Wraps embassy-stm32's bank 2 region.
    pub(super) fn new(region: Region) -> Self {
        Self { region }
    }

    /// Uncorrectable ECC errors met while reading bank 2 since boot (each read as it was).
    pub fn ecc_errors() -> u32 {
        ECC_ERRORS.load(Ordering::Relaxed)
    }
}

/// Called first by the NMI handler: if the NMI is an uncorrectable ECC error in bank 2 (not in
/// bank 1, where the program is, nor in system memory), clears it, counts it and returns true:
/// the interrupted read then completes with the bits as read. False for any other NMI.
pub(super) fn absorb_ecc_error() -> bool {
    let eccr = pac::FLASH.eccr().read();
    if !(eccr.eccd() && eccr.bk_ecc() && !eccr.sysf_ecc()) {
        return false;
    }
    // ECCD is write-1-to-clear; writing 0 to ECCC leaves that flag alone.
    pac::FLASH.eccr().modify(|w| {
        w.set_eccd(true);
        w.set_eccc(false);
    });
    ECC_ERRORS.fetch_add(1, Ordering::Relaxed);
    true
}

/// Clears stale ECC flags before a bank 2 read: while ECCC or ECCD is set, the hardware does
/// not update the error's bank and address (RM0351, FLASH_ECCR), and [`absorb_ecc_error`] needs
/// them to tell a bank 2 error from a program error.
fn clear_ecc_flags() {
    pac::FLASH.eccr().modify(|w| {
        w.set_eccd(true);
        w.set_eccc(true);
    });
}

/// The data cache switched off for as long as this lives (a flash program or erase, however it
/// ends, cancellation included); dropped, it resets the cache and switches it back on if it was.
struct DataCacheOff {
    was_on: bool,
}

impl DataCacheOff {
    fn new() -> Self {
        let was_on = pac::FLASH.acr().read().dcen();
        if was_on {
            pac::FLASH.acr().modify(|w| w.set_dcen(false));
        }
        Self { was_on }
    }
}

impl Drop for DataCacheOff {
    fn drop(&mut self) {
        if self.was_on {
            // DCRST only acts while DCEN = 0 (RM0351, FLASH_ACR).
            pac::FLASH.acr().modify(|w| w.set_dcrst(true));
            pac::FLASH.acr().modify(|w| w.set_dcrst(false));
            pac::FLASH.acr().modify(|w| w.set_dcen(true));
        }
    }
}

impl ErrorType for Bank2 {
    type Error = flash::Error;
}

impl ReadNorFlash for Bank2 {
    const READ_SIZE: usize = <Region as ReadNorFlash>::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        clear_ecc_flags();
        let before = Bank2::ecc_errors();
        self.region.read(offset, bytes).await?;
        let errors = Bank2::ecc_errors().wrapping_sub(before);
        if errors > 0 {
            defmt::warn!(
                "flash bank 2: {=u32} ECC error(s) in {=usize} bytes at {=u32:#x}, read as is",
                errors,
                bytes.len(),
                offset
            );
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.region.0.size as usize
    }
}

impl NorFlash for Bank2 {
    const WRITE_SIZE: usize = <Region as NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize = <Region as NorFlash>::ERASE_SIZE;

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let _cache = DataCacheOff::new();
        self.region.write(offset, bytes).await
    }

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        // embassy-stm32 checks writes against the region but not erases: past the end of the
        // bank (the end of flash) its page lookup panics.
        if from > to || to as usize > self.capacity() {
            return Err(flash::Error::Size);
        }
        let _cache = DataCacheOff::new();
        self.region.erase(from, to).await
    }
}
