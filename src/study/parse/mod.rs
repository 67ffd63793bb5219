//! Reading a study file: the TOML text → a validated [`Study`], every
//! error with its line and field ([`StudyFileError`]).

mod ctx;
mod raw;

use super::file::{
    CleanRule, Peers, BlockOrder, Condition, ConditionSource, Block, Measure, Participant, Questionnaires, Study, StudyFileError, TlxWeighting, TlxWhen, TrialSpec,
    Within, MAX_NAME_LEN, MAX_PARTICIPANTS, MAX_TRIALS_PER_CONDITION, MAX_TRIALS_PER_PARTICIPANT, MAX_TRIAL_S, STUDY_RUN_ARGS,
};
use super::square::MAX_BLOCKS;
use crate::scenario::{canonical_name, PRESET_NAMES};
use crate::service::args::{refusal, RunArgs};
use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use toml::Spanned;
use ctx::Ctx;
use raw::{Raw, RawBlock, RawClean, RawCondition, RawMeasure, RawOrder, RawQuestionnaires, RawTrial, TimeValue};

/// A name that becomes a folder and a CSV value: letters, digits, `-`,
/// `_`, `.`, `+`, spaces inside; not empty, not starting with `.`.
fn check_name(name: &str) -> Result<(), String> {
    let ok_char = |c: char| c.is_ascii_alphanumeric() || "-_.+ ".contains(c);
    if name.trim().is_empty() {
        return Err("empty: give a name".into());
    }
    if name.len() > MAX_NAME_LEN {
        return Err(format!("{} characters: at most {MAX_NAME_LEN}", name.len()));
    }
    if name.starts_with('.') || name.trim() != name {
        return Err(format!("`{name}`: a name neither starts with `.` nor starts or ends with a space"));
    }
    if let Some(c) = name.chars().find(|c| !ok_char(*c)) {
        return Err(format!("`{name}` has `{c}`: letters, digits, `-`, `_`, `.`, `+` and inner spaces only (it names a folder and a CSV column value)"));
    }
    Ok(())
}

/// Parses a study file. `origin` names it in errors; `default_name` is
/// the study's name when the file gives none.
pub fn parse_study(text: &str, origin: &str, default_name: &str) -> Result<Study, StudyFileError> {
    let ctx = Ctx { text, origin };
    let raw: Raw = toml::from_str(text).map_err(|e| ctx.toml_error(&e))?;
    let _ = raw.description;
    let seed = match raw.seed {
        None => return Err(ctx.err(None, "seed", "missing: a study needs a seed so every schedule and trial is reproducible (any integer ≥ 0, e.g. `seed = 2025`)")),
        Some(s) => u64::try_from(*s.get_ref()).map_err(|_| ctx.err(Some(s.span()), "seed", format!("{}: a seed is an integer ≥ 0", s.get_ref())))?,
    };
    let trials_default = match &raw.trials {
        None => 1,
        Some(t) => trials_count(&ctx, t, "trials")?,
    };
    let trial = trial_spec(&ctx, raw.trial)?;
    let first = raw.order.as_ref().and_then(|o| o.first.clone());
    let (order, within) = order(&ctx, raw.order)?;
    let questionnaires = questionnaires(&ctx, raw.questionnaires)?;
    let defined = defined_conditions(&ctx, &raw.condition)?;
    let (conditions, blocks) = blocks(&ctx, &raw.block, &defined, trials_default)?;
    let participants = participants(&ctx, &raw.participant, &blocks, order)?;
    let first_block = first_block(&ctx, first.as_ref(), &blocks, order)?;
    let measures = measures(&ctx, &raw.measure, &participants)?;
    let clean = clean_rule(&ctx, raw.clean)?;
    let per_participant: usize = blocks.iter().map(|b| b.conditions.len() * b.trials as usize).sum();
    if per_participant > MAX_TRIALS_PER_PARTICIPANT {
        return Err(ctx.err(None, "block", format!("{per_participant} trials per participant: at most {MAX_TRIALS_PER_PARTICIPANT}")));
    }
    // Conditions defined but used by no block would be silently left out
    // of the study: a typo in a block's list is the likely cause.
    for (name, (span, _)) in &defined {
        if !conditions.iter().any(|c| &c.name == name) {
            return Err(ctx.err(Some(span.clone()), "condition.name", format!("`{name}` is defined but no block uses it: add it to a block's `conditions` or remove it")));
        }
    }
    let baseline = match raw.baseline {
        Some(b) => {
            let name = canonical_name(b.get_ref()).map(str::to_string).unwrap_or_else(|| b.get_ref().clone());
            let i = conditions.iter().position(|c| c.name == name).ok_or_else(|| {
                let names: Vec<&str> = conditions.iter().map(|c| c.name.as_str()).collect();
                ctx.err(Some(b.span()), "baseline", format!("`{}` is not a condition of this study (its conditions: {})", b.get_ref(), names.join(", ")))
            })?;
            Some(i)
        }
        None => conditions.iter().position(|c| c.name == "Normal"),
    };
    if let Some(data) = &raw.data {
        if data.trim().is_empty() {
            return Err(ctx.err(None, "data", "empty: a folder, relative to the study file, or absolute"));
        }
    }
    let name = raw.name.unwrap_or_else(|| default_name.to_string());
    Ok(Study {
        name,
        seed,
        data: raw.data,
        baseline,
        hide_condition: raw.hide_condition,
        trial,
        conditions,
        blocks,
        participants,
        order,
        within,
        questionnaires,
        measures,
        first_block,
        clean,
    })
}

