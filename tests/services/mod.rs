//! The three real processes over iceoryx2: short runs (seconds) that assert
//! exact conservation, realized loss, delays, replay of the real capture, and
//! the behaviour under killed processes.
//!
//! The runs are serialized: each has a busy-waiting emulator pinned to a
//! core, and a 2-core machine has room for one at a time.

use crate::common::wait_file;
use crate::common::netfi::emulator_pin;
use crate::common::netfi::netfi;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use crate::common::machine;
use crate::common::scratch::Scratch;
use std::time::{Duration, Instant};

mod deaths;
mod faults;
mod integrity;
mod registered;
mod shipped;
mod streams;
mod video;

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("netfi-it-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// `netfi run` with `args`; returns the JSON report and whether it exited 0.
fn run(name: &str, args: &[&str]) -> (Value, bool, PathBuf) {
    let _guard = machine::alone();
    let out = out_dir(name);
    let o = netfi().arg("run").args(args).arg("--out").arg(&out).arg("--json").output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let report: Value = serde_json::from_str(&stdout).unwrap_or_else(|e| {
        panic!("{name}: no JSON report ({e}); stderr:\n{}", String::from_utf8_lossy(&o.stderr))
    });
    (report, o.status.success(), out)
}

#[track_caller]
/// `netfi run ARGS --json --out OUT`, started, its output piped.
fn spawn_run(out: &Path, args: &[&str]) -> std::process::Child {
    netfi().arg("run").args(args).args(["--json", "--out"]).arg(out).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap()
}

fn u(v: &Value) -> u64 {
    match v.as_u64() {
        Some(n) => n,
        None => panic!("not a count: {v}"),
    }
}

/// sent = entered = delivered + dropped + held_at_end, delivered = received.
fn assert_conserved(r: &Value) {
    let f = &r["frames"];
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&f["sent"]), u(&f["entered"]), "{f}");
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + dropped + u(&f["held_at_end"]), "{f}");
    assert_eq!(u(&f["delivered"]), u(&f["received"]), "{f}");
    assert_eq!(f["balanced"], true, "{f}");
}

