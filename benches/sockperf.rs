//! A foreign tool through the UDP bridge: sockperf ping-pong (64-byte
//! messages), client and server on the bench core, first directly, then
//! through the minimal relay a lab would write instead of netfi (one thread
//! busy-polling two non-blocking sockets, relaying both ways, on the
//! emulator's core), then through `netfi emulator --payload raw` (Normal) on
//! its own core, the replies coming back through the return path. Added =
//! through − direct, percentile by percentile, in sockperf's unit (half the
//! round trip), split into the hop any relay adds (relay − direct) and
//! netfi's own part (netfi − relay).
//!
//! ```sh
//! cargo bench --bench sockperf                            # 10 s each way, 3 repetitions
//! cargo bench --bench sockperf -- --halt-poll-ns 200000   # with a VM's guest halt polling on
//! ```
//!
//! Needs `sockperf` (Debian: `apt install sockperf`). On a virtual machine
//! whose guest halt polling is off, every message a relay on another core
//! hands to a sleeping end wakes a halted vCPU through the hypervisor;
//! `--halt-poll-ns` sets it for the run and puts it back after.

#[path = "common/mod.rs"]
mod common;

use anyhow::{bail, ensure, Context, Result};
use common::args::{check_interrupted, stopped, Placement};
use common::host::{clear_core, pin, restore_core, HostTimer};
use common::out::Out;
use common::process::{read_json, Build, EmulatorSpec, OneBuild};
use common::table::{header, median_map, row, Map};
use netfi::service::args::EndsArgs;
use netfi::transport::udp::UdpArgs;
use netfi::transport::Payload;
use serde::Serialize;
use serde_json::{json, Value};
use std::io::ErrorKind;
use std::net::{SocketAddr, UdpSocket};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

const HALT_POLL_NS: &str = "/sys/module/haltpoll/parameters/guest_halt_poll_ns";

/// `cargo bench --bench sockperf -- [FLAGS]`.
#[derive(Debug, clap::Parser, Serialize)]
#[command(name = "sockperf", bin_name = "cargo bench --bench sockperf --", about = "sockperf ping-pong through the UDP bridge, against a direct run")]
struct Args {
    #[command(flatten)]
    #[serde(flatten)]
    build: OneBuild,
    /// Length of each ping-pong
    #[arg(long, default_value_t = 10)]
    seconds: u64,
    #[arg(long, default_value_t = 3)]
    repetitions: usize,
    /// Set the guest's halt polling to this for the run (put back after)
    #[arg(long, value_name = "NS")]
    halt_poll_ns: Option<u64>,
}

fn main() {
    common::args::main("sockperf", "sockperf through the UDP bridge (a minute)", run);
}

fn run(a: Args) -> Result<()> {
    ensure!(a.seconds >= 1 && a.repetitions >= 1, "--seconds and --repetitions must be at least 1");
    if Command::new("sockperf").arg("--version").stdout(Stdio::null()).stderr(Stdio::null()).status().is_err() {
        bail!("sockperf is not installed (Debian: apt install sockperf)");
    }
    let (p, out, build) = a.build.start("sockperf")?;
    let before = std::fs::read_to_string(HALT_POLL_NS).ok();
    if let Some(ns) = a.halt_poll_ns {
        std::fs::write(HALT_POLL_NS, ns.to_string()).with_context(|| format!("setting {HALT_POLL_NS}"))?;
    }
    let cleared = clear_core(&p);
    let reps: Result<Vec<Value>> = (0..a.repetitions).map(|rep| interval(&a, &p, &build, &out, rep)).collect();
    let (cleared, isolation) = restore_core(cleared);
    if let (Some(_), Some(b)) = (a.halt_poll_ns, &before) {
        let _ = std::fs::write(HALT_POLL_NS, b.trim());
    }
    let reps = reps?;
    let halt = before.and_then(|t| t.trim().parse::<u64>().ok());
    let maps = |k: &str| median_map(&reps.iter().filter_map(|v| serde_json::from_value::<Map>(v[k].clone()).ok()).collect::<Vec<_>>());
    let (direct, relay, via, added) = (maps("direct_ns"), maps("through_relay_ns"), maps("through_netfi_ns"), maps("added_ns"));
    let (hop, own) = (maps("hop_ns"), maps("netfi_own_ns"));
    let md = format!(
        "{}. {cleared} Guest halt polling {}. Median over {} repetitions of sockperf's latency (half the round trip); \
         the minimal relay is one thread busy-polling two non-blocking sockets on the emulator's core.\n\n{}\n{}\n{}\n{}\n{}\n{}\n{}\n",
        p.line(),
        a.halt_poll_ns.or(halt).map_or("not available".to_string(), |n| format!("{n} ns")),
        reps.len(),
        header("sockperf latency"),
        row("direct (client → server)", &direct),
        row("through the minimal relay (client → relay → server, and back)", &relay),
        row("through netfi (client → emulator → server, and back)", &via),
        row("**added** (netfi − direct)", &added),
        row("the hop any relay adds (relay − direct)", &hop),
        row("**netfi's own part** (netfi − relay)", &own)
    );
    let median = json!({"direct": direct, "through_relay": relay, "through_netfi": via, "added": added, "hop": hop, "netfi_own": own});
    out.finish(&a, json!({"placement": p, "isolation": isolation, "build": build, "guest_halt_poll_ns_before": halt, "median_ns": median, "repetitions": reps}), &md)
}

