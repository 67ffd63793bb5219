//! Running a participant's next trial, marking it, and reading its figures.
//!
//! A trial is a `netfi run` child process with the trial's condition, its
//! seed, and `--out DATA/P/trial-NN-CONDITION/`. The attempt is recorded
//! `running` before the child starts, under the participant's lock. The
//! child gets its own process group (a Ctrl-C at the terminal reaches only
//! the runner, which passes one SIGINT on, so the run stops as Ctrl-C
//! stops it and writes its report) and is told to stop (SIGTERM) if its
//! runner dies (`PR_SET_PDEATHSIG`), so no run outlives the trial it
//! belongs to.

use super::file::{ConditionSource, TrialSpec, MAX_COUNT};
use std::collections::BTreeMap;
use super::metrics::{figures, Figures, TraceFigures, TraceFrame, METRICS};
use super::questionnaire;
use super::schedule::Due;
use crate::service::args::{self, RunArgs};
use super::store::{claim, now_utc, read_json, save_state, write_json, Attempt, AttemptState, Next, OpenStudy, StudyError};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

/// A trial's figures as `figures.json` keeps them.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FiguresFile {
    /// Metric name → value (null where the run gave none).
    pub figures: std::collections::BTreeMap<String, Option<f64>>,
}

impl FiguresFile {
    /// In [`METRICS`]' order.
    pub fn ordered(&self) -> Figures {
        METRICS.iter().map(|m| self.figures.get(m.name).copied().flatten()).collect()
    }
}

/// The run id of an attempt: unique to the study's data folder, the
/// participant, the trial and the attempt, and ending in 8 hex digits from
/// the kernel's random generator: the rest can be told from a running
/// study's command lines, and another user who knew the whole could take
/// the run's names (its shared-memory files) first and so block the
/// trial. iceoryx2's names: at most 48 characters of `[A-Za-z0-9_-]`.
pub fn run_id(s: &OpenStudy, p: usize, trial: u32, attempt: u32) -> String {
    let key = super::schedule::fnv1a(format!("{}\0{}", s.data.display(), s.study.participants[p].id).as_bytes());
    run_id_of(key, trial, attempt, unguessable())
}

/// `study-` and 10 hex digits of `key` (40 bits: the data folder and the
/// participant), the trial and attempt, 8 random hex digits: at most 48
/// characters whatever the numbers.
fn run_id_of(key: u64, trial: u32, attempt: u32, random: u32) -> String {
    format!("study-{:010x}-t{trial:03}a{attempt}-{random:08x}", key & 0xff_ffff_ffff)
}

/// 32 bits from the kernel's random generator (`getrandom(2)`); where it
/// cannot give them, from a hasher keyed by it (std's `RandomState`).
fn unguessable() -> u32 {
    let mut b = [0u8; 4];
    // SAFETY: getrandom writes at most `b.len()` bytes into `b`.
    let n = unsafe { libc::getrandom(b.as_mut_ptr().cast(), b.len(), 0) };
    if n == b.len() as isize {
        return u32::from_ne_bytes(b);
    }
    use std::hash::BuildHasher;
    std::collections::hash_map::RandomState::new().hash_one(std::process::id()) as u32
}

/// What to tell the experimenter when no trial can start.
fn refusal(s: &OpenStudy, p: usize, next: &Next) -> String {
    let id = &s.study.participants[p].id;
    let file = s.file.display();
    match next {
        Next::Running(a) => format!("trial {} of `{id}` is running (pid {})", a.trial, a.runner_pid.unwrap_or(0)),
        Next::Unmarked(a) => format!(
            "trial {} of `{id}` ({}) ran and waits for its mark: `netfi study mark {file} --participant {id} done|failed|repeat`",
            a.trial, a.condition
        ),
        Next::Questionnaire(Due::Sus) => format!(
            "the System Usability Scale of `{id}` is due before trial 1: `netfi study answer {file} --participant {id} sus ITEM…` (ten answers 1–5), or `--missing REASON`"
        ),
        Next::Questionnaire(Due::Tlx { after, .. }) => format!(
            "the NASA-TLX of `{id}` after trial {after} is due: `netfi study answer {file} --participant {id} tlx MENTAL PHYSICAL TEMPORAL PERFORMANCE EFFORT FRUSTRATION` (0–100 each{}), or `--missing REASON`",
            if s.study.questionnaires.tlx_weighting == super::file::TlxWeighting::Pairwise { ", and `--pairs` with the scale chosen in each of the 15 pairs" } else { "" }
        ),
        Next::Finished => format!("`{id}` has finished every trial"),
        Next::Trial { .. } => String::new(),
    }
}

