//! Messages relayed between rclpy nodes through a scenario: the fates are
//! `scenario check`'s, the delays the injected ones, each lane and the
//! return topic with its own scenario, seed and account, and the motion
//! of PoseStamped read on both sides.

use crate::{assert_balanced, assert_listener_got_what_was_delivered, assert_loss_is_the_models, index, trace, u, Case};
use std::collections::BTreeMap;

#[test]
fn plm2_drops_exactly_what_scenario_check_drops_and_the_listener_gets_the_rest() {
    let Some(c) = Case::start("plm2") else { return };
    const N: usize = 1500;
    let mut listener = c.listener("listener", "/chatter_out", &[]);
    let mut talker = c.node("talker.py", "talker", &["/chatter", &N.to_string(), "--rate-hz", "500"]);
    let mut emu = c.emulator(&["--scenario", "PLM-2", "--seed", "3", "--ros2-topic", "/chatter=/chatter_out"]);
    let e = c.finish(&mut [&mut talker, &mut emu, &mut listener]);
    let f = &e["frames"];
    assert_eq!((u(&f["entered"]), u(&f["sent_by_console"])), (N as u64, N as u64), "every message entered: {f:#}");
    assert_eq!(u(&f["held_at_end"]), 0);
    let r = c.json("ros2.json");
    assert_eq!(r["balanced"], true);
    assert_eq!(r["forward"]["type"], "std_msgs/msg/String");
    assert!(r["forward"]["motion"].is_null(), "a String is no kinematic type");
    assert_eq!(r["forward"]["type_from"], "publisher");
    // rclpy's publisher announces its type's hash in its user data.
    let hash = r["forward"]["type_hash"].as_str().unwrap_or_default();
    assert!(hash.starts_with("RIHS01_") && hash.len() == 7 + 64, "the publisher's type hash: {:#}", r["forward"]["type_hash"]);
    assert_eq!(r["forward"]["lost_before_ingress"], 0);
    assert_eq!(r["forward"]["ended"]["reason"], "publishers_gone");
    // ge_lomax decides per message: with every message entered, the very
    // fates `scenario check` gives in simulated time, message for message.
    let t = trace(&c, "trace_emulator.csv");
    let fates: Vec<String> = t.iter().map(|r| r["fate"].clone()).collect();
    assert_eq!(fates, c.check_fates("PLM-2", N, 3));
    assert!(t.iter().enumerate().all(|(k, r)| index(r) == k as u64), "messages entered in the talker's order");
    assert_listener_got_what_was_delivered(&t, &c.received("listener"));
    assert_loss_is_the_models(&e);
    // What the emulator said, at the end and as it ran, and `netfi report`
    // on its directory: of topics and messages, nodes by name.
    let log = emu.log();
    crate::edges::assert_no_guid(&log);
    assert!(log.contains("netfi emulator: ROS 2 /chatter → /chatter_out, scenario PLM-2 (seed 3)"), "{log}");
    assert!(log.contains(&format!("messages   published {N}  entered {N}  delivered ")), "{log}");
    let o = crate::netfi().arg("report").arg(c.dir.join("out")).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{text}\n{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.starts_with("netfi emulator out: ROS 2 /chatter → /chatter_out (std_msgs/msg/String), scenario PLM-2 (seed 3)"), "{text}");
    assert!(text.contains(&format!("messages   published {N}  entered {N}  delivered {}  received ?", u(&f["delivered"]))), "{text}");
    assert!(text.contains("accounting balanced at the emulator: every message that entered"), "{text}");
    assert!(text.contains("not known: what the subscribers of /chatter_out received"), "{text}");
    assert!(text.contains(&format!("the scenario's drops of the {N} messages it decided")), "{text}");
    for never in ["frame", "console", "simulator", "robot", "missing", "FAULT", "report.json"] {
        assert!(!text.contains(never), "{never}: {text}");
    }
}

/// A reliable message whose datagram was lost on the way out is sent again
/// once the emulator's writer (RustDDS) heartbeats, every second
/// (`HEARTBEAT_PERIOD_SLOW`), and the listener answers: that period and two
/// hops more than the hop out.
const REPAIR_NS: i64 = 1_000_000_000;

