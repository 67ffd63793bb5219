//! The run report assembled from what the services left in the run's
//! directory: by the runner at the end of a `netfi run`, or by `netfi
//! report` from the directory of a run started by hand (an emulator with
//! foreign clients, or netfi's own services started one by one).

use super::delay::delay_check;
use super::phases::{self, RunTimeline};
use super::trace_merge::{merge_trace, Source};
use super::{files, join, Files, ProcessEnd, Ros2Topics, RunReport, RunStream, RunStreams};
use crate::host::Steal;
use crate::scenario::ScenarioSpec;
use crate::service::console::ConsoleReport;
use crate::service::schema::EmulatorReport;
use crate::transport::TransportReports;
use crate::service::simulator::SimulatorReport;
use crate::service::channel::{ChannelSections, Sources};
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};

/// What a run's report says of the run besides what its services wrote.
#[derive(Debug, Clone, Copy)]
pub struct RunFacts<'a> {
    pub run_id: &'a str,
    /// The run's directory: the services' reports, traces and histograms.
    pub out: &'a Path,
    /// The scenario's name.
    pub scenario: &'a str,
    /// The scenario, where it is known (for the delay law).
    pub spec: Option<&'a ScenarioSpec>,
    pub seed: u64,
    /// The run's copy of the scenario, where it has one.
    pub scenario_path: Option<&'a Path>,
}

/// What the runner saw of a run: how long it took, the host's steal time,
/// how each process ended, what went wrong (dead processes), and whether
/// it was interrupted (stopped at a person's request).
#[derive(Debug, Clone, Default)]
pub struct RunnerView {
    pub duration_s: f64,
    pub steal: Steal,
    pub processes: Vec<ProcessEnd>,
    pub faults: Vec<String>,
    pub interrupted: bool,
    /// The roles the lab's own programs played (`console`, `simulator`):
    /// their reports are not the run's to have.
    pub lab: Vec<&'static str>,
}

/// One service's report in a run's directory.
pub(super) enum Found<T> {
    Read(T),
    Absent,
    Unreadable(String),
}

impl<T: DeserializeOwned> Found<T> {
    /// Reads `path`.
    pub(super) fn read(path: &Path) -> Found<T> {
        match crate::load::read_file(path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Found::Absent,
            Err(e) => Found::Unreadable(format!("reading {}: {e}", path.display())),
            Ok(bytes) => match serde_json::from_slice(&bytes) {
                Ok(t) => Found::Read(t),
                Err(e) => Found::Unreadable(format!("{}: {e}", path.display())),
            },
        }
    }
}

/// The services' reports found in a run's directory, and what was not
/// there or not readable: `(file, role, why)`.
pub(super) struct Parts {
    pub console: Option<ConsoleReport>,
    pub emulator: Option<EmulatorReport>,
    pub simulator: Option<SimulatorReport>,
    /// Each transport's report, written only where a side is of it: not
    /// missing where absent.
    pub transports: TransportReports,
    pub missing: Vec<(&'static str, String, Option<String>)>,
    /// The robot was the lab's own program: no report of its own.
    pub lab_robot: bool,
    /// No runner started the run ([`RunReport::by_hand`]).
    pub by_hand: bool,
    /// A ROS 2 run's forward topics, and whether `ros2.json` says its
    /// messages balance.
    pub ros2: Option<(Ros2Topics, bool)>,
}

/// What the report reads of `ros2.json`.
#[derive(serde::Deserialize)]
struct Ros2Json {
    balanced: bool,
    forward: Ros2Topics,
}

impl Parts {
    /// The reports in `out`; the emulator's as already read, when it was.
    pub(super) fn read(out: &Path, emulator: Option<Found<EmulatorReport>>) -> Parts {
        let mut missing = Vec::new();
        let console = take(Found::read(&out.join("console.json")), ("console.json", "console"), &mut missing);
        let emulator = take(emulator.unwrap_or_else(|| Found::read(&out.join("emulator.json"))), ("emulator.json", "emulator"), &mut missing);
        let simulator = take(Found::read(&out.join("simulator.json")), ("simulator.json", "simulator"), &mut missing);
        let (transports, unread) = TransportReports::read(out);
        for (file, scheme, why) in unread {
            missing.push((file, format!("emulator's {} side", scheme.to_uppercase()), Some(why)));
        }
        let ros2 = match Found::<Ros2Json>::read(&out.join("ros2.json")) {
            Found::Read(r) => Some((r.forward, r.balanced)),
            Found::Absent => None,
            Found::Unreadable(why) => {
                missing.push(("ros2.json", "emulator's ROS 2 side".to_string(), Some(why)));
                None
            }
        };
        // No ROS 2 node writes a report of netfi's: the console's and the
        // robot's are not missing there.
        if ros2.is_some() {
            missing.retain(|(file, _, why)| why.is_some() || !["console.json", "simulator.json"].contains(file));
        }
        Parts { console, emulator, simulator, transports, missing, lab_robot: false, by_hand: false, ros2 }
    }