/// One repetition: the direct ping-pong, then the same through the
/// minimal relay, then through netfi.
fn interval(a: &Args, p: &Placement, build: &Build, out: &Out, rep: usize) -> Result<Value> {
    check_interrupted()?;
    let host = HostTimer::start(p.quiet);
    let port = std::net::UdpSocket::bind("127.0.0.1:0")?.local_addr()?.port();
    let dir = out.run_dir(&format!("sockperf-r{rep}"))?;
    let mut server = sockperf_on(p.bench_core, &["server", "-i", "127.0.0.1", "-p", &port.to_string()], &dir.join("server.log"))?;
    std::thread::sleep(Duration::from_millis(300));
    let result = (|| -> Result<Value> {
        let direct = ping_pong(p.bench_core, port, a.seconds, &dir.join("direct.log"))?;
        let relay = MinimalRelay::start(p.emulator_core, p.rt_priority, port)?;
        let through_relay = ping_pong(p.bench_core, relay.port, a.seconds, &dir.join("relay.log"));
        let relayed = relay.stop()?;
        let through_relay = through_relay?;
        let ends = EndsArgs { ingress: "udp://127.0.0.1:0".parse()?, egress: format!("udp://127.0.0.1:{port}").parse()?, idle_end_ms: None };
        let udp = UdpArgs { payload: Payload::Raw, console_from: Some("first".parse()?), ..UdpArgs::default() };
        let spec = EmulatorSpec { scenario: "Normal", dir: &dir, expected_frames: a.seconds * 200_000, run_id: None, feedback: false, queue_capacity: None, ends, udp, streams: 1 };
        let emu = build.emulator(&spec, p)?;
        let via = ping_pong(p.bench_core, emu.udp_ingress()?.port(), a.seconds, &dir.join("through.log"))?;
        let report = emu.finish(Duration::ZERO)?;
        let (added, hop, own) = (minus(&via, &direct), minus(&through_relay, &direct), minus(&via, &through_relay));
        let at = |m: &Map, k: &str| m.get(k).copied().unwrap_or(0);
        println!(
            "  rep {rep}: added p50 {} ns, p99 {} ns = hop (relay − direct) p50 {} ns, p99 {} ns + netfi's own part p50 {} ns, p99 {} ns",
            at(&added, "p50"),
            at(&added, "p99"),
            at(&hop, "p50"),
            at(&hop, "p99"),
            at(&own, "p50"),
            at(&own, "p99")
        );
        let udp = read_json(&dir.join("udp.json")).unwrap_or(Value::Null);
        Ok(json!({
            "repetition": rep, "direct_ns": direct, "through_relay_ns": through_relay, "through_netfi_ns": via,
            "added_ns": added, "hop_ns": hop, "netfi_own_ns": own, "relay_datagrams": relayed,
            "emulator_frames": report["frames"], "return_path": udp["return_path"]
        }))
    })();
    let _ = server.kill();
    let _ = server.wait();
    let mut v = result?;
    v["host"] = json!(host.stop());
    Ok(v)
}

/// `a − b`, percentile by percentile.
fn minus(a: &Map, b: &Map) -> Map {
    a.iter().filter_map(|(k, v)| Some((k.clone(), v - b.get(k)?))).collect()
}