/// How long one read of both clocks may take at most to count (ns).
const CLOCK_READ_NS: i64 = 20_000;

/// The wall clock less the monotonic clock, ns: read between two monotonic
/// reads no more than [`CLOCK_READ_NS`] apart, so it is within that of
/// the truth.
fn wall_less_monotonic() -> i64 {
    loop {
        let a = netfi::clock::now_ns() as i64;
        let wall = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos() as i64;
        let b = netfi::clock::now_ns() as i64;
        if b - a <= CLOCK_READ_NS {
            return wall - (a + b) / 2;
        }
    }
}

#[test]
fn dlm1_delays_seen_by_the_listener_are_the_injected_ones() {
    let Some(c) = Case::start("dlm1") else { return };
    const N: usize = 600;
    let mut listener = c.listener("listener", "/PSM1/servo_cp", &["--type", "pose"]);
    let mut talker = c.node("talker.py", "talker", &["/MTMR/measured_cp", &N.to_string(), "--rate-hz", "200", "--type", "pose"]);
    let wall_before = wall_less_monotonic();
    // The emulator takes the talker's first message only once it has the
    // listener's reader: no release before the listener can match.
    let mut emu = c.emulator(&["--scenario", "DLM-1", "--seed", "5", "--wait-for-peer-s", "60", "--ros2-topic", "/MTMR/measured_cp=/PSM1/servo_cp"]);
    let e = c.finish(&mut [&mut talker, &mut emu, &mut listener]);
    assert_eq!(u(&e["frames"]["delivered"]), N as u64, "DLM-1 drops nothing");
    // The emulator said what it waited for, and who came.
    let log = emu.log();
    let wait = "waiting up to 60.0 s for a subscriber of /PSM1/servo_cp (geometry_msgs/msg/PoseStamped) before reading /MTMR/measured_cp";
    let came = log.lines().any(|l| l.starts_with("emulator: the subscriber /listener of /PSM1/servo_cp ") && l.ends_with(": reading /MTMR/measured_cp"));
    assert!(log.contains(wait) && came, "{log}");
    crate::edges::assert_no_guid(&log);
    assert_eq!(c.json("ros2.json")["forward"]["type"], "geometry_msgs/msg/PoseStamped");
    let t = trace(&c, "trace_emulator.csv");
    let got = c.received("listener");
    assert_listener_got_what_was_delivered(&t, &got);
    // Frame for frame, what the listener sees of a message (its reception
    // less the talker's source timestamp, which the emulator keeps; both
    // read by Fast DDS on the wall clock) is the delay `scenario check`
    // gives that frame for the seed, plus what the report states of it:
    // the hop in (the DDS hop from the talker to the emulator's loop,
    // `ingress_ns − send_ns`) and the release's lateness; plus the hop out
    // (the emulator's write to the listener's DDS reception), which no one
    // measures. The hop out is one DDS hop between the same two
    // middlewares over the same loopback as the hop in: its allowance is
    // the largest hop in the report states for the run
    // (`ingress_wait_ns.max`), and for a message repaired on the way out
    // ([`REPAIR_NS`]) the writer's heartbeat and two such hops more. And the emulator reads the monotonic clock,
    // the listener the wall clock: however far the two drifted apart over
    // the run is allowed on either side.
    let check: BTreeMap<u64, i64> = c.check_rows("DLM-1", N, 5).iter().map(|r| (r["ingress_index"].parse().unwrap(), r["delay_ns"].parse().unwrap())).collect();
    let drift = (wall_less_monotonic() - wall_before).abs() + 2 * CLOCK_READ_NS;
    let hop_max = u(&e["ingress_wait_ns"]["max"]) as i64;
    let late_max = u(&e["release_lateness_ns"]["max"]) as i64;
    let by_index: BTreeMap<u64, &BTreeMap<String, String>> = t.iter().map(|r| (index(r), r)).collect();
    let n = |r: &BTreeMap<String, String>, k: &str| r[k].parse::<i64>().unwrap();
    let mut hops_out = Vec::new();
    for m in &got {
        let r = by_index[&m.index];
        let injected = check[&r["ingress_index"].parse::<u64>().unwrap()];
        assert_eq!(n(r, "delay_ns"), injected, "message {}: the emulator injected the delay scenario check gives", m.index);
        assert_eq!(n(r, "release_sched_ns") - n(r, "ingress_ns"), injected, "message {}: scheduled its delay after it entered", m.index);
        let seen = m.received_ns - m.source_ns;
        let hop_in = n(r, "ingress_ns") - n(r, "send_ns");
        let late = n(r, "release_ns") - n(r, "release_sched_ns");
        assert!((0..=hop_max).contains(&hop_in) && (0..=late_max).contains(&late), "message {}: the trace's hop in {hop_in} ns and lateness {late} ns within the report's {hop_max} and {late_max}", m.index);
        let hop_out = seen - injected - late - hop_in;
        assert!(
            (-drift..=hop_max + REPAIR_NS + 2 * hop_max + drift).contains(&hop_out),
            "message {}: the listener saw {seen} ns; injected {injected} ns, {late} ns late, hop in {hop_in} ns, leaves {hop_out} ns for the hop out, outside [0, {hop_max}] ± {drift} ns (and a repair's {REPAIR_NS} ns and two hops more)",
            m.index
        );
        hops_out.push(hop_out);
    }
    hops_out.sort_unstable();
    let repaired = hops_out.iter().filter(|h| **h > hop_max + drift).count();
    eprintln!("hop out (ns): min {}, p50 {}, max {}; allowance {hop_max} ± {drift}; {repaired} beyond it, within a repair", hops_out[0], hops_out[hops_out.len() / 2], hops_out[hops_out.len() - 1]);
    // DLM-1 reorders: the listener saw that too.
    assert!(got.windows(2).any(|w| w[1].index < w[0].index), "DLM-1 reorders some messages");
    // PoseStamped is read on both sides: the talker's x is its index, so
    // the console's path is N − 1 long; the robot's, in release order, is
    // the sum of the steps between what it got.
    let m = &c.json("ros2.json")["forward"]["motion"];
    assert_eq!(m["kind"], "pose_stamped");
    assert_eq!((u(&m["console"]["messages"]), m["console"]["length"].as_f64()), (N as u64, Some(N as f64 - 1.0)));
    assert_eq!(u(&m["robot"]["messages"]), got.len() as u64);
    let robot_length: u64 = got.windows(2).map(|w| w[1].index.abs_diff(w[0].index)).sum();
    assert_eq!(m["robot"]["length"].as_f64(), Some(robot_length as f64));
    assert!(m["divergence_max"].as_f64().unwrap() >= 1.0, "a delay of 70 ms or more at 200 Hz leaves the robot behind: {m}");
    assert_eq!(u(&m["malformed"]), 0);
}

