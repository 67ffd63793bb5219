//! `netfi study` as an experimenter uses it: a simulated study of three
//! participants under all ten conditions with the synthetic console
//! (trials of one second), its report recomputed from its own table;
//! trials killed mid-run (the runner, or its `netfi run`) resumed at that
//! trial and never counted twice; a second experimenter refused; the
//! experimenter's page driving a trial in headless chromium. The pure
//! parts (squares, schedules, the file's errors, the statistics) are in
//! `pure.rs`.

mod analysis;
mod lab;
mod browser;
mod forms;
mod pure;

use crate::common::machine;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::{Duration, Instant};


pub use crate::common::netfi::netfi;

pub use crate::common::scratch::Scratch;

/// `netfi study ARGS…`, which must succeed; its standard output.
pub fn study(args: &[&str]) -> String {
    let out = study_output(args);
    assert!(out.status.success(), "netfi study {args:?} failed:\n{}\n{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

pub fn study_output(args: &[&str]) -> Output {
    netfi().arg("study").args(args).output().expect("starting netfi")
}

/// The participant's progress (`status --json`).
pub fn status(file: &Path, id: &str) -> serde_json::Value {
    let text = study(&["status", file.to_str().unwrap(), "--participant", id, "--json"]);
    serde_json::from_str::<serde_json::Value>(&text).unwrap()[0].clone()
}

/// Processes whose command line names `needle`.
pub fn processes_naming(needle: &str) -> Vec<(u32, String)> {
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else { continue };
        if pid == std::process::id() {
            continue;
        }
        if let Ok(c) = std::fs::read(format!("/proc/{pid}/cmdline")) {
            let c = String::from_utf8_lossy(&c).replace('\0', " ");
            if c.contains(needle) {
                found.push((pid, c));
            }
        }
    }
    found
}

/// Waits until `f` holds, up to `secs`.
pub fn wait_for(what: &str, secs: u64, mut f: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(t0.elapsed() < Duration::from_secs(secs), "timed out after {secs} s waiting for {what}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A CSV of `trials.csv`'s kind: header and rows (no quoted fields in the
/// studies of these tests).
pub fn csv(text: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    (header, lines.map(|l| l.split(',').map(String::from).collect()).collect())
}

const CONDITIONS: [&str; 10] = ["Normal", "PLM-1", "PLM-2", "PLM-3", "DLM-1", "DLM-2", "DLM-3", "CLM-1", "CLM-2", "CLM-3"];

fn simulated_study() -> String {
    let mut t = String::from(
        "name = \"simulated\"\nseed = 11\ndata = \"data\"\n[trial]\nduration_s = 1\nrun_args = [\"--no-isolate\"]\n\
         [questionnaires]\nsus = \"start\"\ntlx = \"block\"\n\
         [[block]]\nname = \"free\"\nconditions = [\"Normal\"]\n\
         [[block]]\nname = \"packet loss\"\nconditions = [\"PLM-1\", \"PLM-2\", \"PLM-3\"]\n\
         [[block]]\nname = \"delay\"\nconditions = [\"DLM-1\", \"DLM-2\", \"DLM-3\"]\n\
         [[block]]\nname = \"communication loss\"\nconditions = [\"CLM-1\", \"CLM-2\", \"CLM-3\"]\n",
    );
    for (id, g) in [("P1", "a"), ("P2", "b"), ("P3", "a")] {
        t += &format!("[[participant]]\nid = \"{id}\"\ngroup = \"{g}\"\n");
    }
    t
}

/// Three participants through all ten conditions, as an experimenter
/// would: the SUS, each trial then its mark (one repeated), a TLX after
/// each block; then the report, whose every figure is recomputed here from
/// its own per-trial table.
#[test]
fn a_simulated_study_runs_trial_by_trial_and_its_report_is_its_table() {
    let _one = machine::alone();
    let dir = Scratch::new("simulated");
    let file = dir.file("study.toml", &simulated_study());
    let f = file.to_str().unwrap();
    let plan: serde_json::Value = serde_json::from_str(&study(&["plan", f, "--write", "--json"])).unwrap();
    let mut repeated = false;
    for id in ["P1", "P2", "P3"] {
        loop {
            let s = status(&file, id);
            match s["next"]["kind"].as_str().unwrap() {
                "questionnaire" if s["next"]["questionnaire"] == "sus" => {
                    study(&["answer", f, "-p", id, "sus", "4", "2", "5", "1", "4", "2", "5", "1", "4", "2"]);
                }
                "questionnaire" => {
                    study(&["answer", f, "-p", id, "tlx", "55", "30", "40", "25", "60", "35"]);
                }
                "trial" => {
                    let out = study(&["next", f, "-p", id]);
                    assert!(out.contains(": ran ("), "{out}");
                    let how = if id == "P2" && !repeated { "repeat" } else { "done" };
                    repeated |= id == "P2";
                    study(&["mark", f, "-p", id, how]);
                }
                "finished" => break,
                other => panic!("{id}: unexpected next step {other}: {s}"),
            }
        }
        // The conditions ran in the planned order.
        let s = status(&file, id);
        let ran: Vec<&str> = s["trials"].as_array().unwrap().iter().map(|t| t["condition"].as_str().unwrap()).collect();
        let planned: Vec<&str> = plan.as_array().unwrap().iter().find(|p| p["participant"] == id).unwrap()["trials"]
            .as_array().unwrap().iter().map(|t| t["condition"].as_str().unwrap()).collect();
        assert_eq!(ran, planned);
        assert!(s["trials"].as_array().unwrap().iter().all(|t| t["state"] == "done"));
    }
    let out = PathBuf::from(study(&["report", f]).trim());
    let (header, rows) = csv(&std::fs::read_to_string(out.join("trials.csv")).unwrap());
    let col = |n: &str| header.iter().position(|h| h == n).unwrap_or_else(|| panic!("no column {n}"));
    assert_eq!(rows.len(), 31, "30 trials and one repeated attempt");
    let done: Vec<&Vec<String>> = rows.iter().filter(|r| r[col("outcome")] == "done").collect();
    assert_eq!(done.len(), 30);
    assert_eq!(rows.iter().filter(|r| r[col("outcome")] == "repeat").count(), 1);
    assert!(header.contains(&"group".to_string()));
    let num = |r: &Vec<String>, c: &str| -> Option<f64> { r[col(c)].parse().ok() };
    for c in CONDITIONS {
        assert_eq!(done.iter().filter(|r| r[col("condition")] == c).count(), 3, "{c}");
    }
    // What the conditions must do to every frame, exactly.
    for r in &done {
        let c = r[col("condition")].as_str();
        assert_eq!(num(r, "frames_sent"), Some(1000.0), "{c}: one second at 1 kHz");
        let loss = num(r, "loss_rate").unwrap();
        let outages = num(r, "outages").unwrap();
        match &c[..3] {
            "Nor" => assert!(loss == 0.0 && outages == 0.0 && num(r, "delay_mean_ms") == Some(0.0), "{r:?}"),
            "PLM" => assert!(outages == 0.0 && num(r, "delay_mean_ms") == Some(0.0), "{r:?}"),
            "DLM" => assert!(loss == 0.0 && outages == 0.0 && num(r, "delay_mean_ms").unwrap() > 0.0, "{r:?}"),
            _ => assert_eq!(loss > 0.0, outages > 0.0, "an outage stage drops frames only in outages: {r:?}"),
        }
        if c == "Normal" {
            // Every frame arrives, undelayed: the robot moves as the console.
            for arm in ["arm0", "arm1"] {
                assert_eq!(num(r, &format!("console_motion_{arm}_mm")), num(r, &format!("robot_motion_{arm}_mm")), "{r:?}");
                assert_eq!(num(r, &format!("divergence_final_{arm}_mm")), Some(0.0), "{r:?}");
            }
        }
    }
    // Each figure is the run report's own (or counted from its trace).
    let r = done[done.len() - 1];
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.0.join("data").join(&r[col("trial_dir")]).join("report.json")).unwrap()).unwrap();
    for (column, pointer, per) in [
        ("duration_s", "/console/duration_s", 1.0),
        ("console_motion_arm1_mm", "/kinematics/console/length_mm/1", 1.0),
        ("robot_motion_arm0_mm", "/kinematics/robot/length_mm/0", 1.0),
        ("clutch_activations", "/kinematics/console/clutch_activations", 1.0),
        ("robot_stalls", "/kinematics/robot/stalls/count", 1.0),
        ("robot_stall_total_ms", "/kinematics/robot/stalls/total_ns", 1e6),
        ("divergence_max_arm1_mm", "/kinematics/divergence/1/max_mm", 1.0),
        ("frames_received", "/frames/received", 1.0),
        ("loss_rate", "/loss_rate", 1.0),
        ("delay_p99_ms", "/injected_delay_ns/p99", 1e6),
    ] {
        let want = report.pointer(pointer).and_then(|v| v.as_f64()).map(|v| v / per);
        assert_eq!(num(r, column), want, "{column} against {pointer}");
    }
    recompute(&out, &header, &done);
    // The questionnaires are beside them.
    let summary: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["sus"]["n"], 3);
    assert_eq!(summary["sus"]["mean"], 85.0, "2.5 × (17 + 17): items 4,2,5,1,… score 3,3,4,4,…");
    assert_eq!(summary["tlx"].as_array().unwrap().len(), 4);
    assert!((summary["tlx"][0]["raw"]["mean"].as_f64().unwrap() - 245.0 / 6.0).abs() < 1e-12);
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(!html.contains("src=\"http") && !html.contains("href=\"http"), "the page is self-contained");
    assert_eq!(html.matches("<svg id=\"plot-all-").count(), netfi::study::metrics::METRICS.len());
    assert!(html.contains("Holm"));
}

