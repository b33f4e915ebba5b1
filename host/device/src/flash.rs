//! Flashing the controller firmware onto the board through a debug probe (probe-rs).
//!
//! Everything that can be decided without hardware is decided first and is pure and tested:
//! - [`check_image`]: the ELF exists, is a 32-bit Arm ELF built for the real board (its
//!   `CHLADNI_BOARD` symbol says `stm32l475`, not `qemu`), and everything it would write lies in
//!   the `FLASH` region of the repository's `memory.x` ([`parse_memory_x`], [`flash_region`]).
//! - [`ProbeSelector`]: the `VID:PID[:SERIAL]` form of `--probe`.
//! - [`choose_probe`]: which of the attached probes ([`ProbeDesc`]) to use.
//! - [`find_target`]: the chip name, looked up in probe-rs's built-in target registry.
//!
//! The probe-touching part is thin: [`list_probes`] and [`flash`] (attach, download with erase /
//! program / verify progress, reset and run).

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::{Duration, Instant};

use chladni_shared::icd::link::Board;
use object::read::elf::{ElfFile32, ProgramHeader};
use object::{Object, ObjectSection, ObjectSymbol};
use probe_rs::Permissions;
use probe_rs::config::{Registry, Target};
use probe_rs::flashing::{DownloadOptions, ElfLoader, ElfOptions, FlashProgress, ProgressEvent};
use probe_rs::probe::DebugProbeInfo;
use probe_rs::probe::list::{Accessibility, Lister};

/// The chip on the B-L475E-IOT01A board, as probe-rs names it.
pub const DEFAULT_CHIP: &str = "STM32L475VGTx";

/// Name of the symbol in which the firmware records the board it was built for.
pub(crate) const BOARD_SYMBOL: &str = "CHLADNI_BOARD";

/// The board name an image must carry to be flashed (the link's own name for the board).
pub(crate) const FLASHABLE_BOARD: &str = Board::Stm32l475.name();
/// The QEMU board's name, refused with a pointer to the emulator.
const QEMU_BOARD: &str = Board::Qemu.name();

/// The linker memory map of the firmware, as built into this binary.
pub(crate) const MEMORY_X: &str = include_str!("../../../memory.x");

/// What to check when no probe shows up or one cannot be opened.
const PROBE_HINT: &str = "check
  - the USB cable: on the board's micro-USB port marked USB ST-LINK (not USB OTG), and one that carries data;
  - the board's ST-LINK jumpers: fitted, so the on-board ST-LINK drives the STM32's SWD;
  - the udev rule: probe-rs's 69-probe-rs.rules in /etc/udev/rules.d/, then `sudo udevadm control --reload && sudo udevadm trigger` and re-plug the board;
  - permissions: your user may open the USB device (e.g. is in the `plugdev` group; log in again after adding it).
See docs/flash.md.";

