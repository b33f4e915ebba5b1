//! The observations file of `chladni plate calibrate-speed` (docs/plate.md, "Calibrating the
//! settle speed"): CSV with a header, one observation per row, `#` comment lines allowed.
//!
//! ```csv
//! part,x_mm,y_mm,theta_deg,t_s,end_x_mm,end_y_mm,end_theta_deg
//! # time until it reached the node
//! triangle.json,60,100,30,42.5
//! # pose after 10 s (orientation not observed)
//! triangle.json,60,100,30,10,118.2,101.0,
//! ```
//!
//! `part` is a part file (relative to the CSV's directory) or the name or file name of a part
//! given with `--part`; the start pose is the centroid (mm, plate frame) and orientation
//! (degrees, docs/physics.md); `t_s` is either the time until the part reached the node (no
//! end columns) or the time after which the end pose was observed (end_x_mm and end_y_mm
//! given, end_theta_deg optional). Every error names the line and the column.

use std::path::{Path, PathBuf};

use crate::model::part::Part;
use crate::model::pose::Pose;

/// The header, column by column.
pub(crate) const COLUMNS: [&str; 8] =
    ["part", "x_mm", "y_mm", "theta_deg", "t_s", "end_x_mm", "end_y_mm", "end_theta_deg"];

/// Most rows read (a stopwatch session has tens).
pub const MAX_ROWS: usize = 100_000;

/// What was measured in one observation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Measured {
    /// Seconds from switching the mode on until the part reached the node (see the module
    /// docs for the definition).
    TimeToNode {
        /// Seconds.
        t_s: f64,
    },
    /// The pose `t_s` seconds after switching the mode on (orientation optional).
    PoseAfter {
        /// Seconds.
        t_s: f64,
        /// Centroid x (mm).
        x_mm: f64,
        /// Centroid y (mm).
        y_mm: f64,
        /// Orientation (deg), when observed.
        theta_deg: Option<f64>,
    },
}

/// One observation: a part dropped at a start pose, and what was measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Where it was written (a CSV line, 1-based), for messages.
    pub line: usize,
    /// Index of the part in the fit's part list.
    pub part: usize,
    /// Start pose (centroid mm, θ rad).
    pub start: Pose,
    /// The measurement.
    pub measured: Measured,
}

/// What is wrong with an observations file.
#[derive(Debug, thiserror::Error)]
pub enum ObservationsError {
    /// The file could not be read.
    #[error("cannot read observations {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Not CSV (e.g. not UTF-8).
    #[error("line {line}: not CSV: {message}")]
    Csv {
        /// 1-based line.
        line: u64,
        /// What the reader said.
        message: String,
    },
    /// The header is not the documented one.
    #[error(
        "line 1, column {column}: header `{found}`, expected `{expected}` (the header is {})",
        COLUMNS.join(",")
    )]
    Header {
        /// 1-based column.
        column: usize,
        /// What is there.
        found: String,
        /// What belongs there.
        expected: &'static str,
    },
    /// A row with a number of fields other than 5 or 8.
    #[error(
        "line {line}: {count} fields; a row has 5 (part, x_mm, y_mm, theta_deg, t_s: time to the \
         node) or 8 (…, end_x_mm, end_y_mm, end_theta_deg: pose after t_s)"
    )]
    Fields {
        /// 1-based line.
        line: u64,
        /// Fields found.
        count: usize,
    },
    /// A value that is not what its column needs.
    #[error("line {line}, column {column} ({name}): `{value}` {problem}")]
    Value {
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: usize,
        /// The column's name.
        name: &'static str,
        /// The value as written.
        value: String,
        /// What is wrong and what it must be.
        problem: String,
    },
    /// More rows than [`MAX_ROWS`].
    #[error("more than {MAX_ROWS} observations")]
    TooMany,
    /// A header and no rows.
    #[error("no observations: the file has a header and no rows")]
    Empty,
}

/// One row as written: the part reference, start pose (deg) and the measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// 1-based line.
    pub line: u64,
    /// The `part` column.
    pub part: String,
    /// x_mm, y_mm, theta_deg.
    pub start: [f64; 3],
    /// What was measured.
    pub measured: Measured,
}

fn value_error(line: u64, column: usize, value: &str, problem: &str) -> ObservationsError {
    ObservationsError::Value {
        line,
        column: column + 1,
        name: COLUMNS[column],
        value: value.to_string(),
        problem: problem.to_string(),
    }
}

/// A finite number in column `column` (0-based), or `None` when empty.
fn number(line: u64, column: usize, field: &str) -> Result<Option<f64>, ObservationsError> {
    if field.is_empty() {
        return Ok(None);
    }
    let v: f64 = field
        .parse()
        .map_err(|_| value_error(line, column, field, "is not a number (mm, s or degrees)"))?;
    if !v.is_finite() || v.abs() > 1e7 {
        return Err(value_error(line, column, field, "must be a finite number (at most 1e7)"));
    }
    Ok(Some(v))
}

