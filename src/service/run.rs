//! `netfi run`: starts the simulator, the emulator and the console as three
//! processes on one host, waits for the stream to end, and joins their
//! reports into one.
//!
//! The children run in their own process group, so Ctrl-C reaches only the
//! runner, which then stops them in order (console, emulator, simulator) so
//! that every report and the trace are flushed. A child that dies is reported
//! as a fault; the others keep going until the planned end.

use crate::clock::now_ns;
use crate::host::StealTimer;
use crate::scenario::{self, Scenario};
use crate::service::args::RunArgs;
use crate::service::console::ConsoleReport;
use crate::service::emulator::EmulatorReport;
use crate::service::report::{self, DelayCheck, DelayQuantile, Files, Overhead, ProcessEnd, RunReport};
use crate::service::signals;
use crate::service::simulator::SimulatorReport;
use anyhow::{bail, Context, Result};
use std::io::{BufRead, Write};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Default release-queue capacity: 65,536 frames (65 s at 1 kHz).
pub const DEFAULT_QUEUE_CAPACITY: usize = 1 << 16;

/// A seed for runs given none: from the time and the process id.
pub fn fresh_seed() -> u64 {
    let t = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(0);
    scenario::splitmix64(t ^ (u64::from(std::process::id()) << 32))
}

/// A fresh run id: `r` + 10 hex digits.
pub fn fresh_run_id() -> String {
    format!("r{:010x}", fresh_seed() & 0xff_ffff_ffff)
}

struct Proc {
    role: &'static str,
    child: Child,
    core: Option<usize>,
    log: PathBuf,
    status: Option<std::process::ExitStatus>,
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

    fn died(&self) -> Option<String> {
        let s = self.status?;
        if s.success() {
            None
        } else {
            Some(format!("{} ended abnormally ({}); see {}", self.role, self.status_text(), self.log.display()))
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
    Ok(Proc { role, child, core, log, status: None })
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

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Option<T> {
    let bytes = std::fs::read(path).ok()?;
    serde_json::from_slice(&bytes).ok()
}

/// Runs a scenario end to end and returns its report (also written to
/// `<out>/report.json`). The report says whether every frame is accounted
/// for and which processes failed.
pub fn run(args: &RunArgs) -> Result<RunReport> {
    signals::install();
    let spec = scenario::resolve(&args.scenario)?;
    let seed = args.seed.or(spec.seed).unwrap_or_else(fresh_seed);
    // Validate the scenario here, so a bad one fails before any process starts.
    Scenario::new(&spec, seed)?;
    let run_id = args.run_id.clone().unwrap_or_else(fresh_run_id);
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from("out").join(&run_id));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    for stale in [
        "console.ready", "emulator.ready", "simulator.ready", "console.json", "emulator.json", "simulator.json", "console.pid", "emulator.pid",
        "simulator.pid",
    ] {
        let _ = std::fs::remove_file(out.join(stale));
    }
    // What killed runs left cleared (their owners and guardian all dead)
    // is put back before anything else, as `netfi restore` does.
    restore_orphans(None);
    let scenario_path = out.join("scenario.toml");
    std::fs::write(&scenario_path, spec.to_toml()).with_context(|| format!("writing {}", scenario_path.display()))?;
    let cleaned = crate::service::ipc::cleanup_stale()?;
    if cleaned > 0 {
        eprintln!("removed resources of {cleaned} dead process(es) of earlier runs");
    }

    let rate_hz = args.rate_hz.unwrap_or(1000.0);
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        bail!("--rate-hz must be a positive number, got {rate_hz}");
    }
    let (planned_s, expected_frames) = match (&args.capture, args.frames, args.duration_s) {
        (_, Some(n), _) => (n as f64 / rate_hz, n),
        (_, None, Some(d)) => (d, (d * rate_hz).ceil() as u64),
        (Some(_), None, None) if args.rate_hz.is_none() => (90.0, 50_000),
        (Some(_), None, None) => (60.0, (60.0 * rate_hz) as u64),
        (None, None, None) => (10.0, (10.0 * rate_hz) as u64),
    };
    // Placement: the emulator busy-waits on a core of its own (the last). With
    // four cores or more the console and the simulator get one each too;
    // with fewer they share the rest, and are kept off the emulator's core.
    let cores: Vec<usize> = core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).collect();
    // A pin that cannot be honoured is an error when asked for, and a loud
    // warning (also in the report's isolation line) otherwise.
    if let Some(c) = args.emulator_core.filter(|c| !cores.contains(c)) {
        bail!("--emulator-core {c}: this process may only run on CPU(s) {:?} (an inherited CPU mask: `taskset`?)", cores);
    }
    if let (None, Some(w)) = (args.emulator_core, crate::host::isolate::pin_problem()) {
        eprintln!("WARNING: {w}");
    }
    let emulator_core = args.emulator_core.or((cores.len() >= 2).then(|| cores[cores.len() - 1]));
    let (console_core, simulator_core) = match (args.console_core, args.simulator_core) {
        (None, None) if cores.len() >= 4 && args.emulator_core.is_none() => (Some(cores[cores.len() - 3]), Some(cores[cores.len() - 2])),
        given => given,
    };
    // The runner itself wakes every few milliseconds to supervise and reaps
    // dead peers every 200 ms; on the emulator's core each wake-up would
    // preempt the emulator's loop. The services set their own placement.
    if let Some(e) = emulator_core {
        crate::service::place("runner", None, Some(e))?;
    }
    eprintln!(
        "netfi run {run_id}: scenario {} seed {seed}; cores: emulator {}, console {}, simulator {}; output {}",
        spec.name,
        emulator_core.map_or("(not pinned)".into(), |c| c.to_string()),
        console_core.map_or("(shared)".into(), |c| c.to_string()),
        simulator_core.map_or("(shared)".into(), |c| c.to_string()),
        out.display()
    );

