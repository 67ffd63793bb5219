//! Clients nobody here wrote, through the bridge in raw mode: `sockperf`
//! ping-pong (Normal, the return path relaying the replies) and `iperf3 -u`
//! (PLM-2 and Bernoulli 30%), on loopback. Each client binds a port of its
//! own, which the emulator is given as the console's (`--console-from`).
//! Each test skips, saying why, where its tool is not installed (Debian
//! packages `sockperf`, `iperf3`; `.ci/run` installs them), and fails
//! instead where `NETFI_REQUIRE_SOCKPERF=1` or `NETFI_REQUIRE_IPERF3=1`
//! says it must run.
//!
//! Latency is printed, never asserted (the machine is shared and noisy);
//! counts are asserted exactly: what iperf3 says it lost is what netfi says
//! it dropped.

use super::bridge::{free_udp_port, u, Emulator, Reaped};
use crate::common::machine;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Whether `tool` runs here; prints why a test skips if not, and fails
/// where `NETFI_REQUIRE_<TOOL>=1` asks for it.
fn have(tool: &str) -> bool {
    let ok = Command::new(tool).arg("--version").stdout(Stdio::null()).stderr(Stdio::null()).status().is_ok();
    let require = format!("NETFI_REQUIRE_{}", tool.to_ascii_uppercase());
    if !ok {
        assert!(std::env::var(&require).as_deref() != Ok("1"), "{require}=1 but `{tool}` is not installed (Debian package `{tool}`)");
        eprintln!("skipping: `{tool}` is not installed (Debian package `{tool}`; .ci/run installs it)");
    }
    ok
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("netfi-tools-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Whether a socket of `proto` (`udp`, `tcp`) is bound to local `port`
/// (any address, IPv4 or IPv6), from `/proc/net/*`.
fn port_bound(proto: &str, port: u16) -> bool {
    let needle = format!(":{port:04X} ");
    [format!("/proc/net/{proto}"), format!("/proc/net/{proto}6")]
        .iter()
        .filter_map(|p| std::fs::read_to_string(p).ok())
        .any(|t| {
            t.lines()
                .skip(1)
                .any(|l| l.split_whitespace().nth(1).is_some_and(|local| format!("{local} ").ends_with(&needle)))
        })
}

fn wait_bound(proto: &str, port: u16, child: &mut Child, what: &str) {
    let t0 = Instant::now();
    while !port_bound(proto, port) {
        assert!(child.try_wait().unwrap().is_none(), "{what} ended before binding {proto} port {port}");
        assert!(t0.elapsed() < Duration::from_secs(10), "{what} did not bind {proto} port {port} in 10 s");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Runs `cmd` to the end, killing it after `timeout`.
fn run_bounded(cmd: &mut Command, timeout: Duration) -> Output {
    let mut child = cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > timeout {
            let _ = child.kill();
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    child.wait_with_output().unwrap()
}

/// sockperf's summary: (sent, received, p50 µs, p99 µs).
fn sockperf_summary(text: &str) -> (u64, u64, f64, f64) {
    let num_after = |text: &str, key: &str| -> Option<f64> {
        let at = text.find(key)? + key.len();
        text[at..]
            .trim_start_matches([' ', '='])
            .split(|c: char| !(c.is_ascii_digit() || c == '.'))
            .next()?
            .parse()
            .ok()
    };
    let valid = text.find("[Valid Duration]").map_or(text, |i| &text[i..]);
    let sent = num_after(valid, "SentMessages=").unwrap_or(0.0) as u64;
    let received = num_after(valid, "ReceivedMessages=").unwrap_or(0.0) as u64;
    let p50 = num_after(text, "percentile 50.000").unwrap_or(f64::NAN);
    let p99 = num_after(text, "percentile 99.000").unwrap_or(f64::NAN);
    (sent, received, p50, p99)
}

#[test]
fn sockperf_ping_pong_through_the_bridge() {
    if !have("sockperf") {
        return;
    }
    let _guard = machine::alone();
    let out = out_dir("sockperf");
    let server_port = free_udp_port();
    let server = Command::new("sockperf")
        .args(["server", "-i", "127.0.0.1", "-p", &server_port.to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut server = Reaped(server);
    wait_bound("udp", server_port, &mut server.0, "sockperf server");
    // The client's own port, so the emulator can be told it is the console.
    let client_port = free_udp_port();
    let ping = |port: u16| {
        let o = run_bounded(
            Command::new("sockperf").args([
                "ping-pong",
                "-i",
                "127.0.0.1",
                "-p",
                &port.to_string(),
                "--client_ip",
                "127.0.0.1",
                "--client_port",
                &client_port.to_string(),
                "-t",
                "2",
                "-m",
                "64",
                "--full-rtt",
            ]),
            Duration::from_secs(30),
        );
        let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
        assert!(o.status.success(), "sockperf ping-pong failed:\n{text}");
        sockperf_summary(&text)
    };
    let direct = ping(server_port);
    let egress = format!("udp://127.0.0.1:{server_port}");
    let console = format!("127.0.0.1:{client_port}");
    let emu = Emulator::bridge(&out, "Normal", "1", &console, &egress, &["--payload", "raw"]);
    let through = ping(emu.ingress().port());
    let (e, udp) = emu.stop();
    eprintln!(
        "sockperf ping-pong, 64 B, full round trip: direct p50 {:.3} µs p99 {:.3} µs; through netfi (raw, Normal) p50 {:.3} µs p99 {:.3} µs; added p50 {:.3} µs",
        direct.2,
        direct.3,
        through.2,
        through.3,
        through.2 - direct.2
    );
    assert!(direct.1 > 0 && through.1 > 0, "{direct:?} {through:?}");
    // Nothing is lost under Normal: every ping entered and was delivered,
    // every reply came back through the return path.
    let f = &e["frames"];
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + u(&f["held_at_end"]), "{f}");
    assert_eq!(u(&udp["ingress_kernel_drops"]), 0);
    let r = &udp["return_path"];
    assert_eq!(u(&r["unroutable"]), 0, "{r}");
    assert_eq!(u(&r["delivered"]), u(&r["entered"]), "{r}");
    assert!(
        u(&r["delivered"]) >= through.1,
        "sockperf received {} replies, the return path relayed {}",
        through.1,
        r["delivered"]
    );
}

/// The first seed from 1 whose scenario passes frame 0: iperf3 opens a UDP
/// test with one hello datagram (and a reply) and waits for it without a
/// timeout, so that one must get through.
fn seed_passing_the_first_datagram(spec: &netfi::scenario::ScenarioSpec) -> u64 {
    (1..1000)
        .find(|s| {
            let mut sc = netfi::scenario::Scenario::new(spec, *s).unwrap();
            matches!(sc.decide(0, 0), netfi::scenario::Decision::Pass { .. })
        })
        .expect("some seed passes the first frame")
}

/// iperf3 `-u` through the bridge: `-k` datagrams from client to server on
/// the emulator's ingress `127.0.0.2:P`, relayed to the server's wildcard
/// socket on `127.0.0.1:P` (the TCP control connection goes to the server
/// directly). Returns the client's JSON, `emulator.json`, `udp.json`.
fn iperf3_through(name: &str, scenario: &str, seed: u64, datagrams: u64) -> (Value, Value, Value, PathBuf) {
    let out = out_dir(name);
    let port = free_tcp_and_udp_port();
    let server = Command::new("iperf3")
        .args(["-s", "-1", "-p", &port.to_string()])
        .stdout(std::fs::File::create(out.join("iperf3-server.log")).unwrap())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut server = Reaped(server);
    wait_bound("tcp", port, &mut server.0, "iperf3 server");
    let ingress = format!("udp://127.0.0.2:{port}");
    let egress = format!("udp://127.0.0.1:{port}");
    let expected = (datagrams + 1).to_string();
    // The client's UDP test socket, bound where the emulator is told the
    // console is.
    let client_port = free_udp_port();
    let console = format!("127.0.0.1:{client_port}");
    let emu = Emulator::start(
        &out,
        &[
            "--scenario",
            scenario,
            "--seed",
            &seed.to_string(),
            "--payload",
            "raw",
            "--ingress",
            &ingress,
            "--console-from",
            &console,
            "--egress",
            &egress,
            "--expected-frames",
            &expected,
        ],
    );
    let o = run_bounded(
        Command::new("iperf3").args([
            "-c",
            "127.0.0.2",
            "-p",
            &port.to_string(),
            "-B",
            "127.0.0.1",
            "--cport",
            &client_port.to_string(),
            "-u",
            "-b",
            "20M",
            "-l",
            "1000",
            "-k",
            &datagrams.to_string(),
            "--json",
        ]),
        Duration::from_secs(60),
    );
    // The last datagrams may still be on their way (or held).
    std::thread::sleep(Duration::from_millis(200));
    let (e, udp) = emu.stop();
    let client: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|err| {
        panic!(
            "iperf3 client printed no JSON ({err}):\n{}\n{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        )
    });
    assert!(o.status.success(), "iperf3 client failed: {}", client["error"]);
    (client, e, udp, out)
}

/// A port free for both UDP and TCP (IPv4, and IPv6 where there is IPv6),
/// as far as one can tell.
fn free_tcp_and_udp_port() -> u16 {
    let free_v6 = |p: u16| match std::net::TcpListener::bind(("::", p)) {
        Ok(_) => true,
        Err(e) => e.kind() != std::io::ErrorKind::AddrInUse,
    };
    (0..100)
        .map(|_| free_udp_port())
        .find(|p| std::net::TcpListener::bind(("0.0.0.0", *p)).is_ok() && free_v6(*p))
        .expect("no free port in 100 tries")
}

/// Of the datagrams with ingress index `1..=last` (the hello is index 0 and
/// iperf3 numbers its datagrams from 1 in the order netfi takes them), how
/// many netfi's trace says it dropped.
fn drops_in_trace(trace: &Path, last: u64) -> u64 {
    let text = std::fs::read_to_string(trace).unwrap();
    text.lines()
        .skip(1)
        .filter(|l| l.split(',').next().and_then(|i| i.parse::<u64>().ok()).is_some_and(|i| (1..=last).contains(&i)))
        .filter(|l| l.split(',').nth(5) == Some("dropped"))
        .count() as u64
}

/// iperf3's server counts a loss from a gap in its sequence numbers, up to
/// the highest number it saw before the client's end of test reached it over
/// TCP (datagrams still in flight then are not counted). So its `packets` is
/// that highest number P, and its `lost_packets` must equal what netfi
/// dropped among datagrams 1..=P, exactly.
fn check_iperf3_loss(label: &str, client: &Value, e: &Value, udp: &Value, out: &Path, datagrams: u64) {
    let recv = &client["end"]["sum_received"];
    assert!(recv.is_object(), "iperf3 gave no receiver summary: {}", client["end"]);
    let (lost, highest, bytes) = (u(&recv["lost_packets"]), u(&recv["packets"]), u(&recv["bytes"]));
    let f = &e["frames"];
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&udp["ingress_kernel_drops"]), 0, "the kernel dropped datagrams before the emulator: {udp}");
    // The hello datagram, then the test's datagrams.
    assert_eq!(u(&f["entered"]), datagrams + 1, "{f}");
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + dropped + u(&f["held_at_end"]), "{f}");
    assert_eq!(drops_in_trace(&out.join("trace_emulator.csv"), datagrams), dropped, "the hello datagram passed");
    assert!(highest <= datagrams && highest > datagrams / 2, "iperf3 counted up to {highest} of {datagrams}");
    let netfi_lost = drops_in_trace(&out.join("trace_emulator.csv"), highest);
    assert_eq!(lost, netfi_lost, "iperf3 lost {lost} of datagrams 1..={highest}; netfi dropped {netfi_lost} of them");
    assert_eq!(bytes, (highest - lost) * 1000, "iperf3 received every datagram it did not count as lost");
    let [lo, hi] = [e["loss_rate_ci95"][0].as_f64().unwrap(), e["loss_rate_ci95"][1].as_f64().unwrap()];
    let exact = e["stages"][0]["loss_rate_model"].as_f64().unwrap();
    let iperf_rate = lost as f64 / highest as f64;
    eprintln!(
        "{label}: iperf3 lost {lost} of {highest} ({:.2}%); netfi dropped {netfi_lost} of the same, {dropped} of {} in all \
         (loss {:.4}, 95% CI [{lo:.4}, {hi:.4}]); model {exact:.4}",
        100.0 * iperf_rate,
        u(&f["entered"]),
        e["loss_rate"].as_f64().unwrap(),
    );
    assert!(lo <= exact && exact <= hi, "model {exact} outside netfi's interval [{lo}, {hi}]");
    assert!(lo <= iperf_rate && iperf_rate <= hi, "iperf3's {iperf_rate} outside netfi's interval [{lo}, {hi}]");
}

#[test]
fn iperf3_udp_loss_matches_netfi_under_plm2() {
    if !have("iperf3") {
        return;
    }
    let _guard = machine::alone();
    let seed = seed_passing_the_first_datagram(&netfi::load::resolve("PLM-2").unwrap());
    let n = 5000;
    let (client, e, udp, out) = iperf3_through("iperf3-plm2", "PLM-2", seed, n);
    check_iperf3_loss("PLM-2", &client, &e, &udp, &out, n);
    // ge_lomax decides per datagram: the same seed in simulated time drops
    // the same number.
    let o = Command::new(env!("CARGO_BIN_EXE_netfi"))
        .args(["scenario", "check", "PLM-2", "--frames", &(n + 1).to_string(), "--seed", &seed.to_string(), "--json"])
        .output()
        .unwrap();
    let c: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(c["dropped"]["ge_lomax"], e["frames"]["dropped"]["ge_lomax"]);
}

#[test]
fn iperf3_udp_loss_matches_netfi_under_bernoulli_30() {
    if !have("iperf3") {
        return;
    }
    let _guard = machine::alone();
    let text = "name = \"bernoulli 30%\"\n\n[[stage]]\nmodel = \"bernoulli\"\np = \"30%\"\n";
    let spec = netfi::scenario::parse_str(text, "bernoulli30.toml", "bernoulli 30%").unwrap();
    let seed = seed_passing_the_first_datagram(&spec);
    let dir = out_dir("bernoulli-scenario");
    let file = dir.join("bernoulli30.toml");
    std::fs::write(&file, text).unwrap();
    let n = 5000;
    let (client, e, udp, out) = iperf3_through("iperf3-bernoulli", file.to_str().unwrap(), seed, n);
    check_iperf3_loss("bernoulli 30%", &client, &e, &udp, &out, n);
}
