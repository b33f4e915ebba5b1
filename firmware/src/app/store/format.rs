//! The store's format marker: how the store knows its flash area holds what it wrote.
//!
//! The first page of the store's area holds a 16-byte marker (a magic, the layout version and
//! a CRC) and nothing else; the sequential-storage map lives in the pages after it. The marker
//! is checked with plain reads before sequential-storage touches the area, because
//! sequential-storage "repairs" what it cannot read (it erases pages it takes for half-erased):
//! run on another program's data it would destroy some of it and call the rest corrupt.
//!
//! What the store does with each finding (docs/store.md, "Format marker", says why):
//! - **marker there**: its own store; opened as always.
//! - **blank** (every byte of the area erased), or blank but for a marker write that was cut
//!   (the marker's bytes with some bits still set, as a cut program leaves them): formatted at
//!   once by writing the marker. Nothing is erased that held anything.
//! - **anything else** ([`Found::Foreign`]): left alone. Every request is refused with
//!   `StoreError::Foreign` until an explicit `FormatStore` ([`format`]) erases the area.
//!
//! Formatting erases the marker page first, so from the first erase on the area never reads
//! as the store's until the marker is written last; a power cut in between leaves an area that
//! reads as foreign (or blank, if only the marker write was cut), never as a store.

use core::ops::Range;

use embedded_storage_async::nor_flash::NorFlash;

/// The store layout this firmware writes (the marker's version). A different version reads as
/// foreign: a layout change is never read with the old rules.
pub const LAYOUT: u16 = 1;

/// Bytes of the marker at the start of the area.
pub const MARKER_LEN: usize = 16;

/// What the area was found to hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Found {
    /// The marker: the store's own.
    Marked,
    /// Erased (or erased but for a cut marker write): the marker may be written.
    Blank,
    /// Anything else.
    Foreign,
}

/// The marker: magic, layout (LE), two zero bytes, CRC-32 of the 12 bytes before it (LE).
pub fn marker() -> [u8; MARKER_LEN] {
    let mut m = [0u8; MARKER_LEN];
    m[..8].copy_from_slice(b"CHLADNI\x53");
    m[8..10].copy_from_slice(&LAYOUT.to_le_bytes());
    let crc = chladni_shared::icd::frame::CRC32.checksum(&m[..12]);
    m[12..].copy_from_slice(&crc.to_le_bytes());
    m
}

/// Reads what `area` holds (its first page is the marker page). Reads only.
pub async fn examine<F: NorFlash>(flash: &mut F, area: Range<u32>) -> Result<Found, F::Error> {
    let mut head = [0u8; MARKER_LEN];
    flash.read(area.start, &mut head).await?;
    let marker = marker();
    if head == marker {
        return Ok(Found::Marked);
    }
    // A cut program leaves some bits set that it should have cleared, never the reverse.
    let torn_or_erased = head.iter().zip(&marker).all(|(h, m)| h & m == *m);
    if torn_or_erased && is_blank(flash, area.start + MARKER_LEN as u32..area.end).await? {
        Ok(Found::Blank)
    } else {
        Ok(Found::Foreign)
    }
}

/// Whether every byte of `range` reads erased (stops at the first that does not).
pub async fn is_blank<F: NorFlash>(flash: &mut F, range: Range<u32>) -> Result<bool, F::Error> {
    let mut buf = [0u8; 256];
    let mut at = range.start;
    while at < range.end {
        let n = buf.len().min((range.end - at) as usize);
        flash.read(at, &mut buf[..n]).await?;
        // A word at a time (a fresh bank is 256 KiB to read at first boot), bytes at the end.
        let erased = buf[..n].chunks(8).all(|w| match <[u8; 8]>::try_from(w) {
            Ok(word) => u64::from_ne_bytes(word) == u64::MAX,
            Err(_) => w.iter().all(|b| *b == 0xff),
        });
        if !erased {
            return Ok(false);
        }
        at += n as u32;
    }
    Ok(true)
}

/// Writes the marker into a blank area (erasing the marker page first when a cut marker write
/// left bits in it).
pub async fn mark<F: NorFlash>(flash: &mut F, area: Range<u32>) -> Result<(), F::Error> {
    let page = area.start..area.start + F::ERASE_SIZE as u32;
    if !is_blank(flash, page.clone()).await? {
        flash.erase(page.start, page.end).await?;
    }
    flash.write(area.start, &marker()).await
}

/// Erases the whole area, marker page first, skipping pages that already read erased (a page
/// erase takes 22 ms; reading a page, microseconds), then writes the marker.
pub async fn format<F: NorFlash>(flash: &mut F, area: Range<u32>) -> Result<(), F::Error> {
    let page = F::ERASE_SIZE as u32;
    let mut at = area.start;
    while at + page <= area.end {
        if !is_blank(flash, at..at + page).await? {
            flash.erase(at, at + page).await?;
        }
        at += page;
    }
    flash.write(area.start, &marker()).await
}