/// Why flashing did not happen or did not succeed.
#[derive(Debug, thiserror::Error)]
pub enum FlashError {
    /// The ELF file does not exist.
    #[error(
        "firmware image {0} does not exist: pass an existing ELF with --elf, or omit --elf to build the board image"
    )]
    ElfMissing(PathBuf),
    /// The ELF file could not be read.
    #[error("cannot read firmware image {path}: {source}")]
    ElfRead {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Not an ELF file.
    #[error(
        "{path} is not an ELF file ({reason}): pass the firmware ELF (target/firmware/chladni-firmware-stm32l475.elf), not a .bin or .hex"
    )]
    NotElf {
        /// The file.
        path: PathBuf,
        /// What the parser said.
        reason: String,
    },
    /// An ELF, but not for a 32-bit Arm core.
    #[error(
        "{path} is a {found} ELF, not a 32-bit Arm one: pass an image built for the board (scripts/firmware.sh build stm32l475)"
    )]
    NotArm {
        /// The file.
        path: PathBuf,
        /// Class and machine found.
        found: String,
    },
    /// No `CHLADNI_BOARD` symbol.
    #[error(
        "{path} has no {BOARD_SYMBOL} symbol, so it is not a Chladni board image: build one with `scripts/firmware.sh build stm32l475` (or omit --elf)"
    )]
    NoBoardTag {
        /// The file.
        path: PathBuf,
    },
    /// The image was built for QEMU.
    #[error(
        "{path} was built for the QEMU board: run it with `chladni emulator --firmware {path}` instead, or flash the board image (omit --elf)"
    )]
    QemuImage {
        /// The file.
        path: PathBuf,
    },
    /// The image was built for another board.
    #[error(
        "{path} was built for board '{board}', not '{FLASHABLE_BOARD}': build the board image with `scripts/firmware.sh build stm32l475`"
    )]
    WrongBoard {
        /// The file.
        path: PathBuf,
        /// The tag found.
        board: String,
    },
    /// Nothing in the image would be written.
    #[error(
        "{path} has no loadable segment with contents, so there is nothing to flash: pass a linked executable, not an object file"
    )]
    NothingToFlash {
        /// The file.
        path: PathBuf,
    },
    /// A loadable segment lies outside the FLASH region of memory.x.
    #[error(
        "{path}: a loadable segment at {start:#010x}..{end:#010x} lies outside FLASH {flash}: the image was not linked with this project's memory.x; rebuild it with scripts/firmware.sh"
    )]
    OutsideFlash {
        /// The file.
        path: PathBuf,
        /// Start (physical / load address) of the segment.
        start: u64,
        /// End (exclusive).
        end: u64,
        /// The FLASH region.
        flash: MemoryRegion,
    },
    /// memory.x could not be understood.
    #[error("memory.x: {0}")]
    MemoryX(String),
    /// The chip is not in probe-rs's registry.
    #[error(
        "chip '{chip}' {why}{hint}: the board's chip is {DEFAULT_CHIP} (the default when --chip is omitted)"
    )]
    UnknownChip {
        /// The name given.
        chip: String,
        /// `is unknown to probe-rs` or `is ambiguous`.
        why: &'static str,
        /// Close names, formatted as a hint (empty if none).
        hint: String,
    },
    /// No probe attached.
    #[error("no debug probe found ({looked_for}); {PROBE_HINT}")]
    NoProbe {
        /// What was looked for.
        looked_for: String,
    },
    /// Several probes and no `--probe`.
    #[error("{} debug probes are attached; choose one with --probe:\n{}", .0.len(), list_with_selectors(.0))]
    SeveralProbes(Vec<ProbeDesc>),
    /// `--probe` matched none of the attached probes.
    #[error("no attached debug probe matches --probe {selector}; attached:\n{}", list_with_selectors(.attached))]
    NoMatch {
        /// The selector given.
        selector: ProbeSelector,
        /// The probes that are attached.
        attached: Vec<ProbeDesc>,
    },
    /// The chosen probe is there but this user may not open it.
    #[error("no permission to open the debug probe {0}; {PROBE_HINT}")]
    PermissionDenied(ProbeDesc),
    /// Opening the probe or attaching to the chip failed.
    #[error(
        "cannot attach to {chip} through {probe}: {reason}; check that the board is powered and its ST-LINK jumpers are fitted, or try again while holding the black RESET button"
    )]
    Attach {
        /// The probe.
        probe: ProbeDesc,
        /// The chip.
        chip: String,
        /// What probe-rs said.
        reason: String,
    },
    /// Erasing, programming or verifying failed.
    #[error("flashing {path} failed: {reason}")]
    Download {
        /// The file.
        path: PathBuf,
        /// What probe-rs said (with its causes).
        reason: String,
    },
    /// The core could not be reset after flashing.
    #[error(
        "the image was flashed but resetting the core failed: {0}; press the board's black RESET button"
    )]
    Reset(String),
}

impl FlashError {
    /// Whether the error is bad input from the user (exit code 2) rather than a failed operation.
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            FlashError::ElfMissing(_)
                | FlashError::NotElf { .. }
                | FlashError::NotArm { .. }
                | FlashError::NoBoardTag { .. }
                | FlashError::QemuImage { .. }
                | FlashError::WrongBoard { .. }
                | FlashError::NothingToFlash { .. }
                | FlashError::OutsideFlash { .. }
                | FlashError::UnknownChip { .. }
                | FlashError::SeveralProbes(_)
        )
    }
}

/// A region of the linker's `MEMORY` map.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MemoryRegion {
    /// Region name (`FLASH`, `RAM`).
    pub name: String,
    /// First address.
    pub origin: u64,
    /// Length in bytes.
    pub length: u64,
}

impl MemoryRegion {
    /// One past the last address.
    pub fn end(&self) -> u64 {
        self.origin + self.length
    }

    /// Whether `start..end` lies inside the region.
    pub fn contains(&self, start: u64, end: u64) -> bool {
        start >= self.origin && start <= end && end <= self.end()
    }
}

impl fmt::Display for MemoryRegion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:#010x}..{:#010x}", self.origin, self.end())
    }
}

