//! The kill -9 matrix of a run that clears the emulator's core.

use super::*;
use std::collections::BTreeMap;
use std::process::Stdio;

/// What a run may change on the host and must put back.
#[derive(Debug, PartialEq)]
struct HostState {
    /// IRQ → `smp_affinity_list`.
    irqs: BTreeMap<u32, String>,
    /// `/sys/devices/virtual/workqueue/cpumask`.
    workqueue: Option<String>,
    /// Kernel thread pid → (name, CPUs allowed).
    kthreads: BTreeMap<i32, (String, String)>,
}

fn numeric(dir: &str) -> Vec<i32> {
    std::fs::read_dir(dir)
        .map(|rd| rd.filter_map(|e| e.ok()?.file_name().to_str()?.parse().ok()).collect())
        .unwrap_or_default()
}

fn allowed(path: &str) -> Option<String> {
    let status = std::fs::read_to_string(path).ok()?;
    status.lines().find_map(|l| l.strip_prefix("Cpus_allowed_list:")).map(|s| s.trim().to_string())
}

fn snapshot() -> HostState {
    let irqs = numeric("/proc/irq")
        .into_iter()
        .filter_map(|i| Some((i as u32, std::fs::read_to_string(format!("/proc/irq/{i}/smp_affinity_list")).ok()?.trim().to_string())))
        .collect();
    let workqueue = std::fs::read_to_string("/sys/devices/virtual/workqueue/cpumask").ok().map(|s| s.trim().to_string());
    let mut kthreads = BTreeMap::new();
    for pid in numeric("/proc") {
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else { continue };
        let ppid = stat.rsplit_once(')').and_then(|(_, r)| r.split_whitespace().nth(1)?.parse::<i32>().ok());
        if pid != 2 && ppid != Some(2) {
            continue;
        }
        let name = std::fs::read_to_string(format!("/proc/{pid}/comm")).unwrap_or_default().trim().to_string();
        if let Some(a) = allowed(&format!("/proc/{pid}/status")) {
            kthreads.insert(pid, (name, a));
        }
    }
    HostState { irqs, workqueue, kthreads }
}

/// What differs between two snapshots (kernel threads present in both).
fn differences(before: &HostState, after: &HostState) -> Vec<String> {
    let mut d = Vec::new();
    for (irq, a) in &before.irqs {
        if let Some(b) = after.irqs.get(irq).filter(|b| *b != a) {
            d.push(format!("irq {irq}: {a} → {b}"));
        }
    }
    if before.workqueue != after.workqueue {
        d.push(format!("workqueue cpumask: {:?} → {:?}", before.workqueue, after.workqueue));
    }
    for (pid, (name, a)) in &before.kthreads {
        if let Some((_, b)) = after.kthreads.get(pid).filter(|(n, b)| n == name && b != a) {
            d.push(format!("kernel thread {pid} {name}: {a} → {b}"));
        }
    }
    d
}

fn last_core() -> usize {
    *netfi::host::affinity::online_cpus().iter().next_back().unwrap()
}

/// The record of the clearing done by the emulator `pid`, if any.
fn record_of(pid: i32) -> Option<PathBuf> {
    let dir = netfi::host::record::state_dir().ok()?;
    netfi::host::record::list(&dir).into_iter().find(|p| p.to_string_lossy().contains(&format!("isolation-{pid}-")))
}

/// The guardian of `record`: the process whose command line names it.
fn guardian_of(record: &Path) -> Option<i32> {
    let want = format!("restore\0--guard\0{}", record.display());
    numeric("/proc").into_iter().find(|pid| {
        std::fs::read(format!("/proc/{pid}/cmdline")).is_ok_and(|c| String::from_utf8_lossy(&c).contains(&want))
    })
}

#[derive(Debug, Clone, Copy)]
enum Kill {
    Emulator,
    Runner,
    RunnerAndEmulator,
    Guardian,
    /// Runner, emulator and guardian: only `netfi restore` can put it back.
    All,
}

/// A run whose emulator cleared its core, as the kill matrix finds it
/// once everything is up.
struct ClearedRun {
    runner: Reaped,
    out: PathBuf,
    run_id: String,
    emulator: i32,
    /// The console and the simulator.
    others: Vec<i32>,
    record: PathBuf,
    guardian: i32,
}