    /// A fault for each report the runner expected and did not find.
    pub(super) fn faults(&self) -> impl Iterator<Item = String> + '_ {
        self.faults_but(&[])
    }

    /// A fault for each report the runner expected and did not find, but
    /// the absent reports of the roles in `lab` (played by the lab's own
    /// programs).
    pub(super) fn faults_but<'a>(&'a self, lab: &'a [&'static str]) -> impl Iterator<Item = String> + 'a {
        self.missing.iter().filter(move |(_, role, why)| !(why.is_none() && lab.contains(&role.as_str()))).map(|(_, role, why)| match why {
            None => format!("no report from the {role}"),
            Some(why) => format!("no report from the {role}: {why}"),
        })
    }
}

/// The report `found`, or `None` with `(file, role)` and why among the missing.
fn take<T>(found: Found<T>, (file, role): (&'static str, &'static str), missing: &mut Vec<(&'static str, String, Option<String>)>) -> Option<T> {
    match found {
        Found::Read(t) => Some(t),
        Found::Absent => {
            missing.push((file, role.to_string(), None));
            None
        }
        Found::Unreadable(why) => {
            missing.push((file, role.to_string(), Some(why)));
            None
        }
    }
}

/// Assembles the report of the run `facts` from its services' reports
/// `parts`, with what the runner saw (its faults first): joins the
/// reports, the trace (`source`: what becomes of the emulator's), checks
/// the delays, and names the cut files.
pub(super) fn assemble(facts: &RunFacts, parts: Parts, runner: RunnerView, source: Source) -> RunReport {
    let mut faults = runner.faults;
    let mut r = join_parts(facts, parts, runner.duration_s, runner.steal, runner.processes, runner.interrupted);
    faults.append(&mut r.faults);
    // The trace: the emulator's rows joined with the robot's receive times.
    let merged = merge_trace(facts.out, source).unwrap_or_else(|e| {
        faults.push(format!("trace not written: {e}"));
        Default::default()
    });
    r.files.trace = merged.trace;
    // The run's stretches under one condition; the whole run's delays are
    // held against one law only where it had one condition throughout.
    let timeline = facts.spec.map(|s| RunTimeline::of(s, &r.events));
    let single = matches!(&timeline, Some(Ok(t)) if t.is_single());
    match &timeline {
        Some(Ok(t)) if !t.is_single() => r.phases = phases::figures(t, &merged.fates, &merged.delays, &r.stages),
        Some(Err(why)) => r.phases_unknown = Some(why.clone()),
        _ => {}
    }
    r.delay_check = delay_check(facts.spec.filter(|_| single), facts.seed, merged.delays);
    // Last, so that a trace cut by the join itself is named too.
    faults.extend(files::cut_faults(facts.out));
    r.faults = faults;
    r
}

/// The report of `facts`' run from its services' reports alone (no
/// trace, no delay check): every figure the reports give, and the
/// faults their join shows.
fn join_parts(facts: &RunFacts, parts: Parts, duration_s: f64, steal: Steal, processes: Vec<ProcessEnd>, stopped: bool) -> RunReport {
    let Parts { console, emulator, simulator, transports, missing, lab_robot, by_hand, ros2 } = parts;
    let (shaping, emulator) = match emulator {
        Some(EmulatorReport { shaping, process }) => (Some(shaping), Some(process)),
        None => (None, None),
    };
    let frames = match (lab_robot, &simulator) {
        _ if ros2.is_some() => join::account_of_topics(emulator.as_deref(), ros2.as_ref().map(|(t, b)| (t, *b))),
        _ if by_hand => join::account_by_hand(console.as_ref(), emulator.as_deref(), simulator.as_ref()),
        (true, None) => join::account_to_lab_robot(console.as_ref(), emulator.as_deref()),
        _ => join::account(console.as_ref(), emulator.as_deref(), simulator.as_ref()),
    };
    let (console_json, simulator_json) = (console.as_ref().and_then(|c| serde_json::to_value(c).ok()), simulator.as_ref().and_then(|s| serde_json::to_value(s).ok()));
    let sources = Sources { emulator: emulator.as_ref(), console: console_json.as_ref(), simulator: simulator_json.as_ref(), stopped };
    let channels = ChannelSections::join(sources);
    let mut faults = channels.faults();
    faults.extend(if ros2.is_some() { join::faults_of_topics(&frames) } else { join::faults(&frames) });
    faults.extend(transports.faults());
    let e = shaping.as_ref();
    let files = Files {
        out_dir: facts.out.to_path_buf(),
        scenario: facts.scenario_path.map(Path::to_path_buf),
        trace: None,
        decision_hlog: e.and_then(|e| e.decision_hlog.clone()),
        lateness_hlog: e.and_then(|e| e.lateness_hlog.clone()),
        end_to_end_hlog: simulator.as_ref().and_then(|s| s.end_to_end_hlog.clone()),
        report_json: facts.out.join("report.json"),
        channels: channels.files(sources),
    };
    RunReport {
        provenance: None,
        delay_check: None,
        run_id: facts.run_id.to_string(),
        scenario: facts.scenario.to_string(),
        seed: facts.seed,
        duration_s,
        stopped,
        interrupted: false,
        by_hand,
        ros2: ros2.map(|(t, _)| t),
        frames,
        loss_rate: e.map(|e| e.link.loss_rate),
        loss_rate_ci95: e.map(|e| e.link.loss_rate_ci95),
        loss_rate_unseen_model: e.and_then(|e| e.link.loss_rate_unseen_model),
        phases: Vec::new(),
        phases_unknown: None,
        stages: e.map(|e| e.link.stages.clone()).unwrap_or_default(),
        links: e.map(|e| e.link.links.clone()).unwrap_or_default(),
        injected_delay_ns: e.map(|e| e.link.injected_delay_ns),
        overhead_ns: join::overhead(e.map(|e| &e.link), simulator.as_ref()),
        // With a program of the lab's at either end the emulator measures
        // the frames it took in and released (`--kinematics`: the lab's
        // console sends netfi's robot no direct copy); else netfi's robot
        // measures what it received beside the console's direct copy.
        kinematics: emulator.as_ref().and_then(|p| p.kinematics.clone()).or_else(|| simulator.as_ref().and_then(|s| s.kinematics.clone())),
        channels,
        processes,
        faults,
        notes: Vec::new(),
        missing: missing.iter().map(|(file, _, _)| file.to_string()).collect(),
        peer_events: e.map(|e| e.peer_events.clone()).unwrap_or_default(),
        events: e.map(|e| e.events.clone()).unwrap_or_default(),
        steal,
        files,
        console,
        emulator,
        simulator,
        transports,
        streams: None,
    }
}

/// Why a run's directory gives no report.
#[derive(Debug, thiserror::Error)]
pub enum DirError {
    /// Neither the runner's report nor the emulator's is there.
    #[error(
        "{}: no run's report here: neither {} (written by `netfi run`) nor {} (written by `netfi emulator`); give the directory a run wrote into (`--out`)",
        dir.display(), report.display(), emulator.display()
    )]
    NotARun { dir: PathBuf, report: PathBuf, emulator: PathBuf },
    /// The run's runner did not finish it and its emulator left no report.
    #[error("{}: no run's report here: {said}; and the emulator left no report ({})", dir.display(), emulator.display())]
    Unfinished { dir: PathBuf, said: String, emulator: PathBuf },
    /// The run's report is there but cannot be read.
    #[error("{what}")]
    Report { what: String },
    /// The emulator's report is there but cannot be read.
    #[error("{what}")]
    Emulator { what: String },
    /// The emulator served several streams: each has a directory of its own.
    #[error("{}: the report of an emulator of {} streams; each stream's report is in its own directory: {}", path.display(), dirs.len(), dirs.iter().map(|d| d.display().to_string()).collect::<Vec<_>>().join(", "))]
    SeveralStreams { path: PathBuf, dirs: Vec<PathBuf> },
    /// The run's copy of the scenario is there but is not a scenario.
    #[error("{0}")]
    Scenario(#[from] crate::scenario::ScenarioError),
}