    let s = |x: &dyn ToString| x.to_string();
    let out_s = out.display().to_string();
    let mut sim_args = vec![s(&"--run-id"), run_id.clone(), s(&"--out"), out_s.clone()];
    match (simulator_core, emulator_core) {
        (Some(c), _) => sim_args.extend([s(&"--core"), c.to_string(), s(&"--spin")]),
        (None, Some(e)) => sim_args.extend([s(&"--avoid-core"), e.to_string()]),
        (None, None) => {}
    }
    if args.drop_bad_checksum {
        sim_args.push(s(&"--drop-bad-checksum"));
    }
    let mut emu_args = vec![
        s(&"--run-id"),
        run_id.clone(),
        s(&"--scenario"),
        scenario_path.display().to_string(),
        s(&"--seed"),
        seed.to_string(),
        s(&"--out"),
        out_s.clone(),
        s(&"--expected-frames"),
        expected_frames.to_string(),
    ];
    match emulator_core {
        Some(c) => emu_args.extend([s(&"--core"), c.to_string()]),
        None => emu_args.push(s(&"--no-pin")),
    }
    if let Some(q) = args.queue_capacity {
        emu_args.extend([s(&"--queue-capacity"), q.to_string()]);
    }
    if let Some(p) = args.rt_priority {
        emu_args.extend([s(&"--rt-priority"), p.to_string()]);
    }
    // The emulator's core is cleared unless asked not to (`isolate` only
    // restates the default).
    if !args.no_isolate {
        emu_args.push(s(&"--isolate"));
    }
    if args.drop_bad_checksum {
        emu_args.push(s(&"--drop-bad-checksum"));
    }
    let mut con_args = vec![s(&"--run-id"), run_id.clone(), s(&"--out"), out_s.clone(), s(&"--seed"), seed.to_string()];
    if let Some(r) = args.rate_hz {
        con_args.extend([s(&"--rate-hz"), r.to_string()]);
    }
    if let Some(n) = args.frames {
        con_args.extend([s(&"--frames"), n.to_string()]);
    }
    if let Some(d) = args.duration_s {
        con_args.extend([s(&"--duration-s"), d.to_string()]);
    }
    if let Some(c) = &args.capture {
        con_args.extend([s(&"--capture"), c.display().to_string()]);
    }
    if args.no_direct {
        con_args.push(s(&"--no-direct"));
    }
    match (console_core, emulator_core) {
        (Some(c), _) => con_args.extend([s(&"--core"), c.to_string()]),
        (None, Some(e)) => con_args.extend([s(&"--avoid-core"), e.to_string()]),
        (None, None) => {}
    }

