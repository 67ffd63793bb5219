//! The video stream of a run (`--video-mbps`): a camera on the robot side,
//! variable-size frames through a link of their own, measured at the
//! console. At 5 Hz a freeze is a gap over 400 ms, far above what a busy
//! host adds, so that what a link does shows alone.

use super::{run, u};
use serde_json::Value;

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
    let (r, ok, _) = run("video-normal", &[&["Normal", "--seed", "3"][..], &VIDEO].concat());
    assert!(ok, "{r:#}");
    let v = video(&r);
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
    let (r, ok, _) = run("video-rate", &[&["Normal", "--seed", "3", "--video-scenario", path][..], &VIDEO].concat());
    std::fs::remove_file(&scenario).ok();
    assert!(ok, "{r:#}");
    let v = video(&r);
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
    let entered = u(&v["frames"]["sent"]);
    assert!(entered >= 20, "{v:#}");
    // Every key frame (one in ten, from the first) and nothing else.
    assert_eq!(u(&v["dropped"]["too_large"]), entered.div_ceil(10), "{v:#}");
    assert_eq!(u(&v["frames"]["lost"]), entered.div_ceil(10), "{v:#}");
    assert_eq!(u(&v["frames"]["whole"]), entered - entered.div_ceil(10), "{v:#}");
}
