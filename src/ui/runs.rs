//! The runs the UI started: each a `netfi run` child process with its own
//! output directory (`<out>/<run id>/`), its input scenario beside it; and
//! the runs earlier servers left in the same parent directory, read from
//! their reports.

use super::UiOptions;
use super::UiError;
use crate::service::args::{refusal, RunArgs};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// The runs, by id.
pub(crate) struct Runs {
    runs: Mutex<BTreeMap<String, Run>>,
    next: AtomicU64,
    /// The CPU mask the server was started with: its runs get it back (the
    /// server itself keeps off the emulator's core).
    mask: CpuMask,
    /// The trials of the studies opened on the study page, by run id: their
    /// folders, read from their reports like runs earlier servers left.
    study: Mutex<BTreeMap<String, PathBuf>>,
}

/// A CPU affinity mask.
#[derive(Clone, Copy)]
pub(crate) struct CpuMask(libc::cpu_set_t);

impl CpuMask {
    /// This thread's mask.
    pub fn current() -> std::io::Result<CpuMask> {
        // SAFETY: a zeroed cpu_set_t is valid; the kernel fills it.
        let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
        // SAFETY: `set` is a valid cpu_set_t of the size given; pid 0 is this thread.
        if unsafe { libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) } != 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(CpuMask(set))
    }

    /// Gives `cmd`'s process this mask (between fork and exec).
    fn give(self, cmd: &mut Command) {
        use std::os::unix::process::CommandExt;
        let set = self.0;
        // SAFETY: sched_setaffinity is async-signal-safe; `set` is a copy owned by the closure.
        unsafe {
            cmd.pre_exec(move || {
                if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
}

struct Run {
    child: Child,
    out: PathBuf,
    scenario: String,
    duration_s: f64,
    started: Instant,
    /// Wall-clock start, s since the Unix epoch (for the list of runs).
    started_unix_s: u64,
    /// The exit status once seen.
    exit: Option<std::process::ExitStatus>,
    /// Its telemetry as it comes (until it ends).
    telemetry: Option<super::live::Telemetry>,
}

/// What a run's page shows.
#[derive(Debug, Serialize)]
pub(crate) struct Status {
    pub id: String,
    pub scenario: String,
    /// `running`; once ended, `done` (ran its course: every frame
    /// accounted for, no fault), `stopped` (stopped on request, every frame
    /// accounted for, no fault) or `failed`.
    pub state: &'static str,
    /// The state in words, for the page.
    pub state_said: String,
    pub elapsed_s: f64,
    pub duration_s: f64,
    /// Wall-clock start, s since the Unix epoch.
    pub started_unix_s: u64,
    pub out: String,
    /// The run's report (report.json), once written.
    pub report: Option<serde_json::Value>,
    /// The end of the run's standard error, once it failed without a
    /// report that says why.
    pub stderr_tail: Option<String>,
    /// The last telemetry interval as a table, and the plots over time.
    pub live: Option<String>,
    /// Whether this server started it (else: found in its directory).
    pub here: bool,
}

/// What starting a run needs: the scenario, and the options of `netfi
/// run` an experimenter sets.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Start {
    pub toml: String,
    pub duration_s: f64,
    pub seed: Option<u64>,
    /// Frames a second (`--rate-hz`).
    #[serde(default)]
    pub rate_hz: Option<f64>,
    /// The feedback path's scenario: a preset, or `none` for no feedback
    /// path (`--return-scenario`, `--no-feedback`).
    #[serde(default)]
    pub return_scenario: Option<String>,
    /// A video stream robot → console at this mean bit rate (`--video-mbps`)
    /// through this preset (`--video-scenario`).
    #[serde(default)]
    pub video_mbps: Option<f64>,
    #[serde(default)]
    pub video_scenario: Option<String>,
    /// A recorded capture on this host to replay (`--capture`).
    #[serde(default)]
    pub capture: Option<String>,
    /// Clear the emulator's core for the run (`--isolate`, the default;
    /// `false`: `--no-isolate`).
    #[serde(default)]
    pub isolate: Option<bool>,
}

/// What `netfi run` is given as the scenario until the run has its folder.
const SCENARIO_FILE: &str = "scenario.toml";

impl Start {
    /// The `netfi run` this start asks for (its scenario a stand-in, its
    /// own `--out` and `--run-id` not yet given). A choice that names no
    /// preset is an error saying which.
    fn run_args(&self) -> Result<RunArgs, UiError> {
        let preset = |what: &'static str, name: &str| match crate::scenario::canonical_name(name) {
            Some(_) => Ok(name.to_string()),
            None => Err(UiError::NotPreset { what, name: name.to_string() }),
        };
        let mut a = RunArgs::new(SCENARIO_FILE);
        a.source.duration_s = Some(self.duration_s);
        a.scenario.seed = self.seed;
        a.source.rate_hz = self.rate_hz;
        match self.return_scenario.as_deref() {
            None | Some("") => {}
            Some("none") => a.channels.feedback.no_feedback = true,
            Some(name) => a.channels.feedback.return_scenario = Some(preset("the return scenario", name)?),
        }
        if let Some(v) = self.video_mbps {
            a.channels.video.video_mbps = Some(v);
            if let Some(name) = self.video_scenario.as_deref().filter(|n| !n.is_empty()) {
                a.channels.video.video_scenario = Some(preset("the video scenario", name)?);
            }
        }
        if let Some(c) = self.capture.as_deref().map(str::trim).filter(|c| !c.is_empty()) {
            check_capture(c)?;
            a.source.capture = Some(PathBuf::from(c));
        }
        if self.isolate == Some(false) {
            a.placement.no_isolate = true;
        }
        Ok(a)
    }
}

/// Reads the capture `path` as the run's console will (a regular file, up
/// to the default record limit, checked whole), so that a capture the run
/// would refuse is refused before it starts, with the console's reason.
fn check_capture(path: &str) -> Result<(), UiError> {
    if !std::path::Path::new(path).exists() {
        return Err(UiError::NoCapture(path.to_string()));
    }
    crate::capture::load(path).map(drop).map_err(UiError::Capture)
}

/// Checks `run` as `netfi run` would read its argv, before any process
/// starts: the flags' ranges (clap's first paragraph), then the arguments'
/// own check.
fn check_run_args(run: &RunArgs) -> Result<(), UiError> {
    let parsed = RunArgs::from_argv(run.to_argv()).map_err(|e| UiError::RunOptions(refusal(&e)))?;
    parsed.validate()?;
    Ok(())
}

impl Runs {
    pub fn new(mask: CpuMask) -> Runs {
        Runs { runs: Mutex::default(), next: AtomicU64::new(0), mask, study: Mutex::default() }
    }

    /// Validates the scenario (the parser's own errors) and the options (as
    /// `netfi run` reads them) and starts `netfi run`; the run's id.
    pub fn start(&self, opts: &UiOptions, req: &Start) -> Result<String, UiError> {
        let scenario = crate::scenario::parse_str(&req.toml, "scenario", "scenario")?.name;
        if !(req.duration_s.is_finite() && req.duration_s > 0.0 && req.duration_s <= 86_400.0) {
            return Err(UiError::Duration(req.duration_s));
        }
        // A run started here may be switched to any scenario: its queue
        // keeps release-time order whatever its own scenario.
        let mut run = req.run_args()?;
        run.control.reorder_queue = true;
        check_run_args(&run)?;
        let id = format!("ui{}-{}", std::process::id(), self.next.fetch_add(1, Ordering::Relaxed) + 1);
        let out = opts.out_dir.join(&id);
        std::fs::create_dir_all(&out).map_err(|e| UiError::Create { path: out.clone(), cause: e })?;
        let input = out.join("scenario.input.toml");
        crate::durable::write_whole(&input, req.toml.as_bytes()).map_err(|e| UiError::Write { path: input.clone(), cause: std::io::Error::other(e) })?;
        let log = |name: &str| {
            let p = out.join(name);
            crate::durable::create_fresh(&p).map_err(|e| UiError::Create { path: p, cause: e })
        };
        let mut cmd = Command::new(&opts.netfi);
        run.scenario.scenario = input.display().to_string();
        run.out = Some(out.clone());
        run.run_id = Some(id.clone());
        cmd.arg("run").args(run.to_argv());
        self.mask.give(&mut cmd);
        let child = cmd
            .stdin(Stdio::null())
            .stdout(log("run.stdout")?)
            .stderr(log("run.stderr")?)
            .spawn()
            .map_err(|e| UiError::Spawn { path: opts.netfi.clone(), cause: e })?;
        let telemetry = super::live::Telemetry::follow(&opts.netfi, &id).ok();
        let started_unix_s = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
        let run = Run {
            child,
            out,
            scenario,
            duration_s: req.duration_s,
            started: Instant::now(),
            started_unix_s,
            exit: None,
            telemetry,
        };
        self.runs.lock().expect("runs lock").insert(id.clone(), run);
        Ok(id)
    }

    /// Where the run `id` writes: a run this server started, or one an
    /// earlier server left in `parent` (its directory holds a report).
    pub fn out_dir(&self, parent: &Path, id: &str) -> Option<PathBuf> {
        if let Some(r) = self.runs.lock().expect("runs lock").get(id) {
            return Some(r.out.clone());
        }
        past_run_dir(parent, id).or_else(|| self.study_dir(id))
    }

    /// Makes a study's trials runs of this server (their run ids and
    /// folders): listed in `/runs`, each with its page and report.
    pub fn add_study_runs(&self, trials: impl IntoIterator<Item = (String, PathBuf)>) {
        self.study.lock().expect("study runs lock").extend(trials);
    }

    /// A study trial's folder, once it holds a report.
    fn study_dir(&self, id: &str) -> Option<PathBuf> {
        self.study.lock().expect("study runs lock").get(id).filter(|d| d.join("report.json").is_file()).cloned()
    }

    /// Whether the run `id` is one this server started and still going.
    pub fn is_running(&self, id: &str) -> bool {
        self.status_here(id).is_some_and(|s| s.state == "running")
    }

    /// The run's state now: one this server started, or one an earlier
    /// server left in `parent`.
    pub fn status(&self, parent: &Path, id: &str) -> Option<Status> {
        self.status_here(id).or_else(|| past_status(parent, id)).or_else(|| past_status_in(&self.study_dir(id)?, id))
    }

    fn status_here(&self, id: &str) -> Option<Status> {
        let mut runs = self.runs.lock().expect("runs lock");
        let run = runs.get_mut(id)?;
        if run.exit.is_none() {
            run.exit = run.child.try_wait().ok().flatten();
        }
        let live = run.telemetry.as_ref().and_then(|t| t.html());
        if run.exit.is_some() {
            if let Some(mut t) = run.telemetry.take() {
                t.stop();
            }
        }
        let read = |name: &str| std::fs::read_to_string(run.out.join(name)).ok();
        let report: Option<serde_json::Value> = run.exit.and_then(|_| read("report.json")).and_then(|t| serde_json::from_str(&t).ok());
        let (state, state_said) = match (run.exit, &report) {
            (None, _) => ("running", "running".to_string()),
            (Some(_), Some(r)) => ended(r, run.exit.is_some_and(|s| s.success())),
            (Some(s), None) => ("failed", format!("failed ({}) before writing its report", exit_said(s))),
        };
        // The run's own words only where its report does not say why.
        let stderr_tail = (run.exit.is_some() && report.is_none()).then(|| read("run.stderr")).flatten().map(|t| tail(&t, 2000));
        Some(Status {
            id: id.to_string(),
            scenario: run.scenario.clone(),
            state,
            state_said,
            elapsed_s: run.started.elapsed().as_secs_f64(),
            duration_s: run.duration_s,
            started_unix_s: run.started_unix_s,
            out: run.out.display().to_string(),
            report,
            stderr_tail,
            live,
            here: true,
        })
    }

    /// Every run: this server's (newest first), then those earlier servers
    /// left in `parent` (newest first).
    pub fn list(&self, parent: &Path) -> Vec<Status> {
        let ids: Vec<String> = self.runs.lock().expect("runs lock").keys().cloned().collect();
        let mut here: Vec<Status> = ids.iter().filter_map(|id| self.status_here(id)).collect();
        here.sort_by_key(|s| std::cmp::Reverse(s.started_unix_s));
        let mut past: Vec<Status> = std::fs::read_dir(parent)
            .into_iter()
            .flatten()
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|id| !ids.contains(id))
            .filter_map(|id| past_status(parent, &id))
            .collect();
        let study: Vec<(String, PathBuf)> = self.study.lock().expect("study runs lock").iter().map(|(k, v)| (k.clone(), v.clone())).collect();
        past.extend(study.iter().filter(|(id, _)| !ids.contains(id)).filter_map(|(id, dir)| past_status_in(dir, id)));
        past.sort_by_key(|s| std::cmp::Reverse(s.started_unix_s));
        here.extend(past);
        here
    }

    /// Asks the run to stop as Ctrl-C would: it ends its processes and
    /// writes its report. `false` when no such run.
    pub fn stop(&self, id: &str) -> bool {
        let runs = self.runs.lock().expect("runs lock");
        let Some(run) = runs.get(id) else { return false };
        if run.exit.is_none() {
            interrupt(&run.child);
        }
        true
    }

    /// Stops every run still going and waits for each (the server is
    /// ending: no run outlives it).
    pub fn stop_all(&self) {
        let mut runs = self.runs.lock().expect("runs lock");
        for run in runs.values_mut().filter(|r| r.exit.is_none()) {
            interrupt(&run.child);
            let _ = run.child.wait();
        }
    }
}

