//! `netfi run`: starts the simulator, the emulator and the console as three
//! processes on one host, waits for the stream to end, and joins their
//! reports into one.
//!
//! What runs where with which arguments is decided first ([`Plan`]); when
//! to stop which process is the [`Supervisor`]'s policy; the report is
//! assembled from what the services wrote ([`RunReport::assemble`]). This
//! file holds what is left: the processes themselves.
//!
//! The children run in their own process group, so Ctrl-C reaches only the
//! runner, which then stops them in order (console, emulator, simulator) so
//! that every report and the trace are flushed. A child that dies is reported
//! as a fault; the others keep going until the planned end.

use crate::clock::now_ns;
use crate::host::StealTimer;
use crate::scenario::{Scenario, ScenarioSpec};
use crate::service::args::RunArgs;
use crate::service::plan::{parse_stream_scenario, stream_run_id, stream_seed, Plan};
use crate::service::report::{ProcessEnd, RunReport};
use crate::service::signals;
use crate::service::supervise::{Seen, State, Supervisor, CONSOLE_READY};
use anyhow::{bail, Context, Result};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub use crate::service::plan::{fresh_run_id, fresh_seed, DEFAULT_QUEUE_CAPACITY};

struct Proc {
    role: &'static str,
    child: Child,
    core: Option<usize>,
    log: PathBuf,
    status: Option<std::process::ExitStatus>,
    /// Why the runner stopped it, when it was stuck.
    stuck: Option<String>,
}

impl Proc {
    fn poll(&mut self) -> bool {
        if self.status.is_none() {
            if let Ok(Some(s)) = self.child.try_wait() {
                self.status = Some(s);
            }
        }
        self.status.is_some()
    }

    fn terminate(&mut self) {
        if !self.poll() {
            // SAFETY: signalling our own child by pid.
            unsafe {
                libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM);
            }
        }
    }

    fn status_text(&self) -> String {
        match self.status {
            None => "running".into(),
            Some(s) => match (s.code(), s.signal()) {
                (Some(c), _) => format!("exit {c}"),
                (None, Some(sig)) => format!("signal {sig}"),
                _ => format!("{s}"),
            },
        }
    }

    fn state(&self) -> State {
        match self.status {
            None => State::Running,
            Some(s) if s.success() => State::Succeeded,
            Some(_) => State::Failed,
        }
    }

    fn end(&self) -> ProcessEnd {
        ProcessEnd { role: self.role.into(), pid: self.child.id(), core: self.core, status: self.status_text(), log: self.log.clone() }
    }

    /// What went wrong with it: stuck, and how it ended.
    fn faults(&self) -> impl Iterator<Item = String> + '_ {
        self.stuck.clone().into_iter().chain(self.died())
    }

    /// Names a process stuck: what it is doing, as the kernel says (its
    /// state and, when asleep in the kernel, where).
    fn stuck(&mut self, what: &str) {
        let pid = self.child.id();
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        // The state follows the command name, in parentheses.
        let state = stat.rsplit_once(") ").and_then(|(_, rest)| rest.split(' ').next()).unwrap_or("?").to_string();
        let wchan = std::fs::read_to_string(format!("/proc/{pid}/wchan")).unwrap_or_default();
        let at = match (state.as_str(), wchan.trim()) {
            ("D", w) if !w.is_empty() && w != "0" => format!(", waiting in the kernel at {w} (uninterruptibly: a busy disk?)"),
            (_, w) if !w.is_empty() && w != "0" => format!(", asleep at {w}"),
            _ => String::new(),
        };
        let line = format!("{} {what} (pid {pid}, state {state}{at}); see {}", self.role, self.log.display());
        eprintln!("WARNING: {line}");
        self.stuck = Some(line);
    }

    fn died(&self) -> Option<String> {
        let s = self.status?;
        if s.success() {
            None
        } else {
            // The process's own last words (e.g. which file it could not write).
            let last = tail(&self.log, 1);
            let why = if last.trim().is_empty() { String::new() } else { format!(": {}", last.trim()) };
            Some(format!("{} ended abnormally ({}){why}; see {}", self.role, self.status_text(), self.log.display()))
        }
    }
}