/// `order.first`: the block everyone takes first, the others
/// counterbalanced after it (with a Latin square; a table gives each
/// participant's whole order, and fixed is the file's).
fn first_block(ctx: &Ctx, first: Option<&Spanned<String>>, blocks: &[Block], order: BlockOrder) -> Result<Option<usize>, StudyFileError> {
    let Some(first) = first else { return Ok(None) };
    if order != BlockOrder::Latin {
        return Err(ctx.err(Some(first.span()), "order.first", "only with `order.blocks = \"latin\"` (a table gives each participant's whole order; fixed is the file's order)"));
    }
    let names: Vec<&str> = blocks.iter().map(|b| b.name.as_str()).collect();
    names.iter().position(|n| n == first.get_ref()).map(Some).ok_or_else(|| {
        ctx.err(Some(first.span()), "order.first", format!("`{}` is not a block (blocks: {})", first.get_ref(), names.join(", ")))
    })
}

/// The `[[measure]]`s: column names of the study's table, each once.
fn measures(ctx: &Ctx, raw: &[Spanned<RawMeasure>], participants: &[Participant]) -> Result<Vec<Measure>, StudyFileError> {
    let mut out: Vec<Measure> = Vec::new();
    for (i, m) in raw.iter().enumerate() {
        let field = format!("measure[{}].name", i + 1);
        let name = m.get_ref().name.get_ref();
        let at = Some(m.get_ref().name.span());
        check_attribute(name).map_err(|p| ctx.err(at.clone(), &field, p.replace("an attribute", "a measure").replace("the attribute", "the measure")))?;
        if out.iter().any(|x| &x.name == name) {
            return Err(ctx.err(at, field, format!("`{name}` twice: every measure once")));
        }
        if participants.iter().any(|p| p.attributes.contains_key(name)) {
            return Err(ctx.err(at, field, format!("`{name}` is also a participant's attribute: both would be a column of that name")));
        }
        let label = m.get_ref().label.clone().filter(|l| !l.trim().is_empty()).unwrap_or_else(|| name.replace('_', " "));
        out.push(Measure { name: name.clone(), label });
    }
    Ok(out)
}

fn trials_count(ctx: &Ctx, t: &Spanned<i64>, field: &str) -> Result<u32, StudyFileError> {
    let v = *t.get_ref();
    if !(1..=i64::from(MAX_TRIALS_PER_CONDITION)).contains(&v) {
        return Err(ctx.err(Some(t.span()), field, format!("{v}: trials of each condition are 1 to {MAX_TRIALS_PER_CONDITION}")));
    }
    Ok(v as u32)
}

