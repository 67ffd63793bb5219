//! What the emulator refuses, and what it counts and survives: a type or
//! QoS that cannot match, bad input, a flooding publisher, nodes that come,
//! go or are killed.

use crate::{assert_balanced, here, wait_file, u, Case};
use std::time::{Duration, Instant};

#[test]
fn a_killed_publisher_ends_the_run_and_the_report_names_it() {
    let Some(c) = Case::start("killed") else { return };
    let mut listener = c.listener("robot", "/cmd_out", &["--count", "300"]);
    // A talker that stays after its 300 messages until it is killed, with
    // a participant lease of 1 s (Fast DDS's default: 20 s), so that its
    // death is seen soon.
    let ready = c.dir.join("talker.ready");
    let lease = here().join("short_lease.xml");
    let mut talker = c.node_in(None, "talker.py", "console", &["/cmd", "300", "--rate-hz", "300", "--hang", "--linger-s", "0", "--ready", ready.to_str().unwrap()], &[("FASTDDS_DEFAULT_PROFILES_FILE", &lease)]);
    let mut emu = c.emulator(&["--scenario", "Normal", "--seed", "1", "--ros2-topic", "/cmd=/cmd_out"]);
    wait_file(&ready, &mut talker);
    // Its last message is out once it says so.
    let t0 = Instant::now();
    while !talker.log().contains("300 sent") {
        assert!(t0.elapsed() < Duration::from_secs(60), "{}", talker.log());
        std::thread::sleep(Duration::from_millis(20));
    }
    // Its node's name reaches the emulator on Fast DDS's next heartbeat
    // (every 3 s) at the latest.
    std::thread::sleep(Duration::from_millis(3500));
    talker.child.kill().unwrap();
    emu.done();
    let r = c.json("ros2.json");
    let ended = &r["forward"]["ended"];
    assert_eq!(ended["reason"], "publishers_gone", "{r:#}");
    let detail = ended["detail"].as_str().unwrap();
    assert!(detail.contains("/console") && detail.contains("lease_expired"), "{detail}");
    let p = r["forward"]["endpoints"].as_array().unwrap().iter().find(|p| p["role"] == "publisher").expect("the publisher");
    assert_eq!((p["node"].as_str(), p["left"].as_str()), (Some("/console"), Some("lease_expired")));
    let e = c.json("emulator.json");
    assert_balanced(&e["frames"]);
    assert_eq!((u(&e["frames"]["entered"]), u(&e["frames"]["sent_by_console"])), (300, 300));
    assert!(emu.log().contains("the publisher /console of /cmd left (lease_expired)"), "{}", emu.log());
    listener.done();
}

/// Runs the emulator with `args` expecting it to refuse; its log.
fn refused(c: &Case, args: &[&str]) -> String {
    let mut emu = c.emulator(args);
    let s = emu.wait(Duration::from_secs(60));
    assert!(!s.success(), "the emulator did not refuse:\n{}", emu.log());
    emu.log()
}

#[test]
fn a_type_that_differs_from_the_one_given_or_expected_is_refused_with_both_types() {
    let Some(c) = Case::start("type") else { return };
    let _talker = c.node("talker.py", "talker", &["/x", "1", "--wait-subs", "0", "--hang"]);
    let log = refused(&c, &["--scenario", "Normal", "--ros2-topic", "/x=/y", "--ros2-type", "/x=geometry_msgs/msg/PoseStamped"]);
    for says in ["type mismatch on /x", "--ros2-type gives geometry_msgs/msg/PoseStamped", "the publisher /talker publishes std_msgs/msg/String"] {
        assert!(log.contains(says), "{says}: {log}");
    }
    // A subscriber of the topic written that expects another type, there
    // before the emulator: refused at start, named by its node, with or
    // without waiting for the robot's reader.
    let _sub = c.listener("listener", "/y", &["--type", "pose", "--timeout-s", "60"]);
    for wait in [&[][..], &["--wait-for-peer-s", "30"][..]] {
        let log = refused(&c, &[&["--scenario", "Normal", "--ros2-topic", "/x=/y"][..], wait].concat());
        for says in ["type mismatch on /y", "the subscriber /listener expects geometry_msgs/msg/PoseStamped", "the lane relays std_msgs/msg/String"] {
            assert!(log.contains(says), "{wait:?}: {says}: {log}");
        }
        assert_no_guid(&log);
    }
}

