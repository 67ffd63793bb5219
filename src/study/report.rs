//! `netfi study report`: the study's table and the comparison of its
//! conditions, written into `DATA/report/` (or `--out`):
//!
//! - `trials.csv`: one row per attempt of every trial (participant,
//!   attributes, block, condition, order position, outcome, every metric),
//!   tidy, for pandas and R as they are (`,` separated, `.` decimals, a
//!   header row, empty cells for missing values, every number as Rust
//!   writes it: the shortest text that reads back to the same double);
//! - `sus.csv`, `tlx.csv`: one row per questionnaire;
//! - `summary.json`: per condition (and group) mean ± sd and the tests
//!   against the baseline ([`super::summary`]), the questionnaires' means;
//! - `table.csv`: the paper's table: per condition (all participants, then
//!   each group) every column's mean, sd and the Holm-adjusted p of the
//!   paired t-test against the baseline;
//! - `questionnaires.csv`: the TLX scales against the baseline's block (or
//!   condition) in the same long shape as `summary.csv`;
//! - `summary.csv`: `summary.json`'s comparison, one row per group, column
//!   and condition;
//! - `correlations.csv`: Pearson's r, p and n between every column of the
//!   table and each TLX scale, one observation per TLX answered (the
//!   participant's mean of the done trials it follows);
//! - `report.html`: one self-contained page: the paper's tables (marked
//!   where the paired test against the baseline is significant), a plot per
//!   metric across the conditions (inline SVG) beside its full table, the
//!   questionnaires against the baseline, and the correlations.

use super::metrics::METRICS;
use super::questionnaire::{self, Answer, Instrument, TLX_SCALES};
use super::stats::{mean, sd};
use super::store::{load_state, now_utc, write_json, AttemptState, OpenStudy, StudyError};
use super::summary::{summarize_columns, Column, MetricSummary, Row, Summary};
use super::stats::{pearson, Pearson};
use std::borrow::Cow;
use super::trials::load_figures;
use maud::{html, Markup, PreEscaped, DOCTYPE};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// What the report is about, besides the rows.
#[derive(Debug, Clone, Serialize)]
pub struct ReportFile {
    pub study: String,
    pub generated_utc: String,
    pub baseline: Option<String>,
    /// Which trials count, and how the tests are corrected.
    pub method: String,
    pub conditions: Vec<String>,
    /// The attribute participants are grouped by, if any.
    pub group_by: Option<String>,
    /// All participants, then each group.
    pub summaries: Vec<Summary>,
    pub sus: QuestionnaireStat,
    /// The TLX per block.
    pub tlx: Vec<TlxStat>,
    /// What a TLX follows (a block, or the condition of its trial) that is
    /// the baseline of the questionnaires' comparison.
    pub questionnaire_baseline: Option<String>,
    /// The TLX's scales compared as the trials' columns are: all
    /// participants, then each group. Each participant counts by the mean
    /// of their answers after each block (or condition).
    pub questionnaires: Vec<Summary>,
    /// Every column of the table against each TLX scale.
    pub correlations: Vec<Correlation>,
    /// The level below which a Holm-adjusted p marks a difference in the
    /// tables.
    pub alpha: f64,
    /// Done trials that were suspect (`[clean]`), and how many of them the
    /// comparison left out (all, with `--leave-out-suspect`; else none).
    pub suspect_done: usize,
    pub suspect_left_out: usize,
}

/// A column of the trials' table against a TLX scale, over the TLX answers.
#[derive(Debug, Clone, Serialize)]
pub struct Correlation {
    pub metric: String,
    pub label: String,
    pub scale: String,
    /// Answers with both.
    pub n: usize,
    pub pearson: Option<Pearson>,
}

/// The level of the tables' marks.
pub const ALPHA: f64 = 0.05;

/// The table's numeric columns: every metric of a run, then the study's
/// `[[measure]]`s.
pub fn columns(s: &OpenStudy) -> Vec<Column> {
    let mut c = Column::metrics();
    c.extend(s.study.measures.iter().map(|m| Column { name: Cow::Owned(m.name.clone()), label: Cow::Owned(m.label.clone()) }));
    c
}

/// The questionnaires' columns: the raw TLX, the weighted one when the
/// study weights it, and the six scales.
pub fn questionnaire_columns(s: &OpenStudy) -> Vec<Column> {
    let mut c = vec![Column { name: "tlx_raw".into(), label: "Raw TLX (0-100)".into() }];
    if s.study.questionnaires.tlx_weighting == super::file::TlxWeighting::Pairwise {
        c.push(Column { name: "tlx_weighted".into(), label: "Weighted TLX (0-100)".into() });
    }
    c.extend(questionnaire::TLX_FORM.iter().map(|f| Column { name: format!("tlx_{}", f.key).into(), label: format!("TLX {} (0-100)", f.title).into() }));
    c
}

/// An answer's values in [`questionnaire_columns`]' order.
fn tlx_figures(a: &Answer, weighted: bool) -> Vec<Option<f64>> {
    let mut v = vec![a.score];
    if weighted {
        v.push(a.weighted);
    }
    v.extend((0..TLX_SCALES.len()).map(|i| a.values.get(i).map(|&x| f64::from(x))));
    v
}

