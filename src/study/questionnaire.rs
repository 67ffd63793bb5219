//! The questionnaires a study asks: the System Usability Scale (Brooke,
//! 1996) and the NASA Task Load Index (Hart & Staveland, 1988), scored and
//! stored with the participant's data (`DATA/P/questionnaires/KEY.json`).
//!
//! The SUS is ten items answered 1 (strongly disagree) to 5 (strongly
//! agree); its score is 2.5 × (Σ over odd items of (x − 1) + Σ over even
//! items of (5 − x)), 0 to 100. The TLX is six scales 0 to 100 (mental,
//! physical and temporal demand, performance — 0 good, 100 poor — effort,
//! frustration); its score is the raw TLX, their unweighted mean, unless
//! the study asks the pairwise weighting (`questionnaires.tlx_weighting =
//! "pairwise"`): then the participant also chooses in each of the 15 pairs
//! of scales the one that contributed more to the workload, a scale's
//! weight is how often it was chosen (0–5, the weights sum to 15), and the
//! weighted TLX is Σ weight × rating / 15; the raw TLX is kept beside it.
//! Every item is answered: none has a default. A questionnaire that could not be
//! given is recorded as missing, with the reason, so the schedule goes on
//! and the gap is in the data.

use super::file::TlxWeighting;
use super::schedule::Due;
use super::store::{now_utc, read_json, write_json, OpenStudy, StudyError};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The TLX's scales, in the order they are given.
pub const TLX_SCALES: [&str; 6] = ["mental_demand", "physical_demand", "temporal_demand", "performance", "effort", "frustration"];

/// The SUS's item count.
pub const SUS_ITEMS: usize = 10;

/// The SUS's ten statements (Brooke, 1996), in order.
pub const SUS_STATEMENTS: [&str; SUS_ITEMS] = [
    "I think that I would like to use this system frequently.",
    "I found the system unnecessarily complex.",
    "I thought the system was easy to use.",
    "I think that I would need the support of a technical person to be able to use this system.",
    "I found the various functions in this system were well integrated.",
    "I thought there was too much inconsistency in this system.",
    "I would imagine that most people would learn to use this system very quickly.",
    "I found the system very cumbersome to use.",
    "I felt very confident using the system.",
    "I needed to learn a lot of things before I could get going with this system.",
];

/// The SUS's answers 1 to 5, in words.
pub const SUS_SCALE: [&str; 5] = ["Strongly disagree", "Disagree", "Neither agree nor disagree", "Agree", "Strongly agree"];

/// One NASA-TLX scale as the form gives it (Hart, 1986: the NASA Task
/// Load Index's rating scale definitions).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TlxScale {
    /// Its key (a column name).
    pub key: &'static str,
    pub title: &'static str,
    pub question: &'static str,
    /// The words at 0 and at 100.
    pub low: &'static str,
    pub high: &'static str,
}

/// The six scales, in [`TLX_SCALES`]' order. Performance runs from
/// Perfect (0) to Failure (100), so every scale reads "higher is worse".
pub const TLX_FORM: [TlxScale; 6] = [
    TlxScale { key: "mental_demand", title: "Mental Demand", question: "How mentally demanding was the task?", low: "Very Low", high: "Very High" },
    TlxScale { key: "physical_demand", title: "Physical Demand", question: "How physically demanding was the task?", low: "Very Low", high: "Very High" },
    TlxScale { key: "temporal_demand", title: "Temporal Demand", question: "How hurried or rushed was the pace of the task?", low: "Very Low", high: "Very High" },
    TlxScale { key: "performance", title: "Performance", question: "How successful were you in accomplishing what you were asked to do?", low: "Perfect", high: "Failure" },
    TlxScale { key: "effort", title: "Effort", question: "How hard did you have to work to accomplish your level of performance?", low: "Very Low", high: "Very High" },
    TlxScale {
        key: "frustration",
        title: "Frustration",
        question: "How insecure, discouraged, irritated, stressed, and annoyed were you?",
        low: "Very Low",
        high: "Very High",
    },
];

/// The 15 pairs of TLX scales the weighting asks about, in the order they
/// are asked and stored (indices into [`TLX_SCALES`]).
pub fn tlx_pairs() -> Vec<(usize, usize)> {
    (0..TLX_SCALES.len()).flat_map(|a| (a + 1..TLX_SCALES.len()).map(move |b| (a, b))).collect()
}

/// The number of pairs: 6 choose 2.
pub const TLX_PAIRS: usize = 15;