#[test]
fn the_return_topic_goes_back_through_its_own_scenario() {
    let Some(c) = Case::start("return") else { return };
    const N: usize = 800;
    let mut console_view = c.listener("console_view", "/MTMR/state", &[]);
    let mut robot = c.listener("robot", "/PSM1/servo_cp", &["--type", "pose"]);
    let mut state = c.node("talker.py", "robot_state", &["/PSM1/measured_cp", &N.to_string(), "--rate-hz", "400"]);
    let mut console = c.node("talker.py", "console", &["/MTMR/measured_cp", "200", "--rate-hz", "100", "--type", "pose"]);
    let mut emu = c.emulator(&[
        "--scenario",
        "Normal",
        "--seed",
        "8",
        "--ros2-topic",
        "/MTMR/measured_cp=/PSM1/servo_cp",
        "--ros2-return",
        "/PSM1/measured_cp=/MTMR/state",
        "--return-scenario",
        "PLM-2",
    ]);
    let e = c.finish(&mut [&mut state, &mut console, &mut emu, &mut robot, &mut console_view]);
    assert_eq!(u(&e["frames"]["delivered"]), 200);
    let r = &e["ros2_return"];
    assert_balanced(r);
    assert_eq!(r["scenario"], "PLM-2");
    assert_eq!((u(&r["entered"]), u(&r["sent_by_robot"]), u(&r["lost_before_ingress"])), (N as u64, N as u64, 0), "{r:#}");
    // The return path's own seed, derived from the lane's: its fates are
    // scenario check's for that seed.
    assert_ne!(u(&r["seed"]), 8);
    let t = trace(&c, "trace_ros2_return.csv");
    let fates: Vec<String> = t.iter().map(|r| r["fate"].clone()).collect();
    assert_eq!(fates, c.check_fates("PLM-2", N, u(&r["seed"])));
    assert_listener_got_what_was_delivered(&t, &c.received("console_view"));
    assert_eq!(c.received("robot").len(), 200, "the forward topic is untouched (Normal)");
    let ros2 = c.json("ros2.json");
    assert_eq!(ros2["return_path"]["from"], "/PSM1/measured_cp");
    assert_eq!(ros2["return_path"]["to"], "/MTMR/state");
}