/// The participant's next step now (without taking their lock).
pub fn peek(s: &OpenStudy, p: usize) -> Result<Next, StudyError> {
    let state = super::store::load_state(&s.participant_dir(p))?.unwrap_or_default();
    Ok(super::store::next_step(s, p, &state, &questionnaire::answered(s, p)))
}

/// Runs participant `p`'s next trial with the `netfi` executable, until
/// it ends or `stop()` turns true (then the run is stopped as Ctrl-C
/// stops it, and the attempt is `stopped`). `started` is told the attempt
/// once its run is started. Returns the attempt as recorded.
pub fn run_next(s: &OpenStudy, p: usize, netfi: &Path, stop: impl Fn() -> bool, started: impl FnOnce(&Attempt)) -> Result<Attempt, StudyError> {
    s.record_schedules()?;
    s.record_inputs()?;
    let (lock, mut state) = claim(s, p, "netfi study next")?;
    let next = super::store::next_step(s, p, &state, &questionnaire::answered(s, p));
    let Next::Trial { trial, attempt } = next else { return Err(StudyError::State(refusal(s, p, &next))) };
    let dir = s.participant_dir(p);
    let condition = &s.study.conditions[trial.condition];
    let name = s.trial_dir_name(&trial, attempt);
    let out = dir.join(&name);
    std::fs::create_dir_all(&out).map_err(|source| StudyError::Io { path: out.clone(), source })?;
    let scenario = scenario_arg(s, &condition.source, &out)?;
    let mut a = Attempt {
        trial: trial.number,
        attempt,
        condition: condition.name.clone(),
        dir: name,
        state: AttemptState::Running,
        seed: trial.seed,
        started_utc: now_utc(),
        ended_utc: None,
        runner_pid: Some(std::process::id()),
        run_pid: None,
        run_id: Some(run_id(s, p, trial.number, attempt)),
        run_status: None,
        stopped: false,
        report: false,
        faults: Vec::new(),
        note: String::new(),
        counts: Default::default(),
        waiting_for: None,
        console_came_s: None,
    };
    state.attempts.push(a.clone());
    save_state(&dir, &state)?;
    let (mut cmd, run) = run_command(s, netfi, &scenario, &out, trial.seed, a.run_id.as_deref().expect("set above"))?;
    let mut child = match cmd.spawn() {
        Ok(c) => c,
        Err(e) => {
            let last = state.attempts.last_mut().expect("pushed above");
            last.state = AttemptState::Ran;
            last.faults = vec![format!("starting {}: {e}", netfi.display())];
            last.ended_utc = Some(now_utc());
            last.runner_pid = None;
            save_state(&dir, &state)?;
            return Err(StudyError::State(format!("starting {}: {e}", netfi.display())));
        }
    };
    a.run_pid = Some(child.id());
    let mut watch = s.study.trial.lab().then(|| LabWatch::new(&run, &out, s.study.trial.peer_wait_s));
    if let Some(w) = &watch {
        a.waiting_for = w.waiting_for.clone();
    }
    *state.attempts.last_mut().expect("pushed above") = a.clone();
    save_state(&dir, &state)?;
    let running = s.data.join(RUNNING_FILE);
    let _ = write_json(&running, &Running { participant: s.study.participants[p].id.clone(), trial: a.trial, attempt: a.attempt, condition: a.condition.clone(), run_id: a.run_id.clone(), dir: out.clone(), started_utc: a.started_utc.clone() });
    started(&a);
    let mut seen = |w: &LabWatch| {
        // The page and `status` show whom the trial waits for.
        let last = state.attempts.last_mut().expect("pushed above");
        if last.waiting_for != w.waiting_for {
            last.waiting_for = w.waiting_for.clone();
            last.console_came_s = w.console_came_s;
            let _ = save_state(&dir, &state);
        }
    };
    let waited = wait(&mut child, &out, stop, watch.as_mut(), &mut seen);
    let _ = std::fs::remove_file(&running);
    let (status, asked) = waited?;
    finish(&mut a, &out, status, asked);
    if let Some(w) = &watch {
        a.waiting_for = None;
        a.console_came_s = w.console_came_s;
        lab_outcome(&mut a, &out, w);
    }
    *state.attempts.last_mut().expect("pushed above") = a.clone();
    save_state(&dir, &state)?;
    lock.release();
    Ok(a)
}