/// Parses the `MEMORY { NAME [(attrs)] : ORIGIN = n, LENGTH = n[K|M] ... }` block of a linker
/// script (comments allowed; one region a line; `ORIGIN`/`org`/`o`, `LENGTH`/`len`/`l`).
pub fn parse_memory_x(text: &str) -> Result<Vec<MemoryRegion>, String> {
    let text = strip_comments(text);
    let start = text.find("MEMORY").ok_or("no MEMORY block")?;
    let rest = &text[start + "MEMORY".len()..];
    let open = rest.find('{').ok_or("MEMORY without '{'")?;
    if !rest[..open].trim().is_empty() {
        return Err("MEMORY not followed by '{'".into());
    }
    let close = rest.find('}').ok_or("MEMORY block without '}'")?;
    let regions = rest[open + 1..close]
        .lines()
        .map(str::trim)
        .filter(|line| !line.is_empty())
        .map(parse_region)
        .collect::<Result<Vec<_>, _>>()?;
    if regions.is_empty() {
        return Err("empty MEMORY block".into());
    }
    Ok(regions)
}

/// Removes `/* ... */` comments.
fn strip_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find("/*") {
        out.push_str(&rest[..i]);
        rest = rest[i + 2..].find("*/").map_or("", |j| &rest[i + 2 + j + 2..]);
        out.push(' ');
    }
    out.push_str(rest);
    out
}

/// One `NAME [(attrs)] : ORIGIN = n, LENGTH = n` line.
fn parse_region(line: &str) -> Result<MemoryRegion, String> {
    let (head, body) = line.split_once(':').ok_or_else(|| format!("no ':' in '{line}'"))?;
    let name = head.split('(').next().unwrap_or("").trim();
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(format!("bad region name in '{line}'"));
    }
    let (mut origin, mut length) = (None, None);
    for field in body.split(',').map(str::trim).filter(|f| !f.is_empty()) {
        let (key, value) = field.split_once('=').ok_or_else(|| format!("no '=' in '{field}'"))?;
        let value = parse_size(value.trim()).ok_or_else(|| format!("bad number in '{field}'"))?;
        match key.trim() {
            "ORIGIN" | "org" | "o" => origin = Some(value),
            "LENGTH" | "len" | "l" => length = Some(value),
            other => return Err(format!("unknown attribute '{other}' in '{line}'")),
        }
    }
    match (origin, length) {
        (Some(origin), Some(length)) => Ok(MemoryRegion { name: name.to_string(), origin, length }),
        _ => Err(format!("region '{name}' needs both ORIGIN and LENGTH")),
    }
}

/// `0x0800_0000`, `4096`, `512K`, `1M`.
fn parse_size(text: &str) -> Option<u64> {
    let text = text.replace('_', "");
    let (digits, scale) = match text.as_bytes().last()? {
        b'K' | b'k' => (&text[..text.len() - 1], 1024),
        b'M' | b'm' => (&text[..text.len() - 1], 1024 * 1024),
        _ => (text.as_str(), 1),
    };
    let value = match digits.strip_prefix("0x").or_else(|| digits.strip_prefix("0X")) {
        Some(hex) => u64::from_str_radix(hex, 16).ok()?,
        None => digits.parse().ok()?,
    };
    value.checked_mul(scale)
}

/// The `FLASH` region of the repository's memory.x (built into this binary).
pub fn flash_region() -> Result<MemoryRegion, FlashError> {
    parse_memory_x(MEMORY_X)
        .map_err(FlashError::MemoryX)?
        .into_iter()
        .find(|r| r.name == "FLASH")
        .ok_or_else(|| FlashError::MemoryX("no FLASH region".into()))
}

/// A firmware image that passed [`check_image`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CheckedImage {
    /// The ELF file.
    pub path: PathBuf,
    /// The board tag (`stm32l475`).
    pub board: String,
    /// What will be written: (load address, length) of each loadable segment with contents.
    pub segments: Vec<(u64, u64)>,
}

impl CheckedImage {
    /// Bytes to be written to flash.
    pub fn bytes(&self) -> u64 {
        self.segments.iter().map(|&(_, len)| len).sum()
    }
}