/// A questionnaire score's mean ± sd.
#[derive(Debug, Clone, Serialize)]
pub struct QuestionnaireStat {
    pub n: usize,
    pub mean: Option<f64>,
    pub sd: Option<f64>,
    /// Recorded as not answered.
    pub missing: usize,
}

/// The TLX after one block (or one condition, when asked after each trial).
#[derive(Debug, Clone, Serialize)]
pub struct TlxStat {
    pub block: String,
    pub conditions: Vec<String>,
    pub raw: QuestionnaireStat,
    /// Each scale's mean ± sd, in [`TLX_SCALES`]' order.
    pub scales: Vec<QuestionnaireStat>,
}

/// What the report says of the suspect trials (`[clean]`).
pub fn suspect_words(r: &ReportFile) -> String {
    match (r.suspect_done, r.suspect_left_out) {
        (0, _) => "No done trial is suspect: in each, netfi's own added delay and the host's steal were within the study's `[clean]` bounds, and no frame was lost before the emulator or released before the robot listened.".to_string(),
        (n, 0) => format!("{n} done trials are suspect (trials.csv: `clean`, `suspect_because`) and are counted here; `netfi study report --leave-out-suspect` leaves them out."),
        (n, _) => format!("{n} suspect done trials were left out of every comparison (trials.csv keeps them, marked `suspect`)."),
    }
}

/// The words of the report's method.
pub const METHOD: &str = "Trials marked done count; a participant's value for a condition is the mean of their done trials of it; \
mean ± sd are over participants (sd with n − 1). Each condition is compared with the baseline, paired by participant: a two-sided \
paired t-test and a two-sided Wilcoxon signed-rank test (exact below 50 pairs without ties or zero differences, else the normal \
approximation with tie and continuity corrections). p-values are adjusted by Holm's method over the conditions of each metric \
(within each group). The measures the experimenter counted are columns like the run's metrics. The NASA-TLX scales are compared \
the same way, by what each TLX follows (a block, or the condition of its trial) against the one holding the baseline.";

/// Every attempt of every participant as the table's rows.
pub fn rows(s: &OpenStudy) -> Result<Vec<Row>, StudyError> {
    let mut out = Vec::new();
    for (p, part) in s.study.participants.iter().enumerate() {
        let dir = s.participant_dir(p);
        let Some(state) = load_state(&dir)? else { continue };
        let sch = &s.schedules[p];
        for a in &state.attempts {
            let Some(t) = sch.trials.iter().find(|t| t.number == a.trial) else { continue };
            let figures = match a.state {
                AttemptState::Running => None,
                _ => load_figures(&dir.join(&a.dir)),
            };
            let why = figures.as_ref().map(|f| super::metrics::suspect_because(f, &s.study.clean));
            let clean = match &why {
                None => "",
                Some(w) if w.is_empty() => "clean",
                Some(_) => "suspect",
            };
            out.push(Row {
                participant: part.id.clone(),
                attributes: part.attributes.clone(),
                trial: a.trial,
                attempt: a.attempt,
                outcome: a.state.as_str().to_string(),
                clean: clean.to_string(),
                suspect_because: why.map(|w| w.join("; ")).unwrap_or_default(),
                block: s.study.blocks[t.block].name.clone(),
                block_position: t.block_position,
                condition: a.condition.clone(),
                repetition: t.repetition,
                seed: a.seed,
                stopped: a.stopped,
                started_utc: a.started_utc.clone(),
                trial_dir: Path::new(&part.id).join(&a.dir).display().to_string(),
                note: a.note.clone(),
                figures: {
                    let mut f = figures.unwrap_or_else(|| vec![None; METRICS.len()]);
                    f.extend(s.study.measures.iter().map(|m| a.counts.get(&m.name).map(|&c| f64::from(c))));
                    f
                },
            });
        }
    }
    Ok(out)
}

/// A CSV field, quoted when it must be (RFC 4180).
fn field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

