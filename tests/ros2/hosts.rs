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

use crate::{assert_balanced, python, trace, u, Case, ONE_RUN_AT_A_TIME};
use std::process::Command;

/// Runs `ip ARGS`; `Err` with its message if it fails.
fn ip(args: &[&str]) -> Result<(), String> {
    let o = Command::new("ip").args(args).output().map_err(|e| format!("cannot run `ip`: {e}"))?;
    if o.status.success() {
        Ok(())
    } else {
        Err(format!("`ip {}` failed: {}", args.join(" "), String::from_utf8_lossy(&o.stderr).trim()))
    }
}

/// The three namespaces and their links; removed when dropped.
struct Hosts {
    console: String,
    emu: String,
    robot: String,
}

impl Hosts {
    /// The topology of `docs/ros2.md`; `Err` says why it could not be made.
    fn build() -> Result<Hosts, String> {
        let id = std::process::id() % 100_000;
        let h = Hosts { console: format!("nr2-con-{id}"), emu: format!("nr2-emu-{id}"), robot: format!("nr2-rob-{id}") };
        ip(&["netns", "add", &h.console])?;
        ip(&["netns", "add", &h.emu])?;
        ip(&["netns", "add", &h.robot])?;
        let (c0, c1, r0, r1) = (format!("r2c0-{id}"), format!("r2c1-{id}"), format!("r2r0-{id}"), format!("r2r1-{id}"));
        ip(&["link", "add", &c0, "netns", &h.console, "type", "veth", "peer", "name", &c1, "netns", &h.emu])?;
        ip(&["link", "add", &r0, "netns", &h.robot, "type", "veth", "peer", "name", &r1, "netns", &h.emu])?;
        for (ns, dev, addr) in [(&h.console, &c0, "192.0.2.1/24"), (&h.emu, &c1, "192.0.2.2/24"), (&h.emu, &r1, "198.51.100.1/24"), (&h.robot, &r0, "198.51.100.2/24")] {
            ip(&["-n", ns, "addr", "add", addr, "dev", dev])?;
            ip(&["-n", ns, "link", "set", dev, "up"])?;
        }
        for ns in [&h.console, &h.emu, &h.robot] {
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        // DDS discovery is multicast: each end sends it towards the
        // emulator's host (which forwards nothing).
        ip(&["-n", &h.console, "route", "add", "default", "via", "192.0.2.2"])?;
        ip(&["-n", &h.robot, "route", "add", "default", "via", "198.51.100.1"])?;
        Ok(h)
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        for ns in [&self.console, &self.emu, &self.robot] {
            let _ = ip(&["netns", "del", ns]);
        }
    }
}

#[test]
fn console_and_robot_nodes_in_two_network_namespaces_talk_only_through_the_emulator() {
    let Some(py) = python() else { return };
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("skipping: network namespaces need root (or CAP_SYS_ADMIN and CAP_NET_ADMIN)");
        return;
    }
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let hosts = match Hosts::build() {
        Ok(h) => h,
        Err(why) => {
            eprintln!("skipping: this machine does not allow network namespaces joined by veth pairs: {why}");
            return;
        }
    };
    let c = Case::new("hosts", py);
    const N: usize = 600;
    let robot = Some(hosts.robot.as_str());
    let mut servo = c.listener_in(robot, "robot", "/PSM1/servo_cp", &["--type", "pose"]);
    // The console's own topic, watched from the robot's host: nothing
    // reaches it there but through the emulator.
    let mut direct = c.listener_in(robot, "direct", "/MTMR/measured_cp", &["--type", "pose", "--timeout-s", "15"]);
    let mut console = c.node_in(Some(&hosts.console), "talker.py", "console", &["/MTMR/measured_cp", &N.to_string(), "--rate-hz", "300", "--type", "pose"], &[]);
    let mut emu = c.emulator_in(Some(&hosts.emu), &["--scenario", "PLM-1", "--seed", "4", "--ros2-topic", "/MTMR/measured_cp=/PSM1/servo_cp"]);
    console.done();
    emu.done();
    servo.done();
    direct.done();
    let e = c.json("emulator.json");
    assert_balanced(&e["frames"]);
    assert_eq!(u(&e["frames"]["entered"]), N as u64);
    let t = trace(&c, "trace_emulator.csv");
    let fates: Vec<String> = t.iter().map(|r| r["fate"].clone()).collect();
    assert_eq!(fates, c.check_fates("PLM-1", N, 4));
    assert_eq!(c.received("robot").len() as u64, u(&e["frames"]["delivered"]));
    assert_eq!(c.received("direct").len(), 0, "the robot's host reached the console's topic directly");
    let r = c.json("ros2.json");
    let nodes: Vec<&str> = r["forward"]["endpoints"].as_array().unwrap().iter().map(|p| p["node"].as_str().unwrap()).collect();
    assert!(nodes.contains(&"/console") && nodes.contains(&"/robot"), "{nodes:?}");
}