/// Checks that `path` is a board firmware image that fits `flash`, without touching any probe.
pub fn check_image(path: &Path, flash: &MemoryRegion) -> Result<CheckedImage, FlashError> {
    let data = std::fs::read(path).map_err(|source| match source.kind() {
        std::io::ErrorKind::NotFound => FlashError::ElfMissing(path.to_path_buf()),
        _ => FlashError::ElfRead { path: path.to_path_buf(), source },
    })?;
    let not_elf =
        |reason: &str| FlashError::NotElf { path: path.to_path_buf(), reason: reason.into() };
    let not_arm = |found: String| FlashError::NotArm { path: path.to_path_buf(), found };
    match object::FileKind::parse(&*data) {
        Ok(object::FileKind::Elf32) => {}
        Ok(object::FileKind::Elf64) => return Err(not_arm("64-bit".into())),
        Ok(kind) => return Err(not_elf(&format!("it is {kind:?}"))),
        Err(_) => return Err(not_elf("unknown format")),
    }
    let elf =
        ElfFile32::<object::Endianness>::parse(&*data).map_err(|e| not_elf(&e.to_string()))?;
    if elf.architecture() != object::Architecture::Arm {
        return Err(not_arm(format!("32-bit {:?}", elf.architecture())));
    }
    let board =
        board_tag(&elf).ok_or_else(|| FlashError::NoBoardTag { path: path.to_path_buf() })?;
    match board.as_str() {
        FLASHABLE_BOARD => {}
        QEMU_BOARD => return Err(FlashError::QemuImage { path: path.to_path_buf() }),
        _ => return Err(FlashError::WrongBoard { path: path.to_path_buf(), board }),
    }
    let segments = load_segments(&elf);
    if segments.is_empty() {
        return Err(FlashError::NothingToFlash { path: path.to_path_buf() });
    }
    if let Some(&(start, len)) = segments.iter().find(|&&(s, l)| !flash.contains(s, s + l)) {
        let (path, flash) = (path.to_path_buf(), flash.clone());
        return Err(FlashError::OutsideFlash { path, start, end: start + len, flash });
    }
    Ok(CheckedImage { path: path.to_path_buf(), board, segments })
}

/// The NUL-padded board name in the `CHLADNI_BOARD` symbol, if there is one.
fn board_tag(elf: &ElfFile32<object::Endianness>) -> Option<String> {
    let symbol = elf.symbol_by_name(BOARD_SYMBOL)?;
    let section = elf.section_by_index(symbol.section_index()?).ok()?;
    let bytes = section.data_range(symbol.address(), symbol.size()).ok()??;
    let name = bytes.split(|&b| b == 0).next().unwrap_or(&[]);
    Some(String::from_utf8_lossy(name).into_owned())
}

/// (physical address, file size) of each `PT_LOAD` segment with contents: what gets flashed.
fn load_segments(elf: &ElfFile32<object::Endianness>) -> Vec<(u64, u64)> {
    let endian = elf.endian();
    elf.elf_program_headers()
        .iter()
        .filter(|ph| ph.p_type(endian) == object::elf::PT_LOAD && ph.p_filesz(endian) > 0)
        .map(|ph| (u64::from(ph.p_paddr(endian)), u64::from(ph.p_filesz(endian))))
        .collect()
}

/// Looks `chip` up in probe-rs's built-in target registry.
pub fn find_target(chip: &str) -> Result<Target, FlashError> {
    let registry = Registry::from_builtin_families();
    registry.get_target_by_name(chip).map_err(|err| {
        let why = match err {
            probe_rs::config::RegistryError::ChipNotUnique(..) => "is ambiguous",
            _ => "is unknown to probe-rs",
        };
        // Suggest chips sharing the longest prefix that has any match.
        let upper = chip.to_ascii_uppercase();
        let close = (4..=upper.len().min(9))
            .rev()
            .map(|n| {
                let mut found = registry.search_chips(&upper[..n]);
                found.dedup(); // one entry per package of a chip
                found
            })
            .find(|found| !found.is_empty())
            .unwrap_or_default();
        let hint = match close.len() {
            0 => String::new(),
            n if n <= 8 => format!(" (close names: {})", close.join(", ")),
            n => format!(" (close names: {}, … {} in all)", close[..8].join(", "), n),
        };
        FlashError::UnknownChip { chip: chip.to_string(), why, hint }
    })
}

/// `--probe VID:PID[:SERIAL]`, VID and PID in hex.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProbeSelector {
    /// USB vendor id.
    pub vendor_id: u16,
    /// USB product id.
    pub product_id: u16,
    /// Serial number, if given.
    pub serial: Option<String>,
}

