//! A study on disk: the study file opened and checked, its data folder,
//! and each participant's state.
//!
//! ```text
//! DATA/
//!   study.toml            the study file as the schedules were written from it
//!   schedule.json         every participant's schedule (`netfi study plan --write`, or the first trial)
//!   P01/
//!     lock                flock: whoever advances P01 holds it (its pid inside)
//!     state.json          every attempt of every trial, and how it ended
//!     trial-01-PLM-2/     the first attempt's `netfi run --out`, its figures in figures.json
//!     trial-01-PLM-2-attempt-2/
//!     questionnaires/sus.json, tlx-03.json
//! ```
//!
//! Every file is written whole (temp + rename, [`crate::durable`]), so a
//! kill leaves the previous state or the next, never half of one. A trial
//! is recorded `running` before its run starts; whoever next takes the
//! participant's lock and finds it still `running` knows its runner died
//! (the kernel let go of the lock) and marks it `interrupted`: it is kept,
//! never counted, and the trial is run again.


mod lock;
mod state;

pub use lock::{claim, process_names, ParticipantLock};
pub use state::{load_state, next_step, save_state, Attempt, AttemptState, Next, ParticipantState};

use super::file::{ConditionSource, Study, StudyFileError};
use super::parse::parse_study;
use super::schedule::{schedule, Due, Schedule, Trial};
use crate::durable::{write_whole, DurableError};
use lock::StudyLock;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Why a study command could not do what it was asked.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// The study file is wrong (file, line, field).
    #[error(transparent)]
    File(#[from] StudyFileError),
    /// A file could not be read.
    #[error("{}: {problem}", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        problem: String,
    },
    /// A condition's scenario file is wrong.
    #[error("condition `{condition}`: {source}")]
    Scenario {
        /// The condition.
        condition: String,
        /// The scenario parser's error (file, line, field).
        #[source]
        source: Box<crate::scenario::ScenarioError>,
    },
    /// No participant of this id.
    #[error("no participant `{id}` in the study (participants: {known})")]
    UnknownParticipant {
        /// The id asked for.
        id: String,
        /// The study's ids.
        known: String,
    },
    /// Someone else is advancing the participant.
    #[error("participant `{id}` is busy: {holder} holds {} (wait for its trial to end, or stop it)", .lock.display())]
    Busy {
        /// The participant.
        id: String,
        /// Who holds the lock, as its file says.
        holder: String,
        /// The lock file.
        lock: PathBuf,
    },
    /// The schedule a participant started with is no longer what the
    /// study file gives.
    #[error("the study file changed the schedule of `{id}`, who has begun: {what}. Put the file back as it was (a copy is {}), or give the change to participants who have not begun", .copy.display())]
    Changed {
        /// The participant.
        id: String,
        /// The first difference.
        what: String,
        /// The study file as the schedules were written from it.
        copy: PathBuf,
    },
    /// What was asked does not fit the participant's state.
    #[error("{0}")]
    State(String),
    /// Writing the state.
    #[error(transparent)]
    Durable(#[from] DurableError),
    /// Another file system error.
    #[error("{}: {source}", .path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The kernel's error.
        #[source]
        source: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> StudyError + '_ {
    move |source| StudyError::Io { path: path.to_path_buf(), source }
}

/// The largest study file read.
const MAX_STUDY_BYTES: u64 = 16 << 20;
/// The largest state or report JSON read.
const MAX_JSON_BYTES: u64 = 256 << 20;

/// A study file opened: validated, its conditions' files checked, its
/// paths resolved, every schedule computed.
#[derive(Debug, Clone)]
pub struct OpenStudy {
    pub study: Study,
    /// The study file.
    pub file: PathBuf,
    /// Its text, as read.
    pub text: String,
    /// The data folder.
    pub data: PathBuf,
    /// Each participant's schedule, in the file's order.
    pub schedules: Vec<Schedule>,
    /// The capture each trial replays, resolved.
    pub capture: Option<PathBuf>,
}