fn number(v: Option<f64>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

/// The attribute names of the study's participants, sorted.
fn attribute_names(s: &OpenStudy) -> Vec<String> {
    let set: BTreeSet<&String> = s.study.participants.iter().flat_map(|p| p.attributes.keys()).collect();
    set.into_iter().cloned().collect()
}

/// The rows as `trials.csv`.
pub fn trials_csv(rows: &[Row], attributes: &[String], columns: &[Column]) -> String {
    let mut header: Vec<String> = vec!["participant".into()];
    header.extend(attributes.iter().cloned());
    header.extend(super::metrics::FIXED_COLUMNS[1..].iter().map(|c| c.to_string()));
    header.extend(columns.iter().map(|m| m.name.to_string()));
    let mut out = header.iter().map(|h| field(h)).collect::<Vec<_>>().join(",") + "\n";
    for r in rows {
        let mut cells = vec![field(&r.participant)];
        cells.extend(attributes.iter().map(|a| field(r.attributes.get(a).map_or("", String::as_str))));
        cells.extend([
            r.trial.to_string(),
            r.attempt.to_string(),
            r.outcome.clone(),
            r.clean.clone(),
            field(&r.suspect_because),
            field(&r.block),
            r.block_position.to_string(),
            field(&r.condition),
            r.repetition.to_string(),
            r.seed.to_string(),
            r.stopped.to_string(),
            r.started_utc.clone(),
            field(&r.trial_dir),
            field(&r.note),
        ]);
        cells.extend(r.figures.iter().map(|v| number(*v)));
        out += &cells.join(",");
        out.push('\n');
    }
    out
}

/// The answers of one instrument as CSV.
fn answers_csv(s: &OpenStudy, answers: &[Answer], instrument: Instrument, attributes: &[String]) -> String {
    let items: Vec<String> = match instrument {
        Instrument::Sus => (1..=questionnaire::SUS_ITEMS).map(|i| format!("item_{i}")).collect(),
        Instrument::Tlx => TLX_SCALES.iter().map(|s| s.to_string()).collect(),
    };
    let mut header: Vec<String> = vec!["participant".into()];
    header.extend(attributes.iter().cloned());
    header.extend(["key", "after_trial", "block", "conditions", "answered_utc", "score", "missing"].map(String::from));
    header.extend(items.iter().cloned());
    let mut out = header.join(",") + "\n";
    for a in answers.iter().filter(|a| a.instrument == instrument) {
        let part = s.study.participants.iter().find(|p| p.id == a.participant);
        let mut cells = vec![field(&a.participant)];
        cells.extend(attributes.iter().map(|k| field(part.and_then(|p| p.attributes.get(k)).map_or("", String::as_str))));
        cells.extend([
            a.key.clone(),
            a.after_trial.map(|t| t.to_string()).unwrap_or_default(),
            field(a.block.as_deref().unwrap_or("")),
            field(&a.conditions.join(";")),
            a.answered_utc.clone(),
            number(a.score),
            field(a.missing.as_deref().unwrap_or("")),
        ]);
        cells.extend((0..items.len()).map(|i| a.values.get(i).map(|v| v.to_string()).unwrap_or_default()));
        out += &cells.join(",");
        out.push('\n');
    }
    out
}

fn stat(values: &[f64], missing: usize) -> QuestionnaireStat {
    QuestionnaireStat { n: values.len(), mean: mean(values), sd: sd(values), missing }
}

/// The group attribute: `given`, else `group` when every participant has one.
fn group_by(s: &OpenStudy, given: Option<&str>) -> Result<Option<String>, StudyError> {
    match given {
        Some(g) => {
            if s.study.participants.iter().any(|p| !p.attributes.contains_key(g)) {
                let ids: Vec<&str> = s.study.participants.iter().filter(|p| !p.attributes.contains_key(g)).map(|p| p.id.as_str()).collect();
                return Err(StudyError::State(format!("--group {g}: participants without it: {}", ids.join(", "))));
            }
            Ok(Some(g.to_string()))
        }
        None => Ok(s.study.participants.iter().all(|p| p.attributes.contains_key("group")).then(|| "group".to_string())),
    }
}

/// Writes the report into `out` (default `DATA/report/`); the folder, and
/// what it says of the suspect trials.
pub fn write(s: &OpenStudy, out: Option<&Path>, group: Option<&str>, leave_out_suspect: bool) -> Result<(PathBuf, String), StudyError> {
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| s.data.join("report"));
    std::fs::create_dir_all(&out).map_err(|source| StudyError::Io { path: out.clone(), source })?;
    let rows = rows(s)?;
    let attributes = attribute_names(s);
    crate::durable::write_whole(&out.join("trials.csv"), trials_csv(&rows, &attributes, &columns(s)).as_bytes())?;
    let mut answers = Vec::new();
    for p in 0..s.study.participants.len() {
        answers.extend(questionnaire::load(s, p)?);
    }
    crate::durable::write_whole(&out.join("sus.csv"), answers_csv(s, &answers, Instrument::Sus, &attributes).as_bytes())?;
    crate::durable::write_whole(&out.join("tlx.csv"), answers_csv(s, &answers, Instrument::Tlx, &attributes).as_bytes())?;
    let report = compute(s, &rows, &answers, group, leave_out_suspect)?;
    write_json(&out.join("summary.json"), &report)?;
    crate::durable::write_whole(&out.join("summary.csv"), summary_csv(&report.summaries, &report.group_by).as_bytes())?;
    crate::durable::write_whole(&out.join("questionnaires.csv"), summary_csv(&report.questionnaires, &report.group_by).as_bytes())?;
    crate::durable::write_whole(&out.join("table.csv"), table_csv(&report).as_bytes())?;
    crate::durable::write_whole(&out.join("correlations.csv"), correlations_csv(&report.correlations).as_bytes())?;
    crate::durable::write_whole(&out.join("report.html"), page(&report).into_string().as_bytes())?;
    Ok((out, suspect_words(&report)))
}