impl FromStr for ProbeSelector {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let bad = |why: &str| {
            format!(
                "'{text}' is not a probe selector ({why}): use VID:PID or VID:PID:SERIAL with VID and PID in hex, e.g. 0483:374b or 0483:374b:066DFF; `chladni flash` lists the attached probes when there are several"
            )
        };
        let mut parts = text.splitn(3, ':');
        let hex = |part: Option<&str>, what: &str| {
            let part =
                part.filter(|p| !p.is_empty()).ok_or_else(|| bad(&format!("{what} missing")))?;
            let digits = part.strip_prefix("0x").unwrap_or(part);
            if digits.is_empty() || digits.len() > 4 {
                return Err(bad(&format!("{what} '{part}' is not 1 to 4 hex digits")));
            }
            u16::from_str_radix(digits, 16).map_err(|_| bad(&format!("{what} '{part}' is not hex")))
        };
        let vendor_id = hex(parts.next(), "VID")?;
        let product_id = hex(parts.next(), "PID")?;
        let serial = match parts.next() {
            Some("") => return Err(bad("empty SERIAL")),
            serial => serial.map(str::to_string),
        };
        Ok(ProbeSelector { vendor_id, product_id, serial })
    }
}

impl fmt::Display for ProbeSelector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:04x}:{:04x}", self.vendor_id, self.product_id)?;
        match &self.serial {
            Some(serial) => write!(f, ":{serial}"),
            None => Ok(()),
        }
    }
}

/// An attached probe, as much as choosing one needs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProbeDesc {
    /// What probe-rs calls it (e.g. `STLink V2-1`).
    pub name: String,
    /// USB vendor id.
    pub vendor_id: u16,
    /// USB product id.
    pub product_id: u16,
    /// Serial number, if the probe has one.
    pub serial: Option<String>,
    /// Whether this user may open it.
    pub accessible: bool,
}

impl ProbeDesc {
    /// The `--probe` value that picks exactly this probe.
    pub fn selector(&self) -> ProbeSelector {
        ProbeSelector {
            vendor_id: self.vendor_id,
            product_id: self.product_id,
            serial: self.serial.clone(),
        }
    }

    /// Whether `selector` picks this probe (serial compared exactly when given).
    pub fn matches(&self, selector: &ProbeSelector) -> bool {
        self.vendor_id == selector.vendor_id
            && self.product_id == selector.product_id
            && selector.serial.as_ref().is_none_or(|s| self.serial.as_ref() == Some(s))
    }
}

impl fmt::Display for ProbeDesc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.name, self.selector())?;
        if !self.accessible {
            write!(f, " [no permission]")?;
        }
        Ok(())
    }
}

/// One probe a line, each with the `--probe` value that picks it.
fn list_with_selectors(probes: &[ProbeDesc]) -> String {
    if probes.is_empty() {
        return "  (none)".into();
    }
    let lines: Vec<String> =
        probes.iter().map(|p| format!("  {p}: --probe {}", p.selector())).collect();
    lines.join("\n")
}

/// Picks the probe to use: the only one, or the one `selector` matches (the first if several
/// do). Returns its index in `probes`.
pub fn choose_probe(
    probes: &[ProbeDesc],
    selector: Option<&ProbeSelector>,
) -> Result<usize, FlashError> {
    let index = match selector {
        None => match probes.len() {
            0 => {
                let looked_for = "any CMSIS-DAP, ST-Link or J-Link USB probe".to_string();
                return Err(FlashError::NoProbe { looked_for });
            }
            1 => 0,
            _ => return Err(FlashError::SeveralProbes(probes.to_vec())),
        },
        Some(selector) if probes.is_empty() => {
            return Err(FlashError::NoProbe { looked_for: format!("--probe {selector}") });
        }
        Some(selector) => probes.iter().position(|p| p.matches(selector)).ok_or_else(|| {
            FlashError::NoMatch { selector: selector.clone(), attached: probes.to_vec() }
        })?,
    };
    if !probes[index].accessible {
        return Err(FlashError::PermissionDenied(probes[index].clone()));
    }
    Ok(index)
}

/// The probes attached now (probe-rs's lister), with what [`flash`] needs to open one.
pub struct AttachedProbes {
    infos: Vec<DebugProbeInfo>,
    /// Their descriptions, in the same order.
    pub descs: Vec<ProbeDesc>,
}

/// Lists the attached debug probes.
pub fn list_probes() -> AttachedProbes {
    let items = Lister::new().list_all_with_access();
    let descs = items
        .iter()
        .map(|item| ProbeDesc {
            name: item.info.identifier.clone(),
            vendor_id: item.info.vendor_id,
            product_id: item.info.product_id,
            serial: item.info.serial_number.clone(),
            accessible: item.accessibility == Accessibility::Accessible,
        })
        .collect();
    AttachedProbes { infos: items.into_iter().map(|item| item.info).collect(), descs }
}

/// What [`flash`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct FlashReport {
    /// Bytes written.
    pub bytes: u64,
    /// Whether the written data was read back and compared.
    pub verified: bool,
    /// Wall time of attach, erase, program, verify and reset.
    pub duration: Duration,
}

