//! Scenario TOML → validated [`ScenarioSpec`]s, with errors that name the
//! file, the line, the field, and what would be accepted.
//!
//! Pure: the text comes in as a `&str` with the name of its source for
//! errors; reading files and telling a preset name from a path is the
//! shell's ([`crate::load`]).
//!
//! The file format (see `config/scenarios/*.toml` and the README):
//!
//! ```toml
//! name = "PLM-2 then DLM-2"     # optional; defaults to the file stem
//! seed = 7                      # optional; the command line wins
//! queue_capacity = 65536        # optional
//!
//! [[stage]]                     # a pipeline, in order
//! preset = "PLM-2"              # a study preset as one stage …
//!
//! [[stage]]
//! model = "delay"               # … or a model with its parameters
//! min_ms = 210
//! dist = "hyperexp"
//! weights = [0.89258, 0.10742]
//! rates_per_ms = [0.01081, 0.01624]
//! ```
//!
//! A timeline uses `[[phase]]` tables (`start_s` or `start_ms`, and either
//! `preset = "..."` or `[[phase.stage]]` tables) instead of top-level stages.
//! A whole-file `preset = "..."` is also accepted. A phase starts at most one
//! year after the first ([`MAX_PHASE_START_MS`]); the models bound their own
//! durations ([`crate::model::units`]).

use super::presets::preset_stages;
use crate::model::presets::{canonical_name, PRESET_NAMES};
use crate::model::units::MAX_PHASE_START_MS;
use super::spec::{PhaseSpec, ScenarioSpec, StageSpec};
use crate::model::ModelSpec;
use crate::model::ModelKind;
use serde::de::DeserializeOwned;
use serde::Deserialize;
use crate::model::replay::MAX_FATES;
use crate::model::{Recording, ReplayParams, Schedule};
use std::fmt;
use std::sync::Arc;
use toml::Spanned;

/// A scenario that could not be read, with where and why.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioError {
    /// The file, or `<preset>`/`<inline>` for scenarios not read from a file.
    pub origin: String,
    /// 1-based line in the file, when known.
    pub line: Option<usize>,
    /// Which part of the scenario, e.g. `stage 2 (ge_lomax)` or `phase 1`.
    pub location: Option<String>,
    /// The field as written, e.g. `alpha[1]`.
    pub field: Option<String>,
    /// What is wrong, and what would be accepted.
    pub problem: String,
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write_located(f, &self.origin, self.line, self.location.as_deref(), self.field.as_deref(), &self.problem)
    }
}

/// An error in a file as netfi says it: `origin:line: location: `field`:
/// problem`, each part there where known (scenario and study files alike).
pub(crate) fn write_located(
    f: &mut fmt::Formatter<'_>,
    origin: &str,
    line: Option<usize>,
    location: Option<&str>,
    field: Option<&str>,
    problem: &str,
) -> fmt::Result {
    write!(f, "{origin}")?;
    if let Some(line) = line {
        write!(f, ":{line}")?;
    }
    write!(f, ": ")?;
    if let Some(loc) = location {
        write!(f, "{loc}: ")?;
    }
    if let Some(field) = field {
        write!(f, "`{field}`: ")?;
    }
    write!(f, "{problem}")
}

impl std::error::Error for ScenarioError {}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    name: Option<String>,
    description: Option<String>,
    seed: Option<u64>,
    queue_capacity: Option<usize>,
    preset: Option<String>,
    stage: Option<Vec<Spanned<toml::Table>>>,
    phase: Option<Vec<Spanned<RawPhase>>>,
}

/// A time as a file writes it: a number in the field's unit, or a string
/// with its own (`"90s"`, `"2min"`; [`crate::model::parse_duration`]).
#[derive(Deserialize)]
#[serde(untagged)]
enum TimeValue {
    Number(f64),
    Text(String),
}

impl TimeValue {
    fn in_unit(&self, unit: crate::model::TimeUnit) -> Result<f64, String> {
        match self {
            TimeValue::Number(v) => Ok(*v),
            TimeValue::Text(t) => crate::model::parse_duration(t, unit),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPhase {
    name: Option<String>,
    start_s: Option<TimeValue>,
    start_ms: Option<TimeValue>,
    preset: Option<String>,
    stage: Option<Vec<Spanned<toml::Table>>>,
}

/// A file a scenario names that could not be used: which file, where in it
/// (`line 3`, `record 7`), and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileError {
    pub file: String,
    pub at: Option<String>,
    pub problem: String,
}

impl fmt::Display for FileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "`{}`", self.file)?;
        if let Some(at) = &self.at {
            write!(f, " {at}")?;
        }
        write!(f, ": {}", self.problem)
    }
}

/// The files a scenario's stages name (`trace` link traces, `replay`
/// recordings), read and parsed by the shell ([`crate::load`]): the core
/// only parses text.
pub trait ScenarioFiles {
    /// The link trace `file` names (relative to the scenario file).
    fn link_trace(&self, file: &str) -> Result<Arc<Schedule>, FileError>;
    /// The recording `file` names (a `trace.csv` or a delay capture, read
    /// up to `max_records` records, or the capture reader's default).
    fn recording(&self, file: &str, max_records: Option<u64>) -> Result<Arc<Recording>, FileError>;
}