#[test]
fn normal_delivers_every_frame_and_measures_overhead() {
    let (r, ok, out) = run("normal", &["Normal", "--duration-s", "2", "--seed", "1"]);
    assert!(ok, "{r:#}");
    assert_conserved(&r);
    assert_eq!(u(&r["frames"]["sent"]), 2000);
    assert_eq!(u(&r["frames"]["delivered"]), 2000);
    assert_eq!(u(&r["frames"]["held_at_end"]), 0);
    for h in ["decision", "release_lateness", "end_to_end_extra"] {
        for p in ["p50", "p99", "p999", "max"] {
            assert!(r["overhead_ns"][h][p].is_u64(), "overhead_ns.{h}.{p} missing");
        }
        assert_eq!(u(&r["overhead_ns"][h]["count"]), 2000, "{h}");
    }
    // The trace has one row per frame and the receive time of each.
    let trace = std::fs::read_to_string(out.join("trace.csv")).unwrap();
    let rows: Vec<&str> = trace.lines().skip(1).collect();
    assert_eq!(rows.len(), 2000);
    assert!(rows.iter().all(|l| l.contains(",delivered,") && !l.ends_with(',')), "{}", rows[0]);
    for f in ["decision.hlog", "lateness.hlog", "end_to_end.hlog", "report.json"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    // The simulator's logs have one interval per second of its run (the
    // last one partial), their counts adding up to the frames it received,
    // and the whole-run figures are those of the intervals' sum.
    let sim = &r["simulator"];
    let seconds = sim["duration_s"].as_f64().unwrap();
    for (file, count, summary) in [
        ("end_to_end.hlog", u(&sim["received"]), &sim["end_to_end_extra_ns"]),
        ("direct_hop.hlog", u(&sim["received_direct"]), &sim["direct_hop_ns"]),
    ] {
        let (total, intervals) = netfi::html::inputs::read_hlog_intervals(&out.join(file)).unwrap();
        // An interval is cut once a second has passed (never sooner), so
        // there are at most as many as whole seconds, plus the last partial
        // one; how much later than the second a cut falls is the host's.
        let n = intervals.len() as f64;
        assert!(n >= 2.0 && n <= seconds.ceil() + 1.0, "{file}: {n} intervals in a run of {seconds} s");
        let full = &intervals[..intervals.len() - 1];
        assert!(full.iter().all(|i| i.duration_s >= 0.999), "{file}: {intervals:?}");
        assert!(intervals.windows(2).all(|w| (w[1].start_s - (w[0].start_s + w[0].duration_s)).abs() < 0.002), "{file}: not contiguous: {intervals:?}");
        assert_eq!(intervals.iter().map(|i| i.count).sum::<u64>(), count, "{file}");
        assert_eq!(total.len(), count, "{file}");
        assert_eq!(u(&summary["count"]), count, "{file}");
        assert_eq!(u(&summary["p99"]), total.value_at_quantile(0.99), "{file}");
        assert_eq!(u(&summary["max"]), total.max(), "{file}");
    }
}

/// A run through a `rate` link below its capacity: the report's link
/// section shows the utilisation the offered load implies, the queue second
/// by second and the time at the link; the HTML report shows them too.
#[test]
fn a_rate_link_reports_utilisation_queue_and_queueing_delay() {
    let dir = Scratch::new("it-rate-link-scenario");
    // 2 Mbit/s; 124 + 42 = 166 wire bytes a frame, 1 328 bits: 0.664 ms of
    // the link's time each; at 1 kHz the offered load is 1.328 Mbit/s.
    let scenario = dir.file("rate.toml", "name = \"rate\"\n[[stage]]\nmodel = \"rate\"\nrate_bit_s = 2_000_000\noverhead_bytes = 42\n");
    let (r, ok, out) = run("rate-link", &[scenario.to_str().unwrap(), "--duration-s", "2", "--seed", "1"]);
    assert!(ok, "{r:#}");
    assert_conserved(&r);
    let links = r["links"].as_array().unwrap_or_else(|| panic!("no links section: {r:#}"));
    assert_eq!(links.len(), 1, "{links:?}");
    let l = &links[0];
    let f = |k: &str| l[k].as_f64().unwrap_or_else(|| panic!("{k} missing: {l}"));
    let frames = u(&l["frames"]);
    assert_eq!(frames + u(&l["frames_dropped"]), u(&r["frames"]["entered"]), "{l}");
    assert_eq!(u(&l["bytes"]), frames * 166, "{l}");
    // Utilisation = busy time over the span from the first frame to the
    // last departure; busy time = bytes · 8 / rate exactly, so utilisation ·
    // capacity is the bit rate carried over the same span.
    assert_eq!(f("capacity_bit_s"), 2e6);
    assert!((f("utilisation") * f("capacity_bit_s") - f("carried_bit_s")).abs() < 1e-6 * f("carried_bit_s"), "{l}");
    // Below capacity the link carries what is offered: over the span of
    // arrivals A (first to last frame taken in, from the trace) the
    // offered load is bytes · 8 / A, and utilisation = busy / (A + the
    // last frame's time at the link) = (offered / capacity) · A / (A +
    // d_last), with d_last at most the report's longest time at the link.
    // (The arrivals are the emulator's take times: on a loaded host they
    // come in bursts, so A is measured rather than taken as 2 s.)
    let trace = std::fs::read_to_string(out.join("trace.csv")).unwrap();
    let ingress: Vec<u64> = trace.lines().skip(1).map(|row| row.split(',').nth(4).unwrap().parse().unwrap()).collect();
    let span_s = (ingress.iter().max().unwrap() - ingress.iter().min().unwrap()) as f64 / 1e9;
    let offered = u(&l["bytes"]) as f64 * 8.0 / span_s / 2e6;
    let d_last_s = l["delay_ms"]["max"].as_f64().unwrap() / 1e3;
    let (lo, hi) = (offered * span_s / (span_s + d_last_s), offered);
    let util = f("utilisation");
    assert!(util >= lo * (1.0 - 1e-6) && util <= hi * (1.0 + 1e-6), "utilisation {util} outside [{lo}, {hi}]: {l}");
    assert!(util < 1.0, "{l}");
    // No frame spends less than its own serialization at the link (0.664
    // ms; the report's percentiles are HdrHistogram's, within 0.1%).
    assert!(l["delay_ms"]["p50"].as_f64().unwrap() >= 0.664 * (1.0 - 1e-3), "{l}");
    assert!(l["delay_ms"]["max"].as_f64().unwrap() >= l["delay_ms"]["p99"].as_f64().unwrap(), "{l}");
    // Occupancy second by second: each second of the stream has an entry,
    // and a frame counts itself in the queue.
    let occ = l["occupancy"].as_array().unwrap();
    assert!((2..=3).contains(&occ.len()), "{occ:?}");
    assert!(occ.iter().all(|o| u(&o["packets_max"]) >= 1 && u(&o["bytes_max"]) >= 166), "{occ:?}");
    // emulator.json carries the same section.
    let em: Value = serde_json::from_slice(&std::fs::read(out.join("emulator.json")).unwrap()).unwrap();
    assert_eq!(em["links"][0]["frames"], l["frames"], "{em:#}");
    // The HTML report: the table and the queue plot with one point a second.
    let o = netfi().arg("report").arg(&out).arg("--html").output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("id=\"links\"") && html.contains(&format!("data-value=\"{}\"", l["utilisation"])), "no link table");
    let at = html.find("id=\"plot-link-occupancy-1\"").expect("no occupancy plot");
    let plot = &html[at..at + html[at..].find("</svg>").unwrap()];
    assert!(plot.contains("<polyline"), "no line in the occupancy plot");
    // And what netfi added over time (end to end and release lateness per bin).
    let at = html.find("id=\"plot-added-over-time\"").expect("no added-over-time plot");
    assert!(html[at..at + html[at..].find("</svg>").unwrap()].contains("<polyline"), "no line in the added-over-time plot");
}

