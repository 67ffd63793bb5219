//! Loading scenarios: the shell side of [`crate::scenario`], which only
//! parses text. This module reads scenario files, the files their stages
//! name (link traces, recordings: [`DirFiles`]), and decides whether a
//! command-line argument names a preset or a file.
//!
//! A scenario may come from someone else (the browser front end writes the
//! scenario it is sent, and netfi often runs as root), so what it makes
//! netfi read is bounded: only regular files (not a device, a FIFO or a
//! directory, which are refused before a byte is read), of at most
//! [`MAX_SCENARIO_BYTES`] for a scenario and [`MAX_STAGE_FILE_BYTES`] for
//! a file a stage names; and an error in a file a stage names gives the
//! line or record and what was expected, never the file's content.

use crate::model::{Recording, Schedule};
use crate::scenario::{parse_str_with, preset, FileError, ScenarioError, ScenarioFiles, ScenarioSpec, PRESET_NAMES};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The largest scenario file read: 64 MiB.
pub const MAX_SCENARIO_BYTES: u64 = 64 << 20;
/// The largest file a stage reads (a link trace, a recording): 1 GiB.
pub const MAX_STAGE_FILE_BYTES: u64 = 1 << 30;

/// Reads the regular file `path`, of at most `max_bytes`; the error says
/// what was found instead (and is to be prefixed with the file's name).
/// The file is opened without blocking, so a FIFO is refused rather than
/// waited on, and checked on the open descriptor, so what is read is what
/// was checked.
pub fn read_regular(path: &Path, max_bytes: u64) -> Result<Vec<u8>, String> {
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| format!("cannot read: {e}"))?;
    let meta = file.metadata().map_err(|e| format!("cannot read: {e}"))?;
    let t = meta.file_type();
    let other = if t.is_dir() {
        Some("a directory")
    } else if t.is_char_device() || t.is_block_device() {
        Some("a device")
    } else if t.is_fifo() {
        Some("a FIFO")
    } else if t.is_socket() {
        Some("a socket")
    } else if !t.is_file() {
        Some("not a regular file")
    } else {
        None
    };
    if let Some(what) = other {
        return Err(format!("{what}: only regular files are read"));
    }
    let too_large = |n: u64| format!("{n} bytes: at most {max_bytes} are read (a larger file is not one netfi wrote or ships)");
    if meta.len() > max_bytes {
        return Err(too_large(meta.len()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(max_bytes + 1).read_to_end(&mut bytes).map_err(|e| format!("cannot read: {e}"))?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// Reads and validates a scenario file; errors name the file (and, for a
/// parse error, the line). A file without `name` is named after its stem.
/// Files its stages name are read relative to its directory.
pub fn parse_file(path: &Path) -> Result<ScenarioSpec, ScenarioError> {
    let origin = path.display().to_string();
    let err = |problem: String| ScenarioError { origin: origin.clone(), line: None, location: None, field: None, problem };
    let bytes = read_regular(path, MAX_SCENARIO_BYTES).map_err(|e| err(format!("the scenario file: {e}")))?;
    let text = String::from_utf8(bytes).map_err(|e| err(format!("the scenario file is not text (UTF-8): byte {} is not", e.utf8_error().valid_up_to())))?;
    let default_name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let files = DirFiles::new(path.parent().unwrap_or(Path::new(".")));
    parse_str_with(&text, &origin, &default_name, &files)
}

/// Resolves a command-line scenario argument: a preset name (which wins over
/// a file of the same name), or a file.
pub fn resolve(arg: &str) -> Result<ScenarioSpec, ScenarioError> {
    if let Some(spec) = preset(arg) {
        return Ok(spec);
    }
    let path = Path::new(arg);
    if path.exists() {
        return parse_file(path);
    }
    Err(ScenarioError {
        origin: arg.to_string(),
        line: None,
        location: None,
        field: None,
        problem: format!("neither a scenario file nor a preset (presets: {})", PRESET_NAMES.join(", ")),
    })
}

/// [`resolve`], with every file the scenario's stages name (link traces,
/// recordings) made absolute: the spec can then be written anywhere (a
/// run's output directory) and read again from there, and names the very
/// files that were read. A preset names none.
pub fn resolve_anchored(arg: &str) -> Result<ScenarioSpec, ScenarioError> {
    let mut spec = resolve(arg)?;
    if preset(arg).is_some() {
        return Ok(spec);
    }
    let dir = Path::new(arg).parent().unwrap_or(Path::new("."));
    for file in spec.files_mut() {
        *file = anchored(dir, file).map_err(|problem| ScenarioError { origin: arg.to_string(), line: None, location: None, field: Some("file".into()), problem })?;
    }
    Ok(spec)
}

/// `file` as a scenario in `dir` names it, as an absolute path: the file
/// itself with links followed, or (a file gone since it was read) the
/// path made absolute as it is.
fn anchored(dir: &Path, file: &str) -> Result<String, String> {
    let path = dir.join(file);
    let absolute = path.canonicalize().or_else(|_| std::path::absolute(&path)).map_err(|e| format!("`{file}`: cannot be made absolute: {e}"))?;
    absolute.into_os_string().into_string().map_err(|p| format!("`{file}`: its absolute path `{}` is not UTF-8 text, which a scenario file cannot name", p.to_string_lossy()))
}

/// The files a scenario names, read from a directory (absolute names as
/// they are). Errors name the file as written in the scenario, and the line
/// (link traces, `trace.csv`) or record (captures) that is wrong.
pub struct DirFiles {
    dir: PathBuf,
}

impl DirFiles {
    pub fn new(dir: impl Into<PathBuf>) -> DirFiles {
        DirFiles { dir: dir.into() }
    }

    fn read(&self, file: &str) -> Result<Vec<u8>, FileError> {
        let path = self.dir.join(file);
        read_regular(&path, MAX_STAGE_FILE_BYTES).map_err(|problem| FileError { file: path.display().to_string(), at: None, problem })
    }

    fn text(&self, file: &str, bytes: Vec<u8>) -> Result<String, FileError> {
        String::from_utf8(bytes).map_err(|e| FileError {
            file: file.into(),
            at: None,
            problem: format!("not text (UTF-8): byte {} is not", e.utf8_error().valid_up_to()),
        })
    }
}

impl ScenarioFiles for DirFiles {
    fn link_trace(&self, file: &str) -> Result<Arc<Schedule>, FileError> {
        let text = self.text(file, self.read(file)?)?;
        Schedule::parse(&text)
            .map(Arc::new)
            .map_err(|e| FileError { file: file.into(), at: e.line.map(|l| format!("line {l}")), problem: e.problem })
    }

    fn recording(&self, file: &str) -> Result<Arc<Recording>, FileError> {
        let bytes = self.read(file)?;
        let recording = if bytes.starts_with(&[0x04, 0x22, 0x4d, 0x18]) {
            recording_of_capture(file, &bytes)?
        } else {
            let text = self.text(file, bytes)?;
            Recording::parse_trace_csv(&text).map_err(|e| FileError { file: file.into(), at: e.at, problem: e.problem })?
        };
        Ok(Arc::new(recording))
    }
}

/// The delays of a delay-trial capture; a capture in the other layout has
/// none to replay.
fn recording_of_capture(file: &str, bytes: &[u8]) -> Result<Recording, FileError> {
    use crate::capture::RecordLayout;
    let err = |at: Option<String>, problem: String| FileError { file: file.into(), at, problem };
    let capture = crate::capture::parse(bytes).map_err(|e| err(None, e.to_string()))?;
    if capture.layout != RecordLayout::Delay {
        return Err(err(
            None,
            format!("a capture of layout `{}` records no delays: only delay-trial captures (`{}`) can be replayed", capture.layout.describe(), RecordLayout::Delay.describe()),
        ));
    }
    let delays: Vec<f32> = capture.records.iter().map(|r| r.delay_s.unwrap_or(0.0)).collect();
    Recording::from_delays_s(&delays).map_err(|e| err(e.at, e.problem))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scratch::dir as scratch;

    #[test]
    fn only_regular_files_of_bounded_size_are_read() {
        let dir = scratch("regular");
        std::fs::write(dir.join("small"), b"12\n").unwrap();
        assert_eq!(read_regular(&dir.join("small"), 3).unwrap(), b"12\n");
        let e = read_regular(&dir.join("small"), 2).unwrap_err();
        assert!(e.starts_with("3 bytes: at most 2 are read"), "{e}");
        assert!(read_regular(Path::new("/dev/zero"), 1 << 20).unwrap_err().starts_with("a device"));
        assert!(read_regular(&dir, 1 << 20).unwrap_err().starts_with("a directory"));
        let fifo = dir.join("fifo");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        // Refused at once, not waited on for a writer.
        assert!(read_regular(&fifo, 1 << 20).unwrap_err().starts_with("a FIFO"));
        assert!(read_regular(&dir.join("absent"), 1).unwrap_err().starts_with("cannot read"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_stage_file_that_is_not_a_regular_file_or_holds_a_secret_is_refused_without_echo() {
        let dir = scratch("echo");
        let secret = "root:$6$kFj2.secret$hash:19000:0:99999:7:::";
        std::fs::write(dir.join("shadow"), format!("{secret}\nbin:*:19000\n")).unwrap();
        for (model, file) in [("trace", "shadow"), ("replay", "shadow"), ("trace", "/dev/zero"), ("replay", "/dev/zero")] {
            let scenario = dir.join("s.toml");
            std::fs::write(&scenario, format!("[[stage]]\nmodel = \"{model}\"\nfile = \"{file}\"\n")).unwrap();
            let e = parse_file(&scenario).unwrap_err().to_string();
            assert!(!e.contains("root") && !e.contains("secret") && !e.contains("19000"), "{model} {file}: {e}");
            if file == "/dev/zero" {
                assert!(e.contains("a device: only regular files are read"), "{e}");
            } else {
                assert!(e.contains("shadow") && e.contains("line 1"), "{e}");
            }
        }
        let e = parse_file(&PathBuf::from("/dev/zero")).unwrap_err().to_string();
        assert!(e.contains("a device"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
