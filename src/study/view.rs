//! A participant's progress as `netfi study status` and the experimenter's
//! page show it: every trial with its last attempt, and what comes next.

use super::questionnaire;
use super::schedule::Due;
use super::store::{claim, load_state, AttemptState, Next, OpenStudy, ParticipantState, StudyError};
use serde::Serialize;
use std::collections::BTreeMap;

/// One trial of a participant's schedule and how it stands.
#[derive(Debug, Clone, Serialize)]
pub struct TrialView {
    pub trial: u32,
    pub block: String,
    pub block_position: u32,
    pub condition: String,
    pub repetition: u32,
    pub seed: u64,
    /// `pending`, or its last attempt's state.
    pub state: String,
    pub attempts: u32,
    /// The last attempt's folder, relative to the participant's.
    pub dir: Option<String>,
    pub stopped: bool,
    pub faults: Vec<String>,
    pub note: String,
    /// The last attempt's run id (its run in `netfi ui`'s `/runs`).
    pub run_id: Option<String>,
    /// The last attempt's counts of the study's measures.
    pub counts: BTreeMap<String, u32>,
    /// `clean` or `suspect` (the study's `[clean]`), once its run gave
    /// figures; empty before.
    pub clean: String,
    /// Why it is suspect.
    pub suspect_because: Vec<String>,
}

/// What comes next, for people.
#[derive(Debug, Clone, Serialize)]
pub struct NextView {
    /// `trial`, `running`, `unmarked`, `questionnaire` or `finished`.
    pub kind: &'static str,
    pub trial: Option<u32>,
    pub attempt: Option<u32>,
    pub condition: Option<String>,
    pub block: Option<String>,
    /// `sus` or `tlx`, and the key it is stored under.
    pub questionnaire: Option<&'static str>,
    pub key: Option<String>,
    /// A questionnaire's title, naming the trial or block it follows.
    pub title: Option<String>,
    /// A running trial with the lab's programs: the peer it waits for.
    pub waiting_for: Option<String>,
}

/// A participant's progress.
#[derive(Debug, Clone, Serialize)]
pub struct ParticipantView {
    pub participant: String,
    pub attributes: BTreeMap<String, String>,
    pub square_row: Option<usize>,
    pub blocks: Vec<String>,
    pub trials: Vec<TrialView>,
    /// Counts of the trials by state.
    pub counts: BTreeMap<String, u32>,
    pub next: NextView,
    /// Who is advancing the participant now, if someone is.
    pub busy: Option<String>,
    pub questionnaires_answered: Vec<String>,
    pub questionnaires_due: Vec<String>,
    /// The study's input files that changed after participants began.
    pub study_changed: Vec<String>,
}

/// Participant `p`'s progress. An attempt whose runner died is marked
/// `interrupted` on the way, when nobody holds the participant.
pub fn participant(s: &OpenStudy, p: usize) -> Result<ParticipantView, StudyError> {
    let dir = s.participant_dir(p);
    let stored = load_state(&dir)?.unwrap_or_default();
    // Only a trial left `running` needs the lock (to be found interrupted);
    // otherwise reading is enough, and takes nobody's lock from under them.
    let (state, busy) = if stored.attempts.iter().any(|a| a.state == AttemptState::Running) {
        match claim(s, p, "netfi study status") {
            Ok((lock, state)) => {
                lock.release();
                (state, None)
            }
            Err(StudyError::Busy { holder, .. }) => (stored, Some(holder)),
            Err(e) => return Err(e),
        }
    } else {
        (stored, None)
    };
    let answered = questionnaire::answered(s, p);
    let next = super::store::next_step(s, p, &state, &answered);
    let mut v = view(s, p, &state, &next, busy, answered);
    v.study_changed = s.changed_inputs()?;
    Ok(v)
}