/// Every mean, sd, t and p of `summary.json` from the rows of `trials.csv`.
fn recompute(out: &Path, header: &[String], done: &[&Vec<String>]) {
    use statrs::distribution::{ContinuousCDF, StudentsT};
    let summary: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let col = |n: &str| header.iter().position(|h| h == n).unwrap();
    let close = |a: f64, b: f64, what: &str| assert!((a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-300), "{what}: report {a}, recomputed {b}");
    let all = &summary["summaries"][0];
    assert!(all["group"].is_null());
    let mut checked_tests = 0;
    for m in all["metrics"].as_array().unwrap() {
        let metric = m["metric"].as_str().unwrap();
        let k = col(metric);
        // participant → condition → value (one done trial each here).
        let value = |p: &str, c: &str| -> Option<f64> {
            done.iter().find(|r| r[0] == p && r[col("condition")] == c).and_then(|r| r[k].parse().ok())
        };
        for cs in m["conditions"].as_array().unwrap() {
            let c = cs["condition"].as_str().unwrap();
            let xs: Vec<f64> = ["P1", "P2", "P3"].iter().filter_map(|p| value(p, c)).collect();
            assert_eq!(cs["participants"].as_u64().unwrap() as usize, xs.len(), "{metric} {c}");
            if xs.is_empty() {
                continue;
            }
            let mean = xs.iter().sum::<f64>() / xs.len() as f64;
            close(cs["mean"].as_f64().unwrap(), mean, &format!("{metric} {c} mean"));
            let sd = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (xs.len() - 1) as f64).sqrt();
            close(cs["sd"].as_f64().unwrap(), sd, &format!("{metric} {c} sd"));
            let Some(t) = cs["versus_baseline"]["t_test"].as_object() else { continue };
            let d: Vec<f64> = ["P1", "P2", "P3"].iter().filter_map(|p| Some(value(p, c)? - value(p, "Normal")?)).collect();
            let md = d.iter().sum::<f64>() / d.len() as f64;
            let sdd = (d.iter().map(|x| (x - md).powi(2)).sum::<f64>() / (d.len() - 1) as f64).sqrt();
            let tt = md / (sdd / (d.len() as f64).sqrt());
            close(t["t"].as_f64().unwrap(), tt, &format!("{metric} {c} t"));
            let p = 2.0 * StudentsT::new(0.0, 1.0, (d.len() - 1) as f64).unwrap().sf(tt.abs());
            close(t["p"].as_f64().unwrap(), p, &format!("{metric} {c} p"));
            checked_tests += 1;
        }
    }
    assert!(checked_tests > 50, "only {checked_tests} t-tests were recomputed");
}