/// The report's figures from the rows and answers.
pub fn compute(s: &OpenStudy, rows: &[Row], answers: &[Answer], group: Option<&str>, leave_out_suspect: bool) -> Result<ReportFile, StudyError> {
    let suspect_done = rows.iter().filter(|r| r.outcome == "done" && r.clean == "suspect").count();
    let kept: Vec<Row>;
    let rows = if leave_out_suspect {
        kept = rows.iter().filter(|r| r.clean != "suspect").cloned().collect();
        &kept[..]
    } else {
        rows
    };
    let conditions: Vec<String> = s.study.conditions.iter().map(|c| c.name.clone()).collect();
    let baseline = s.study.baseline.map(|b| conditions[b].clone());
    let group_by = group_by(s, group)?;
    let all: Vec<&Row> = rows.iter().collect();
    let cols = columns(s);
    let groups: Vec<String> = match &group_by {
        Some(g) => s.study.participants.iter().filter_map(|p| p.attributes.get(g)).collect::<BTreeSet<&String>>().into_iter().cloned().collect(),
        None => Vec::new(),
    };
    let by_group = |rows: &[Row], columns: &[Column], units: &[String], base: Option<&str>| -> Vec<Summary> {
        let all: Vec<&Row> = rows.iter().collect();
        let mut out = vec![summarize_columns(&all, columns, units, base, None)];
        for v in &groups {
            let g = group_by.as_deref().unwrap_or_default();
            let these: Vec<&Row> = rows.iter().filter(|r| r.attributes.get(g) == Some(v)).collect();
            out.push(summarize_columns(&these, columns, units, base, Some(v.clone())));
        }
        out
    };
    let summaries = by_group(rows, &cols, &conditions, baseline.as_deref());
    let _ = all;
    let (units, unit_baseline, tlx_rows) = tlx_units(s, answers);
    let questionnaires = if tlx_rows.is_empty() { Vec::new() } else { by_group(&tlx_rows, &questionnaire_columns(s), &units, unit_baseline.as_deref()) };
    let correlations = correlations(s, rows, answers, &cols);
    let sus_scores: Vec<f64> = answers.iter().filter(|a| a.instrument == Instrument::Sus).filter_map(|a| a.score).collect();
    let sus_missing = answers.iter().filter(|a| a.instrument == Instrument::Sus && a.missing.is_some()).count();
    let mut blocks: BTreeMap<String, Vec<&Answer>> = BTreeMap::new();
    for a in answers.iter().filter(|a| a.instrument == Instrument::Tlx) {
        let key = if s.study.questionnaires.tlx == super::file::TlxWhen::Trial { a.conditions.join(";") } else { a.block.clone().unwrap_or_default() };
        blocks.entry(key).or_default().push(a);
    }
    let tlx = blocks
        .into_iter()
        .map(|(block, list)| {
            let given: Vec<&&Answer> = list.iter().filter(|a| a.score.is_some()).collect();
            let raw: Vec<f64> = given.iter().filter_map(|a| a.score).collect();
            let scales = (0..TLX_SCALES.len())
                .map(|i| stat(&given.iter().filter_map(|a| a.values.get(i).map(|&v| f64::from(v))).collect::<Vec<_>>(), 0))
                .collect();
            TlxStat { conditions: list[0].conditions.clone(), block, raw: stat(&raw, list.len() - given.len()), scales }
        })
        .collect();
    Ok(ReportFile {
        study: s.study.name.clone(),
        generated_utc: now_utc(),
        baseline,
        method: METHOD.to_string(),
        conditions,
        group_by,
        summaries,
        sus: stat(&sus_scores, sus_missing),
        tlx,
        questionnaire_baseline: unit_baseline,
        questionnaires,
        correlations,
        alpha: ALPHA,
        suspect_done,
        suspect_left_out: if leave_out_suspect { suspect_done } else { 0 },
    })
}

/// What each TLX follows, as the unit its scales are compared by: the
/// block (`tlx = "block"`) or the condition of its trial (`tlx =
/// "trial"`); the baseline's unit (the block holding the baseline
/// condition, or the baseline); and every answered TLX as a row of its
/// participant and unit.
fn tlx_units(s: &OpenStudy, answers: &[Answer]) -> (Vec<String>, Option<String>, Vec<Row>) {
    let per_trial = s.study.questionnaires.tlx == super::file::TlxWhen::Trial;
    let weighted = s.study.questionnaires.tlx_weighting == super::file::TlxWeighting::Pairwise;
    let (units, base): (Vec<String>, Option<String>) = if per_trial {
        (s.study.conditions.iter().map(|c| c.name.clone()).collect(), s.study.baseline.map(|b| s.study.conditions[b].name.clone()))
    } else {
        let base = s.study.baseline.and_then(|b| s.study.blocks.iter().find(|bl| bl.conditions.contains(&b))).map(|bl| bl.name.clone());
        (s.study.blocks.iter().map(|b| b.name.clone()).collect(), base)
    };
    let rows = answers
        .iter()
        .filter(|a| a.instrument == Instrument::Tlx && a.score.is_some())
        .filter_map(|a| {
            let unit = if per_trial { a.conditions.first()?.clone() } else { a.block.clone()? };
            let part = s.study.participants.iter().find(|p| p.id == a.participant)?;
            Some(Row {
                participant: a.participant.clone(),
                attributes: part.attributes.clone(),
                trial: a.after_trial.unwrap_or(0),
                attempt: 1,
                outcome: "done".into(),
                clean: String::new(),
                suspect_because: String::new(),
                block: a.block.clone().unwrap_or_default(),
                block_position: 0,
                condition: unit,
                repetition: 1,
                seed: 0,
                stopped: false,
                started_utc: a.answered_utc.clone(),
                trial_dir: String::new(),
                note: String::new(),
                figures: tlx_figures(a, weighted),
            })
        })
        .collect();
    (units, base, rows)
}

