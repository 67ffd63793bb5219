//! Run integrity: a run owns its output directory, and Ctrl-C to the
//! terminal's process group ends a run cleanly.

use super::{assert_conserved, netfi, out_dir, spawn_run, u, wait_pid};
use crate::common::machine;
use serde_json::Value;
use std::os::unix::process::CommandExt;
use std::process::Stdio;
use std::time::{Duration, Instant};

/// A second `netfi run` on a directory in use is refused, naming the
/// directory and the first run's pid; the first run applies its own
/// scenario to the end.
#[test]
fn two_runs_on_one_directory_the_second_is_refused() {
    let _guard = machine::alone();
    let out = out_dir("two-runs");
    let first = spawn_run(&out, &["Normal", "--duration-s", "3", "--seed", "1"]);
    // The first run is streaming.
    wait_pid(&out, "console");
    let second = netfi().args(["run", "PLM-2", "--duration-s", "3", "--seed", "2", "--json", "--out"]).arg(&out).output().unwrap();
    assert!(!second.status.success(), "the second run must be refused");
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(err.contains("in use by another netfi run"), "{err}");
    assert!(err.contains(&out.display().to_string()), "the directory is named: {err}");
    assert!(err.contains(&format!("pid {}", first.id())), "the owner's pid is named: {err}");
    let o = first.wait_with_output().unwrap();
    let r: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("no report ({e}): {}", String::from_utf8_lossy(&o.stderr)));
    assert!(o.status.success(), "{r:#}");
    assert_conserved(&r);
    assert_eq!(r["scenario"], "Normal");
    assert_eq!(r["frames"]["dropped"].as_object().map(|d| d.len()), Some(0), "Normal drops nothing: {:#}", r["frames"]);
    assert_eq!(u(&r["frames"]["delivered"]), 3000, "{:#}", r["frames"]);
    let kept = std::fs::read_to_string(out.join("scenario.toml")).unwrap();
    assert!(kept.contains("Normal"), "{kept}");
    // Once the first run has ended the directory is free again.
    let third = netfi().args(["run", "Normal", "--frames", "200", "--seed", "3", "--json", "--out"]).arg(&out).output().unwrap();
    assert!(third.status.success(), "{}", String::from_utf8_lossy(&third.stderr));
}

/// SIGINT to the whole process group, as a terminal's Ctrl-C sends it: the
/// run ends within seconds, every frame is accounted for, and the report
/// says it was stopped (a normal end, not a fault).
#[test]
fn ctrl_c_to_the_process_group_ends_the_run() {
    let _guard = machine::alone();
    for attempt in 0..3 {
        let out = out_dir(&format!("ctrl-c-{attempt}"));
        let child = netfi()
            .args(["run", "Normal", "--duration-s", "30", "--seed", "5", "--json", "--out"])
            .arg(&out)
            .process_group(0)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let pgid = child.id() as i32;
        wait_pid(&out, "console");
        std::thread::sleep(Duration::from_millis(500 + 400 * attempt));
        // SAFETY: signalling the process group this test created.
        unsafe { libc::kill(-pgid, libc::SIGINT) };
        let t0 = Instant::now();
        let o = child.wait_with_output().unwrap();
        let took = t0.elapsed();
        let r: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("no report ({e}): {}", String::from_utf8_lossy(&o.stderr)));
        // A 30 s stream cut short: far less than the planned end (a bound
        // on the stopping policy, not on the machine's latency).
        assert!(took < Duration::from_secs(15), "attempt {attempt}: the run went on for {took:?} after Ctrl-C");
        assert!(u(&r["frames"]["sent"]) < 25_000, "{:#}", r["frames"]);
        assert_conserved(&r);
        // A stop asked for is a normal end: reported as such, no fault.
        assert_eq!(r["stopped"], true, "the report says it was stopped");
        assert_eq!(r["faults"].as_array().map(Vec::len), Some(0), "{:#}", r["faults"]);
        assert_eq!(r["console"]["ended_by"], "signal", "{:#}", r["console"]);
        assert!(o.status.success(), "a stopped run exits as one that ran its course: {}", String::from_utf8_lossy(&o.stderr));
    }
}