/// Flashes `image` onto `target` through probe `index` of `probes`, then resets and runs the
/// core. `progress` sees probe-rs's erase / program / verify events.
pub fn flash(
    image: &CheckedImage,
    target: Target,
    probes: &AttachedProbes,
    index: usize,
    verify: bool,
    progress: impl FnMut(ProgressEvent),
) -> Result<FlashReport, FlashError> {
    let started = Instant::now();
    let desc = &probes.descs[index];
    let chip = target.name.clone();
    let attach_error =
        |reason: String| FlashError::Attach { probe: desc.clone(), chip: chip.clone(), reason };
    let probe = probes.infos[index].open().map_err(|e| attach_error(e.to_string()))?;
    let mut session =
        probe.attach(target, Permissions::default()).map_err(|e| attach_error(error_chain(&e)))?;
    let mut options = DownloadOptions::default();
    options.verify = verify;
    options.progress = FlashProgress::new(progress);
    probe_rs::flashing::download_file_with_options(
        &mut session,
        &image.path,
        ElfLoader(ElfOptions::default()),
        options,
    )
    .map_err(|e| FlashError::Download { path: image.path.clone(), reason: error_chain(&e) })?;
    let mut core = session.core(0).map_err(|e| FlashError::Reset(error_chain(&e)))?;
    core.reset().map_err(|e| FlashError::Reset(error_chain(&e)))?;
    Ok(FlashReport { bytes: image.bytes(), verified: verify, duration: started.elapsed() })
}

/// `err: cause: cause` on one line.
fn error_chain(err: &dyn std::error::Error) -> String {
    let mut text = err.to_string();
    let mut source = err.source();
    while let Some(cause) = source {
        text.push_str(&format!(": {cause}"));
        source = cause.source();
    }
    text
}

#[cfg(test)]
#[path = "../../cli/tests/integration/support/elf.rs"]
mod elf_fixture;

#[cfg(test)]
mod tests {
    use super::elf_fixture::{EM_ARM, EM_RISCV, Segment, elf};
    use super::*;

    const FLASH: MemoryRegion =
        MemoryRegion { name: String::new(), origin: 0x0800_0000, length: 512 * 1024 };

    fn write(name: &str, bytes: &[u8]) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("chladni-flash-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    fn check(name: &str, bytes: &[u8]) -> Result<CheckedImage, FlashError> {
        check_image(&write(name, bytes), &FLASH)
    }