/// Pearson's r between every column and each TLX scale: one observation
/// per TLX answered, its participant's mean of the column over the done
/// trials it follows (the block's trials up to it, or its trial).
fn correlations(s: &OpenStudy, rows: &[Row], answers: &[Answer], cols: &[Column]) -> Vec<Correlation> {
    let weighted = s.study.questionnaires.tlx_weighting == super::file::TlxWeighting::Pairwise;
    let qcols = questionnaire_columns(s);
    let per_trial = s.study.questionnaires.tlx == super::file::TlxWhen::Trial;
    // Each answered TLX: its values, and the done rows it follows.
    let observations: Vec<(Vec<Option<f64>>, Vec<&Row>)> = answers
        .iter()
        .filter(|a| a.instrument == Instrument::Tlx && a.score.is_some())
        .filter_map(|a| {
            let after = a.after_trial?;
            let followed: Vec<&Row> = rows
                .iter()
                .filter(|r| r.participant == a.participant && r.outcome == "done")
                .filter(|r| if per_trial { r.trial == after } else { Some(&r.block) == a.block.as_ref() && r.trial <= after })
                .collect();
            Some((tlx_figures(a, weighted), followed))
        })
        .collect();
    let mut out = Vec::new();
    for (k, c) in cols.iter().enumerate() {
        for (q, qc) in qcols.iter().enumerate() {
            let pairs: Vec<(f64, f64)> = observations
                .iter()
                .filter_map(|(tlx, followed)| {
                    let xs: Vec<f64> = followed.iter().filter_map(|r| r.figures.get(k).copied().flatten()).collect();
                    Some((mean(&xs)?, tlx.get(q).copied().flatten()?))
                })
                .collect();
            out.push(Correlation { metric: c.name.to_string(), label: c.label.to_string(), scale: qc.name.to_string(), n: pairs.len(), pearson: pearson(&pairs) });
        }
    }
    out
}

/// A summary's rows as CSV: one per group, column and condition.
pub fn summary_csv(summaries: &[Summary], group_by: &Option<String>) -> String {
    let mut out = String::from(
        "group_by,group,metric,condition,participants,trials,mean,sd,pairs,mean_difference,t,df,p,p_holm,wilcoxon_v,wilcoxon_p,wilcoxon_p_holm\n",
    );
    for sm in summaries {
        for m in &sm.metrics {
            for c in &m.conditions {
                let v = c.versus_baseline.as_ref();
                let t = v.and_then(|v| v.t_test);
                let w = v.and_then(|v| v.wilcoxon);
                let cells = [
                    field(if sm.group.is_some() { group_by.as_deref().unwrap_or("") } else { "" }),
                    field(sm.group.as_deref().unwrap_or("all")),
                    field(&m.metric),
                    field(&c.condition),
                    c.participants.to_string(),
                    c.trials.to_string(),
                    number(c.mean),
                    number(c.sd),
                    v.map(|v| v.pairs.to_string()).unwrap_or_default(),
                    number(t.map(|t| t.mean_difference)),
                    number(t.map(|t| t.t)),
                    number(t.map(|t| t.df)),
                    number(t.map(|t| t.p)),
                    number(v.and_then(|v| v.t_p_holm)),
                    number(w.map(|w| w.v)),
                    number(w.map(|w| w.p)),
                    number(v.and_then(|v| v.wilcoxon_p_holm)),
                ];
                out += &cells.join(",");
                out.push('\n');
            }
        }
    }
    out
}

/// The paper's table as CSV: a row per group and condition, each column's
/// mean, sd and Holm-adjusted paired t-test p against the baseline.
pub fn table_csv(r: &ReportFile) -> String {
    let Some(first) = r.summaries.first() else { return String::new() };
    let mut header = vec!["group".to_string(), "condition".to_string(), "participants".to_string()];
    for m in &first.metrics {
        header.extend([format!("{}_mean", m.metric), format!("{}_sd", m.metric), format!("{}_p_holm", m.metric)]);
    }
    let mut out = header.iter().map(|h| field(h)).collect::<Vec<_>>().join(",") + "\n";
    for sm in &r.summaries {
        for (i, c) in r.conditions.iter().enumerate() {
            let mut cells = vec![field(sm.group.as_deref().unwrap_or("all")), field(c)];
            cells.push(sm.metrics.iter().map(|m| m.conditions.get(i).map_or(0, |x| x.participants)).max().unwrap_or(0).to_string());
            for m in &sm.metrics {
                let x = m.conditions.get(i);
                cells.extend([number(x.and_then(|x| x.mean)), number(x.and_then(|x| x.sd)), number(x.and_then(|x| x.versus_baseline.as_ref()?.t_p_holm))]);
            }
            out += &cells.join(",");
            out.push('\n');
        }
    }
    out
}

