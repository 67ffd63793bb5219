//! Several streams on one emulator (`netfi run --streams N`): each stream's
//! own scenario, seed, accounting and files, and their total.

use super::{assert_conserved, netfi, run, u};
use serde_json::Value;

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
}