fn trial_spec(ctx: &Ctx, raw: Option<RawTrial>) -> Result<TrialSpec, StudyFileError> {
    let Some(raw) = raw else { return Ok(TrialSpec { duration_s: None, capture: None, rate_hz: None, run_args: Vec::new(), peers: Peers::Synthetic, lab_args: Vec::new(), peer_wait_s: None }) };
    let duration_s = match raw.duration_s {
        None => None,
        Some(d) => {
            let at = Some(d.span());
            let s = match d.get_ref() {
                TimeValue::Number(v) => *v,
                TimeValue::Text(t) => crate::model::parse_duration(t, crate::model::TimeUnit::S).map_err(|p| ctx.err(at.clone(), "trial.duration_s", p))?,
            };
            if !(s.is_finite() && s > 0.0 && s <= MAX_TRIAL_S) {
                return Err(ctx.err(at, "trial.duration_s", format!("{s} s: a trial lasts more than 0 and at most {MAX_TRIAL_S} s (a day)")));
            }
            Some(s)
        }
    };
    let rate_hz = match raw.rate_hz {
        Some(r) if !(r.get_ref().is_finite() && crate::flags::values::RATE_HZ_RANGE.contains(r.get_ref())) => {
            return Err(ctx.err(Some(r.span()), "trial.rate_hz", format!("{}: a frame rate of 0.001 to 1e6 Hz (as `netfi run --rate-hz`)", r.get_ref())));
        }
        r => r.map(Spanned::into_inner),
    };
    refuse_what_the_study_sets(ctx, &raw.run_args)?;
    if let Some(c) = &raw.capture {
        if c.trim().is_empty() {
            return Err(ctx.err(None, "trial.capture", "empty: a capture file, relative to the study file"));
        }
    }
    let lab_args = match &raw.lab {
        Some(t) => lab_flags(ctx, t)?,
        None => Vec::new(),
    };
    let peers = match &raw.peers {
        None if raw.lab.is_some() => {
            return Err(ctx.err(raw.lab.as_ref().map(|t| t.span()), "trial.peers", "missing: with a `[trial.lab]`, say who plays each trial: `peers = \"lab\"` (the lab's console and robot) or `peers = \"synthetic\"` (netfi's own, a dry run)"));
        }
        None => Peers::Synthetic,
        Some(p) => match p.get_ref().as_str() {
            "lab" => Peers::Lab,
            "synthetic" => Peers::Synthetic,
            other => return Err(ctx.err(Some(p.span()), "trial.peers", format!("`{other}`: lab (the lab's console and robot, met where `[trial.lab]` says) or synthetic (netfi's own console and robot: a dry run)"))),
        },
    };
    if let (Peers::Lab, Some(_)) = (peers, &raw.capture) {
        return Err(ctx.err(raw.peers.as_ref().map(|p| p.span()), "trial.capture", "a capture is replayed by netfi's own console; with `peers = \"lab\"` the lab's console plays (keep the capture for a dry run with `peers = \"synthetic\"`)"));
    }
    let peer_wait_s = match raw.peer_wait_s {
        Some(w) if !(w.get_ref().is_finite() && *w.get_ref() > 0.0 && *w.get_ref() <= 3600.0) => {
            return Err(ctx.err(Some(w.span()), "trial.peer_wait_s", format!("{}: seconds, more than 0 and at most an hour (default 60)", w.get_ref())));
        }
        w => w.map(Spanned::into_inner),
    };
    let spec = TrialSpec { duration_s, capture: raw.capture, rate_hz, run_args: raw.run_args.iter().map(|a| a.get_ref().clone()).collect(), peers, lab_args, peer_wait_s };
    check_run_args(ctx, &spec, &raw.run_args, raw.lab.as_ref().map(|t| t.span()))?;
    Ok(spec)
}