/// The correlations as CSV.
pub fn correlations_csv(c: &[Correlation]) -> String {
    let mut out = String::from("metric,scale,n,r,p\n");
    for x in c {
        out += &[field(&x.metric), field(&x.scale), x.n.to_string(), number(x.pearson.map(|p| p.r)), number(x.pearson.map(|p| p.p))].join(",");
        out.push('\n');
    }
    out
}

fn fmt(v: Option<f64>) -> String {
    match v {
        None => "–".into(),
        Some(0.0) => "0".into(),
        Some(x) if x.abs() >= 1000.0 => format!("{x:.0}"),
        Some(x) if x.abs() >= 1.0 => format!("{x:.2}"),
        Some(x) => format!("{x:.4}"),
    }
}

/// A mean and its sd, both to the mean's precision.
fn fmt_mean_sd(mean: Option<f64>, sd: Option<f64>) -> String {
    let Some(m) = mean else { return "–".into() };
    let decimals = match m.abs() {
        a if a >= 1000.0 => 0,
        a if a >= 1.0 || a == 0.0 => 2,
        _ => 4,
    };
    match sd {
        Some(s) => format!("{m:.decimals$} ± {s:.decimals$}"),
        None => format!("{m:.decimals$} (one value)"),
    }
}

fn fmt_p(p: Option<f64>) -> String {
    match p {
        None => "–".into(),
        Some(p) if p < 0.0001 => format!("{p:.1e}"),
        Some(p) => format!("{p:.4}"),
    }
}

const STYLE: &str = "body{font-family:system-ui,sans-serif;margin:1.5em auto;max-width:1100px;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:.5em 0 1em}td,th{border:1px solid #ccc;padding:.2em .5em;text-align:right}\
th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}svg.plot{width:100%;max-width:760px;height:auto}\
.method{font-size:.9em;color:#444;max-width:60em}.sig{font-weight:bold}.wide{overflow-x:auto}td small{color:#555}";

/// The report page.
pub fn page(r: &ReportFile) -> Markup {
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title { "Study report: " (r.study) }
                style { (PreEscaped(STYLE)) }
            }
            body {
                h1 { "Study report: " (r.study) }
                p { "Generated " (r.generated_utc) ". Baseline: " b { (r.baseline.as_deref().unwrap_or("none (no tests)")) } "." }
                p class="method" { (r.method) }
                p class="method" { (suspect_words(r)) }
                @for summary in &r.summaries {
                    (paper_table(r, summary))
                }
                @if r.summaries.len() > 1 {
                    (group_tables(r))
                }
                @if r.sus.n + r.sus.missing > 0 || !r.tlx.is_empty() {
                section id="questionnaires" {
                    h2 { "Questionnaires" }
                    @if r.sus.n + r.sus.missing > 0 {
                        p id="sus" { "System Usability Scale: n = " (r.sus.n) ", mean ± sd " (fmt_mean_sd(r.sus.mean, r.sus.sd))
                            @if r.sus.missing > 0 { ", " (r.sus.missing) " missing" } "." }
                    }
                    @if !r.tlx.is_empty() {
                        table id="tlx" {
                            tr { th { "NASA-TLX after" } th { "n" } th { "raw TLX" } @for s in TLX_SCALES { th { (s.replace('_', " ")) } } }
                            @for t in &r.tlx {
                                tr { td { (t.block) } td { (t.raw.n) } td { (fmt_mean_sd(t.raw.mean, t.raw.sd)) }
                                     @for s in &t.scales { td { (fmt_mean_sd(s.mean, s.sd)) } } }
                            }
                        }
                    }
                    @for summary in &r.questionnaires {
                        section class="questionnaire-summary" {
                            h3 { "NASA-TLX against " (r.questionnaire_baseline.as_deref().unwrap_or("–")) ": "
                                 @match &summary.group { None => { "all participants" } Some(g) => { (r.group_by.as_deref().unwrap_or("group")) " = " (g) } }
                                 " (" (summary.participants) ")" }
                            @for m in &summary.metrics {
                                (metric_section_as("q", r.questionnaire_baseline.as_deref(), summary, m))
                            }
                        }
                    }
                }
                }
                @if r.correlations.iter().any(|c| c.pearson.is_some()) {
                    (correlation_table(r))
                }
                @for summary in &r.summaries {
                    section class="summary" {
                        h2 { @match &summary.group { None => { "All participants" } Some(g) => { (r.group_by.as_deref().unwrap_or("group")) " = " (g) } }
                             " (" (summary.participants) ")" }
                        @for m in &summary.metrics {
                            (metric_section(r, summary, m))
                        }
                    }
                }
            }
        }
    }
}

