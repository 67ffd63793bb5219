//! The emulator's UDP bridge on loopback: UDP → UDP, UDP → iceoryx2 and
//! iceoryx2 → UDP with exact conservation; malformed and garbage datagrams;
//! raw mode; the return path, untouched and shaped.
//!
//! The test plays the console and the robot with its own sockets. Every run
//! is short, and runs are serialized (one busy-waiting emulator at a time).
//! Conservation is checked including what
//! the kernel dropped: `sent = entered + kernel drops at the ingress`, and
//! `delivered = received by the robot + kernel drops at the robot`.

use crate::common::netfi::netfi;
use crate::common::machine;
use netfi::frame::ItpView;
use netfi::transport::udp::{PeerAddr, UdpOptions, UdpPort};
use serde_json::Value;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub(crate) fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("netfi-udp-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub(crate) fn read_json(path: &Path) -> Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[track_caller]
pub(crate) fn u(v: &Value) -> u64 {
    match v.as_u64() {
        Some(n) => n,
        None => panic!("not a count: {v}"),
    }
}

fn dropped_total(frames: &Value) -> u64 {
    frames["dropped"].as_object().unwrap().values().map(u).sum()
}

/// A valid ITP frame with sequence `seq`.
pub(crate) fn itp(seq: u32) -> [u8; 124] {
    let mut b = [0u8; 124];
    let mut v = ItpView::new_unchecked(&mut b[..]);
    v.set_sequence(seq);
    v.set_delx([(seq % 7) as i32, 1]);
    v.set_dely([2, -((seq % 5) as i32)]);
    v.set_qw([1.0, 1.0]);
    v.set_surgeon_mode(1);
    v.fill_checksum();
    b
}

/// A UDP port that was free on loopback a moment ago.
pub(crate) fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

pub(crate) fn socket() -> UdpPort {
    UdpPort::bind("127.0.0.1:0".parse().unwrap(), &UdpOptions { reuse_address: false, buffer_bytes: Some(4 << 20) })
        .unwrap()
}

/// Sends `datagrams`, pausing 1 ms every `burst` of them so the emulator
/// (which may share its core) keeps up without the kernel dropping any.
pub(crate) fn send_paced(from: &UdpPort, to: SocketAddr, datagrams: impl IntoIterator<Item = Vec<u8>>, burst: usize) -> u64 {
    let to = PeerAddr::new(to);
    let mut n = 0u64;
    for d in datagrams {
        loop {
            match from.send_to(&d, &to) {
                Ok(()) => break,
                // Our own send buffer is full: wait for it to drain.
                Err(netfi::transport::udp::UdpSendError::WouldBlock { .. }) => {
                    std::thread::sleep(Duration::from_micros(200))
                }
                Err(e) => panic!("{e}"),
            }
        }
        n += 1;
        if n % burst as u64 == 0 {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    n
}

/// A thread that receives on `port` until `stop` is set and nothing more
/// arrives for 200 ms (at most 60 s), answering each datagram with `reply`
/// (if given) to its source; returns what it received.
pub(crate) fn receiver(port: UdpPort, stop: Arc<AtomicBool>, reply: Option<Vec<u8>>) -> JoinHandle<(Vec<Vec<u8>>, UdpPort)> {
    std::thread::spawn(move || {
        let mut got = Vec::new();
        let mut buf = vec![0u8; 1 << 16];
        let t0 = Instant::now();
        let mut last = Instant::now();
        loop {
            match port.recv_from(&mut buf).unwrap() {
                Some(d) => {
                    got.push(buf[..d.len].to_vec());
                    if let Some(r) = &reply {
                        port.send_to(r, &PeerAddr::new(d.from)).unwrap();
                    }
                    last = Instant::now();
                }
                None => {
                    if stop.load(Ordering::Acquire) && last.elapsed() > Duration::from_millis(200) {
                        break;
                    }
                    if t0.elapsed() > Duration::from_secs(60) {
                        break;
                    }
                    std::thread::sleep(Duration::from_micros(100));
                }
            }
        }
        (got, port)
    })
}

/// The two ends of a bridge on loopback: the robot, collecting what
/// reaches it (`robot`) until `stop` is set, and the console's socket.
pub(crate) struct Ends {
    pub(crate) console: UdpPort,
    /// The console's address, for `--console-from`.
    pub(crate) from: String,
    /// The robot's address, for `--egress`.
    pub(crate) egress: String,
    pub(crate) stop: Arc<AtomicBool>,
    pub(crate) robot: JoinHandle<(Vec<Vec<u8>>, UdpPort)>,
}

/// A robot that collects what reaches it, and a console socket.
pub(crate) fn ends() -> Ends {
    ends_answering(None)
}

/// A robot that collects what reaches it and answers each datagram with
/// `reply` (if any), and a console socket.
fn ends_answering(reply: Option<Vec<u8>>) -> Ends {
    let robot = socket();
    let egress = format!("udp://{}", robot.local_addr());
    let stop = Arc::new(AtomicBool::new(false));
    let robot = receiver(robot, stop.clone(), reply);
    let console = socket();
    let from = console.local_addr().to_string();
    Ends { console, from, egress, stop, robot }
}

/// A child process killed (if still running) when dropped, so a failing
/// test leaves nothing behind.
pub(crate) struct Reaped(pub(crate) Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// One emulator process.
pub(crate) struct Emulator {
    child: Option<Child>,
    out: PathBuf,
}

impl Emulator {
    /// Starts `netfi emulator` with `args` and waits until it is ready.
    pub(crate) fn start(out: &Path, args: &[&str]) -> Emulator {
        let mut cmd = netfi();
        cmd.arg("emulator");
        Emulator::start_command(cmd, out, args)
    }

    /// Starts a UDP bridge: `netfi emulator` applying `scenario` with
    /// `seed`, taking the console's datagrams from `console_from` on an
    /// ephemeral port and sending to `egress`, with `extra` flags.
    pub(crate) fn bridge(out: &Path, scenario: &str, seed: &str, console_from: &str, egress: &str, extra: &[&str]) -> Emulator {
        let mut args = vec!["--scenario", scenario, "--seed", seed, "--ingress", "udp://127.0.0.1:0", "--console-from", console_from, "--egress", egress];
        args.extend_from_slice(extra);
        Emulator::start(out, &args)
    }

    /// Starts `cmd` (which runs `netfi emulator`, perhaps through a wrapper
    /// such as `ip netns exec`) with `args`, and waits until it is ready.
    pub(crate) fn start_command(mut cmd: Command, out: &Path, args: &[&str]) -> Emulator {
        let log = std::fs::File::create(out.join("emulator.log")).unwrap();
        let child = cmd
            .args(args)
            .arg("--out")
            .arg(out)
            .stdin(Stdio::null())
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .spawn()
            .unwrap();
        let mut e = Emulator { child: Some(child), out: out.to_path_buf() };
        let t0 = Instant::now();
        while !out.join("emulator.ready").exists() {
            if let Some(s) = e.child.as_mut().unwrap().try_wait().unwrap() {
                panic!("the emulator ended before it was ready ({s}):\n{}", e.log());
            }
            assert!(t0.elapsed() < Duration::from_secs(30), "the emulator was not ready in 30 s:\n{}", e.log());
            std::thread::sleep(Duration::from_millis(5));
        }
        e
    }

    /// The emulator's pid.
    pub(crate) fn pid(&self) -> u32 {
        self.child.as_ref().unwrap().id()
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.out.join("emulator.log")).unwrap_or_default()
    }

    fn endpoints(&self) -> Value {
        read_json(&self.out.join("udp_endpoints.json"))
    }

    pub(crate) fn ingress(&self) -> SocketAddr {
        self.endpoints()["ingress"].as_str().unwrap().parse().unwrap()
    }

    pub(crate) fn egress_local(&self) -> SocketAddr {
        self.endpoints()["egress_local"].as_str().unwrap().parse().unwrap()
    }

    /// Waits for the emulator to end by itself (at most `timeout`, then
    /// SIGTERM), and returns `emulator.json` and `udp.json`.
    pub(crate) fn finish(mut self, timeout: Duration) -> (Value, Value) {
        let mut child = self.child.take().unwrap();
        let t0 = Instant::now();
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            if t0.elapsed() > timeout {
                // SAFETY: signalling a process this test started.
                unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
                break child.wait().unwrap();
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        assert!(status.success(), "the emulator failed ({status}):\n{}", self.log());
        (read_json(&self.out.join("emulator.json")), read_json(&self.out.join("udp.json")))
    }

    /// SIGTERM now; returns the reports.
    pub(crate) fn stop(self) -> (Value, Value) {
        // SAFETY: signalling a process this test started.
        unsafe { libc::kill(self.child.as_ref().unwrap().id() as libc::pid_t, libc::SIGTERM) };
        self.finish(Duration::from_secs(20))
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// entered = delivered + dropped + held_at_end.
fn assert_balanced(e: &Value) {
    let f = &e["frames"];
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + dropped_total(f) + u(&f["held_at_end"]), "{f}");
}

/// The ingress side: every datagram sent entered or was dropped by the kernel.
/// The account closes ([`assert_balanced`]) and every datagram sent entered
/// ([`assert_all_entered`]).
fn assert_accounted(e: &Value, udp: &Value, sent: u64) {
    assert_balanced(e);
    assert_all_entered(e, udp, sent);
}

fn assert_all_entered(e: &Value, udp: &Value, sent: u64) {
    let kernel = u(&udp["ingress_kernel_drops"]);
    assert_eq!(u(&e["frames"]["entered"]) + kernel, sent, "{udp}");
    assert_eq!(u(&udp["datagrams_in"]), u(&e["frames"]["entered"]));
    if kernel > 0 {
        eprintln!("note: the kernel dropped {kernel} datagrams at the emulator's ingress (counted, not entered)");
    }
}

#[test]
fn udp_to_udp_conserves_every_frame_and_realizes_plm2() {
    let _guard = machine::alone();
    let out = out_dir("u2u");
    let (console, robot) = (socket(), socket());
    let robot_addr = robot.local_addr().to_string();
    let egress = format!("udp://{robot_addr}");
    let from = console.local_addr().to_string();
    let n = 3000u32;
    let emu = Emulator::bridge(&out, "PLM-2", "3", &from, &egress, &["--idle-end-ms", "1000", "--expected-frames", "3000"]);
    let stop = Arc::new(AtomicBool::new(false));
    let rx = receiver(robot, stop.clone(), None);
    let sent = send_paced(&console, emu.ingress(), (0..n).map(|i| itp(i).to_vec()), 20);
    let (e, udp) = emu.finish(Duration::from_secs(30));
    stop.store(true, Ordering::Release);
    let (got, robot) = rx.join().unwrap();

    assert_eq!(e["ended_by"], "end_marker", "the idle end closes the stream");
    assert_accounted(&e, &udp, sent);
    assert_eq!(u(&e["frames"]["held_at_end"]), 0);
    let delivered = u(&e["frames"]["delivered"]);
    assert_eq!(got.len() as u64 + robot.kernel_drops().unwrap(), delivered, "the robot got what was released");
    assert!(got.iter().all(|d| d.len() == 124 && ItpView::new_unchecked(&d[..]).verify_checksum()));
    // Survivors keep their order (no delay stage) and their bytes.
    let seqs: Vec<u32> = got.iter().map(|d| ItpView::new_unchecked(&d[..]).sequence()).collect();
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "order kept");
    for (d, s) in got.iter().zip(&seqs) {
        assert_eq!(d[..], itp(*s), "bytes kept");
    }
    assert_eq!(udp["console"].as_str().unwrap(), console.local_addr().to_string());

    // ge_lomax decides per frame: the frames that entered (every one, but
    // those the kernel dropped at the ingress) meet the very drops
    // `scenario check` makes for as many frames in simulated time.
    let entered = u(&e["frames"]["entered"]).to_string();
    let o = netfi().args(["scenario", "check", "PLM-2", "--frames", &entered, "--seed", "3", "--json"]).output().unwrap();
    let c: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(c["dropped"]["ge_lomax"], e["frames"]["dropped"]["ge_lomax"], "{entered} of {n} entered");
    let exact = e["stages"][0]["loss_rate_model"].as_f64().unwrap();
    let [lo, hi] = [e["loss_rate_ci95"][0].as_f64().unwrap(), e["loss_rate_ci95"][1].as_f64().unwrap()];
    assert!(lo <= exact && exact <= hi, "model {exact} outside [{lo}, {hi}]");
    // The trace has a row per datagram.
    let trace = std::fs::read_to_string(out.join("trace_emulator.csv")).unwrap();
    assert_eq!(trace.lines().count() as u64 - 1, u(&e["frames"]["entered"]));
}

#[test]
fn udp_to_iceoryx2_feeds_the_simulator() {
    let _guard = machine::alone();
    let out = out_dir("u2i");
    let run_id = format!("u2i{}", std::process::id());
    let sim_log = std::fs::File::create(out.join("simulator.log")).unwrap();
    let mut sim = Reaped(
        netfi()
            .args(["simulator", "--run-id", &run_id, "--out"])
            .arg(&out)
            .stdout(sim_log.try_clone().unwrap())
            .stderr(sim_log)
            .spawn()
            .unwrap(),
    );
    let sim = &mut sim.0;
    let t0 = Instant::now();
    while !out.join("simulator.ready").exists() {
        assert!(sim.try_wait().unwrap().is_none(), "the simulator ended early");
        assert!(t0.elapsed() < Duration::from_secs(30), "the simulator was not ready");
        std::thread::sleep(Duration::from_millis(5));
    }
    let console = socket();
    let from = console.local_addr().to_string();
    let emu = Emulator::bridge(&out, "PLM-1", "8", &from, "iceoryx2", &["--run-id", &run_id, "--idle-end-ms", "1000"]);
    let sent = send_paced(&console, emu.ingress(), (0..1500).map(|i| itp(i).to_vec()), 20);
    let (e, udp) = emu.finish(Duration::from_secs(30));
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = sim.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > Duration::from_secs(20) {
            let _ = sim.kill();
            panic!("the simulator did not end after the emulator's end marker");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    assert!(status.success());
    let s = read_json(&out.join("simulator.json"));
    assert_accounted(&e, &udp, sent);
    assert!(dropped_total(&e["frames"]) > 0, "PLM-1 drops some of 1500 frames");
    assert_eq!(u(&s["received"]), u(&e["frames"]["delivered"]), "the simulator got every released frame");
    assert_eq!(s["released_by_emulator"], e["frames"]["delivered"]);
    assert_eq!(u(&s["bad_checksum"]), 0);
    assert_eq!(u(&s["wrong_size"]), 0);
}

#[test]
fn iceoryx2_to_udp_drives_a_udp_robot() {
    let _guard = machine::alone();
    let out = out_dir("i2u");
    let run_id = format!("i2u{}", std::process::id());
    let robot = socket();
    let egress = format!("udp://{}", robot.local_addr());
    let stop = Arc::new(AtomicBool::new(false));
    let rx = receiver(robot, stop.clone(), None);
    let emu = Emulator::start(
        &out,
        &["--run-id", &run_id, "--scenario", "DLM-1", "--seed", "9", "--ingress", "iceoryx2", "--egress", &egress],
    );
    let con = netfi()
        .args([
            "console",
            "--run-id",
            &run_id,
            "--frames",
            "2000",
            "--rate-hz",
            "5000",
            "--seed",
            "9",
            "--no-direct",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(con.status.success(), "console: {}", String::from_utf8_lossy(&con.stderr));
    let (e, udp) = emu.finish(Duration::from_secs(30));
    stop.store(true, Ordering::Release);
    let (got, robot) = rx.join().unwrap();
    assert_eq!(e["ended_by"], "end_marker");
    assert_balanced(&e);
    assert_eq!(u(&e["frames"]["sent_by_console"]), 2000);
    assert_eq!(u(&e["frames"]["entered"]), 2000);
    assert_eq!(u(&e["frames"]["delivered"]), 2000, "DLM-1 only delays");
    assert_eq!(got.len() as u64 + robot.kernel_drops().unwrap(), 2000);
    assert!(got.iter().all(|d| d.len() == 124 && ItpView::new_unchecked(&d[..]).verify_checksum()));
    assert!(udp["ingress_local"].is_null());
    // Delays of 70 ms and more reorder frames at 5 kHz.
    let seqs: Vec<u32> = got.iter().map(|d| ItpView::new_unchecked(&d[..]).sequence()).collect();
    assert!(seqs.windows(2).any(|w| w[0] > w[1]), "DLM-1 reorders");
}

#[test]
fn wrong_sizes_and_checksums_are_counted_then_dropped_or_passed() {
    let _guard = machine::alone();
    let bad = |i: u32| {
        let mut f = itp(i);
        f[12] ^= 0x5a; // delx[0] changed after sealing
        f.to_vec()
    };
    let mut datagrams: Vec<Vec<u8>> = (0..10).map(|i| itp(i).to_vec()).collect();
    datagrams.extend([vec![], vec![1u8; 100], vec![2u8; 123], vec![3u8; 125], vec![4u8; 4000]]);
    datagrams.extend((10..14).map(bad));
    for drop_bad in [true, false] {
        let out = out_dir(if drop_bad { "bad-drop" } else { "bad-pass" });
        let Ends { console, from, egress, stop, robot: rx } = ends();
        let extra: &[&str] = if drop_bad { &["--idle-end-ms", "1000", "--drop-bad-checksum"] } else { &["--idle-end-ms", "1000"] };
        let emu = Emulator::bridge(&out, "Normal", "1", &from, &egress, extra);
        let sent = send_paced(&console, emu.ingress(), datagrams.clone(), 5);
        let (e, udp) = emu.finish(Duration::from_secs(30));
        stop.store(true, Ordering::Release);
        let (got, _) = rx.join().unwrap();
        assert_accounted(&e, &udp, sent);
        let f = &e["frames"];
        assert_eq!(u(&f["dropped"]["wrong_size"]), 5, "{f}");
        // The loss figure is the scenario's (Normal: none): the malformed
        // frames never reached it.
        assert_eq!((e["loss_rate"].as_f64(), e["loss_rate_ci95"][0].as_f64()), (Some(0.0), Some(0.0)), "{e:#}");
        if drop_bad {
            assert_eq!(u(&f["dropped"]["bad_checksum"]), 4, "{f}");
            assert_eq!(u(&f["delivered"]), 10);
            assert_eq!(got.len(), 10);
        } else {
            assert!(f["dropped"].get("bad_checksum").is_none(), "{f}");
            assert_eq!(u(&f["bad_checksum_passed"]), 4);
            assert_eq!(u(&f["delivered"]), 14);
            assert_eq!(got.iter().filter(|d| !ItpView::new_unchecked(&d[..]).verify_checksum()).count(), 4);
        }
        // The trace names the reason of each drop.
        let trace = std::fs::read_to_string(out.join("trace_emulator.csv")).unwrap();
        assert_eq!(trace.lines().filter(|l| l.contains(",dropped,wrong_size,")).count(), 5);
    }
}

#[test]
fn a_flood_of_garbage_is_counted_and_the_emulator_stays_up() {
    let _guard = machine::alone();
    let out = out_dir("flood");
    let Ends { console, from, egress, stop, robot: rx } = ends();
    let emu = Emulator::bridge(&out, "Normal", "1", &from, &egress, &["--drop-bad-checksum", "--idle-end-ms", "1000"]);
    // 20,000 datagrams of random bytes and sizes (0..=1500), as fast as the
    // socket takes them: the kernel may drop some at the emulator's ingress,
    // and must count them.
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let garbage: Vec<Vec<u8>> = (0..20_000)
        .map(|_| {
            let len = (next() % 1501) as usize;
            (0..len).map(|_| next() as u8).collect()
        })
        .collect();
    let garbage_124 = garbage.iter().filter(|g| g.len() == 124).count() as u64;
    let flood = send_paced(&console, emu.ingress(), garbage, usize::MAX);
    std::thread::sleep(Duration::from_millis(100));
    // Then real frames: the emulator still delivers.
    let valid = send_paced(&console, emu.ingress(), (0..100).map(|i| itp(i).to_vec()), 10);
    let (e, udp) = emu.finish(Duration::from_secs(30));
    stop.store(true, Ordering::Release);
    let (got, _) = rx.join().unwrap();
    assert_accounted(&e, &udp, flood + valid);
    let f = &e["frames"];
    let entered = u(&f["entered"]);
    let bad_checksum = f["dropped"].get("bad_checksum").map_or(0, u);
    assert_eq!(u(&f["dropped"]["wrong_size"]) + bad_checksum + u(&f["delivered"]), entered, "{f}");
    assert!(bad_checksum <= garbage_124);
    assert_eq!(u(&f["delivered"]), 100, "only the real frames pass: {f}");
    assert_eq!(got.len(), 100);
    assert_eq!(u(&e["receive_errors"]), 0);
}

#[test]
fn raw_mode_forwards_any_datagram_and_the_return_path_relays_untouched() {
    let _guard = machine::alone();
    let out = out_dir("raw");
    // The robot answers each datagram with a 52-byte feedback frame.
    let feedback: Vec<u8> = (0..52u8).collect();
    let Ends { console, from, egress, stop, robot: rx } = ends_answering(Some(feedback.clone()));
    let replies = receiver(console.try_clone().unwrap(), stop.clone(), None);
    let emu = Emulator::bridge(&out, "Normal", "1", &from, &egress, &["--payload", "raw", "--idle-end-ms", "1000"]);
    let mut datagrams: Vec<Vec<u8>> =
        vec![vec![], vec![0xab], vec![7u8; 1000], (0..60_000u32).map(|i| i as u8).collect()];
    datagrams.extend((0..500u32).map(|i| i.to_le_bytes().repeat(16)));
    let sent = send_paced(&console, emu.ingress(), datagrams.clone(), 10);
    let (e, udp) = emu.finish(Duration::from_secs(30));
    stop.store(true, Ordering::Release);
    let (got, _) = rx.join().unwrap();
    let (back, _) = replies.join().unwrap();
    assert_accounted(&e, &udp, sent);
    assert_eq!(u(&e["frames"]["delivered"]), sent, "Normal delivers everything");
    assert_eq!(got, datagrams, "every datagram, byte for byte, in order");
    assert_eq!(udp["payload"], "raw");
    assert!(u(&udp["arena_high_water"]) >= 1 && u(&udp["arena_slots"]) == 4097, "{udp}");
    let r = &udp["return_path"];
    assert_eq!(r["mode"], "untouched");
    assert_eq!(u(&r["received"]), sent, "{r}");
    assert_eq!(u(&r["unroutable"]), 0, "the console is named: every reply has somewhere to go: {r}");
    assert_eq!(u(&r["entered"]), sent);
    assert_eq!(u(&r["delivered"]), sent);
    assert_eq!(u(&r["send_errors"]), 0);
    assert_eq!(back.len() as u64, sent, "the console got every reply");
    assert!(back.iter().all(|b| *b == feedback));
    // netfi's own time per datagram each way: each path's release lateness.
    let own = &udp["own_time_ns"];
    for (way, lateness) in [("forward", &e["release_lateness_ns"]), ("return", &r["release_lateness_ns"])] {
        assert_eq!(u(&own[way]["count"]), sent, "{way}: {own}");
        assert_eq!((&own[way]["p50"], &own[way]["p99"]), (&lateness["p50"], &lateness["p99"]), "{way}: {own}");
    }
}

#[test]
fn a_return_scenario_shapes_the_way_back() {
    let _guard = machine::alone();
    let out = out_dir("return");
    let scenario = out.join("return.toml");
    std::fs::write(
        &scenario,
        "name = \"return loss and delay\"\n\n[[stage]]\nmodel = \"bernoulli\"\np = 0.3\n\n[[stage]]\nmodel = \"delay\"\nmin_ms = 5\ndist = \"none\"\norder = \"fifo\"\n",
    )
    .unwrap();
    let Ends { console, from, egress, stop, robot: rx } = ends_answering(Some(vec![9u8; 52]));
    let replies = receiver(console.try_clone().unwrap(), stop.clone(), None);
    let emu = Emulator::bridge(&out, "Normal", "1", &from, &egress, &["--return-scenario", scenario.to_str().unwrap(), "--return-seed", "11", "--idle-end-ms", "400"]);
    let sent = send_paced(&console, emu.ingress(), (0..1000).map(|i| itp(i).to_vec()), 10);
    // Replies are held 5 ms on the way back: let the last ones arrive before
    // the forward stream's idle end stops the loop.
    let (e, udp) = emu.finish(Duration::from_secs(30));
    stop.store(true, Ordering::Release);
    let (got, _) = rx.join().unwrap();
    let (back, _) = replies.join().unwrap();
    assert_accounted(&e, &udp, sent);
    assert_eq!(got.len() as u64, sent);
    let r = &udp["return_path"];
    assert_eq!(r["mode"], "scenario");
    assert_eq!(u(&r["seed"]), 11);
    assert_eq!(u(&r["received"]), u(&r["entered"]) + u(&r["unroutable"]), "{r}");
    let dropped: u64 = r["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&r["entered"]), u(&r["delivered"]) + dropped + u(&r["held_at_end"]), "{r}");
    assert_eq!(u(&r["received"]), sent, "one reply per datagram: {r}");
    assert_eq!(back.len() as u64, u(&r["delivered"]), "the console got what the return path released");
    // 1000 Bernoulli(0.3) draws: 300 ± 5 standard deviations (72).
    let lost = u(&r["dropped"]["bernoulli"]);
    assert!((228..=372).contains(&lost), "{lost}");
    let [lo, hi] = [r["loss_rate_ci95"][0].as_f64().unwrap(), r["loss_rate_ci95"][1].as_f64().unwrap()];
    assert!(lo < hi && lo <= 0.3 + 0.1 && hi >= 0.3 - 0.1, "[{lo}, {hi}]");
    // Each delivered reply was held at least its 5 ms.
    assert!(r["injected_delay_ns"]["p50"].as_u64().unwrap() >= 5_000_000, "{r}");
    let trace = std::fs::read_to_string(out.join("trace_return.csv")).unwrap();
    assert_eq!(trace.lines().count() as u64 - 1, u(&r["entered"]));
}

#[test]
fn a_stopped_bridge_reports_what_it_held() {
    let _guard = machine::alone();
    let out = out_dir("held");
    let Ends { console, from, egress, stop, robot: rx } = ends();
    let emu = Emulator::bridge(&out, "DLM-2", "2", &from, &egress, &[]);
    let sent = send_paced(&console, emu.ingress(), (0..200).map(|i| itp(i).to_vec()), 20);
    std::thread::sleep(Duration::from_millis(50));
    // DLM-2 holds every frame 210 ms or more: stopped now, all are held.
    let (e, udp) = emu.stop();
    stop.store(true, Ordering::Release);
    let (got, _) = rx.join().unwrap();
    assert_eq!(e["ended_by"], "signal");
    assert_accounted(&e, &udp, sent);
    assert!(u(&e["frames"]["held_at_end"]) > 0, "{}", e["frames"]);
    assert_eq!(got.len() as u64, u(&e["frames"]["delivered"]));
}

#[test]
fn bad_udp_options_are_clear_errors() {
    for (args, expect) in [
        (vec!["--ingress", "tcp://127.0.0.1:5"], "expected `iceoryx2` or `udp://ADDR:PORT`"),
        (
            vec!["--ingress", "udp://127.0.0.1:0", "--egress", "iceoryx2", "--payload", "raw", "--run-id", "x"],
            "--payload raw needs UDP on both sides",
        ),
        (vec!["--ingress", "udp://127.0.0.1:0", "--egress", "iceoryx2"], "--run-id is needed"),
        (vec!["--ingress", "udp://127.0.0.1:0", "--egress", "udp://127.0.0.1:0"], "a port other than 0"),
        // No console named: a UDP ingress does not start, and says how to
        // name one.
        (
            vec!["--ingress", "udp://127.0.0.1:0", "--egress", "udp://127.0.0.1:9"],
            "give the console's address (--console-from ADDR:PORT) or pair with the first sender (--console-from first)",
        ),
    ] {
        let out = out_dir("bad-args");
        let o = netfi().args(["emulator", "--scenario", "Normal", "--out"]).arg(&out).args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(expect), "{args:?}: {err}");
    }
}