/// No files: a scenario given as text alone cannot name any.
pub struct NoFiles;

impl NoFiles {
    fn refuse(file: &str) -> FileError {
        FileError { file: file.into(), at: None, problem: "a scenario not read from a file cannot name other files".into() }
    }
}

impl ScenarioFiles for NoFiles {
    fn link_trace(&self, file: &str) -> Result<Arc<Schedule>, FileError> {
        Err(NoFiles::refuse(file))
    }
    fn recording(&self, file: &str, _max_records: Option<u64>) -> Result<Arc<Recording>, FileError> {
        Err(NoFiles::refuse(file))
    }
}

/// Parses scenario TOML. `origin` names the source in errors; `default_name`
/// is used when the file has no `name`. Stages that name files (`trace`,
/// `replay`) are refused: see [`parse_str_with`].
pub fn parse_str(text: &str, origin: &str, default_name: &str) -> Result<ScenarioSpec, ScenarioError> {
    parse_str_with(text, origin, default_name, &NoFiles)
}

/// [`parse_str`], with the files the stages name read through `files`.
pub fn parse_str_with(text: &str, origin: &str, default_name: &str, files: &dyn ScenarioFiles) -> Result<ScenarioSpec, ScenarioError> {
    let ctx = Ctx { text, origin, files };
    let raw: RawScenario = toml::from_str(text).map_err(|e| ctx.toml_error(&e))?;
    if let Some(0) = raw.queue_capacity {
        return Err(ctx.err(ctx.key_line(0..text.len(), "queue_capacity"), None, Some("queue_capacity"), "must be at least 1 frame"));
    }
    let given = [raw.preset.is_some(), raw.stage.is_some(), raw.phase.is_some()];
    if given.iter().filter(|g| **g).count() > 1 {
        return Err(ctx.err(None, None, None, "give exactly one of `preset`, `[[stage]]` tables or `[[phase]]` tables"));
    }
    let phases = if let Some(raw_phases) = raw.phase {
        parse_phases(&ctx, raw_phases)?
    } else {
        let stages = if let Some(p) = &raw.preset {
            resolve_preset(&ctx, ctx.key_line(0..text.len(), "preset"), None, p)?
        } else {
            parse_stages(&ctx, raw.stage.unwrap_or_default(), None)?
        };
        vec![PhaseSpec { name: None, start_ms: 0.0, stages }]
    };
    Ok(ScenarioSpec {
        name: raw.name.unwrap_or_else(|| default_name.to_string()),
        description: raw.description,
        seed: raw.seed,
        queue_capacity: raw.queue_capacity,
        phases,
    })
}

fn parse_phases(ctx: &Ctx, raw_phases: Vec<Spanned<RawPhase>>) -> Result<Vec<PhaseSpec>, ScenarioError> {
    let mut phases = Vec::with_capacity(raw_phases.len());
    for (i, sp) in raw_phases.into_iter().enumerate() {
        let span = sp.span();
        let line = Some(ctx.line_of(span.start));
        let loc = format!("phase {}", i + 1);
        let rp = sp.into_inner();
        let time = |v: &Option<TimeValue>, field: &str, unit| {
            v.as_ref().map(|t| t.in_unit(unit)).transpose().map_err(|e| ctx.err(ctx.key_line(span.clone(), field), Some(&loc), Some(field), e))
        };
        let (start_s, start_ms) = (time(&rp.start_s, "start_s", crate::model::TimeUnit::S)?, time(&rp.start_ms, "start_ms", crate::model::TimeUnit::Ms)?);
        let start_ms = match (start_s, start_ms) {
            (Some(s), None) => s * 1e3,
            (None, Some(ms)) => ms,
            (None, None) if i == 0 => 0.0,
            (None, None) => {
                return Err(ctx.err(line, Some(&loc), Some("start_s"), "missing: every phase after the first needs `start_s` or `start_ms`"))
            }
            (Some(_), Some(_)) => return Err(ctx.err(line, Some(&loc), Some("start_ms"), "give `start_s` or `start_ms`, not both")),
        };
        let field = if rp.start_s.is_some() { "start_s" } else { "start_ms" };
        if !start_ms.is_finite() || start_ms < 0.0 || start_ms > MAX_PHASE_START_MS {
            let range = if field == "start_s" {
                format!("0 to {} s", MAX_PHASE_START_MS / 1e3)
            } else {
                format!("0 to {MAX_PHASE_START_MS} ms")
            };
            return Err(ctx.err(
                ctx.key_line(span.clone(), field),
                Some(&loc),
                Some(field),
                format!("must be a finite time from {range} (one year)"),
            ));
        }
        if i == 0 && start_ms != 0.0 {
            return Err(ctx.err(ctx.key_line(span.clone(), field), Some(&loc), Some(field), "the first phase must start at 0"));
        }
        if let Some(prev) = phases.last().map(|p: &PhaseSpec| p.start_ms) {
            if start_ms <= prev {
                return Err(ctx.err(
                    ctx.key_line(span.clone(), field),
                    Some(&loc),
                    Some(field),
                    format!("phases must start in increasing order: this one starts at {start_ms} ms, the previous at {prev} ms"),
                ));
            }
        }
        let stages = match (rp.preset, rp.stage) {
            (Some(p), None) => resolve_preset(ctx, ctx.key_line(span.clone(), "preset"), Some(&loc), &p)?,
            (None, Some(st)) => parse_stages(ctx, st, Some(i + 1))?,
            (None, None) => Vec::new(),
            (Some(_), Some(_)) => {
                return Err(ctx.err(line, Some(&loc), Some("preset"), "give `preset` or `[[phase.stage]]` tables, not both"))
            }
        };
        phases.push(PhaseSpec { name: rp.name, start_ms, stages });
    }
    if phases.is_empty() {
        return Err(ctx.err(None, None, Some("phase"), "a timeline needs at least one `[[phase]]`"));
    }
    Ok(phases)
}

