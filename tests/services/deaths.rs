//! A process of a real `netfi run` killed (kill -9) mid-stream: the run
//! ends long before its planned end, the host is put back, a report names
//! the dead, and no process of the run is left. The runner killed: its
//! processes die with it. Flags out of range: nothing starts.

use super::faults::processes_naming;
use super::*;

/// How long a 30 s run is planned to stream.
const PLANNED_S: &str = "30";

/// How long this test waits for a run to end after a kill: far less than
/// the run's planned 30 s, far more than the run needs. A bound on the
/// test's own wait, not a latency asserted.
const END_WAIT: Duration = Duration::from_secs(10);

/// A child waited for at most `wait`; `None` if it still ran (then it is
/// killed, and with it the run's processes).
fn wait_at_most(child: &mut std::process::Child, wait: Duration) -> Option<std::process::ExitStatus> {
    let t0 = Instant::now();
    while t0.elapsed() < wait {
        if let Some(s) = child.try_wait().unwrap() {
            return Some(s);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
    None
}

/// Kills whatever process of run `run_id` is still running (so that a
/// failing test leaves nothing behind), and returns what it found.
fn kill_left(run_id: &str) -> Vec<String> {
    let left = processes_naming(run_id);
    for p in &left {
        let pid: i32 = p.split(':').next().unwrap().parse().unwrap();
        // SAFETY: signalling a process of a run this test started.
        unsafe { libc::kill(pid, libc::SIGKILL) };
    }
    left
}

/// The record of the core a run's emulator (pid `emulator`) cleared, if left.
fn record_of(emulator: i32) -> Option<PathBuf> {
    let dir = netfi::host::record::state_dir().unwrap();
    netfi::host::record::list(&dir).into_iter().find(|p| p.to_string_lossy().contains(&format!("isolation-{emulator}-")))
}

/// Starts `netfi run Normal` for 30 s (the emulator's core cleared) with
/// `run_id` in `out`, and waits until its console streams. Returns the
/// runner and the emulator's pid.
fn start_long_run(run_id: &str, out: &Path) -> (std::process::Child, i32) {
    let child = spawn_run(out, &["Normal", "--duration-s", PLANNED_S, "--seed", "5", "--run-id", run_id]);
    let emulator = wait_pid(out, "emulator");
    wait_file(&out.join("console.ready"));
    std::thread::sleep(Duration::from_millis(500));
    (child, emulator)
}

/// Kills `role` of a 30 s run mid-stream; checks what every such run must
/// leave: it ended within [`END_WAIT`], failed, its report (printed and in
/// `report.json`) names the dead, no process of the run is left, and the
/// core it cleared is put back. Returns the report and the runner's stderr.
fn kill_one(role: &str) -> (Value, String) {
    let _guard = machine::alone();
    let out = out_dir(&format!("death-{role}"));
    let run_id = format!("it-death-{role}-{}", std::process::id());
    let (mut child, emulator) = start_long_run(&run_id, &out);
    let victim = wait_pid(&out, role);
    // SAFETY: signalling a process of the run this test started.
    unsafe { libc::kill(victim, libc::SIGKILL) };
    let ended = wait_at_most(&mut child, END_WAIT);
    let left = kill_left(&run_id);
    let o = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    let status = ended.unwrap_or_else(|| panic!("the run went on {END_WAIT:?} after its {role} was killed:\n{stderr}"));
    assert!(!status.success(), "a run whose {role} was killed must fail:\n{stderr}");
    let printed: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("no JSON report ({e}):\n{stderr}"));
    let written: Value = serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    for r in [&printed, &written] {
        let faults: Vec<&str> = r["faults"].as_array().unwrap().iter().filter_map(Value::as_str).collect();
        let dead = format!("{role} ended abnormally (signal 9)");
        assert!(faults.iter().any(|f| f.starts_with(&dead)), "{dead} not in {faults:?}");
        let procs = r["processes"].as_array().unwrap();
        assert!(procs.iter().any(|p| p["role"] == role && p["status"] == "signal 9"), "{procs:?}");
        assert!(procs.iter().all(|p| p["status"] != "running"), "{procs:?}");
    }
    assert_eq!(left, Vec::<String>::new(), "processes of the run still running");
    assert_eq!(record_of(emulator), None, "the record of the cleared core was left behind:\n{stderr}");
    (printed, stderr)
}

#[test]
fn a_killed_emulator_ends_the_run_at_once() {
    let (r, stderr) = kill_one("emulator");
    // What reached the robot was sent; nothing is made up.
    let f = &r["frames"];
    assert!(u(&f["received"]) <= u(&f["sent"]), "{f}");
    assert!(stderr.contains("the emulator died: stopping the run"), "{stderr}");
}

#[test]
fn a_killed_console_ends_the_run_at_once() {
    let (r, _) = kill_one("console");
    // The emulator and the robot close their accounts.
    let f = &r["frames"];
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + dropped + u(&f["held_at_end"]), "{f}");
    assert_eq!(u(&f["delivered"]), u(&f["received"]), "{f}");
    assert_eq!(r["emulator"]["ended_by"], "signal");
}

