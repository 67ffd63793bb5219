//! Only the intended peers over UDP: the ingress takes the named console's
//! datagrams only (`--console-from ADDR:PORT`; or, when asked, the first
//! sender's, `--console-from first`), and the return path only the robot's
//! (the egress address, or `--robot-from`). Everything else is refused
//! before it enters: counted per sender, never relayed, and it never takes
//! over either direction.

use super::bridge::{itp, out_dir, read_json, receiver, send_paced, socket, u, Emulator};
use crate::common::machine;
use netfi::frame::ItpView;
use netfi::transport::udp::UdpPort;
use serde_json::Value;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

fn frames(seqs: std::ops::Range<u32>) -> Vec<Vec<u8>> {
    seqs.map(|s| itp(s).to_vec()).collect()
}

/// What a hostile run sends besides the console.
struct Hostile {
    /// Frames the intruder sends to the ingress before the console's first.
    intruder_first: u32,
    /// Frames it sends in the middle of the console's.
    intruder_middle: u32,
    /// Datagrams a stranger sends to the emulator's egress port, before
    /// the console's first frame and again in the middle.
    stranger_each: u32,
}

/// What came of it.
struct Outcome {
    e: Value,
    udp: Value,
    log: String,
    console: UdpPort,
    intruder: UdpPort,
    stranger: UdpPort,
    /// The console's frames sent, and the intruder's and the stranger's.
    sent: u64,
    intruder_sent: u64,
    stranger_sent: u64,
}

/// One run: the robot answers each frame with a 52-byte feedback frame;
/// the console sends 200 frames; the intruder and the stranger send what
/// `h` says. `console_from` is the flag's value (`None`: the console's
/// address). Checks what the robot, the console and the intruder got.
fn run(name: &str, console_from: Option<&str>, h: Hostile) -> Outcome {
    let _guard = machine::alone();
    let out = out_dir(name);
    let (robot, console, intruder, stranger) = (socket(), socket(), socket(), socket());
    let egress = format!("udp://{}", robot.local_addr());
    let from = console_from.map_or_else(|| console.local_addr().to_string(), str::to_string);
    let emu = Emulator::bridge(&out, "Normal", "1", &from, &egress, &["--idle-end-ms", "1000"]);
    let feedback: Vec<u8> = (0..52u8).collect();
    let stop = Arc::new(AtomicBool::new(false));
    let robot_rx = receiver(robot, stop.clone(), Some(feedback.clone()));
    let console_rx = receiver(console.try_clone().unwrap(), stop.clone(), None);
    let intruder_rx = receiver(intruder.try_clone().unwrap(), stop.clone(), None);
    let junk = |n: u32| (0..n).map(|i| format!("not the robot {i}").into_bytes()).collect::<Vec<_>>();
    let mut stranger_sent = send_paced(&stranger, emu.egress_local(), junk(h.stranger_each), 10);
    let mut intruder_sent = send_paced(&intruder, emu.ingress(), frames(5000..5000 + h.intruder_first), 10);
    let mut sent = send_paced(&console, emu.ingress(), frames(0..100), 10);
    intruder_sent += send_paced(&intruder, emu.ingress(), frames(6000..6000 + h.intruder_middle), 10);
    stranger_sent += send_paced(&stranger, emu.egress_local(), junk(h.stranger_each), 10);
    sent += send_paced(&console, emu.ingress(), frames(100..200), 10);
    let (e, udp) = emu.finish(Duration::from_secs(30));
    stop.store(true, Ordering::Release);
    let (got, _) = robot_rx.join().unwrap();
    let (back, console) = console_rx.join().unwrap();
    let (stolen, intruder) = intruder_rx.join().unwrap();

    assert_eq!(u(&udp["ingress_kernel_drops"]), 0, "paced sends on loopback: {udp}");
    // The robot got the console's frames only, in order.
    let seqs: Vec<u32> = got.iter().map(|d| ItpView::new_unchecked(&d[..]).sequence()).collect();
    assert_eq!(seqs, (0..200).collect::<Vec<_>>(), "the robot got only the console's frames");
    // The robot's replies all went to the console, none to the intruder,
    // and nothing of the stranger's was relayed.
    assert_eq!(back.len() as u64, sent, "the console got one reply per frame, and nothing else");
    assert!(back.iter().all(|b| *b == feedback), "the console got something that is not the robot's reply");
    assert!(stolen.is_empty(), "the intruder got {} replies", stolen.len());
    // The accounting: the console's frames entered; the others were
    // counted apart.
    assert_eq!(u(&e["frames"]["entered"]), sent, "{}", e["frames"]);
    assert_eq!(u(&e["frames"]["delivered"]), sent);
    assert_eq!(u(&udp["datagrams_in"]), sent);
    assert_eq!(udp["console"], console.local_addr().to_string());
    let r = &udp["return_path"];
    assert_eq!(u(&r["received"]), sent, "only the robot's datagrams are taken on the way back: {r:#}");
    assert_eq!(u(&r["delivered"]), sent, "{r:#}");
    let _ = read_json(&out.join("udp_endpoints.json"));
    let log = std::fs::read_to_string(out.join("emulator.log")).unwrap_or_default();
    Outcome { e, udp, log, console, intruder, stranger, sent, intruder_sent, stranger_sent }
}