impl RunReport {
    /// Joins what the services left in the run's directory into the
    /// run's report, with what the runner saw (`runner`: dead processes
    /// among its faults); adds missing reports, lost frames, an
    /// interruption, a trace that could not be joined and cut files to the
    /// faults. The emulator's trace is joined into `trace.csv` and removed.
    pub fn assemble_run(facts: &RunFacts, mut runner: RunnerView) -> RunReport {
        let mut parts = Parts::read(facts.out, None);
        let lab = std::mem::take(&mut runner.lab);
        parts.lab_robot = lab.contains(&"simulator");
        runner.faults.extend(parts.faults_but(&lab));
        assemble(facts, parts, runner, Source::Consume)
    }

    /// The report of a run of several streams from each stream's own
    /// (stream 0's first, each already written to its directory): stream
    /// 0's figures, every process of the run, each stream's faults (named
    /// by stream) and the files cut in the run's directory `out` itself,
    /// and the streams' table and total.
    pub fn join_streams(mut reports: Vec<RunReport>, processes: Vec<ProcessEnd>, out: &Path) -> RunReport {
        let lines: Vec<RunStream> = reports.iter().enumerate().map(|(k, r)| RunStream::of(k, r)).collect();
        let mut top = reports.swap_remove(0);
        top.processes = processes;
        top.faults = lines.iter().flat_map(|l| l.faults.iter().map(move |f| format!("stream {}: {f}", l.stream))).collect();
        top.faults.extend(files::cut_faults_here(out));
        top.files.report_json = out.join("report.json");
        top.streams = Some(RunStreams::of(lines));
        top
    }

