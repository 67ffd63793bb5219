//! The processes of a run: started in their own process group, each kind
//! once the one before is ready; watched, signalled and, however the
//! runner leaves (an error, a panic), never left behind: a process still
//! running when its handle is dropped is stopped, and killed if it does not
//! end within [`KILL_GRACE`](crate::service::supervise::KILL_GRACE).

use crate::durable::PartialFile;
use crate::host::guardian::RunGuard;
use crate::service::plan::Plan;
use crate::service::report::ProcessEnd;
use crate::service::supervise::{State, KILL_GRACE};
use super::RunnerError;

type Result<T> = std::result::Result<T, RunnerError>;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// One process of the run.
pub struct Proc {
    pub role: &'static str,
    pub child: Child,
    pub core: Option<usize>,
    pub log: PathBuf,
    /// The log while the process runs, as `<role>.log.partial`; given its
    /// own name once the process has ended ([`Proc::settle_log`]).
    pub log_file: Option<PartialFile>,
    /// Why the log could not be given its own name.
    pub log_error: Option<String>,
    pub status: Option<std::process::ExitStatus>,
    /// Why the runner stopped it, when it was stuck.
    pub stuck: Option<String>,
}

impl Proc {
    /// Whether it has ended (reaped now if it just did).
    pub fn poll(&mut self) -> bool {
        if self.status.is_none() {
            if let Ok(Some(s)) = self.child.try_wait() {
                self.status = Some(s);
            }
        }
        self.status.is_some()
    }