fn spawn(role: &'static str, args: Vec<String>, core: Option<usize>, out: &Path) -> Result<Proc> {
    let exe = std::env::current_exe().context("locating the netfi executable")?;
    let log = out.join(format!("{role}.log"));
    let file = std::fs::File::create(&log).with_context(|| format!("creating {}", log.display()))?;
    let child = Command::new(&exe)
        .arg(role)
        .args(&args)
        .stdin(Stdio::null())
        .stdout(file.try_clone()?)
        .stderr(file)
        .process_group(0)
        .env(crate::host::isolate::RUNNER_PID_ENV, std::process::id().to_string())
        .spawn()
        .with_context(|| format!("starting the {role} ({})", exe.display()))?;
    Ok(Proc { role, child, core, log, status: None, stuck: None })
}

/// Waits for `<out>/<role>.ready`, failing early if the process ends.
fn wait_ready(p: &mut Proc, out: &Path, timeout: Duration) -> Result<()> {
    let ready = out.join(format!("{}.ready", p.role));
    let t0 = Instant::now();
    while !ready.exists() {
        if p.poll() {
            bail!("the {} ended before it was ready ({}):\n{}", p.role, p.status_text(), tail(&p.log, 20));
        }
        if t0.elapsed() > timeout {
            p.terminate();
            bail!("the {} was not ready after {:?}:\n{}", p.role, timeout, tail(&p.log, 20));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(())
}

fn tail(path: &Path, lines: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let all: Vec<&str> = text.lines().collect();
    all[all.len().saturating_sub(lines)..].join("\n")
}

/// A run's exclusive claim on its output directory: an `flock` on
/// `<out>/run.lock`, held for the runner's life (the kernel lets it go
/// when the runner ends, however it ends). The file holds the owner's pid,
/// so that a refused run can say whose the directory is.
pub struct OutDirLock {
    _file: std::fs::File,
}

/// The lock file in a run's output directory.
pub const LOCK_FILE: &str = "run.lock";

impl OutDirLock {
    /// Takes the lock on `out` (which must exist) without waiting; a
    /// directory another run holds is an error naming it and that run's pid.
    pub fn take(out: &Path) -> Result<OutDirLock> {
        use std::io::{Read, Seek, Write};
        use std::os::fd::AsRawFd;
        let path = out.join(LOCK_FILE);
        // Not truncated on open: until the lock is ours the pid in it is
        // the owner's.
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .with_context(|| format!("opening {}", path.display()))?;
        // SAFETY: flock on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let err = std::io::Error::last_os_error();
            if err.raw_os_error() == Some(libc::EWOULDBLOCK) {
                let mut text = String::new();
                let _ = file.read_to_string(&mut text);
                let owner = text.trim().parse::<u32>().map_or("unknown".to_string(), |p| p.to_string());
                bail!(
                    "the output directory {} is in use by another netfi run (pid {owner}); wait for it to end or give another --out",
                    out.display()
                );
            }
            return Err(err).with_context(|| format!("locking {}", path.display()));
        }
        file.set_len(0).and_then(|_| file.rewind()).and_then(|_| writeln!(file, "{}", std::process::id()))
            .with_context(|| format!("writing {}", path.display()))?;
        Ok(OutDirLock { _file: file })
    }
}

/// Writes the scenario the emulator is to apply into a file of this run's
/// own, created exclusively (`scenario.<run id>.toml`, read-only): no other
/// run can have written or can overwrite it. `scenario.toml` beside it is
/// the copy kept for people.
fn write_run_scenario(spec: &ScenarioSpec, path: &Path, out: &Path, run_id: &str) -> Result<PathBuf> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let toml = spec.to_toml();
    std::fs::write(path, &toml).with_context(|| format!("writing {}", path.display()))?;
    let own = own_scenario(out, run_id);
    // A file left by an earlier run with this run id (given with --run-id).
    let _ = std::fs::remove_file(&own);
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o444)
        .open(&own)
        .with_context(|| format!("creating {}", own.display()))?;
    f.write_all(toml.as_bytes()).and_then(|_| f.sync_all()).with_context(|| format!("writing {}", own.display()))?;
    Ok(own)
}

/// The emulator's own copy of a stream's scenario.
fn own_scenario(out: &Path, run_id: &str) -> PathBuf {
    out.join(format!("scenario.{run_id}.toml"))
}

