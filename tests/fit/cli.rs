//! `netfi fit` and `netfi export netem` as a user runs them.

use crate::common::netfi::{netfi, Outcome};
use crate::common::machine;


#[test]
fn fit_json_has_the_documented_fields_and_reproduces() {
    let _machine = machine::not_beside_a_run();
    let out = netfi().args(["fit", "loss", "30%", "--seed", "3", "--json"]).ok();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "model",
        "params",
        "target",
        "realized",
        "realized_ci95",
        "exact",
        "seed",
        "confirm_seed",
        "frames",
        "tool_version",
    ] {
        assert!(v.get(key).is_some(), "missing `{key}` in {v}");
    }
    assert_eq!(v["model"], "ge_lomax");
    assert_eq!(v["seed"], 3);
    assert_eq!(v["target"]["loss_rate"], 0.3);
    let realized = v["realized"]["loss_rate"].as_f64().unwrap();
    let ci = v["realized_ci95"]["loss_rate"].as_array().unwrap();
    assert!(ci[0].as_f64().unwrap() <= realized && realized <= ci[1].as_f64().unwrap());
    assert!((realized - 0.3).abs() <= 0.005 * 0.3);
    assert_eq!(v["params"]["alpha"].as_array().unwrap().len(), 2);
    let again = netfi().args(["fit", "loss", "0.3", "--seed", "3", "--json", "--threads", "1"]).ok();
    assert_eq!(out.stdout, again.stdout);
}

#[test]
fn fit_prints_its_seed_and_a_stage() {
    let _machine = machine::not_beside_a_run();
    let out = netfi().args(["fit", "delay", "250ms", "--p99-ms", "900"]).ok();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains(" seed "), "{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("[[stage]]\nmodel = \"delay\""), "{stdout}");
    assert!(stdout.contains("delay_ms_p99"), "{stdout}");
    let bad = netfi().args(["fit", "outage", "120%"]).output().unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("not a probability"));
}

#[test]
fn fit_jitter_takes_mean_p99_law_and_correlation() {
    let _machine = machine::not_beside_a_run();
    let v = netfi().args(["fit", "jitter", "100ms", "--p99-ms", "180", "--dist", "paretonormal", "--correlation", "25%", "--seed", "3", "--json"]).json();
    assert_eq!(v["model"], "jitter");
    assert_eq!(v["params"]["dist"], "paretonormal");
    assert_eq!(v["params"]["correlation"], 0.25);
    assert_eq!(v["within_tolerance"], true);
    assert_eq!(v["target"]["delay_ms_p99"], 180.0);
    for (args, says) in [
        (&["fit", "jitter", "100", "--p99-ms", "180", "--dist", "cauchy"][..], "expected one of normal, pareto, paretonormal"),
        (&["fit", "jitter", "100", "--p99-ms", "80"][..], "above the mean"),
        (&["fit", "jitter", "100", "--p99-ms", "180", "--correlation", "1"][..], "[0, 1)"),
    ] {
        let bad = netfi().args(args).output().unwrap();
        assert!(!bad.status.success(), "{args:?}");
        assert!(String::from_utf8_lossy(&bad.stderr).contains(says), "{args:?}: {}", String::from_utf8_lossy(&bad.stderr));
    }
}

#[test]
fn export_maps_loss_and_delay_and_says_what_is_approximated() {
    let _machine = machine::not_beside_a_run();
    let out = netfi().args(["export", "netem", "config/scenarios/plm2_dlm2.toml", "--dev", "veth0"]).ok();
    let script = String::from_utf8_lossy(&out.stdout);
    let cmd = script.lines().find(|l| l.starts_with("tc qdisc replace dev veth0 root netem")).unwrap();
    assert!(cmd.contains(" loss gemodel ") && cmd.contains(" 100% 0%"), "{cmd}");
    assert!(cmd.contains(" distribution netfi-h2-"), "{cmd}");
    // 300 ms of delay at 1 kHz holds more than netem's default 1000 packets.
    let limit: u64 = cmd.split_whitespace().skip_while(|w| *w != "limit").nth(1).unwrap().parse().unwrap();
    assert!(limit > 1000, "{cmd}");
    assert!(script.contains("geometric") && script.contains("limit raised"), "{script}");
    assert!(script.contains("<<'NETFI_TABLE'"), "{script}");

    let out = netfi().args(["export", "netem", "config/scenarios/netem_markov4.toml"]).ok();
    let script = String::from_utf8_lossy(&out.stdout);
    assert!(script.contains(" loss state ") && script.contains("exact"), "{script}");
}

#[test]
fn export_refuses_what_netem_cannot_express() {
    let _machine = machine::not_beside_a_run();
    for (scenario, says) in [("CLM-1", "outage windows"), ("config/scenarios/outage_timeline.toml", "timeline")] {
        let out = netfi().args(["export", "netem", scenario]).output().unwrap();
        assert!(!out.status.success(), "{scenario}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(says), "{scenario}: {stderr}");
    }
}