/// A 3 s run whose console is killed: the others close their accounts,
/// and the emulator saw its console go.
#[test]
fn a_killed_console_is_reported_and_the_others_finish() {
    let _guard = machine::alone();
    let out = out_dir("kill-console");
    let child = spawn_run(&out, &["Normal", "--duration-s", "3", "--seed", "7"]);
    let pid = wait_pid(&out, "console");
    std::thread::sleep(Duration::from_millis(700));
    // SAFETY: signalling a process this test started (through the runner).
    unsafe { libc::kill(pid, libc::SIGKILL) };
    let o = child.wait_with_output().unwrap();
    assert!(!o.status.success(), "a run with a killed process must fail");
    let r: Value = serde_json::from_slice(&o.stdout).unwrap();
    let faults: Vec<String> = r["faults"].as_array().unwrap().iter().map(|f| f.as_str().unwrap().to_string()).collect();
    assert!(faults.iter().any(|f| f.contains("console ended abnormally (signal 9)")), "{faults:?}");
    // The emulator and simulator finished and closed their own accounts.
    let f = &r["frames"];
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    assert!(u(&f["entered"]) > 300, "{f}");
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + dropped + u(&f["held_at_end"]));
    assert_eq!(u(&f["delivered"]), u(&f["received"]));
    assert_eq!(r["emulator"]["ended_by"], "signal");
    // The emulator saw its console go away (the runner reaps dead peers).
    let events = r["peer_events"].as_array().unwrap();
    assert!(events.iter().any(|e| e["peer"] == "console" && e["connected"] == 0), "{events:?}");
}

#[test]
fn a_killed_simulator_ends_the_run_at_once() {
    let (r, _) = kill_one("simulator");
    // The console and the emulator close their accounts.
    let f = &r["frames"];
    assert_eq!(u(&f["sent"]), u(&f["entered"]), "{f}");
    assert!(r["console"].is_object() && r["emulator"].is_object(), "{r:#}");
}

/// The runner killed: its processes get SIGTERM from the kernel (a
/// parent-death signal), end, and the emulator puts its core back.
#[test]
fn a_killed_runner_takes_its_processes_with_it() {
    let _guard = machine::alone();
    let out = out_dir("death-runner");
    let run_id = format!("it-death-runner-{}", std::process::id());
    let (mut child, emulator) = start_long_run(&run_id, &out);
    child.kill().unwrap();
    child.wait().unwrap();
    let t0 = Instant::now();
    while !processes_naming(&run_id).is_empty() && t0.elapsed() < END_WAIT {
        std::thread::sleep(Duration::from_millis(20));
    }
    let left = kill_left(&run_id);
    assert_eq!(left, Vec::<String>::new(), "processes of the run outlived its runner by {END_WAIT:?}");
    let e: Value = serde_json::from_slice(&std::fs::read(out.join("emulator.json")).unwrap()).unwrap();
    assert_eq!(e["ended_by"], "signal", "the emulator was stopped, not killed: {e:#}");
    let t0 = Instant::now();
    while record_of(emulator).is_some() && t0.elapsed() < END_WAIT {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(record_of(emulator), None, "the record of the cleared core was left behind");
}

/// A numeric flag out of range is refused before anything starts: no
/// output directory, no process.
#[test]
fn a_flag_out_of_range_starts_nothing() {
    for (flag, value, range) in [("--duration-s", "1e30", "at most a week"), ("--telemetry-ms", "18446744073709551615", "0..=3600000"), ("--frames", "0", "1..=")] {
        let out = out_dir(&format!("range{flag}"));
        let run_id = format!("it-range-{}", std::process::id());
        let o = netfi().args(["run", "Normal", flag, value, "--run-id", &run_id, "--out"]).arg(&out).output().unwrap();
        let left = kill_left(&run_id);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(flag) && err.contains(range), "{flag} {value}: {err}");
        assert!(!out.exists() && left.is_empty(), "{flag} {value}: the run started: {left:?}");
    }
    // Flags that are each in range but make a stream longer than a run.
    let o = netfi().args(["run", "Normal", "--frames", "10000000", "--rate-hz", "1"]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("a run lasts at most a week"), "{err}");
}

/// The longest telemetry interval accepted does not hold a short run up.
#[test]
fn the_longest_telemetry_interval_lets_a_run_end() {
    let _guard = machine::alone();
    let out = out_dir("telemetry-hour");
    let mut child = spawn_run(&out, &["Normal", "--duration-s", "1", "--seed", "2", "--telemetry-ms", "3600000"]);
    let status = wait_at_most(&mut child, Duration::from_secs(60)).expect("a 1 s run with an hour's telemetry interval did not end in a minute");
    assert!(status.success());
}

/// `netfi run --no-feedback`: no feedback path, every frame still
/// accounted for.
#[test]
fn a_run_without_feedback_has_no_feedback_path() {
    let (r, ok, _) = run("no-feedback", &["PLM-1", "--duration-s", "1", "--seed", "4", "--no-feedback"]);
    assert!(ok, "{r:#}");
    assert_conserved(&r);
    assert!(r["feedback"].is_null(), "{:#}", r["feedback"]);
    assert!(r["emulator"]["feedback"].is_null(), "{:#}", r["emulator"]);
    let (with, _, _) = run("with-feedback", &["PLM-1", "--duration-s", "1", "--seed", "4"]);
    assert!(with["feedback"].is_object(), "the same run with its feedback has the section");
}
