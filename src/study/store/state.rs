//! A participant's state (`state.json`): every attempt of every trial and
//! how it ended, and what comes next.

use crate::study::schedule::{Due, Trial};
use super::{read_json, write_json, OpenStudy, StudyError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// How an attempt stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AttemptState {
    /// Its run is going (or its runner died: see the module's docs).
    Running,
    /// Its run ended; the experimenter has not marked it yet.
    Ran,
    /// Counted.
    Done,
    /// Over, not counted, not repeated (the task or the run failed).
    Failed,
    /// Not counted; the trial is run again.
    Repeat,
    /// Its runner was killed: not counted; the trial is run again.
    Interrupted,
}

impl AttemptState {
    /// As the table writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            AttemptState::Running => "running",
            AttemptState::Ran => "ran",
            AttemptState::Done => "done",
            AttemptState::Failed => "failed",
            AttemptState::Repeat => "repeat",
            AttemptState::Interrupted => "interrupted",
        }
    }
}

/// One attempt of one trial.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Attempt {
    pub trial: u32,
    pub attempt: u32,
    pub condition: String,
    /// Its folder, relative to the participant's.
    pub dir: String,
    pub state: AttemptState,
    pub seed: u64,
    pub started_utc: String,
    #[serde(default)]
    pub ended_utc: Option<String>,
    /// The process running it (`netfi study next`), while running.
    #[serde(default)]
    pub runner_pid: Option<u32>,
    /// Its `netfi run`.
    #[serde(default)]
    pub run_pid: Option<u32>,
    /// Its run id (`netfi ctl --run-id`; the page's link to the run).
    #[serde(default)]
    pub run_id: Option<String>,
    /// How the run ended (`exit 0`, `signal 9`).
    #[serde(default)]
    pub run_status: Option<String>,
    /// The experimenter stopped it.
    #[serde(default)]
    pub stopped: bool,
    /// The run left a report (`report.json`).
    #[serde(default)]
    pub report: bool,
    /// The run's own faults, from its report.
    #[serde(default)]
    pub faults: Vec<String>,
    #[serde(default)]
    pub note: String,
    /// The study's `[[measure]]`s as the experimenter counted them.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub counts: std::collections::BTreeMap<String, u32>,
    /// While it runs with the lab's programs: the peer it waits for
    /// (`the lab's console at udp://…`); `None` once both came.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub waiting_for: Option<String>,
    /// With the lab's programs: seconds from the run's start until the
    /// lab's console's first frame was seen (to within about a second:
    /// the trace is written once a second).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub console_came_s: Option<f64>,
}

/// A participant's state: every attempt, in the order they began.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ParticipantState {
    pub participant: String,
    pub attempts: Vec<Attempt>,
}

impl ParticipantState {
    /// The last attempt of trial `n`.
    pub fn last_of(&self, n: u32) -> Option<&Attempt> {
        self.attempts.iter().rev().find(|a| a.trial == n)
    }

    /// Whether trial `n` is over (its last attempt done or failed).
    pub fn finished(&self, n: u32) -> bool {
        self.last_of(n).is_some_and(|a| matches!(a.state, AttemptState::Done | AttemptState::Failed))
    }
}

/// What comes next for a participant.
#[derive(Debug, Clone, PartialEq)]
pub enum Next {
    /// Run this trial, as this attempt.
    Trial { trial: Trial, attempt: u32 },
    /// An attempt is running.
    Running(Attempt),
    /// An attempt ran and waits for the experimenter's mark.
    Unmarked(Attempt),
    /// A questionnaire is due first.
    Questionnaire(Due),
    /// Every trial is over.
    Finished,
}

/// What comes next for participant `p` given their state and the
/// questionnaires answered (their keys).
pub fn next_step(s: &OpenStudy, p: usize, state: &ParticipantState, answered: &[String]) -> Next {
    if let Some(a) = state.attempts.iter().find(|a| a.state == AttemptState::Running) {
        return Next::Running(a.clone());
    }
    if let Some(a) = state.attempts.iter().find(|a| a.state == AttemptState::Ran) {
        return Next::Unmarked(a.clone());
    }
    let sch = &s.schedules[p];
    let Some(trial) = sch.trials.iter().find(|t| !state.finished(t.number)) else {
        // Questionnaires after the last trial are still due.
        return match sch.due.iter().find(|d| !answered.contains(&d.key())) {
            Some(d) => Next::Questionnaire(d.clone()),
            None => Next::Finished,
        };
    };
    if let Some(d) = sch.due.iter().find(|d| d.before_trial() <= trial.number && !answered.contains(&d.key())) {
        return Next::Questionnaire(d.clone());
    }
    let attempt = state.attempts.iter().filter(|a| a.trial == trial.number).count() as u32 + 1;
    Next::Trial { trial: trial.clone(), attempt }
}

/// Reads `dir/state.json` (`None` before the participant's first trial).
pub fn load_state(dir: &Path) -> Result<Option<ParticipantState>, StudyError> {
    let path = dir.join("state.json");
    if !path.exists() {
        return Ok(None);
    }
    read_json(&path).map(Some)
}

/// Writes `dir/state.json` whole.
pub fn save_state(dir: &Path, state: &ParticipantState) -> Result<(), StudyError> {
    write_json(&dir.join("state.json"), state)
}
