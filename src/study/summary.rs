//! The comparison across conditions, from the per-trial rows alone.
//!
//! Pure. Only trials marked `done` count. A participant's value for a
//! condition is the mean of their done trials of it; the mean ± sd of a
//! condition is over those participant values (so a participant with three
//! Normal trials weighs as much as one with one), and each condition is
//! compared with the baseline by a paired t-test and a Wilcoxon
//! signed-rank test over the participants who have both. For each metric
//! (and group) the conditions' p-values form one family, adjusted by Holm's
//! method.

use super::metrics::{Figures, METRICS};
use std::borrow::Cow;
use super::stats::{holm, mean, paired_t, sd, wilcoxon, TTest, Wilcoxon};
use serde::Serialize;
use std::collections::BTreeMap;

/// One attempt of a trial, as the study's table has it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    pub participant: String,
    pub attributes: BTreeMap<String, String>,
    pub trial: u32,
    pub attempt: u32,
    /// `done`, `failed`, `repeat`, `interrupted`, `ran` (not yet marked)
    /// or `running`.
    pub outcome: String,
    /// `clean`, `suspect` (netfi or the host got in the trial's way:
    /// `[clean]`), or empty where the run gave no figures.
    pub clean: String,
    /// Why it is suspect.
    pub suspect_because: String,
    pub block: String,
    pub block_position: u32,
    pub condition: String,
    pub repetition: u32,
    pub seed: u64,
    /// The experimenter stopped it (before its longest duration).
    pub stopped: bool,
    pub started_utc: String,
    pub trial_dir: String,
    pub note: String,
    /// In the order of the table's columns ([`Column`]): [`METRICS`], then
    /// the study's measures.
    pub figures: Figures,
}

/// A numeric column the comparison is made of: a metric of the runs, a
/// measure the experimenter counted, a questionnaire's scale.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Column {
    pub name: Cow<'static, str>,
    pub label: Cow<'static, str>,
}

impl Column {
    /// Every metric of a run, in [`METRICS`]' order.
    pub fn metrics() -> Vec<Column> {
        METRICS.iter().map(|m| Column { name: Cow::Borrowed(m.name), label: Cow::Borrowed(m.label) }).collect()
    }
}

/// One condition's figure for one metric.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConditionStat {
    pub condition: String,
    /// Done trials with this figure.
    pub trials: usize,
    /// Participants with this figure (the n of the mean and sd).
    pub participants: usize,
    pub mean: Option<f64>,
    pub sd: Option<f64>,
    /// Against the baseline (absent for the baseline itself).
    pub versus_baseline: Option<Comparison>,
}

/// A condition against the baseline, paired by participant.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Comparison {
    /// Participants with both.
    pub pairs: usize,
    pub t_test: Option<TTest>,
    /// The t-test's p adjusted by Holm over this metric's conditions.
    pub t_p_holm: Option<f64>,
    pub wilcoxon: Option<Wilcoxon>,
    pub wilcoxon_p_holm: Option<f64>,
}

/// One metric across the conditions.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MetricSummary {
    pub metric: Cow<'static, str>,
    pub label: Cow<'static, str>,
    pub conditions: Vec<ConditionStat>,
}

/// The comparison for one set of participants (all, or one group).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// `None` for all participants, else the group's value.
    pub group: Option<String>,
    pub participants: usize,
    pub metrics: Vec<MetricSummary>,
}

/// Each participant's mean of `metric` per condition, over done trials.
fn participant_means(rows: &[&Row], metric: usize) -> BTreeMap<(String, String), (f64, usize)> {
    let mut sums: BTreeMap<(String, String), (f64, usize)> = BTreeMap::new();
    for r in rows.iter().filter(|r| r.outcome == "done") {
        if let Some(v) = r.figures.get(metric).copied().flatten() {
            let e = sums.entry((r.condition.clone(), r.participant.clone())).or_default();
            e.0 += v;
            e.1 += 1;
        }
    }
    sums.into_iter().map(|(k, (s, n))| (k, (s / n as f64, n))).collect()
}

/// The summary of `rows` over `conditions` (in the study's order), against
/// `baseline` if given, for every metric of a run.
pub fn summarize(rows: &[&Row], conditions: &[String], baseline: Option<&str>, group: Option<String>) -> Summary {
    summarize_columns(rows, &Column::metrics(), conditions, baseline, group)
}

/// The summary of `rows`' figures in `columns`' order (any numeric
/// columns) over `conditions`, against `baseline` if given.
pub fn summarize_columns(rows: &[&Row], columns: &[Column], conditions: &[String], baseline: Option<&str>, group: Option<String>) -> Summary {
    let participants = {
        let mut ids: Vec<&str> = rows.iter().map(|r| r.participant.as_str()).collect();
        ids.sort_unstable();
        ids.dedup();
        ids.len()
    };
    let metrics = columns
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let means = participant_means(rows, k);
            let of = |c: &str| -> BTreeMap<&str, (f64, usize)> {
                means.iter().filter(|((cc, _), _)| cc == c).map(|((_, p), v)| (p.as_str(), *v)).collect()
            };
            let base = baseline.map(of);
            let mut stats: Vec<ConditionStat> = conditions
                .iter()
                .map(|c| {
                    let values = of(c);
                    let xs: Vec<f64> = values.values().map(|v| v.0).collect();
                    let versus_baseline = match (&base, baseline) {
                        (Some(b), Some(name)) if name != c => {
                            let d: Vec<f64> = values.iter().filter_map(|(p, v)| b.get(p).map(|bv| v.0 - bv.0)).collect();
                            Some(Comparison { pairs: d.len(), t_test: paired_t(&d), t_p_holm: None, wilcoxon: wilcoxon(&d), wilcoxon_p_holm: None })
                        }
                        _ => None,
                    };
                    ConditionStat {
                        condition: c.clone(),
                        trials: values.values().map(|v| v.1).sum(),
                        participants: xs.len(),
                        mean: mean(&xs),
                        sd: sd(&xs),
                        versus_baseline,
                    }
                })
                .collect();
            adjust(&mut stats);
            MetricSummary { metric: m.name.clone(), label: m.label.clone(), conditions: stats }
        })
        .collect();
    Summary { group, participants, metrics }
}

/// Holm over the conditions that have a test, for each of the two tests.
fn adjust(stats: &mut [ConditionStat]) {
    let t: Vec<(usize, f64)> =
        stats.iter().enumerate().filter_map(|(i, s)| Some((i, s.versus_baseline.as_ref()?.t_test?.p))).collect();
    for ((i, _), adj) in t.iter().zip(holm(&t.iter().map(|x| x.1).collect::<Vec<_>>())) {
        if let Some(c) = stats[*i].versus_baseline.as_mut() {
            c.t_p_holm = Some(adj);
        }
    }
    let w: Vec<(usize, f64)> =
        stats.iter().enumerate().filter_map(|(i, s)| Some((i, s.versus_baseline.as_ref()?.wilcoxon?.p))).collect();
    for ((i, _), adj) in w.iter().zip(holm(&w.iter().map(|x| x.1).collect::<Vec<_>>())) {
        if let Some(c) = stats[*i].versus_baseline.as_mut() {
            c.wilcoxon_p_holm = Some(adj);
        }
    }
}
