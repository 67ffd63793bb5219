//! Live control and telemetry of real runs: `netfi run` in the background,
//! `netfi ctl` against it, then the run's report and trace.
//!
//! The runs are serialized: each has a busy-waiting emulator pinned to a
//! core, and a 2-core machine has room for one at a time.

use crate::common::netfi::netfi;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use crate::common::machine;

fn run_id(name: &str) -> String {
    format!("ctl-{}-{name}", std::process::id())
}

/// A `netfi run` in the background, its report read when it ends.
struct Run {
    child: Child,
    out: PathBuf,
    id: String,
}

impl Run {
    fn start(name: &str, args: &[&str]) -> Run {
        let id = run_id(name);
        let out = std::env::temp_dir().join(format!("netfi-ctl-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let child = netfi()
            .arg("run")
            .args(args)
            .args(["--run-id", &id, "--no-isolate", "--json", "--out"])
            .arg(&out)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let r = Run { child, out, id };
        r.wait_started();
        r
    }

    /// Until the emulator answers and a frame has entered.
    fn wait_started(&self) {
        let t0 = Instant::now();
        loop {
            let (ok, stdout, _) = ctl(&self.id, &["--json", "show"]);
            if ok && serde_json::from_str::<Value>(&stdout).is_ok_and(|v| v["state"]["started"] == true) {
                return;
            }
            assert!(t0.elapsed() < Duration::from_secs(30), "the run never answered");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn report(self) -> (Value, PathBuf) {
        let o = self.child.wait_with_output().unwrap();
        let report: Value = serde_json::from_slice(&o.stdout)
            .unwrap_or_else(|e| panic!("no JSON report ({e}); stderr:\n{}", String::from_utf8_lossy(&o.stderr)));
        assert!(o.status.success(), "{report:#}");
        (report, self.out)
    }
}

/// `netfi ctl --run-id RUN ARGS`: success, stdout, stderr.
fn ctl(run: &str, args: &[&str]) -> (bool, String, String) {
    let o = netfi().args(["ctl", "--run-id", run]).args(args).output().unwrap();
    (o.status.success(), String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
}

fn show(run: &str) -> Value {
    let (ok, stdout, stderr) = ctl(run, &["--json", "show"]);
    assert!(ok, "{stderr}");
    serde_json::from_str::<Value>(&stdout).unwrap()["state"].clone()
}

/// Until at least `n` frames have entered the run's emulator (as its
/// control service last counted them).
fn wait_entered(run: &str, n: u64) {
    let t0 = Instant::now();
    while show(run)["frames_entered"].as_u64().unwrap() < n {
        assert!(t0.elapsed() < Duration::from_secs(30), "fewer than {n} frames entered in 30 s");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The trace's rows: (ingress_ns, dropped, delay_ns).
fn trace(out: &Path) -> Vec<(u64, bool, Option<u64>)> {
    let text = std::fs::read_to_string(out.join("trace.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (ingress, fate, delay) = (col("ingress_ns"), col("fate"), col("delay_ns"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[ingress].parse().unwrap(), f[fate] == "dropped", f[delay].parse().ok())
        })
        .collect()
}

#[test]
fn a_live_switch_from_plm2_to_dlm1_takes_effect_and_is_reported() {
    let _guard = machine::alone();
    // A plain run: any run under control may be switched to any scenario.
    let run = Run::start("switch", &["PLM-2", "--duration-s", "6", "--seed", "3"]);
    let id = run.id.clone();
    let s = show(&id);
    assert_eq!((s["scenario"].as_str(), s["phase"].as_u64(), s["paused"].as_bool()), (Some("PLM-2"), Some(1), Some(false)), "{s}");

    // Bad switches: the parser's own errors, and nothing changes.
    let (ok, _, err) = ctl(&id, &["switch", "loss=130%"]);
    assert!(!ok && err.contains("loss") && err.contains("130"), "{err}");
    let (ok, _, err) = ctl(&id, &["switch", "PLM-9"]);
    assert!(!ok && err.contains("neither a scenario file, a preset"), "{err}");
    let (ok, _, err) = ctl(&id, &["phase", "2"]);
    assert!(!ok && err.contains("no phase `2`: give a number from 1 to 1"), "{err}");
    let s = show(&id);
    assert_eq!((s["scenario"].as_str(), s["phase"].as_u64()), (Some("PLM-2"), Some(1)), "{s}");

    // Enough of PLM-2 for the frame-by-frame check below, however fast
    // the calls above were.
    wait_entered(&id, 500);
    let (ok, stdout, err) = ctl(&id, &["switch", "DLM-1"]);
    assert!(ok, "{err}");
    assert!(stdout.contains("switch to DLM-1: took effect at t = "), "{stdout}");
    let s = show(&id);
    assert_eq!((s["scenario"].as_str(), s["phase"].as_u64()), (Some("DLM-1"), Some(2)), "{s}");

    // The telemetry: at least one interval, of the new phase.
    let (ok, stdout, err) = ctl(&id, &["--json", "watch", "--count", "2"]);
    assert!(ok, "{err}");
    let intervals: Vec<Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(intervals.len(), 2, "{stdout}");
    assert!(intervals.iter().all(|i| i["phase"] == 2 && i["length_ns"] == 100_000_000), "{stdout}");

    let (r, out) = run.report();
    let events = r["events"].as_array().unwrap();
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(events[0]["what"], "switch to DLM-1");
    let t_switch_s = events[0]["t_s"].as_f64().unwrap();
    assert!(t_switch_s > 0.0 && t_switch_s < 6.0, "{t_switch_s}");
    // Each condition apart: PLM-2's stretch its loss, DLM-1's delays held
    // against DLM-1's own law (not PLM-2's, which has none), within its
    // DKW band (95%).
    let phases = r["phases"].as_array().unwrap_or_else(|| panic!("no phases in {r:#}"));
    assert_eq!(phases.len(), 2, "{phases:?}");
    assert_eq!((phases[0]["scenario"].as_str(), phases[1]["scenario"].as_str()), (Some("PLM-2"), Some("DLM-1")));
    assert_eq!(phases[1]["dropped"], 0, "{}", phases[1]);
    assert_eq!(phases[1]["delay_check"]["injected_within_model_band"], true, "{}", phases[1]["delay_check"]);
    assert!(r["delay_check"].is_null() || r["delay_check"]["injected_within_model_band"].is_null(), "the whole run held against one law");
    // The same event streamed beside the trace.
    let log = std::fs::read_to_string(out.join("events.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 1, "{log}");

    // Before the switch PLM-2's bursts, after it DLM-1: nothing dropped,
    // every delay at least its 70 ms minimum, their mean its 100 ms
    // (standard deviation about 27 ms: over 1000+ frames the mean is within
    // 0.85 ms at 1σ; 5 ms is about 6σ).
    let rows = trace(&out);
    let t0 = rows.iter().map(|r| r.0).min().unwrap();
    let switch_ns = t0 + (t_switch_s * 1e9) as u64;
    let (before, after): (Vec<&(u64, bool, Option<u64>)>, Vec<_>) = rows.iter().partition(|r| r.0 < switch_ns);
    // ge_lomax decides per frame: before the switch, the fates are exactly
    // PLM-2's with the run's seed, frame by frame.
    assert!(before.len() > 100, "{} frames before the switch", before.len());
    let mut plm2 = netfi::scenario::Scenario::new(&netfi::scenario::preset("PLM-2").unwrap(), 3).unwrap();
    for (i, r) in before.iter().enumerate() {
        let dropped = matches!(plm2.decide(r.0 - t0, r.0), netfi::scenario::Decision::Drop { .. });
        assert_eq!(r.1, dropped, "frame {i} before the switch");
    }
    assert!(before.iter().any(|r| r.1), "PLM-2 dropped nothing before the switch");
    assert!(after.len() > 1000, "{}", after.len());
    assert!(after.iter().all(|r| !r.1 && r.2.is_some_and(|d| d >= 70_000_000)), "a frame after the switch was dropped or not delayed");
    let mean_ms = after.iter().map(|r| r.2.unwrap() as f64 / 1e6).sum::<f64>() / after.len() as f64;
    assert!((mean_ms - 100.0).abs() < 5.0, "mean delay after the switch {mean_ms} ms");
    std::fs::remove_dir_all(out).ok();
}

#[test]
fn pause_passes_every_frame_and_any_run_may_switch_to_a_reordering_scenario() {
    let _guard = machine::alone();
    let run = Run::start("pause", &["PLM-3", "--duration-s", "4", "--seed", "5"]);
    let id = run.id.clone();
    // PLM-3 cannot reorder, yet the run under control keeps release-time
    // order: a switch to a reordering scenario would be taken.
    assert_eq!(show(&id)["queue_order"], "reorder");
    let (ok, _, err) = ctl(&id, &["pause"]);
    assert!(ok, "{err}");
    assert_eq!(show(&id)["paused"], true);
    std::thread::sleep(Duration::from_millis(1000));
    let (ok, _, err) = ctl(&id, &["resume"]);
    assert!(ok, "{err}");
    let (r, out) = run.report();
    let events = r["events"].as_array().unwrap();
    assert_eq!(events.len(), 2, "{events:?}");
    assert!(events[0]["what"].as_str().unwrap().starts_with("pause"));
    assert_eq!(events[1]["what"], "resume");
    let (p, q) = (events[0]["t_s"].as_f64().unwrap(), events[1]["t_s"].as_f64().unwrap());
    assert!(q - p > 0.5, "{p} {q}");
    // While paused, every frame passed at once; PLM-3 dropped around half
    // of the others.
    let rows = trace(&out);
    let t0 = rows.iter().map(|r| r.0).min().unwrap();
    let at = |s: f64| t0 + (s * 1e9) as u64;
    let paused: Vec<_> = rows.iter().filter(|r| r.0 >= at(p) && r.0 < at(q)).collect();
    assert!(paused.len() > 400 && paused.iter().all(|r| !r.1 && r.2 == Some(0)), "{} paused frames", paused.len());
    let other = rows.iter().filter(|r| r.0 < at(p) || r.0 >= at(q)).filter(|r| r.1).count();
    assert!(other > 300, "{other} dropped outside the pause");
    std::fs::remove_dir_all(out).ok();
}

#[test]
fn ctl_to_a_run_that_does_not_exist_fails_clearly_and_leaves_nothing() {
    let id = run_id("nosuch");
    for args in [&["show"][..], &["switch", "DLM-1"], &["watch", "--count", "1"]] {
        let (ok, _, err) = ctl(&id, args);
        assert!(!ok, "{args:?}");
        assert!(err.contains(&format!("no run `{id}`")), "{err}");
    }
    let left: Vec<_> = std::fs::read_dir("/dev/shm").unwrap().filter_map(|e| e.ok()).filter(|e| e.file_name().to_string_lossy().contains(&id)).collect();
    assert!(left.is_empty(), "{left:?}");
    let (ok, _, err) = ctl("bad/id", &["show"]);
    assert!(!ok && err.contains("run id `bad/id`"), "{err}");
}

/// A client of the control service written against iceoryx2 itself, as any
/// binding could be: it sends what it likes, with no size check of its own.
fn raw_request(run: &str, request: &[u8]) -> Value {
    use iceoryx2::prelude::*;
    use netfi::transport::ipc::control::{CONTROL_SERVICE, MAX_CONTROL_CLIENTS};
    let config = netfi::transport::IpcConfig::new(netfi::transport::RunId::new(run).unwrap());
    let name = NodeName::new(&config.node_name(netfi::transport::Role::Tool)).unwrap();
    let node = NodeBuilder::new().name(&name).config(config.iceoryx2()).create::<ipc::Service>().unwrap();
    // The service's own limits: opening asks for no more than it has.
    let service = node
        .service_builder(&ServiceName::new(&format!("netfi/{run}/{CONTROL_SERVICE}")).unwrap())
        .request_response::<[u8], [u8]>()
        .max_servers(1)
        .max_clients(MAX_CONTROL_CLIENTS)
        .max_nodes(netfi::transport::MAX_NODES_PER_CHANNEL)
        .max_active_requests_per_client(1)
        .max_response_buffer_size(1)
        .max_borrowed_responses_per_pending_response(1)
        .max_loaned_requests(1)
        .enable_fire_and_forget_requests(false)
        .open()
        .unwrap_or_else(|e| panic!("opening the control service: {e:?}"));
    let client = service.client_builder().initial_max_slice_len(request.len()).create().unwrap();
    let pending = client.loan_slice_uninit(request.len()).unwrap().write_from_slice(request).send().unwrap();
    let t0 = Instant::now();
    loop {
        if let Some(resp) = pending.receive().unwrap() {
            return serde_json::from_slice(resp.payload()).unwrap();
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "no answer to a {} byte request", request.len());
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// A valid `show` request padded with JSON whitespace to `len` bytes.
fn padded_show(len: usize) -> Vec<u8> {
    let mut r = br#"{"cmd":"show"}"#.to_vec();
    r.resize(len, b' ');
    r
}

#[test]
fn a_request_over_the_1_mib_limit_is_refused_and_one_at_it_answered() {
    use netfi::transport::ipc::control::MAX_MESSAGE_BYTES;
    let _guard = machine::alone();
    let run = Run::start("toolarge", &["Normal", "--duration-s", "4", "--seed", "1"]);
    let id = run.id.clone();
    let at_limit = raw_request(&id, &padded_show(MAX_MESSAGE_BYTES));
    assert_eq!(at_limit["ok"], true, "{at_limit}");
    for len in [MAX_MESSAGE_BYTES + 1, 10 << 20] {
        let r = raw_request(&id, &padded_show(len));
        assert_eq!(r["ok"], false, "a {len} byte request was answered {r}");
        let message = r["message"].as_str().unwrap();
        assert!(message.contains(&format!("the request is {len} bytes; at most {MAX_MESSAGE_BYTES} are accepted")), "{message}");
    }
    // The run went on, its control too.
    assert_eq!(show(&id)["scenario"], "Normal");
    let (r, out) = run.report();
    assert!(r["events"].as_array().is_none_or(|e| e.is_empty()), "{}", r["events"]);
    std::fs::remove_dir_all(out).ok();
}