/// Writes every stream's scenario and tells the emulator where they are.
fn write_scenarios(plan: &mut Plan) -> Result<()> {
    let own = plan.streams.iter().map(|s| write_run_scenario(&s.spec, &s.scenario_path, &s.out, &s.run_id)).collect::<Result<Vec<_>>>()?;
    plan.emulator.scenario = own[0].display().to_string();
    if own.len() > 1 {
        plan.emulator.stream.stream_scenario = own.iter().enumerate().skip(1).map(|(k, p)| format!("{k}={}", p.display())).collect();
    }
    Ok(())
}

/// Each stream's scenario (`--stream-scenario K=...`, else `spec`), each
/// checked with its seed, and each stream's run id checked.
fn stream_specs(args: &RunArgs, spec: ScenarioSpec, seed: u64, run_id: &str) -> Result<Vec<ScenarioSpec>> {
    let mut specs = vec![spec; args.stream.streams as usize];
    for text in &args.stream.stream_scenario {
        let (k, what) = parse_stream_scenario(text, args.stream.streams)?;
        specs[k] = crate::load::resolve(&what).with_context(|| format!("--stream-scenario {text}"))?;
    }
    for (k, s) in specs.iter().enumerate() {
        Scenario::new(s, stream_seed(seed, k)).with_context(|| format!("the scenario of stream {k}"))?;
        crate::transport::RunId::new(&stream_run_id(run_id, k)).with_context(|| format!("the run id of stream {k}"))?;
    }
    Ok(specs)
}

/// Resolves the scenario and the seed, plans the run, and readies its
/// output directory: locked for this run, stale files of an earlier run
/// there removed, what an earlier emulator left moved put back, the
/// scenario written, dead processes' iceoryx2 resources removed.
fn prepare(args: &RunArgs) -> Result<(Plan, OutDirLock)> {
    let spec = crate::load::resolve(&args.scenario)?;
    let seed = args.seed.or(spec.seed).unwrap_or_else(fresh_seed);
    // Validate the scenario here, so a bad one fails before any process starts.
    Scenario::new(&spec, seed)?;
    let run_id = args.run_id.clone().unwrap_or_else(fresh_run_id);
    let mut specs = stream_specs(args, spec, seed, &run_id)?;
    let host_cores: Vec<usize> = core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).collect();
    // A pin that cannot be honoured is an error when asked for, and a loud
    // warning (also in the report's isolation line) otherwise.
    if let Some(c) = args.emulator_core.filter(|c| !host_cores.contains(c)) {
        bail!("--emulator-core {c}: this process may only run on CPU(s) {:?} (an inherited CPU mask: `taskset`?)", host_cores);
    }
    if let (None, Some(w)) = (args.emulator_core, crate::host::isolate::pin_problem()) {
        eprintln!("WARNING: {w}");
    }
    let first = specs.remove(0);
    let mut plan = Plan::new(args, first.clone(), seed, run_id, &host_cores);
    if !specs.is_empty() {
        specs.insert(0, first);
        plan = plan.with_streams(specs);
    }
    let out = &plan.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let lock = OutDirLock::take(out)?;
    let dirs = std::iter::once(out).chain(plan.streams.iter().map(|s| &s.out));
    for dir in dirs {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for role in ["console", "emulator", "simulator"] {
            for ext in ["ready", "json", "pid"] {
                let _ = std::fs::remove_file(dir.join(format!("{role}.{ext}")));
            }
        }
    }
    // What killed runs left cleared (their owners and guardian all dead)
    // is put back before anything else, as `netfi restore` does.
    restore_orphans(None);
    write_scenarios(&mut plan)?;
    let cleaned = crate::transport::cleanup_stale()?;
    if cleaned > 0 {
        eprintln!("removed resources of {cleaned} dead process(es) of earlier runs");
    }
    Ok((plan, lock))
}

/// The processes of a run: each stream's console and robot, and the one
/// emulator.
struct Procs {
    consoles: Vec<Proc>,
    emulator: Proc,
    simulators: Vec<Proc>,
}

impl Procs {
    /// Consoles, emulator, robots: the order of the report.
    fn all(&self) -> impl Iterator<Item = &Proc> {
        self.consoles.iter().chain(std::iter::once(&self.emulator)).chain(self.simulators.iter())
    }

    fn all_mut(&mut self) -> impl Iterator<Item = &mut Proc> {
        self.consoles.iter_mut().chain(std::iter::once(&mut self.emulator)).chain(self.simulators.iter_mut())
    }
}