fn kill_study() -> String {
    "name = \"kills\"\nseed = 5\ndata = \"data\"\n[trial]\nduration_s = 3\nrun_args = [\"--no-isolate\"]\n[order]\nblocks = \"fixed\"\nwithin = \"fixed\"\n\
     [[block]]\nname = \"only\"\nconditions = [\"Normal\", \"PLM-2\"]\n[[participant]]\nid = \"X\"\n[[participant]]\nid = \"Y\"\n"
        .to_string()
}

/// Starts `netfi study next` for `id`; waits until its run streams;
/// returns the child, the run's pid and the trial's folder.
fn start_trial(file: &Path, data: &Path, id: &str) -> (std::process::Child, u32, PathBuf) {
    let child = netfi()
        .args(["study", "next", file.to_str().unwrap(), "--participant", id])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let state = data.join(id).join("state.json");
    let mut run: Option<(u32, PathBuf)> = None;
    wait_for("the trial's run to stream", 60, || {
        let Ok(text) = std::fs::read_to_string(&state) else { return false };
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let Some(a) = v["attempts"].as_array().unwrap().last() else { return false };
        let (Some(pid), Some(d)) = (a["run_pid"].as_u64(), a["dir"].as_str()) else { return false };
        let out = data.join(id).join(d);
        run = Some((pid as u32, out.clone()));
        out.join("console.ready").exists()
    });
    let (pid, out) = run.unwrap();
    (child, pid, out)
}