    let steal_timer = StealTimer::start();
    let t0 = now_ns();
    let mut sim = spawn("simulator", sim_args, simulator_core, &out)?;
    wait_ready(&mut sim, &out, Duration::from_secs(30))?;
    let mut emu = match spawn("emulator", emu_args, emulator_core, &out) {
        Ok(p) => p,
        Err(e) => {
            sim.terminate();
            return Err(e);
        }
    };
    if let Err(e) = wait_ready(&mut emu, &out, Duration::from_secs(30)) {
        sim.terminate();
        return Err(e);
    }
    let mut con = match spawn("console", con_args, console_core, &out) {
        Ok(p) => p,
        Err(e) => {
            emu.terminate();
            sim.terminate();
            return Err(e);
        }
    };

    // Supervise: poll the children; stop them in pipeline order.
    let started = Instant::now();
    let planned = Duration::from_secs_f64(planned_s + 1.0);
    // Time for the emulator to release what it holds after the console ends:
    // the longest delay the scenario can realistically inject, generously.
    let drain_grace = Duration::from_secs(30);
    let hard_deadline = planned + drain_grace + Duration::from_secs(60);
    let mut interrupted = false;
    let mut console_done_at: Option<Instant> = None;
    // The runner reaps the run's dead processes, off the emulator's core, so
    // the survivors see their peer counts drop and a restarted peer can take
    // over its port.
    let ipc = crate::transport::RunId::new(&run_id).ok().map(crate::transport::IpcConfig::new);
    let mut last_reap = Instant::now();
    let mut emulator_done_at: Option<Instant> = None;
    loop {
        std::thread::sleep(Duration::from_millis(5));
        let (c, e, m) = (con.poll(), emu.poll(), sim.poll());
        if last_reap.elapsed() > Duration::from_millis(200) {
            last_reap = Instant::now();
            if let Some(cfg) = &ipc {
                if let Ok(r) = crate::transport::cleanup_dead_nodes(cfg) {
                    for dead in r.dead() {
                        eprintln!("reaped a dead peer: {dead}");
                    }
                }
            }
        }
        if signals::stop_requested() && !interrupted {
            interrupted = true;
            eprintln!("stopping: console, then emulator, then simulator");
            con.terminate();
        }
        if c && console_done_at.is_none() {
            console_done_at = Some(Instant::now());
        }
        if e && emulator_done_at.is_none() {
            emulator_done_at = Some(Instant::now());
        }
        if c && m && e {
            break;
        }
        // The console ended abnormally: the others keep going to the planned
        // end, then the emulator is stopped.
        let console_failed = c && !con.status.is_some_and(|s| s.success());
        if !e && (interrupted && c || console_failed && started.elapsed() >= planned) {
            emu.terminate();
        }
        // The console ended normally but the emulator has not finished
        // draining in time.
        if !e && console_done_at.is_some_and(|t| t.elapsed() > drain_grace) {
            emu.terminate();
        }
        // The emulator is gone: the simulator will get no end marker.
        if e && !m && (emu.died().is_some() || emulator_done_at.is_some_and(|t| t.elapsed() > Duration::from_secs(5))) {
            sim.terminate();
        }
        // The emulator is gone and the console still streams into nothing:
        // let it reach the planned end, then stop it.
        if e && !c && (interrupted || started.elapsed() >= planned) {
            con.terminate();
        }
        if started.elapsed() > hard_deadline {
            for p in [&mut con, &mut emu, &mut sim] {
                if !p.poll() {
                    let _ = p.child.kill();
                }
            }
            let _ = (con.child.wait(), emu.child.wait(), sim.child.wait());
            let _ = (con.poll(), emu.poll(), sim.poll());
            break;
        }
    }
    let duration_s = (now_ns() - t0) as f64 / 1e9;
    let steal = steal_timer.stop();
    // An emulator that died while its core was cleared could not put back
    // what it moved; its record lets the runner do it.
    restore_orphans(Some(std::process::id() as i32));