/// A full disk: the output directory on a 128 KiB tmpfs (mounting one
/// needs root; elsewhere the test says so and passes, or fails where
/// `NETFI_REQUIRE_ROOT` is set). Every failed write is an error naming its
/// file, the run exits non-zero, and the text report still prints to
/// stdout. (A file size limit, RLIMIT_FSIZE, would also
/// refuse iceoryx2's shared-memory segments, so it cannot stand in.)
#[test]
fn a_full_disk_names_the_files_not_written_and_the_report_still_prints() {
    let _guard = machine::alone();
    let out = out_dir("full-disk");
    std::fs::create_dir_all(&out).unwrap();
    let mounted = std::process::Command::new("mount").args(["-t", "tmpfs", "-o", "size=128k", "tmpfs"]).arg(&out).output();
    let why = match mounted {
        Ok(o) if o.status.success() => None,
        Ok(o) => Some(format!("`mount -t tmpfs` failed ({}): {}", o.status, String::from_utf8_lossy(&o.stderr).lines().next().unwrap_or_default())),
        Err(e) => Some(format!("cannot run `mount`: {e}")),
    };
    if let Some(why) = why {
        let _ = std::fs::remove_dir_all(&out);
        assert!(std::env::var_os("NETFI_REQUIRE_ROOT").is_none(), "NETFI_REQUIRE_ROOT is set but a tmpfs cannot be mounted on {}: {why}", out.display());
        eprintln!("skipping: cannot mount a small tmpfs here ({why}): the full-disk test did not run");
        return;
    }
    struct Unmount(std::path::PathBuf);
    impl Drop for Unmount {
        fn drop(&mut self) {
            let _ = std::process::Command::new("umount").arg(&self.0).status();
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
    let _unmount = Unmount(out.clone());
    // 4,000 frames: a trace of ≈ 240 KB, received.csv ≈ 72 KB.
    let o = netfi().args(["run", "Normal", "--frames", "4000", "--rate-hz", "2000", "--seed", "1", "--out"]).arg(&out).output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    eprintln!("{stdout}\n{stderr}");
    assert!(!o.status.success(), "a run that could not write its files must fail:\n{stdout}\n{stderr}");
    assert!(stdout.contains("frames") && stdout.contains("sent"), "the text report prints:\n{stdout}\n{stderr}");
    assert!(stdout.contains("trace_emulator.csv") && stdout.contains("No space left on device"), "the trace is named as not written:\n{stdout}");
    // No file is cut under its own name: each histogram log there decodes
    // whole, each CSV ends its last row; every file left `.partial` is
    // named as cut in the report.
    let mut cut = 0;
    for e in std::fs::read_dir(&out).unwrap().filter_map(|e| e.ok()) {
        let (path, name) = (e.path(), e.file_name().to_string_lossy().into_owned());
        if name.ends_with(".partial") {
            cut += 1;
            assert!(stdout.contains(&format!("cut file: {}", path.display())), "{name} is not named as cut:\n{stdout}");
        } else if name.ends_with(".hlog") {
            assert!(netfi::html::inputs::read_hlog(&path).is_ok(), "{name} is cut under its own name ({} bytes)", std::fs::metadata(&path).unwrap().len());
        } else if name.ends_with(".csv") {
            let text = std::fs::read(&path).unwrap();
            assert!(text.ends_with(b"\n"), "{name} is cut under its own name ({} bytes)", text.len());
        }
    }
    assert!(cut > 0, "a disk this small cuts some file");
    // The last words name the report as it is on disk.
    let report = out.join("report.json");
    if !report.exists() {
        assert!(!stderr.contains(&format!("(its report: {})", report.display())), "a report not written is named as written:\n{stderr}");
    }
}

/// kill -9 of the runner mid-run: its processes end with it, and `netfi
/// report` on what they left says the run was interrupted, in its text and
/// its faults, rather than rebuilding it as if it were whole.
#[test]
fn a_killed_runner_leaves_a_directory_reported_as_interrupted() {
    let _guard = machine::alone();
    let out = out_dir("kill-runner");
    let mut child = spawn_run(&out, &["Normal", "--duration-s", "6", "--seed", "9", "--no-isolate"]);
    let emulator = wait_pid(&out, "emulator");
    wait_pid(&out, "console");
    std::thread::sleep(Duration::from_secs(1));
    child.kill().unwrap();
    let _ = child.wait();
    // Its processes die with it (a parent-death signal): wait for the
    // emulator, which writes its report on the way out.
    let t0 = Instant::now();
    while std::path::Path::new(&format!("/proc/{emulator}")).exists() && t0.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(out.join("run.unfinished").exists(), "no mark of the unfinished run");
    assert!(!out.join("report.json").exists(), "a report of a run its runner never finished");
    let o = netfi().arg("report").arg(&out).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(!o.status.success(), "an interrupted run reported as whole:\n{text}");
    assert!(String::from_utf8_lossy(&o.stderr).contains("interrupted: the runner of this run did not finish it"), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.contains("INTERRUPTED"), "the report does not say the run was interrupted:\n{text}");
    assert!(text.contains("FAULT      interrupted: the runner of this run did not finish it (netfi run"), "{text}");
    // A run that ends has no mark left.
    let o = netfi().args(["run", "Normal", "--frames", "200", "--seed", "3", "--no-isolate", "--out"]).arg(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!out.join("run.unfinished").exists());
    let o = netfi().arg("report").arg(&out).output().unwrap();
    assert!(!String::from_utf8_lossy(&o.stdout).contains("INTERRUPTED"));
}

/// kill -9 of the emulator mid-run: its trace and histogram logs are on
/// disk up to its last second (the writer flushes every second), under
/// their cut names, and the run's report names each as cut.
#[test]
fn a_killed_emulator_leaves_its_trace_up_to_its_last_second() {
    let _guard = machine::alone();
    let out = out_dir("kill-emulator-trace");
    let child = spawn_run(&out, &["Normal", "--duration-s", "6", "--seed", "9"]);
    let pid = wait_pid(&out, "emulator");
    wait_pid(&out, "console");
    // At 1 kHz, 3 s of stream: at least the first 2 s are flushed.
    std::thread::sleep(Duration::from_secs(3));
    // SAFETY: signalling a process of the run this test started.
    unsafe { libc::kill(pid, libc::SIGKILL) };
    let o = child.wait_with_output().unwrap();
    assert!(!o.status.success(), "a run with a killed emulator fails");
    assert!(!out.join("trace.csv").exists(), "a trace joined from a cut one is not whole");
    let trace = out.join("trace.csv.partial");
    let text = std::fs::read_to_string(&trace).unwrap_or_else(|e| panic!("{}: {e}\n{}", trace.display(), String::from_utf8_lossy(&o.stderr)));
    let rows = text.lines().count() - 1;
    assert!(rows >= 1500, "only {rows} rows of a 3 s stream at 1 kHz survived");
    let log = std::fs::read_to_string(out.join("decision.hlog.partial")).unwrap();
    let intervals = log.lines().filter(|l| !l.starts_with('#') && !l.starts_with('"') && l.contains(',')).count();
    assert!(intervals >= 2, "{intervals} intervals in decision.hlog.partial:\n{log}");
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let faults: Vec<&str> = r["faults"].as_array().unwrap().iter().filter_map(|f| f.as_str()).collect();
    for cut in ["trace.csv.partial", "decision.hlog.partial"] {
        assert!(faults.iter().any(|f| f.starts_with("cut file:") && f.contains(cut)), "{cut} not named as cut: {faults:?}");
    }
}

/// A pin that cannot be honoured is refused before any port opens: nothing
/// of the run is left in /dev/shm.
#[test]
fn an_emulator_core_the_host_lacks_is_refused_before_any_port_opens() {
    let run_id = format!("nocore{}", std::process::id());
    let core = ::netfi::host::affinity::online_cpus().iter().max().copied().unwrap_or(0) + 1;
    let o = netfi()
        .args(["emulator", "--run-id", &run_id, "--scenario", "Normal", "--core", &core.to_string()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{stderr}");
    assert!(stderr.contains(&format!("--core {core}: this process may only run on CPU(s)")), "{stderr}");
    let left: Vec<String> = std::fs::read_dir("/dev/shm")
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(&format!("_{run_id}_")))
        .collect();
    assert!(left.is_empty(), "left in /dev/shm: {left:?}");
}