/// Parses the CSV text (see the module docs).
pub fn parse(text: &str) -> Result<Vec<Row>, ObservationsError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    // The reader's line numbers do not count comment lines, and a record's position is where
    // the reader began, before the comment and empty lines it skipped: the line named is the
    // first line from there that holds data, counted in the file.
    let line_at = |byte: u64| {
        let bytes = text.as_bytes();
        let mut at = (byte as usize).min(bytes.len());
        let mut line = 1 + bytes[..at].iter().filter(|&&b| b == b'\n').count() as u64;
        while let Some(rest) = bytes.get(at..).filter(|r| !r.is_empty()) {
            let len = rest.iter().position(|&b| b == b'\n').map_or(rest.len(), |n| n + 1);
            let content = rest[..len].trim_ascii();
            if !(content.is_empty() || rest[0] == b'#') {
                break;
            }
            at += len;
            line += 1;
        }
        line
    };
    let csv_error = |e: csv::Error| ObservationsError::Csv {
        line: e.position().map_or(0, |p| line_at(p.byte())),
        message: e.to_string(),
    };
    let header = reader.headers().map_err(csv_error)?.clone();
    for (column, expected) in COLUMNS.iter().enumerate() {
        let found = header.get(column).unwrap_or("");
        // The end columns may be left out when no row uses them.
        if found.is_empty() && column >= 5 && header.len() == 5 {
            break;
        }
        if found != *expected {
            return Err(ObservationsError::Header {
                column: column + 1,
                found: found.into(),
                expected,
            });
        }
    }
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(csv_error)?;
        let line = record.position().map_or(0, |p| line_at(p.byte()));
        if rows.len() == MAX_ROWS {
            return Err(ObservationsError::TooMany);
        }
        rows.push(row(line, &record)?);
    }
    if rows.is_empty() {
        return Err(ObservationsError::Empty);
    }
    Ok(rows)
}

/// One record as a [`Row`].
fn row(line: u64, record: &csv::StringRecord) -> Result<Row, ObservationsError> {
    let count = record.len();
    if count != 5 && count != 8 {
        return Err(ObservationsError::Fields { line, count });
    }
    let field = |i: usize| record.get(i).unwrap_or("");
    let part = field(0).to_string();
    if part.is_empty() {
        return Err(value_error(line, 0, "", "is empty: name the part file"));
    }
    let need = |i: usize| {
        number(line, i, field(i))?
            .ok_or_else(|| value_error(line, i, "", "is empty: give a number"))
    };
    let start = [need(1)?, need(2)?, need(3)?];
    let t_s = need(4)?;
    if t_s < 0.0 {
        return Err(value_error(line, 4, field(4), "is negative: give seconds ≥ 0"));
    }
    let end = [5, 6, 7].map(|i| if count == 8 { number(line, i, field(i)) } else { Ok(None) });
    let [ex, ey, eth] = end;
    let measured = match (ex?, ey?, eth?) {
        (None, None, None) => Measured::TimeToNode { t_s },
        (Some(x_mm), Some(y_mm), theta_deg) => Measured::PoseAfter { t_s, x_mm, y_mm, theta_deg },
        (None, _, _) => {
            return Err(value_error(
                line,
                5,
                "",
                "is empty: a pose after t_s needs end_x_mm and end_y_mm",
            ));
        }
        (Some(_), None, _) => {
            return Err(value_error(
                line,
                6,
                "",
                "is empty: a pose after t_s needs end_x_mm and end_y_mm",
            ));
        }
    };
    Ok(Row { line, part, start, measured })
}

/// The parts and observations of some rows: a row's `part` is one of `given` (path as
/// given, its file name, or the part's name), else a part file relative to `dir`, loaded once.
pub fn resolve(
    rows: &[Row],
    dir: &Path,
    given: &[(PathBuf, Part)],
) -> Result<(Vec<Part>, Vec<Observation>), ObservationsError> {
    let mut parts: Vec<(PathBuf, Part)> = given.to_vec();
    let mut obs = Vec::with_capacity(rows.len());
    for r in rows {
        let named = |(p, part): &(PathBuf, Part)| {
            p.as_os_str() == r.part.as_str()
                || p.file_name().is_some_and(|f| f == r.part.as_str())
                || part.name == r.part
        };
        let index = match parts.iter().position(named) {
            Some(i) => i,
            None => {
                let path = dir.join(&r.part);
                let part = Part::load(&path).map_err(|e| {
                    value_error(r.line, 0, &r.part, &format!("is no part: {}: {e}", path.display()))
                })?;
                parts.push((PathBuf::from(&r.part), part));
                parts.len() - 1
            }
        };
        let [x, y, th] = r.start;
        obs.push(Observation {
            line: r.line as usize,
            part: index,
            start: Pose { x, y, theta: th.to_radians() },
            measured: r.measured,
        });
    }
    Ok((parts.into_iter().map(|(_, p)| p).collect(), obs))
}