fn interrupt(child: &Child) {
    if let Ok(pid) = i32::try_from(child.id()) {
        // SAFETY: signalling our own child, which has not been reaped.
        unsafe { libc::kill(pid, libc::SIGINT) };
    }
}

/// A run's end from its report: `done`, `stopped` (on request; a normal
/// end) or `failed` (a fault, frames unaccounted for, or the run's exit
/// status), and in words.
fn ended(r: &serde_json::Value, exit_ok: bool) -> (&'static str, String) {
    let faults: Vec<&str> = r["faults"].as_array().map(|f| f.iter().filter_map(|x| x.as_str()).collect()).unwrap_or_default();
    let balanced = r["frames"]["balanced"].as_bool().unwrap_or(false);
    let stopped = r["stopped"].as_bool().unwrap_or(false);
    let secs = r["duration_s"].as_f64().unwrap_or(0.0);
    match (faults.is_empty() && balanced && exit_ok, stopped) {
        (true, true) => ("stopped", format!("stopped on request after {secs:.1} s; every frame accounted for")),
        (true, false) => ("done", format!("done after {secs:.1} s; every frame accounted for")),
        (false, _) if !faults.is_empty() => ("failed", format!("failed: {}", faults.join("; "))),
        (false, _) if !balanced => ("failed", "failed: not every frame is accounted for (see the report)".to_string()),
        (false, _) => ("failed", "failed (see the report)".to_string()),
    }
}

