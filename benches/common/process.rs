//! The `netfi` binaries as processes: a build ([`Build`]: `netfi run`, and
//! `netfi emulator` started and stopped by the benchmark), their reports
//! read back as JSON, tolerant of fields an older build does not write.
//!
//! Everything here goes through the command line and the files a run
//! writes, not through the library: a benchmark can time a build of
//! another commit beside this one. The command lines are this build's
//! arguments rendered ([`RunArgs`], [`EmulatorArgs`]): only what differs
//! from the defaults, which a build of another commit reads the same.

use crate::common::args::{check_interrupted, stopped, Common, Cores, Placement, NETFI};
use crate::common::out::Out;
use anyhow::{bail, Context, Result};
use netfi::metrics::Summary;
use netfi::service::args::{EmulatorArgs, EndsArgs, RunArgs};
use netfi::transport::udp::UdpArgs;
use serde::Serialize;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// A `netfi` build: its binary (the services are its subcommands; the
/// stand-alone `netfi-console`, `netfi-emulator` and `netfi-simulator` of
/// the same build sit beside it).
#[derive(Debug, Clone, Serialize)]
pub struct Build {
    pub label: String,
    pub netfi: PathBuf,
    /// `netfi --version`.
    pub version: String,
    /// The binary's modification time, seconds since 1970: which build it is.
    pub modified_unix_s: Option<u64>,
    /// Whether `netfi-emulator` sits beside it.
    pub services_beside: bool,
}

impl Build {
    /// The build at `path`, else the one this package builds.
    pub fn new(label: &str, path: Option<&Path>) -> Result<Build> {
        let netfi = path.map_or_else(|| PathBuf::from(NETFI), Path::to_path_buf);
        let meta = std::fs::metadata(&netfi).with_context(|| format!("{label}: no netfi binary at {}", netfi.display()))?;
        let out = Command::new(&netfi).arg("--version").output().with_context(|| format!("running {} --version", netfi.display()))?;
        let version = String::from_utf8_lossy(&out.stdout).trim().to_string();
        let modified_unix_s = meta.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok()).map(|d| d.as_secs());
        let services_beside = netfi.with_file_name("netfi-emulator").exists();
        Ok(Build { label: label.to_string(), netfi, version, modified_unix_s, services_beside })
    }

    /// `netfi run SCENARIO` at `rate_hz` for `seconds` (seed 1) writing to
    /// `dir`, with `extra` flags (as given, for every build); its
    /// `report.json`. The per-frame files are removed after (large at high
    /// rates).
    pub fn run(&self, dir: &Path, scenario: &str, rate_hz: f64, seconds: f64, extra: &[String]) -> Result<Value> {
        let mut run = RunArgs::new(scenario);
        run.source.rate_hz = Some(rate_hz);
        run.source.duration_s = Some(seconds);
        run.scenario.seed = Some(1);
        run.out = Some(dir.to_path_buf());
        let mut cmd = Command::new(&self.netfi);
        cmd.arg("run").args(run.to_argv()).args(extra);
        let status = wait(spawn_logged(cmd, &dir.join("run.log"))?)?;
        check_interrupted()?;
        let report = read_json(&dir.join("report.json")).with_context(|| format!("netfi run ({}: {status}); see {}", self.label, dir.join("run.log").display()))?;
        for big in ["trace.csv", "received.csv"] {
            let _ = std::fs::remove_file(dir.join(big));
        }
        Ok(report)
    }

    /// This package's build (or `netfi`'s), and `baseline` beside it when
    /// given: the builds a before/after program times.
    pub fn pair(netfi: Option<&Path>, baseline: Option<&Path>) -> Result<Vec<Build>> {
        let mut builds = vec![Build::new("netfi", netfi)?];
        if let Some(b) = baseline {
            builds.push(Build::new("baseline", Some(b))?);
        }
        Ok(builds)
    }

    /// Starts `netfi emulator` as `spec` says, and waits until it is ready.
    pub fn emulator(&self, spec: &EmulatorSpec, p: &Placement) -> Result<Emulator> {
        self.emulator_of(&spec.args(p))
    }

    /// Starts `netfi emulator ARGS`, and waits until it is ready (in
    /// `args.out`).
    pub fn emulator_of(&self, args: &EmulatorArgs) -> Result<Emulator> {
        let argv: Vec<String> = std::iter::once("emulator".to_string()).chain(args.to_argv()).collect();
        Emulator::spawn(&self.netfi, &args.out, &argv)
    }
}

/// The flags of a program that measures one build's emulator, started by
/// the program itself: the common flags, the cores and the build.
#[derive(Debug, Clone, clap::Args, Serialize)]
pub struct OneBuild {
    #[command(flatten)]
    #[serde(flatten)]
    pub common: Common,
    #[command(flatten)]
    #[serde(flatten)]
    pub cores: Cores,
    /// The netfi binary whose emulator is measured [default: this
    /// package's build]
    #[arg(long, value_name = "PATH")]
    pub netfi: Option<PathBuf>,
}

