//! `netfi report DIR --html` on a real run: one self-contained page in the
//! run's directory with plots that carry data, the report's own figures,
//! the provenance, the control events, and errors that name their file.
//!
//! One short run (PLM-2 then DLM-2, a few seconds) serves every test; a
//! test that changes the run's files works on its own copy. `foreign`: a
//! run started by hand, without `netfi run`.

use crate::common::netfi::netfi;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;

use crate::common::machine;

mod foreign;

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("netfi-html-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// The run's directory (made once).
fn the_run() -> &'static Path {
    static RUN: OnceLock<PathBuf> = OnceLock::new();
    RUN.get_or_init(|| {
        let _guard = machine::alone();
        let out = temp_dir("run");
        let scenario = concat!(env!("CARGO_MANIFEST_DIR"), "/config/scenarios/plm2_dlm2.toml");
        let o = netfi().args(["run", scenario, "--duration-s", "3", "--seed", "11", "--out"]).arg(&out).output().unwrap();
        assert!(o.status.success(), "netfi run failed:\n{}\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
        out
    })
}

/// A copy of the run's directory that a test may change.
fn copy_of_the_run(name: &str) -> PathBuf {
    copy_dir(the_run(), name)
}

/// A copy of the files of the run directory `from`.
fn copy_dir(from: &Path, name: &str) -> PathBuf {
    let to = temp_dir(name);
    std::fs::create_dir_all(&to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
    to
}

fn report_html(dir: &Path) -> Output {
    netfi().arg("report").arg(dir).arg("--html").output().unwrap()
}

fn json(dir: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap()
}

/// The text of the element with `id`, up to the next tag.
fn text_of<'a>(html: &'a str, id: &str) -> &'a str {
    let at = html.find(&format!("id=\"{id}\"")).unwrap_or_else(|| panic!("no element #{id}"));
    let start = at + html[at..].find('>').unwrap() + 1;
    &html[start..start + html[start..].find('<').unwrap()]
}

/// The `<svg>` element with `id`.
fn svg<'a>(html: &'a str, id: &str) -> &'a str {
    let at = html.find(&format!("<svg id=\"{id}\"")).unwrap_or_else(|| panic!("no plot #{id}"));
    &html[at..at + html[at..].find("</svg>").unwrap()]
}

/// The number of points of each data curve of a plot: its polylines drawn
/// 2 wide (the grid's are 1 wide), less the legend's 2-point samples.
fn polylines(svg: &str) -> Vec<usize> {
    svg.split("<polyline")
        .skip(1)
        .map(|tag| &tag[..tag.find("/>").unwrap()])
        .filter(|tag| tag.contains("stroke-width=\"2\""))
        .map(|tag| {
            let pts = tag.split("points=\"").nth(1).unwrap();
            pts[..pts.find('"').unwrap()].split_whitespace().count()
        })
        .filter(|n| *n > 2)
        .collect()
}

/// The texts of a plot (titles, tick labels, legend), trimmed.
fn texts(svg: &str) -> Vec<&str> {
    svg.split("<text").skip(1).map(|t| t[t.find('>').unwrap() + 1..t.find("</text>").unwrap()].trim()).collect()
}

fn escaped(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;").replace('\'', "&#39;")
}