/// A condition's cell of the paper's tables: mean (± sd), marked `*`
/// where the Holm-adjusted paired t-test against the baseline is below
/// the report's α.
fn paper_cell(r: &ReportFile, c: Option<&super::summary::ConditionStat>) -> Markup {
    let Some(c) = c.filter(|c| c.mean.is_some()) else { return html! { td { "–" } } };
    let p = c.versus_baseline.as_ref().and_then(|v| v.t_p_holm);
    let marked = p.is_some_and(|p| p < r.alpha);
    let sd = c.sd.map(|s| format!(" (±{})", short(s))).unwrap_or_default();
    html! { td class=[marked.then_some("sig")] title=[p.map(|p| format!("p Holm {}", fmt_p(Some(p))))] { (short(c.mean.unwrap_or_default())) @if marked { sup { "*" } } small { (sd) } } }
}

/// A number to about three significant digits, as a table shows it.
fn short(x: f64) -> String {
    match x.abs() {
        0.0 => "0".into(),
        a if a < 0.01 => format!("{x:.2e}"),
        a if a >= 100.0 => format!("{x:.0}"),
        a if a >= 10.0 => format!("{x:.1}"),
        a if a >= 1.0 => format!("{x:.2}"),
        _ => format!("{x:.3}"),
    }
}

/// The paper's table for one set of participants: a row per condition, a
/// column per metric with a value.
fn paper_table(r: &ReportFile, summary: &Summary) -> Markup {
    let shown: Vec<&MetricSummary> = summary.metrics.iter().filter(|m| m.conditions.iter().any(|c| c.mean.is_some())).collect();
    let id = format!("table-{}", summary.group.as_deref().unwrap_or("all").replace(' ', "_"));
    html! {
        section class="paper-table" id=(id) {
            h2 { "Conditions: " @match &summary.group { None => { "all participants" } Some(g) => { (r.group_by.as_deref().unwrap_or("group")) " = " (g) } }
                 " (" (summary.participants) ")" }
            p class="method" { "Mean (± sd) over participants; * where the paired t-test against " (r.baseline.as_deref().unwrap_or("the baseline"))
                ", Holm-adjusted over the conditions of the column, gives p < " (r.alpha) "." }
            div class="wide" {
                table {
                    tr { th { "condition" } @for m in &shown { th title=(m.label) { (m.metric) } } }
                    @for (i, c) in r.conditions.iter().enumerate() {
                        tr { td { (c) } @for m in &shown { (paper_cell(r, m.conditions.get(i))) } }
                    }
                }
            }
        }
    }
}

/// One table per metric: a row per condition, all participants then each
/// group (the paper's table by proficiency).
fn group_tables(r: &ReportFile) -> Markup {
    let all = &r.summaries[0];
    html! {
        section id="by-group" {
            h2 { "By " (r.group_by.as_deref().unwrap_or("group")) }
            @for (k, m) in all.metrics.iter().enumerate().filter(|(_, m)| m.conditions.iter().any(|c| c.mean.is_some())) {
                div class="group-table" id={ "group-" (m.metric) } {
                    h3 { (m.label) }
                    table {
                        tr { th { "condition" } @for s in &r.summaries { th { (s.group.as_deref().unwrap_or("all")) " (" (s.participants) ")" } } }
                        @for (i, c) in r.conditions.iter().enumerate() {
                            tr { td { (c) } @for s in &r.summaries { (paper_cell(r, s.metrics.get(k).and_then(|m| m.conditions.get(i)))) } }
                        }
                    }
                }
            }
        }
    }
}