/// `[trial.lab]` as `netfi run` flags: each key a flag of where the
/// emulator meets the lab's programs (`ingress`, `console-from`,
/// `ros2-topic`, …; `_` or `-`), a value its value (a list repeats the
/// flag, `true` gives a switch).
fn lab_flags(ctx: &Ctx, table: &Spanned<toml::Table>) -> Result<Vec<String>, StudyFileError> {
    use clap::Args as _;
    let peers = crate::service::args::PeersArgs::augment_args(clap::Command::new("lab"));
    let longs: Vec<&str> = peers.get_arguments().filter_map(|a| a.get_long()).collect();
    let at = Some(table.span());
    let mut out = Vec::new();
    for (key, value) in table.get_ref() {
        let long = key.replace('_', "-");
        let field = format!("trial.lab.{key}");
        if !longs.contains(&long.as_str()) {
            return Err(ctx.err(at.clone(), &field, format!("`{key}` is not where a trial meets the lab's programs: one of {}", longs.join(", "))));
        }
        let flag = format!("--{long}");
        let word = |v: &toml::Value| -> Result<String, StudyFileError> {
            match v {
                toml::Value::String(s) => Ok(s.clone()),
                toml::Value::Integer(i) => Ok(i.to_string()),
                toml::Value::Float(f) => Ok(f.to_string()),
                _ => Err(ctx.err(at.clone(), &field, "a text, a number, `true`, or a list of texts (the flag given once for each)")),
            }
        };
        match value {
            toml::Value::Boolean(true) => out.push(flag),
            toml::Value::Boolean(false) => {}
            toml::Value::Array(items) => {
                for v in items {
                    out.push(flag.clone());
                    out.push(word(v)?);
                }
            }
            v => {
                out.push(flag);
                out.push(word(v)?);
            }
        }
    }
    Ok(out)
}

/// `[clean]`: when a trial is suspect.
fn clean_rule(ctx: &Ctx, raw: Option<RawClean>) -> Result<CleanRule, StudyFileError> {
    let mut rule = CleanRule::default();
    let Some(raw) = raw else { return Ok(rule) };
    if let Some(v) = raw.netfi_added_p99_ms {
        if !(v.get_ref().is_finite() && *v.get_ref() > 0.0) {
            return Err(ctx.err(Some(v.span()), "clean.netfi_added_p99_ms", format!("{}: a time in ms, more than 0 (default 1)", v.get_ref())));
        }
        rule.netfi_added_p99_ms = *v.get_ref();
    }
    if let Some(v) = raw.steal_fraction {
        if !(0.0..=1.0).contains(v.get_ref()) {
            return Err(ctx.err(Some(v.span()), "clean.steal_fraction", format!("{}: a fraction 0 to 1 of the trial's CPU time (default 0.05)", v.get_ref())));
        }
        rule.steal_fraction = *v.get_ref();
    }
    Ok(rule)
}

/// Refuses a `run_args` word that gives what the study decides for each
/// trial ([`STUDY_RUN_ARGS`]), by its flag or an alias as `netfi run`
/// declares them, saying where the file gives it instead.
fn refuse_what_the_study_sets(ctx: &Ctx, run_args: &[Spanned<String>]) -> Result<(), StudyFileError> {
    let cmd = RunArgs::command();
    let flags = |arg: &clap::Arg| -> Vec<String> { arg.get_long().into_iter().chain(arg.get_all_aliases().unwrap_or_default()).map(|f| format!("--{f}")).collect() };
    let reserved: Vec<(&clap::Arg, Option<&str>)> = STUDY_RUN_ARGS
        .iter()
        .map(|(id, instead)| (cmd.get_arguments().find(|a| a.get_id() == id).unwrap_or_else(|| panic!("`{id}` is no argument of `netfi run`")), *instead))
        .collect();
    for (i, a) in run_args.iter().enumerate() {
        let flag = a.get_ref().split('=').next().unwrap_or_default();
        if let Some((_, instead)) = reserved.iter().find(|(arg, _)| flags(arg).iter().any(|f| f == flag)) {
            let own = match instead {
                Some(field) => format!("write it as `{field}`"),
                None => "the study sets it for each trial".to_string(),
            };
            let all: Vec<String> = reserved.iter().flat_map(|(arg, _)| flags(arg)).collect();
            return Err(ctx.err(Some(a.span()), format!("trial.run_args[{}]", i + 1), format!("`{flag}`: {own} (the study decides {})", all.join(", "))));
        }
    }
    Ok(())
}