/// The relay a lab would write instead of netfi: one thread on the
/// emulator's core busy-polling two non-blocking sockets, relaying the
/// client's datagrams to the server and the server's back to the client
/// that last sent; no fault, no record, no clock.
struct MinimalRelay {
    /// The port the client sends to.
    port: u16,
    stop: Arc<AtomicBool>,
    thread: JoinHandle<std::io::Result<u64>>,
}

impl MinimalRelay {
    fn start(core: Option<usize>, rt_priority: Option<i32>, server_port: u16) -> Result<MinimalRelay> {
        let ingress = UdpSocket::bind("127.0.0.1:0")?;
        let egress = UdpSocket::bind("127.0.0.1:0")?;
        egress.connect(("127.0.0.1", server_port))?;
        ingress.set_nonblocking(true)?;
        egress.set_nonblocking(true)?;
        let port = ingress.local_addr()?.port();
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = Arc::clone(&stop);
        let thread = std::thread::spawn(move || {
            pin(core, rt_priority);
            let mut buf = [0u8; 65536];
            let mut client: Option<SocketAddr> = None;
            let mut relayed = 0u64;
            // A datagram the kernel refuses (a full buffer, a server not
            // there yet) is dropped, as a minimal relay would.
            let passing = |r: std::io::Result<()>| match r {
                Err(e) if !matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::ConnectionRefused) => Err(e),
                _ => Ok(()),
            };
            while !stopping.load(Ordering::Relaxed) {
                match ingress.recv_from(&mut buf) {
                    Ok((n, from)) => {
                        client = Some(from);
                        relayed += 1;
                        passing(egress.send(&buf[..n]).map(drop))?;
                    }
                    Err(e) => passing(Err(e))?,
                }
                match egress.recv(&mut buf) {
                    Ok(n) => {
                        if let Some(c) = client {
                            relayed += 1;
                            passing(ingress.send_to(&buf[..n], c).map(drop))?;
                        }
                    }
                    Err(e) => passing(Err(e))?,
                }
            }
            Ok(relayed)
        });
        Ok(MinimalRelay { port, stop, thread })
    }

    /// Stops the relay: the datagrams it relayed, both ways.
    fn stop(self) -> Result<u64> {
        self.stop.store(true, Ordering::Relaxed);
        let relayed = self.thread.join().map_err(|_| anyhow::anyhow!("the relay thread panicked"))?;
        relayed.context("the minimal relay")
    }
}

/// Starts `sockperf ARGS` on `core` (a child takes its parent thread's
/// placement), its output in `log`.
fn sockperf_on(core: Option<usize>, args: &[&str], log: &Path) -> Result<Child> {
    let file = std::fs::File::create(log)?;
    std::thread::scope(|sc| {
        sc.spawn(|| {
            pin(core, None);
            Command::new("sockperf").args(args).stdin(Stdio::null()).stdout(file.try_clone()?).stderr(file).spawn().context("starting sockperf")
        })
        .join()
        .map_err(|_| anyhow::anyhow!("the spawning thread panicked"))?
    })
}

/// One ping-pong of `seconds` against `port`: sockperf's percentiles, ns.
fn ping_pong(core: Option<usize>, port: u16, seconds: u64, log: &Path) -> Result<Map> {
    let mut child = sockperf_on(core, &["ping-pong", "-i", "127.0.0.1", "-p", &port.to_string(), "-t", &seconds.to_string(), "-m", "64"], log)?;
    while child.try_wait()?.is_none() {
        if stopped() {
            let _ = child.kill();
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    check_interrupted()?;
    let text = std::fs::read_to_string(log)?;
    parse(&text).with_context(|| format!("no percentiles in sockperf's output ({})", log.display()))
}

/// sockperf's latency percentiles (µs in its output) in ns.
fn parse(text: &str) -> Option<Map> {
    let mut m = Map::new();
    for line in text.lines() {
        let value = |l: &str| l.rsplit('=').next()?.trim().parse::<f64>().ok();
        let key = if let Some(rest) = line.split("percentile ").nth(1) {
            match rest.split_whitespace().next()? {
                "50.000" => "p50",
                "90.000" => "p90",
                "99.000" => "p99",
                "99.900" => "p999",
                "99.990" => "p9999",
                _ => continue,
            }
        } else if line.contains("<MAX> observation") {
            "max"
        } else {
            continue;
        };
        m.insert(key.to_string(), (value(line)? * 1000.0).round() as i64);
    }
    m.contains_key("p50").then_some(m)
}
