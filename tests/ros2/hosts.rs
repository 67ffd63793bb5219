//! Two hosts on one machine (`docs/ros2.md`): the console's node and the
//! robot's in network namespaces of their own, joined only through a third
//! where the emulator runs, by two veth pairs; no namespace forwards. The
//! robot's side cannot reach the console's topic: what it gets, it gets
//! through the emulator.
//!
//! Needs root (or CAP_SYS_ADMIN and CAP_NET_ADMIN) and `ip` (iproute2);
//! skips, saying why, where the machine does not allow it. The addresses
//! are documentation ranges that exist only inside these namespaces, which
//! the test removes again.

use crate::{index, trace, u, Case};
use netns::Hosts;

#[path = "../common/netns.rs"]
mod netns;

#[test]
fn console_and_robot_nodes_in_two_network_namespaces_talk_only_through_the_emulator() {
    let Some(c) = Case::start("hosts") else { return };
    let Some(hosts) = Hosts::or_skip("r2", true) else { return };
    const N: usize = 600;
    let robot = Some(hosts.robot.as_str());
    let mut servo = c.listener_in(robot, "robot", "/PSM1/servo_cp", &["--type", "pose"]);
    // The console's own topic, watched from the robot's host: nothing
    // reaches it there but through the emulator.
    let mut direct = c.listener_in(robot, "direct", "/MTMR/measured_cp", &["--type", "pose", "--timeout-s", "15"]);
    let mut console = c.node_in(Some(&hosts.console), "talker.py", "console", &["/MTMR/measured_cp", &N.to_string(), "--rate-hz", "300", "--type", "pose"], &[]);
    // The emulator reads the console's topic only once the robot's reader
    // is there, so that across namespaces too no release comes before the
    // robot's reader and the emulator's writer have matched.
    let mut emu = c.emulator_in(Some(&hosts.emu), &["--scenario", "PLM-1", "--seed", "4", "--wait-for-peer-s", "60", "--ros2-topic", "/MTMR/measured_cp=/PSM1/servo_cp"]);
    let e = c.finish(&mut [&mut console, &mut emu, &mut servo, &mut direct]);
    assert_eq!(u(&e["frames"]["entered"]), N as u64);
    let t = trace(&c, "trace_emulator.csv");
    let fates: Vec<String> = t.iter().map(|r| r["fate"].clone()).collect();
    assert_eq!(fates, c.check_fates("PLM-1", N, 4));
    // The robot got every delivered message, in release order, from the
    // first: none was released before its reader matched.
    let mut delivered: Vec<_> = t.iter().filter(|r| r["fate"] == "delivered").collect();
    assert_eq!(delivered.len() as u64, u(&e["frames"]["delivered"]));
    delivered.sort_by_key(|r| r["release_ns"].parse::<u64>().unwrap());
    let want: Vec<u64> = delivered.iter().map(|r| index(r)).collect();
    let have: Vec<u64> = c.received("robot").iter().map(|r| r.index).collect();
    assert_eq!(have, want, "the robot got every delivered message, in release order");
    assert_eq!(u(&e["frames"]["delivered_unsubscribed"]), 0);
    assert_eq!(c.received("direct").len(), 0, "the robot's host reached the console's topic directly");
    let r = c.json("ros2.json");
    let nodes: Vec<&str> = r["forward"]["endpoints"].as_array().unwrap().iter().map(|p| p["node"].as_str().unwrap()).collect();
    assert!(nodes.contains(&"/console") && nodes.contains(&"/robot"), "{nodes:?}");
}
