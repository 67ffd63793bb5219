//! Several streams on one emulator (`netfi run --streams N`): each stream's
//! own scenario, seed, accounting and files, and their total.

use crate::common::netfi::emulator_pin;
use super::{assert_conserved, netfi, out_dir, run, service, u, wait_file};
use crate::common::machine;
use serde_json::Value;
use std::path::PathBuf;
use std::process::Child;
use std::time::Duration;

/// What `netfi scenario check` drops of `frames` frames of `scenario` with
/// `seed`, in simulated time.
fn dropped_in_simulated_time(scenario: &str, frames: u64, seed: u64) -> Value {
    let o = netfi().args(["scenario", "check", scenario, "--frames", &frames.to_string(), "--seed", &seed.to_string(), "--json"]).output().unwrap();
    let c: Value = serde_json::from_slice(&o.stdout).unwrap();
    c["dropped"].clone()
}

#[test]
fn three_streams_each_realize_their_own_scenario_and_balance() {
    const FRAMES: u64 = 6000;
    let (r, ok, out) = run(
        "streams3",
        &["Normal", "--streams", "3", "--stream-scenario", "1=PLM-1", "--stream-scenario", "2=PLM-3", "--frames", "6000", "--rate-hz", "2000", "--seed", "3"],
    );
    assert!(ok, "{r:#}");
    let st = &r["streams"]["streams"];
    let streams = st.as_array().expect("a report of each stream");
    assert_eq!(streams.len(), 3);
    // Stream 0 keeps the run's seed (one stream is today's run); the others
    // get seeds of their own.
    assert_eq!(u(&st[0]["seed"]), 3);
    assert!(u(&st[1]["seed"]) != 3 && u(&st[2]["seed"]) != 3 && st[1]["seed"] != st[2]["seed"]);
    let mut total_entered = 0;
    let mut total_dropped = 0;
    for (k, scenario) in ["Normal", "PLM-1", "PLM-3"].into_iter().enumerate() {
        // Each stream's own report, in its own directory.
        let own: Value = serde_json::from_slice(&std::fs::read(out.join(format!("stream-{k}/report.json"))).unwrap()).unwrap();
        assert_eq!(own["scenario"], scenario);
        assert_conserved(&own);
        assert_eq!(u(&own["frames"]["sent"]), FRAMES, "stream {k}");
        assert_eq!(st[k]["frames"], own["frames"], "stream {k}");
        // ge_lomax decides per frame, not per time: each stream drops exactly
        // what its scenario drops with its seed in simulated time, so the
        // streams' random draws are their own.
        let dropped = &own["frames"]["dropped"];
        if scenario != "Normal" {
            assert_eq!(dropped["ge_lomax"], dropped_in_simulated_time(scenario, FRAMES, u(&st[k]["seed"]))["ge_lomax"], "stream {k}");
            // And its realized loss is its model's: within twice the half
            // width of the report's 95% interval (about 3.9 standard
            // errors, α ≈ 1e-4 per stream), which accounts for the bursts.
            let exact = own["stages"][0]["loss_rate_model"].as_f64().unwrap();
            let realized = own["loss_rate"].as_f64().unwrap();
            let [lo, hi] = [own["loss_rate_ci95"][0].as_f64().unwrap(), own["loss_rate_ci95"][1].as_f64().unwrap()];
            assert!((realized - exact).abs() <= hi - lo, "stream {k}: realized {realized}, model {exact}, 95% CI [{lo}, {hi}]");
            let others = [0.1, 0.3, 0.5].into_iter().filter(|m| (m - exact).abs() > 0.05);
            for m in others {
                assert!((realized - m).abs() > hi - lo, "stream {k}: {realized} would also pass for a loss of {m}");
            }
        } else {
            assert!(dropped.as_object().unwrap().is_empty(), "{dropped}");
        }
        total_entered += u(&own["frames"]["entered"]);
        total_dropped += dropped.as_object().unwrap().values().map(u).sum::<u64>();
        // Its console said it streams, as the runner asks of every console.
        assert!(out.join(format!("stream-{k}/console.ready")).exists(), "stream {k}");
        let trace = std::fs::read_to_string(out.join(format!("stream-{k}/trace.csv"))).unwrap();
        assert_eq!(trace.lines().skip(1).count() as u64, FRAMES, "stream {k}");
    }
    // The total: sums of the streams, balanced.
    let t = &r["streams"]["total"];
    assert_eq!(u(&t["entered"]), total_entered);
    assert_eq!(u(&t["sent"]), 3 * FRAMES);
    assert_eq!(u(&t["entered"]), u(&t["delivered"]) + total_dropped + u(&t["held_at_end"]));
    assert_eq!(u(&t["delivered"]), u(&t["received"]));
    assert_eq!(t["balanced"], true);
    // The emulator's joint report says the same.
    let e: Value = serde_json::from_slice(&std::fs::read(out.join("emulator.json")).unwrap()).unwrap();
    assert_eq!(u(&e["total"]["entered"]), total_entered);
    assert_eq!(e["balanced"], true);
    assert_eq!(e["streams"].as_array().unwrap().len(), 3);
    // And the loop's time on frames, all streams together: each stream's
    // own figures summed (one loop served them, each turn counted once).
    let own_busy: Vec<Value> = (0..3)
        .map(|k| serde_json::from_slice::<Value>(&std::fs::read(out.join(format!("stream-{k}/emulator.json"))).unwrap()).unwrap()["busy"].clone())
        .collect();
    for key in ["turns", "busy_turns", "busy_ns", "frames", "long_turns", "long_ns"] {
        assert_eq!(u(&e["busy"][key]), own_busy.iter().map(|b| u(&b[key])).sum::<u64>(), "busy.{key}: {}", e["busy"]);
    }
    assert!(u(&e["busy"]["frames"]) >= 3 * FRAMES, "{}", e["busy"]);
    let per_frame = e["busy"]["busy_ns_per_frame"].as_f64().unwrap();
    assert!((per_frame - u(&e["busy"]["busy_ns"]) as f64 / u(&e["busy"]["frames"]) as f64).abs() < 1e-6, "{}", e["busy"]);
}

