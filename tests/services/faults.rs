//! Copies and flips in a real run (docs/spec.md §3.8, §3.9): a `duplicate`
//! and a `corrupt` stage applied by the real-time emulator between the
//! real console and simulator; and processes of a run of several streams
//! killed mid-run.

use super::{allowed_cpus, assert_conserved, core_affinity_count, netfi, out_dir, run, spawn_run, u, wait_pid, Witness};
use crate::common::machine;
use crate::common::scratch::Scratch;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// Duplicate (10%), then corrupt (20%, each frame and copy its own flip),
/// then Bernoulli loss (5%, which also drops copies), then a short uniform
/// delay that may reorder. Every frame and copy is accounted for, exactly;
/// the simulator's checksum catches the flips that land in bytes it covers.
#[test]
fn duplicates_and_corruption_are_accounted_for_exactly() {
    let dir = Scratch::new("it-dup-corrupt-scenario");
    let scenario = dir.file(
        "dup_corrupt.toml",
        "name = \"dup_corrupt\"\n\
         [[stage]]\nmodel = \"duplicate\"\np = 0.1\n\
         [[stage]]\nmodel = \"corrupt\"\np = 0.2\n\
         [[stage]]\nmodel = \"bernoulli\"\np = 0.05\n\
         [[stage]]\nmodel = \"delay\"\nmin_ms = 1\ndist = \"uniform\"\njitter_ms = 2\norder = \"reorder\"\n",
    );
    let (r, ok, out) = run("dup-corrupt", &[scenario.to_str().unwrap(), "--frames", "6000", "--rate-hz", "2000", "--seed", "11"]);
    assert!(ok, "{r:#}");
    let f = &r["frames"];
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    let (entered, duplicated, delivered, held) = (u(&f["entered"]), u(&f["duplicated"]), u(&f["delivered"]), u(&f["held_at_end"]));
    // sent = entered; every frame and copy has one fate; all reached the robot.
    assert_eq!(u(&f["sent"]), entered, "{f}");
    assert_eq!(entered + duplicated, delivered + dropped + held, "{f}");
    assert_eq!(delivered, u(&f["received"]), "{f}");
    assert_eq!(held, 0, "{f}");
    assert_eq!(f["balanced"], true, "{f}");
    assert!(delivered > entered - dropped, "copies were delivered: {f}");

    // The trace: per frame, the copies made are its copy rows plus
    // `copies_dropped`; delivered copies = copies made − copies dropped.
    let trace = std::fs::read_to_string(out.join("trace.csv")).unwrap();
    let header: Vec<&str> = trace.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no column {name}"));
    let (fate, copy, copies_dropped, corrupted, recv) = (col("fate"), col("copy"), col("copies_dropped"), col("corrupted"), col("recv_ns"));
    let rows: Vec<Vec<&str>> = trace.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let originals = rows.iter().filter(|c| c[copy] == "0").count() as u64;
    let copy_rows: Vec<&Vec<&str>> = rows.iter().filter(|c| c[copy] != "0").collect();
    let made_dropped: u64 = rows.iter().filter_map(|c| c[copies_dropped].parse::<u64>().ok()).sum();
    assert_eq!(originals, entered);
    assert_eq!(copy_rows.len() as u64 + made_dropped, duplicated);
    let copies_delivered = copy_rows.iter().filter(|c| c[fate] == "delivered").count() as u64;
    assert_eq!(copies_delivered, duplicated - made_dropped, "every copy taken was delivered");
    assert_eq!(rows.iter().filter(|c| c[fate] == "delivered").count() as u64, delivered);
    assert_eq!(rows.iter().filter(|c| c[fate] == "dropped").count() as u64 + made_dropped, dropped);
    // Every delivered row, copies included, has the robot's receive time.
    assert!(rows.iter().filter(|c| c[fate] == "delivered").all(|c| c[recv].parse::<u64>().is_ok()), "a delivered row without recv_ns");

    // Corruption: caught + passed = corrupted delivered; the simulator's
    // bad checksums are exactly the caught ones (the console's are valid).
    let c: &Value = &f["corruption"];
    let corrupted_delivered = u(&c["delivered"]);
    assert_eq!(corrupted_delivered, rows.iter().filter(|r| r[fate] == "delivered" && r[corrupted] == "1").count() as u64);
    assert_eq!(u(&c["caught"]) + u(&c["passed"]), corrupted_delivered, "{c}");
    assert_eq!(u(&c["caught"]), u(&r["simulator"]["bad_checksum"]), "{c}");
    assert_eq!(u(&c["corrupted"]), corrupted_delivered, "nothing held, nothing dropped after the corrupt stage but loss");
    // One flip per corrupted item, uniform over the 992 bits: caught with
    // probability 44/124 = 11/31, independently. Within 5 binomial
    // standard deviations (two-sided α ≈ 6e-7).
    let n = corrupted_delivered as f64;
    let p = 11.0 / 31.0;
    let sd = (n * p * (1.0 - p)).sqrt();
    assert!(n > 500.0, "{c}");
    assert!((u(&c["caught"]) as f64 - n * p).abs() < 5.0 * sd, "caught {} of {n}, expected {:.0} ± {:.0}", u(&c["caught"]), n * p, 5.0 * sd);
    // Realized rates of the stages, each within 5 binomial standard deviations.
    let dup_rate = duplicated as f64 / entered as f64;
    assert!((dup_rate - 0.1).abs() < 5.0 * (0.1 * 0.9 / entered as f64).sqrt(), "duplicated {duplicated} of {entered}");
    // Corruption and loss are independent: of the items that passed the
    // loss stage, a fraction 0.2 were corrupted.
    let passed_loss = (entered + duplicated - u(&f["dropped"]["bernoulli"])) as f64;
    let corrupted_rate = u(&c["corrupted"]) as f64 / passed_loss;
    assert!((corrupted_rate - 0.2).abs() < 5.0 * (0.2 * 0.8 / passed_loss).sqrt(), "corrupted rate {corrupted_rate}");
}