fn resolve_preset(ctx: &Ctx, line: Option<usize>, loc: Option<&str>, name: &str) -> Result<Vec<StageSpec>, ScenarioError> {
    preset_stages(name).ok_or_else(|| {
        ctx.err(line, loc, Some("preset"), format!("unknown preset `{name}`: expected one of {}", PRESET_NAMES.join(", ")))
    })
}

fn parse_stages(ctx: &Ctx, raw: Vec<Spanned<toml::Table>>, phase: Option<usize>) -> Result<Vec<StageSpec>, ScenarioError> {
    let mut stages = Vec::with_capacity(raw.len());
    for (i, st) in raw.into_iter().enumerate() {
        let n = i + 1;
        let loc = match phase {
            Some(p) => format!("phase {p}, stage {n}"),
            None => format!("stage {n}"),
        };
        stages.extend(parse_stage(ctx, &loc, st)?);
    }
    Ok(stages)
}

/// Reads the file a `trace` or `replay` stage names into its parameters.
fn read_files(ctx: &Ctx, model: &mut ModelSpec) -> Result<(), FileError> {
    match model {
        ModelSpec::LinkTrace(p) => p.schedule = Some(ctx.files.link_trace(&p.file)?),
        ModelSpec::Replay(p) => p.recording = Some(ctx.files.recording(&p.file, p.max_records)?),
        _ => {}
    }
    Ok(())
}

fn take_string(ctx: &Ctx, span: &std::ops::Range<usize>, loc: &str, t: &mut toml::Table, key: &str) -> Result<Option<String>, ScenarioError> {
    match t.remove(key) {
        None => Ok(None),
        Some(toml::Value::String(s)) => Ok(Some(s)),
        Some(other) => Err(ctx.err(
            ctx.key_line(span.clone(), key),
            Some(loc),
            Some(key),
            format!("expected a string, found {}", other.type_str()),
        )),
    }
}