#[test]
fn plm_loss_is_conserved_and_realizes_the_model() {
    // ge_lomax decides per frame, not per time: with the seed fixed, its
    // fates do not depend on the timing of this run.
    let (r, ok, _) = run("plm", &["PLM-2", "--frames", "20000", "--rate-hz", "5000", "--seed", "3"]);
    assert!(ok, "{r:#}");
    assert_conserved(&r);
    // The same seed in simulated time gives the very same drops.
    crate::common::assert_plm2_seed3_is_the_checks(&r);
}

#[test]
fn dlm_delays_are_injected_and_held_frames_released() {
    let (r, ok, out) = run("dlm", &["DLM-1", "--duration-s", "2", "--seed", "4"]);
    assert!(ok, "{r:#}");
    assert_conserved(&r);
    assert_eq!(u(&r["frames"]["delivered"]), 2000);
    // The mean of 2000 draws of a law with mean 103.0 ms and sd ≈ 33 ms:
    // within ±5 standard errors (3.7 ms).
    let mean_ms = r["injected_delay_ns"]["mean"].as_f64().unwrap() / 1e6;
    let model = r["stages"][0]["delay_ms_model"].as_f64().unwrap();
    assert!((mean_ms - model).abs() < 3.7, "mean {mean_ms} vs {model}");
    // Per frame, the robot never sees a command earlier than its injected
    // delay after it was sent (how much later is a measurement, not a test).
    let trace = std::fs::read_to_string(out.join("trace.csv")).unwrap();
    let mut checked = 0;
    for row in trace.lines().skip(1) {
        let c: Vec<&str> = row.split(',').collect();
        let (send, delay, sched, release, recv): (u64, u64, u64, u64, u64) =
            (c[3].parse().unwrap(), c[9].parse().unwrap(), c[10].parse().unwrap(), c[11].parse().unwrap(), c[12].parse().unwrap());
        assert!(release >= sched && recv >= release && recv - send >= delay, "{row}");
        checked += 1;
    }
    assert_eq!(checked, 2000);
    // The report compares the delays seen, drawn and modelled, quantile by quantile.
    let dc = &r["delay_check"];
    assert_eq!(u(&dc["frames"]), 2000);
    for q in dc["quantiles"].as_array().unwrap() {
        assert!(q["seen_ms"].as_f64().unwrap() >= q["injected_ms"].as_f64().unwrap(), "{q}");
        assert!(q["model_ms"].is_f64(), "{q}");
    }
}

