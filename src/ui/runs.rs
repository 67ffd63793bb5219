//! The runs the UI started: each a `netfi run` child process with its own
//! output directory (`<out>/<run id>/`), its input scenario beside it.

use super::UiOptions;
use anyhow::{bail, Context};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::PathBuf;
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
    /// `running`, `done` (the report balanced, no fault) or `failed`.
    pub state: &'static str,
    pub elapsed_s: f64,
    pub duration_s: f64,
    pub out: String,
    /// The run's report (report.json), once written.
    pub report: Option<serde_json::Value>,
    /// The end of the run's standard error, once it ended.
    pub stderr_tail: Option<String>,
    /// The last telemetry interval as a table, and the loss over time.
    pub live: Option<String>,
}

/// What starting a run needs.
#[derive(Debug, serde::Deserialize)]
pub(crate) struct Start {
    pub toml: String,
    pub duration_s: f64,
    pub seed: Option<u64>,
}

impl Runs {
    pub fn new(mask: CpuMask) -> Runs {
        Runs { runs: Mutex::default(), next: AtomicU64::new(0), mask }
    }

    /// Validates the scenario (the parser's own errors) and starts `netfi
    /// run` on it; the run's id.
    pub fn start(&self, opts: &UiOptions, req: &Start) -> anyhow::Result<String> {
        let scenario = crate::scenario::parse_str(&req.toml, "scenario", "scenario")?.name;
        if !(req.duration_s.is_finite() && req.duration_s > 0.0 && req.duration_s <= 86_400.0) {
            bail!("the duration must be between 0 and 86400 s, got {}", req.duration_s);
        }
        let id = format!("ui{}-{}", std::process::id(), self.next.fetch_add(1, Ordering::Relaxed) + 1);
        let out = opts.out_dir.join(&id);
        std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
        let input = out.join("scenario.input.toml");
        std::fs::write(&input, &req.toml).with_context(|| format!("writing {}", input.display()))?;
        let log = |name: &str| -> anyhow::Result<std::fs::File> {
            let p = out.join(name);
            std::fs::File::create(&p).with_context(|| format!("creating {}", p.display()))
        };
        let mut cmd = Command::new(&opts.netfi);
        // A run started here may be switched to any scenario: its queue
        // keeps release-time order whatever its own scenario.
        cmd.arg("run").arg(&input).arg("--out").arg(&out).args(["--run-id", &id, "--duration-s", &req.duration_s.to_string(), "--reorder-queue"]);
        self.mask.give(&mut cmd);
        if let Some(seed) = req.seed {
            cmd.args(["--seed", &seed.to_string()]);
        }
        let child = cmd
            .stdin(Stdio::null())
            .stdout(log("run.stdout")?)
            .stderr(log("run.stderr")?)
            .spawn()
            .with_context(|| format!("starting {}", opts.netfi.display()))?;
        let telemetry = super::live::Telemetry::follow(&opts.netfi, &id).ok();
        let run = Run { child, out, scenario, duration_s: req.duration_s, started: Instant::now(), exit: None, telemetry };
        self.runs.lock().expect("runs lock").insert(id.clone(), run);
        Ok(id)
    }

    /// Where the run `id` writes, if the UI started it.
    pub fn out_dir(&self, id: &str) -> Option<PathBuf> {
        self.runs.lock().expect("runs lock").get(id).map(|r| r.out.clone())
    }

    /// The run's state now.
    pub fn status(&self, id: &str) -> Option<Status> {
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
        let report = run.exit.and_then(|_| read("report.json")).and_then(|t| serde_json::from_str(&t).ok());
        let stderr_tail = run.exit.and_then(|_| read("run.stderr")).map(|t| tail(&t, 2000));
        Some(Status {
            id: id.to_string(),
            scenario: run.scenario.clone(),
            state: match run.exit {
                None => "running",
                Some(s) if s.success() => "done",
                Some(_) => "failed",
            },
            elapsed_s: run.started.elapsed().as_secs_f64(),
            duration_s: run.duration_s,
            out: run.out.display().to_string(),
            report,
            stderr_tail,
            live,
        })
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

/// The last `n` bytes of `text`, cut at a character boundary.
fn tail(text: &str, n: usize) -> String {
    let mut start = text.len().saturating_sub(n);
    while !text.is_char_boundary(start) {
        start += 1;
    }
    text[start..].to_string()
}
