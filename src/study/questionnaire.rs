//! The questionnaires a study asks: the System Usability Scale (Brooke,
//! 1996) and the NASA Task Load Index (Hart & Staveland, 1988), scored and
//! stored with the participant's data (`DATA/P/questionnaires/KEY.json`).
//!
//! The SUS is ten items answered 1 (strongly disagree) to 5 (strongly
//! agree); its score is 2.5 × (Σ over odd items of (x − 1) + Σ over even
//! items of (5 − x)), 0 to 100. The TLX is six scales 0 to 100 (mental,
//! physical and temporal demand, performance — 0 good, 100 poor — effort,
//! frustration); its score here is the raw TLX, their unweighted mean (the
//! pairwise weighting is not asked). A questionnaire that could not be
//! given is recorded as missing, with the reason, so the schedule goes on
//! and the gap is in the data.

use super::schedule::Due;
use super::store::{now_utc, read_json, write_json, OpenStudy, StudyError};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The TLX's scales, in the order they are given.
pub const TLX_SCALES: [&str; 6] = ["mental_demand", "physical_demand", "temporal_demand", "performance", "effort", "frustration"];

/// The SUS's item count.
pub const SUS_ITEMS: usize = 10;

/// Which questionnaire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Instrument {
    Sus,
    Tlx,
}

/// One questionnaire as answered (or recorded missing).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Answer {
    pub participant: String,
    pub instrument: Instrument,
    /// `sus`, `tlx-NN` (after trial NN).
    pub key: String,
    /// The trial it follows (a TLX).
    pub after_trial: Option<u32>,
    /// The block it follows (a TLX), and that block's conditions.
    pub block: Option<String>,
    pub conditions: Vec<String>,
    pub answered_utc: String,
    /// The items (SUS, 1–5) or scales (TLX, 0–100, in [`TLX_SCALES`]' order).
    pub values: Vec<u32>,
    /// The SUS score, or the raw TLX (0–100).
    pub score: Option<f64>,
    /// Why it was not answered, when it was not.
    pub missing: Option<String>,
}

/// The SUS score of ten answers 1–5.
pub fn sus_score(items: &[u32]) -> Result<f64, String> {
    if items.len() != SUS_ITEMS {
        return Err(format!("the SUS has {SUS_ITEMS} items, {} given", items.len()));
    }
    if let Some((i, x)) = items.iter().enumerate().find(|(_, x)| !(1..=5).contains(*x)) {
        return Err(format!("SUS item {}: {x}: each item is answered 1 (strongly disagree) to 5 (strongly agree)", i + 1));
    }
    let sum: u32 = items.iter().enumerate().map(|(i, &x)| if i % 2 == 0 { x - 1 } else { 5 - x }).sum();
    Ok(2.5 * f64::from(sum))
}

/// The raw TLX of six scales 0–100.
pub fn tlx_raw(scales: &[u32]) -> Result<f64, String> {
    if scales.len() != TLX_SCALES.len() {
        return Err(format!("the NASA-TLX has {} scales ({}), {} given", TLX_SCALES.len(), TLX_SCALES.join(", "), scales.len()));
    }
    if let Some((i, x)) = scales.iter().enumerate().find(|(_, x)| **x > 100) {
        return Err(format!("TLX {}: {x}: each scale is 0 to 100", TLX_SCALES[i]));
    }
    Ok(f64::from(scales.iter().sum::<u32>()) / TLX_SCALES.len() as f64)
}

fn folder(s: &OpenStudy, p: usize) -> PathBuf {
    s.participant_dir(p).join("questionnaires")
}

/// The keys of the questionnaires participant `p` has answered (or
/// recorded missing).
pub fn answered(s: &OpenStudy, p: usize) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(folder(s, p)) else { return Vec::new() };
    let mut keys: Vec<String> = entries
        .filter_map(|e| e.ok()?.file_name().to_str()?.strip_suffix(".json").map(str::to_string))
        .collect();
    keys.sort();
    keys
}

/// Every answer of participant `p`, by key.
pub fn load(s: &OpenStudy, p: usize) -> Result<Vec<Answer>, StudyError> {
    let dir = folder(s, p);
    answered(s, p).iter().map(|k| read_json(&dir.join(format!("{k}.json")))).collect()
}

/// The questionnaire of `instrument` due now for participant `p` (its
/// trials before it are over), if one is.
pub fn due_now(s: &OpenStudy, p: usize, instrument: Instrument, finished: impl Fn(u32) -> bool) -> Option<Due> {
    let done = answered(s, p);
    s.schedules[p].due.iter().find(|d| {
        let kind = match d {
            Due::Sus => Instrument::Sus,
            Due::Tlx { .. } => Instrument::Tlx,
        };
        kind == instrument && !done.contains(&d.key()) && (1..d.before_trial()).all(&finished)
    }).cloned()
}

/// Records participant `p`'s answers (`values`) to `due`, or that it was
/// not answered (`missing`: the reason). Returns the file written.
pub fn record(s: &OpenStudy, p: usize, due: &Due, values: &[u32], missing: Option<&str>) -> Result<PathBuf, StudyError> {
    let (instrument, after_trial, block) = match due {
        Due::Sus => (Instrument::Sus, None, None),
        Due::Tlx { after, block } => (Instrument::Tlx, Some(*after), Some(*block)),
    };
    let score = match (missing, instrument) {
        (Some(why), _) if why.trim().is_empty() => return Err(StudyError::State("a missing questionnaire needs its reason".into())),
        (Some(_), _) if !values.is_empty() => return Err(StudyError::State("either answers or a reason it is missing, not both".into())),
        (Some(_), _) => None,
        (None, Instrument::Sus) => Some(sus_score(values).map_err(StudyError::State)?),
        (None, Instrument::Tlx) => Some(tlx_raw(values).map_err(StudyError::State)?),
    };
    let conditions = match due {
        Due::Tlx { after, .. } if s.study.questionnaires.tlx == super::file::TlxWhen::Trial => {
            let t = &s.schedules[p].trials[*after as usize - 1];
            vec![s.study.conditions[t.condition].name.clone()]
        }
        _ => block.map(|b| s.study.blocks[b].conditions.iter().map(|&c| s.study.conditions[c].name.clone()).collect()).unwrap_or_default(),
    };
    let answer = Answer {
        participant: s.study.participants[p].id.clone(),
        instrument,
        key: due.key(),
        after_trial,
        block: block.map(|b| s.study.blocks[b].name.clone()),
        conditions,
        answered_utc: now_utc(),
        values: values.to_vec(),
        score,
        missing: missing.map(str::to_string),
    };
    let dir = folder(s, p);
    std::fs::create_dir_all(&dir).map_err(|source| StudyError::Io { path: dir.clone(), source })?;
    let path = dir.join(format!("{}.json", due.key()));
    write_json(&path, &answer)?;
    Ok(path)
}