/// Every column against each TLX scale: r (p, n).
fn correlation_table(r: &ReportFile) -> Markup {
    let scales: Vec<&str> = r.correlations.iter().map(|c| c.scale.as_str()).collect::<BTreeSet<_>>().into_iter().collect();
    let mut metrics: Vec<(&str, &str)> = Vec::new();
    for c in &r.correlations {
        if !metrics.iter().any(|(m, _)| *m == c.metric) && r.correlations.iter().any(|x| x.metric == c.metric && x.pearson.is_some()) {
            metrics.push((&c.metric, &c.label));
        }
    }
    let scales: Vec<&str> = {
        // In the questionnaire's own order, as the CSV gives them.
        let mut ordered: Vec<&str> = Vec::new();
        for c in &r.correlations {
            if scales.contains(&c.scale.as_str()) && !ordered.contains(&c.scale.as_str()) {
                ordered.push(&c.scale);
            }
        }
        ordered
    };
    html! {
        section id="correlations" {
            h2 { "Task metrics and workload" }
            p class="method" { "Pearson's r (two-sided p, n) between each column and each NASA-TLX scale, one observation per TLX answered: \
                the participant's mean of the column over the done trials the TLX follows. Bold where p < " (r.alpha) " (not adjusted)." }
            div class="wide" {
                table {
                    tr { th { "" } @for s in &scales { th { (s) } } }
                    @for (m, label) in &metrics {
                        tr { td title=(label) { (m) }
                            @for s in &scales {
                                @let c = r.correlations.iter().find(|c| c.metric == *m && c.scale == *s);
                                @match c.and_then(|c| c.pearson) {
                                    Some(p) => { td class=[(p.p < r.alpha).then_some("sig")] { (format!("{:.2}", p.r)) small { " (" (fmt_p(Some(p.p))) ", " (p.n) ")" } } }
                                    None => { td { "–" small { " (n " (c.map_or(0, |c| c.n)) ")" } } }
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}

fn metric_section(r: &ReportFile, summary: &Summary, m: &MetricSummary) -> Markup {
    metric_section_as("", r.baseline.as_deref(), summary, m)
}

/// A metric's table and plot; `prefix` sets its ids apart (`q`: the
/// questionnaires), `baseline` names what it is compared with.
fn metric_section_as(prefix: &str, baseline: Option<&str>, summary: &Summary, m: &MetricSummary) -> Markup {
    let id = format!("{prefix}{}{}-{}", if prefix.is_empty() { "" } else { "-" }, summary.group.as_deref().unwrap_or("all").replace(' ', "_"), m.metric);
    let svg = plot(&id, m).unwrap_or_default();
    html! {
        div class="metric" id=(id) {
            h3 { (m.label) }
            table {
                tr { th { "condition" } th { "participants" } th { "trials" } th { "mean ± sd" }
                     th { "Δ vs " (baseline.unwrap_or("–")) } th { "t (df)" } th { "p" } th { "p Holm" }
                     th { "Wilcoxon V" } th { "p" } th { "p Holm" } }
                @for c in &m.conditions {
                    @let v = c.versus_baseline.as_ref();
                    @let t = v.and_then(|v| v.t_test);
                    @let w = v.and_then(|v| v.wilcoxon);
                    tr {
                        td { (c.condition) } td { (c.participants) } td { (c.trials) }
                        td { (fmt_mean_sd(c.mean, c.sd)) }
                        td { (fmt(t.map(|t| t.mean_difference))) }
                        td { @if let Some(t) = t { (format!("{:.3} ({})", t.t, t.df)) } @else { "–" } }
                        td { (fmt_p(t.map(|t| t.p))) }
                        td class=[v.and_then(|v| v.t_p_holm).filter(|p| *p < 0.05).map(|_| "sig")] { (fmt_p(v.and_then(|v| v.t_p_holm))) }
                        td { (fmt(w.map(|w| w.v))) }
                        td { (fmt_p(w.map(|w| w.p))) }
                        td class=[v.and_then(|v| v.wilcoxon_p_holm).filter(|p| *p < 0.05).map(|_| "sig")] { (fmt_p(v.and_then(|v| v.wilcoxon_p_holm))) }
                    }
                }
            }
            @if !svg.is_empty() { div class="plot" { (PreEscaped(svg)) } }
        }
    }
}

/// Each condition's mean with its sd as a whisker, across the conditions.
fn plot(id: &str, m: &super::summary::MetricSummary) -> Option<String> {
    use crate::html::plot::{BLUE, GREY, SIZE};
    use plotters::prelude::*;
    let points: Vec<(usize, f64, f64)> =
        m.conditions.iter().enumerate().filter_map(|(i, c)| Some((i, c.mean?, c.sd.unwrap_or(0.0)))).collect();
    if points.is_empty() {
        return None;
    }
    let lo = points.iter().map(|p| p.1 - p.2).fold(f64::INFINITY, f64::min).min(0.0);
    let hi = points.iter().map(|p| p.1 + p.2).fold(f64::NEG_INFINITY, f64::max);
    let hi = if hi > lo { hi + 0.05 * (hi - lo) } else { lo + 1.0 };
    let names: Vec<String> = m.conditions.iter().map(|c| c.condition.clone()).collect();
    let n = names.len() as f64;
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, SIZE).into_drawing_area();
        root.fill(&WHITE).ok()?;
        let mut chart = crate::html::plot::chart_on(&root, &m.label)
            .build_cartesian_2d(-0.5..n - 0.5, lo..hi)
            .ok()?;
        let label = |v: &f64| crate::html::plot::whole(*v).and_then(|i| names.get(usize::try_from(i).ok()?).cloned()).unwrap_or_default();
        chart
            .configure_mesh()
            .x_labels(names.len())
            .x_label_formatter(&label)
            .y_label_formatter(&crate::html::plot::short)
            .x_desc("condition")
            .y_desc(m.label.as_ref())
            .disable_x_mesh()
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .ok()?;
        chart
            .draw_series(points.iter().map(|&(i, mu, s)| PathElement::new(vec![(i as f64, mu - s), (i as f64, mu + s)], GREY.stroke_width(2))))
            .ok()?;
        chart.draw_series(points.iter().map(|&(i, mu, _)| Circle::new((i as f64, mu), 5, BLUE.filled()))).ok()?;
        root.present().ok()?;
    }
    let rest = buf.find('>').map_or(buf.as_str(), |end| &buf[end + 1..]);
    Some(format!("<svg id=\"plot-{id}\" class=\"plot\" viewBox=\"0 0 {} {}\" role=\"img\" aria-label=\"{}\">{rest}", SIZE.0, SIZE.1, m.label))
}