impl ClearedRun {
    fn start(kill: Kill, core: usize) -> ClearedRun {
        let out = out_dir(&format!("kill-{kill:?}"));
        let run_id = format!("kill{kill:?}{}", std::process::id());
        std::fs::create_dir_all(&out).unwrap();
        let runner = Reaped(
            netfi()
                .args(["run", "Normal", "--duration-s", "6", "--seed", "5", "--emulator-core", &core.to_string(), "--run-id", &run_id, "--out"])
                .arg(&out)
                .stdout(Stdio::null())
                .stderr(std::fs::File::create(out.join("runner.stderr")).unwrap())
                .spawn()
                .unwrap(),
        );
        let mut found = None;
        wait_for("the emulator's pid", Duration::from_secs(60), || {
            found = read_pid(&out, "emulator");
            found.is_some()
        });
        let emulator = found.unwrap();
        let mut record = None;
        wait_for("the record of the cleared core", Duration::from_secs(60), || {
            record = record_of(emulator);
            record.is_some()
        });
        let record = record.unwrap();
        let mut guardian = None;
        wait_for("the guardian", Duration::from_secs(10), || {
            guardian = guardian_of(&record);
            guardian.is_some()
        });
        let mut others = Vec::new();
        wait_for("the console's and the simulator's pids", Duration::from_secs(60), || {
            others = ["console", "simulator"].iter().filter_map(|r| read_pid(&out, r)).collect();
            others.len() == 2
        });
        ClearedRun { runner, out, run_id, emulator, others, record, guardian: guardian.unwrap() }
    }

    fn kill(&self, kill: Kill) {
        let runner = self.runner.0.id() as i32;
        match kill {
            Kill::Emulator => sigkill(self.emulator),
            Kill::Runner => sigkill(runner),
            Kill::RunnerAndEmulator => {
                sigkill(runner);
                sigkill(self.emulator);
            }
            Kill::Guardian => sigkill(self.guardian),
            Kill::All => {
                // The run's own guardian too, else it would end the run and
                // restore; the emulator before the runner, else the runner's
                // death could let it restore itself first.
                super::orphans::guardians_of_run(runner).into_iter().for_each(sigkill);
                sigkill(self.guardian);
                sigkill(self.emulator);
                sigkill(runner);
            }
        }
    }

    /// With the runner killed: no process of the run is left after about
    /// 2 s; with the emulator killed too, the guardian that ended the run
    /// removed its shared memory.
    fn check_nothing_outlives_the_runner(&self, kill: Kill) {
        if let Kill::Runner | Kill::RunnerAndEmulator | Kill::All = kill {
            let run: Vec<i32> = self.others.iter().copied().chain([self.emulator]).collect();
            wait_for(&format!("{kill:?}: no process of the run left (console, simulator, emulator: {run:?})"), Duration::from_millis(2500), || {
                run.iter().all(|&p| !alive(p))
            });
        }
        if let Kill::RunnerAndEmulator = kill {
            let mut left = ipc_files_of(&self.run_id);
            let t0 = Instant::now();
            while !left.is_empty() && t0.elapsed() < Duration::from_secs(10) {
                std::thread::sleep(Duration::from_millis(100));
                left = ipc_files_of(&self.run_id);
            }
            assert!(left.is_empty(), "{kill:?}: the run's shared memory is left after its processes ended: {left:?}");
        }
    }
}

impl Drop for ClearedRun {
    /// A failed check must not leave the run going, or the host changed,
    /// for the cases after it.
    fn drop(&mut self) {
        self.others.iter().chain([&self.emulator]).filter(|&&p| alive(p)).for_each(|&p| sigkill(p));
        if std::thread::panicking() {
            let _ = self.runner.0.kill();
            let _ = self.runner.0.wait();
            let _ = netfi().arg("restore").output();
        }
    }
}

