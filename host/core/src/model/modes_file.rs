//! `[[mode]]` entries for plate files: solver modes as sampled mode shapes (`node.kind =
//! "grid"`), photo-derived straight nodes (`node.kind = "line"`) and photo-derived curved
//! nodes as a sampled signed distance (`node.kind = "grid"`), several photo-derived straight
//! nodes of one frequency as one mode (`node.kind = "lines"`; [`add_entry`] merges a photo's
//! lines into the entry already at its frequency), and resonances measured by a
//! sweep, which have a frequency but no node yet ([`measured_mode`]: the plate file then
//! refuses to load until the node is filled in). Schema in docs/plate.md.

use crate::model::grid::Grid;
use crate::model::plate::SAME_FREQ_HZ;
use crate::model::plate_file::{LineEntry, ModeEntry, NodeEntry, PlateFile, PlateTable};

/// Rounds to `digits` decimals so files stay small and diff well.
fn round(v: f64, digits: i32) -> f64 {
    let s = 10f64.powi(digits);
    (v * s).round() / s
}

/// A `[[mode]]` entry holding a sampled mode shape.
pub fn grid_mode(name: &str, freq_hz: f64, lambda: f64, grid: &Grid) -> ModeEntry {
    ModeEntry {
        name: Some(name.into()),
        freq_hz: Some(round(freq_hz, 4)),
        lambda: Some(round(lambda, 5)),
        node: Some(grid_node(grid)),
        ..ModeEntry::default()
    }
}

/// A `[[mode]]` entry holding a grid node that is not a solver mode (no λ; the frequency only
/// if known), e.g. the signed distance to the nodes seen in a photo.
pub(crate) fn sampled_mode(name: &str, freq_hz: Option<f64>, grid: &Grid) -> ModeEntry {
    ModeEntry {
        name: Some(name.into()),
        freq_hz,
        node: Some(grid_node(grid)),
        ..ModeEntry::default()
    }
}

/// A `[[mode]]` entry for a resonance measured by `chladni device sweep`: its frequency, no
/// node. The node is not known from a sweep; the entry has none, which the plate file's check
/// refuses (naming the mode and the fix) until it is filled from the solver or a photo.
pub fn measured_mode(freq_hz: f64, q: Option<f64>) -> ModeEntry {
    let q = q.map_or(String::new(), |q| format!(", Q {q:.0}"));
    ModeEntry {
        name: Some(format!("swept {:.2} Hz{q}", round(freq_hz, 2))),
        freq_hz: Some(round(freq_hz, 3)),
        ..ModeEntry::default()
    }
}

/// `node = { kind = "grid", nx, ny, values }`.
fn grid_node(grid: &Grid) -> NodeEntry {
    NodeEntry::Grid {
        nx: Some(grid.nx as i64),
        ny: Some(grid.ny as i64),
        values: Some(grid.values.iter().map(|&v| round(v, 5)).collect()),
    }
}

/// A `[[mode]]` entry holding a straight node line.
pub(crate) fn line_mode(
    name: &str,
    freq_hz: Option<f64>,
    angle_deg: f64,
    offset_mm: f64,
) -> ModeEntry {
    ModeEntry {
        name: Some(name.into()),
        freq_hz,
        node: Some(NodeEntry::Line {
            angle_deg: Some(round(angle_deg, 3)),
            offset_mm: Some(round(offset_mm, 3)),
        }),
        ..ModeEntry::default()
    }
}

/// A `[[mode]]` entry holding all straight node lines `(angle_deg, offset_mm)` of one
/// frequency: a `line` node for one line, a `lines` node for several (one frequency is one
/// mode, see [`crate::model::plate`]).
pub(crate) fn lines_mode(name: &str, freq_hz: Option<f64>, lines: &[(f64, f64)]) -> ModeEntry {
    if let [(angle_deg, offset_mm)] = lines {
        return line_mode(name, freq_hz, *angle_deg, *offset_mm);
    }
    let lines = lines
        .iter()
        .map(|&(a, o)| LineEntry { angle_deg: round(a, 3), offset_mm: round(o, 3) })
        .collect();
    ModeEntry {
        name: Some(name.into()),
        freq_hz,
        node: Some(NodeEntry::Lines { lines: Some(lines) }),
        ..ModeEntry::default()
    }
}

