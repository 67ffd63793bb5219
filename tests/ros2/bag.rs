//! `netfi ros2 record` and `replay` with rclpy nodes: what the robot's side
//! received through a scenario, recorded as MCAP, then replayed as the
//! console at its recorded timing.

use crate::{python, trace, u, Case};
use std::process::Command;

/// A PoseStamped's x (the talker's index), from its CDR with the header.
fn x_of(data: &[u8]) -> f64 {
    let body = &data[4..];
    let s = netfi::ros2msg::decode(netfi::ros2msg::Kind::PoseStamped, body).expect("a PoseStamped");
    s.q[0]
}

/// The fields of `pkg/msg/Type`'s `.msg` file as the ROS 2 installation
/// of `py` ships it: its lines without comments and blank lines.
fn installed_fields(py: &std::path::Path, ty: &str) -> String {
    let o = Command::new(py).args(["-c", "import sys; print(sys.prefix)"]).output().unwrap();
    let prefix = String::from_utf8(o.stdout).unwrap();
    let path = std::path::Path::new(prefix.trim()).join("share").join(format!("{ty}.msg"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines().map(|l| l.split('#').next().unwrap().trim_end()).filter(|l| !l.trim().is_empty()).map(|l| format!("{l}\n")).collect()
}

#[test]
fn the_definitions_written_into_mcap_are_those_ros_2_ships() {
    let Some(py) = python() else { return };
    let delimiter = format!("{}\nMSG: ", "=".repeat(80));
    for (kind, ty) in [
        (netfi::ros2msg::Kind::PoseStamped, "geometry_msgs/msg/PoseStamped"),
        (netfi::ros2msg::Kind::TransformStamped, "geometry_msgs/msg/TransformStamped"),
        (netfi::ros2msg::Kind::JointState, "sensor_msgs/msg/JointState"),
    ] {
        let mut parts = kind.definition().split(&delimiter);
        assert_eq!(parts.next().unwrap(), installed_fields(&py, ty), "{ty}");
        for part in parts {
            let (name, fields) = part.split_once('\n').unwrap();
            assert_eq!(fields, installed_fields(&py, name), "{name}, used by {ty}");
        }
    }
}

#[test]
fn what_the_robot_received_is_recorded_as_mcap_and_replays_at_its_timing() {
    let Some(c) = Case::start("bag") else { return };
    const N: usize = 300;
    let bag = c.dir.join("robot.mcap");
    let mut talker = c.node("talker.py", "console", &["/MTMR/measured_cp", &N.to_string(), "--rate-hz", "200", "--type", "pose"]);
    // The emulator's writer first, and its reader only once the recorder
    // subscribes, so that the recording has every message delivered.
    let mut emu = c.emulator(&["--scenario", "PLM-2", "--seed", "3", "--wait-for-peer-s", "60", "--ros2-topic", "/MTMR/measured_cp=/PSM1/servo_cp"]);
    let mut rec = Command::new(env!("CARGO_BIN_EXE_netfi"));
    rec.args(["ros2", "record"]).arg(&bag).args(["/PSM1/servo_cp", "--idle-end-ms", "1500", "--discovery-s", "60"]);
    let mut rec = c.spawn(rec, "record");
    let e = c.finish(&mut [&mut talker, &mut emu, &mut rec]);
    assert_eq!(u(&e["frames"]["entered"]), N as u64);
    // The recording is what was delivered, in release order, byte for byte
    // what the talker's PoseStamped serializes to.
    let bytes = std::fs::read(&bag).unwrap();
    let recorded: Vec<(u64, Vec<u8>)> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            assert_eq!((m.channel.topic.as_str(), m.channel.message_encoding.as_str()), ("/PSM1/servo_cp", "cdr"));
            let schema = m.channel.schema.as_ref().unwrap();
            assert_eq!((schema.name.as_str(), schema.encoding.as_str()), ("geometry_msgs/msg/PoseStamped", "ros2msg"));
            assert_eq!(std::str::from_utf8(&schema.data), Ok(netfi::ros2msg::Kind::PoseStamped.definition()), "the complete definition");
            (m.log_time, m.data.to_vec())
        })
        .collect();
    // rosbag2's header profile, and each channel's publishers' QoS as
    // rosbag2 writes it (the talker's: reliable, volatile).
    let header = mcap::read::LinearReader::new(&bytes).unwrap().find_map(|r| match r.unwrap() {
        mcap::records::Record::Header(h) => Some(h),
        _ => None,
    });
    assert_eq!(header.map(|h| h.profile), Some("ros2".to_string()));
    let channel = mcap::MessageStream::new(&bytes).unwrap().next().unwrap().unwrap().channel;
    let qos = &channel.metadata["offered_qos_profiles"];
    assert!(qos.starts_with("- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  liveliness: 1\n"), "{qos}");
    assert_eq!(qos.matches("- history").count(), 1, "one profile, the one publisher's (the emulator's writer): {qos}");
    let mut delivered: Vec<_> = trace(&c, "trace_emulator.csv").into_iter().filter(|r| r["fate"] == "delivered").collect();
    delivered.sort_by_key(|r| r["release_ns"].parse::<u64>().unwrap());
    let want: Vec<f64> = delivered.iter().map(|r| crate::index(r) as f64).collect();
    let have: Vec<f64> = recorded.iter().map(|(_, d)| x_of(d)).collect();
    assert_eq!(have, want, "the recording is what the emulator delivered, in order");
    assert!(recorded.iter().all(|(_, d)| d[..4] == [0, 1, 0, 0]), "each message with its CDR header");
    // Replayed onto the robot's topic: a listener gets every message, in
    // order, spread as recorded.
    let count = want.len().to_string();
    let mut listener = c.listener("replayed", "/PSM1/servo_cp", &["--type", "pose", "--count", &count]);
    let mut play = Command::new(env!("CARGO_BIN_EXE_netfi"));
    play.args(["ros2", "replay"]).arg(&bag);
    let mut play = c.spawn(play, "replay");
    play.done();
    listener.done();
    let got = c.received("replayed");
    assert_eq!(got.iter().map(|r| r.index as f64).collect::<Vec<_>>(), want, "the replay is the recording");
    // The span of the replay is the recording's: each message is due at
    // its recorded offset (a sleep's lateness, well under 20 ms, is what
    // may be added at the last).
    let span_recorded = (recorded.last().unwrap().0 - recorded[0].0) as i64;
    let span_replayed = got.last().unwrap().received_ns - got[0].received_ns;
    assert!((span_replayed - span_recorded).abs() < 20_000_000, "recorded over {span_recorded} ns, replayed over {span_replayed} ns");
}