/// The file naming the trial running now (the last started), for the
/// lab's programs: its run id (their iceoryx2 names), participant, trial
/// and folder. Written when the trial starts, removed when it ends.
pub const RUNNING_FILE: &str = "running.json";

/// What [`RUNNING_FILE`] holds.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Running {
    pub participant: String,
    pub trial: u32,
    pub attempt: u32,
    pub condition: String,
    pub run_id: Option<String>,
    pub dir: PathBuf,
    pub started_utc: String,
}

/// How long a trial waits for the lab's console's first frame when the
/// study does not say (`[trial] peer_wait_s`), s.
pub const LAB_CONSOLE_WAIT_S: f64 = args::run::LAB_ROBOT_WAIT_S;

/// Whom a trial waits for before its emulator has opened its ports (a
/// console that sends before then sends into nothing).
const STARTING: &str = "netfi's emulator to open its ports";

/// A trial with the lab's programs, watched while it runs: whom it waits
/// for, when the console came, and a peer found dead (the run's log says
/// so), which ends the trial.
struct LabWatch {
    out: PathBuf,
    /// Whom the trial waits for now.
    waiting_for: Option<String>,
    robot: Option<String>,
    console: String,
    console_wait: Duration,
    console_came_s: Option<f64>,
    started: std::time::Instant,
    next_look: std::time::Instant,
    stderr_read: usize,
    /// Why the trial is interrupted, once it is.
    interrupted: Option<String>,
}

impl LabWatch {
    fn new(run: &RunArgs, out: &Path, console_wait_s: Option<f64>) -> LabWatch {
        let p = &run.peers;
        let ros2 = p.ros2.on();
        let console = if ros2 { "the ROS 2 topics".to_string() } else { p.ends.ingress.to_string() };
        let robot_subscribes = p.robot() == args::Peer::Lab && !ros2 && p.ends.egress.of::<crate::transport::ipc::Iceoryx2>().is_some();
        let robot = robot_subscribes.then(|| format!("the lab's robot at {}", p.ends.egress));
        let now = std::time::Instant::now();
        LabWatch {
            out: out.to_path_buf(),
            waiting_for: Some(robot.clone().unwrap_or_else(|| STARTING.to_string())),
            robot,
            console,
            console_wait: Duration::from_secs_f64(console_wait_s.unwrap_or(LAB_CONSOLE_WAIT_S)),
            console_came_s: None,
            started: now,
            next_look: now,
            stderr_read: 0,
            interrupted: None,
        }
    }

