//! The motion of JointState and TransformStamped streams from rclpy
//! talkers, as the report gives it, recomputed from what the talker sent
//! (each message's coordinates, written by the talker as it sent them) and
//! when the emulator took each message in and released it (its trace).

use crate::{assert_listener_got_what_was_delivered, index, rows, trace, u, Case};
use serde_json::Value;
use std::collections::BTreeMap;

/// The report's stall threshold (`kinematics::STALL_THRESHOLD_NS_DEFAULT`).
const STALL_NS: u64 = 10_000_000;

/// One side's motion, as `ros2msg::Motion` measures it.
#[derive(Default)]
struct Side {
    messages: u64,
    length: f64,
    last: Option<Vec<f64>>,
    last_ns: Option<u64>,
    stalls: (u64, u64, u64),
}

impl Side {
    fn push(&mut self, t: u64, q: &[f64]) {
        if let Some(l) = &self.last {
            self.length += distance(l, q);
        }
        if let Some(p) = self.last_ns {
            let gap = t.saturating_sub(p);
            if gap > STALL_NS {
                self.stalls = (self.stalls.0 + 1, self.stalls.1 + gap, self.stalls.2.max(gap));
            }
        }
        self.messages += 1;
        self.last = Some(q.to_vec());
        self.last_ns = Some(t);
    }

    /// Its figures equal the report's `side`.
    fn check(&self, side: &Value, what: &str) {
        assert_eq!(u(&side["messages"]), self.messages, "{what}");
        close(side["length"].as_f64().unwrap(), self.length, &format!("{what} length"));
        let s = &side["stalls"];
        assert_eq!((u(&s["count"]), u(&s["total_ns"]), u(&s["longest_ns"])), self.stalls, "{what} stalls");
    }
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

/// Equal but for rounding: the same sums of the same terms in the same
/// order are equal to the last bit; 1e-9 relative leaves room only for a
/// different order of a sum's terms.
fn close(report: f64, want: f64, what: &str) {
    assert!((report - want).abs() <= 1e-9 * want.abs().max(1.0), "{what}: the report says {report}, what was sent gives {want}");
}

/// The talker's `--sent` CSV: each index's position coordinates (a pose's
/// first three; every joint of a joint state).
fn sent(c: &Case, name: &str, positions: Option<usize>) -> BTreeMap<u64, Vec<f64>> {
    rows(&c.dir.join(format!("{name}.sent.csv")))
        .iter()
        .map(|r| {
            let q: Vec<f64> = (0..r.len() - 1).map(|k| r[&format!("q{k}")].parse().unwrap()).collect();
            (r["index"].parse().unwrap(), q[..positions.unwrap_or(q.len())].to_vec())
        })
        .collect()
}

/// Runs `kind` messages from a talker through `scenario` to a listener and
/// checks the report's motion against the talker's coordinates; the
/// report's motion.
fn run(name: &str, kind: &str, type_name: &str, positions: Option<usize>, scenario: &str, seed: u64) -> Option<Value> {
    let c = Case::start(name)?;
    const N: usize = 600;
    let sent_csv = c.dir.join("talker.sent.csv");
    let mut listener = c.listener("robot", "/arm/servo", &["--type", kind]);
    let mut talker = c.node("talker.py", "talker", &["/arm/measured", &N.to_string(), "--rate-hz", "200", "--type", kind, "--sent", sent_csv.to_str().unwrap()]);
    let mut emu = c.emulator(&["--scenario", scenario, "--seed", &seed.to_string(), "--wait-for-peer-s", "60", "--ros2-topic", "/arm/measured=/arm/servo"]);
    let e = c.finish(&mut [&mut talker, &mut emu, &mut listener]);
    assert_eq!(u(&e["frames"]["entered"]), N as u64);
    let r = c.json("ros2.json");
    assert_eq!(r["forward"]["type"], type_name);
    let t = trace(&c, "trace_emulator.csv");
    assert_listener_got_what_was_delivered(&t, &c.received("robot"));
    let q = sent(&c, "talker", positions);
    assert_eq!(q.len(), N);
    // Each side's messages at the emulator's times: the console's as they
    // entered, the robot's as they were released; the divergence sampled
    // at each, in time order, once both sides have one.
    let ns = |r: &BTreeMap<String, String>, k: &str| r[k].parse::<u64>().unwrap();
    let mut events: Vec<(u64, bool, &Vec<f64>)> = t.iter().map(|r| (ns(r, "ingress_ns"), false, &q[&index(r)])).collect();
    events.extend(t.iter().filter(|r| r["fate"] == "delivered").map(|r| (ns(r, "release_ns"), true, &q[&index(r)])));
    events.sort_by_key(|e| (e.0, e.1));
    let (mut console, mut robot) = (Side::default(), Side::default());
    let (mut d_max, mut d_sum, mut d_n) = (0.0f64, 0.0, 0u64);
    for (t, is_robot, q) in events {
        (if is_robot { &mut robot } else { &mut console }).push(t, q);
        if let (Some(a), Some(b)) = (&console.last, &robot.last) {
            let d = distance(a, b);
            d_max = d_max.max(d);
            d_sum += d;
            d_n += 1;
        }
    }
    let m = r["forward"]["motion"].clone();
    assert_eq!(u(&m["malformed"]), 0);
    assert_eq!(u(&m["stall_threshold_ns"]), STALL_NS);
    console.check(&m["console"], "console");
    robot.check(&m["robot"], "robot");
    close(m["divergence_max"].as_f64().unwrap(), d_max, "divergence_max");
    close(m["divergence_mean"].as_f64().unwrap(), d_sum / d_n as f64, "divergence_mean");
    close(m["divergence_final"].as_f64().unwrap(), distance(console.last.as_ref().unwrap(), robot.last.as_ref().unwrap()), "divergence_final");
    Some(m)
}

#[test]
fn joint_states_through_plm2_motion_stalls_and_divergence_are_what_was_sent() {
    let Some(m) = run("joints", "joint", "sensor_msgs/msg/JointState", None, "PLM-2", 21) else { return };
    assert_eq!(m["kind"], "joint_state");
    // PLM-2's bursts leave gaps of two periods (10 ms) and more: stalls.
    assert!(u(&m["robot"]["stalls"]["count"]) > 0, "{m}");
    assert!(m["divergence_max"].as_f64().unwrap() > 0.0, "{m}");
}

#[test]
fn transforms_through_dlm1_motion_and_divergence_are_what_was_sent() {
    let Some(m) = run("transforms", "transform", "geometry_msgs/msg/TransformStamped", Some(3), "DLM-1", 5) else { return };
    assert_eq!(m["kind"], "transform_stamped");
    // DLM-1 reorders: the robot goes back and forth, a longer path.
    assert!(m["robot"]["length"].as_f64().unwrap() > m["console"]["length"].as_f64().unwrap(), "{m}");
}