/// Starts `role` in `out` and waits until it is ready.
fn start_one(role: &'static str, args: Vec<String>, core: Option<usize>, out: &Path) -> Result<Proc> {
    let mut p = spawn(role, args, core, out)?;
    wait_ready(&mut p, out, Duration::from_secs(30))?;
    Ok(p)
}

/// Starts the simulators, the emulator and the consoles, each kind once
/// the one before is ready; stops those started if one fails to start.
fn start(plan: &Plan) -> Result<Procs> {
    let (out, cores) = (&plan.out, plan.cores);
    let stop = |started: &mut [Proc]| started.iter_mut().for_each(Proc::terminate);
    let mut simulators = Vec::new();
    for s in &plan.streams {
        match start_one("simulator", s.simulator.to_argv(), cores.simulator, &s.out) {
            Ok(p) => simulators.push(p),
            Err(e) => {
                stop(&mut simulators);
                return Err(e);
            }
        }
    }
    // Each stream's link, queue, trace and feedback path are set up before
    // the emulator is ready: a second or so each on a loaded machine.
    let ready_s = 30 + 2 * plan.streams.len() as u64;
    let emulator = match spawn("emulator", plan.emulator.to_argv(), cores.emulator, out)
        .and_then(|mut p| wait_ready(&mut p, out, Duration::from_secs(ready_s)).map(|_| p))
    {
        Ok(p) => p,
        Err(e) => {
            stop(&mut simulators);
            return Err(e);
        }
    };
    let mut procs = Procs { consoles: Vec::new(), emulator, simulators };
    for s in &plan.streams {
        match spawn("console", s.console.to_argv(), cores.console, &s.out) {
            Ok(p) => procs.consoles.push(p),
            Err(e) => {
                procs.all_mut().for_each(Proc::terminate);
                return Err(e);
            }
        }
    }
    Ok(procs)
}

/// Reaps the dead iceoryx2 peers of every stream of the run.
fn reap(ipcs: &[crate::transport::IpcConfig]) {
    for cfg in ipcs {
        if let Ok(r) = crate::transport::cleanup_dead_nodes(cfg) {
            for dead in r.dead() {
                eprintln!("reaped a dead peer: {dead}");
            }
        }
    }
}

/// Watches the processes until they have ended, stopping them as the
/// [`Supervisor`] says (each stream's console and robot as one role);
/// reaps the run's dead iceoryx2 peers meanwhile; names each console not
/// streaming ([`CONSOLE_READY`]) after its start. Returns whether the run
/// was interrupted.
fn supervise(plan: &Plan, procs: &mut Procs) -> bool {
    let started = Instant::now();
    let mut policy = Supervisor::new(plan.planned_s);
    // The runner reaps the run's dead processes, off the emulator's core, so
    // the survivors see their peer counts drop and a restarted peer can take
    // over its port.
    let ipcs: Vec<_> =
        plan.streams.iter().filter_map(|s| crate::transport::RunId::new(&s.run_id).ok().map(crate::transport::IpcConfig::new)).collect();
    let mut last_reap = Instant::now();
    // Each console's mark that it streams, and whether all have made it.
    let ready: Vec<PathBuf> = plan.streams.iter().map(|s| s.out.join("console.ready")).collect();
    let mut consoles_ready = false;
    loop {
        std::thread::sleep(Duration::from_millis(5));
        procs.all_mut().for_each(|p| {
            p.poll();
        });
        if last_reap.elapsed() > Duration::from_millis(200) {
            last_reap = Instant::now();
            reap(&ipcs);
        }
        if signals::ensure_installed() {
            eprintln!("WARNING: the Ctrl-C handler had been replaced; put back");
        }
        consoles_ready = consoles_ready || procs.consoles.iter().zip(&ready).all(|(p, r)| p.status.is_some() || r.exists());
        let seen = Seen {
            now: started.elapsed(),
            stop_requested: signals::stop_requested(),
            console: State::of_group(procs.consoles.iter().map(Proc::state)),
            consoles_ready,
            emulator: procs.emulator.state(),
            simulator: State::of_group(procs.simulators.iter().map(Proc::state)),
        };
        let was_interrupted = policy.interrupted();
        let o = policy.look(seen);
        if policy.interrupted() && !was_interrupted {
            eprintln!("stopping: console, then emulator, then simulator");
        }
        obey(&o, procs, &ready);
        if o.done {
            return policy.interrupted();
        }
    }
}

