//! `netfi run`: starts the simulator, the emulator and the console as three
//! processes on one host, waits for the stream to end, and joins their
//! reports into one.
//!
//! Every scenario is resolved and every seed decided once, here and in the
//! [`Plan`]; the processes are told, and derive nothing. When to stop which
//! process is the [`Supervisor`](crate::service::supervise::Supervisor)'s
//! policy; the report is assembled from what the services wrote.
//!
//! | file | what |
//! |---|---|
//! | `procs` | the processes: started, signalled, never left behind |
//! | `watch` | the watch over them, carrying out the supervisor's orders |
//! | `outdir` | the output directory: lock, scenarios, leftovers |
//! | `assemble` | the report, joined and written |
//!
//! The children run in their own process group, so Ctrl-C reaches only the
//! runner, which then stops them in order (console, emulator, simulator) so
//! that every report and the trace are flushed. A child that dies ends the
//! run: the others are stopped at once, the host restored, and the report
//! names the dead. A child dies with its runner (a parent-death signal),
//! and a runner that fails or panics stops its children first.

mod assemble;
mod error;
mod outdir;
mod procs;
mod watch;

pub use crate::service::plan::{fresh_run_id, fresh_seed, DEFAULT_QUEUE_CAPACITY};
pub use error::RunnerError;
pub use outdir::{OutDirLock, LOCK_FILE};

use crate::clock::now_ns;
use crate::host::StealTimer;
use crate::scenario::{Scenario, ScenarioSpec};
use crate::service::args::RunArgs;
use crate::service::plan::{Plan, Resolved, Seeds};
use crate::service::report::RunReport;
use crate::service::args::streams;
use crate::service::{seeds, signals};
use crate::service::emulator::opening::PathScenarioError;

type Result<T> = std::result::Result<T, RunnerError>;

/// A reverse path's scenario (`flag`'s, default Normal: nothing injected).
fn resolve_path(flag: &'static str, name: Option<&str>) -> Result<ScenarioSpec> {
    let name = name.unwrap_or("Normal");
    crate::load::resolve(name).map_err(|cause| PathScenarioError { flag, name: name.into(), cause }.into())
}

/// Every scenario of the run, resolved once and checked with its seed
/// (so a bad one fails before any process starts), each stream's run id
/// checked; and the run's seed.
fn resolve(args: &RunArgs, run_id: &str) -> Result<(Resolved, u64)> {
    // Anchored: the emulator reads its copy in the output directory, and
    // the files the stages name are where the scenario file is.
    let spec = crate::load::resolve_anchored(&args.scenario.scenario)?;
    let seed = seeds::run(args.scenario.seed, &spec);
    let mut specs = vec![spec; args.stream.streams as usize];
    for (k, what) in args.stream.named_scenarios()? {
        specs[k] = crate::load::resolve_anchored(&what).map_err(|cause| RunnerError::StreamScenario { stream: k, what: what.clone(), cause })?;
    }
    for (k, s) in specs.iter().enumerate() {
        Scenario::new(s, seeds::stream(seed, k)).map_err(|e| RunnerError::StreamSeed(k, e))?;
        crate::transport::RunId::new(&streams::run_id(run_id, k)).map_err(|e| RunnerError::StreamRunId(k, e))?;
    }
    let p = &args.peers;
    let shape = crate::service::channel::LaneShape { ingress: &p.ends.ingress, egress: &p.ends.egress, transports: &p.transports, streams: args.stream.streams };
    let paths = args.channels.wants(&shape).into_iter().map(|(c, w)| Ok((c, resolve_path(w.flag, w.scenario.as_deref())?, w))).collect::<Result<Vec<_>>>()?;
    let paths = paths.into_iter().map(|(c, spec, w)| (c, w, spec)).collect();
    Ok((Resolved { streams: specs, paths }, seed))
}

/// Checks the reverse paths' scenarios with the seeds decided for them.
fn check_paths(r: &Resolved, s: &Seeds) -> Result<()> {
    for (c, w, spec) in &r.paths {
        Scenario::new(spec, s.paths[c]).map_err(|cause| PathScenarioError { flag: w.flag, name: spec.name.clone(), cause })?;
    }
    Ok(())
}

/// A run readied: its plan, its directories (each marked unfinished) and
/// its lock on them, and what the run's report is to note.
struct Prepared {
    plan: Plan,
    dirs: outdir::Dirs,
    _lock: OutDirLock,
    notes: Vec<String>,
}