/// A stand-alone emulator of two streams notices a dead robot as the
/// emulator of one does: it reaps each stream's run, ends that stream's
/// feedback early so its console ends its stream, and names the dead peer
/// in that stream's report; the other stream runs to its end.
#[test]
fn a_standalone_emulator_of_two_streams_notices_a_dead_robot() {
    let _guard = machine::alone();
    let out = out_dir("streams-dead-robot");
    let run_id = format!("it-sdr-{}", std::process::id());
    let ids = [run_id.clone(), netfi::service::plan::stream_run_id(&run_id, 1)];
    let dirs = [out.join("stream-0"), out.join("stream-1")];
    let nap = ["--nap-us", "200"];
    let mut robots: Vec<Child> = (0..2).map(|k| service("simulator", &ids[k], &dirs[k], &nap)).collect();
    dirs.iter().for_each(|d| wait_file(&d.join("simulator.ready")));
    let pin = emulator_pin();
    let pin: Vec<&str> = pin.iter().map(String::as_str).collect();
    let emu = service("emulator", &run_id, &out, &[&["--scenario", "Normal", "--streams", "2"], pin.as_slice()].concat());
    wait_file(&out.join("emulator.ready"));
    let consoles: Vec<Child> = (0..2).map(|k| service("console", &ids[k], &dirs[k], &[&["--frames", "4000"], &nap[..]].concat())).collect();
    wait_file(&dirs[1].join("console.ready"));
    std::thread::sleep(Duration::from_millis(700));
    robots[1].kill().unwrap();
    robots[1].wait().unwrap();
    for (k, c) in consoles.into_iter().enumerate() {
        let o = c.wait_with_output().unwrap();
        assert!(o.status.success(), "console {k}: {}", String::from_utf8_lossy(&o.stderr));
    }
    let e = emu.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&e.stderr);
    assert!(e.status.success(), "emulator: {stderr}");
    assert!(robots[0].wait().unwrap().success());
    let json = |path: PathBuf| -> Value { serde_json::from_slice(&std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))).unwrap() };
    // Stream 1: its console was told and ended its stream early; every
    // frame that entered is accounted for; the dead robot is named.
    let c1 = json(dirs[1].join("console.json"));
    assert_eq!(c1["ended_by"], "emulator_ended", "{c1}");
    assert!(u(&c1["frames_sent"]) < 4000, "{c1}");
    let e1 = json(dirs[1].join("emulator.json"));
    assert_eq!(e1["ended_by"], "peer_died", "{stderr}");
    let dead = e1["dead_peers"].as_array().unwrap();
    assert!(dead.iter().any(|d| d.as_str().is_some_and(|d| d.starts_with("simulator"))), "{dead:?}");
    let f = &e1["frames"];
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + dropped + u(&f["held_at_end"]), "{f}");
    assert_eq!(u(&f["entered"]), u(&c1["frames_sent"]), "{f}");
    // Stream 0 ran to its end, untouched.
    let c0 = json(dirs[0].join("console.json"));
    assert_eq!(c0["ended_by"], "done", "{c0}");
    let e0 = json(dirs[0].join("emulator.json"));
    assert_eq!(e0["ended_by"], "end_marker");
    assert_eq!(e0["dead_peers"].as_array().map(Vec::len), Some(0));
    assert_eq!(u(&e0["frames"]["delivered"]), 4000);
    // The joint report says how the loop ended.
    assert_eq!(json(out.join("emulator.json"))["ended_by"], "peer_died");
    let left = super::faults::iceoryx2_files_of(&run_id, 2);
    assert!(left.is_empty(), "left {left:?}");
}
