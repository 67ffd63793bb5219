//! The video stream of a run (`--video-mbps`): a camera on the robot side,
//! variable-size frames through a link of their own, measured at the
//! console. At 5 Hz a freeze is a gap over 400 ms, far above what a busy
//! host adds, so that what a link does shows alone.

use super::{run, u};
use serde_json::Value;
use std::path::Path;

/// One row of `video_received.csv`, by column name.
struct Row<'a>(std::collections::HashMap<&'a str, &'a str>);

impl Row<'_> {
    fn n(&self, col: &str) -> u64 {
        self.0[col].parse().unwrap_or_else(|e| panic!("{col} = {:?}: {e}", self.0[col]))
    }
}

/// `video_received.csv` against the run's report: one row per frame the
/// console received, frame indices increasing, whole and damaged rows the
/// report's counts, the whole rows' delays the report's (within the
/// histogram's precision, 3 significant digits), every displayed row's gap
/// the time since the previous displayed row, and its freeze rows the
/// report's freezes. Returns the rows' frame indices.
fn check_received_csv(out: &Path, r: &Value) -> Vec<u64> {
    let v = &r["video"];
    let c = &r["console"]["video"];
    let path = out.join("video_received.csv");
    assert_eq!(r["files"]["video_received"].as_str().map(Path::new), Some(path.as_path()), "{:#}", r["files"]);
    assert!(r["files"]["video_trace"].as_str().is_some_and(|p| p.ends_with("trace_video.csv")), "{:#}", r["files"]);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header.join(","), netfi::video::RECEIVED_CSV_HEADER);
    let rows: Vec<Row> = lines
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            assert_eq!(cells.len(), header.len(), "{l}");
            Row(header.iter().copied().zip(cells).collect())
        })
        .collect();
    assert_eq!(rows.len() as u64, u(&c["received"]), "{c:#}");
    let whole: Vec<&Row> = rows.iter().filter(|r| r.0["fate"] == "whole").collect();
    assert_eq!(whole.len() as u64, u(&v["frames"]["whole"]), "{v:#}");
    assert_eq!((rows.len() - whole.len()) as u64, u(&c["damaged"]), "{c:#}");
    let idx: Vec<u64> = rows.iter().map(|r| r.n("frame_index")).collect();
    assert!(idx.windows(2).all(|w| w[0] < w[1]), "{idx:?}");
    for r in &rows {
        assert_eq!(r.n("delay_ns"), r.n("recv_ns") - r.n("send_ns"));
        assert!(r.n("send_ns") <= r.n("ingress_ns") && r.n("ingress_ns") <= r.n("release_ns") && r.n("release_ns") <= r.n("recv_ns"));
        assert_eq!(r.n("key") == 1, r.n("gop_index") == 0);
        assert_eq!(r.n("len"), r.n("bytes"));
    }
    // The delays: the histogram's max is the highest value equivalent to the
    // largest row's (3 significant digits: within 0.1 %), its median at
    // rank ceil(n/2) of the rows.
    let mut d: Vec<u64> = whole.iter().map(|r| r.n("delay_ns")).collect();
    d.sort_unstable();
    let s = &v["delay_ns"];
    assert_eq!(u(&s["count"]), d.len() as u64);
    let near = |hist: u64, row: u64| hist >= row && hist - row <= row / 1000 + 1;
    assert!(near(u(&s["max"]), *d.last().unwrap()), "report max {} vs rows' {}", s["max"], d.last().unwrap());
    let k = d.len().div_ceil(2);
    assert!(near(u(&s["p50"]), d[k - 1]), "report p50 {} vs the rows' {}", s["p50"], d[k - 1]);
    // Displayed rows: the gaps chain the receive times; freezes are the report's.
    let shown: Vec<&&Row> = whole.iter().filter(|r| r.n("displayed") == 1).collect();
    assert_eq!(shown.len() as u64, u(&v["frames"]["whole"]) - u(&v["late"]));
    assert_eq!(shown[0].0["gap_ns"], "");
    for w in shown.windows(2) {
        assert_eq!(w[1].n("gap_ns"), w[1].n("recv_ns") - w[0].n("recv_ns"));
    }
    let freezes = rows.iter().filter(|r| r.n("freeze") == 1).count() as u64;
    assert_eq!(freezes, u(&v["freezes"]), "{v:#}");
    idx
}

const VIDEO: [&str; 8] = ["--video-mbps", "2", "--video-hz", "5", "--video-gop", "5", "--duration-s", "4"];