/// The robot → console feedback path applies `duplicate` in its return
/// scenario: every feedback sample and copy is accounted for and reaches the
/// console; `corrupt` there (feedback is not an ITP frame) is refused by
/// name before the run starts.
#[test]
fn the_feedback_path_duplicates_and_refuses_corruption() {
    let dir = Scratch::new("it-fb-dup-scenarios");
    let dup = dir.file("fb_dup.toml", "name = \"fb_dup\"\n[[stage]]\nmodel = \"duplicate\"\np = 0.2\n[[stage]]\nmodel = \"bernoulli\"\np = 0.05\n");
    let corrupt = dir.file("fb_corrupt.toml", "name = \"fb_corrupt\"\n[[stage]]\nmodel = \"corrupt\"\np = 0.2\n");
    let (r, ok, _) = run("fb-dup", &["Normal", "--return-scenario", dup.to_str().unwrap(), "--frames", "3000", "--rate-hz", "2000", "--seed", "9"]);
    assert!(ok, "{r:#}");
    let fb = &r["feedback"];
    let dropped: u64 = fb["dropped"].as_object().unwrap().values().map(u).sum();
    let (entered, duplicated, delivered) = (u(&fb["entered"]), u(&fb["duplicated"]), u(&fb["delivered"]));
    assert_eq!(entered + duplicated, delivered + dropped + u(&fb["held_at_end"]), "{fb}");
    assert_eq!(Some(delivered), fb["received_by_console"].as_u64(), "{fb}");
    assert_eq!(fb["balanced"], true, "{fb}");
    // 3000 feedback samples, each copied with probability 0.2: within 5
    // binomial standard deviations.
    assert!((duplicated as f64 - 600.0).abs() < 5.0 * (3000.0f64 * 0.2 * 0.8).sqrt(), "{fb}");
    let out = out_dir("fb-corrupt");
    let o = {
        let _guard = machine::alone();
        netfi().args(["run", "Normal", "--return-scenario", corrupt.to_str().unwrap(), "--frames", "100", "--seed", "9", "--out"]).arg(&out).output().unwrap()
    };
    std::fs::remove_dir_all(&out).ok();
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("the `corrupt` stage") && stderr.contains("fb_corrupt"), "{stderr}");
}