fn exit_said(s: std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (s.code(), s.signal()) {
        (Some(c), _) => format!("exit status {c}"),
        (None, Some(sig)) => format!("killed by signal {sig}"),
        _ => "ended".to_string(),
    }
}

/// The directory of a run an earlier server left in `parent`: a plain
/// name (no path), holding a report.
fn past_run_dir(parent: &Path, id: &str) -> Option<PathBuf> {
    let plain = !id.is_empty() && !id.starts_with('.') && id.chars().all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c));
    let dir = parent.join(id);
    (plain && dir.join("report.json").is_file()).then_some(dir)
}

/// The state of a run an earlier server left in `parent`, from its report.
fn past_status(parent: &Path, id: &str) -> Option<Status> {
    past_status_in(&past_run_dir(parent, id)?, id)
}

/// The state of the run `id` whose folder is `dir`, from its report.
fn past_status_in(dir: &Path, id: &str) -> Option<Status> {
    let dir = dir.to_path_buf();
    if !dir.join("report.json").is_file() {
        return None;
    }
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).ok()?).ok()?;
    let started = report["provenance"]["started_utc"].as_str().and_then(|t| humantime::parse_rfc3339(t).ok());
    let started = started.or_else(|| std::fs::metadata(dir.join("report.json")).ok()?.modified().ok());
    let started_unix_s = started?.duration_since(std::time::UNIX_EPOCH).ok()?.as_secs();
    let (state, state_said) = ended(&report, true);
    Some(Status {
        id: id.to_string(),
        scenario: report["scenario"].as_str().unwrap_or_default().to_string(),
        state,
        state_said,
        elapsed_s: report["duration_s"].as_f64().unwrap_or(0.0),
        duration_s: report["duration_s"].as_f64().unwrap_or(0.0),
        started_unix_s,
        out: dir.display().to_string(),
        report: Some(report),
        stderr_tail: None,
        live: None,
        here: false,
    })
}

