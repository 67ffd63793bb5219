//! The `netfi scenario` command as a user runs it.

use crate::common::machine;
use crate::common::scratch::Scratch;
use crate::common::netfi::{netfi, Outcome};

#[test]
fn check_json_has_the_documented_fields() {
    let _machine = machine::not_beside_a_run();
    let out = netfi().args(["scenario", "check", "PLM-2", "--frames", "200000", "--seed", "5", "--json"]).ok();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in ["frames", "delivered", "dropped", "loss_rate", "loss_rate_ci95", "loss_run_mean", "delay_ms", "reordered_fraction", "outages", "seed"] {
        assert!(v.get(key).is_some(), "missing `{key}` in {v}");
    }
    for key in ["mean", "p50", "p99", "max"] {
        assert!(v["delay_ms"].get(key).is_some(), "missing delay_ms.{key}");
    }
    assert_eq!(v["frames"], 200_000);
    assert_eq!(v["seed"], 5);
    let dropped = v["dropped"]["ge_lomax"].as_u64().unwrap();
    assert_eq!(v["delivered"].as_u64().unwrap() + dropped, 200_000);
    let ci = v["loss_rate_ci95"].as_array().unwrap();
    let rate = v["loss_rate"].as_f64().unwrap();
    assert!(ci[0].as_f64().unwrap() < rate && rate < ci[1].as_f64().unwrap());
    // The same seed gives the same report.
    let again = netfi().args(["scenario", "check", "PLM-2", "--frames", "200000", "--seed", "5", "--json"]).ok();
    assert_eq!(out.stdout, again.stdout);
}

#[test]
fn a_run_without_seed_prints_the_seed_it_chose() {
    let _machine = machine::not_beside_a_run();
    let out = netfi().args(["scenario", "check", "CLM-2", "--frames", "20000"]).output().unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let seed: u64 = stderr.split("seed ").nth(1).and_then(|s| s.split_whitespace().next()).and_then(|s| s.parse().ok()).unwrap_or_else(|| panic!("no seed in {stderr}"));
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains(&format!("seed              {seed}")), "{table}");
}

/// `netfi scenario check` of a file `name` holding `text`, refused: its
/// standard error.
fn refused_scenario(name: &str, text: &str) -> String {
    let dir = Scratch::new(&format!("cli-refused-{name}"));
    netfi().args(["scenario", "check"]).arg(dir.file(name, text)).fails()
}

#[test]
fn a_bad_scenario_file_is_a_clear_error() {
    let _machine = machine::not_beside_a_run();
    let err = refused_scenario("bad.toml", "[[stage]]\nmodel = \"ge_lomax\"\ntransition = [[0.9, 0.05], [0.1, 0.9]]\nalpha = [1.0, 1.0]\nlambda = [1.0, 1.0]\n");
    assert!(err.contains("bad.toml:3: stage 1 (ge_lomax): `transition[0]`"), "{err}");
}

#[test]
fn values_beyond_their_physical_range_are_refused_with_the_range() {
    let _machine = machine::not_beside_a_run();
    let out = netfi().args(["scenario", "check", "PLM-2", "--frames", "1000", "--rate-hz", "1e-300"]).output().unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("--rate-hz, --frames: 1e-300 Hz is out of range: expected a command rate from 0.1 to 1000000 frames per second"), "{stderr}");
    let out = netfi().args(["scenario", "check", "PLM-2", "--frames", "100000000000000", "--rate-hz", "1"]).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("one year"), "{}", String::from_utf8_lossy(&out.stderr));

    let err = refused_scenario("far.toml", "[[stage]]\nmodel = \"delay\"\nmin_ms = 1e15\n");
    assert!(err.contains("far.toml:3: stage 1 (delay): `min_ms`: 1000000000000000 ms is out of range: expected 0 to 3600000 ms (one hour)"), "{err}");
}