    let console: Option<ConsoleReport> = read_json(&out.join("console.json"));
    let emulator: Option<EmulatorReport> = read_json(&out.join("emulator.json"));
    let simulator: Option<SimulatorReport> = read_json(&out.join("simulator.json"));
    let mut faults: Vec<String> = [&con, &emu, &sim].iter().filter_map(|p| p.died()).collect();
    for (role, missing) in [("console", console.is_none()), ("emulator", emulator.is_none()), ("simulator", simulator.is_none())] {
        if missing {
            faults.push(format!("no report from the {role}"));
        }
    }
    let frames = report::account(console.as_ref(), emulator.as_ref(), simulator.as_ref());
    if let Some(n) = frames.lost_before_emulator.filter(|n| *n > 0) {
        faults.push(format!("{n} frames sent by the console never entered the emulator"));
    }
    if let Some(n) = frames.lost_after_emulator.filter(|n| *n > 0) {
        faults.push(format!("{n} frames released by the emulator never reached the simulator"));
    }
    if interrupted {
        faults.push("interrupted (Ctrl-C / SIGTERM)".into());
    }

    // The trace: the emulator's rows joined with the simulator's receive times.
    let mut delays = Delays::default();
    let trace = match merge_trace(&out, &mut delays) {
        Ok(p) => p,
        Err(e) => {
            faults.push(format!("trace not written: {e:#}"));
            None
        }
    };

    let ingress_wait = emulator.as_ref().map(|e| e.ingress_wait_ns);
    let decision = emulator.as_ref().map(|e| e.decision_ns);
    let release_lateness = emulator.as_ref().map(|e| e.release_lateness_ns);
    let end_to_end_extra = simulator.as_ref().map(|s| s.end_to_end_extra_ns).filter(|p| p.count > 0);
    let direct_hop = simulator.as_ref().map(|s| s.direct_hop_ns).filter(|p| p.count > 0);
    let added_over_direct = end_to_end_extra.as_ref().zip(direct_hop.as_ref()).map(|(a, b)| report::difference(a, b));
    let delay_check = delay_check(&spec, seed, delays);
    let report_json = out.join("report.json");
    let report = RunReport {
        delay_check,
        run_id: run_id.clone(),
        scenario: spec.name.clone(),
        seed,
        duration_s,
        frames,
        loss_rate: emulator.as_ref().map(|e| e.loss_rate),
        loss_rate_ci95: emulator.as_ref().map(|e| e.loss_rate_ci95),
        stages: emulator.as_ref().map(|e| e.stages.clone()).unwrap_or_default(),
        injected_delay_ns: emulator.as_ref().map(|e| e.injected_delay_ns),
        overhead_ns: Overhead { ingress_wait, decision, release_lateness, end_to_end_extra, direct_hop, added_over_direct },
        kinematics: simulator.as_ref().and_then(|s| s.kinematics.clone()),
        processes: [&con, &emu, &sim]
            .iter()
            .map(|p| ProcessEnd { role: p.role.into(), pid: p.child.id(), core: p.core, status: p.status_text(), log: p.log.clone() })
            .collect(),
        faults,
        peer_events: emulator.as_ref().map(|e| e.peer_events.clone()).unwrap_or_default(),
        steal,
        files: Files {
            out_dir: out.clone(),
            scenario: scenario_path,
            trace,
            decision_hlog: emulator.as_ref().and_then(|e| e.decision_hlog.clone()),
            lateness_hlog: emulator.as_ref().and_then(|e| e.lateness_hlog.clone()),
            end_to_end_hlog: simulator.as_ref().and_then(|s| s.end_to_end_hlog.clone()),
            report_json: report_json.clone(),
        },
        console,
        emulator,
        simulator,
    };
    let json = serde_json::to_vec_pretty(&report)?;
    std::fs::write(&report_json, &json).with_context(|| format!("writing {}", report_json.display()))?;
    if let Some(extra) = &args.report_json {
        std::fs::write(extra, &json).with_context(|| format!("writing {}", extra.display()))?;
    }
    Ok(report)
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

/// Per delivered and received frame: the injected delay and the delay the
/// simulator saw (receive − console send), in ns.
#[derive(Debug, Default)]
struct Delays {
    injected: Vec<u64>,
    seen: Vec<u64>,
}

/// Joins `trace_emulator.csv` with `received.csv` into `trace.csv`, and
/// collects the delays of the frames that made it through.
fn merge_trace(out: &Path, delays: &mut Delays) -> Result<Option<PathBuf>> {
    let emu = out.join("trace_emulator.csv");
    if !emu.exists() {
        return Ok(None);
    }
    let mut recv: Vec<u64> = Vec::new();
    if let Ok(f) = std::fs::File::open(out.join("received.csv")) {
        for line in std::io::BufReader::new(f).lines().skip(1) {
            let line = line?;
            let mut it = line.split(',');
            if let (Some(Ok(i)), Some(Ok(t))) = (it.next().map(str::parse::<usize>), it.next().map(str::parse::<u64>)) {
                if recv.len() <= i {
                    recv.resize(i + 1, 0);
                }
                recv[i] = t;
            }
        }
    }
    let path = out.join("trace.csv");
    let mut w = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(&path)?);
    for (n, line) in std::io::BufReader::new(std::fs::File::open(&emu)?).lines().enumerate() {
        let line = line?;
        if n == 0 {
            writeln!(w, "{line}")?;
            continue;
        }
        let cols: Vec<&str> = line.split(',').collect();
        let index: usize = cols[0].parse().unwrap_or(usize::MAX);
        match recv.get(index).filter(|t| **t != 0) {
            Some(t) => {
                writeln!(w, "{line}{t}")?;
                // Columns: 3 send_ns, 9 delay_ns (see `trace`).
                if let (Some(Ok(send)), Some(Ok(delay))) = (cols.get(3).map(|x| x.parse::<u64>()), cols.get(9).map(|x| x.parse::<u64>())) {
                    delays.injected.push(delay);
                    delays.seen.push(t.saturating_sub(send));
                }
            }
            None => writeln!(w, "{line}")?,
        }
    }
    w.flush()?;
    std::fs::remove_file(&emu)?;
    Ok(Some(path))
}