    #[test]
    fn memory_x_of_the_repository_has_the_board_flash() {
        let flash = flash_region().unwrap();
        assert_eq!((flash.origin, flash.length), (0x0800_0000, 512 * 1024));
        let regions = parse_memory_x(MEMORY_X).unwrap();
        let names: Vec<&str> = regions.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["FLASH", "RAM", "SRAM2"]);
        assert_eq!((regions[1].origin, regions[1].length), (0x2000_0000, 96 * 1024));
        // The stack's own region (memory.x puts the stack there).
        assert_eq!((regions[2].origin, regions[2].length), (0x1000_0000, 32 * 1024));
    }

    #[test]
    fn memory_x_parser_reads_attributes_abbreviations_and_units() {
        let text = "/* a */ MEMORY /* b */ {\n  BOOT (rx) : org = 0x0, len = 0x1_000 /* c */\n\
                    FLASH:ORIGIN=0x10000,LENGTH=1M\n  RAM (rwx) : o = 4096, l = 2k\n}\n";
        let regions = parse_memory_x(text).unwrap();
        let got: Vec<(&str, u64, u64)> =
            regions.iter().map(|r| (r.name.as_str(), r.origin, r.length)).collect();
        assert_eq!(got, [("BOOT", 0, 4096), ("FLASH", 0x10000, 1 << 20), ("RAM", 4096, 2048)]);
    }

    #[test]
    fn memory_x_parser_names_what_is_wrong() {
        for (text, expected) in [
            ("", "no MEMORY block"),
            ("MEMORY { }", "empty MEMORY block"),
            ("MEMORY { FLASH : ORIGIN = 0x0 }", "needs both ORIGIN and LENGTH"),
            ("MEMORY { FLASH : ORIGIN = zz, LENGTH = 1K }", "bad number in 'ORIGIN = zz'"),
            ("MEMORY { FLASH : START = 0, LENGTH = 1K }", "unknown attribute 'START'"),
            ("MEMORY { FLASH ORIGIN = 0 }", "no ':'"),
            ("MEMORY { FLASH : ORIGIN = 0, LENGTH = 1K", "without '}'"),
        ] {
            let err = parse_memory_x(text).unwrap_err();
            assert!(err.contains(expected), "{text:?}: {err}");
        }
    }

    #[test]
    fn region_containment_is_inclusive_of_the_last_byte_only() {
        assert!(FLASH.contains(0x0800_0000, 0x0808_0000));
        assert!(!FLASH.contains(0x07ff_ffff, 0x0800_0010));
        assert!(!FLASH.contains(0x0807_fff0, 0x0808_0001));
    }

    #[test]
    fn a_board_image_in_flash_passes_and_counts_its_bytes() {
        let bytes = elf(EM_ARM, Some("stm32l475"), &[Segment::at(0x0800_0000, 64)]);
        let image = check("ok.elf", &bytes).unwrap();
        assert_eq!(image.board, "stm32l475");
        assert_eq!(image.segments, [(0x0800_0000, 64)]);
        assert_eq!(image.bytes(), 64);
    }

    #[test]
    fn data_loaded_in_flash_but_run_in_ram_is_checked_at_its_load_address() {
        let data = Segment { vaddr: 0x2000_0000, paddr: 0x0800_0100, len: 32 };
        let bytes = elf(EM_ARM, Some("stm32l475"), &[Segment::at(0x0800_0000, 64), data]);
        assert_eq!(check("lma.elf", &bytes).unwrap().segments[1], (0x0800_0100, 32));
        let in_ram = Segment { vaddr: 0x0800_0100, paddr: 0x2000_0000, len: 32 };
        let bytes = elf(EM_ARM, Some("stm32l475"), &[Segment::at(0x0800_0000, 64), in_ram]);
        let err = check("ram.elf", &bytes).unwrap_err();
        assert!(matches!(
            err,
            FlashError::OutsideFlash { start: 0x2000_0000, end: 0x2000_0020, .. }
        ));
        assert!(
            err.to_string()
                .contains("0x20000000..0x20000020 lies outside FLASH 0x08000000..0x08080000"),
            "{err}"
        );
    }

    #[test]
    fn a_segment_running_past_the_end_of_flash_is_refused() {
        let bytes = elf(EM_ARM, Some("stm32l475"), &[Segment::at(0x0807_ffe0, 64)]);
        assert!(matches!(check("end.elf", &bytes), Err(FlashError::OutsideFlash { .. })));
    }

    #[test]
    fn the_board_tag_decides() {
        let seg = [Segment::at(0x0800_0000, 64)];
        let err = check("qemu.elf", &elf(EM_ARM, Some("qemu"), &seg)).unwrap_err();
        assert!(matches!(err, FlashError::QemuImage { .. }));
        assert!(err.to_string().contains("chladni emulator"), "{err}");
        let err = check("other.elf", &elf(EM_ARM, Some("nrf52"), &seg)).unwrap_err();
        assert!(matches!(err, FlashError::WrongBoard { ref board, .. } if board == "nrf52"));
        let err = check("untagged.elf", &elf(EM_ARM, None, &seg)).unwrap_err();
        assert!(matches!(err, FlashError::NoBoardTag { .. }));
        assert!(err.is_bad_input());
    }

    #[test]
    fn files_that_are_not_arm_elfs_are_named() {
        let missing = std::env::temp_dir().join("chladni-flash-unit-no-such.elf");
        assert!(matches!(check_image(&missing, &FLASH), Err(FlashError::ElfMissing(_))));
        let err = check("text.elf", b"hello, not an ELF").unwrap_err();
        assert!(matches!(err, FlashError::NotElf { .. }));
        assert!(err.to_string().contains("text.elf is not an ELF file"), "{err}");
        let riscv = elf(EM_RISCV, Some("stm32l475"), &[Segment::at(0x0800_0000, 64)]);
        assert!(matches!(check("riscv.elf", &riscv), Err(FlashError::NotArm { .. })));
        let mut elf64 = elf(EM_ARM, Some("stm32l475"), &[Segment::at(0x0800_0000, 64)]);
        elf64[4] = 2; // ELFCLASS64
        let err = check("elf64.elf", &elf64).unwrap_err();
        assert!(matches!(err, FlashError::NotArm { .. } | FlashError::NotElf { .. }), "{err}");
    }

    #[test]
    fn an_image_with_nothing_to_load_is_refused() {
        let bytes = elf(EM_ARM, Some("stm32l475"), &[Segment::at(0x0800_0000, 64)]);
        let mut no_load = bytes.clone();
        no_load[52] = 4; // PT_LOAD -> PT_NOTE
        let err = check("noload.elf", &no_load).unwrap_err();
        assert!(matches!(err, FlashError::NothingToFlash { .. }), "{err}");
    }

    #[test]
    fn probe_selectors_parse_in_hex_with_an_optional_serial() {
        let s: ProbeSelector = "0483:374b".parse().unwrap();
        assert_eq!((s.vendor_id, s.product_id, s.serial), (0x0483, 0x374b, None));
        let s: ProbeSelector = "0x0483:374B:066DFF:49".parse().unwrap();
        assert_eq!(s.serial.as_deref(), Some("066DFF:49"));
        assert_eq!(s.to_string(), "0483:374b:066DFF:49");
        for bad in ["", "0483", "0483:", ":374b", "g483:374b", "12345:1", "0483:374b:"] {
            let err = bad.parse::<ProbeSelector>().unwrap_err();
            assert!(err.contains(&format!("'{bad}' is not a probe selector")), "{err}");
            assert!(err.contains("VID:PID"), "{err}");
        }
    }

    fn probe(name: &str, vid: u16, pid: u16, serial: Option<&str>) -> ProbeDesc {
        let serial = serial.map(str::to_string);
        ProbeDesc { name: name.into(), vendor_id: vid, product_id: pid, serial, accessible: true }
    }

    #[test]
    fn one_probe_is_taken_none_or_several_are_errors() {
        let stlink = probe("STLink V2-1", 0x0483, 0x374b, Some("066D"));
        let jlink = probe("J-Link", 0x1366, 0x0101, None);
        assert_eq!(choose_probe(std::slice::from_ref(&stlink), None).unwrap(), 0);
        let err = choose_probe(&[], None).unwrap_err();
        assert!(matches!(err, FlashError::NoProbe { .. }) && !err.is_bad_input());
        let text = err.to_string();
        for needle in ["CMSIS-DAP, ST-Link or J-Link", "USB cable", "jumpers", "69-probe-rs.rules"]
        {
            assert!(text.contains(needle), "{needle} missing in {text}");
        }
        let err = choose_probe(&[stlink.clone(), jlink.clone()], None).unwrap_err();
        assert!(err.is_bad_input());
        let text = err.to_string();
        assert!(
            text.contains("--probe 0483:374b:066D") && text.contains("--probe 1366:0101"),
            "{text}"
        );
    }

    #[test]
    fn a_selector_picks_its_probe_or_names_itself_and_the_attached_ones() {
        let a = probe("STLink V2-1", 0x0483, 0x374b, Some("AAA"));
        let b = probe("STLink V2-1", 0x0483, 0x374b, Some("BBB"));
        let probes = [a, b];
        let pick = |s: &str| choose_probe(&probes, Some(&s.parse().unwrap()));
        assert_eq!(pick("0483:374b:BBB").unwrap(), 1);
        assert_eq!(pick("0483:374b").unwrap(), 0);
        let err = pick("0483:374b:CCC").unwrap_err();
        assert!(!err.is_bad_input());
        let text = err.to_string();
        assert!(text.contains("--probe 0483:374b:CCC") && text.contains("0483:374b:AAA"), "{text}");
        let err = choose_probe(&[], Some(&"1366:0101".parse().unwrap())).unwrap_err();
        assert!(err.to_string().contains("--probe 1366:0101"), "{err}");
    }

    #[test]
    fn a_probe_without_permission_points_at_the_udev_rule() {
        let mut p = probe("STLink V2-1", 0x0483, 0x374b, None);
        p.accessible = false;
        let err = choose_probe(&[p], None).unwrap_err();
        assert!(matches!(err, FlashError::PermissionDenied(_)));
        assert!(err.to_string().contains("69-probe-rs.rules in /etc/udev/rules.d/"), "{err}");
    }

    #[test]
    fn the_board_chip_is_known_and_a_typo_gets_close_names() {
        assert_eq!(find_target(DEFAULT_CHIP).unwrap().name, DEFAULT_CHIP);
        let err = find_target("STM32L475XYZ").unwrap_err();
        assert!(err.is_bad_input());
        let text = err.to_string();
        assert!(
            text.contains("chip 'STM32L475XYZ' is unknown to probe-rs")
                && text.contains("STM32L475VGTx"),
            "{text}"
        );
        let err = find_target("stm32l4").unwrap_err();
        assert!(
            err.to_string().contains("chip 'stm32l4' is ambiguous (close names: STM32L4"),
            "{err}"
        );
        let err = find_target("nonsense").unwrap_err();
        assert!(err.to_string().contains("the board's chip is STM32L475VGTx"), "{err}");
    }
}