/// `udp.json`'s refused ingress datagrams name exactly `who` with `n`.
fn assert_ingress_refused(udp: &Value, who: &UdpPort, n: u64) {
    assert_eq!(u(&udp["foreign_sender"]), n, "{udp:#}");
    let named = udp["foreign_senders"].as_array().unwrap();
    assert_eq!(named.len(), 1, "{udp:#}");
    assert_eq!(named[0]["addr"], who.local_addr().to_string());
    assert_eq!(u(&named[0]["datagrams"]), n);
    assert_eq!(u(&udp["foreign_unnamed"]), 0);
}

#[test]
fn an_intruder_before_and_after_the_named_console_is_refused_and_counted() {
    let o = run("foreign-named", None, Hostile { intruder_first: 30, intruder_middle: 50, stranger_each: 0 });
    assert_eq!(o.intruder_sent, 80);
    assert_ingress_refused(&o.udp, &o.intruder, o.intruder_sent);
    assert_eq!(o.e["frames"]["entered"], o.sent);
}

/// Needs the emulator's `--console-from first`.
#[test]
fn paired_with_the_first_sender_an_intruder_after_it_is_refused_and_the_pairing_is_said() {
    let o = run("foreign-first", Some("first"), Hostile { intruder_first: 0, intruder_middle: 50, stranger_each: 0 });
    assert_ingress_refused(&o.udp, &o.intruder, o.intruder_sent);
    let paired = format!("paired with its first sender, udp://{}", o.console.local_addr());
    assert!(o.log.contains(&paired), "the pairing is not said on stderr:\n{}", o.log);
    assert!(o.log.contains("whoever sends first is trusted"), "no warning at start:\n{}", o.log);
}

/// The relaying part holds as is; the counts need the return path's
/// report to carry what its port refused (`return_path.refused`).
#[test]
fn a_stranger_at_the_egress_port_is_refused_counted_and_never_reaches_the_console() {
    let o = run("foreign-egress", None, Hostile { intruder_first: 0, intruder_middle: 0, stranger_each: 10 });
    assert_eq!(o.stranger_sent, 20);
    let refused = &o.udp["return_path"]["refused"];
    assert_eq!(u(&refused["datagrams"]), o.stranger_sent, "{:#}", o.udp["return_path"]);
    let senders = refused["senders"].as_array().unwrap();
    assert_eq!(senders.len(), 1, "{refused:#}");
    assert_eq!(senders[0]["addr"], o.stranger.local_addr().to_string());
    assert_eq!(u(&senders[0]["datagrams"]), o.stranger_sent);
}

/// A robot that answers from another socket than the one it listens on:
/// its replies are refused until it is named with `--robot-from` (needs
/// the emulator's `--robot-from`).
#[test]
fn a_robot_answering_from_another_port_is_refused_unless_named_with_robot_from() {
    for named in [false, true] {
        let _guard = machine::alone();
        let out = out_dir(if named { "robot-from-named" } else { "robot-from-not" });
        let (robot_in, robot_out, console) = (socket(), socket(), socket());
        let (egress, from) = (format!("udp://{}", robot_in.local_addr()), console.local_addr().to_string());
        let robot_from = robot_out.local_addr().to_string();
        let extra: &[&str] = if named { &["--idle-end-ms", "1000", "--robot-from", &robot_from] } else { &["--idle-end-ms", "1000"] };
        let emu = Emulator::bridge(&out, "Normal", "1", &from, &egress, extra);
        let egress_local = emu.egress_local();
        let stop = Arc::new(AtomicBool::new(false));
        let robot = {
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut buf = vec![0u8; 1 << 16];
                let mut n = 0u64;
                let t0 = std::time::Instant::now();
                while !(stop.load(Ordering::Acquire) || t0.elapsed() > Duration::from_secs(60)) {
                    match robot_in.recv_from(&mut buf).unwrap() {
                        Some(_) => {
                            n += 1;
                            send_paced(&robot_out, egress_local, [vec![0x52u8; 52]], usize::MAX);
                        }
                        None => std::thread::sleep(Duration::from_micros(100)),
                    }
                }
                n
            })
        };
        let console_rx = receiver(console.try_clone().unwrap(), stop.clone(), None);
        let sent = send_paced(&console, emu.ingress(), frames(0..100), 10);
        let (_, udp) = emu.finish(Duration::from_secs(30));
        stop.store(true, Ordering::Release);
        let answered = robot.join().unwrap();
        let (back, _) = console_rx.join().unwrap();
        assert_eq!(answered, sent);
        let r = &udp["return_path"];
        if named {
            assert_eq!(back.len() as u64, sent, "named, the robot's every reply reaches the console: {r:#}");
            assert_eq!(u(&r["refused"]["datagrams"]), 0, "{r:#}");
        } else {
            assert!(back.is_empty(), "a reply from an address other than the robot's reached the console");
            assert_eq!(u(&r["received"]), 0, "{r:#}");
            assert_eq!(u(&r["refused"]["datagrams"]), sent, "{r:#}");
            assert_eq!(r["refused"]["senders"][0]["addr"], robot_from);
        }
    }
}