/// No DDS GUID (32 hex digits, as ROS 2's tools print a gid) in `log`:
/// nodes are named.
pub(crate) fn assert_no_guid(log: &str) {
    let guid = log.split(|c: char| !c.is_ascii_hexdigit()).find(|w| w.len() == 32);
    assert!(guid.is_none(), "a GUID ({}) where a node's name was due:\n{log}", guid.unwrap_or_default());
}

#[test]
fn a_qos_that_cannot_match_is_refused_naming_the_policy_and_both_sides() {
    let Some(c) = Case::start("qos") else { return };
    let _talker = c.node("talker.py", "talker", &["/x", "1", "--qos", "best_effort", "--wait-subs", "0", "--hang"]);
    // The reader asked for more than the publisher offers.
    let log = refused(&c, &["--scenario", "Normal", "--ros2-topic", "/x=/y", "--ros2-qos", "/x=reliable"]);
    for says in ["QoS mismatch on /x", "reliability", "the publisher /talker of /x offers best_effort", "requests reliable"] {
        assert!(log.contains(says), "{says}: {log}");
    }
    // A subscriber asks for more than the relay offers (the publisher's).
    let _sub = c.listener("listener", "/y", &["--qos", "reliable", "--timeout-s", "60"]);
    let log = refused(&c, &["--scenario", "Normal", "--ros2-topic", "/x=/y"]);
    for says in ["QoS mismatch on /y", "reliability", "offers best_effort", "the subscriber /listener of /y requests reliable"] {
        assert!(log.contains(says), "{says}: {log}");
    }
}

#[test]
fn bad_input_and_a_publisher_that_leaves_and_another_that_comes_keep_the_emulator_up() {
    let Some(c) = Case::start("restart") else { return };
    let mut listener = c.listener("listener", "/b", &[]);
    // Every 50th message of the first talker is larger than the emulator
    // relays; the second comes after the first has left, within the
    // emulator's linger.
    let mut a = c.node("talker.py", "talker_a", &["/a", "200", "--rate-hz", "400", "--big-every", "50", "--big-bytes", "3000", "--linger-s", "0.5"]);
    let mut emu = c.emulator(&["--scenario", "Normal", "--ros2-topic", "/a=/b", "--ros2-max-bytes", "1024", "--ros2-linger-ms", "8000"]);
    a.done();
    let mut b = c.node("talker.py", "talker_b", &["/a", "100", "--rate-hz", "400", "--first", "200"]);
    let e = c.finish(&mut [&mut b, &mut emu, &mut listener]);
    let f = &e["frames"];
    assert_eq!((u(&f["entered"]), u(&f["sent_by_console"])), (300, 300), "{f:#}");
    assert_eq!((u(&f["dropped"]["too_large"]), u(&f["bad_input"]["len_oversize"])), (4, 4));
    assert_eq!(f["bad_input"]["from"], serde_json::json!(["/talker_a"]));
    assert_eq!(u(&f["delivered"]), 296);
    assert_eq!(c.received("listener").len(), 296);
    let r = c.json("ros2.json");
    let events: Vec<(String, String)> = r["forward"]["events"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["role"] == "publisher")
        .map(|e| (e["node"].as_str().unwrap().to_string(), e["what"].as_str().unwrap().to_string()))
        .collect();
    let want = [("/talker_a", "joined"), ("/talker_a", "left"), ("/talker_b", "joined"), ("/talker_b", "left")];
    assert_eq!(events, want.map(|(n, w)| (n.to_string(), w.to_string())));
}