/// The lines of a `line` or `lines` entry (`None` for other nodes, or a line without angle).
fn entry_lines(e: &ModeEntry) -> Option<Vec<LineEntry>> {
    match &e.node {
        Some(NodeEntry::Line { angle_deg: Some(a), offset_mm }) => {
            Some(vec![LineEntry { angle_deg: *a, offset_mm: offset_mm.unwrap_or(0.0) }])
        }
        Some(NodeEntry::Lines { lines: Some(l) }) => Some(l.clone()),
        _ => None,
    }
}

/// How [`add_entry`] added an entry.
#[derive(Debug, Clone, PartialEq)]
pub enum Added {
    /// As a new `[[mode]]` (no entry at its frequency).
    New,
    /// Its lines merged into the entry at this index (0-based), which keeps its name.
    Merged(usize),
}

/// Why [`add_entry`] refused an entry: an entry already holds its frequency and the two cannot
/// merge (only straight-node entries that agree on every other key do).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "[[mode]] {} ({existing}) is already at {freq_hz} Hz and cannot take the lines of {added} (only \
     straight-node entries with the same other keys merge): one drive frequency is one mode; \
     remove that entry first, or write to another file",
    index + 1
)]
pub struct ModeClash {
    /// The entry already at the frequency (0-based index into the file's `[[mode]]`s).
    pub index: usize,
    /// Its name ("unnamed" without one).
    pub existing: String,
    /// Its frequency (Hz).
    pub freq_hz: f64,
    /// The refused entry's name ("unnamed" without one).
    pub added: String,
}

/// Adds `entry` to `modes`, keeping one mode per frequency: a straight-node entry at the
/// frequency of a straight-node entry that agrees on every other key is merged into it; an
/// entry at an existing frequency that cannot be merged is refused ([`ModeClash`] names both,
/// the frequency and the fix).
pub fn add_entry(modes: &mut Vec<ModeEntry>, entry: ModeEntry) -> Result<Added, ModeClash> {
    let same = |m: &ModeEntry| match (m.freq_hz, entry.freq_hz) {
        (Some(a), Some(b)) => (a - b).abs() < SAME_FREQ_HZ,
        _ => false,
    };
    let Some(k) = modes.iter().position(same) else {
        modes.push(entry);
        return Ok(Added::New);
    };
    let old = &mut modes[k];
    let name = |e: &ModeEntry| e.name.clone().unwrap_or_else(|| "unnamed".into());
    // Every key but the name, the node and the frequency (equal within SAME_FREQ_HZ) must agree.
    let strip = |e: &ModeEntry| ModeEntry { name: None, node: None, freq_hz: None, ..e.clone() };
    match (entry_lines(old), entry_lines(&entry)) {
        (Some(mut lines), Some(new)) if strip(old) == strip(&entry) => {
            lines.extend(new);
            old.node = Some(NodeEntry::Lines { lines: Some(lines) });
            Ok(Added::Merged(k))
        }
        _ => Err(ModeClash {
            index: k,
            existing: name(old),
            freq_hz: old.freq_hz.unwrap_or_default(),
            added: name(&entry),
        }),
    }
}

/// Renders a plate file with the given `[plate]` table and `[[mode]]` entries.
pub fn render(plate: &PlateTable, modes: Vec<ModeEntry>) -> Result<String, toml::ser::Error> {
    toml::to_string(&PlateFile { plate: plate.clone(), mode: modes, learned: None })
}

