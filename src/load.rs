//! Loading scenarios: the shell side of [`crate::scenario`], which only
//! parses text. This module reads scenario files and decides whether a
//! command-line argument names a preset or a file.

use crate::scenario::{parse_str, preset, ScenarioError, ScenarioSpec, PRESET_NAMES};
use std::path::Path;

/// Reads and validates a scenario file; errors name the file (and, for a
/// parse error, the line). A file without `name` is named after its stem.
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
    parse_str(&text, &origin, &default_name)
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