/// Reads the trial's `netfi run` as `netfi run` will (a preset for its
/// scenario): clap's refusal, at the word it names, else the run's own
/// check.
fn check_run_args(ctx: &Ctx, spec: &TrialSpec, run_args: &[Spanned<String>], lab: Option<Range<usize>>) -> Result<(), StudyFileError> {
    if spec.peers == Peers::Synthetic && lab.is_some() {
        // A dry run leaves `[trial.lab]` aside; it is still read, so the
        // lab's run does not fail on the day.
        let as_lab = TrialSpec { peers: Peers::Lab, capture: None, run_args: Vec::new(), ..spec.clone() };
        let run = as_lab.run("Normal", None).map_err(|e| ctx.err(lab.clone(), "trial.lab", refusal(&e)))?;
        run.validate().map_err(|e| ctx.err(lab.clone(), "trial.lab", e.to_string()))?;
    }
    if run_args.is_empty() {
        // The lab's endpoints, read as `netfi run` reads them.
        let run = spec.run("Normal", None).map_err(|e| ctx.err(lab.clone(), "trial.lab", refusal(&e)))?;
        return run.validate().map_err(|e| ctx.err(lab, "trial.lab", e.to_string()));
    }
    let first = &run_args[0];
    let capture = spec.capture.as_deref().map(std::path::Path::new);
    let at = |i: usize| (Some(run_args[i].span()), format!("trial.run_args[{}]", i + 1));
    let run = spec.run("Normal", capture).map_err(|e| {
        // clap names the word it refused: a flag (with its value's name),
        // or the value itself.
        let named: Vec<String> = [clap::error::ContextKind::InvalidArg, clap::error::ContextKind::InvalidValue]
            .into_iter()
            .filter_map(|k| match e.get(k) {
                Some(clap::error::ContextValue::String(s)) => s.split(' ').next().map(str::to_string),
                _ => None,
            })
            .collect();
        let i = named.iter().find_map(|n| run_args.iter().position(|a| a.get_ref() == n || a.get_ref().split('=').next() == Some(n.as_str())));
        let (span, field) = i.map_or((Some(first.span()), "trial.run_args".to_string()), at);
        ctx.err(span, field, refusal(&e))
    })?;
    run.validate().map_err(|e| ctx.err(Some(first.span()), "trial.run_args", e.to_string()))
}

fn order(ctx: &Ctx, raw: Option<RawOrder>) -> Result<(BlockOrder, Within), StudyFileError> {
    let Some(raw) = raw else { return Ok((BlockOrder::Latin, Within::Shuffle)) };
    let order = ctx.choice(
        raw.blocks.as_ref(),
        "order.blocks",
        &[("latin", BlockOrder::Latin), ("table", BlockOrder::Table), ("fixed", BlockOrder::Fixed)],
        "latin (a balanced Latin square), table (each participant's `blocks`) or fixed (the file's order)",
    )?;
    let within = ctx.choice(raw.within.as_ref(), "order.within", &[("shuffle", Within::Shuffle), ("fixed", Within::Fixed)], "shuffle or fixed")?;
    Ok((order, within))
}