    /// The report of the run in `dir`: its `report.json` (what `netfi run`
    /// wrote), or else assembled from the services' reports
    /// ([`RunReport::from_dir`]).
    pub fn of_dir(dir: &Path) -> Result<RunReport, DirError> {
        let path = dir.join("report.json");
        match Found::read(&path) {
            Found::Read(r) => Ok(r),
            Found::Absent => RunReport::from_dir(dir),
            Found::Unreadable(what) => Err(DirError::Report { what: format!("{what} (not a run report)") }),
        }
    }

    /// The report of the run in `dir` assembled from whatever its services
    /// wrote there, for a run no runner joined (started by hand, with
    /// foreign clients or netfi's own services; or a runner that was
    /// killed): `emulator.json` at least; `console.json` and
    /// `simulator.json` where they are (those not there are listed in
    /// `missing`, and what needs them is unknown). The emulator's trace is
    /// joined into `trace.csv` and kept, so the report can be made again.
    /// The run id is the directory's name; the scenario is the run's copy
    /// (`scenario.toml`) or else the preset the emulator names.
    pub fn from_dir(dir: &Path) -> Result<RunReport, DirError> {
        let emulator_json = dir.join("emulator.json");
        let emulator = match Found::<serde_json::Value>::read(&emulator_json) {
            Found::Absent => {
                if let Some(said) = files::unfinished(dir) {
                    return Err(DirError::Unfinished { dir: dir.to_path_buf(), said, emulator: emulator_json });
                }
                return Err(DirError::NotARun { dir: dir.to_path_buf(), report: dir.join("report.json"), emulator: emulator_json });
            }
            Found::Unreadable(what) => return Err(DirError::Emulator { what }),
            Found::Read(v) => several_streams(&emulator_json, &v)?,
        };
        let scenario_path = dir.join("scenario.toml");
        let spec = match scenario_path.exists() {
            true => Some(crate::load::parse_file(&scenario_path)?),
            false => crate::scenario::preset(&emulator.process.scenario),
        };
        let run_id = dir.canonicalize().ok().and_then(|d| Some(d.file_name()?.to_string_lossy().into_owned())).unwrap_or_default();
        let scenario = emulator.process.scenario.clone();
        let facts = RunFacts {
            run_id: &run_id,
            out: dir,
            scenario: &scenario,
            spec: spec.as_ref(),
            seed: emulator.process.seed,
            scenario_path: scenario_path.exists().then_some(scenario_path.as_path()),
        };
        let p = &emulator.process;
        let steal = Steal { ms: p.steal_ms, fraction: p.steal_fraction };
        let duration_s = p.duration_s;
        let mut parts = Parts::read(dir, Some(Found::Read(emulator)));
        // Without a runner, a missing console or robot report is no fault
        // (a foreign client writes none); one that cannot be read is.
        let faults = parts.faults().zip(&parts.missing).filter(|(_, (_, _, why))| why.is_some()).map(|(f, _)| f).collect();
        let mut faults: Vec<String> = faults;
        // A runner that was killed (or failed) leaves its mark: the run is
        // not whole, whatever its processes wrote. Without it, no runner
        // started the run.
        let unfinished = files::unfinished(dir);
        parts.by_hand = unfinished.is_none();
        faults.extend(unfinished.clone());
        let runner = RunnerView { duration_s, steal, processes: Vec::new(), faults, interrupted: false, lab: Vec::new() };
        let mut r = assemble(&facts, parts, runner, Source::Keep);
        r.interrupted = unfinished.is_some();
        Ok(r)
    }
}