/// Refuses rows whose start or end centroid lies off a plate of `size_mm` ([0, W]×[0, H]).
pub fn check_on_plate(rows: &[Row], size_mm: [f64; 2]) -> Result<(), ObservationsError> {
    for r in rows {
        let mut points = vec![(1, r.start[0], size_mm[0]), (2, r.start[1], size_mm[1])];
        if let Measured::PoseAfter { x_mm, y_mm, .. } = r.measured {
            points.extend([(5, x_mm, size_mm[0]), (6, y_mm, size_mm[1])]);
        }
        for (column, v, side) in points {
            if !(0.0..=side).contains(&v) {
                let problem = format!("is off the plate: give 0..={side} mm (plate frame)");
                return Err(value_error(r.line, column, &v.to_string(), &problem));
            }
        }
    }
    Ok(())
}

/// Reads and parses an observations file.
pub fn load(path: &Path) -> Result<Vec<Row>, ObservationsError> {
    let text = std::fs::read_to_string(path)
        .map_err(|source| ObservationsError::Io { path: path.to_path_buf(), source })?;
    parse(&text)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "part,x_mm,y_mm,theta_deg,t_s,end_x_mm,end_y_mm,end_theta_deg\n";

    #[test]
    fn rows_of_both_kinds_with_comments() {
        let text = format!(
            "{HEAD}# a comment\ntri.json, 60, 100, 30, 42.5\ntri.json,60,100,30,10,118.2,101.0,\n\
             tri.json,60,100,30,10,118.2,101.0,91\n"
        );
        let rows = parse(&text).unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!(rows[0].line, 3);
        assert_eq!(rows[0].measured, Measured::TimeToNode { t_s: 42.5 });
        assert_eq!(
            rows[1].measured,
            Measured::PoseAfter { t_s: 10.0, x_mm: 118.2, y_mm: 101.0, theta_deg: None }
        );
        assert_eq!(rows[0].start, [60.0, 100.0, 30.0]);
        // A five-column header is enough for time observations.
        let rows = parse("part,x_mm,y_mm,theta_deg,t_s\na,1,2,3,4\n").unwrap();
        assert_eq!(rows[0].measured, Measured::TimeToNode { t_s: 4.0 });
    }

    #[test]
    fn errors_name_line_and_column() {
        let err = |body: &str| parse(&format!("{HEAD}{body}")).unwrap_err().to_string();
        assert_eq!(
            err("a,1,2,3,abc\n"),
            "line 2, column 5 (t_s): `abc` is not a number (mm, s or degrees)"
        );
        assert!(err("a,1,2,3,-1\n").contains("line 2, column 5 (t_s): `-1` is negative"));
        assert!(err("a,1,2,3,4\nb,1,NaN,3,4\n").contains("line 3, column 3 (y_mm): `NaN`"));
        assert!(err("a,1,2,3\n").contains("line 2: 4 fields"));
        assert!(err("a,1,2,3,4,5,,\n").contains("line 2, column 7 (end_y_mm)"));
        assert!(err(",1,2,3,4\n").contains("column 1 (part)"));
        assert!(err("a,1,,3,4\n").contains("column 3 (y_mm): `` is empty"));
        let e = parse("part,x,y,theta_deg,t_s\n").unwrap_err().to_string();
        assert!(e.starts_with("line 1, column 2: header `x`, expected `x_mm`"), "{e}");
        assert!(matches!(parse(HEAD), Err(ObservationsError::Empty)));
    }

    #[test]
    fn parts_by_name_or_file_relative_to_the_csv() {
        let dir = std::env::temp_dir().join(format!("chladni-obs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("sq.json"),
            r#"{"name": "sq", "outline": [[0,0],[9,0],[9,9],[0,9]]}"#,
        )
        .unwrap();
        let tri =
            Part::new("tri".into(), vec![[0.0, 0.0], [30.0, 0.0], [8.0, 20.0]], vec![]).unwrap();
        let rows =
            parse(&format!("{HEAD}tri,1,2,3,4\nsq.json,1,2,0,4\nsq.json,5,6,0,1\n")).unwrap();
        let given = vec![(PathBuf::from("parts/tri.json"), tri)];
        let (parts, obs) = resolve(&rows, &dir, &given).unwrap();
        assert_eq!(parts.len(), 2);
        assert_eq!(obs.iter().map(|o| o.part).collect::<Vec<_>>(), vec![0, 1, 1]);
        assert!((obs[0].start.theta - 3f64.to_radians()).abs() < 1e-15);
        let rows = parse(&format!("{HEAD}nope.json,1,2,3,4\n")).unwrap();
        let e = resolve(&rows, &dir, &given).unwrap_err().to_string();
        assert!(e.starts_with("line 2, column 1 (part): `nope.json` is no part"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
