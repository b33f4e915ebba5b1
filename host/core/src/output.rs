//! Writing output files safely, for every command that writes: a command never overwrites one
//! of its own inputs ([`OutputGuard`]), and every file appears whole or not at all
//! ([`write_atomic`], [`write_with`]: written to a temporary file in the same directory, then
//! renamed over the target, so a crash or a full disk never leaves half a file).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

/// Why an output was not written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The output is one of the command's inputs (bad input: nothing was done).
    #[error("{flag} {output} is the {role} {input}: refusing to overwrite an input")]
    IsInput {
        /// The option that named the output (`--out`, `--plot`, ...).
        flag: String,
        /// The output as given.
        output: PathBuf,
        /// What the input is (`part`, `plate`, ...).
        role: String,
        /// The input as given.
        input: PathBuf,
    },
    /// Writing, or renaming the finished temporary file, failed.
    #[error("writing {path}: {message}")]
    Write {
        /// The output.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

impl OutputError {
    /// True when the error is the user's (an output that names an input).
    pub fn is_bad_input(&self) -> bool {
        matches!(self, OutputError::IsInput { .. })
    }
}

/// A command's input files, to refuse outputs that would overwrite one of them. Paths are
/// compared canonically (symbolic links and `..` resolved).
#[derive(Debug, Default, Clone)]
pub struct OutputGuard {
    inputs: Vec<(String, PathBuf, PathBuf)>,
}

impl OutputGuard {
    /// A guard with no inputs yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records an input (`role` names it in the error, e.g. "part"). A path that does not
    /// exist is no file to protect.
    pub fn input(mut self, role: &str, path: &Path) -> Self {
        if let Ok(canonical) = path.canonicalize() {
            self.inputs.push((role.to_string(), path.to_path_buf(), canonical));
        }
        self
    }

    /// Refuses `output` (named by option `flag`) when it is one of the inputs.
    pub fn check(&self, flag: &str, output: &Path) -> Result<(), OutputError> {
        let Some(canonical) = canonical_output(output) else { return Ok(()) };
        match self.inputs.iter().find(|(_, _, c)| *c == canonical) {
            Some((role, input, _)) => Err(OutputError::IsInput {
                flag: flag.to_string(),
                output: output.to_path_buf(),
                role: role.clone(),
                input: input.clone(),
            }),
            None => Ok(()),
        }
    }
}

/// Where `output` would land: the file itself if it exists, else its canonical directory
/// joined with its name (`None` when the directory does not exist either).
fn canonical_output(output: &Path) -> Option<PathBuf> {
    if let Ok(c) = output.canonicalize() {
        return Some(c);
    }
    let name = output.file_name()?;
    let dir = match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    Some(dir.canonicalize().ok()?.join(name))
}

/// Writes `bytes` to `path` atomically.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    write_with(path, |tmp| std::fs::write(tmp, bytes).map_err(|e| e.to_string()))
}

/// Writes `path` atomically through `render`, which writes the whole file to the temporary
/// path it is given: in the same directory, with the same extension (so encoders that pick
/// the format by extension, like image and plot backends, still do), then renamed to `path`.
/// On any failure the temporary file is removed and `path` is left as it was.
pub fn write_with<E: std::fmt::Display>(
    path: &Path,
    render: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), OutputError> {
    let fail = |message: String| OutputError::Write { path: path.to_path_buf(), message };
    if path.is_dir() {
        return Err(fail("is a directory".into()));
    }
    let tmp = temp_path(path);
    let done = render(&tmp)
        .map_err(|e| e.to_string())
        .and_then(|()| std::fs::rename(&tmp, path).map_err(|e| e.to_string()));
    if let Err(message) = done {
        let _ = std::fs::remove_file(&tmp);
        return Err(fail(message));
    }
    Ok(())
}

/// `dir/.name.tmp-PID-N.ext`: hidden, unique within the process, same directory and extension.
fn temp_path(path: &Path) -> PathBuf {
    static COUNT: AtomicU32 = AtomicU32::new(0);
    let n = COUNT.fetch_add(1, Ordering::Relaxed);
    let stem = path.file_stem().map_or("out".into(), |s| s.to_string_lossy());
    let mut name = format!(".{stem}.tmp-{}-{n}", std::process::id());
    if let Some(ext) = path.extension() {
        name += ".";
        name += &ext.to_string_lossy();
    }
    path.with_file_name(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("chladni-output-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn an_input_is_refused_by_any_spelling_and_other_paths_pass() {
        let d = dir("guard");
        let part = d.join("tri.json");
        std::fs::write(&part, "{}").unwrap();
        let guard = OutputGuard::new().input("part", &part).input("plate", &d.join("missing"));
        let spelled = d.join("sub/../tri.json");
        std::fs::create_dir_all(d.join("sub")).unwrap();
        let err = guard.check("--out", &spelled).unwrap_err();
        assert!(err.is_bad_input());
        let msg = err.to_string();
        assert!(msg.contains("--out") && msg.contains("is the part") && msg.contains("tri.json"));
        assert!(guard.check("--out", &d.join("plan.json")).is_ok());
        assert!(guard.check("--out", &d.join("nowhere/plan.json")).is_ok());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn writes_are_whole_or_nothing() {
        let d = dir("atomic");
        let f = d.join("a.txt");
        write_atomic(&f, b"one").unwrap();
        write_atomic(&f, b"two").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"two");
        // A render that fails leaves the old file and no temporary file.
        let r = write_with(&f, |tmp| {
            assert_eq!(tmp.extension().unwrap(), "txt");
            std::fs::write(tmp, "half").unwrap();
            Err("disk full")
        });
        assert!(r.unwrap_err().to_string().contains("disk full"));
        assert_eq!(std::fs::read(&f).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        assert!(write_atomic(&d, b"x").unwrap_err().to_string().contains("is a directory"));
        std::fs::remove_dir_all(&d).unwrap();
    }
}
