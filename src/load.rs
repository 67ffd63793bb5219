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
use std::cell::RefCell;
use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The largest scenario file read: 64 MiB.
pub const MAX_SCENARIO_BYTES: u64 = 64 << 20;
/// The largest file a stage reads (a link trace, a recording): 1 GiB.
pub const MAX_STAGE_FILE_BYTES: u64 = 1 << 30;

/// What a file netfi is told to read turned out to be instead of a regular
/// file; carried inside the `io::Error` of [`open_regular`] (kind
/// `InvalidInput`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{0}: only regular files are read")]
pub struct NotRegular(pub &'static str);

/// Opens `path` for reading if it is a regular file: the one check of every
/// file a user names for netfi to read (a scenario, the files its stages
/// name, a capture, a study, a run's directory, a bag, …). It is opened
/// without blocking (a FIFO without a writer would block the open for
/// ever) and without becoming a controlling terminal, and checked on the
/// open descriptor (`fstat`), so what is read is what was checked. A
/// directory, device, FIFO or socket is an `InvalidInput` error holding
/// [`NotRegular`]; `O_NONBLOCK` does nothing to reads of a regular file.
pub fn open_regular(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    let file = std::fs::OpenOptions::new().read(true).custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY).open(path)?;
    let t = file.metadata()?.file_type();
    let other = if t.is_file() {
        return Ok(file);
    } else if t.is_dir() {
        "a directory"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    };
    Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, NotRegular(other)))
}

/// `std::fs::read` for a regular file only ([`open_regular`]).
pub fn read_file(path: &Path) -> std::io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    open_regular(path)?.read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// An error of [`open_regular`] in words: what the file is, or `cannot
/// read: …`.
fn open_error(e: &std::io::Error) -> String {
    match e.get_ref().and_then(|inner| inner.downcast_ref::<NotRegular>()) {
        Some(not) => not.to_string(),
        None => format!("cannot read: {e}"),
    }
}

/// Reads the regular file `path` ([`open_regular`]), of at most
/// `max_bytes`; the error says what was found instead (and is to be
/// prefixed with the file's name).
pub fn read_regular(path: &Path, max_bytes: u64) -> Result<Vec<u8>, String> {
    read_open(open_regular(path).map_err(|e| open_error(&e))?, max_bytes)
}