impl OneBuild {
    /// The placement, the results directory of `program` and the build.
    pub fn start(&self, program: &'static str) -> Result<(Placement, Out, Build)> {
        let p = self.cores.placement(&self.common)?;
        let out = Out::create(&self.common, program)?;
        Ok((p, out, Build::new("netfi", self.netfi.as_deref())?))
    }
}

/// The flags of a program that times one build, or two alternated: the
/// common flags, the builds and the runs of each.
#[derive(Debug, Clone, clap::Args, Serialize)]
pub struct TwoBuilds {
    #[command(flatten)]
    #[serde(flatten)]
    pub common: Common,
    /// The netfi binary to measure [default: this package's build]
    #[arg(long, value_name = "PATH")]
    pub netfi: Option<PathBuf>,
    /// A second build, timed alternately with the first
    #[arg(long, value_name = "PATH")]
    pub baseline: Option<PathBuf>,
    /// Runs of each scenario by each build
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
}

impl TwoBuilds {
    /// The results directory of `program` and the builds it times.
    pub fn start(&self, program: &'static str) -> Result<(Out, Vec<Build>)> {
        let out = Out::create(&self.common, program)?;
        Ok((out, Build::pair(self.netfi.as_deref(), self.baseline.as_deref())?))
    }
}

/// Calls `f(build, scenario, round)` for each of `rounds` rounds, each
/// scenario and each build, the builds' order turned round every round
/// (A B, then B A): every build meets the same phases of the host, and
/// none always runs first.
pub fn alternate<T>(builds: &[Build], scenarios: &[String], rounds: usize, mut f: impl FnMut(&Build, &str, usize) -> Result<T>) -> Result<Vec<T>> {
    let mut out = Vec::new();
    for round in 0..rounds {
        for sc in scenarios {
            let order: Vec<&Build> = if round % 2 == 0 { builds.iter().collect() } else { builds.iter().rev().collect() };
            for b in order {
                out.push(f(b, sc, round)?);
            }
        }
    }
    Ok(out)
}

/// A scenario's short name: a preset's own, a file's stem.
pub fn scenario_label(scenario: &str) -> String {
    Path::new(scenario).file_stem().map_or(scenario.to_string(), |s| s.to_string_lossy().into_owned())
}

/// Starts `cmd` with its output in `log`.
pub fn spawn_logged(mut cmd: Command, log: &Path) -> Result<Child> {
    let file = std::fs::File::create(log).with_context(|| format!("creating {}", log.display()))?;
    cmd.stdin(Stdio::null()).stdout(file.try_clone()?).stderr(file).spawn().with_context(|| format!("starting {:?}", cmd.get_program()))
}

/// Waits for `child`, polling, so that a stop of the benchmark (SIGTERM,
/// or Ctrl-C outside a terminal) reaches it as SIGINT.
pub fn wait(mut child: Child) -> Result<ExitStatus> {
    let mut signalled = false;
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(status);
        }
        if stopped() && !signalled {
            signalled = true;
            signal(&child, libc::SIGINT);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn signal(child: &Child, sig: libc::c_int) {
    // SAFETY: signalling our own child by its pid.
    unsafe {
        libc::kill(child.id() as libc::pid_t, sig);
    }
}

/// A JSON file.
pub fn read_json(path: &Path) -> Result<Value> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_slice(&bytes).with_context(|| format!("parsing {}", path.display()))
}

/// The member at `path` (`a.b.c`), `Null` where any part is missing.
pub fn at<'v>(v: &'v Value, path: &str) -> &'v Value {
    path.split('.').fold(v, |v, k| v.get(k).unwrap_or(&Value::Null))
}

/// The number at `path`, if there is one.
pub fn num(v: &Value, path: &str) -> Option<f64> {
    at(v, path).as_f64()
}

/// The percentile summary at `path`, if there is one.
pub fn summary(v: &Value, path: &str) -> Option<Summary> {
    serde_json::from_value(at(v, path).clone()).ok()
}

/// A run id of this process's own, new at each call.
pub fn fresh_run_id() -> String {
    static N: AtomicU64 = AtomicU64::new(0);
    let t = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_micros() as u64);
    format!("b{:x}x{}", t & 0xff_ffff_ffff, N.fetch_add(1, Ordering::Relaxed))
}

/// What an emulator the benchmark starts runs: `scenario` with seed 1,
/// writing to `dir`, on the placement's core.
pub struct EmulatorSpec<'a> {
    pub scenario: &'a str,
    pub dir: &'a Path,
    pub expected_frames: u64,
    /// iceoryx2 on both sides, this run's ports; `None`: the endpoints are
    /// UDP ones (`udp`).
    pub run_id: Option<&'a str>,
    /// Keep the iceoryx2 feedback loop open (off: the forward path alone).
    pub feedback: bool,
    pub queue_capacity: Option<usize>,
    /// The endpoints (default: iceoryx2 on both sides).
    pub ends: EndsArgs,
    /// The UDP bridge's options.
    pub udp: UdpArgs,
    /// Console → robot streams through the one emulator.
    pub streams: u32,
}

