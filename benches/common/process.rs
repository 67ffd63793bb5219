//! The `netfi` binaries as processes: a build ([`Build`]: `netfi run`, and
//! `netfi emulator` started and stopped by the benchmark), their reports
//! read back as JSON, tolerant of fields an older build does not write.
//!
//! Everything here goes through the command line and the files a run
//! writes, not through the library: a benchmark can time a build of
//! another commit beside this one.

use crate::common::args::{check_interrupted, stopped, Placement, NETFI};
use anyhow::{bail, Context, Result};
use netfi::metrics::Summary;
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
    /// `dir`, with `extra` flags; its `report.json`. The per-frame files are
    /// removed after (large at high rates).
    pub fn run(&self, dir: &Path, scenario: &str, rate_hz: f64, seconds: f64, extra: &[String]) -> Result<Value> {
        let mut cmd = Command::new(&self.netfi);
        cmd.args(["run", scenario, "--rate-hz", &rate_hz.to_string(), "--duration-s", &seconds.to_string(), "--seed", "1", "--out"]).arg(dir).args(extra);
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
        Emulator::spawn(&self.netfi, spec.dir, &spec.argv(p))
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

/// Stream `k`'s run id and directory in a run of several streams (as
/// `netfi emulator --streams` names them).
pub fn stream_run_id(run_id: &str, k: usize) -> String {
    if k == 0 {
        run_id.to_string()
    } else {
        format!("{run_id}-s{k}")
    }
}

/// What an emulator the benchmark starts runs: `scenario` with seed 1,
/// writing to `dir`, on the placement's core.
pub struct EmulatorSpec<'a> {
    pub scenario: &'a str,
    pub dir: &'a Path,
    pub expected_frames: u64,
    /// iceoryx2 on both sides, this run's ports; `None`: the endpoints are
    /// in `extra`.
    pub run_id: Option<&'a str>,
    /// Keep the iceoryx2 feedback loop open (off: the forward path alone).
    pub feedback: bool,
    pub queue_capacity: Option<usize>,
    /// Further flags: UDP endpoints, `--streams`, a return scenario.
    pub extra: Vec<String>,
}

impl EmulatorSpec<'_> {
    /// The argv after the binary.
    pub fn argv(&self, p: &Placement) -> Vec<String> {
        let mut a: Vec<String> = vec!["emulator".into(), "--scenario".into(), self.scenario.into(), "--seed".into(), "1".into()];
        a.extend(["--out".into(), self.dir.display().to_string(), "--expected-frames".into(), self.expected_frames.to_string()]);
        match self.run_id {
            Some(id) => a.extend(["--run-id".to_string(), id.to_string()]),
            // Live control and telemetry are served under a run id.
            None => a.push("--no-control".into()),
        }
        if self.run_id.is_some() && !self.feedback {
            a.push("--no-feedback".into());
        }
        match p.emulator_core {
            Some(c) => a.extend(["--core".to_string(), c.to_string()]),
            None => a.push("--no-pin".into()),
        }
        if let Some(r) = p.rt_priority {
            a.extend(["--rt-priority".to_string(), r.to_string()]);
        }
        if let Some(q) = self.queue_capacity {
            a.extend(["--queue-capacity".to_string(), q.to_string()]);
        }
        a.extend(self.extra.iter().cloned());
        a
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