#[test]
fn clm_outages_are_conserved() {
    let (r, ok, _) = run("clm", &["CLM-2", "--duration-s", "4", "--seed", "5"]);
    assert!(ok, "{r:#}");
    assert_conserved(&r);
    let lost = u(&r["frames"]["dropped"]["outage"]);
    // Windows of U(0, 1 s) after 1 s cooldowns: in 4 s at least one opens.
    assert!(lost > 0 && lost < 4000, "{lost}");
    let [lo, hi] = [r["loss_rate_ci95"][0].as_f64().unwrap(), r["loss_rate_ci95"][1].as_f64().unwrap()];
    let realized = r["loss_rate"].as_f64().unwrap();
    assert!(lo <= realized && realized <= hi);
}

#[test]
fn the_real_capture_replays_with_its_timing() {
    let Some(cap) = crate::common::data::shipped_capture() else { return };
    let (r, ok, _) = run("replay", &["PLM-1", "--capture", cap.to_str().unwrap(), "--duration-s", "3", "--seed", "6"]);
    assert!(ok, "{r:#}");
    assert_conserved(&r);
    let sent = u(&r["frames"]["sent"]);
    // About 517 Hz for 3 s of the recording.
    assert!((1300..=1800).contains(&sent), "{sent}");
    assert_eq!(r["console"]["source"].as_str().map(|s| s.starts_with("capture:")), Some(true));
    // The recording has no LZ4 content checksum: the report says what of
    // it no checksum covers.
    let note = &r["console"]["capture"];
    assert_eq!((note["records"].as_u64(), note["content_checksum"].as_bool()), (Some(41_508), Some(false)), "{note:#}");
    assert_eq!(note["unverified"][0], "time_ns");
    // Every frame of the recording has a valid checksum.
    assert_eq!(u(&r["simulator"]["bad_checksum"]), 0);
}