impl EmulatorSpec<'_> {
    /// The emulator's arguments.
    pub fn args(&self, p: &Placement) -> EmulatorArgs {
        let mut e = EmulatorArgs::new(self.run_id.map(str::to_string), self.scenario);
        e.scenario.seed = Some(1);
        e.scenario.queue_capacity = self.queue_capacity;
        e.out = self.dir.to_path_buf();
        e.expected_frames = self.expected_frames;
        // Live control and telemetry are served under a run id.
        e.control.no_control = self.run_id.is_none();
        e.channels.feedback.no_feedback = self.run_id.is_some() && !self.feedback;
        e.placement.core = p.emulator_core;
        e.placement.no_pin = p.emulator_core.is_none();
        e.placement.rt_priority = p.rt_priority;
        e.ends = self.ends.clone();
        e.transports.udp = self.udp.clone();
        e.stream.streams = self.streams;
        e
    }
}

/// Removes the management segments of its runs when dropped, once all
/// their processes have ended: two processes that drop their nodes at the
/// same moment (the emulator on its end marker, the benchmark's ends) each
/// see the other's node and leave the segment in `/dev/shm`. Declared
/// before the [`Emulator`] of those runs, it is dropped after it.
pub struct ForgetRuns(pub Vec<String>);

impl Drop for ForgetRuns {
    fn drop(&mut self) {
        for id in &self.0 {
            if let Ok(run) = netfi::transport::RunId::new(id) {
                netfi::transport::ipc::remove_run_segment_if_unused(&run);
            }
        }
    }
}

/// A running `netfi emulator`, stopped when dropped.
pub struct Emulator {
    child: Child,
    dir: PathBuf,
}

impl Emulator {
    fn spawn(netfi: &Path, dir: &Path, argv: &[String]) -> Result<Emulator> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for stale in ["emulator.ready", "emulator.json", "udp_endpoints.json", "udp.json"] {
            let _ = std::fs::remove_file(dir.join(stale));
        }
        let mut cmd = Command::new(netfi);
        cmd.args(argv);
        let mut e = Emulator { child: spawn_logged(cmd, &dir.join("emulator.log"))?, dir: dir.to_path_buf() };
        let t0 = Instant::now();
        while !dir.join("emulator.ready").exists() {
            if let Ok(Some(status)) = e.child.try_wait() {
                bail!("the emulator ended before it was ready ({status}); see {}", dir.join("emulator.log").display());
            }
            // An emulator of many streams sets each up first.
            if t0.elapsed() > Duration::from_secs(120) || stopped() {
                bail!("the emulator was not ready after {:.0} s; see {}", t0.elapsed().as_secs_f64(), dir.join("emulator.log").display());
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        Ok(e)
    }

    /// The address of the emulator's UDP ingress (`udp_endpoints.json`).
    pub fn udp_ingress(&self) -> Result<std::net::SocketAddr> {
        let endpoints = read_json(&self.dir.join("udp_endpoints.json"))?;
        Ok(endpoints["ingress"].as_str().context("udp_endpoints.json: no ingress")?.parse()?)
    }

    /// Waits up to `wait` for the emulator to end by itself, then stops it;
    /// its `emulator.json`.
    pub fn finish(self, wait: Duration) -> Result<Value> {
        let dir = self.dir.clone();
        self.end(wait);
        read_report(&dir)
    }

    /// [`Emulator::finish`] of an emulator of `n` streams: each stream's
    /// report (stream K's in `stream-K/`).
    pub fn finish_streams(self, wait: Duration, n: usize) -> Result<Vec<Value>> {
        let dir = self.dir.clone();
        self.end(wait);
        (0..n).map(|k| read_report(&if n <= 1 { dir.clone() } else { dir.join(format!("stream-{k}")) })).collect()
    }

    fn end(mut self, wait: Duration) {
        let t0 = Instant::now();
        while t0.elapsed() < wait && !matches!(self.child.try_wait(), Ok(Some(_))) {
            std::thread::sleep(Duration::from_millis(5));
        }
        self.stop();
    }

    fn stop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            signal(&self.child, libc::SIGTERM);
            let t0 = Instant::now();
            while t0.elapsed() < Duration::from_secs(10) {
                if let Ok(Some(_)) = self.child.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

/// The `emulator.json` in `dir`; its per-frame trace is removed.
fn read_report(dir: &Path) -> Result<Value> {
    let report = read_json(&dir.join("emulator.json"))?;
    let _ = std::fs::remove_file(dir.join("trace_emulator.csv"));
    Ok(report)
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop();
    }
}