impl OpenStudy {
    /// Reads and checks the study at `path`: the file, every condition's
    /// scenario file, the capture's presence.
    pub fn open(path: &Path) -> Result<OpenStudy, StudyError> {
        let bytes = crate::load::read_regular(path, MAX_STUDY_BYTES).map_err(|problem| StudyError::Read { path: path.into(), problem })?;
        let text = String::from_utf8(bytes)
            .map_err(|e| StudyError::Read { path: path.into(), problem: format!("not text (UTF-8): byte {} is not", e.utf8_error().valid_up_to()) })?;
        let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "study".into());
        let study = parse_study(&text, &path.display().to_string(), &stem)?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let dir = if dir.as_os_str().is_empty() { PathBuf::from(".") } else { dir };
        for c in &study.conditions {
            if let ConditionSource::File(f) = &c.source {
                crate::load::parse_file(&dir.join(f)).map_err(|source| StudyError::Scenario { condition: c.name.clone(), source: Box::new(source) })?;
            }
        }
        let capture = study.trial.capture.as_ref().map(|c| dir.join(c));
        if let Some(c) = &capture {
            if !c.is_file() {
                return Err(StudyError::Read { path: c.clone(), problem: "the study's `trial.capture`: no such file".into() });
            }
        }
        let data = match &study.data {
            Some(d) => dir.join(d),
            None => dir.join(format!("{stem}-data")),
        };
        let schedules = (0..study.participants.len()).map(|p| schedule(&study, p)).collect();
        Ok(OpenStudy { study, file: path.to_path_buf(), text, data, schedules, capture })
    }

    /// The index of participant `id`.
    pub fn participant(&self, id: &str) -> Result<usize, StudyError> {
        self.study.participants.iter().position(|p| p.id == id).ok_or_else(|| StudyError::UnknownParticipant {
            id: id.to_string(),
            known: self.study.participants.iter().map(|p| p.id.as_str()).collect::<Vec<_>>().join(", "),
        })
    }

    /// Participant `p`'s folder.
    pub fn participant_dir(&self, p: usize) -> PathBuf {
        self.data.join(&self.study.participants[p].id)
    }

    /// The name of trial `t`'s folder for attempt `attempt`.
    pub fn trial_dir_name(&self, t: &Trial, attempt: u32) -> String {
        let c = self.study.conditions[t.condition].name.replace(' ', "_");
        match attempt {
            1 => format!("trial-{:02}-{c}", t.number),
            k => format!("trial-{:02}-{c}-attempt-{k}", t.number),
        }
    }

    /// Writes `DATA/schedule.json` and the study file's copy, after
    /// checking that no participant who has begun would get another
    /// schedule. Participants who have not begun take the file as it is.
    pub fn record_schedules(&self) -> Result<PathBuf, StudyError> {
        std::fs::create_dir_all(&self.data).map_err(io(&self.data))?;
        let path = self.data.join("schedule.json");
        let copy = self.data.join("study.toml");
        // Two participants' trials may start at once: one writer at a time
        // (waiting, as this is short), and nothing written when nothing changed.
        let _guard = StudyLock::take(&self.data.join("schedule.lock"))?;
        if path.exists() {
            let old: Vec<ScheduleRecord> = read_json(&path)?;
            for (p, part) in self.study.participants.iter().enumerate() {
                let Some(before) = old.iter().find(|r| r.participant == part.id) else { continue };
                let began = load_state(&self.participant_dir(p))?.is_some_and(|s| !s.attempts.is_empty());
                if !began {
                    continue;
                }
                let now = ScheduleRecord::of(self, p);
                if let Some(what) = before.first_difference(&now) {
                    return Err(StudyError::Changed { id: part.id.clone(), what, copy });
                }
            }
        }
        let records: Vec<ScheduleRecord> = (0..self.study.participants.len()).map(|p| ScheduleRecord::of(self, p)).collect();
        let unchanged = path.exists() && read_json::<Vec<ScheduleRecord>>(&path).is_ok_and(|old| old == records);
        if !unchanged {
            write_json(&path, &records)?;
        }
        if std::fs::read_to_string(&copy).ok().as_deref() != Some(self.text.as_str()) {
            write_whole(&copy, self.text.as_bytes())?;
        }
        Ok(path)
    }
}

/// One input file of the study (the study file, a condition's scenario
/// file, the capture) as it was at the study's first trial.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputPrint {
    /// What it is to the study: `study file`, `condition NAME`, `capture`.
    pub what: String,
    pub path: String,
    pub bytes: u64,
    /// The 64-bit FNV-1a hash of its bytes, hex.
    pub fnv1a: String,
}

/// The study's inputs at its first trial (`DATA/inputs.json`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Inputs {
    pub recorded_utc: String,
    pub files: Vec<InputPrint>,
}

impl OpenStudy {
    /// The study's input files now: the study file (as read), each
    /// condition's scenario file, the capture.
    pub fn input_prints(&self) -> Vec<InputPrint> {
        let print = |what: String, path: &Path, bytes: Option<Vec<u8>>| {
            let bytes = bytes.unwrap_or_default();
            InputPrint {
                what,
                path: path.display().to_string(),
                bytes: bytes.len() as u64,
                fnv1a: format!("{:016x}", super::schedule::fnv1a(&bytes)),
            }
        };
        let dir = self.file.parent().map(Path::to_path_buf).unwrap_or_default();
        let mut files = vec![print("study file".into(), &self.file, Some(self.text.as_bytes().to_vec()))];
        for c in &self.study.conditions {
            if let ConditionSource::File(f) = &c.source {
                let path = dir.join(f);
                files.push(print(format!("condition `{}`", c.name), &path, std::fs::read(&path).ok()));
            }
        }
        if let Some(c) = &self.capture {
            files.push(print("capture".into(), c, std::fs::read(c).ok()));
        }
        files
    }