fn kill_matrix_case(kill: Kill) {
    let _guard = machine::alone();
    let core = last_core();
    let before = snapshot();
    let own_mask = allowed("/proc/self/status").unwrap();
    let run = ClearedRun::start(kill, core);
    std::thread::sleep(Duration::from_millis(500));
    // The run did change the host (else the comparison below proves nothing).
    let during = snapshot();
    assert!(!differences(&before, &during).is_empty(), "the run changed nothing: is the core cleared?");
    // Started while the core is cleared: it inherits this process's
    // narrowed mask.
    let mid_run = Reaped(Command::new("sleep").arg("120").spawn().unwrap());
    let mid_pid = mid_run.0.id() as i32;
    let narrowed = allowed(&format!("/proc/{mid_pid}/status")).unwrap();
    assert!(!netfi::host::affinity::parse_list(&narrowed).unwrap().contains(&core), "not narrowed: {narrowed}");

    run.kill(kill);
    run.check_nothing_outlives_the_runner(kill);
    let (record, guardian) = (&run.record, run.guardian);
    if let Kill::All = kill {
        wait_for("the killed processes to end", Duration::from_secs(10), || !alive(guardian) && !alive(run.emulator));
        std::thread::sleep(Duration::from_millis(500));
        assert!(record.exists(), "with every owner and the guardian killed, nothing should have restored yet");
        let said = restore();
        assert!(said.contains("restored"), "{said}");
    }
    // The guardian (owners all dead), the runner (emulator dead), or the
    // emulator (runner or guardian dead) puts everything back.
    wait_for(&format!("{kill:?}: the record to be restored and removed"), Duration::from_secs(60), || !record.exists());
    wait_for("the guardian to end", Duration::from_secs(10), || !alive(guardian));

    // Whatever of the run is left is stopped; `netfi restore` removes the
    // iceoryx2 resources of the killed processes.
    let pids: Vec<i32> = ["console", "emulator", "simulator"].iter().filter_map(|role| read_pid(&run.out, role)).collect();
    for &pid in pids.iter().filter(|p| alive(**p)) {
        sigkill(pid);
    }
    let (out, run_id) = (run.out.clone(), run.run_id.clone());
    drop(run);
    // `netfi restore` leaves a live process's node alone: it runs once every
    // process of the run is gone (a process dying by its runner's death may
    // still be on its way out), and again while a file is left, for at most
    // a few seconds; what is left after that was left for good.
    wait_for("the run's processes to end", Duration::from_secs(10), || pids.iter().all(|p| !alive(*p)));
    let t0 = std::time::Instant::now();
    let mut shm = Vec::new();
    while t0.elapsed() < Duration::from_secs(5) {
        restore();
        shm = ipc_files_of(&run_id);
        if shm.is_empty() {
            break;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(shm.is_empty(), "{kill:?}: left in /dev/shm or iceoryx2's directory after `netfi restore`: {shm:?}");
    let after = snapshot();
    let d = differences(&before, &after);
    let stderr = std::fs::read_to_string(out.join("runner.stderr")).unwrap_or_default();
    assert!(d.is_empty(), "{kill:?}: the host was left changed:\n{}\nrunner:\n{stderr}", d.join("\n"));
    assert_eq!(allowed("/proc/self/status").unwrap(), own_mask, "{kill:?}: this process's mask");
    let widened = allowed(&format!("/proc/{mid_pid}/status")).unwrap();
    assert_eq!(widened, own_mask, "{kill:?}: a process started mid-run kept the narrowed mask {narrowed}");
    drop(mid_run);
    let _ = std::fs::remove_dir_all(&out);
}

fn skip() -> bool {
    if skip_unless_root("moving other processes' threads, interrupts and the workqueue mask") {
        return true;
    }
    if netfi::host::affinity::online_cpus().len() < 2 {
        eprintln!("skipped: one core only");
        return true;
    }
    false
}

/// One test per case of the kill matrix: `name: kill`.
macro_rules! kill_matrix {
    ($($name:ident: $kill:expr,)*) => {$(
        #[test]
        fn $name() {
            if !skip() {
                kill_matrix_case($kill);
            }
        }
    )*};
}

kill_matrix! {
    kill_9_of_the_emulator_leaves_the_host_as_it_was: Kill::Emulator,
    kill_9_of_the_runner_leaves_the_host_as_it_was: Kill::Runner,
    kill_9_of_runner_and_emulator_leaves_the_host_as_it_was: Kill::RunnerAndEmulator,
    kill_9_of_the_guardian_leaves_the_host_as_it_was: Kill::Guardian,
    kill_9_of_everything_is_undone_by_netfi_restore: Kill::All,
}

/// A runner started with one CPU allowed (`taskset -c 0`): a requested
/// emulator core outside it is an error; by default the run goes on
/// unpinned with a warning in the report's isolation line.
#[test]
fn a_pin_that_cannot_be_honoured_is_an_error_or_a_warning_in_the_report() {
    if netfi::host::affinity::online_cpus().len() < 2 {
        eprintln!("skipped: one core only");
        return;
    }
    let _guard = machine::alone();
    let first = *netfi::host::affinity::online_cpus().iter().next().unwrap();
    let other = last_core();
    let on_one_core = |args: &[&str], out: &Path| {
        use std::os::unix::process::CommandExt;
        let mut cmd = netfi();
        cmd.arg("run").args(args).arg("--out").arg(out);
        // SAFETY: sched_setaffinity is async-signal-safe; it narrows the
        // child's own mask, as `taskset -c FIRST` would.
        unsafe {
            cmd.pre_exec(move || {
                let mut set: libc::cpu_set_t = std::mem::zeroed();
                libc::CPU_SET(first, &mut set);
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
                Ok(())
            });
        }
        cmd.output().unwrap()
    };
    let out = out_dir("pin-requested");
    let o = on_one_core(&["Normal", "--duration-s", "1", "--emulator-core", &other.to_string()], &out);
    assert!(!o.status.success(), "an explicit pin outside the allowed CPUs was accepted");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--emulator-core"), "{err}");

    let out = out_dir("pin-default");
    let o = on_one_core(&["Normal", "--duration-s", "1", "--seed", "2", "--json"], &out);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("WARNING") && err.contains("not pinned"), "{err}");
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("no report ({e}): {err}"));
    let iso = &report["emulator"]["isolation"];
    assert_eq!(iso["cleared"], false, "{iso}");
    assert!(iso["warnings"][0].as_str().is_some_and(|w| w.contains("not pinned")), "{iso}");
    let text = netfi::service::report::RunReport::to_text(&serde_json::from_value(report.clone()).unwrap());
    assert!(text.contains("WARNING"), "{text}");
    let _ = std::fs::remove_dir_all(&out);
}