    /// Looks at the trial's folder (4 times a second); whether the run
    /// must be stopped (a peer died, or the console never came).
    fn look(&mut self) -> bool {
        let now = std::time::Instant::now();
        if now < self.next_look || self.interrupted.is_some() {
            return false;
        }
        self.next_look = now + Duration::from_millis(250);
        // The run's log names a peer that died (the runner reaps the
        // run's dead iceoryx2 peers).
        if let Ok(text) = std::fs::read_to_string(self.out.join("run.stderr")) {
            let new = text.get(self.stderr_read..).unwrap_or_default();
            if let Some(line) = new.lines().find(|l| l.contains("reaped a dead peer") || l.contains("a peer died")) {
                self.interrupted = Some(format!("a peer died mid-trial ({})", line.trim()));
                return true;
            }
            // A line still being written is read again whole next time.
            self.stderr_read = text.rfind('\n').map_or(0, |i| i + 1).max(self.stderr_read);
        }
        let ready = self.out.join("emulator.ready").exists();
        if self.console_came_s.is_none() && ready && trace_has_rows(&self.out) {
            self.console_came_s = Some(self.started.elapsed().as_secs_f64());
        }
        self.waiting_for = match (&self.robot, ready, self.console_came_s) {
            (Some(r), false, _) => Some(r.clone()),
            (None, false, _) => Some(STARTING.to_string()),
            (_, true, None) => Some(format!("the lab's console at {}", self.console)),
            _ => None,
        };
        if ready && self.console_came_s.is_none() && self.started.elapsed() > self.console_wait + Duration::from_secs(1) {
            self.interrupted = Some(format!("the lab's console sent nothing to {} within {} s", self.console, self.console_wait.as_secs_f64()));
            return true;
        }
        false
    }
}

/// Whether a trace of the run (of any of its lanes) has a row: a frame of
/// the console's reached the emulator.
fn trace_has_rows(out: &Path) -> bool {
    let rows = |dir: &Path| {
        ["trace_emulator.csv.partial", "trace_emulator.csv"].iter().any(|n| {
            std::fs::read(dir.join(n)).is_ok_and(|b| b.iter().filter(|c| **c == b'\n').count() >= 2)
        })
    };
    rows(out) || std::fs::read_dir(out).into_iter().flatten().flatten().any(|e| e.path().is_dir() && rows(&e.path()))
}

/// A lab trial's outcome: `interrupted`, with the reason, when a peer was
/// absent, died or was of the wrong type; never counted.
fn lab_outcome(a: &mut Attempt, out: &Path, w: &LabWatch) {
    let why = w.interrupted.clone().or_else(|| {
        if a.state == AttemptState::Interrupted {
            return None;
        }
        if !a.report {
            // The run refused or lost a peer before it could report
            // (the robot did not come; a peer of the wrong type).
            return Some(format!("the run ended without a report: {}", a.faults.first().cloned().unwrap_or_default()));
        }
        let r: serde_json::Value = read_json(&out.join("report.json")).ok()?;
        let entered = r.pointer("/frames/entered").and_then(serde_json::Value::as_u64).or_else(|| ros2_entered(&r));
        let bad = r.pointer("/emulator/frames/bad_input").and_then(serde_json::Value::as_object).map_or(0, |b| b.values().filter_map(serde_json::Value::as_u64).sum::<u64>());
        match entered {
            Some(0) if bad > 0 => Some(format!("the lab's console sent {bad} datagrams, none an ITP frame (wrong size, or bad flags): a peer of the wrong type")),
            Some(0) => Some(format!("the lab's console sent nothing to {}", w.console)),
            _ => None,
        }
    });
    if let Some(why) = why {
        a.state = AttemptState::Interrupted;
        a.note = why;
    }
}

/// Messages that entered a ROS 2 run's lanes, summed.
fn ros2_entered(r: &serde_json::Value) -> Option<u64> {
    let lanes = r.get("ros2")?.get("lanes")?.as_array()?;
    Some(lanes.iter().filter_map(|l| l.pointer("/frames/entered").and_then(serde_json::Value::as_u64)).sum())
}

/// What `netfi run` is given as the condition's scenario: a preset's name,
/// a file's absolute path, or inline stages written into the trial's folder.
fn scenario_arg(s: &OpenStudy, source: &ConditionSource, out: &Path) -> Result<String, StudyError> {
    Ok(match source {
        ConditionSource::Preset(p) => p.to_string(),
        ConditionSource::File(f) => absolute(&s.file.parent().unwrap_or(Path::new(".")).join(f)).display().to_string(),
        ConditionSource::Inline(text) => {
            let path = out.join("condition.toml");
            crate::durable::write_whole(&path, text.as_bytes())?;
            absolute(&path).display().to_string()
        }
    })
}