/// Carries out the supervisor's orders `o`; `ready` is each console's
/// mark that it streams.
fn obey(o: &crate::service::supervise::Orders, procs: &mut Procs, ready: &[PathBuf]) {
    if o.consoles_stalled {
        let what = format!("was not streaming {} s after its start", CONSOLE_READY.as_secs());
        procs.consoles.iter_mut().zip(ready).filter(|(p, r)| p.status.is_none() && !r.exists()).for_each(|(p, _)| p.stuck(&what));
    }
    if o.stop_console {
        procs.consoles.iter_mut().for_each(Proc::terminate);
    }
    if o.stop_emulator {
        procs.emulator.terminate();
    }
    if o.stop_simulator {
        procs.simulators.iter_mut().for_each(Proc::terminate);
    }
    if o.kill_all {
        for p in procs.all_mut() {
            if !p.poll() {
                if p.stuck.is_none() {
                    p.stuck("was still running at the run's hard deadline, and was killed");
                }
                let _ = p.child.kill();
            }
        }
        for p in procs.all_mut() {
            let _ = p.child.wait();
            p.poll();
        }
    }
}

/// The run's report: the services' reports joined; with several streams,
/// each stream's (also `<out>/stream-K/report.json`) and the total, under
/// stream 0's.
fn assemble(plan: &Plan, procs: &Procs, duration_s: f64, steal: crate::host::Steal, interrupted: bool) -> RunReport {
    if plan.streams.len() == 1 {
        let faults = procs.all().flat_map(Proc::faults).collect();
        let processes = procs.all().map(Proc::end).collect();
        return RunReport::assemble(plan, duration_s, steal, processes, faults, interrupted);
    }
    let mut lines = Vec::new();
    let mut reports = Vec::new();
    for (k, s) in plan.streams.iter().enumerate() {
        let own = [&procs.consoles[k], &procs.emulator, &procs.simulators[k]];
        let faults = own.iter().flat_map(|p| p.faults()).collect();
        let processes = own.iter().map(|p| p.end()).collect();
        let sp = Plan { run_id: s.run_id.clone(), out: s.out.clone(), spec: s.spec.clone(), seed: s.seed, scenario_path: s.scenario_path.clone(), ..plan.clone() };
        let mut r = RunReport::assemble(&sp, duration_s, steal, processes, faults, interrupted);
        if let Err(e) = serde_json::to_vec_pretty(&r).map_err(anyhow::Error::from).and_then(|j| Ok(std::fs::write(&r.files.report_json, j)?)) {
            r.faults.push(format!("writing {}: {e}", r.files.report_json.display()));
        }
        lines.push(crate::service::report::RunStream::of(k, &r));
        reports.push(r);
    }
    let mut top = reports.swap_remove(0);
    top.processes = procs.all().map(Proc::end).collect();
    top.faults = lines.iter().flat_map(|l| l.faults.iter().map(move |f| format!("stream {}: {f}", l.stream))).collect();
    top.files.report_json = plan.out.join("report.json");
    top.streams = Some(crate::service::report::RunStreams::of(lines));
    top
}

/// Runs a scenario end to end and returns its report (also written to
/// `<out>/report.json`). The report says whether every frame is accounted
/// for and which processes failed.
pub fn run(args: &RunArgs) -> Result<RunReport> {
    signals::install();
    let started = std::time::SystemTime::now();
    args.video.validate()?;
    anyhow::ensure!(!args.video.on() || args.stream.streams == 1, "--video-mbps goes with one stream: the video path is stream 0's, and --streams {} asks for more", args.stream.streams);
    let (plan, _lock) = prepare(args)?;
    let cores = plan.cores;
    // The runner itself wakes every few milliseconds to supervise and reaps
    // dead peers every 200 ms; on the emulator's core each wake-up would
    // preempt the emulator's loop. The services set their own placement.
    if let Some(e) = cores.emulator {
        crate::service::place("runner", None, Some(e))?;
    }
    eprintln!(
        "netfi run {}: scenario {} seed {}; cores: emulator {}, console {}, simulator {}; output {}",
        plan.run_id,
        plan.spec.name,
        plan.seed,
        cores.emulator.map_or("(not pinned)".into(), |c| c.to_string()),
        cores.console.map_or("(shared)".into(), |c| c.to_string()),
        cores.simulator.map_or("(shared)".into(), |c| c.to_string()),
        plan.out.display()
    );
    let steal_timer = StealTimer::start();
    let t0 = now_ns();
    let mut procs = start(&plan)?;
    let interrupted = supervise(&plan, &mut procs);
    let duration_s = (now_ns() - t0) as f64 / 1e9;
    let steal = steal_timer.stop();
    // An emulator that died while its core was cleared could not put back
    // what it moved; its record lets the runner do it.
    restore_orphans(Some(std::process::id() as i32));
    let run_ids: Vec<&str> = plan.streams.iter().map(|s| s.run_id.as_str()).collect();
    remove_half_created_nodes(&crate::transport::ipc::user_root_dir().join("nodes"), &run_ids);
    // The emulator read its own copies at its start; the ones kept are scenario.toml.
    for s in &plan.streams {
        let _ = std::fs::remove_file(own_scenario(&s.out, &s.run_id));
    }
    let mut report = assemble(&plan, &procs, duration_s, steal, interrupted);
    report.provenance = Some(crate::service::report::Provenance::capture(started, plan.seed));
    // A report that cannot be written (a full disk) is a fault of the run;
    // the report is still returned, for stdout.
    let json = serde_json::to_vec_pretty(&report)?;
    let mut paths = vec![report.files.report_json.clone()];
    paths.extend(args.report_json.clone());
    for path in paths {
        if let Err(e) = std::fs::write(&path, &json) {
            report.faults.push(format!("writing {}: {e}", path.display()));
        }
    }
    Ok(report)
}