/// The last `n` bytes of `text`, cut at a character boundary.
fn tail(text: &str, n: usize) -> String {
    let mut start = text.len().saturating_sub(n);
    while !text.is_char_boundary(start) {
        start += 1;
    }
    text[start..].to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::args::{RunPlacement, SourceArgs};
    use crate::service::channel::video::VideoArgs;

    /// A start of two and a half seconds at 500 Hz, seed 7, nothing else.
    fn start() -> Start {
        Start { toml: String::new(), duration_s: 2.5, seed: Some(7), rate_hz: Some(500.0), return_scenario: None, video_mbps: None, video_scenario: None, capture: None, isolate: None }
    }

    #[test]
    fn a_start_is_the_run_it_asks_for() {
        let s = Start { return_scenario: Some("PLM-1".into()), video_mbps: Some(2.0), video_scenario: Some("DLM-1".into()), isolate: Some(false), ..start() };
        let mut want = RunArgs::new(SCENARIO_FILE);
        want.scenario.seed = Some(7);
        want.source = SourceArgs { rate_hz: Some(500.0), duration_s: Some(2.5), ..SourceArgs::default() };
        want.channels.feedback.return_scenario = Some("PLM-1".into());
        want.channels.video.video_mbps = Some(2.0);
        want.channels.video.video_scenario = Some("DLM-1".into());
        want.placement.no_isolate = true;
        assert_eq!(s.run_args().unwrap(), want);
        check_run_args(&want).unwrap();
        // `none`: no feedback path; a video scenario only with video.
        let run = Start { return_scenario: Some("none".into()), video_scenario: Some("DLM-1".into()), isolate: Some(true), ..start() }.run_args().unwrap();
        assert!(run.channels.feedback.no_feedback && run.channels.feedback.return_scenario.is_none());
        assert_eq!(run.channels.video, VideoArgs::default());
        assert_eq!(run.placement, RunPlacement::default());
    }

    #[test]
    fn a_start_netfi_run_would_refuse_is_refused_in_its_words() {
        let e = Start { return_scenario: Some("PLM-9".into()), ..start() }.run_args().unwrap_err();
        assert!(matches!(e, UiError::NotPreset { what: "the return scenario", .. }), "{e}");
        let e = Start { capture: Some("/nonexistent/capture.lz4".into()), ..start() }.run_args().unwrap_err();
        assert!(matches!(e, UiError::NoCapture(_)), "{e}");
        let e = check_run_args(&Start { rate_hz: Some(1e9), ..start() }.run_args().unwrap()).unwrap_err().to_string();
        assert!(e.starts_with("invalid value '1000000000' for '--rate-hz"), "{e}");
        let e = check_run_args(&Start { video_scenario: Some("x".into()), ..start() }.run_args().unwrap());
        assert!(e.is_ok(), "a video scenario without video is left out: {e:?}");
    }

    /// The capture field is read as the run's console will read it: a
    /// FIFO is refused at once (not waited on), a damaged file with the
    /// reader's reason, before any process starts.
    #[test]
    fn the_capture_field_is_refused_as_the_console_would_refuse_it() {
        let dir = crate::scratch::dir("capture-field");
        let options = |c: &std::path::Path| {
            serde_json::from_value::<Start>(serde_json::json!({ "toml": "", "duration_s": 1.0, "seed": null, "capture": c })).unwrap().run_args()
        };
        let good = dir.join("good.lz4");
        let mut w = crate::capture::CaptureWriter::create(&good).unwrap();
        w.write_frame(1, &crate::frame::ItpFrame::default().with_checksum()).unwrap();
        w.finish().unwrap();
        let a = options(&good).unwrap();
        assert_eq!(a.source.capture.as_deref(), Some(good.as_path()));
        assert!(matches!(options(&dir.join("absent.lz4")), Err(UiError::NoCapture(_))));
        let fifo = dir.join("fifo.lz4");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let e = options(&fifo).unwrap_err().to_string();
        assert!(e.contains("a FIFO: only regular files are read"), "{e}");
        std::fs::write(dir.join("text.lz4"), b"not a capture").unwrap();
        let e = options(&dir.join("text.lz4")).unwrap_err().to_string();
        assert!(e.contains("text.lz4") && e.contains("LZ4"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