/// The emulator's report of one stream, from `emulator.json`'s JSON `v`;
/// the joint report of several is refused, naming each stream's directory.
fn several_streams(path: &Path, v: &serde_json::Value) -> Result<EmulatorReport, DirError> {
    if let (Some(streams), Some(_)) = (v.get("streams").and_then(|s| s.as_array()), v.get("total")) {
        let dirs = streams.iter().filter_map(|s| s.get("dir")?.as_str().map(PathBuf::from)).collect();
        return Err(DirError::SeveralStreams { path: path.to_path_buf(), dirs });
    }
    serde_json::from_value(v.clone()).map_err(|e| DirError::Emulator { what: format!("{}: not the emulator's report: {e}", path.display()) })
}

#[cfg(test)]
mod tests {
    use super::super::join::tests::{console, emulator, simulator};
    use super::*;
    use crate::metrics::Summary;
    use serde_json::json;
    use crate::scratch::dir;

    /// `emulator.json` of PLM-2 seed 7: 10 frames in, 6 delivered, 3
    /// dropped, 1 held; the console's word `sent`.
    fn emulator_json(sent: Option<u64>) -> serde_json::Value {
        let mut v = serde_json::to_value(emulator(10, 6, 3, 1, sent)).unwrap();
        let shaping = json!({
            "loss_rate": 0.3, "loss_rate_ci95": [0.1, 0.5], "stages": [], "injected_delay_ns": Summary::default(),
            "ingress_wait_ns": Summary::default(), "decision_ns": Summary::default(), "release_lateness_ns": Summary::default(),
            "peer_events": [], "trace_path": null, "decision_hlog": null, "lateness_hlog": null
        });
        v.as_object_mut().unwrap().extend(shaping.as_object().unwrap().clone());
        v
    }

    fn write(path: &Path, v: &impl serde::Serialize) {
        std::fs::write(path, serde_json::to_vec(v).unwrap()).unwrap();
    }

