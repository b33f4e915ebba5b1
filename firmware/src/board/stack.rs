//! The stack's high water, by painting: at boot every word of the stack region below the
//! current stack pointer is filled with [`PAINT`]; later, [`high_water`] counts the words from
//! the region's bottom that still hold it. The stack grows down, so the first overwritten word
//! marks the deepest the stack (thread mode, the drive's interrupt executor and every other
//! handler, all on the main stack) has ever reached.
//!
//! The region is memory.x's SRAM2, `_stack_end`..`_stack_start` (32 KiB), for both boards.
//! A frame that reserves stack but never writes part of it would be missed; Rust frames write
//! what they use, so in practice the figure is exact to a few words.

/// The word painted into the unused stack.
pub const PAINT: u32 = 0xC0DE_57AC;

/// Words left unpainted just below the stack pointer at boot (the painting loop's own frame).
const MARGIN_WORDS: usize = 64;

unsafe extern "C" {
    static _stack_start: u32;
    static _stack_end: u32;
}

/// The region's bottom and top (linker symbols: only their addresses are taken).
fn region() -> (*mut u32, *mut u32) {
    (&raw const _stack_end as *mut u32, &raw const _stack_start as *mut u32)
}

/// Size of the stack region, bytes.
pub fn size() -> u32 {
    let (bottom, top) = region();
    top as u32 - bottom as u32
}

/// Paints the free stack. Call once, first thing at boot (before any task runs).
pub fn paint() {
    let (bottom, _) = region();
    let sp = cortex_m::register::msp::read() as *mut u32;
    // SAFETY: `bottom..sp - MARGIN_WORDS` is stack below the current frame: nothing lives there.
    unsafe {
        let end = sp.sub(MARGIN_WORDS);
        let mut p = bottom;
        while p < end {
            p.write_volatile(PAINT);
            p = p.add(1);
        }
    }
}

/// The most stack used since [`paint`], bytes. Reads at most the whole region (8 Ki words):
/// call it from a low-priority task, a few times a second at most.
pub fn high_water() -> u32 {
    let (bottom, top) = region();
    let mut p = bottom;
    // SAFETY: reads stay inside the stack region.
    unsafe {
        while p < top && p.read_volatile() == PAINT {
            p = p.add(1);
        }
    }
    top as u32 - p as u32
}