/// Waits for `<out>/<role>.pid` and returns the pid.
fn wait_pid(out: &Path, role: &str) -> i32 {
    let t0 = Instant::now();
    loop {
        if let Ok(s) = std::fs::read_to_string(out.join(format!("{role}.pid"))) {
            if let Ok(p) = s.trim().parse() {
                return p;
            }
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "{role} never started");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Starts one service alone (`netfi <role> --run-id … --out …`).
fn service(role: &str, run_id: &str, out: &Path, extra: &[&str]) -> std::process::Child {
    netfi()
        .arg(role)
        .args(["--run-id", run_id, "--out"])
        .arg(out)
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

#[test]
fn a_restarted_console_reconnects() {
    let _guard = machine::alone();
    let out = out_dir("restart");
    let run_id = format!("it-restart-{}", std::process::id());
    let mut sim = service("simulator", &run_id, &out, &[]);
    wait_file(&out.join("simulator.ready"));
    let pin = emulator_pin();
    let pin: Vec<&str> = pin.iter().map(String::as_str).collect();
    let emu = service("emulator", &run_id, &out, &[&["--scenario", "Normal"], pin.as_slice()].concat());
    wait_file(&out.join("emulator.ready"));
    // The first console streams for a while and is killed mid-stream.
    let mut first = service("console", &run_id, &out, &["--duration-s", "10", "--no-direct"]);
    std::thread::sleep(Duration::from_millis(1500));
    first.kill().unwrap();
    first.wait().unwrap();
    // A second console with the same run id takes over the port and ends the stream.
    let second = service("console", &run_id, &out, &["--frames", "1000", "--no-direct"]);
    let o = second.wait_with_output().unwrap();
    assert!(o.status.success(), "second console: {}", String::from_utf8_lossy(&o.stderr));
    let e = emu.wait_with_output().unwrap();
    assert!(e.status.success(), "emulator: {}", String::from_utf8_lossy(&e.stderr));
    let s = sim.wait().unwrap();
    // The simulator ends on the emulator's end marker once the direct port is idle.
    assert!(s.success());
    let emu: Value = serde_json::from_slice(&std::fs::read(out.join("emulator.json")).unwrap()).unwrap();
    let simr: Value = serde_json::from_slice(&std::fs::read(out.join("simulator.json")).unwrap()).unwrap();
    let entered = u(&emu["frames"]["entered"]);
    // ~1500 frames from the first console, then exactly 1000 from the second.
    assert!(entered > 1000 + 500, "entered {entered}");
    assert_eq!(emu["frames"]["sent_by_console"], 1000);
    assert_eq!(emu["ended_by"], "end_marker");
    assert_eq!(u(&emu["frames"]["delivered"]), entered);
    assert_eq!(u(&simr["received"]), entered);
}

fn core_affinity_count() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// The CPUs a process may run on, from `/proc/<pid>/status`.
fn allowed_cpus(pid: u32) -> String {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    status.lines().find_map(|l| l.strip_prefix("Cpus_allowed_list:")).unwrap().trim().to_string()
}

/// `--isolate` moves other processes off the emulator's core for the run
/// and puts them back: at the end of a normal run, and, through the
/// runner, when the emulator was killed. A child of this test (our own
/// process: no privilege needed) is the witness.
#[test]
fn isolate_clears_the_emulators_core_and_puts_everything_back() {
    let cores = core_affinity_count();
    if cores < 2 {
        eprintln!("skipped: one core only");
        return;
    }
    let core = (cores - 1).to_string();
    let witness = Witness(Command::new("sleep").arg("60").spawn().unwrap());
    let before = allowed_cpus(witness.id());
    if !netfi::host::isolate::parse_list(&before).unwrap().contains(&(cores - 1)) {
        eprintln!("skipped: this test may not run on core {core}");
        return;
    }

    // A whole run: cleared while it runs, restored at its end.
    let (r, ok, _) = run("isolate", &["Normal", "--duration-s", "1", "--seed", "3", "--isolate", "--emulator-core", &core]);
    assert!(ok, "{r:#}");
    assert_conserved(&r);
    let iso = &r["emulator"]["isolation"];
    assert_eq!(u(&iso["core"]), (cores - 1) as u64, "{iso}");
    assert!(u(&iso["threads_moved"]) >= 1, "the witness at least must have moved: {iso}");
    assert!(u(&iso["restored"]) >= 1, "{iso}");
    assert_eq!(allowed_cpus(witness.id()), before, "the witness was not put back");

    // The emulator killed while the core is cleared: the runner restores.
    let _guard = machine::alone();
    let out = out_dir("isolate-kill");
    let child = spawn_run(&out, &["Normal", "--duration-s", "3", "--seed", "3", "--isolate", "--emulator-core", &core]);
    let pid = wait_pid(&out, "emulator");
    let t0 = Instant::now();
    while allowed_cpus(witness.id()) == before {
        assert!(t0.elapsed() < Duration::from_secs(30), "the emulator never cleared core {core}");
        std::thread::sleep(Duration::from_millis(10));
    }
    let record = |pid: i32| {
        let dir = netfi::host::record::state_dir().unwrap();
        netfi::host::record::list(&dir).into_iter().find(|p| p.to_string_lossy().contains(&format!("isolation-{pid}-")))
    };
    assert!(record(pid).is_some(), "what was moved is not on record");
    std::thread::sleep(Duration::from_millis(300));
    // SAFETY: signalling a process this test started (through the runner).
    unsafe { libc::kill(pid, libc::SIGKILL) };
    let o = child.wait_with_output().unwrap();
    assert!(!o.status.success(), "a run with a killed emulator must fail");
    assert_eq!(allowed_cpus(witness.id()), before, "the runner did not put the witness back");
    assert!(record(pid).is_none(), "the record of what was moved was left behind");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("a killed process left moved"), "{stderr}");
}

/// A child process, killed and reaped however the test ends.
struct Witness(std::process::Child);

impl Witness {
    fn id(&self) -> u32 {
        self.0.id()
    }
}

impl Drop for Witness {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Each thread of process `pid`: its name and the CPUs it may run on.
fn threads_of(pid: i32) -> Vec<(i32, String, String)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(format!("/proc/{pid}/task")).unwrap().flatten() {
        let Ok(tid) = e.file_name().to_string_lossy().parse::<i32>() else { continue };
        let comm = std::fs::read_to_string(e.path().join("comm")).unwrap_or_default().trim().to_string();
        let status = std::fs::read_to_string(e.path().join("status")).unwrap_or_default();
        let cpus = status.lines().find_map(|l| l.strip_prefix("Cpus_allowed_list:")).unwrap_or("").trim().to_string();
        out.push((tid, comm, cpus));
    }
    out
}

/// The emulator pinned to a core keeps its own other threads (the trace
/// writer, the control server) off it: each time one of them ran there it
/// would take the core from the loop for as long as it ran (milliseconds at
/// high rates). Checked on a running `netfi emulator --core N` started as a
/// user would start it by hand, its CPU mask the whole machine, the core
/// not cleared (clearing it, as `netfi run` does by default, moves them too
/// and would hide the emulator's own placement).
#[test]
fn the_emulators_own_threads_stay_off_its_core() {
    let cores = core_affinity_count();
    if cores < 2 {
        eprintln!("skipped: one core only");
        return;
    }
    let core = cores - 1;
    let _guard = machine::alone();
    let out = out_dir("own-threads");
    let run_id = format!("it-own-threads-{}", std::process::id());
    let mut emu = service("emulator", &run_id, &out, &["--scenario", "Normal", "--core", &core.to_string()]);
    wait_file(&out.join("emulator.ready"));
    let threads = threads_of(emu.id() as i32);
    // SAFETY: signalling the emulator this test started.
    unsafe { libc::kill(emu.id() as i32, libc::SIGTERM) };
    let status = emu.wait().unwrap();
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut emu.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(status.success(), "{stderr}");
    let on = |cpus: &str| netfi::host::isolate::parse_list(cpus).unwrap();
    let pid = emu.id() as i32;
    let main = threads.iter().find(|t| t.0 == pid).expect("the loop's thread");
    assert_eq!(on(&main.2).into_iter().collect::<Vec<_>>(), vec![core], "the loop is pinned: {threads:?}");
    let others: Vec<_> = threads.iter().filter(|t| t.0 != pid).collect();
    assert!(others.iter().any(|t| t.1 == "netfi-trace"), "a trace writer runs beside the loop: {threads:?}");
    for (_, comm, cpus) in others {
        assert!(!on(cpus).contains(&core), "{comm} may run on the loop's core {core} ({cpus})");
    }
    assert!(!stderr.contains("could not be kept off core"), "{stderr}");
}

/// The feedback loop robot → emulator → console through its own scenario
/// (`--return-scenario`): one feedback per command the robot received,
/// every one accounted for, the return scenario's fates those it gives its
/// seed in simulated time, and a round trip per feedback the console got.
#[test]
fn the_feedback_loop_is_shaped_accounted_for_and_timed() {
    let (r, ok, out) = run("feedback", &["PLM-1", "--return-scenario", "PLM-2", "--frames", "4000", "--rate-hz", "2000", "--seed", "7"]);
    assert!(ok, "{r:#}");
    assert_conserved(&r);
    let fb = &r["feedback"];
    let received = u(&r["frames"]["received"]);
    assert_eq!(fb["return_scenario"], "PLM-2", "{fb}");
    assert_eq!(u(&fb["sent_by_robot"]), received, "{fb}");
    assert_eq!(u(&fb["entered"]), received, "{fb}");
    let dropped: u64 = fb["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&fb["entered"]), u(&fb["delivered"]) + dropped + u(&fb["held_at_end"]), "{fb}");
    assert_eq!(u(&fb["received_by_console"]), u(&fb["delivered"]), "{fb}");
    assert_eq!(fb["balanced"], true, "{fb}");
    // ge_lomax decides per sample: the same seed over the same count in
    // simulated time drops the very same feedback.
    let seed = u(&r["emulator"]["feedback"]["seed"]).to_string();
    let n = u(&fb["entered"]).to_string();
    let o = netfi().args(["scenario", "check", "PLM-2", "--frames", &n, "--seed", &seed, "--json"]).output().unwrap();
    let c: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(c["dropped"]["ge_lomax"], fb["dropped"]["ge_lomax"], "{fb}");
    assert!(u(&fb["dropped"]["ge_lomax"]) > 0);
    // One round trip per feedback the console received, each longer than
    // the emulator's own share of it.
    assert_eq!(u(&fb["round_trip_ns"]["count"]), u(&fb["delivered"]), "{fb}");
    assert!(u(&fb["round_trip_ns"]["p50"]) >= u(&fb["emulator_share_ns"]["p50"]), "{fb}");
    assert!(out.join("trace_feedback.csv").exists());
    assert!(out.join("round_trip.hlog").exists());
}