/// Quantiles of the delays the simulator saw against the delays the
/// emulator drew and, when the scenario is a single `reorder` delay stage
/// (possibly behind loss stages), against the model's analytic law.
fn delay_check(spec: &scenario::ScenarioSpec, seed: u64, mut d: Delays) -> Option<DelayCheck> {
    let n = d.seen.len();
    if n < 100 || d.injected.iter().all(|x| *x == 0) {
        return None;
    }
    d.injected.sort_unstable();
    d.seen.sort_unstable();
    let model = Scenario::new(spec, seed).ok().and_then(|sc| {
        let [phase] = sc.phases() else { return None };
        let delays: Vec<_> = phase.stages().iter().filter_map(|s| match s.model() {
            crate::model::AnyModel::Delay(m) => Some(m.clone()),
            _ => None,
        }).collect();
        match delays.as_slice() {
            [one] if one.may_reorder() || one.cdf_ms(one.mean_ms_exact()) >= 0.0 => Some(one.clone()),
            _ => None,
        }
    });
    // Dvoretzky–Kiefer–Wolfowitz: with 95% confidence the empirical
    // distribution is within ε of the true one everywhere.
    let eps = ((2.0f64 / 0.05).ln() / (2.0 * n as f64)).sqrt();
    let pick = |v: &[u64], q: f64| v[((q * n as f64) as usize).min(n - 1)] as f64 / 1e6;
    let quantiles: Vec<DelayQuantile> = [0.01, 0.1, 0.25, 0.5, 0.75, 0.9, 0.99]
        .into_iter()
        .map(|q| {
            let (injected_ms, seen_ms) = (pick(&d.injected, q), pick(&d.seen, q));
            let model_ms = model.as_ref().map(|m| m.quantile_ms(q));
            let model_band_ms = model.as_ref().map(|m| [m.quantile_ms((q - eps).max(1e-9)), m.quantile_ms((q + eps).min(1.0 - 1e-9))]);
            DelayQuantile { q, model_ms, model_band_ms, injected_ms, seen_ms, seen_minus_injected_us: (seen_ms - injected_ms) * 1e3 }
        })
        .collect();
    let worst = quantiles.iter().map(|x| x.seen_minus_injected_us.abs()).fold(0.0, f64::max);
    let injected_within_model_band = model.as_ref().map(|_| {
        quantiles.iter().all(|x| x.model_band_ms.is_some_and(|[lo, hi]| lo <= x.injected_ms && x.injected_ms <= hi))
    });
    Some(DelayCheck { frames: n as u64, dkw_epsilon: eps, quantiles, max_abs_seen_minus_injected_us: worst, injected_within_model_band })
}
