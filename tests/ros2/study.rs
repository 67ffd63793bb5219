//! A study whose trials join rclpy nodes standing in for a lab's console
//! and robot (ROS 2 lanes): the trial's run takes the console's poses off
//! one topic and releases them on another; the study's table gives the
//! motion of what the talker sent and the listener received, recomputed
//! here from the talker's own coordinates.

use crate::{rows, u, Case};
use std::collections::BTreeMap;
use std::process::Command;

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

/// The path length of `positions` in order, mm (the talker's are metres).
fn path_mm<'a>(positions: impl IntoIterator<Item = &'a Vec<f64>>) -> f64 {
    let mut len = 0.0;
    let mut last: Option<&Vec<f64>> = None;
    for q in positions {
        if let Some(l) = last {
            len += distance(l, q);
        }
        last = Some(q);
    }
    len * 1e3
}

#[test]
fn a_study_between_rclpy_nodes_measures_their_streams() {
    let Some(c) = Case::start("study") else { return };
    const N: usize = 500;
    let file = c.dir.join("study.toml");
    std::fs::write(
        &file,
        format!(
            "name = \"ros2 lab\"\nseed = 3\ndata = \"data\"\n[trial]\nduration_s = 60\npeers = \"lab\"\n\
             [trial.lab]\nros2-topic = [\"/arm/measured=/arm/servo\"]\nros2-domain = {}\nros2-linger-ms = 500\n\
             [questionnaires]\nsus = \"none\"\ntlx = \"none\"\n[[block]]\nname = \"b\"\nconditions = [\"PLM-2\"]\n[[participant]]\nid = \"P1\"\n",
            c.domain
        ),
    )
    .unwrap();
    let f = file.to_str().unwrap();
    let mut listener = c.listener("robot", "/arm/servo", &["--type", "transform"]);
    let mut next = Command::new(env!("CARGO_BIN_EXE_netfi"));
    next.args(["study", "next", f, "-p", "P1"]);
    let mut trial = c.spawn(next, "study-next");
    let sent_csv = c.dir.join("talker.sent.csv");
    let mut talker = c.node("talker.py", "talker", &["/arm/measured", &N.to_string(), "--rate-hz", "200", "--type", "transform", "--sent", sent_csv.to_str().unwrap()]);
    talker.done();
    trial.done();
    listener.done();
    assert!(trial.log().contains(": ran ("), "{}", trial.log());
    let netfi = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_netfi")).arg("study").args(args).output().unwrap();
        assert!(o.status.success(), "netfi study {args:?}: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout).unwrap()
    };
    netfi(&["mark", f, "-p", "P1", "done"]);
    let out = netfi(&["report", f]);
    let table = rows(&std::path::Path::new(out.trim()).join("trials.csv"));
    let row = &table[0];
    // The talker's translations (its first three coordinates), by index.
    let q: BTreeMap<u64, Vec<f64>> = rows(&sent_csv).iter().map(|r| (r["index"].parse().unwrap(), (0..3).map(|k| r[&format!("q{k}")].parse().unwrap()).collect())).collect();
    assert_eq!(q.len(), N);
    let received: Vec<u64> = c.received("robot").iter().map(|r| r.index).collect();
    assert!(received.len() < N && !received.is_empty(), "PLM-2 dropped none, or all, of {N}: {}", received.len());
    let close = |what: &str, got: &str, want: f64| {
        let got: f64 = got.parse().unwrap_or_else(|_| panic!("{what} = `{got}`"));
        assert!((got - want).abs() <= 1e-9 * want.abs().max(1.0), "{what}: the table says {got}, the nodes give {want}");
    };
    close("console motion", &row["console_motion_arm0_mm"], path_mm(q.values()));
    close("robot motion", &row["robot_motion_arm0_mm"], path_mm(received.iter().map(|i| &q[i])));
    assert_eq!(row["console_motion_arm1_mm"], "", "one lane: one arm");
    assert_eq!(row["outcome"], "done");
    assert!(["clean", "suspect"].contains(&row["clean"].as_str()), "{row:?}");
    assert_eq!(u(&serde_json::json!(row["frames_sent"].parse::<u64>().unwrap())), N as u64);
}