#[test]
fn a_jitter_scenario_reports_its_exact_model_values() {
    let _machine = machine::not_beside_a_run();
    let v = netfi().args(["scenario", "check", "config/scenarios/netem_jitter.toml", "--frames", "50000", "--seed", "2", "--json"]).json();
    let stage = &v["stages"][1];
    assert_eq!(stage["model"], "jitter");
    // Far from 0 the clamp moves the mean by less than 1e-9 ms.
    assert!((stage["delay_ms_model"].as_f64().unwrap() - 100.0).abs() < 1e-6, "{stage}");
    let p99 = stage["delay_ms_p99_model"].as_f64().unwrap();
    assert!(p99 > 150.0 && p99 < 200.0, "{stage}");
    assert_eq!(stage["correlation_model"]["normal_scores_lag1"], 0.25);
    let rank = stage["correlation_model"]["rank_lag1"].as_f64().unwrap();
    assert!((rank - 6.0 / std::f64::consts::PI * (0.125f64).asin()).abs() < 1e-12);
    // Stages without these values do not carry the keys.
    assert!(v["stages"][0].get("delay_ms_p99_model").is_none());

    let show = netfi().args(["scenario", "show", "config/scenarios/netem_jitter.toml"]).output().unwrap();
    let text = String::from_utf8_lossy(&show.stdout);
    assert!(text.contains("model = \"jitter\"") && text.contains("dist = \"paretonormal\"") && text.contains("correlation = 0.25"), "{text}");
}

#[test]
fn a_bad_jitter_is_refused_with_file_line_and_field() {
    let _machine = machine::not_beside_a_run();
    let err = refused_scenario("jitter.toml", "[[stage]]\nmodel = \"jitter\"\nmean_ms = 10\nsd_ms = 5\ndist = \"normal\"\ncorrelation = 1\n");
    assert!(err.contains("jitter.toml:6: stage 1 (jitter): `correlation`: 1 is out of range: expected a correlation in [0, 1)"), "{err}");
}

#[test]
fn duplication_is_counted_apart() {
    let _machine = machine::not_beside_a_run();
    let v = netfi().args(["scenario", "check", "config/scenarios/netem_duplicate.toml", "--frames", "100000", "--seed", "3", "--json"]).json();
    let copies = v["duplicated"].as_u64().unwrap();
    let dropped: u64 = v["dropped"].as_object().unwrap().values().map(|n| n.as_u64().unwrap()).sum();
    assert_eq!(100_000 + copies, v["delivered"].as_u64().unwrap() + dropped);
    let stage = &v["stages"][0];
    assert_eq!((stage["model"].as_str(), stage["duplicated"].as_u64()), (Some("duplicate"), Some(copies)));
    assert_eq!(stage["duplicate_rate_model"], 0.01);
    // Copies: 1% of 10^5 frames, binomial sd 31.5; 4 sd either side.
    assert!((874..=1126).contains(&copies), "{copies}");

    let err = refused_scenario("dup.toml", "[[stage]]\nmodel = \"duplicate\"\n\np = 1.5\n");
    assert!(err.contains("dup.toml:4: stage 1 (duplicate): `p`: 1.5 is not a probability"), "{err}");
}

#[test]
fn corruption_reports_what_the_checksum_catches() {
    let _machine = machine::not_beside_a_run();
    let v = netfi().args(["scenario", "check", "config/scenarios/netem_corrupt.toml", "--frames", "100000", "--seed", "3", "--json"]).json();
    let c = &v["corruption"];
    let (n, caught, passed) = (c["corrupted"].as_u64().unwrap(), c["caught"].as_u64().unwrap(), c["passed"].as_u64().unwrap());
    assert_eq!(caught + passed, n);
    assert_eq!(v["stages"][0]["corrupted"].as_u64(), Some(n));
    assert_eq!(v["stages"][0]["corrupt_rate_model"], 0.01);
    // Corruption is not loss: every frame is delivered.
    assert_eq!(v["delivered"], 100_000);

    let err = refused_scenario("c.toml", "[[stage]]\nmodel = \"corrupt\"\np = \"150%\"\n");
    assert!(err.contains("c.toml:3: stage 1 (corrupt): `p`: 1.5 is not a probability"), "{err}");
}

