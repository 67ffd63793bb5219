//! Where a study file's errors point: the line of a span, the key written
//! on a line, and TOML's own errors in words a person wrote.

use crate::scenario::field_of_message;
use crate::study::file::StudyFileError;
use std::ops::Range;

/// Where errors point: the text, for lines, and the file's name.
pub(super) struct Ctx<'a> {
    pub(super) text: &'a str,
    pub(super) origin: &'a str,
}

impl Ctx<'_> {
    pub(super) fn line_of(&self, byte: usize) -> usize {
        self.text[..byte.min(self.text.len())].matches('\n').count() + 1
    }

    pub(super) fn err(&self, span: Option<Range<usize>>, field: impl Into<String>, problem: impl Into<String>) -> StudyFileError {
        StudyFileError {
            origin: self.origin.to_string(),
            line: span.map(|s| self.line_of(s.start)),
            field: Some(field.into()).filter(|f: &String| !f.is_empty()),
            problem: problem.into(),
        }
    }

    /// The value `raw` names among `choices` (the first where `raw` is
    /// absent); else an error at `field` saying what is `accepted`.
    pub(super) fn choice<V: Copy>(&self, raw: Option<&toml::Spanned<String>>, field: &str, choices: &[(&str, V)], accepted: &str) -> Result<V, StudyFileError> {
        let Some(raw) = raw else { return Ok(choices[0].1) };
        let given = raw.get_ref().as_str();
        choices.iter().find(|(name, _)| *name == given).map(|&(_, v)| v).ok_or_else(|| self.err(Some(raw.span()), field, format!("`{given}`: {accepted}")))
    }

    /// The key written on `line` (1-based), if the line is `key = …`.
    pub(super) fn key_on_line(&self, line: usize) -> Option<String> {
        let text = self.text.lines().nth(line.checked_sub(1)?)?;
        let (key, _) = text.split_once('=')?;
        let key = key.trim().trim_matches('"');
        (!key.is_empty() && !key.starts_with('[') && !key.contains(' ')).then(|| key.to_string())
    }

    /// The byte span of `key = …` inside the table written at `table`, if
    /// the key is written there. A table's span may be its header alone:
    /// its keys are the lines after it, up to the next header.
    pub(super) fn key_span(&self, table: &Range<usize>, key: &str) -> Option<Range<usize>> {
        let start = table.start.min(self.text.len());
        let mut offset = start;
        for (k, line) in self.text[start..].split_inclusive('\n').enumerate() {
            let t = line.trim_start();
            if k > 0 && t.starts_with('[') && offset >= table.end {
                return None;
            }
            let rest = t.strip_prefix(key).or_else(|| t.strip_prefix(&format!("\"{key}\"")));
            if rest.is_some_and(|r| r.trim_start().starts_with('=')) {
                return Some(offset..offset + line.len());
            }
            offset += line.len();
        }
        None
    }

    /// A TOML syntax or type error: its line, and the key written there.
    pub(super) fn toml_error(&self, e: &toml::de::Error) -> StudyFileError {
        let line = e.span().map(|s| self.line_of(s.start));
        let mut message = e.message().trim().to_string();
        // serde names Rust's types; a person wrote a number or text.
        for (rust, words) in [("expected i64", "expected an integer"), ("expected f64", "expected a number"), ("expected a string", "expected text in quotes")] {
            message = message.replace(rust, words);
        }
        let mut field = line.and_then(|l| self.key_on_line(l));
        if let Some((named, said)) = field_of_message(&message, "missing: this table requires it") {
            field = Some(named);
            message = said;
        }
        StudyFileError { origin: self.origin.to_string(), line, field, problem: message }
    }
}