/// Whether a socket bound to `[::]` here also takes IPv4 datagrams (IPv6
/// on, `net.ipv6.bindv6only` 0, Linux's default); the error says why not.
fn dual_stack() -> Result<(), String> {
    if std::fs::read_to_string("/proc/sys/net/ipv6/bindv6only").is_ok_and(|v| v.trim() != "0") {
        return Err("net.ipv6.bindv6only is set: a socket on [::] takes no IPv4".into());
    }
    std::net::UdpSocket::bind("[::]:0").map(drop).map_err(|e| format!("no IPv6 socket: {e}"))
}

/// A dual-stack wildcard (`[::]`) gives an IPv4 sender as an IPv4-mapped
/// address (`[::ffff:127.0.0.1]:P`). Named by their IPv4 addresses, the
/// console (`--console-from`) and the robot (the egress address, and
/// `--robot-from`) are the same peers: every frame and every reply goes
/// through, nothing is refused. Each of 100 console frames was once
/// refused as `[::ffff:127.0.0.1]:P`.
#[test]
fn ipv4_peers_of_a_dual_stack_wildcard_are_taken_as_their_ipv4_selves() {
    if let Err(why) = dual_stack() {
        eprintln!("skipped: {why}");
        return;
    }
    for robot_from in [false, true] {
        let _guard = machine::alone();
        let out = out_dir(if robot_from { "dual-stack-robot-from" } else { "dual-stack" });
        let (robot, console) = (socket(), socket());
        let (egress, from, robot_addr) = (format!("udp://{}", robot.local_addr()), console.local_addr().to_string(), robot.local_addr().to_string());
        let mut args = vec!["--scenario", "Normal", "--seed", "1", "--ingress", "udp://[::]:0", "--console-from", &from, "--egress", &egress, "--egress-bind", "[::]:0", "--idle-end-ms", "1000"];
        if robot_from {
            args.extend(["--robot-from", &robot_addr]);
        }
        let emu = Emulator::start(&out, &args);
        let on_v4 = |a: std::net::SocketAddr| std::net::SocketAddr::from(([127, 0, 0, 1], a.port()));
        assert!(emu.ingress().ip().is_unspecified() && emu.ingress().is_ipv6(), "{}", emu.ingress());
        let feedback: Vec<u8> = (0..52u8).collect();
        let stop = Arc::new(AtomicBool::new(false));
        let robot_rx = receiver(robot, stop.clone(), Some(feedback.clone()));
        let console_rx = receiver(console.try_clone().unwrap(), stop.clone(), None);
        let sent = send_paced(&console, on_v4(emu.ingress()), frames(0..100), 10);
        let (e, udp) = emu.finish(Duration::from_secs(30));
        stop.store(true, Ordering::Release);
        let (got, _) = robot_rx.join().unwrap();
        let (back, _) = console_rx.join().unwrap();
        assert_eq!(u(&udp["foreign_sender"]), 0, "the console was refused: {udp:#}");
        assert_eq!(u(&e["frames"]["entered"]), sent, "{}", e["frames"]);
        assert_eq!(got.len() as u64, sent, "the robot got every frame");
        let r = &udp["return_path"];
        assert_eq!(u(&r["refused"]["datagrams"]), 0, "the robot was refused: {r:#}");
        assert_eq!(u(&r["received"]), sent, "{r:#}");
        assert_eq!(back.len() as u64, sent, "the console got every reply: {r:#}");
        assert!(back.iter().all(|b| *b == feedback));
    }
}