/// Reads a file [`open_regular`] opened, of at most `max_bytes`.
fn read_open(file: std::fs::File, max_bytes: u64) -> Result<Vec<u8>, String> {
    let len = file.metadata().map_err(|e| format!("cannot read: {e}"))?.len();
    let too_large = |n: u64| format!("{n} bytes: at most {max_bytes} are read (a larger file is not one netfi wrote or ships)");
    if len > max_bytes {
        return Err(too_large(len));
    }
    let mut bytes = Vec::with_capacity(len as usize);
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
///
/// Each file is read and parsed once: stages that name the same file (by
/// any name: the same device and inode) share one copy, however many
/// stages and phases name it.
pub struct DirFiles {
    dir: PathBuf,
    traces: Shared<FileId, Schedule>,
    /// By file and the records a capture is read up to.
    recordings: Shared<(FileId, Option<u64>), Recording>,
}

/// A file's identity: its device and inode.
type FileId = (u64, u64);

/// What was parsed of the files read, by key.
type Shared<K, T> = RefCell<HashMap<K, Arc<T>>>;

impl DirFiles {
    pub fn new(dir: impl Into<PathBuf>) -> DirFiles {
        DirFiles { dir: dir.into(), traces: RefCell::default(), recordings: RefCell::default() }
    }

    /// Opens `file` ([`open_regular`]): the file and its identity.
    fn open(&self, file: &str) -> Result<(std::fs::File, FileId), FileError> {
        use std::os::unix::fs::MetadataExt;
        let path = self.dir.join(file);
        let err = |problem: String| FileError { file: path.display().to_string(), at: None, problem };
        let f = open_regular(&path).map_err(|e| err(open_error(&e)))?;
        let meta = f.metadata().map_err(|e| err(format!("cannot read: {e}")))?;
        Ok((f, (meta.dev(), meta.ino())))
    }

    /// Reads the file `open` gave, of at most [`MAX_STAGE_FILE_BYTES`].
    fn read(&self, file: &str, f: std::fs::File) -> Result<Vec<u8>, FileError> {
        read_open(f, MAX_STAGE_FILE_BYTES).map_err(|problem| FileError { file: self.dir.join(file).display().to_string(), at: None, problem })
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
        let (f, id) = self.open(file)?;
        if let Some(shared) = self.traces.borrow().get(&id) {
            return Ok(shared.clone());
        }
        let text = self.text(file, self.read(file, f)?)?;
        let schedule = Schedule::parse(&text)
            .map(Arc::new)
            .map_err(|e| FileError { file: file.into(), at: e.line.map(|l| format!("line {l}")), problem: e.problem })?;
        self.traces.borrow_mut().insert(id, schedule.clone());
        Ok(schedule)
    }

    fn recording(&self, file: &str, max_records: Option<u64>) -> Result<Arc<Recording>, FileError> {
        let (f, id) = self.open(file)?;
        if let Some(shared) = self.recordings.borrow().get(&(id, max_records)) {
            return Ok(shared.clone());
        }
        let bytes = self.read(file, f)?;
        let recording = if bytes.starts_with(&crate::capture::LZ4_MAGIC) {
            let limits = max_records.map_or_else(crate::capture::CaptureLimits::default, crate::capture::CaptureLimits::records);
            recording_of_capture(file, &bytes, limits)?
        } else {
            let text = self.text(file, bytes)?;
            Recording::parse_trace_csv(&text).map_err(|e| FileError { file: file.into(), at: e.at, problem: e.problem })?
        };
        let recording = Arc::new(recording);
        self.recordings.borrow_mut().insert((id, max_records), recording.clone());
        Ok(recording)
    }
}

/// The delays of a delay-trial capture, read up to `limits`, keeping only
/// each record's delay; a capture in the other layout has none to replay.
fn recording_of_capture(file: &str, bytes: &[u8], limits: crate::capture::CaptureLimits) -> Result<Recording, FileError> {
    use crate::capture::{CaptureReader, RecordLayout};
    let err = |at: Option<String>, problem: String| FileError { file: file.into(), at, problem };
    let mut delays: Vec<f32> = Vec::new();
    let scanned = crate::capture::scan(CaptureReader::new(bytes), limits, |r| {
        if let Some(d) = r.delay_s {
            delays.push(d);
        }
    })
    .map_err(|e| err(None, e.to_string()))?;
    if scanned.layout != RecordLayout::Delay {
        return Err(err(
            None,
            format!("a capture of layout `{}` records no delays: only delay-trial captures (`{}`) can be replayed", scanned.layout.describe(), RecordLayout::Delay.describe()),
        ));
    }
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

    /// Stages and phases naming one file, by whatever name, share one
    /// parsed copy; a trace of 128 MiB once cost 0.52 GB a stage.
    #[test]
    fn stages_naming_one_file_share_one_copy() {
        use crate::model::AnyModel;
        let dir = scratch("share");
        std::fs::write(dir.join("t.up"), "1\n2\n3\n").unwrap();
        std::os::unix::fs::symlink(dir.join("t.up"), dir.join("link.up")).unwrap();
        let mut text = String::new();
        for (k, name) in ["t.up", "./t.up", "link.up", "t.up"].iter().enumerate() {
            text.push_str(&format!("[[phase]]\nstart_s = {}\n[[phase.stage]]\nmodel = \"trace\"\nfile = \"{name}\"\n", k * 10));
        }
        std::fs::write(dir.join("s.toml"), text).unwrap();
        let spec = parse_file(&dir.join("s.toml")).unwrap();
        let scenario = crate::scenario::Scenario::new(&spec, 1).unwrap();
        let schedules: Vec<*const Schedule> = scenario
            .phases()
            .iter()
            .flat_map(|p| p.stages())
            .map(|st| match st.model() {
                AnyModel::LinkTrace(m) => m.schedule() as *const Schedule,
                _ => unreachable!(),
            })
            .collect();
        assert_eq!(schedules.len(), 4);
        assert!(schedules.iter().all(|s| *s == schedules[0]), "{schedules:?}");
        // Recordings too, per limit read with.
        let files = DirFiles::new(&dir);
        std::fs::write(dir.join("r.csv"), "fate,reason,delay_ns\ndelivered,,5\n").unwrap();
        let a = files.recording("r.csv", None).unwrap();
        assert!(Arc::ptr_eq(&a, &files.recording("./r.csv", None).unwrap()));
        assert!(!Arc::ptr_eq(&a, &files.recording("r.csv", Some(7)).unwrap()));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A delay capture a replay stage names is read up to the capture
    /// limit, or the stage's own `max_records`, and refused beyond it.
    #[test]
    fn a_replay_capture_is_read_up_to_its_limit() {
        let dir = scratch("replay-limit");
        let mut w = crate::capture::CaptureWriter::create(dir.join("d.lz4")).unwrap();
        let frame = crate::frame::ItpFrame::default().with_checksum().to_bytes();
        for i in 0..11u32 {
            w.write_delay_record(u64::from(i) * 1_000_000, 0.1, &frame).unwrap();
        }
        w.finish().unwrap();
        let stage = |extra: &str| {
            std::fs::write(dir.join("s.toml"), format!("[[stage]]\nmodel = \"replay\"\nfile = \"d.lz4\"\n{extra}")).unwrap();
            parse_file(&dir.join("s.toml"))
        };
        assert!(stage("").is_ok());
        assert!(stage("max_records = 11\n").is_ok());
        let e = stage("max_records = 10\n").unwrap_err();
        assert_eq!((e.line, e.field.as_deref()), (Some(3), Some("file")), "{e}");
        assert!(e.problem.contains("more than 10 records") && e.problem.contains("`max_records`"), "{e}");
        for bad in ["0", "268435457"] {
            let e = stage(&format!("max_records = {bad}\n")).unwrap_err();
            assert_eq!((e.line, e.field.as_deref()), (Some(4), Some("max_records")), "{e}");
            assert!(e.problem.contains("expected 1 to 268435456 records"), "{e}");
        }
        // Printed back, the limit is kept.
        assert!(stage("max_records = 11\n").unwrap().to_toml().contains("max_records = 11"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