fn questionnaires(ctx: &Ctx, raw: Option<RawQuestionnaires>) -> Result<Questionnaires, StudyFileError> {
    let Some(raw) = raw else { return Ok(Questionnaires { sus: false, tlx: TlxWhen::None, tlx_weighting: TlxWeighting::Raw }) };
    let sus = ctx.choice(
        raw.sus.as_ref(),
        "questionnaires.sus",
        &[("none", false), ("start", true)],
        "start (a System Usability Scale before the first trial) or none",
    )?;
    let tlx = ctx.choice(
        raw.tlx.as_ref(),
        "questionnaires.tlx",
        &[("none", TlxWhen::None), ("block", TlxWhen::Block), ("trial", TlxWhen::Trial)],
        "block (a NASA-TLX after each block), trial (after each trial) or none",
    )?;
    let tlx_weighting = ctx.choice(
        raw.tlx_weighting.as_ref(),
        "questionnaires.tlx_weighting",
        &[("raw", TlxWeighting::Raw), ("pairwise", TlxWeighting::Pairwise)],
        "raw (the unweighted mean of the six scales) or pairwise (the 15 pairwise choices weight the scales)",
    )?;
    Ok(Questionnaires { sus, tlx, tlx_weighting })
}

/// The `[[condition]]` tables by name: their span and source.
type Defined = BTreeMap<String, (Range<usize>, ConditionSource)>;

fn defined_conditions(ctx: &Ctx, raw: &[Spanned<RawCondition>]) -> Result<Defined, StudyFileError> {
    let mut defined = Defined::new();
    for (i, c) in raw.iter().enumerate() {
        let field = format!("condition[{}]", i + 1);
        let table = c.span();
        let c = c.get_ref();
        let name = c.name.get_ref();
        check_name(name).map_err(|p| ctx.err(Some(c.name.span()), format!("{field}.name"), p))?;
        if let Some(p) = canonical_name(name) {
            // A condition named like a preset but running something else
            // would be mistaken for the preset in every table.
            if !matches!(c.scenario.as_ref().map(|s| canonical_name(s.get_ref())), Some(Some(q)) if q == p) {
                return Err(ctx.err(Some(c.name.span()), format!("{field}.name"), format!("`{name}` is the name of a preset: name a condition of your own otherwise (`{name}-own`), or use the preset directly in a block")));
            }
        }
        if defined.contains_key(name) {
            return Err(ctx.err(Some(c.name.span()), format!("{field}.name"), format!("`{name}` is defined twice")));
        }
        let source = match (&c.scenario, &c.stage) {
            (Some(_), Some(_)) | (None, None) => {
                return Err(ctx.err(Some(table), field, "give either `scenario` (a preset or a scenario file) or `stage` (inline stages), not both or neither"));
            }
            (Some(s), None) => match canonical_name(s.get_ref()) {
                Some(p) => ConditionSource::Preset(p),
                None if s.get_ref().trim().is_empty() => return Err(ctx.err(Some(s.span()), format!("{field}.scenario"), "empty: a preset or a scenario file")),
                None => ConditionSource::File(s.get_ref().clone()),
            },
            (None, Some(stages)) => ConditionSource::Inline(inline_scenario(ctx, name, stages, table.clone(), &field)?),
        };
        defined.insert(name.clone(), (table, source));
    }
    Ok(defined)
}

/// The scenario TOML of inline stages, checked by the scenario parser;
/// its errors are given at the condition's `stage` line.
fn inline_scenario(ctx: &Ctx, name: &str, stages: &[toml::Table], table: Range<usize>, field: &str) -> Result<String, StudyFileError> {
    let at = ctx.key_span(&table, "stage").unwrap_or(table);
    if stages.is_empty() {
        return Err(ctx.err(Some(at), format!("{field}.stage"), "no stages: give at least one, e.g. `stage = [{ loss = \"30%\" }]`"));
    }
    let mut doc = toml::Table::new();
    doc.insert("name".into(), toml::Value::String(name.to_string()));
    doc.insert("stage".into(), toml::Value::Array(stages.iter().cloned().map(toml::Value::Table).collect()));
    let text = toml::to_string(&doc).map_err(|e| ctx.err(Some(at.clone()), format!("{field}.stage"), e.to_string()))?;
    crate::scenario::parse_str(&text, "inline", name).map_err(|e| {
        let loc = e.location.map(|l| format!("{l}: ")).unwrap_or_default();
        let f = e.field.map(|f| format!("`{f}`: ")).unwrap_or_default();
        ctx.err(Some(at), format!("{field}.stage"), format!("{loc}{f}{}", e.problem))
    })?;
    Ok(text)
}