fn parse_stage(ctx: &Ctx, loc: &str, st: Spanned<toml::Table>) -> Result<Vec<StageSpec>, ScenarioError> {
    let span = st.span();
    let header_line = Some(ctx.line_of(span.start));
    let mut t = st.into_inner();
    let name = take_string(ctx, &span, loc, &mut t, "name")?;
    let preset = take_string(ctx, &span, loc, &mut t, "preset")?;
    let model = take_string(ctx, &span, loc, &mut t, "model")?;
    match (preset, model) {
        (Some(p), None) => {
            if let Some(k) = t.keys().next() {
                return Err(ctx.err(
                    ctx.key_line(span.clone(), k),
                    Some(loc),
                    Some(k),
                    "does not apply to a preset stage: a preset stage takes only `preset` and `name`",
                ));
            }
            let mut stages = resolve_preset(ctx, ctx.key_line(span.clone(), "preset"), Some(loc), &p)?;
            if name.is_some() {
                if stages.len() != 1 {
                    return Err(ctx.err(ctx.key_line(span, "name"), Some(loc), Some("name"), format!("preset `{p}` has no stage to name")));
                }
                stages[0].name = name;
            }
            Ok(stages)
        }
        (None, Some(m)) => {
            let Some(kind) = ModelKind::from_name(&m) else {
                let names: Vec<_> = ModelKind::ALL.iter().map(|k| k.name()).collect();
                return Err(ctx.err(
                    ctx.key_line(span, "model"),
                    Some(loc),
                    Some("model"),
                    format!("unknown model `{m}`: expected one of {}", names.join(", ")),
                ));
            };
            let loc = format!("{loc} ({})", kind.name());
            let model = match kind {
                ModelKind::Bernoulli => ModelSpec::Bernoulli(params(ctx, &span, &loc, t)?),
                ModelKind::GeLomax => ModelSpec::GeLomax(params(ctx, &span, &loc, t)?),
                ModelKind::Markov4 => ModelSpec::Markov4(params(ctx, &span, &loc, t)?),
                ModelKind::GilbertElliott => ModelSpec::GilbertElliott(params(ctx, &span, &loc, t)?),
                ModelKind::Delay => ModelSpec::Delay(params(ctx, &span, &loc, t)?),
                ModelKind::Outage => ModelSpec::Outage(params(ctx, &span, &loc, t)?),
                ModelKind::Jitter => ModelSpec::Jitter(params(ctx, &span, &loc, t)?),
                ModelKind::Duplicate => ModelSpec::Duplicate(params(ctx, &span, &loc, t)?),
                ModelKind::Corrupt => ModelSpec::Corrupt(params(ctx, &span, &loc, t)?),
                ModelKind::Reorder => ModelSpec::Reorder(params(ctx, &span, &loc, t)?),
                ModelKind::Slot => ModelSpec::Slot(params(ctx, &span, &loc, t)?),
                ModelKind::Rate => ModelSpec::Rate(params(ctx, &span, &loc, t)?),
                ModelKind::LinkTrace => ModelSpec::LinkTrace(params(ctx, &span, &loc, t)?),
                ModelKind::Replay => ModelSpec::Replay(params(ctx, &span, &loc, t)?),
            };
            let mut model = model;
            if let ModelSpec::Replay(ReplayParams { max_records: Some(n), .. }) = &model {
                if !(1..=MAX_FATES as u64).contains(n) {
                    return Err(ctx.err(ctx.key_line(span, "max_records").or(header_line), Some(&loc), Some("max_records"), format!("{n}: expected 1 to {MAX_FATES} records")));
                }
            }
            read_files(ctx, &mut model).map_err(|e| ctx.err(ctx.key_line(span.clone(), "file").or(header_line), Some(&loc), Some("file"), e.to_string()))?;
            if let Err(e) = model.build() {
                let key = e.field.split(['[', '.']).next().unwrap_or(&e.field).to_string();
                return Err(ctx.err(ctx.key_line(span, &key).or(header_line), Some(&loc), Some(&e.field), e.problem));
            }
            Ok(vec![StageSpec { name, preset: None, model }])
        }
        (Some(_), Some(_)) => Err(ctx.err(header_line, Some(loc), Some("preset"), "give `model` or `preset`, not both")),
        (None, None) => {
            // A target (`loss = "30%"`, `delay_ms_mean = 250`, `outage = "10%"`)
            // takes its model from the fault parameter database.
            if let Some(found) = crate::fit::db::target_stage(&t) {
                let (label, model) = found
                    .map_err(|e| ctx.err(ctx.key_line(span.clone(), &e.field).or(header_line), Some(loc), Some(&e.field), e.problem))?;
                return Ok(vec![StageSpec { name, preset: Some(label), model }]);
            }
            let names: Vec<_> = ModelKind::ALL.iter().map(|k| k.name()).collect();
            Err(ctx.err(
                header_line,
                Some(loc),
                None,
                format!(
                    "a stage needs `model` (one of {}), `preset` (one of {}) or a target (`loss`, `delay_ms_mean` or `outage`)",
                    names.join(", "),
                    PRESET_NAMES.join(", ")
                ),
            ))
        }
    }
}

/// serde's `unknown field `x`, expected …` or `missing field `x``: the
/// field named, and the message without it (`missing` says a missing one
/// in the caller's words).
pub(crate) fn field_of_message(message: &str, missing: &str) -> Option<(String, String)> {
    ["unknown field `", "missing field `"].into_iter().find_map(|prefix| {
        let rest = message.strip_prefix(prefix)?;
        let end = rest.find('`')?;
        let said = if prefix.starts_with("unknown") { format!("unknown field{}", &rest[end + 1..]) } else { missing.to_string() };
        Some((rest[..end].to_string(), said))
    })
}

/// Deserializes a stage's remaining keys into the model's parameter struct,
/// keeping the path of the offending field.
fn params<P: DeserializeOwned>(ctx: &Ctx, span: &std::ops::Range<usize>, loc: &str, t: toml::Table) -> Result<P, ScenarioError> {
    serde_path_to_error::deserialize::<_, P>(toml::Value::Table(t)).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let mut message = inner.message().trim().to_string();
        // Unknown and missing fields are reported at the table's level, with
        // the field only inside the message: pull it out.
        let mut field = if path == "." { None } else { Some(path) };
        if let Some((named, said)) = field_of_message(&message, "missing: this model requires it") {
            field = Some(named);
            message = said;
        }
        let line = field
            .as_deref()
            .and_then(|f| ctx.key_line(span.clone(), f.split(['[', '.']).next().unwrap_or(f)))
            .or(Some(ctx.line_of(span.start)));
        ctx.err(line, Some(loc), field.as_deref(), message)
    })
}

struct Ctx<'a> {
    text: &'a str,
    origin: &'a str,
    files: &'a dyn ScenarioFiles,
}

