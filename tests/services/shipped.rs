//! Every shipped scenario file under `netfi run`, as a newcomer first runs
//! it: from the repository, and from another directory with relative paths;
//! and a `replay` stage whose recording is named relative to its scenario.

use super::u;
use crate::common::machine;
use crate::common::netfi::netfi;
use crate::common::scratch::Scratch;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Every `*.toml` under `dir`, its folders' too, in name order.
fn scenario_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(scenario_files(&path));
        } else if path.extension().is_some_and(|e| e == "toml") {
            out.push(path);
        }
    }
    out.sort();
    out
}

/// `path` (absolute) as a relative path from the directory `from` (absolute,
/// no links): up to the root, then down.
fn relative_from(from: &Path, path: &Path) -> PathBuf {
    let mut rel = PathBuf::new();
    for _ in from.components().skip(1) {
        rel.push("..");
    }
    rel.join(path.strip_prefix("/").unwrap())
}

/// `netfi run SCENARIO --out OUT ARGS --json` in `cwd`: exit 0, every frame
/// accounted for; the report.
#[track_caller]
fn run_in(cwd: &Path, scenario: &Path, out: &Path, args: &[&str]) -> Value {
    let o = netfi().current_dir(cwd).arg("run").arg(scenario).arg("--out").arg(out).args(args).arg("--json").output().unwrap();
    let what = format!("netfi run {} in {}", scenario.display(), cwd.display());
    assert!(o.status.success(), "{what}: {}\n{}", o.status, String::from_utf8_lossy(&o.stderr));
    let r: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{what}: no JSON report ({e})"));
    assert_eq!(r["frames"]["balanced"], true, "{what}: {:#}", r["frames"]);
    assert!(u(&r["frames"]["entered"]) > 0, "{what}: {:#}", r["frames"]);
    r
}

#[test]
fn every_shipped_scenario_runs_from_the_repository_and_from_elsewhere() {
    let _guard = machine::alone();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).canonicalize().unwrap();
    let scratch = Scratch::new("shipped");
    let elsewhere = scratch.canonicalize().unwrap();
    let files = scenario_files(&repo.join("config/scenarios"));
    let mut ran = 0;
    for (k, file) in files.iter().enumerate() {
        let text = std::fs::read_to_string(file).unwrap();
        if text.contains("shared/data/") && !repo.join("../shared/data/traces").exists() {
            eprintln!("skipped {}: the shared Mahimahi traces are absent", file.display());
            continue;
        }
        let in_repo = file.strip_prefix(&repo).unwrap();
        // From the repository: the path as its README gives it, the output
        // elsewhere; from another directory: both relative to it.
        for (cwd, scenario, out) in [
            (repo.as_path(), in_repo.to_path_buf(), elsewhere.join(format!("{k}-repo"))),
            (elsewhere.as_path(), relative_from(&elsewhere, file), PathBuf::from(format!("{k}-elsewhere"))),
        ] {
            run_in(cwd, &scenario, &out, &["--duration-s", "0.2", "--seed", "1"]);
            // The run's copy names every file a stage read, where it is.
            let kept = std::fs::read_to_string(cwd.join(&out).join("scenario.toml")).unwrap();
            for line in text.lines().filter(|l| l.starts_with("file = ")) {
                let named = line.trim_start_matches("file = ").trim_matches('"');
                let absolute = file.parent().unwrap().join(named).canonicalize().unwrap();
                assert!(kept.contains(&format!("file = \"{}\"", absolute.display())), "{}: {kept}", file.display());
            }
        }
        ran += 1;
    }
    assert!(ran >= 12, "ran {ran} of {} shipped scenarios", files.len());
}

#[test]
fn a_replay_stage_reads_its_recording_beside_its_scenario_and_says_what_it_replayed() {
    let _guard = machine::alone();
    let scratch = Scratch::new("replay-relative");
    let dir = scratch.canonicalize().unwrap();
    // A recording: the trace of a run of PLM-2.
    run_in(&dir, Path::new("PLM-2"), Path::new("recorded"), &["--frames", "300", "--seed", "3"]);
    std::fs::create_dir(dir.join("trial")).unwrap();
    std::fs::copy(dir.join("recorded/trace.csv"), dir.join("trial/fates.csv")).unwrap();
    std::fs::write(dir.join("trial/replay.toml"), "name = \"again\"\n\n[[stage]]\nmodel = \"replay\"\nfile = \"fates.csv\"\n").unwrap();
    // Each recorded fate used once: nothing started again. One frame more:
    // started again once.
    for (frames, wraps) in [("300", 0), ("301", 1)] {
        let out = dir.join(format!("again-{frames}"));
        let o = netfi().current_dir(&dir).args(["run", "trial/replay.toml", "--frames", frames, "--out"]).arg(&out).output().unwrap();
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{}\n{text}", String::from_utf8_lossy(&o.stderr));
        let r: Value = serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
        let rec = &r["stages"][0]["recording"];
        let file = dir.join("trial/fates.csv");
        assert_eq!((rec["file"].as_str(), u(&rec["fates"]), u(&rec["wraps"])), (file.to_str(), 300, wraps), "{rec:#}");
        // The text names the recording, its layout and how often it started again.
        let line = format!("replays `{}`: trace.csv (columns fate, reason, delay_ns), 300 fates, started again {wraps} times", file.display());
        assert!(text.contains(&line), "no `{line}` in:\n{text}");
        if wraps == 0 {
            // The recorded run's drops, frame for frame.
            let recorded: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("recorded/report.json")).unwrap()).unwrap();
            assert_eq!(r["frames"]["dropped"]["replay"], recorded["frames"]["dropped"]["ge_lomax"], "{:#}", r["frames"]);
        }
    }
}