/// The weights of the 15 choices (`chosen[k]`: the scale chosen in pair
/// `k`, one of its two): how often each scale was chosen.
pub fn tlx_weights(chosen: &[usize]) -> Result<Vec<u32>, String> {
    let pairs = tlx_pairs();
    if chosen.len() != pairs.len() {
        return Err(format!("the NASA-TLX weighting has {} pairs, {} choices given", pairs.len(), chosen.len()));
    }
    let mut w = vec![0u32; TLX_SCALES.len()];
    for (k, (&c, &(a, b))) in chosen.iter().zip(&pairs).enumerate() {
        if c != a && c != b {
            return Err(format!("pair {} is {} or {}: {} is neither", k + 1, TLX_SCALES[a], TLX_SCALES[b], TLX_SCALES.get(c).copied().unwrap_or("?")));
        }
        w[c] += 1;
    }
    Ok(w)
}

/// The weighted TLX: Σ weight × rating / 15.
pub fn tlx_weighted(scales: &[u32], weights: &[u32]) -> f64 {
    let sum: u32 = scales.iter().zip(weights).map(|(x, w)| x * w).sum();
    f64::from(sum) / TLX_PAIRS as f64
}

/// The scale a word names: its key, or the key's first word
/// (`mental`, `physical`, `temporal`, `performance`, `effort`, `frustration`).
pub fn tlx_scale_named(word: &str) -> Option<usize> {
    let w = word.trim().to_ascii_lowercase();
    TLX_SCALES.iter().position(|k| *k == w || k.split('_').next() == Some(w.as_str()))
}

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
    /// The TLX's pairwise choices (the scale chosen in each of
    /// [`tlx_pairs`]), when the study weights it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pairs: Option<Vec<usize>>,
    /// The weights they give, and the weighted TLX.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<Vec<u32>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weighted: Option<f64>,
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

/// Answers as a form sends them: an item left untouched is `None`.
/// Every item must have been answered.
pub fn complete(instrument: Instrument, values: &[Option<u32>]) -> Result<Vec<u32>, String> {
    let (n, what) = match instrument {
        Instrument::Sus => (SUS_ITEMS, "SUS item"),
        Instrument::Tlx => (TLX_SCALES.len(), "NASA-TLX scale"),
    };
    let open: Vec<String> = values
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_none())
        .map(|(i, _)| match instrument {
            Instrument::Sus => (i + 1).to_string(),
            Instrument::Tlx => TLX_SCALES[i.min(TLX_SCALES.len() - 1)].to_string(),
        })
        .collect();
    if !open.is_empty() {
        return Err(format!("not answered: {what} {} (every item is answered; none has a default)", open.join(", ")));
    }
    if values.len() != n {
        return Err(format!("{n} answers expected, {} given", values.len()));
    }
    Ok(values.iter().flatten().copied().collect())
}

/// Records participant `p`'s answers (`values`) to `due`, or that it was
/// not answered (`missing`: the reason); with a weighted TLX, the 15
/// pairwise choices (`pairs`). Returns the file written.
pub fn record(s: &OpenStudy, p: usize, due: &Due, values: &[u32], pairs: Option<&[usize]>, missing: Option<&str>) -> Result<PathBuf, StudyError> {
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
    let weighting = s.study.questionnaires.tlx_weighting;
    let weights = match (instrument, weighting, missing, pairs) {
        (Instrument::Tlx, TlxWeighting::Pairwise, None, Some(chosen)) => Some(tlx_weights(chosen).map_err(StudyError::State)?),
        (Instrument::Tlx, TlxWeighting::Pairwise, None, None) => {
            return Err(StudyError::State("this study weights the NASA-TLX: give the 15 pairwise choices too".into()))
        }
        (_, _, _, Some(_)) => {
            return Err(StudyError::State("pairwise choices belong to an answered NASA-TLX of a study that weights it (`questionnaires.tlx_weighting = \"pairwise\"`)".into()))
        }
        _ => None,
    };
    let weighted = weights.as_ref().map(|w| tlx_weighted(values, w));
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
        pairs: weights.as_ref().and(pairs).map(<[usize]>::to_vec),
        weights,
        weighted,
    };
    let dir = folder(s, p);
    std::fs::create_dir_all(&dir).map_err(|source| StudyError::Io { path: dir.clone(), source })?;
    let path = dir.join(format!("{}.json", due.key()));
    write_json(&path, &answer)?;
    Ok(path)
}