    #[test]
    fn a_run_started_by_hand_is_reported_from_the_emulators_report_alone() {
        let d = dir("emulator-only");
        write(&d.join("emulator.json"), &emulator_json(Some(10)));
        let r = RunReport::of_dir(&d).unwrap();
        assert_eq!((r.scenario.as_str(), r.seed, r.run_id.as_str()), ("PLM-2", 7, d.file_name().unwrap().to_str().unwrap()));
        assert_eq!(r.missing, ["console.json", "simulator.json"]);
        assert_eq!(r.faults, Vec::<String>::new(), "a foreign client's missing report is no fault");
        assert_eq!((r.frames.sent, r.frames.entered, r.frames.received), (Some(10), Some(10), None));
        assert!(r.by_hand, "no runner's mark: an emulator started by hand");
        assert!(r.frames.balanced, "what the robot received is not known, not wrong: {:?}", r.frames);
        assert_eq!(r.loss_rate, Some(0.3));
        assert_eq!(r.files.scenario, None);
        let text = r.to_text();
        let head = format!("netfi emulator {}: scenario PLM-2 (seed 7), 1.00 s; started without `netfi run`", r.run_id);
        assert!(text.starts_with(&head), "{text}");
        assert!(text.contains("missing    console.json, simulator.json (what needs them is shown as ?)"), "{text}");
        assert!(text.contains("frames     sent 10  entered 10  delivered 6  received ?  held at end 1"), "{text}");
        assert!(text.contains("accounting balanced at the emulator: every frame that entered"), "{text}");
        assert!(text.contains("; not known: what the robot received (no report gives it)\n"), "{text}");
        assert!(!text.contains("report.json") && !text.contains("FAULT"), "{text}");
        // The console's word, where it gave one, must be what entered.
        write(&d.join("emulator.json"), &emulator_json(Some(12)));
        let r = RunReport::of_dir(&d).unwrap();
        assert!(!r.frames.balanced && r.faults == ["2 frames sent by the console never entered the emulator"], "{:?} {:?}", r.frames, r.faults);
        assert!(r.to_text().contains("accounting NOT balanced (lost before emulator 2, after emulator ?)"));
        // Without an end marker, what the console sent is not known either.
        write(&d.join("emulator.json"), &emulator_json(None));
        let r = RunReport::of_dir(&d).unwrap();
        assert!(r.frames.balanced && r.faults.is_empty(), "{:?} {:?}", r.frames, r.faults);
        assert!(r.to_text().contains("; not known: what the console sent, what the robot received (no report gives it)\n"), "{}", r.to_text());
        write(&d.join("emulator.json"), &emulator_json(Some(10)));
        // With the robot's report, and one from a console that cannot be read.
        write(&d.join("simulator.json"), &simulator(6, 0));
        std::fs::write(d.join("console.json"), b"{\"frames_sent\": ").unwrap();
        let r = RunReport::of_dir(&d).unwrap();
        assert_eq!(r.missing, ["console.json"]);
        assert!(r.frames.balanced, "{:?}", r.frames);
        assert_eq!(r.faults.len(), 1);
        assert!(r.faults[0].starts_with(&format!("no report from the console: {}", d.join("console.json").display())), "{:?}", r.faults);
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_udp_run_reports_its_sockets_and_what_the_kernel_dropped_before_the_emulator() {
        let d = dir("udp");
        write(&d.join("emulator.json"), &emulator_json(None));
        write(
            &d.join("udp.json"),
            &json!({
                "ingress": "udp://127.0.0.1:5000", "egress": "udp://127.0.0.1:6000", "payload": "itp",
                "ingress_local": "127.0.0.1:5000", "egress_local": "127.0.0.1:40000", "datagrams_in": 10,
                "ingress_kernel_drops": 3, "ingress_buffer_bytes": 212992, "console": "127.0.0.1:4000",
                "foreign_sender": 2, "foreign_senders": [{"addr": "127.0.0.1:4444", "datagrams": 2}], "foreign_unnamed": 0,
                "arena_slots": null, "arena_high_water": null, "return_path": null
            }),
        );
        let r = RunReport::of_dir(&d).unwrap();
        assert_eq!(r.transports.udp.as_ref().and_then(|u| u.ingress_kernel_drops), Some(3));
        assert_eq!(r.missing, ["console.json", "simulator.json"], "udp.json is not missing where a run has none");
        assert_eq!(
            r.faults,
            ["3 datagrams dropped by the kernel at the emulator's ingress socket udp://127.0.0.1:5000 (its receive buffer full): they never entered"]
        );
        let text = r.to_text();
        let udp = "udp        ingress udp://127.0.0.1:5000 (bound 127.0.0.1:5000), egress udp://127.0.0.1:6000 (from 127.0.0.1:40000), payload itp: \
                   10 datagrams in, 3 dropped by the kernel before ingress; console 127.0.0.1:4000; 2 datagrams from other senders refused: 127.0.0.1:4444 (2)\n";
        assert!(text.contains(udp), "{text}");
        std::fs::write(d.join("udp.json"), b"[").unwrap();
        let r = RunReport::of_dir(&d).unwrap();
        assert!(r.transports.udp.is_none() && r.missing.contains(&"udp.json".to_string()));
        assert!(r.faults[0].starts_with("no report from the emulator's UDP side: "), "{:?}", r.faults);
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_directory_without_a_report_is_an_error_naming_what_would_do() {
        let d = dir("errors");
        let e = RunReport::of_dir(&d).unwrap_err().to_string();
        for f in ["report.json", "emulator.json"] {
            assert!(e.contains(&d.join(f).display().to_string()), "{f}: {e}");
        }
        std::fs::write(d.join("emulator.json"), b"{\"scenario\": 3}").unwrap();
        let e = RunReport::of_dir(&d).unwrap_err().to_string();
        assert!(e.contains(&d.join("emulator.json").display().to_string()) && e.contains("not the emulator's report"), "{e}");
        write(&d.join("emulator.json"), &json!({"streams": [{"dir": "/runs/a/stream-0"}, {"dir": "/runs/a/stream-1"}], "total": {}}));
        let e = RunReport::of_dir(&d).unwrap_err().to_string();
        assert!(e.contains("2 streams") && e.contains("/runs/a/stream-0, /runs/a/stream-1"), "{e}");
        std::fs::write(d.join("report.json"), b"{\"run_id\": ").unwrap();
        let e = RunReport::of_dir(&d).unwrap_err().to_string();
        assert!(e.contains(&d.join("report.json").display().to_string()) && e.contains("not a run report"), "{e}");
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_run_of_several_streams_is_stream_0s_figures_every_fault_and_the_table() {
        let d = dir("streams");
        let stream = |k: usize, faults: &[&str]| {
            let out = d.join(format!("stream-{k}"));
            std::fs::create_dir_all(&out).unwrap();
            write(&out.join("emulator.json"), &emulator_json(Some(10)));
            let facts = RunFacts { run_id: "r", out: &out, scenario: "PLM-2", spec: None, seed: k as u64, scenario_path: None };
            RunReport::assemble_run(&facts, RunnerView { faults: faults.iter().map(|f| f.to_string()).collect(), ..RunnerView::default() })
        };
        let reports = vec![stream(0, &[]), stream(1, &["console ended abnormally (signal 9)"])];
        std::fs::write(d.join("emulator.json.partial"), b"{").unwrap();
        let top = RunReport::join_streams(reports, vec![], &d);
        assert_eq!(top.seed, 0, "stream 0's figures");
        assert_eq!(top.files.report_json, d.join("report.json"));
        let cut = format!("cut file: {} (its writer stopped before it was whole)", d.join("emulator.json.partial").display());
        let want = [
            "stream 0: no report from the console",
            "stream 0: no report from the simulator",
            "stream 1: console ended abnormally (signal 9)",
            "stream 1: no report from the console",
            "stream 1: no report from the simulator",
            cut.as_str(),
        ];
        assert_eq!(top.faults, want);
        let s = top.streams.unwrap();
        assert_eq!((s.streams.len(), s.total.entered, s.total.balanced), (2, 20, false));
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn the_runners_report_names_missing_reports_and_cut_files_as_faults() {
        let d = dir("runner");
        write(&d.join("emulator.json"), &emulator_json(Some(10)));
        write(&d.join("console.json"), &console(10));
        std::fs::create_dir_all(d.join("stream-1")).unwrap();
        std::fs::write(d.join("stream-1").join("received.csv.partial"), b"ingress_index,recv_ns\n0,1").unwrap();
        let facts = RunFacts { run_id: "r1", out: &d, scenario: "PLM-2", spec: None, seed: 7, scenario_path: Some(&d.join("scenario.toml")) };
        let runner = RunnerView { faults: vec!["simulator ended abnormally (signal 9)".into()], interrupted: true, ..RunnerView::default() };
        let r = RunReport::assemble_run(&facts, runner);
        let cut = format!("cut file: {} (its writer stopped before it was whole)", d.join("stream-1/received.csv.partial").display());
        assert_eq!(r.faults, ["simulator ended abnormally (signal 9)", "no report from the simulator", cut.as_str()]);
        assert!(r.stopped, "a stop is a normal end, reported as such");
        assert_eq!(r.missing, ["simulator.json"]);
        assert_eq!((r.run_id.as_str(), r.files.report_json.clone()), ("r1", d.join("report.json")));
        std::fs::remove_dir_all(&d).ok();
    }
}