fn view(s: &OpenStudy, p: usize, state: &ParticipantState, next: &Next, busy: Option<String>, answered: Vec<String>) -> ParticipantView {
    let sch = &s.schedules[p];
    let part = &s.study.participants[p];
    let trials: Vec<TrialView> = sch
        .trials
        .iter()
        .map(|t| {
            let last = state.last_of(t.number);
            let figures = last.filter(|a| !matches!(a.state, AttemptState::Running)).and_then(|a| super::trials::load_figures(&s.participant_dir(p).join(&a.dir)));
            let why = figures.as_ref().map(|f| super::metrics::suspect_because(f, &s.study.clean));
            TrialView {
                trial: t.number,
                block: s.study.blocks[t.block].name.clone(),
                block_position: t.block_position,
                condition: s.study.conditions[t.condition].name.clone(),
                repetition: t.repetition,
                seed: t.seed,
                state: last.map_or("pending", |a| a.state.as_str()).to_string(),
                attempts: state.attempts.iter().filter(|a| a.trial == t.number).count() as u32,
                dir: last.map(|a| a.dir.clone()),
                stopped: last.is_some_and(|a| a.stopped),
                faults: last.map(|a| a.faults.clone()).unwrap_or_default(),
                note: last.map(|a| a.note.clone()).unwrap_or_default(),
                run_id: last.and_then(|a| a.run_id.clone()),
                counts: last.map(|a| a.counts.clone()).unwrap_or_default(),
                clean: match &why {
                    None => String::new(),
                    Some(w) if w.is_empty() => "clean".into(),
                    Some(_) => "suspect".into(),
                },
                suspect_because: why.unwrap_or_default(),
            }
        })
        .collect();
    let mut counts = BTreeMap::new();
    for t in &trials {
        *counts.entry(t.state.clone()).or_insert(0) += 1;
    }
    let name = |t: u32| sch.trials.iter().find(|x| x.number == t).map(|x| (s.study.conditions[x.condition].name.clone(), s.study.blocks[x.block].name.clone()));
    let nv = |kind, trial: Option<u32>, attempt| {
        let (condition, block) = trial.and_then(name).map_or((None, None), |(c, b)| (Some(c), Some(b)));
        NextView { kind, trial, attempt, condition, block, questionnaire: None, key: None, title: None, waiting_for: None }
    };
    let next = match next {
        Next::Trial { trial, attempt } => nv("trial", Some(trial.number), Some(*attempt)),
        Next::Running(a) => NextView { waiting_for: a.waiting_for.clone(), ..nv("running", Some(a.trial), Some(a.attempt)) },
        Next::Unmarked(a) => nv("unmarked", Some(a.trial), Some(a.attempt)),
        Next::Questionnaire(d) => {
            let (q, block) = match d {
                Due::Sus => ("sus", None),
                Due::Tlx { block, .. } => ("tlx", Some(s.study.blocks[*block].name.clone())),
            };
            let title = questionnaire_title(s, p, d);
            NextView { kind: "questionnaire", trial: None, attempt: None, condition: None, block, questionnaire: Some(q), key: Some(d.key()), title: Some(title), waiting_for: None }
        }
        Next::Finished => nv("finished", None, None),
    };
    let due = sch.due.iter().map(Due::key).filter(|k| !answered.contains(k)).collect();
    ParticipantView {
        participant: part.id.clone(),
        attributes: part.attributes.clone(),
        square_row: sch.square_row,
        blocks: sch.blocks.iter().map(|&b| s.study.blocks[b].name.clone()).collect(),
        trials,
        counts,
        next,
        busy,
        questionnaires_answered: answered,
        questionnaires_due: due,
        study_changed: Vec::new(),
    }
}

/// A questionnaire's title: the instrument, and the trial or block (with
/// its trials) it follows.
pub fn questionnaire_title(s: &OpenStudy, p: usize, d: &Due) -> String {
    let sch = &s.schedules[p];
    match d {
        Due::Sus => "System Usability Scale, before trial 1".to_string(),
        Due::Tlx { after, block } if s.study.questionnaires.tlx == super::file::TlxWhen::Trial => {
            let c = sch.trials.iter().find(|t| t.number == *after).map(|t| s.study.conditions[t.condition].name.as_str()).unwrap_or("?");
            format!("NASA-TLX after trial {after} ({c}, block {})", s.study.blocks[*block].name)
        }
        Due::Tlx { after, block } => {
            let numbers: Vec<u32> = sch.trials.iter().filter(|t| t.block == *block).map(|t| t.number).collect();
            let (first, last) = (numbers.first().copied().unwrap_or(*after), numbers.last().copied().unwrap_or(*after));
            let span = if first == last { format!("trial {first}") } else { format!("trials {first}–{last}") };
            format!("NASA-TLX after block {} ({span})", s.study.blocks[*block].name)
        }
    }
}