fn video(r: &Value) -> &Value {
    let v = &r["video"];
    assert!(v.is_object(), "no video section: {r:#}");
    assert_eq!(v["balanced"], true, "{v:#}");
    let f = &v["frames"];
    assert_eq!(u(&f["sent"]), u(&f["whole"]) + u(&f["damaged"]) + u(&f["lost"]), "{f}");
    v
}

#[test]
fn through_normal_every_video_frame_arrives_whole_without_a_freeze() {
    let (r, ok, out) = run("video-normal", &[&["Normal", "--seed", "3"][..], &VIDEO].concat());
    assert!(ok, "{r:#}");
    let v = video(&r);
    // The console's record: every frame it was sent, whole, one after another.
    let idx = check_received_csv(&out, &r);
    assert_eq!(idx.len() as u64, u(&v["frames"]["whole"]) + u(&v["frames"]["damaged"]));
    assert_eq!(idx, (idx[0]..idx[0] + idx.len() as u64).collect::<Vec<_>>());
    let f = &v["frames"];
    // 4 s at 5 Hz: about 20 frames (the camera starts once the emulator listens).
    assert!(u(&f["sent"]) >= 15, "{f}");
    assert_eq!(u(&f["whole"]), u(&f["sent"]), "{v:#}");
    assert_eq!(u(&v["delay_ns"]["count"]), u(&f["whole"]));
    assert_eq!(u(&v["freezes"]), 0, "{v:#}");
    assert_eq!(u(&v["camera"]["key_bytes"]), 166_667);
    // A normal run is unchanged by the video beside it.
    assert_eq!(u(&r["frames"]["delivered"]), 4000);
}

#[test]
fn a_rate_link_slower_than_the_video_queues_it_and_freezes_the_picture() {
    // 2 Mbit/s of video through 1 Mbit/s: a key frame of 166,667 bytes alone
    // takes 1.333 s on the link, and every frame waits behind the ones before.
    let scenario = std::env::temp_dir().join(format!("netfi-it-{}-rate1m.toml", std::process::id()));
    std::fs::write(&scenario, "name = \"rate-1M\"\n[[stage]]\nmodel = \"rate\"\nrate_bit_s = 1_000_000\n").unwrap();
    let path = scenario.to_str().unwrap();
    let (r, ok, out) = run("video-rate", &[&["Normal", "--seed", "3", "--video-scenario", path][..], &VIDEO].concat());
    std::fs::remove_file(&scenario).ok();
    assert!(ok, "{r:#}");
    let v = video(&r);
    // Queued delays of a second and more, and freezes, row by row as reported.
    check_received_csv(&out, &r);
    // Exact in the model: the key frame's serialization, 166,667 × 8 bits at 1 Mbit/s.
    assert!(u(&v["injected_delay_ns"]["max"]) >= 1_333_336_000, "{v:#}");
    // Every frame waits at least 1.2 s in the model (module docs of the test);
    // the transport only adds.
    assert!(u(&v["delay_ns"]["p50"]) >= 1_200_000_000, "{v:#}");
    assert!(u(&v["freezes"]) >= 1, "{v:#}");
    assert!(v["freeze_longest_ms"].as_f64().unwrap() >= 1000.0, "{v:#}");
    assert!(u(&v["frames"]["whole"]) < u(&v["frames"]["sent"]), "frames still queued at the end are lost: {v:#}");
}

#[test]
fn a_frame_over_the_runs_maximum_is_the_drop_too_large() {
    // 8 Mbit/s at 10 Hz, GOP 10: key frames of 470,588 bytes, deltas of 58,824.
    let args = ["Normal", "--seed", "3", "--duration-s", "3", "--video-mbps", "8", "--video-hz", "10", "--video-gop", "10", "--video-max-bytes", "100000"];
    let (r, ok, _) = run("video-too-large", &args);
    assert!(ok, "{r:#}");
    let v = video(&r);
    // The camera's frames all enter the emulator; those it releases while no
    // console listens (before the console's receiver subscribed, or after it
    // ended) are not counted as sent to the console, and they are deltas
    // (a key frame is never released).
    let camera = u(&v["camera"]["frames_sent"]);
    assert!(camera >= 20, "{v:#}");
    assert_eq!(v["bytes_entered"], v["camera"]["bytes_sent"], "{v:#}");
    let keys = camera.div_ceil(10);
    // Every key frame (one in ten, from the first) and nothing else.
    assert_eq!(u(&v["dropped"]["too_large"]), keys, "{v:#}");
    assert_eq!(u(&v["frames"]["lost"]), keys, "{v:#}");
    assert_eq!(u(&v["frames"]["whole"]), u(&v["frames"]["sent"]) - keys, "{v:#}");
}
