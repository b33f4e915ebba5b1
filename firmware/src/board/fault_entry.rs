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
/// (semihosting or RTT) and wait for the watchdog. Their use is measured by the QEMU
/// `failsafe` image ([`paint`], [`high_water`]; docs/firmware.md has the figure).
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

    /// Logs the fault: a stack overflow with the SP and CFSR, else the faulting PC.
    pub fn log(&self) {
        if self.stack_overflow() {
            defmt::error!(
                "hard fault: stack overflow (sp {=u32:#010x}, CFSR {=u32:#010x})",
                self.sp,
                self.cfsr()
            );
        } else if let Some(pc) = self.pc() {
            defmt::error!("hard fault at pc {=u32:#010x}", pc);
        } else {
            defmt::error!("hard fault (sp {=u32:#010x}: no frame to read)", self.sp);
        }
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

/// The fault stack's words, bottom first.
fn fault_stack_words() -> *mut u32 {
    core::ptr::addr_of_mut!(FAULT_STACK).cast::<u32>()
}

const FAULT_STACK_WORDS: usize = FAULT_STACK_SIZE / 4;

/// Fills the fault stack with `board::stack::PAINT`, so that [`high_water`] can tell later
/// how much of it a fault used. Only while no fault runs (the `failsafe` image, at boot).
pub fn paint() {
    let words = fault_stack_words();
    for i in 0..FAULT_STACK_WORDS {
        // SAFETY: inside FAULT_STACK, which only the HardFault handler uses (not running).
        unsafe { words.add(i).write_volatile(super::stack::PAINT) };
    }
}

/// Bytes of the fault stack used since [`paint`]: from the bottom, the words still painted
/// are unused. (RAM that was never painted reads as all used.) Survives QEMU's reset: the
/// stack is in `.uninit`.
pub fn high_water() -> u32 {
    let words = fault_stack_words();
    // SAFETY: reads stay inside FAULT_STACK; any bit pattern is a valid u32.
    let unused = (0..FAULT_STACK_WORDS)
        .take_while(|&i| unsafe { words.add(i).read_volatile() } == super::stack::PAINT)
        .count();
    ((FAULT_STACK_WORDS - unused) * 4) as u32
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