fn blocks(ctx: &Ctx, raw: &[Spanned<RawBlock>], defined: &Defined, trials_default: u32) -> Result<(Vec<Condition>, Vec<Block>), StudyFileError> {
    if raw.is_empty() {
        return Err(ctx.err(None, "block", "no blocks: give at least one `[[block]]` with `name` and `conditions`"));
    }
    if raw.len() > MAX_BLOCKS {
        return Err(ctx.err(Some(raw[MAX_BLOCKS].span()), "block", format!("{} blocks: at most {MAX_BLOCKS}", raw.len())));
    }
    let mut conditions: Vec<Condition> = Vec::new();
    let mut blocks: Vec<Block> = Vec::new();
    for (i, b) in raw.iter().enumerate() {
        let field = format!("block[{}]", i + 1);
        let b = b.get_ref();
        check_name(b.name.get_ref()).map_err(|p| ctx.err(Some(b.name.span()), format!("{field}.name"), p))?;
        if blocks.iter().any(|x| &x.name == b.name.get_ref()) {
            return Err(ctx.err(Some(b.name.span()), format!("{field}.name"), format!("`{}`: two blocks of one name", b.name.get_ref())));
        }
        if b.conditions.get_ref().is_empty() {
            return Err(ctx.err(Some(b.conditions.span()), format!("{field}.conditions"), "empty: a block runs at least one condition"));
        }
        let trials = match &b.trials {
            Some(t) => trials_count(ctx, t, &format!("{field}.trials"))?,
            None => trials_default,
        };
        let mut members = Vec::new();
        for (j, c) in b.conditions.get_ref().iter().enumerate() {
            let cfield = format!("{field}.conditions[{}]", j + 1);
            let written = c.get_ref();
            let (name, source) = match (defined.get(written), canonical_name(written)) {
                (Some((_, source)), _) => (written.clone(), source.clone()),
                (None, Some(p)) => (p.to_string(), ConditionSource::Preset(p)),
                (None, None) => {
                    let own: Vec<&str> = defined.keys().map(String::as_str).collect();
                    let own = if own.is_empty() { "none defined".to_string() } else { own.join(", ") };
                    return Err(ctx.err(
                        Some(c.span()),
                        cfield,
                        format!("`{written}` is neither a `[[condition]]` of this file ({own}) nor a preset ({})", PRESET_NAMES.join(", ")),
                    ));
                }
            };
            let k = match conditions.iter().position(|x| x.name == name) {
                Some(k) => k,
                None => {
                    conditions.push(Condition { name, source });
                    conditions.len() - 1
                }
            };
            if members.contains(&k) {
                return Err(ctx.err(Some(c.span()), cfield, format!("`{written}` twice in one block: use `trials` for more trials of it")));
            }
            members.push(k);
        }
        blocks.push(Block { name: b.name.get_ref().clone(), conditions: members, trials });
    }
    Ok((conditions, blocks))
}