/// A trial killed mid-run, its runner (`netfi study next`) or its
/// `netfi run`: marked interrupted, its folder kept, no process of it left,
/// and the next `netfi study next` runs that trial again as attempt 2; the
/// table counts it once. While it runs, a second experimenter is refused.
#[test]
fn a_trial_killed_mid_run_is_interrupted_and_run_again_never_counted_twice() {
    let _one = machine::alone();
    let dir = Scratch::new("kills");
    let file = dir.file("study.toml", &kill_study());
    let f = file.to_str().unwrap();
    let data = dir.0.join("data");
    for (id, victim) in [("X", "runner"), ("Y", "run")] {
        let (mut runner, run_pid, out) = start_trial(&file, &data, id);
        // A second experimenter on the same participant is refused.
        let second = study_output(&["next", f, "-p", id]);
        let err = String::from_utf8_lossy(&second.stderr);
        assert!(!second.status.success() && err.contains("busy") && err.contains(&format!("pid {}", runner.id())), "{err}");
        let mark = study_output(&["mark", f, "-p", id, "done"]);
        assert!(!mark.status.success() && String::from_utf8_lossy(&mark.stderr).contains("busy"));
        let target = if victim == "runner" { runner.id() } else { run_pid };
        unsafe { libc::kill(target as i32, libc::SIGKILL) };
        let _ = runner.wait();
        // Nothing of the trial is left running.
        let needle = out.display().to_string();
        wait_for(&format!("every process of {needle} to end"), 60, || processes_naming(&needle).is_empty());
        let s = status(&file, id);
        assert_eq!(s["trials"][0]["state"], "interrupted", "{victim} killed: {s}");
        assert!(out.is_dir(), "the interrupted trial's folder is kept");
        // Resumed at that trial, as its second attempt.
        assert_eq!(s["next"]["kind"], "trial");
        assert_eq!((s["next"]["trial"].as_u64(), s["next"]["attempt"].as_u64()), (Some(1), Some(2)));
        let ran = study(&["next", f, "-p", id]);
        assert!(ran.contains("trial 1 (Normal) ended: ran"), "{ran}");
        assert!(data.join(id).join("trial-01-Normal-attempt-2/report.json").is_file());
        study(&["mark", f, "-p", id, "done"]);
        let s = status(&file, id);
        assert_eq!((s["trials"][0]["state"].as_str(), s["trials"][0]["attempts"].as_u64()), (Some("done"), Some(2)));
        assert_eq!(s["next"]["trial"], 2);
    }
    let out = PathBuf::from(study(&["report", f]).trim());
    let (header, rows) = csv(&std::fs::read_to_string(out.join("trials.csv")).unwrap());
    let (o, t) = (header.iter().position(|h| h == "outcome").unwrap(), header.iter().position(|h| h == "trial").unwrap());
    for id in ["X", "Y"] {
        let mine: Vec<(&str, &str)> = rows.iter().filter(|r| r[0] == id).map(|r| (r[t].as_str(), r[o].as_str())).collect();
        assert_eq!(mine, [("1", "interrupted"), ("1", "done")], "{id}");
    }
    let summary: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let normal = &summary["summaries"][0]["metrics"][0]["conditions"][0];
    assert_eq!((normal["condition"].as_str(), normal["trials"].as_u64()), (Some("Normal"), Some(2)), "one trial each counted");
}