impl Ctx<'_> {
    fn err(&self, line: Option<usize>, loc: Option<&str>, field: Option<&str>, problem: impl Into<String>) -> ScenarioError {
        ScenarioError {
            origin: self.origin.to_string(),
            line,
            location: loc.map(str::to_string),
            field: field.map(str::to_string),
            problem: problem.into(),
        }
    }

    fn line_of(&self, byte: usize) -> usize {
        self.text[..byte.min(self.text.len())].matches('\n').count() + 1
    }

    /// The line of `key = ...` in the table whose header is at `span` (the
    /// header and its key/value lines up to the next table header), if there.
    fn key_line(&self, span: std::ops::Range<usize>, key: &str) -> Option<usize> {
        let start = span.start.min(self.text.len());
        let end = self.table_end(span.end.min(self.text.len()));
        let mut offset = start;
        for line in self.text[start..end].split_inclusive('\n') {
            let trimmed = line.trim_start();
            let k = trimmed.strip_prefix(key).or_else(|| trimmed.strip_prefix(&format!("\"{key}\"")));
            if let Some(rest) = k {
                if rest.trim_start().starts_with('=') {
                    return Some(self.line_of(offset));
                }
            }
            offset += line.len();
        }
        None
    }

    /// Where the table that starts before `from` ends: the start of the next
    /// line that is a table header (`[name]` or `[[name]]`), or the end.
    fn table_end(&self, from: usize) -> usize {
        let mut offset = from;
        for line in self.text[from..].split_inclusive('\n') {
            let t = line.trim_start();
            let after = t.strip_prefix("[[").or_else(|| t.strip_prefix('['));
            let is_header = offset > from
                && after.and_then(|a| a.trim_start().chars().next()).is_some_and(|c| c.is_alphabetic() || c == '_' || c == '"' || c == '\'');
            if is_header {
                return offset;
            }
            offset += line.len();
        }
        self.text.len()
    }

    fn toml_error(&self, e: &toml::de::Error) -> ScenarioError {
        let line = e.span().map(|s| self.line_of(s.start));
        let message = e.message().trim().to_string();
        let mut field = None;
        let mut problem = message.clone();
        if let Some(rest) = message.strip_prefix("unknown field `") {
            if let Some(end) = rest.find('`') {
                field = Some(rest[..end].to_string());
                problem = format!("unknown field{}", &rest[end + 1..]);
            }
        }
        ScenarioError { origin: self.origin.to_string(), line, location: None, field, problem }
    }
}