/// Once every process of the run has ended: removes the nodes of the
/// runs `run_ids` in iceoryx2's node directory `nodes` that a process left
/// half created (its node's details written, its monitor not: killed, or
/// stopped while iceoryx2 synced the details to a busy disk). iceoryx2
/// neither lists nor cleans such a node; a node alive or killed later on
/// has its monitor, and is left to the reaping of dead peers.
fn remove_half_created_nodes(nodes: &Path, run_ids: &[&str]) {
    use crate::transport::{IpcConfig, RunId};
    let prefixes: Vec<String> = run_ids.iter().filter_map(|r| RunId::new(r).ok()).map(|r| IpcConfig::new(r).prefix().to_string()).collect();
    let Ok(rd) = std::fs::read_dir(nodes) else { return };
    for e in rd.filter_map(|e| e.ok()) {
        let id = e.file_name().to_string_lossy().into_owned();
        let half = |p: &String| e.path().join(format!("{p}node.details")).exists() && !nodes.join(format!("{p}{id}.node_monitor")).exists();
        if e.file_type().is_ok_and(|t| t.is_dir()) && prefixes.iter().any(half) && std::fs::remove_dir_all(e.path()).is_ok() {
            eprintln!("removed the half-created iceoryx2 node {id} of a process of this run");
        }
    }
}

/// Restores the host-wide records of cleared cores whose owners (but
/// `except`) are all gone, saying what was done.
fn restore_orphans(except: Option<i32>) {
    match crate::host::record::restore_orphans(except) {
        Ok(done) => {
            for (path, r) in done {
                eprintln!("restored {} placement(s) a killed process left moved ({} threads widened), from {}", r.undone, r.widened, path.display());
            }
        }
        Err(e) => eprintln!("WARNING: could not look for cleared cores left by killed runs: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_runs_half_created_nodes_are_removed() {
        let nodes = std::env::temp_dir().join(format!("netfi-half-nodes-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&nodes);
        let prefix = |run: &str| crate::transport::IpcConfig::new(crate::transport::RunId::new(run).unwrap()).prefix().to_string();
        let node = |id: &str, run: &str, monitor: bool| {
            std::fs::create_dir_all(nodes.join(id)).unwrap();
            std::fs::write(nodes.join(id).join(format!("{}node.details", prefix(run))), b"").unwrap();
            if monitor {
                std::fs::write(nodes.join(format!("{}{id}.node_monitor", prefix(run))), b"").unwrap();
            }
        };
        node("11", "r1", false);
        node("12", "r1-s1", false);
        node("13", "r1", true);
        node("14", "r2", false);
        remove_half_created_nodes(&nodes, &["r1", "r1-s1"]);
        let left = |id: &str| nodes.join(id).exists();
        assert!(!left("11") && !left("12"), "the run's half-created nodes stay");
        assert!(left("13"), "a node with its monitor is not this function's");
        assert!(left("14"), "another run's node was removed");
        std::fs::remove_dir_all(&nodes).unwrap();
    }
}