#[test]
fn the_page_is_self_contained_and_shows_the_run() {
    let dir = copy_of_the_run("page");
    let o = report_html(&dir);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let path = dir.join("report.html");
    assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), path.display().to_string());
    let html = std::fs::read_to_string(&path).unwrap();
    use std::os::unix::fs::PermissionsExt;
    assert_eq!(std::fs::metadata(&path).unwrap().permissions().mode() & 0o022, 0, "writable by others");
    assert!(html.starts_with("<!DOCTYPE html>"));
    // Nothing outside the file: no URL, no linked or embedded resource, no script.
    for outside in ["http://", "https://", "src=", "href=", "url(", "@import", "<script", "<link"] {
        assert!(!html.contains(outside), "the page names {outside:?}");
    }
    let r = json(&dir);
    // The realized loss is the report's own figure.
    let loss = r["loss_rate"].as_f64().unwrap();
    let at = html.find("id=\"realized-loss\"").unwrap();
    let value: f64 = html[at..].split("data-value=\"").nth(1).unwrap().split('"').next().unwrap().parse().unwrap();
    assert_eq!(value, loss);
    assert_eq!(text_of(&html, "realized-loss"), format!("{loss:.4}"));
    // The provenance, as the run recorded it.
    let p = &r["provenance"];
    assert_eq!(p["seed"], 11);
    assert!(p["command_line"].as_str().unwrap().contains("--seed 11"), "{p}");
    for (id, key) in [("prov-version", "version"), ("prov-command", "command_line"), ("prov-started", "started_utc"), ("prov-host", "host")] {
        assert_eq!(text_of(&html, id), escaped(p[key].as_str().unwrap()), "{id}");
    }
    assert_eq!(text_of(&html, "prov-seed"), "11");
    assert_eq!(text_of(&html, "prov-version"), env!("CARGO_PKG_VERSION"));
    // Plots with data: every latency series and the delay curves are drawn
    // point by point (a percentile curve has tens of points).
    let lat = polylines(svg(&html, "plot-latency"));
    assert_eq!(lat.len(), 4, "{lat:?}");
    assert!(lat.iter().all(|n| *n >= 20), "{lat:?}");
    let law = polylines(svg(&html, "plot-delay-law"));
    assert_eq!(law.len(), 3, "seen, drawn and the law: {law:?}");
    assert!(law.iter().all(|n| *n >= 50), "{law:?}");
    // One point per time bin: a bin is at most 2.5 hundredths of the run
    // (a 100th rounded up to 1, 2 or 5 × 10^k ns), so 3 s of frames in a
    // run of D s fill at least 3 / (0.025 D) bins, less one at each end
    // (20 in a run of 6 s; a loaded host makes the run longer).
    let d = r["duration_s"].as_f64().unwrap();
    let bins = (3.0 / (0.025 * d)).floor() as usize - 2;
    for id in ["plot-loss-over-time", "plot-delay-over-time"] {
        assert!(polylines(svg(&html, id)).iter().all(|n| *n >= bins), "{id}: fewer than {bins} points in a run of {d} s");
    }
    assert!(svg(&html, "plot-loss-runs").matches("<rect").count() >= 3);
    // Text is drawn without a font file: the labels are there, as text.
    let lat_texts = texts(svg(&html, "plot-latency"));
    for label in ["Latency by percentile", "90%", "99%", "direct hop", "release lateness"] {
        assert!(lat_texts.contains(&label), "{label:?} not in {lat_texts:?}");
    }
    let arms = texts(svg(&html, "plot-divergence"));
    assert!(arms.contains(&"arm 0") && arms.contains(&"arm 1"), "{arms:?}");
    assert!(html.contains("id=\"no-events\"") && text_of(&html, "no-events") == "no control events");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn control_events_in_the_report_are_listed() {
    let dir = copy_of_the_run("events");
    let mut r = json(&dir);
    r["events"] = serde_json::json!([{"t_s": 1.25, "what": "switch to DLM-1 <now>"}, {"t_s": 2.5, "what": "pause"}]);
    std::fs::write(dir.join("report.json"), serde_json::to_vec(&r).unwrap()).unwrap();
    let o = report_html(&dir);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(!html.contains("no control events"));
    let list = &html[html.find("id=\"event-list\"").unwrap()..];
    assert_eq!(list.matches("<tr class=\"event\">").count(), 2);
    assert!(list.contains("<td>1.250</td><td>switch to DLM-1 &lt;now&gt;</td>"), "{}", &list[..400.min(list.len())]);
    std::fs::remove_dir_all(&dir).ok();
}

/// `netfi report DIR --html` fails, naming `file`.
fn fails_naming(dir: &Path, file: &str) {
    let o = report_html(dir);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "succeeded");
    assert!(err.contains(&dir.join(file).display().to_string()), "{file} not named: {err}");
}

#[test]
fn missing_or_malformed_inputs_are_errors_naming_the_file() {
    let dir = copy_of_the_run("inputs");
    let trace = std::fs::read_to_string(dir.join("trace.csv")).unwrap();
    std::fs::write(dir.join("trace.csv"), format!("{trace}0,0,0,notanumber,0,delivered,,,,1,1,1,1\n")).unwrap();
    fails_naming(&dir, "trace.csv");
    std::fs::write(dir.join("trace.csv"), &trace).unwrap();
    for hlog in ["lateness.hlog", "direct_hop.hlog"] {
        let bytes = std::fs::read(dir.join(hlog)).unwrap();
        std::fs::write(dir.join(hlog), "Tag=x,0.0,1.0,5.0,notbase64!!\n").unwrap();
        fails_naming(&dir, hlog);
        std::fs::remove_file(dir.join(hlog)).unwrap();
        fails_naming(&dir, hlog);
        std::fs::write(dir.join(hlog), bytes).unwrap();
    }
    let report = std::fs::read(dir.join("report.json")).unwrap();
    std::fs::write(dir.join("report.json"), &report[..report.len() / 2]).unwrap();
    fails_naming(&dir, "report.json");
    // Without report.json the report is assembled from the services' own;
    // without the emulator's too, there is no run to report.
    std::fs::remove_file(dir.join("report.json")).unwrap();
    std::fs::remove_file(dir.join("emulator.json")).unwrap();
    fails_naming(&dir, "report.json");
    fails_naming(&dir, "emulator.json");
    assert!(!dir.join("report.html").exists(), "a page was written from bad inputs");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_failed_write_is_an_error_naming_the_page() {
    let dir = copy_of_the_run("write");
    // A directory (not empty) where the page goes: it cannot be replaced.
    std::fs::create_dir_all(dir.join("report.html").join("keep")).unwrap();
    fails_naming(&dir, "report.html");
    assert!(!dir.join("report.html.tmp").exists(), "the partial page was left behind");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_text_report_carries_the_provenance() {
    let o = netfi().arg("report").arg(the_run()).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let r = json(the_run());
    let p = &r["provenance"];
    let line = text.lines().find(|l| l.starts_with("provenance")).unwrap_or_else(|| panic!("{text}"));
    for key in ["version", "host", "started_utc"] {
        assert!(line.contains(p[key].as_str().unwrap()), "{key}: {line}");
    }
    assert!(text.contains(p["command_line"].as_str().unwrap()));
}