    /// Asks it to stop (SIGTERM), if it still runs.
    pub fn terminate(&mut self) {
        if !self.poll() {
            // SAFETY: signalling our own child by pid; it is not reaped yet,
            // so the pid is still its.
            unsafe {
                libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM);
            }
        }
    }

    /// Kills it (SIGKILL) if it still runs, saying why.
    pub fn kill(&mut self, why: &str) {
        if !self.poll() {
            if self.stuck.is_none() {
                self.stuck(why);
            }
            let _ = self.child.kill();
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

    pub fn state(&self) -> State {
        match self.status {
            None => State::Running,
            Some(s) if s.success() => State::Succeeded,
            Some(_) => State::Failed,
        }
    }

    pub fn end(&self) -> ProcessEnd {
        ProcessEnd { role: self.role.into(), pid: self.child.id(), core: self.core, status: self.status_text(), log: self.log.clone() }
    }

    /// What went wrong with it: stuck, how it ended, its log not whole.
    pub fn faults(&self) -> impl Iterator<Item = String> + '_ {
        self.stuck.clone().into_iter().chain(self.died()).chain(self.log_error.clone())
    }

    /// Gives the log of a process that has ended its own name (synced):
    /// nothing writes to it any more. A log that cannot be is left cut,
    /// and said among the process's faults.
    pub fn settle_log(&mut self) {
        if !self.poll() {
            return;
        }
        if let Some(f) = self.log_file.take() {
            if let Err(e) = f.commit() {
                self.log_error = Some(format!("the {}'s log is not whole: {e}", self.role));
            }
        }
    }

    /// Names a process stuck: what it is doing, as the kernel says (its
    /// state and, when asleep in the kernel, where).
    pub fn stuck(&mut self, what: &str) {
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

impl Drop for Proc {
    /// A process still running when the runner lets go of it (an error, a
    /// panic) is stopped, then killed after the grace, and reaped: no
    /// process of a run outlives its runner.
    fn drop(&mut self) {
        if self.poll() {
            self.settle_log();
            return;
        }
        self.terminate();
        let t0 = Instant::now();
        while !self.poll() && t0.elapsed() < KILL_GRACE {
            std::thread::sleep(Duration::from_millis(5));
        }
        let _ = self.child.kill();
        if let Ok(s) = self.child.wait() {
            self.status = Some(s);
        }
        self.settle_log();
    }
}

/// Starts `netfi <role> <args>` with its log `<out>/<role>.log` (written
/// as `<role>.log.partial` while it runs), in a process group of its own
/// (Ctrl-C reaches only the runner), telling it the runner's pid (it dies
/// with the runner).
pub fn spawn(role: &'static str, args: Vec<String>, core: Option<usize>, out: &Path, guard: &mut Option<RunGuard>) -> Result<Proc> {
    let exe = std::env::current_exe().map_err(RunnerError::Exe)?;
    let log = out.join(format!("{role}.log"));
    let log_file = PartialFile::create(&log).map_err(|e| RunnerError::Create(log.clone(), std::io::Error::other(e)))?;
    let file = log_file.file().try_clone().map_err(|e| RunnerError::Create(log.clone(), e))?;
    let stdout = file.try_clone().map_err(|e| RunnerError::Create(log.clone(), e))?;
    let child = Command::new(&exe)
        .arg(role)
        .args(&args)
        .stdin(Stdio::null())
        .stdout(stdout)
        .stderr(file)
        .process_group(0)
        .env(crate::host::process::RUNNER_PID_ENV, std::process::id().to_string())
        .env(crate::transport::ipc::IPC_ROOT_ENV, crate::transport::ipc::user_root_dir())
        .spawn()
        .map_err(|cause| RunnerError::Spawn { role, exe: exe.clone(), cause })?;
    if let Some(Err(e)) = guard.as_mut().map(|g| g.add(child.id())) {
        eprintln!("WARNING: the {role} is not on the run's record ({e}): if the runner is killed, it ends by the parent-death signal only");
    }
    Ok(Proc { role, child, core, log, log_file: Some(log_file), log_error: None, status: None, stuck: None })
}

/// Waits for `<out>/<role>.ready`, failing early if the process ends.
fn wait_ready(p: &mut Proc, out: &Path, timeout: Duration) -> Result<()> {
    let ready = out.join(format!("{}.ready", p.role));
    let t0 = Instant::now();
    while !ready.exists() {
        if p.poll() {
            return Err(RunnerError::EndedEarly { role: p.role, status: p.status_text(), log: tail(&p.log, 20) });
        }
        if t0.elapsed() > timeout {
            p.terminate();
            return Err(RunnerError::NotReady { role: p.role, after: timeout, log: tail(&p.log, 20) });
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(())
}

/// The last `lines` lines of a log (its `.partial` while it is written).
pub fn tail(path: &Path, lines: usize) -> String {
    let text = std::fs::read_to_string(path).or_else(|_| std::fs::read_to_string(crate::durable::partial_path(path))).unwrap_or_default();
    let all: Vec<&str> = text.lines().collect();
    all[all.len().saturating_sub(lines)..].join("\n")
}

/// The processes of a run: each stream's console and robot, and the one
/// emulator.
pub struct Procs {
    pub consoles: Vec<Proc>,
    pub emulator: Proc,
    pub simulators: Vec<Proc>,
}

impl Procs {
    /// Consoles, emulator, robots: the order of the report.
    pub fn all(&self) -> impl Iterator<Item = &Proc> {
        self.consoles.iter().chain(std::iter::once(&self.emulator)).chain(self.simulators.iter())
    }

    pub fn all_mut(&mut self) -> impl Iterator<Item = &mut Proc> {
        self.consoles.iter_mut().chain(std::iter::once(&mut self.emulator)).chain(self.simulators.iter_mut())
    }
}

/// Starts `role` in `out` and waits until it is ready.
fn start_one(role: &'static str, args: Vec<String>, core: Option<usize>, out: &Path, timeout: Duration, guard: &mut Option<RunGuard>) -> Result<Proc> {
    let mut p = spawn(role, args, core, out, guard)?;
    wait_ready(&mut p, out, timeout)?;
    Ok(p)
}

/// Starts the simulators, the emulator and the consoles (netfi's own,
/// where they play the robot and the console: the lab's programs are not
/// the run's to start), each kind once the one before is ready. Those
/// started are stopped (as their handles are dropped) if one fails to
/// start. Each is put on the run's record `guard` (its guardian ends them
/// if the runner is killed).
pub fn start(plan: &Plan, guard: &mut Option<RunGuard>) -> Result<Procs> {
    let (out, cores) = (&plan.out, plan.cores);
    let mut simulators = Vec::new();
    for (s, args) in plan.streams.iter().filter_map(|s| Some((s, s.simulator.as_ref()?))) {
        simulators.push(start_one("simulator", args.to_argv(), cores.simulator, &s.out, Duration::from_secs(30), guard)?);
    }
    // Each stream's link, queue, trace and feedback path are set up before
    // the emulator is ready: a second or so each on a loaded machine.
    // The emulator says it is ready once it has the lab's robot, when it
    // waits for it.
    let ready = Duration::from_secs(30 + 2 * plan.streams.len() as u64) + Duration::from_secs_f64(plan.emulator.wait_for_peer_s.unwrap_or(0.0));
    if let Some(s) = plan.emulator.wait_for_peer_s {
        eprintln!("waiting up to {s} s for the lab's robot at {}", plan.emulator.ends.egress);
    }
    let emulator = start_one("emulator", plan.emulator.to_argv(), cores.emulator, out, ready, guard)?;
    let mut procs = Procs { consoles: Vec::new(), emulator, simulators };
    for (s, args) in plan.streams.iter().filter_map(|s| Some((s, s.console.as_ref()?))) {
        procs.consoles.push(spawn("console", args.to_argv(), cores.console, &s.out, guard)?);
    }
    if plan.streams[0].console.is_none() {
        eprintln!("taking the lab's console at {}", if plan.emulator.ros2.on() { "the ROS 2 topics".to_string() } else { plan.emulator.ends.ingress.to_string() });
    }
    Ok(procs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sleeper() -> Proc {
        let child = Command::new("sleep").arg("60").spawn().unwrap();
        Proc { role: "console", child, core: None, log: PathBuf::from("/nonexistent"), log_file: None, log_error: None, status: None, stuck: None }
    }

    fn gone(pid: u32) -> bool {
        !Path::new(&format!("/proc/{pid}")).exists()
    }

    #[test]
    fn a_panic_in_the_runner_takes_its_processes_with_it() {
        let pids = std::sync::Mutex::new(Vec::new());
        let r = std::panic::catch_unwind(|| {
            let procs = [sleeper(), sleeper()];
            pids.lock().unwrap().extend(procs.iter().map(|p| p.child.id()));
            panic!("the runner fails with its processes running");
        });
        assert!(r.is_err());
        let pids = pids.into_inner().unwrap();
        assert_eq!(pids.len(), 2);
        assert!(pids.iter().all(|&p| gone(p)), "processes left: {pids:?}");
    }

    #[test]
    fn a_process_that_ended_is_left_as_it_was() {
        let child = Command::new("true").spawn().unwrap();
        let mut p = Proc { role: "simulator", child, core: None, log: PathBuf::from("/nonexistent"), log_file: None, log_error: None, status: None, stuck: None };
        while !p.poll() {
            std::thread::sleep(Duration::from_millis(1));
        }
        assert_eq!(p.state(), State::Succeeded);
        drop(p);
    }
}