/// What a run of three streams left when one of its processes was killed.
struct Killed {
    report: Value,
    stderr: String,
    out: PathBuf,
    /// The emulator's core was cleared: the witness was moved off it.
    cleared: bool,
}

/// `netfi run Normal --streams 3` (3 s at 1 kHz, the emulator's core
/// cleared), whose `role` in directory `dir(out)` is sent SIGKILL once
/// every stream's console streams. Checks what every killed run must
/// leave: every process of the run ended, the run failed with a report,
/// nothing of its streams' services in /dev/shm or under iceoryx2's root,
/// no record of a cleared core, and a witness process's CPUs as they were.
fn kill_in_three_streams(name: &str, role: &str, dir: impl Fn(&Path) -> PathBuf) -> Killed {
    let _guard = machine::alone();
    let out = out_dir(name);
    let run_id = format!("it-{name}-{}", std::process::id());
    let witness = Witness(Command::new("sleep").arg("60").spawn().unwrap());
    let cpus_before = allowed_cpus(witness.id());
    // The emulator's core is the last; the witness may run there unless this test may not.
    let cores = core_affinity_count();
    let cleared = cores >= 2 && netfi::host::isolate::parse_list(&cpus_before).unwrap().contains(&(cores - 1));
    let child = spawn_run(&out, &["Normal", "--streams", "3", "--duration-s", "3", "--seed", "5", "--run-id", &run_id]);
    let emulator = wait_pid(&out, "emulator");
    for k in 0..3 {
        wait_pid(&out.join(format!("stream-{k}")), "console");
    }
    let victim = wait_pid(&dir(&out), role);
    std::thread::sleep(Duration::from_millis(700));
    // SAFETY: signalling a process of the run this test started.
    unsafe { libc::kill(victim, libc::SIGKILL) };
    let o = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "a run with a killed {role} must fail:\n{stderr}");
    let report: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("no JSON report ({e}):\n{stderr}"));
    assert_eq!(report["processes"].as_array().map(Vec::len), Some(7), "3 consoles, the emulator, 3 robots: {:#}", report["processes"]);
    assert!(report["processes"].as_array().unwrap().iter().all(|p| p["status"] != "running"), "{:#}", report["processes"]);
    assert_eq!(processes_naming(&run_id), Vec::<String>::new(), "processes of the run still running");
    let left = iceoryx2_files_of(&run_id, 3);
    assert!(left.is_empty(), "the run left {left:?}\n{stderr}");
    let dir = netfi::host::record::state_dir().unwrap();
    let record = netfi::host::record::list(&dir).into_iter().find(|p| p.to_string_lossy().contains(&format!("isolation-{emulator}-")));
    assert_eq!(record, None, "the record of the cleared core was left behind");
    assert_eq!(allowed_cpus(witness.id()), cpus_before, "the witness's CPUs were not put back:\n{stderr}");
    Killed { report, stderr, out, cleared }
}

/// Processes whose command line names `run_id` (every process of the run does, by `--run-id`).
pub(super) fn processes_naming(run_id: &str) -> Vec<String> {
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().filter_map(|e| e.ok()) {
        let Ok(cmd) = std::fs::read(e.path().join("cmdline")) else { continue };
        let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
        if cmd.contains(run_id) {
            found.push(format!("{}: {cmd}", e.file_name().to_string_lossy()));
        }
    }
    found
}