#[test]
fn a_publisher_faster_than_the_queue_is_counted_as_queue_full() {
    let Some(c) = Case::start("flood") else { return };
    let mut listener = c.listener("listener", "/b", &[]);
    // DLM-1 holds each message 70 ms or more: at 500 Hz that is 35 or more
    // at once, more than the 8 the queue holds.
    let mut a = c.node("talker.py", "talker", &["/a", "500", "--rate-hz", "500"]);
    let mut emu = c.emulator(&["--scenario", "DLM-1", "--seed", "2", "--ros2-topic", "/a=/b", "--queue-capacity", "8"]);
    let e = c.finish(&mut [&mut a, &mut emu, &mut listener]);
    let f = &e["frames"];
    assert_eq!(u(&f["entered"]), 500);
    assert!(u(&f["dropped"]["queue_full"]) > 0, "{f:#}");
    assert_eq!(c.received("listener").len() as u64, u(&f["delivered"]));
    assert!(c.json("ros2.json")["forward"]["slots_high_water"].as_u64().unwrap() <= 9, "one slot more than the queue");
}

#[test]
fn malformed_empty_and_oversized_messages_from_a_raw_dds_writer_are_counted_drops() {
    use netfi::transport::ros2::{qos, Role, Ros2Node, TopicName, TypeName};
    let Some(c) = Case::start("malformed") else { return };
    let mut listener = c.listener("listener", "/out", &["--type", "pose"]);
    // A DDS writer of this process, not a ROS node: it writes whatever
    // bytes it is given as PoseStamped.
    let mut node = Ros2Node::open(c.domain).unwrap();
    let topic = TopicName::parse("/in").unwrap();
    let mut writer = node.writer(&topic, &TypeName::parse("geometry_msgs/msg/PoseStamped").unwrap(), &qos::relay(None)).unwrap();
    let mut emu = c.emulator(&["--scenario", "Normal", "--ros2-topic", "/in=/out", "--ros2-max-bytes", "512"]);
    // The emulator's reader, seen from here.
    let t0 = Instant::now();
    loop {
        node.poll(netfi::clock::now_ns());
        if node.remotes(&topic, Role::Subscriber).next().is_some() {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "the emulator never subscribed:\n{}", emu.log());
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));
    // A PoseStamped as rclpy writes it (frame id `0`), with its x set.
    let pose = |x: f64| {
        let mut b = vec![0u8; 8];
        b.extend_from_slice(&2u32.to_le_bytes());
        b.extend_from_slice(b"0\0");
        b.resize(16, 0);
        for v in [x, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b
    };
    let mut sent = Vec::new();
    for i in 0..40u32 {
        let m = match i % 10 {
            3 => pose(f64::from(i))[..30].to_vec(), // truncated
            5 => vec![0u8; 600],                   // larger than 512 bytes
            7 => Vec::new(),                       // empty
            _ => pose(f64::from(i)),
        };
        writer.write(&m, Some(rustdds::Timestamp::now())).unwrap();
        sent.push(i % 10);
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(500));
    drop(writer);
    drop(node);
    let e = c.finish(&mut [&mut emu, &mut listener]);
    let f = &e["frames"];
    assert_eq!(u(&f["entered"]), 40);
    assert_eq!((u(&f["dropped"]["wrong_size"]), u(&f["dropped"]["too_large"])), (8, 4), "{f:#}");
    let b = &f["bad_input"];
    assert_eq!((u(&b["len_short"]), u(&b["len_zero"]), u(&b["len_oversize"])), (4, 4, 4), "{b:#}");
    assert_eq!(b["from"].as_array().unwrap().len(), 1, "the writer is named (by its GUID: it is no ROS node)");
    assert_eq!(u(&f["delivered"]), 28);
    assert_eq!(c.received("listener").len(), 28, "the emulator stayed up and relayed the rest");
    let m = &c.json("ros2.json")["forward"]["motion"];
    assert_eq!((u(&m["malformed"]), u(&m["console"]["messages"])), (4, 28), "{m}");
}