/// Resolves the scenarios and the seeds, plans the run, and readies its
/// output directory: refused if another user's, locked for this run, stale
/// files of an earlier run there removed (its report, replaced, noted),
/// marked unfinished, what an earlier emulator left moved put back, the
/// scenarios written, dead processes' iceoryx2 resources removed.
fn prepare(args: &RunArgs) -> Result<Prepared> {
    let run_id = args.run_id.clone().unwrap_or_else(fresh_run_id);
    let (resolved, seed) = resolve(args, &run_id)?;
    let host_cores = crate::host::allowed_cores();
    // A pin that cannot be honoured is an error when asked for, and a loud
    // warning (also in the report's isolation line) otherwise.
    args.placement.check_cores(&host_cores)?;
    for w in args.placement.shared_core_warnings() {
        eprintln!("{w}");
    }
    if let (None, Some(w)) = (args.placement.emulator.core, crate::host::isolate::pin_problem()) {
        eprintln!("WARNING: {w}");
    }
    let plan = Plan::new(args, &resolved, seed, run_id, &host_cores)?;
    check_paths(&resolved, &plan.seeds)?;
    std::fs::create_dir_all(&plan.out).map_err(|e| RunnerError::Create(plan.out.clone(), e))?;
    let out = outdir::open_checked(&plan.out, args.out_owned_by_other)?;
    let lock = OutDirLock::take(&out)?;
    let dirs = outdir::Dirs::open(&plan, out)?;
    let notes = dirs.clear_and_mark(&plan.run_id)?;
    // What killed runs left (their owners and guardian all dead) is ended
    // and put back before anything else, as `netfi restore` does.
    if let Err(e) = crate::host::record::end_orphaned_runs() {
        eprintln!("WARNING: could not end what earlier runs left running: {e}");
    }
    restore_orphans(None);
    outdir::write_scenarios(&plan.streams)?;
    let cleaned = crate::transport::cleanup_stale()?;
    if cleaned > 0 {
        eprintln!("removed resources of {cleaned} dead process(es) of earlier runs");
    }
    // Before any process starts: names already taken would fail a service
    // only once the others are up.
    for s in &plan.streams {
        let files = crate::transport::names_taken(&s.run_id);
        if !files.is_empty() {
            return Err(RunnerError::NamesTaken { run_id: s.run_id.clone(), files }.into());
        }
    }
    Ok(Prepared { plan, dirs, _lock: lock, notes })
}

/// Where netfi's own end runs, or that the lab's program plays it.
fn end(own: bool, core: Option<usize>) -> String {
    match (own, core) {
        (false, _) => "(the lab's)".into(),
        (true, None) => "(shared)".into(),
        (true, Some(c)) => c.to_string(),
    }
}

/// Keeps the runner off the emulator's core and says what runs where.
fn announce(plan: &Plan) -> Result<()> {
    let cores = plan.cores;
    // The runner itself wakes every few milliseconds to supervise and reaps
    // dead peers every 200 ms; on the emulator's core each wake-up would
    // preempt the emulator's loop. The services set their own placement.
    if let Some(e) = cores.emulator {
        crate::host::placement::place("runner", None, Some(e))?;
    }
    eprintln!(
        "netfi run {}: scenario {} seed {}; cores: emulator {}, console {}, simulator {}; output {}",
        plan.run_id,
        plan.spec.name,
        plan.seed,
        cores.emulator.map_or("(not pinned)".into(), |c| c.to_string()),
        end(plan.streams[0].console.is_some(), cores.console),
        end(plan.streams[0].simulator.is_some(), cores.simulator),
        plan.out.display()
    );
    Ok(())
}

/// Puts back what the run's processes left moved when the runner leaves
/// early (an error, a panic), once its processes have been stopped: it is
/// declared before them, so it is dropped after them.
struct RestoreOnLeaving {
    armed: bool,
}

impl Drop for RestoreOnLeaving {
    fn drop(&mut self) {
        if self.armed {
            restore_orphans(Some(std::process::id() as i32));
        }
    }
}

/// Runs a scenario end to end and returns its report (also written to
/// `<out>/report.json`). The report says whether every frame is accounted
/// for and which processes failed.
pub fn run(args: &RunArgs) -> Result<RunReport> {
    signals::install();
    let started = std::time::SystemTime::now();
    args.validate()?;
    let Prepared { plan, dirs, _lock, notes } = prepare(args)?;
    announce(&plan)?;
    let steal_timer = StealTimer::start();
    let t0 = now_ns();
    let mut restore = RestoreOnLeaving { armed: true };
    let mut guard = guard_run(&plan);
    let mut procs = procs::start(&plan, &mut guard)?;
    let interrupted = watch::supervise(&plan, &mut procs);
    procs.all_mut().for_each(procs::Proc::settle_log);
    let duration_s = (now_ns() - t0) as f64 / 1e9;
    let steal = steal_timer.stop();
    // An emulator that died while its core was cleared could not put back
    // what it moved; its record lets the runner do it.
    restore.armed = false;
    restore_orphans(Some(std::process::id() as i32));
    let run_ids: Vec<&str> = plan.streams.iter().map(|s| s.run_id.as_str()).collect();
    outdir::remove_half_created_nodes(&crate::transport::ipc::user_root_dir().join("nodes"), &run_ids);
    outdir::remove_own_scenarios(&plan.streams);
    let mut report = assemble::assemble(&plan, &procs, duration_s, steal, interrupted);
    report.provenance = Some(crate::service::report::Provenance::capture(started, plan.seed));
    report.notes = notes;
    let paths: Vec<_> = std::iter::once(report.files.report_json.clone()).chain(args.report_json.clone()).collect();
    assemble::write(&mut report, &paths);
    dirs.finished();
    Ok(report)
}

/// The record of the run's processes, watched by a guardian that ends them
/// should the runner be killed; a warning where it cannot be had.
fn guard_run(plan: &Plan) -> Option<crate::host::guardian::RunGuard> {
    let run_ids: Vec<&str> = plan.streams.iter().map(|s| s.run_id.as_str()).collect();
    match crate::host::guardian::RunGuard::start(&run_ids) {
        Ok(g) => {
            g.warnings().iter().for_each(|w| eprintln!("WARNING: {w}"));
            Some(g)
        }
        Err(e) => {
            eprintln!("WARNING: no record of the run's processes ({e}): if the runner is killed, they end by the parent-death signal only");
            None
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
