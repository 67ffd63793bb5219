//! Loading scenarios: the shell side of [`crate::scenario`], which only
//! parses text. This module reads scenario files, the files their stages
//! name (link traces, recordings: [`DirFiles`]), and decides whether a
//! command-line argument names a preset or a file.

use crate::model::{Recording, Schedule};
use crate::scenario::{parse_str_with, preset, FileError, ScenarioError, ScenarioFiles, ScenarioSpec, PRESET_NAMES};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Reads and validates a scenario file; errors name the file (and, for a
/// parse error, the line). A file without `name` is named after its stem.
/// Files its stages name are read relative to its directory.
pub fn parse_file(path: &Path) -> Result<ScenarioSpec, ScenarioError> {
    let origin = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError {
        origin: origin.clone(),
        line: None,
        location: None,
        field: None,
        problem: format!("cannot read the scenario file: {e}"),
    })?;
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
        std::fs::read(&path).map_err(|e| FileError { file: path.display().to_string(), at: None, problem: format!("cannot read: {e}") })
    }

    fn text(&self, file: &str, bytes: Vec<u8>) -> Result<String, FileError> {
        String::from_utf8(bytes).map_err(|_| FileError { file: file.into(), at: None, problem: "not text (UTF-8)".into() })
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
