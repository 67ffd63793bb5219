//! Two hosts on one machine (`docs/udp.md`): the console and the robot in
//! network namespaces of their own, joined only through a third namespace
//! where the emulator runs, by two veth pairs. The console has no route to
//! the robot: everything it sends reaches the robot through the emulator, and
//! every reply comes back through it.
//!
//! Needs root (or CAP_SYS_ADMIN and CAP_NET_ADMIN) and `ip` (iproute2);
//! skips, saying why, where the machine does not allow it. The addresses are
//! documentation ranges (192.0.2.0/24, 198.51.100.0/24) that exist only
//! inside these namespaces, which the test removes again.

use super::bridge::{itp, u, Emulator};
use crate::common::machine;
use netfi::frame::ItpView;
use netfi::transport::udp::{PeerAddr, UdpOptions, UdpPort};
use crate::common::netns::Hosts;
use std::net::SocketAddr;
use std::os::fd::AsRawFd;
use std::process::Command;
use std::time::{Duration, Instant};


/// Opens a UDP socket bound to `addr` inside network namespace `ns`: a
/// thread enters the namespace (a thread's own network namespace is what new
/// sockets are created in) and the socket stays there when used elsewhere.
fn socket_in(ns: &str, addr: &str) -> Result<UdpPort, String> {
    let path = format!("/var/run/netns/{ns}");
    let addr: SocketAddr = addr.parse().unwrap();
    std::thread::spawn(move || {
        let f = std::fs::File::open(&path).map_err(|e| format!("{path}: {e}"))?;
        // SAFETY: setns on a namespace file this thread opened; it changes
        // only this short-lived thread's network namespace.
        if unsafe { libc::setns(f.as_raw_fd(), libc::CLONE_NEWNET) } != 0 {
            return Err(format!("setns({path}): {}", std::io::Error::last_os_error()));
        }
        UdpPort::bind(addr, &UdpOptions { reuse_address: false, buffer_bytes: Some(4 << 20) })
            .map_err(|e| e.to_string())
    })
    .join()
    .unwrap()
}

fn recv_until(port: &UdpPort, want: usize, timeout: Duration) -> Vec<Vec<u8>> {
    let mut got = Vec::new();
    let mut buf = vec![0u8; 1 << 16];
    let t0 = Instant::now();
    while got.len() < want && t0.elapsed() < timeout {
        match port.recv_from(&mut buf).unwrap() {
            Some(d) => got.push(buf[..d.len].to_vec()),
            None => std::thread::sleep(Duration::from_micros(100)),
        }
    }
    got
}

#[test]
fn console_and_robot_in_two_namespaces_talk_only_through_the_emulator() {
    let _guard = machine::alone();
    let Some(hosts) = Hosts::or_skip("nf", false) else { return };
    let console = socket_in(&hosts.console, "192.0.2.1:0").unwrap();
    let robot = socket_in(&hosts.robot, "198.51.100.2:36000").unwrap();

    // No route from the console to the robot: only the emulator joins them.
    let direct = console.send_to(b"direct", &PeerAddr::new("198.51.100.2:36000".parse().unwrap()));
    assert!(direct.is_err(), "the console must not reach the robot directly");

    let out = std::env::temp_dir().join(format!("netfi-netns-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).unwrap();
    let mut cmd = Command::new("ip");
    cmd.args(["netns", "exec", &hosts.emu, env!("CARGO_BIN_EXE_netfi"), "emulator"]);
    let emu = Emulator::start_command(
        cmd,
        &out,
        &[
            "--scenario",
            "PLM-1",
            "--seed",
            "5",
            "--ingress",
            "udp://192.0.2.2:36000",
            "--console-from",
            &console.local_addr().to_string(),
            "--egress",
            "udp://198.51.100.2:36000",
            "--idle-end-ms",
            "1000",
        ],
    );
    assert_eq!(emu.ingress(), "192.0.2.2:36000".parse::<SocketAddr>().unwrap());

    // The robot answers every command with a 52-byte feedback frame.
    let robot_thread = std::thread::spawn(move || {
        let mut buf = vec![0u8; 1 << 16];
        let mut commands = Vec::new();
        let mut peers = std::collections::BTreeSet::new();
        let t0 = Instant::now();
        let mut last = Instant::now();
        while t0.elapsed() < Duration::from_secs(30) && last.elapsed() < Duration::from_millis(1500) {
            match robot.recv_from(&mut buf).unwrap() {
                Some(d) => {
                    commands.push(buf[..d.len].to_vec());
                    peers.insert(d.from.ip());
                    robot.send_to(&[0x52; 52], &PeerAddr::new(d.from)).unwrap();
                    last = Instant::now();
                }
                None => std::thread::sleep(Duration::from_micros(100)),
            }
        }
        (commands, peers)
    });
    let to = PeerAddr::new("192.0.2.2:36000".parse().unwrap());
    let n = 1000u32;
    for i in 0..n {
        console.send_to(&itp(i), &to).unwrap();
        if i % 10 == 9 {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    let (e, udp) = emu.finish(Duration::from_secs(30));
    let (commands, peers) = robot_thread.join().unwrap();
    let replies = recv_until(&console, commands.len(), Duration::from_secs(2));

    let f = &e["frames"];
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&f["entered"]) + u(&udp["ingress_kernel_drops"]), u64::from(n), "{udp}");
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + dropped + u(&f["held_at_end"]), "{f}");
    assert!(dropped > 0, "PLM-1 drops some of 1000 frames");
    assert_eq!(commands.len() as u64, u(&f["delivered"]), "the robot got what the emulator released");
    assert!(commands.iter().all(|c| c.len() == 124 && ItpView::new_unchecked(&c[..]).verify_checksum()));
    // The robot saw only the emulator's address; the console got every
    // reply through the return path.
    assert_eq!(peers.into_iter().collect::<Vec<_>>(), ["198.51.100.1".parse::<std::net::IpAddr>().unwrap()]);
    assert_eq!(udp["console"].as_str().unwrap(), console.local_addr().to_string());
    let r = &udp["return_path"];
    assert_eq!(u(&r["received"]), commands.len() as u64, "{r}");
    assert_eq!(u(&r["delivered"]), commands.len() as u64, "{r}");
    assert_eq!(replies.len(), commands.len());
    assert!(replies.iter().all(|r| r.len() == 52));
}
