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
//! - `report.html`: one self-contained page, a plot per metric across the
//!   conditions (inline SVG) beside its table, and the questionnaires.

use super::metrics::METRICS;
use super::questionnaire::{self, Answer, Instrument, TLX_SCALES};
use super::stats::{mean, sd};
use super::store::{load_state, now_utc, write_json, AttemptState, OpenStudy, StudyError};
use super::summary::{summarize, Row, Summary};
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

/// The words of the report's method.
pub const METHOD: &str = "Trials marked done count; a participant's value for a condition is the mean of their done trials of it; \
mean ± sd are over participants (sd with n − 1). Each condition is compared with the baseline, paired by participant: a two-sided \
paired t-test and a two-sided Wilcoxon signed-rank test (exact below 50 pairs without ties or zero differences, else the normal \
approximation with tie and continuity corrections). p-values are adjusted by Holm's method over the conditions of each metric \
(within each group).";

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
            out.push(Row {
                participant: part.id.clone(),
                attributes: part.attributes.clone(),
                trial: a.trial,
                attempt: a.attempt,
                outcome: a.state.as_str().to_string(),
                block: s.study.blocks[t.block].name.clone(),
                block_position: t.block_position,
                condition: a.condition.clone(),
                repetition: t.repetition,
                seed: a.seed,
                stopped: a.stopped,
                started_utc: a.started_utc.clone(),
                trial_dir: Path::new(&part.id).join(&a.dir).display().to_string(),
                note: a.note.clone(),
                figures: figures.unwrap_or_else(|| vec![None; METRICS.len()]),
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
pub fn trials_csv(rows: &[Row], attributes: &[String]) -> String {
    let mut header: Vec<String> = vec!["participant".into()];
    header.extend(attributes.iter().cloned());
    header.extend(super::metrics::FIXED_COLUMNS[1..].iter().map(|c| c.to_string()));
    header.extend(METRICS.iter().map(|m| m.name.to_string()));
    let mut out = header.iter().map(|h| field(h)).collect::<Vec<_>>().join(",") + "\n";
    for r in rows {
        let mut cells = vec![field(&r.participant)];
        cells.extend(attributes.iter().map(|a| field(r.attributes.get(a).map_or("", String::as_str))));
        cells.extend([
            r.trial.to_string(),
            r.attempt.to_string(),
            r.outcome.clone(),
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

/// Writes the report into `out` (default `DATA/report/`); the folder.
pub fn write(s: &OpenStudy, out: Option<&Path>, group: Option<&str>) -> Result<PathBuf, StudyError> {
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| s.data.join("report"));
    std::fs::create_dir_all(&out).map_err(|source| StudyError::Io { path: out.clone(), source })?;
    let rows = rows(s)?;
    let attributes = attribute_names(s);
    crate::durable::write_whole(&out.join("trials.csv"), trials_csv(&rows, &attributes).as_bytes())?;
    let mut answers = Vec::new();
    for p in 0..s.study.participants.len() {
        answers.extend(questionnaire::load(s, p)?);
    }
    crate::durable::write_whole(&out.join("sus.csv"), answers_csv(s, &answers, Instrument::Sus, &attributes).as_bytes())?;
    crate::durable::write_whole(&out.join("tlx.csv"), answers_csv(s, &answers, Instrument::Tlx, &attributes).as_bytes())?;
    let report = compute(s, &rows, &answers, group)?;
    write_json(&out.join("summary.json"), &report)?;
    crate::durable::write_whole(&out.join("report.html"), page(&report).into_string().as_bytes())?;
    Ok(out)
}

/// The report's figures from the rows and answers.
pub fn compute(s: &OpenStudy, rows: &[Row], answers: &[Answer], group: Option<&str>) -> Result<ReportFile, StudyError> {
    let conditions: Vec<String> = s.study.conditions.iter().map(|c| c.name.clone()).collect();
    let baseline = s.study.baseline.map(|b| conditions[b].clone());
    let group_by = group_by(s, group)?;
    let all: Vec<&Row> = rows.iter().collect();
    let mut summaries = vec![summarize(&all, &conditions, baseline.as_deref(), None)];
    if let Some(g) = &group_by {
        let values: BTreeSet<&String> = s.study.participants.iter().filter_map(|p| p.attributes.get(g)).collect();
        for v in values {
            let these: Vec<&Row> = rows.iter().filter(|r| r.attributes.get(g) == Some(v)).collect();
            summaries.push(summarize(&these, &conditions, baseline.as_deref(), Some(v.clone())));
        }
    }
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
    })
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
.method{font-size:.9em;color:#444;max-width:60em}.sig{font-weight:bold}";

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
                }
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

fn metric_section(r: &ReportFile, summary: &Summary, m: &super::summary::MetricSummary) -> Markup {
    let id = format!("{}-{}", summary.group.as_deref().unwrap_or("all").replace(' ', "_"), m.metric);
    let svg = plot(&id, m).unwrap_or_default();
    html! {
        div class="metric" id=(id) {
            h3 { (m.label) }
            table {
                tr { th { "condition" } th { "participants" } th { "trials" } th { "mean ± sd" }
                     th { "Δ vs " (r.baseline.as_deref().unwrap_or("–")) } th { "t (df)" } th { "p" } th { "p Holm" }
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
        let mut chart = crate::html::plot::chart_on(&root, m.label)
            .build_cartesian_2d(-0.5..n - 0.5, lo..hi)
            .ok()?;
        let label = |v: &f64| crate::html::plot::whole(*v).and_then(|i| names.get(usize::try_from(i).ok()?).cloned()).unwrap_or_default();
        chart
            .configure_mesh()
            .x_labels(names.len())
            .x_label_formatter(&label)
            .y_label_formatter(&crate::html::plot::short)
            .x_desc("condition")
            .y_desc(m.label)
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