/// Files of the services of `streams` streams of run `run_id` in /dev/shm
/// and under this user's iceoryx2 root (its node and service directories).
pub(super) fn iceoryx2_files_of(run_id: &str, streams: usize) -> Vec<PathBuf> {
    use netfi::transport::{IpcConfig, RunId};
    let prefixes: Vec<String> =
        (0..streams).map(|k| IpcConfig::new(RunId::new(&netfi::service::plan::stream_run_id(run_id, k)).unwrap()).prefix().to_string()).collect();
    let mut left = Vec::new();
    let mut dirs = vec![PathBuf::from("/dev/shm"), netfi::transport::ipc::user_root_dir()];
    while let Some(d) = dirs.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else { continue };
        for e in rd.filter_map(|e| e.ok()) {
            let name = e.file_name().to_string_lossy().into_owned();
            if prefixes.iter().any(|p| name.starts_with(p.as_str())) {
                left.push(e.path());
            } else if d != Path::new("/dev/shm") && e.file_type().is_ok_and(|t| t.is_dir()) {
                dirs.push(e.path());
            }
        }
    }
    left
}

/// SIGKILL to the emulator of three streams: every stream's report names
/// it, every console and robot ends, and the runner puts back what the
/// emulator moved off its core and reaps what its nodes left.
#[test]
fn a_killed_emulator_of_three_streams_ends_every_stream_and_leaves_nothing() {
    let k = kill_in_three_streams("streams-kill-emulator", "emulator", |out| out.to_path_buf());
    let faults: Vec<&str> = k.report["faults"].as_array().unwrap().iter().filter_map(Value::as_str).collect();
    for s in 0..3 {
        let fault = format!("stream {s}: emulator ended abnormally (signal 9)");
        assert!(faults.iter().any(|f| f.starts_with(&fault)), "{fault} not in {faults:?}");
        let own: Value = serde_json::from_slice(&std::fs::read(k.out.join(format!("stream-{s}/report.json"))).unwrap()).unwrap();
        let f = &own["frames"];
        // What reached the robot was sent; nothing is made up.
        assert!(u(&f["received"]) <= u(&f["sent"]), "stream {s}: {f}");
        assert!(u(&f["sent"]) > 0, "stream {s}: {f}");
    }
    assert!(!k.cleared || k.stderr.contains("a killed process left moved"), "the runner did not put back what the emulator moved:\n{}", k.stderr);
}

/// SIGKILL to stream 1's console: the run fails naming it; streams 0 and
/// 2 run to their end, every frame accounted for; stream 1's emulator and
/// robot close their own accounts, and the emulator saw its console go.
#[test]
fn a_killed_console_of_one_stream_is_reported_and_the_others_finish() {
    let k = kill_in_three_streams("streams-kill-console", "console", |out| out.join("stream-1"));
    let faults: Vec<&str> = k.report["faults"].as_array().unwrap().iter().filter_map(Value::as_str).collect();
    assert!(faults.iter().any(|f| f.starts_with("stream 1: console ended abnormally (signal 9)")), "{faults:?}");
    assert!(faults.iter().all(|f| f.starts_with("stream 1: ")), "only stream 1 failed: {faults:?}");
    let own = |s: usize| -> Value { serde_json::from_slice(&std::fs::read(k.out.join(format!("stream-{s}/report.json"))).unwrap()).unwrap() };
    for s in [0, 2] {
        let r = own(s);
        assert_conserved(&r);
        assert_eq!(u(&r["frames"]["sent"]), 3000, "stream {s}");
    }
    let r = own(1);
    let f = &r["frames"];
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    assert!(u(&f["entered"]) > 300, "{f}");
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + dropped + u(&f["held_at_end"]), "{f}");
    assert_eq!(u(&f["delivered"]), u(&f["received"]), "{f}");
    assert_eq!(r["emulator"]["ended_by"], "signal");
    let events = r["peer_events"].as_array().unwrap();
    assert!(events.iter().any(|e| e["peer"] == "console" && e["connected"] == 0), "{events:?}");
}
