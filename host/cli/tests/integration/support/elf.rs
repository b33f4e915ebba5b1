//! Test fixture: small hand-assembled 32-bit little-endian ELF executables, enough for
//! `chladni_device::flash::check_image` (program headers, one section per segment, a symbol table with
//! the board tag). Shared by the unit tests in host/device/src/flash.rs and host/cli/tests/integration/cli_flash.rs.
// Each includer uses only part of it.
#![allow(dead_code)]

/// `EM_ARM`.
pub const EM_ARM: u16 = 40;
/// `EM_RISCV`.
pub const EM_RISCV: u16 = 243;

/// One loadable segment: where it runs, where it is loaded, how many bytes it holds.
#[derive(Clone, Copy)]
pub struct Segment {
    pub vaddr: u32,
    pub paddr: u32,
    pub len: u32,
}

impl Segment {
    /// A segment that runs where it is loaded.
    pub fn at(addr: u32, len: u32) -> Self {
        Segment { vaddr: addr, paddr: addr, len }
    }
}

/// An ELF for `machine` with `segments` (each its own section `.sN`); if `tag` is given, the
/// symbol `CHLADNI_BOARD` (16 bytes, NUL-padded) sits at the start of the first segment.
pub fn elf(machine: u16, tag: Option<&str>, segments: &[Segment]) -> Vec<u8> {
    const EH: usize = 52;
    const PH: usize = 32;
    const SH: usize = 40;
    let n = segments.len();
    // Layout: header, program headers, segment data, symtab, strtab, shstrtab, section headers.
    let mut data_off = Vec::new();
    let mut off = EH + PH * n;
    for s in segments {
        data_off.push(off);
        off += s.len as usize;
    }
    let symtab_off = off;
    let symbols: usize = if tag.is_some() { 2 } else { 1 };
    let strtab_off = symtab_off + 16 * symbols;
    let strtab = b"\0CHLADNI_BOARD\0";
    let shstrtab_off = strtab_off + strtab.len();
    let mut shstrtab = b"\0.symtab\0.strtab\0.shstrtab\0".to_vec();
    let sec_names: Vec<u32> = (0..n)
        .map(|i| {
            let at = shstrtab.len() as u32;
            shstrtab.extend_from_slice(format!(".s{i}\0").as_bytes());
            at
        })
        .collect();
    let sh_off = (shstrtab_off + shstrtab.len()).next_multiple_of(4);
    let shnum = 4 + n; // null, segments…, .symtab, .strtab, .shstrtab

    let mut out = Vec::new();
    out.extend_from_slice(&[0x7f, b'E', b'L', b'F', 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
    for v in [2u16, machine] {
        out.extend_from_slice(&v.to_le_bytes()); // e_type = ET_EXEC, e_machine
    }
    let entry = segments.first().map_or(0, |s| s.vaddr);
    for v in [1u32, entry, EH as u32, sh_off as u32, 0x0500_0400] {
        out.extend_from_slice(&v.to_le_bytes()); // version, entry, phoff, shoff, flags
    }
    let (ph_n, shstrndx) = (n as u16, (shnum - 1) as u16);
    for v in [EH as u16, PH as u16, ph_n, SH as u16, shnum as u16, shstrndx] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for (s, &o) in segments.iter().zip(&data_off) {
        // PT_LOAD, offset, vaddr, paddr, filesz, memsz, flags (R+X), align
        for v in [1u32, o as u32, s.vaddr, s.paddr, s.len, s.len, 5, 4] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    for (i, s) in segments.iter().enumerate() {
        let mut bytes = vec![0xa5u8; s.len as usize];
        if let (0, Some(tag)) = (i, tag) {
            let mut padded = [0u8; 16];
            padded[..tag.len()].copy_from_slice(tag.as_bytes());
            bytes[..16].copy_from_slice(&padded);
        }
        out.extend_from_slice(&bytes);
    }
    out.extend_from_slice(&[0u8; 16]); // the null symbol
    if tag.is_some() {
        let vaddr = segments[0].vaddr;
        for v in [1u32, vaddr, 16] {
            out.extend_from_slice(&v.to_le_bytes()); // name, value, size
        }
        out.extend_from_slice(&[0x11, 0]); // STB_GLOBAL | STT_OBJECT, default visibility
        out.extend_from_slice(&1u16.to_le_bytes()); // section .s0
    }
    out.extend_from_slice(strtab);
    out.extend_from_slice(&shstrtab);
    out.resize(sh_off, 0);
    out.extend_from_slice(&[0u8; SH]);
    for ((s, &o), &name) in segments.iter().zip(&data_off).zip(&sec_names) {
        // PROGBITS, ALLOC|EXECINSTR
        section(&mut out, [name, 1, 6, s.vaddr, o as u32, s.len, 0, 0, 4, 0]);
    }
    let (strtab_index, symtab_size) = (n as u32 + 2, (16 * symbols) as u32);
    section(&mut out, [1, 2, 0, 0, symtab_off as u32, symtab_size, strtab_index, 1, 4, 16]);
    section(&mut out, [9, 3, 0, 0, strtab_off as u32, strtab.len() as u32, 0, 0, 1, 0]);
    let shstrtab_len = shstrtab.len() as u32;
    section(&mut out, [17, 3, 0, 0, shstrtab_off as u32, shstrtab_len, 0, 0, 1, 0]);
    out
}

/// name, type, flags, addr, offset, size, link, info, addralign, entsize
fn section(out: &mut Vec<u8>, fields: [u32; 10]) {
    for v in fields {
        out.extend_from_slice(&v.to_le_bytes());
    }
}
