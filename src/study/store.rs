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

use super::file::{ConditionSource, Study, StudyFileError};
use super::parse::parse_study;
use super::schedule::{schedule, Due, Schedule, Trial};
use crate::durable::{write_whole, DurableError};
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

/// The exclusive claim on a participant: an `flock` on `DATA/P/lock`,
/// held as long as this value lives (the kernel lets it go when the
/// process ends, however it ends). The file holds the holder's pid and
/// what it does, so a refused command can say who holds it.
#[derive(Debug)]
pub struct ParticipantLock {
    file: std::fs::File,
}

impl ParticipantLock {
    /// Takes the lock of the participant folder `dir` (created if need
    /// be) without waiting, saying what the holder does (`what`).
    pub fn take(dir: &Path, id: &str, what: &str) -> Result<ParticipantLock, StudyError> {
        use std::io::{Read, Seek, Write};
        use std::os::fd::AsRawFd;
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let path = dir.join("lock");
        let mut file =
            std::fs::OpenOptions::new().read(true).write(true).create(true).truncate(false).open(&path).map_err(io(&path))?;
        // SAFETY: flock on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let err = std::io::Error::last_os_error();
            if err.raw_os_error() == Some(libc::EWOULDBLOCK) {
                let mut text = String::new();
                let _ = file.read_to_string(&mut text);
                let holder = if text.trim().is_empty() { "another process".to_string() } else { text.trim().to_string() };
                return Err(StudyError::Busy { id: id.to_string(), holder, lock: path });
            }
            return Err(io(&path)(err));
        }
        let line = format!("pid {} ({what}, since {})\n", std::process::id(), now_utc());
        file.set_len(0).and_then(|_| file.rewind()).and_then(|_| file.write_all(line.as_bytes())).map_err(io(&path))?;
        Ok(ParticipantLock { file })
    }

    /// Lets the lock go and empties its file.
    pub fn release(self) {
        let _ = self.file.set_len(0);
    }
}

/// A short exclusive claim on a whole study's shared files, waited for.
struct StudyLock {
    _file: std::fs::File,
}

impl StudyLock {
    fn take(path: &Path) -> Result<StudyLock, StudyError> {
        use std::os::fd::AsRawFd;
        let file = std::fs::OpenOptions::new().write(true).create(true).truncate(false).open(path).map_err(io(path))?;
        // SAFETY: flock on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX) } != 0 {
            return Err(io(path)(std::io::Error::last_os_error()));
        }
        Ok(StudyLock { _file: file })
    }
}

/// Whether process `pid` is alive and its command line names `needle`.
pub fn process_names(pid: u32, needle: &str) -> bool {
    std::fs::read(format!("/proc/{pid}/cmdline")).is_ok_and(|c| String::from_utf8_lossy(&c).contains(needle))
}

/// Takes participant `p`'s lock and brings their state up to date: an
/// attempt still `running` had its runner die, and is `interrupted` (its
/// `netfi run`, if still stopping, is waited for: the trial's next attempt
/// must not share the emulator's core with it).
pub fn claim(s: &OpenStudy, p: usize, what: &str) -> Result<(ParticipantLock, ParticipantState), StudyError> {
    let dir = s.participant_dir(p);
    let id = &s.study.participants[p].id;
    let lock = ParticipantLock::take(&dir, id, what)?;
    let mut state = load_state(&dir)?.unwrap_or_else(|| ParticipantState { participant: id.clone(), attempts: Vec::new() });
    let mut changed = false;
    for a in state.attempts.iter_mut().filter(|a| a.state == AttemptState::Running) {
        if let Some(pid) = a.run_pid {
            let out = dir.join(&a.dir);
            let needle = out.display().to_string();
            let t0 = std::time::Instant::now();
            while process_names(pid, &needle) && t0.elapsed() < std::time::Duration::from_secs(60) {
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
        }
        a.state = AttemptState::Interrupted;
        a.report = dir.join(&a.dir).join("report.json").is_file();
        a.ended_utc = Some(now_utc());
        a.runner_pid = None;
        if a.note.is_empty() {
            a.note = "its runner ended while the trial was running".into();
        }
        changed = true;
    }
    if changed {
        save_state(&dir, &state)?;
    }
    Ok((lock, state))
}
