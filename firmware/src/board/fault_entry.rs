//! HardFault entry on a stack of its own, for both boards.
//!
//! The main stack has SRAM2 to itself (memory.x), with unmapped addresses below it, so a stack
//! overflow faults at once instead of running into the statics. But then the stack pointer
//! is at or below the bottom of SRAM2: the core's own exception entry pushes its frame there
//! (and fails: the frame is lost, CFSR.STKERR says so), and the first push of any Rust
//! handler's prologue would fault again inside HardFault, which locks the core up. The fail-safe
//! (`park_output`) would never run and the DMA would replay the last ring into the amplifier.
//!
//! So the vector's `HardFault` is the few instructions below, before any Rust code: remember
//! the faulting stack pointer and EXC_RETURN, move MSP to the top of [`FAULT_STACK`] (a
//! reserve in SRAM1 that no overflow of SRAM2 can reach), and branch to the board's
//! `failsafe::hard_fault`, which never returns. This replaces cortex-m-rt's
//! `#[exception] HardFault` trampoline (cortex-m-rt 0.7.7 links our `HardFault` symbol
//! instead of its default: `PROVIDE(HardFault = HardFault_)` in its link.x); it is placed in a
//! `.HardFault.*` section, which that link.x keeps in `.text`.

/// Bytes of the fault stack: the fault handlers park (register writes), log through defmt
/// (semihosting or RTT) and halt or reset; their deepest path measured under 1 KiB.
pub const FAULT_STACK_SIZE: usize = 2048;

/// The stack the HardFault handler runs on, 8-byte aligned as AAPCS wants at a call. In
/// `.uninit` (cortex-m-rt neither loads nor zeroes it): its contents never matter.
#[repr(C, align(8))]
pub struct FaultStack([u8; FAULT_STACK_SIZE]);

#[unsafe(link_section = ".uninit.chladni_fault_stack")]
static mut FAULT_STACK: core::mem::MaybeUninit<FaultStack> = core::mem::MaybeUninit::uninit();

/// What the entry code saw: the stack pointer at the fault (where the core tried to push
/// its frame) and EXC_RETURN.
#[derive(Clone, Copy)]
pub struct FaultEntry {
    /// MSP or PSP at entry, as EXC_RETURN bit 2 says.
    pub sp: u32,
    /// The handler's LR at entry.
    pub exc_return: u32,
}

/// CFSR (configurable fault status register).
const CFSR: *const u32 = 0xE000_ED28 as *const u32;
/// CFSR.MSTKERR (MemManage fault on exception-entry stacking).
const CFSR_MSTKERR: u32 = 1 << 4;
/// CFSR.STKERR (BusFault on exception-entry stacking).
const CFSR_STKERR: u32 = 1 << 12;

unsafe extern "C" {
    static _stack_end: u32;
    static _stack_start: u32;
}

impl FaultEntry {
    /// CFSR at the fault.
    pub fn cfsr(&self) -> u32 {
        // SAFETY: CFSR is a word-aligned, always-readable System Control Space register.
        unsafe { CFSR.read_volatile() }
    }

    /// Whether the fault is a stack overflow: the core could not push its exception frame
    /// (CFSR.STKERR or MSTKERR), or the stack pointer is below the stack region's bottom.
    pub fn stack_overflow(&self) -> bool {
        let bottom = &raw const _stack_end as u32;
        self.cfsr() & (CFSR_STKERR | CFSR_MSTKERR) != 0 || self.sp < bottom
    }

    /// The faulting instruction's address from the exception frame, if the frame is there
    /// to read (not after a stack overflow: the push that would have written it failed).
    pub fn pc(&self) -> Option<u32> {
        let (bottom, top) = (&raw const _stack_end as u32, &raw const _stack_start as u32);
        let frame_in_stack = self.sp >= bottom && self.sp.saturating_add(32) <= top;
        if self.stack_overflow() || !frame_in_stack {
            return None;
        }
        // SAFETY: the 8-word frame lies inside the stack region (checked above), and the
        // core wrote it on entry (no stacking error); word 6 is the stacked PC.
        Some(unsafe { (self.sp as *const u32).add(6).read_volatile() })
    }
}

/// Called by the entry code on the fault stack. Never returns.
unsafe extern "C" fn on_fault_stack(sp: u32, exc_return: u32) -> ! {
    super::failsafe::hard_fault(FaultEntry { sp, exc_return })
}

// The vector: r0 = the stack pointer the fault left (MSP or PSP per EXC_RETURN bit 2),
// r1 = EXC_RETURN, then MSP := top of FAULT_STACK, then the Rust handler. Nothing here touches
// the old stack.
core::arch::global_asm!(
    ".pushsection .HardFault.chladni, \"ax\"",
    ".global HardFault",
    ".type HardFault,%function",
    ".thumb_func",
    "HardFault:",
    "mov r1, lr",
    "tst r1, #4",
    "ite eq",
    "mrseq r0, MSP",
    "mrsne r0, PSP",
    "ldr r2, ={stack}+{size}",
    "msr MSP, r2",
    "b {handler}",
    ".ltorg",
    ".size HardFault, . - HardFault",
    ".popsection",
    stack = sym FAULT_STACK,
    size = const FAULT_STACK_SIZE,
    handler = sym on_fault_stack,
);