/// The scenario of a preset given by name (any spelling [`canonical_name`]
/// accepts), or `None` if `name` is not one.
pub fn preset(name: &str) -> Option<ScenarioSpec> {
    let canonical = canonical_name(name)?;
    let stages = preset_stages(canonical).expect("canonical names are presets");
    Some(ScenarioSpec::single(canonical, stages))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> ScenarioError {
        parse_str(text, "s.toml", "s").expect_err("must be rejected")
    }

    #[test]
    fn a_bernoulli_pipeline_parses() {
        let spec = parse_str("seed = 3\n[[stage]]\nmodel = \"bernoulli\"\np = \"30%\"\n", "s.toml", "s").unwrap();
        assert_eq!(spec.name, "s");
        assert_eq!(spec.seed, Some(3));
        assert_eq!(spec.phases.len(), 1);
        match &spec.phases[0].stages[0].model {
            ModelSpec::Bernoulli(p) => assert!((p.p.get() - 0.3).abs() < 1e-15),
            other => panic!("parsed as {other:?}"),
        }
    }

    #[test]
    fn an_unknown_field_names_file_line_and_field() {
        let e = err("name = \"x\"\n\n[[stage]]\nmodel = \"bernoulli\"\np = 0.1\nq = 2\n");
        assert_eq!(e.origin, "s.toml");
        assert_eq!(e.line, Some(6), "{e}");
        assert_eq!(e.field.as_deref(), Some("q"));
        assert!(e.problem.contains("expected") && e.problem.contains("`p`"), "{e}");
        assert_eq!(e.location.as_deref(), Some("stage 1 (bernoulli)"));
    }

    #[test]
    fn a_bad_probability_names_its_line() {
        let e = err("[[stage]]\nmodel = \"bernoulli\"\n\np = 1.5\n");
        assert_eq!((e.line, e.field.as_deref()), (Some(4), Some("p")), "{e}");
        assert!(e.problem.contains("[0, 1]"), "{e}");
        let e = err("[[stage]]\nmodel = \"bernoulli\"\np = \"abc\"\n");
        assert_eq!((e.line, e.field.as_deref()), (Some(3), Some("p")), "{e}");
        let e = err("[[stage]]\nmodel = \"bernoulli\"\np = true\n");
        assert_eq!(e.field.as_deref(), Some("p"), "{e}");
    }

    #[test]
    fn a_missing_field_is_named() {
        let e = err("[[stage]]\nmodel = \"bernoulli\"\n");
        assert_eq!((e.line, e.field.as_deref()), (Some(1), Some("p")), "{e}");
        assert!(e.problem.contains("missing"), "{e}");
    }

    #[test]
    fn unknown_models_and_presets_list_what_is_accepted() {
        let e = err("[[stage]]\nmodel = \"bernouli\"\np = 0.1\n");
        assert_eq!((e.line, e.field.as_deref()), (Some(2), Some("model")), "{e}");
        assert!(e.problem.contains("ge_lomax") && e.problem.contains("outage"), "{e}");
        let e = err("[[stage]]\npreset = \"PLM-9\"\n");
        assert_eq!((e.line, e.field.as_deref()), (Some(2), Some("preset")), "{e}");
        assert!(e.problem.contains("PLM-2") && e.problem.contains("CLM-3"), "{e}");
        let e = err("[[stage]]\n");
        assert!(e.problem.contains("needs `model`"), "{e}");
    }

    #[test]
    fn top_level_mistakes_are_located() {
        let e = err("name = \"x\"\nsed = 4\n");
        assert_eq!((e.line, e.field.as_deref()), (Some(2), Some("sed")), "{e}");
        let e = err("name = \"x\"\nseed = -4\n");
        assert_eq!(e.line, Some(2), "{e}");
        let e = err("name = \"x\"\n[[stage]\nmodel = 1\n");
        assert_eq!(e.line, Some(2), "{e}");
        let e = err("queue_capacity = 0\n");
        assert_eq!((e.line, e.field.as_deref()), (Some(1), Some("queue_capacity")), "{e}");
    }

    #[test]
    fn phases_must_be_ordered_and_start_at_zero() {
        let e = err("[[phase]]\nstart_s = 1\npreset = \"Normal\"\n");
        assert_eq!((e.line, e.field.as_deref()), (Some(2), Some("start_s")), "{e}");
        let e = err("[[phase]]\npreset = \"Normal\"\n[[phase]]\nstart_s = 5\npreset = \"Normal\"\n[[phase]]\nstart_ms = 5000\npreset = \"Normal\"\n");
        assert_eq!((e.line, e.location.as_deref()), (Some(7), Some("phase 3")), "{e}");
        let e = err("[[phase]]\npreset = \"Normal\"\n[[phase]]\npreset = \"Normal\"\n");
        assert_eq!((e.line, e.field.as_deref()), (Some(3), Some("start_s")), "{e}");
        let ok = parse_str(
            "[[phase]]\npreset = \"Normal\"\n[[phase]]\nstart_s = 2.5\n[[phase.stage]]\nmodel = \"bernoulli\"\np = 0.5\n",
            "s.toml",
            "s",
        )
        .unwrap();
        assert_eq!(ok.phases.len(), 2);
        assert_eq!(ok.phases[1].start_ms, 2500.0);
        assert_eq!(ok.phases[1].stages.len(), 1);
    }

    #[test]
    fn preset_stages_take_only_a_name() {
        let e = err("[[stage]]\npreset = \"PLM-2\"\np = 0.1\n");
        assert_eq!((e.line, e.field.as_deref()), (Some(3), Some("p")), "{e}");
        let e = err("[[stage]]\npreset = \"PLM-2\"\nmodel = \"bernoulli\"\n");
        assert!(e.problem.contains("not both"), "{e}");
    }

    #[test]
    fn display_reads_like_a_compiler_message() {
        let e = err("[[stage]]\nmodel = \"bernoulli\"\np = 2\n");
        assert_eq!(e.to_string(), format!("s.toml:3: stage 1 (bernoulli): `p`: {}", e.problem));
    }

    #[test]
    fn values_beyond_the_physical_ranges_are_rejected_with_the_range() {
        let delay = "[[stage]]\nmodel = \"delay\"\n";
        let hyper = "dist = \"hyperexp\"\nweights = [1.0]\n";
        let outage_t = "[[stage]]\nmodel = \"outage\"\np_start = 1\n";
        let outage_f = "[[stage]]\nmodel = \"outage\"\np_start = 1\nunit = \"frames\"\n";
        let lomax = "[[stage]]\nmodel = \"ge_lomax\"\ntransition = [[1.0]]\nalpha = [2.0]\n";
        // (file, line of the bad value, field, a piece of the stated range)
        let cases: [(String, usize, &str, &str); 10] = [
            (format!("{delay}min_ms = 1e15\n"), 3, "min_ms", "3600000 ms (one hour)"),
            (format!("{delay}min_ms = 1\ndist = \"uniform\"\njitter_ms = 3600001\n"), 5, "jitter_ms", "one hour"),
            (format!("{delay}min_ms = 1\n{hyper}rates_per_ms = [1e-300]\n"), 6, "rates_per_ms[0]", "at most 1e10 ms"),
            (format!("{outage_t}max_ms = 1e300\ncooldown_ms = 1\n"), 4, "max_ms", "1e300 ms is out of range"),
            (format!("{outage_t}max_ms = 10\ncooldown_ms = 1e12\n"), 5, "cooldown_ms", "604800000 ms (one week)"),
            (format!("{outage_f}max_frames = 9000000000000000000\ncooldown_frames = 1\n"), 5, "max_frames", "3600000000"),
            (format!("{outage_f}max_frames = 2\ncooldown_frames = 4000000000\n"), 6, "cooldown_frames", "one hour at 1 MHz"),
            (format!("{lomax}lambda = [1e300]\n"), 5, "lambda[0]", "3600000000 frames"),
            (
                "[[phase]]\npreset = \"Normal\"\n[[phase]]\nstart_s = 1e300\npreset = \"PLM-2\"\n".to_string(),
                4,
                "start_s",
                "0 to 31557600 s (one year)",
            ),
            (
                "[[phase]]\npreset = \"Normal\"\n[[phase]]\nstart_ms = 3.2e10\npreset = \"PLM-2\"\n".to_string(),
                4,
                "start_ms",
                "31557600000 ms (one year)",
            ),
        ];
        for (text, line, field, range) in cases {
            let e = err(&text);
            assert_eq!((e.line, e.field.as_deref()), (Some(line), Some(field)), "{e}\n{text}");
            assert!(e.problem.contains(range), "{e}");
        }
        // The limits themselves are accepted.
        let ok = parse_str(
            &format!("{delay}min_ms = 3600000\n{hyper}rates_per_ms = [{}]\n", crate::model::delay::MIN_RATE_PER_MS),
            "s.toml",
            "s",
        );
        assert!(ok.is_ok(), "{ok:?}");
        assert!(parse_str("[[phase]]\npreset = \"Normal\"\n[[phase]]\nstart_s = 31557600\n", "s.toml", "s").is_ok());
    }

    #[test]
    fn jitter_mistakes_name_file_line_and_field() {
        let head = "name = \"j\"\n[[stage]]\nmodel = \"jitter\"\nmean_ms = 100\n";
        // (the rest of the stage, line of the bad value, field, a piece of the message)
        let cases = [
            ("sd_ms = -1\ndist = \"normal\"\n", 5, "sd_ms", "≥ 0"),
            ("sd_ms = 20\ndist = \"normal\"\ncorrelation = 1\n", 7, "correlation", "[0, 1)"),
            ("sd_ms = 20\ndist = \"normal\"\ncorrelation = \"100%\"\n", 7, "correlation", "[0, 1)"),
            ("sd_ms = 20\ndist = \"normal\"\ncorrelation = -0.5\n", 7, "correlation", "[0, 1]"),
            ("sd_ms = 20\ndist = \"lognormal\"\n", 6, "dist", "paretonormal"),
            ("sd_ms = 4e6\ndist = \"pareto\"\n", 5, "sd_ms", "one hour"),
            ("sd_ms = 20\ndist = \"pareto\"\norder = \"lifo\"\n", 7, "order", "fifo"),
        ];
        for (rest, line, field, piece) in cases {
            let e = err(&format!("{head}{rest}"));
            assert_eq!((e.line, e.field.as_deref()), (Some(line), Some(field)), "{e}\n{rest}");
            assert_eq!(e.location.as_deref(), Some("stage 1 (jitter)"), "{e}");
            assert!(e.problem.contains(piece), "{e}");
        }
        let e = err(&format!("{head}sd_ms = 20\n"));
        assert_eq!((e.line, e.field.as_deref()), (Some(2), Some("dist")), "{e}");
        let ok = parse_str(&format!("{head}sd_ms = 20\ndist = \"paretonormal\"\ncorrelation = \"25%\"\n"), "s.toml", "s");
        assert!(ok.is_ok(), "{ok:?}");
    }

    #[test]
    fn new_netem_stages_name_file_line_and_field() {
        let cases = [
            ("[[stage]]\nmodel = \"slot\"\nmin_ms = 5\nmax_ms = 2\n", 4, "max_ms", "min_ms ≤ max_ms", "slot"),
            ("[[stage]]\nmodel = \"slot\"\nmin_ms = 1\nmax_ms = 2\npackets = 0\n", 5, "packets", "at least 1", "slot"),
            ("[[stage]]\nmodel = \"reorder\"\np = 0.5\ngap = 0\ndelay_ms = 10\n", 4, "gap", "from 1", "reorder"),
            ("[[stage]]\nmodel = \"reorder\"\np = 0.5\n", 1, "delay_ms", "missing", "reorder"),
            ("[[stage]]\nmodel = \"corrupt\"\n\np = 1.2\n", 4, "p", "[0, 1]", "corrupt"),
            ("[[stage]]\nmodel = \"corrupt\"\nber_per_byte = 1.5\n", 3, "ber_per_byte", "[0, 1]", "corrupt"),
            ("[[stage]]\nmodel = \"corrupt\"\n\nber_per_byte = -0.01\n", 4, "ber_per_byte", "[0, 1]", "corrupt"),
            ("[[stage]]\nmodel = \"corrupt\"\np = 0.1\nber_per_byte = \"0.1%\"\n", 4, "ber_per_byte", "not both", "corrupt"),
            ("[[stage]]\nmodel = \"corrupt\"\n", 1, "p", "ber_per_byte", "corrupt"),
            ("[[stage]]\nmodel = \"duplicate\"\np = -1\n", 3, "p", "[0, 1]", "duplicate"),
        ];
        for (text, line, field, piece, model) in cases {
            let e = err(text);
            assert_eq!((e.line, e.field.as_deref()), (Some(line), Some(field)), "{e}\n{text}");
            assert_eq!(e.location.as_deref(), Some(format!("stage 1 ({model})").as_str()), "{e}");
            assert!(e.problem.contains(piece), "{e}");
        }
    }

    /// Files held in memory, parsed as the shell parses them.
    struct MemFiles(&'static [(&'static str, &'static str)]);

    impl MemFiles {
        fn get(&self, file: &str) -> Result<&'static str, FileError> {
            self.0.iter().find(|(n, _)| *n == file).map(|(_, t)| *t).ok_or(FileError { file: file.into(), at: None, problem: "no such file".into() })
        }
    }

    impl ScenarioFiles for MemFiles {
        fn link_trace(&self, file: &str) -> Result<Arc<Schedule>, FileError> {
            Schedule::parse(self.get(file)?)
                .map(Arc::new)
                .map_err(|e| FileError { file: file.into(), at: e.line.map(|l| format!("line {l}")), problem: e.problem })
        }
        fn recording(&self, file: &str, _max_records: Option<u64>) -> Result<Arc<Recording>, FileError> {
            Recording::parse_trace_csv(self.get(file)?).map(Arc::new).map_err(|e| FileError { file: file.into(), at: e.at, problem: e.problem })
        }
    }

    const FILES: MemFiles = MemFiles(&[("ok.up", "1\n2\n"), ("bad.up", "1\n3\n2\n"), ("zeros.up", "0\n0\n"), ("empty.up", "")]);

    #[test]
    fn link_stage_mistakes_are_refused_at_parse_time() {
        let cases = [
            ("[[stage]]\nmodel = \"rate\"\nrate_bit_s = 0\n", 3, "rate_bit_s", "rate of zero"),
            ("[[stage]]\nmodel = \"rate\"\nrate_bit_s = 1e6\nqueue_bytes = 100\n", 4, "queue_bytes", "at least one packet"),
            ("[[stage]]\nmodel = \"rate\"\nrate_bit_s = 1e6\nqueue_packets = 0\n", 4, "queue_packets", "from 1"),
            ("[[stage]]\nmodel = \"rate\"\nrate_bit_s = 1e6\nrate = 5\n", 4, "rate", "unknown field"),
            ("[[stage]]\nmodel = \"trace\"\nfile = \"bad.up\"\n", 3, "file", "`bad.up` line 3: earlier than the line before: times must not decrease"),
            ("[[stage]]\nmodel = \"trace\"\nfile = \"zeros.up\"\n", 3, "file", "`zeros.up` line 2: every time is 0"),
            ("[[stage]]\nmodel = \"trace\"\nfile = \"empty.up\"\n", 3, "file", "`empty.up`: the trace is empty"),
            ("[[stage]]\nmodel = \"trace\"\nfile = \"ok.up\"\nqueue_bytes = 10\n", 4, "queue_bytes", "at least one packet"),
            ("[[stage]]\nmodel = \"replay\"\nfile = \"none.csv\"\n", 3, "file", "no such file"),
        ];
        for (text, line, field, piece) in cases {
            let e = parse_str_with(text, "s.toml", "s", &FILES).expect_err(text);
            assert_eq!((e.line, e.field.as_deref()), (Some(line), Some(field)), "{e}\n{text}");
            assert!(e.problem.contains(piece), "{e}");
        }
        let ok = parse_str_with("[[stage]]\nmodel = \"trace\"\nfile = \"ok.up\"\n[[stage]]\nmodel = \"rate\"\nrate_bit_s = 1e6\n", "s.toml", "s", &FILES).unwrap();
        assert_eq!(ok.phases[0].stages.len(), 2);
        // Printed back, the trace stage names its file, not its contents.
        let toml = ok.to_toml();
        assert!(toml.contains("model = \"trace\"") && toml.contains("file = \"ok.up\"") && toml.contains("rate_bit_s = 1000000.0"), "{toml}");
        // Text alone cannot name files.
        let e = parse_str("[[stage]]\nmodel = \"trace\"\nfile = \"ok.up\"\n", "s.toml", "s").unwrap_err();
        assert!(e.problem.contains("cannot name other files"), "{e}");
    }

    #[test]
    fn a_built_timeline_checks_its_phase_starts_too() {
        let mut spec = preset("Normal").unwrap();
        spec.phases.push(PhaseSpec { name: None, start_ms: 1e300, stages: Vec::new() });
        let e = crate::scenario::Scenario::new(&spec, 1).expect_err("must be rejected");
        assert_eq!((e.location.as_deref(), e.field.as_deref()), (Some("phase 2"), Some("start_ms")), "{e}");
        assert!(e.problem.contains("one year"), "{e}");
    }
}