#[cfg(test)]
/// The grid of a `node = { kind = "grid", ... }` entry, if it is one with nx·ny samples
/// (for checks and tools; the planner's check is [`crate::model::plate::check_mode`]).
pub(crate) fn grid_of(entry: &ModeEntry, size_mm: [f64; 2]) -> Option<Grid> {
    let Some(NodeEntry::Grid { nx: Some(nx), ny: Some(ny), values: Some(values) }) = &entry.node
    else {
        return None;
    };
    let (nx, ny) = (usize::try_from(*nx).ok()?, usize::try_from(*ny).ok()?);
    (values.len() == nx * ny && nx >= 2 && ny >= 2).then(|| Grid {
        nx,
        ny,
        size_mm,
        values: values.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sampled mode shape without the solver (model is below plate): (1, 1) cosines, its
    /// largest sample +1 as the solver normalises.
    fn cosine_grid(nx: usize, ny: usize, size_mm: [f64; 2]) -> Grid {
        let c = |k: usize, n: usize| (std::f64::consts::PI * k as f64 / (n - 1) as f64).cos();
        let values = (0..ny).flat_map(|j| (0..nx).map(move |i| c(i, nx) * c(j, ny))).collect();
        Grid { nx, ny, size_mm, values }
    }

    #[test]
    fn written_modes_parse_back_as_a_plate_file_with_grids() {
        let text = "[plate]\nname = \"p\"\nsize_mm = [300.0, 200.0]\nthickness_mm = 2.0\n\
                    youngs_modulus_gpa = 70.0\ndensity_kg_m3 = 2700.0\npoisson = 0.33\nboundary = \"cantilever\"\n";
        let file = PlateFile::parse(text, "t").unwrap();
        let plate = file.plate.mechanics().unwrap();
        let grid = cosine_grid(31, 21, plate.size_mm);
        let out = render(&file.plate, vec![grid_mode("mode 2", 61.25, 3.47, &grid)]).unwrap();
        let back = PlateFile::parse(&out, "out").unwrap();
        assert_eq!(back.plate.mechanics().unwrap(), plate);
        assert_eq!(back.mode.len(), 1);
        let g = grid_of(&back.mode[0], plate.size_mm).unwrap();
        assert_eq!((g.nx, g.ny), (31, 21));
        assert!(g.values.iter().zip(&grid.values).all(|(a, b)| (a - b).abs() <= 5e-6));
        let photo = sampled_mode("photo nodes", None, &grid);
        assert!(photo.freq_hz.is_none() && photo.lambda.is_none());
        assert_eq!(grid_of(&photo, plate.size_mm).unwrap().values.len(), 31 * 21);
        let line = line_mode("l", Some(60.0), 90.0, -12.5);
        assert!(matches!(line.node, Some(NodeEntry::Line { .. })));
        assert!(grid_of(&line, plate.size_mm).is_none());
    }

    #[test]
    fn lines_of_one_frequency_are_one_entry() {
        use crate::model::plate::{Node, PlateModel};
        let mut modes = vec![lines_mode("a", Some(60.0), &[(90.0, -50.0), (0.0, 10.0)])];
        assert!(
            matches!(&modes[0].node, Some(NodeEntry::Lines { lines: Some(l) }) if l.len() == 2)
        );
        // A third line at 60 Hz merges; 80 Hz is a new mode; a grid at 60 Hz is refused.
        assert_eq!(
            add_entry(&mut modes, line_mode("b", Some(60.0004), 45.0, 0.0)),
            Ok(Added::Merged(0))
        );
        assert_eq!(add_entry(&mut modes, line_mode("c", Some(80.0), 45.0, 0.0)), Ok(Added::New));
        let grid =
            Grid { nx: 2, ny: 2, size_mm: [300.0, 200.0], values: vec![1.0, -1.0, 1.0, -1.0] };
        let e = add_entry(&mut modes, sampled_mode("g", Some(60.0), &grid)).unwrap_err();
        assert_eq!((e.index, e.existing.as_str(), e.added.as_str()), (0, "a", "g"));
        let e = e.to_string();
        assert!(
            e.contains("[[mode]] 1 (a)") && e.contains("60 Hz") && e.contains("lines of g"),
            "{e}"
        );
        let mut loud = line_mode("d", Some(80.0), 0.0, 0.0);
        loud.amplitude = Some(0.5);
        assert!(add_entry(&mut modes, loud).is_err(), "other keys differ: not merged");
        let table = PlateTable { size_mm: Some([300.0, 200.0]), ..PlateTable::default() };
        let text = render(&table, modes).unwrap();
        let model = PlateModel::parse(&text, "t").unwrap();
        assert_eq!(model.modes.len(), 2);
        assert!(matches!(&model.modes[0].node, Node::Lines(l) if l.len() == 3), "{text}");
        assert!(matches!(model.modes[1].node, Node::Line { .. }));
    }

    #[test]
    fn a_measured_mode_is_kept_but_refused_until_its_node_is_filled() {
        use crate::model::plate::check_mode;
        let table =
            PlateTable { name: "p".into(), size_mm: Some([200.0, 150.0]), ..PlateTable::default() };
        let out = render(&table, vec![measured_mode(181.5049, Some(47.6))]).unwrap();
        assert!(out.contains("name = \"swept 181.50 Hz, Q 48\""), "{out}");
        assert!(out.contains("freq_hz = 181.505"), "{out}");
        let back = PlateFile::parse(&out, "out").unwrap();
        let err = check_mode(0, &back.mode[0], [200.0, 150.0]).unwrap_err().to_string();
        assert!(err.contains("node") && err.contains("swept 181.50 Hz"), "{err}");
        assert!(err.contains("chladni plate"), "the fix names where a node comes from: {err}");
    }
}