#[test]
fn two_lanes_each_with_its_own_scenario_seed_and_account() {
    let Some(c) = Case::start("bimanual") else { return };
    const N: usize = 800;
    let mut psm1 = c.listener("psm1", "/PSM1/servo_cp", &["--type", "pose"]);
    let mut psm2 = c.listener("psm2", "/PSM2/servo_cp", &["--type", "pose"]);
    let mut mtmr = c.node("talker.py", "mtmr", &["/MTMR/measured_cp", &N.to_string(), "--rate-hz", "400", "--type", "pose"]);
    let mut mtml = c.node("talker.py", "mtml", &["/MTML/measured_cp", &N.to_string(), "--rate-hz", "400", "--type", "pose"]);
    let mut emu = c.emulator(&[
        "--scenario",
        "PLM-2",
        "--stream-scenario",
        "1=PLM-1",
        "--seed",
        "11",
        "--ros2-topic",
        "/MTMR/measured_cp=/PSM1/servo_cp",
        "--ros2-topic",
        "/MTML/measured_cp=/PSM2/servo_cp",
    ]);
    for p in [&mut mtmr, &mut mtml, &mut emu, &mut psm1, &mut psm2] {
        p.done();
    }
    let mut seeds = Vec::new();
    for (k, (scenario, listener)) in [("PLM-2", "psm1"), ("PLM-1", "psm2")].into_iter().enumerate() {
        let e = c.json(&format!("stream-{k}/emulator.json"));
        assert_eq!(e["scenario"], scenario);
        assert_balanced(&e["frames"]);
        assert_eq!(u(&e["frames"]["entered"]), N as u64, "lane {k}");
        let t = trace(&c, &format!("stream-{k}/trace_emulator.csv"));
        let fates: Vec<String> = t.iter().map(|r| r["fate"].clone()).collect();
        assert_eq!(fates, c.check_fates(scenario, N, u(&e["seed"])), "lane {k}");
        let got = c.received(listener);
        assert_listener_got_what_was_delivered(&t, &got);
        // Loss costs an absolute pose nothing once the next one arrives:
        // the robot's path runs from the first message it got to the last.
        let m = &c.json(&format!("stream-{k}/ros2.json"))["forward"]["motion"];
        assert_eq!(m["console"]["length"].as_f64(), Some(N as f64 - 1.0));
        let (first, last) = (got.first().unwrap().index, got.last().unwrap().index);
        assert_eq!(m["robot"]["length"].as_f64(), Some((last - first) as f64), "lane {k}");
        seeds.push(u(&e["seed"]));
    }
    assert_eq!(seeds[0], 11, "lane 0 keeps the run's seed");
    assert_ne!(seeds[0], seeds[1], "each lane its own seed");
    let joint = c.json("emulator.json");
    assert_eq!(u(&joint["total"]["entered"]), 2 * N as u64);
}