/// A trial's `netfi run` of `scenario`: the study file's (its trial spec,
/// the capture resolved) and what the study sets for each trial
/// ([`super::file::STUDY_RUN_ARGS`]): its output in `out`, its seed, its
/// run id, a JSON report.
fn trial_run(spec: &TrialSpec, scenario: &str, capture: Option<&Path>, out: &Path, seed: u64, run_id: &str) -> Result<RunArgs, StudyError> {
    // The file's `run_args` were read as `netfi run` reads them when the
    // study was opened.
    let mut run = spec.run(scenario, capture).map_err(|e| StudyError::State(format!("trial.run_args: {}", args::refusal(&e))))?;
    run.out = Some(absolute(out));
    run.scenario.seed = Some(seed);
    run.run_id = Some(run_id.to_string());
    run.json = true;
    Ok(run)
}

/// The trial's `netfi run`: its own process group, its output in `out`,
/// stopped (SIGTERM) if its runner dies; and the run it starts.
fn run_command(s: &OpenStudy, netfi: &Path, scenario: &str, out: &Path, seed: u64, run_id: &str) -> Result<(Command, RunArgs), StudyError> {
    let capture = s.capture.as_deref().map(absolute);
    let run = trial_run(&s.study.trial, scenario, capture.as_deref(), out, seed, run_id)?;
    let mut cmd = Command::new(netfi);
    cmd.arg("run").args(run.to_argv());
    let file = |n: &str| crate::durable::create_fresh(&out.join(n)).map_err(|source| StudyError::Io { path: out.join(n), source });
    cmd.stdin(Stdio::null()).stdout(file("run.stdout")?).stderr(file("run.stderr")?).process_group(0);
    // SAFETY: prctl is async-signal-safe; it only sets this child's parent-death signal.
    unsafe {
        cmd.pre_exec(|| {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    Ok((cmd, run))
}

/// Waits for the run to end, passing one SIGINT on once `stop()` turns
/// true; how it ended, and whether it was asked to stop.
fn wait(
    child: &mut std::process::Child,
    out: &Path,
    stop: impl Fn() -> bool,
    mut watch: Option<&mut LabWatch>,
    seen: &mut impl FnMut(&LabWatch),
) -> Result<(std::process::ExitStatus, bool), StudyError> {
    let mut asked = false;
    loop {
        match child.try_wait() {
            Ok(Some(status)) => return Ok((status, asked)),
            Ok(None) => {}
            Err(e) => return Err(StudyError::Io { path: out.to_path_buf(), source: e }),
        }
        let lab_ends = watch.as_deref_mut().is_some_and(|w| {
            let end = w.look();
            seen(w);
            end
        });
        if lab_ends && !asked {
            // A peer died or never came: the run is stopped as Ctrl-C
            // stops it, and the trial is interrupted (not `stopped`).
            // SAFETY: signalling our own child, not yet reaped.
            unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
        }
        if stop() && !asked {
            asked = true;
            // SAFETY: signalling our own child, not yet reaped.
            unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Records how the run ended: its report and figures if it left one;
/// `interrupted` if it was killed without one.
fn finish(a: &mut Attempt, out: &Path, status: std::process::ExitStatus, asked: bool) {
    a.runner_pid = None;
    a.ended_utc = Some(now_utc());
    a.stopped = asked;
    a.run_status = Some(match (status.code(), status.signal()) {
        (Some(c), _) => format!("exit {c}"),
        (None, Some(sig)) => format!("signal {sig}"),
        _ => format!("{status}"),
    });
    let report_path = out.join("report.json");
    a.report = report_path.is_file();
    let report: Option<serde_json::Value> = if a.report { read_json(&report_path).ok() } else { None };
    match &report {
        Some(r) => {
            a.state = AttemptState::Ran;
            a.faults = r.get("faults").and_then(|f| serde_json::from_value(f.clone()).ok()).unwrap_or_default();
            if let Ok(figs) = trial_figures(out, r) {
                let _ = write_json(&out.join("figures.json"), &figs);
            }
        }
        None if status.signal().is_some() => {
            a.state = AttemptState::Interrupted;
            a.note = format!("its run was killed ({}) and left no report", a.run_status.as_deref().unwrap_or("?"));
        }
        None => {
            a.state = AttemptState::Ran;
            let stderr = std::fs::read_to_string(out.join("run.stderr")).unwrap_or_default();
            let last = stderr.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no message").to_string();
            a.faults = vec![format!("the run left no report ({}): {last}", a.run_status.as_deref().unwrap_or("?"))];
        }
    }
}

/// A trial folder's figures: from its `report.json`, `trace.csv`, and the
/// `ros2.json` of each ROS 2 lane.
pub fn trial_figures(out: &Path, report: &serde_json::Value) -> Result<FiguresFile, StudyError> {
    let o = read_trace(&out.join("trace.csv"))?;
    let values = figures(report, &o, &ros2_lanes(out));
    Ok(FiguresFile { figures: METRICS.iter().zip(values).map(|(m, v)| (m.name.to_string(), v)).collect() })
}

/// The `ros2.json` of each ROS 2 lane of the run in `out`, in lane order
/// (one lane: in `out`; several: in its folders, by name).
fn ros2_lanes(out: &Path) -> Vec<serde_json::Value> {
    if let Ok(v) = read_json(&out.join("ros2.json")) {
        return vec![v];
    }
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(out).into_iter().flatten().flatten().map(|e| e.path()).filter(|p| p.join("ros2.json").is_file()).collect();
    dirs.sort();
    dirs.iter().filter_map(|d| read_json(&d.join("ros2.json")).ok()).collect()
}

/// The figures of a run's `trace.csv` (copies left out).
fn read_trace(path: &Path) -> Result<TraceFigures, StudyError> {
    use crate::trace::{Column, Header};
    use std::io::BufRead;
    let bad = |problem: String| StudyError::Read { path: path.to_path_buf(), problem };
    let f = match std::fs::File::open(path) {
        Ok(f) => f,
        // A run without a trace (a foreign layout) has no outage figures
        // to give; the count is then of nothing.
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(TraceFigures::default()),
        Err(e) => return Err(StudyError::Io { path: path.to_path_buf(), source: e }),
    };
    let mut lines = std::io::BufReader::new(f).lines();
    let header = lines.next().transpose().map_err(|e| bad(e.to_string()))?.unwrap_or_default();
    let cols = Header::parse(&header);
    let col = |c: Column| cols.get(c).ok_or_else(|| bad(format!("no `{c}` column")));
    let (ix, ns, reason, copy) = (col(Column::IngressIndex)?, col(Column::IngressNs)?, col(Column::Reason)?, col(Column::Copy)?);
    let mut frames = Vec::new();
    for (k, line) in lines.enumerate() {
        let line = line.map_err(|e| bad(e.to_string()))?;
        let f: Vec<&str> = line.split(',').collect();
        let num = |i: usize, c: Column| f.get(i).and_then(|v| v.parse::<u64>().ok()).ok_or_else(|| bad(format!("line {}: column {c} is not a number", k + 2)));
        if f.get(copy).is_some_and(|c| *c != "0" && !c.is_empty()) {
            continue;
        }
        frames.push(TraceFrame { ingress_index: num(ix, Column::IngressIndex)?, ingress_ns: num(ns, Column::IngressNs)?, outage: f.get(reason) == Some(&"outage") });
    }
    Ok(TraceFigures::of(frames))
}

fn absolute(p: &Path) -> PathBuf {
    std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf())
}

/// How the experimenter marks an attempt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mark {
    Done,
    Failed,
    Repeat,
}

/// Marks participant `p`'s attempt (the last of trial `trial`, or the one
/// waiting for its mark) `done`, `failed` or `repeat`, with a note.
pub fn mark(s: &OpenStudy, p: usize, trial: Option<u32>, how: Mark, note: &str) -> Result<Attempt, StudyError> {
    mark_counting(s, p, trial, how, note, &BTreeMap::new())
}

/// As [`mark`], recording the study's `[[measure]]`s the experimenter
/// counted in the trial (`counts`: by measure name).
pub fn mark_counting(s: &OpenStudy, p: usize, trial: Option<u32>, how: Mark, note: &str, counts: &BTreeMap<String, u32>) -> Result<Attempt, StudyError> {
    check_counts(s, counts)?;
    let (lock, mut state) = claim(s, p, "netfi study mark")?;
    let id = &s.study.participants[p].id;
    let index = match trial {
        Some(n) => state.attempts.iter().rposition(|a| a.trial == n).ok_or_else(|| StudyError::State(format!("trial {n} of `{id}` has not run")))?,
        None => state
            .attempts
            .iter()
            .rposition(|a| a.state == AttemptState::Ran)
            .ok_or_else(|| StudyError::State(format!("no trial of `{id}` waits for its mark (give --trial N to change one)")))?,
    };
    let a = &mut state.attempts[index];
    match a.state {
        AttemptState::Running => return Err(StudyError::State(format!("trial {} of `{id}` is still running", a.trial))),
        AttemptState::Interrupted => {
            return Err(StudyError::State(format!("trial {} of `{id}` was interrupted: it is run again by the next `netfi study next`", a.trial)))
        }
        _ => {}
    }
    if how == Mark::Done && !a.report {
        return Err(StudyError::State(format!(
            "trial {} of `{id}` left no run report, so it has no figures to count: mark it repeat or failed",
            a.trial
        )));
    }
    a.state = match how {
        Mark::Done => AttemptState::Done,
        Mark::Failed => AttemptState::Failed,
        Mark::Repeat => AttemptState::Repeat,
    };
    if !note.is_empty() {
        a.note = note.to_string();
    }
    a.counts.extend(counts.iter().map(|(k, v)| (k.clone(), *v)));
    let marked = a.clone();
    save_state(&s.participant_dir(p), &state)?;
    lock.release();
    Ok(marked)
}

/// Refuses a count of no `[[measure]]` of the study, or beyond [`MAX_COUNT`].
fn check_counts(s: &OpenStudy, counts: &BTreeMap<String, u32>) -> Result<(), StudyError> {
    for (name, v) in counts {
        if s.study.measure(name).is_none() {
            let known: Vec<&str> = s.study.measures.iter().map(|m| m.name.as_str()).collect();
            let known = if known.is_empty() { "none: declare it as a `[[measure]]` of the study file".to_string() } else { known.join(", ") };
            return Err(StudyError::State(format!("`{name}` is no measure of this study (its measures: {known})")));
        }
        if *v > MAX_COUNT {
            return Err(StudyError::State(format!("{name} = {v}: a count is 0 to {MAX_COUNT}")));
        }
    }
    Ok(())
}

/// Records the study's `[[measure]]`s counted in participant `p`'s trial
/// (the last attempt of `trial`, or the last that ran), without changing
/// its mark. Returns the attempt as recorded.
pub fn count(s: &OpenStudy, p: usize, trial: Option<u32>, counts: &BTreeMap<String, u32>) -> Result<Attempt, StudyError> {
    check_counts(s, counts)?;
    let (lock, mut state) = claim(s, p, "netfi study count")?;
    let id = &s.study.participants[p].id;
    let index = match trial {
        Some(n) => state.attempts.iter().rposition(|a| a.trial == n).ok_or_else(|| StudyError::State(format!("trial {n} of `{id}` has not run")))?,
        None => state
            .attempts
            .iter()
            .rposition(|a| a.state != AttemptState::Running && a.state != AttemptState::Interrupted)
            .ok_or_else(|| StudyError::State(format!("no trial of `{id}` has run")))?,
    };
    let a = &mut state.attempts[index];
    if matches!(a.state, AttemptState::Running | AttemptState::Interrupted) {
        return Err(StudyError::State(format!("trial {} of `{id}` is {}: count what a trial that ran shows", a.trial, a.state.as_str())));
    }
    a.counts.extend(counts.iter().map(|(k, v)| (k.clone(), *v)));
    let counted = a.clone();
    save_state(&s.participant_dir(p), &state)?;
    lock.release();
    Ok(counted)
}

/// `NAME=COUNT` words as the command line gives them.
pub fn parse_counts(words: &[String]) -> Result<BTreeMap<String, u32>, String> {
    let mut out = BTreeMap::new();
    for w in words {
        let (k, v) = w.split_once('=').ok_or_else(|| format!("`{w}`: write a count as NAME=COUNT (e.g. drops=2)"))?;
        let v: u32 = v.trim().parse().map_err(|_| format!("`{w}`: a count is a whole number ≥ 0"))?;
        if out.insert(k.trim().to_string(), v).is_some() {
            return Err(format!("`{}` twice", k.trim()));
        }
    }
    Ok(out)
}

/// A trial folder's figures: `figures.json`, or computed from its report
/// (and written) if missing.
pub fn load_figures(out: &Path) -> Option<Figures> {
    let path = out.join("figures.json");
    if let Ok(f) = read_json::<FiguresFile>(&path) {
        return Some(f.ordered());
    }
    let report: serde_json::Value = read_json(&out.join("report.json")).ok()?;
    let figs = trial_figures(out, &report).ok()?;
    let _ = write_json(&path, &figs);
    Some(figs.ordered())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::file::STUDY_RUN_ARGS;

    #[test]
    fn an_attempts_run_id_is_a_valid_one_that_no_one_can_tell_ahead() {
        let longest = run_id_of(u64::MAX, u32::MAX, u32::MAX, u32::MAX);
        assert!(crate::transport::RunId::new(&longest).is_ok(), "{longest} ({} characters)", longest.len());
        // Equal by chance once in 2^32.
        assert_ne!(unguessable(), unguessable());
    }

    #[test]
    fn what_a_study_sets_for_each_trial_is_what_run_args_may_not_give() {
        let spec = TrialSpec { duration_s: Some(60.0), capture: Some("c.lz4".into()), rate_hz: Some(500.0), run_args: vec![], peers: Default::default(), lab_args: vec![], peer_wait_s: None };
        let run = trial_run(&spec, "PLM-1", Some(Path::new("/data/c.lz4")), Path::new("/data/P1/trial-01"), 3, "study-r1").unwrap();
        let cmd = RunArgs::command();
        let m = cmd.clone().try_get_matches_from(run.to_argv()).unwrap();
        let given: Vec<&str> = cmd.get_arguments().map(|a| a.get_id().as_str()).filter(|id| m.value_source(id) == Some(clap::parser::ValueSource::CommandLine)).collect();
        assert_eq!(given.len(), 8, "{given:?}");
        for id in given.iter().filter(|id| **id != "scenario") {
            assert!(STUDY_RUN_ARGS.iter().any(|(own, _)| own == id), "the study sets `{id}`, which `run_args` may give");
        }
        for (id, _) in STUDY_RUN_ARGS {
            assert!(cmd.get_arguments().any(|a| a.get_id() == id), "`{id}` is no argument of `netfi run`");
        }
        // What the file adds comes along, the study's own settings kept.
        let spec = TrialSpec { run_args: vec!["--no-isolate".into(), "--return-scenario".into(), "DLM-1".into()], ..spec };
        let with = trial_run(&spec, "PLM-1", Some(Path::new("/data/c.lz4")), Path::new("/data/P1/trial-01"), 3, "study-r1").unwrap();
        assert!(with.placement.no_isolate && with.channels.feedback.return_scenario.as_deref() == Some("DLM-1"));
        assert_eq!(RunArgs { placement: run.placement.clone(), channels: run.channels.clone(), ..with }, run);
    }
}