    /// Records the inputs' prints and the study file's text
    /// (`DATA/study-at-first-trial.toml`) before the study's first trial;
    /// later calls keep what the first recorded.
    pub fn record_inputs(&self) -> Result<(), StudyError> {
        let path = self.data.join("inputs.json");
        let _guard = StudyLock::take(&self.data.join("schedule.lock"))?;
        if path.exists() {
            return Ok(());
        }
        write_whole(&self.data.join("study-at-first-trial.toml"), self.text.as_bytes())?;
        write_json(&path, &Inputs { recorded_utc: now_utc(), files: self.input_prints() })
    }

    /// The input files that changed since the study's first trial, in
    /// words naming each; empty before the first trial.
    pub fn changed_inputs(&self) -> Result<Vec<String>, StudyError> {
        let path = self.data.join("inputs.json");
        if !path.exists() {
            return Ok(Vec::new());
        }
        let then: Inputs = read_json(&path)?;
        let now = self.input_prints();
        let mut changed = Vec::new();
        for before in &then.files {
            match now.iter().find(|n| n.what == before.what) {
                Some(n) if n.bytes == before.bytes && n.fnv1a == before.fnv1a => {}
                Some(n) => changed.push(format!(
                    "the {} {} changed after participants began (at the first trial, {}: {} bytes, FNV-1a {}; now {} bytes, FNV-1a {}){}",
                    before.what,
                    n.path,
                    then.recorded_utc,
                    before.bytes,
                    before.fnv1a,
                    n.bytes,
                    n.fnv1a,
                    if before.what == "study file" {
                        format!("; as it was: {}", self.data.join("study-at-first-trial.toml").display())
                    } else {
                        String::new()
                    },
                )),
                None => changed.push(format!("the {} {} of the first trial ({}) is no longer the study's", before.what, before.path, then.recorded_utc)),
            }
        }
        for n in now.iter().filter(|n| !then.files.iter().any(|b| b.what == n.what)) {
            changed.push(format!("the {} {} was added after participants began ({})", n.what, n.path, then.recorded_utc));
        }
        Ok(changed)
    }
}

/// One participant's schedule as `schedule.json` keeps it (names, not
/// indices, so a reordered file is still compared trial by trial).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ScheduleRecord {
    pub participant: String,
    pub square_row: Option<usize>,
    pub blocks: Vec<String>,
    pub trials: Vec<TrialRecord>,
    pub questionnaires: Vec<String>,
}

/// One trial of a [`ScheduleRecord`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TrialRecord {
    pub trial: u32,
    pub block: String,
    pub condition: String,
    pub repetition: u32,
    pub seed: u64,
}

impl ScheduleRecord {
    /// Participant `p`'s record.
    pub fn of(s: &OpenStudy, p: usize) -> ScheduleRecord {
        let sch = &s.schedules[p];
        ScheduleRecord {
            participant: s.study.participants[p].id.clone(),
            square_row: sch.square_row,
            blocks: sch.blocks.iter().map(|&b| s.study.blocks[b].name.clone()).collect(),
            trials: sch
                .trials
                .iter()
                .map(|t| TrialRecord {
                    trial: t.number,
                    block: s.study.blocks[t.block].name.clone(),
                    condition: s.study.conditions[t.condition].name.clone(),
                    repetition: t.repetition,
                    seed: t.seed,
                })
                .collect(),
            questionnaires: sch.due.iter().map(Due::key).collect(),
        }
    }

    fn first_difference(&self, now: &ScheduleRecord) -> Option<String> {
        for (a, b) in self.trials.iter().zip(&now.trials) {
            if a != b {
                return Some(format!(
                    "trial {} was {} ({}, seed {}) and would now be {} ({}, seed {})",
                    a.trial, a.condition, a.block, a.seed, b.condition, b.block, b.seed
                ));
            }
        }
        if self.trials.len() != now.trials.len() {
            return Some(format!("{} trials before, {} now", self.trials.len(), now.trials.len()));
        }
        (self.questionnaires != now.questionnaires)
            .then(|| format!("questionnaires {} before, {} now", self.questionnaires.join(" "), now.questionnaires.join(" ")))
    }
}


/// Reads a JSON file of at most 256 MiB.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, StudyError> {
    let bytes = crate::load::read_regular(path, MAX_JSON_BYTES).map_err(|problem| StudyError::Read { path: path.into(), problem })?;
    serde_json::from_slice(&bytes).map_err(|e| StudyError::Read { path: path.into(), problem: format!("not the JSON expected: {e}") })
}

/// Writes `value` as pretty JSON, whole.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), StudyError> {
    let mut text = serde_json::to_string_pretty(value).expect("study records serialize");
    text.push('\n');
    write_whole(path, text.as_bytes())?;
    Ok(())
}

/// The current time, RFC 3339 (UTC, seconds).
pub fn now_utc() -> String {
    humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string()
}