fn participants(ctx: &Ctx, raw: &[Spanned<toml::Table>], blocks: &[Block], order: BlockOrder) -> Result<Vec<Participant>, StudyFileError> {
    if raw.is_empty() {
        return Err(ctx.err(None, "participant", "no participants: give at least one `[[participant]]` with an `id`"));
    }
    if raw.len() > MAX_PARTICIPANTS {
        return Err(ctx.err(Some(raw[MAX_PARTICIPANTS].span()), "participant", format!("{} participants: at most {MAX_PARTICIPANTS}", raw.len())));
    }
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    for (i, p) in raw.iter().enumerate() {
        let field = format!("participant[{}]", i + 1);
        let span = p.span();
        let at = |key: &str| Some(ctx.key_span(&span, key).unwrap_or(span.clone()));
        let table = p.get_ref();
        let id = match table.get("id") {
            Some(toml::Value::String(s)) => s.clone(),
            Some(toml::Value::Integer(n)) => n.to_string(),
            Some(_) => return Err(ctx.err(at("id"), format!("{field}.id"), "a participant's id is text (`id = \"P01\"`)")),
            None => return Err(ctx.err(Some(span.clone()), format!("{field}.id"), "missing: every participant has an `id`")),
        };
        check_name(&id).map_err(|p| ctx.err(at("id"), format!("{field}.id"), p))?;
        if !seen.insert(id.clone()) {
            return Err(ctx.err(at("id"), format!("{field}.id"), format!("`{id}`: two participants of one id")));
        }
        let mut attributes = BTreeMap::new();
        for (k, v) in table.iter().filter(|(k, _)| !matches!(k.as_str(), "id" | "blocks")) {
            let text = match v {
                toml::Value::String(s) => s.clone(),
                toml::Value::Integer(n) => n.to_string(),
                toml::Value::Float(x) => x.to_string(),
                toml::Value::Boolean(b) => b.to_string(),
                _ => return Err(ctx.err(at(k), format!("{field}.{k}"), "an attribute is a string, a number or a boolean")),
            };
            check_attribute(k).map_err(|p| ctx.err(at(k), format!("{field}.{k}"), p))?;
            attributes.insert(k.clone(), text);
        }
        let order_of = match (table.get("blocks"), order) {
            (None, BlockOrder::Table) => {
                return Err(ctx.err(Some(span.clone()), format!("{field}.blocks"), "missing: with `order.blocks = \"table\"` every participant lists the blocks in their order"));
            }
            (None, _) => None,
            (Some(_), BlockOrder::Latin | BlockOrder::Fixed) => {
                return Err(ctx.err(at("blocks"), format!("{field}.blocks"), "a participant's own block order needs `order.blocks = \"table\"`"));
            }
            (Some(v), BlockOrder::Table) => Some(block_row(v, blocks).map_err(|p| ctx.err(at("blocks"), format!("{field}.blocks"), p))?),
        };
        out.push(Participant { id, attributes, blocks: order_of });
    }
    Ok(out)
}

/// Attribute names become CSV column names beside the fixed ones.
fn check_attribute(key: &str) -> Result<(), String> {
    if super::metrics::FIXED_COLUMNS.contains(&key) || super::metrics::METRICS.iter().any(|m| m.name == key) {
        return Err(format!("`{key}` is a column of the study's table: name the attribute otherwise"));
    }
    if key.is_empty() || !key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') || key.starts_with(|c: char| c.is_ascii_digit()) {
        return Err(format!("`{key}`: an attribute's name is letters, digits and `_`, not starting with a digit (it becomes a column name)"));
    }
    Ok(())
}

/// A participant's block order: every block once, by name or 1-based number.
fn block_row(v: &toml::Value, blocks: &[Block]) -> Result<Vec<usize>, String> {
    let names: Vec<&str> = blocks.iter().map(|b| b.name.as_str()).collect();
    let toml::Value::Array(items) = v else { return Err(format!("a list of the blocks in order, e.g. [\"{}\"]", names.join("\", \""))) };
    let mut row = Vec::new();
    for item in items {
        let k = match item {
            toml::Value::String(s) => names.iter().position(|n| n == s).ok_or_else(|| format!("`{s}` is not a block (blocks: {})", names.join(", ")))?,
            toml::Value::Integer(n) if (1..=blocks.len() as i64).contains(n) => *n as usize - 1,
            other => return Err(format!("{other}: a block's name or its number, 1 to {}", blocks.len())),
        };
        if row.contains(&k) {
            return Err(format!("`{}` twice: every block once", names[k]));
        }
        row.push(k);
    }
    if row.len() != blocks.len() {
        let missing: Vec<&str> = (0..blocks.len()).filter(|k| !row.contains(k)).map(|k| names[k]).collect();
        return Err(format!("{} of {} blocks: missing {}", row.len(), blocks.len(), missing.join(", ")));
    }
    Ok(row)
}