#[test]
fn export_netem_writes_the_new_stages_as_netems_own() {
    let _machine = machine::not_beside_a_run();
    let export = |file: &str| {
        let out = netfi().args(["export", "netem", file, "--dev", "eth0"]).output().unwrap();
        assert!(out.status.success(), "{file}: {}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8_lossy(&out.stdout).to_string();
        let tc = text.lines().find(|l| l.starts_with("tc qdisc replace")).unwrap_or_else(|| panic!("{text}")).to_string();
        (text, tc)
    };
    let (text, tc) = export("config/scenarios/netem_jitter.toml");
    // sd 20 ms over netem's Pareto-normal table's sd 1.0518: sigma 19015 µs.
    assert!(tc.ends_with("loss random 1% delay 100000us 19015us 25% distribution paretonormal"), "{tc}");
    assert!(text.contains("netem's correlation mixes each draw with the last"), "{text}");
    let (_, tc) = export("config/scenarios/netem_duplicate.toml");
    assert!(tc.contains("duplicate 1%") && tc.contains("distribution normal"), "{tc}");
    let (text, tc) = export("config/scenarios/netem_corrupt.toml");
    assert!(tc.contains("corrupt 1%") && tc.contains("delay 5000us"), "{tc}");
    assert!(text.contains("headers included"), "{text}");
    let (_, tc) = export("config/scenarios/netem_reorder.toml");
    assert!(tc.ends_with("delay 10000us reorder 25% gap 5"), "{tc}");
    let (_, tc) = export("config/scenarios/netem_slot.toml");
    assert!(tc.ends_with("loss random 1% slot 2000us 6000us packets 8"), "{tc}");
}

#[test]
fn check_refuses_an_oversized_queue_with_a_message_not_a_panic() {
    let _machine = machine::not_beside_a_run();
    let o = netfi().args(["scenario", "check", "Normal", "--frames", "10", "--queue-capacity", "4294967295"]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("queue_capacity (--queue-capacity) of 4294967295 frames") && !err.contains("panicked"), "{err}");
}

#[test]
fn check_trace_writes_every_fate_in_a_runs_columns() {
    let _machine = machine::not_beside_a_run();
    let dir = Scratch::new("check-trace");
    let path = dir.join("trace.csv");
    let v = netfi().args(["scenario", "check", "PLM-2", "--frames", "20000", "--seed", "5", "--json", "--trace"]).arg(&path).json();
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(netfi::trace::CSV_HEADER));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 20_000);
    let dropped = rows.iter().filter(|r| r[5] == "dropped").count() as u64;
    assert_eq!(dropped, v["dropped"]["ge_lomax"].as_u64().unwrap());
    assert!(rows.iter().filter(|r| r[5] == "dropped").all(|r| r[6] == "ge_lomax" && r[7] == "1" && r[8] == "1"));
    assert!(rows.iter().filter(|r| r[5] == "delivered").all(|r| r[9] == "0" && r[10] == r[11]));
    // The same seed, the same fates: the trace is the check's, frame by frame.
    let again = netfi().args(["scenario", "check", "PLM-2", "--frames", "20000", "--seed", "5", "--trace"]).arg(dir.join("again.csv")).output().unwrap();
    assert!(again.status.success());
    assert_eq!(std::fs::read_to_string(dir.join("again.csv")).unwrap(), text);
    // A file that cannot be written is an error naming it.
    let bad = netfi().args(["scenario", "check", "PLM-2", "--frames", "2000", "--trace", "/nonexistent-dir/trace.csv"]).output().unwrap();
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && err.contains("/nonexistent-dir/trace.csv"), "{err}");
}

/// The delay percentiles of `scenario check` are exact: the delays of the
/// frames its own `--trace` lists, at ranks `⌈q·n⌉` (they were an HDR
/// histogram's, up to 0.1 % high); the JSON then carries no error bound.
#[test]
fn check_delay_percentiles_are_the_exact_ones() {
    let _machine = machine::not_beside_a_run();
    let dir = Scratch::new("cli-exact");
    let csv = dir.join("trace.csv");
    let v = netfi().args(["scenario", "check", "config/scenarios/plm2_dlm2.toml", "--frames", "50000", "--seed", "7", "--json", "--trace"]).arg(&csv).json();
    let text = std::fs::read_to_string(&csv).unwrap();
    let cols: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let (fate, delay) = (cols.iter().position(|c| *c == "fate").unwrap(), cols.iter().position(|c| *c == "delay_ns").unwrap());
    let mut delays: Vec<u64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|c| c[fate] == "delivered")
        .map(|c| c[delay].parse().unwrap())
        .collect();
    delays.sort_unstable();
    assert_eq!(delays.len() as u64, v["delivered"].as_u64().unwrap());
    for (key, q) in [("p50", 0.5), ("p99", 0.99)] {
        let rank = ((q * delays.len() as f64).ceil() as usize).max(1);
        assert_eq!(v["delay_ms"][key].as_f64(), Some(delays[rank - 1] as f64 / 1e6), "{key}");
    }
    assert!(v["delay_ms"].get("error_fraction_max").is_none());
}
