//! sockperf ping-pong through the UDP bridge, against a direct run.

use crate::args::Settings;
use crate::emulator::{self, Emulator};
use crate::figures::ns;
use crate::host::{pin, HostTimer};
use crate::{check_interrupted, Results};
use anyhow::{Context, Result};
use netfi::service::plan::fresh_run_id;
use netfi::service::signals::stop_requested;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

const HALT_POLL_NS: &str = "/sys/module/haltpoll/parameters/guest_halt_poll_ns";
/// Guest halt polling for the second sockperf variant: 200 µs, the
/// kernel's documented default where the cpuidle-haltpoll driver polls.
const SOCKPERF_HALT_POLL_NS: u64 = 200_000;

/// sockperf's latency percentiles of one ping-pong run, in ns. sockperf
/// reports half the round trip (its "latency"); the round trip is twice it.
fn parse_sockperf(text: &str) -> Option<BTreeMap<String, i64>> {
    let mut m = BTreeMap::new();
    for line in text.lines() {
        let value = |l: &str| l.rsplit('=').next()?.trim().parse::<f64>().ok();
        if let Some(rest) = line.split("percentile ").nth(1) {
            let q = rest.split_whitespace().next()?;
            let key = match q {
                "50.000" => "p50",
                "90.000" => "p90",
                "99.000" => "p99",
                "99.900" => "p999",
                "99.990" => "p9999",
                _ => continue,
            };
            m.insert(key.to_string(), (value(line)? * 1000.0).round() as i64);
        } else if line.contains("<MAX> observation") {
            m.insert("max".to_string(), (value(line)? * 1000.0).round() as i64);
        }
    }
    m.contains_key("p50").then_some(m)
}

/// A free UDP port on loopback (bound and released: a small race only).
fn free_udp_port() -> Result<u16> {
    Ok(std::net::UdpSocket::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// Runs `sockperf` with `args` on `core` (the child inherits the spawning
/// thread's placement), returning its output.
fn sockperf_on(core: Option<usize>, args: Vec<String>) -> Result<(Child, PathBuf)> {
    let log = std::env::temp_dir().join(format!("netfi-sockperf-{}-{}.log", std::process::id(), fresh_run_id()));
    let file = std::fs::File::create(&log)?;
    let child = std::thread::scope(|sc| {
        sc.spawn(|| {
            pin(core, None);
            Command::new("sockperf").args(&args).stdin(Stdio::null()).stdout(file.try_clone()?).stderr(file).spawn()
        })
        .join()
        .map_err(|_| anyhow::anyhow!("the spawning thread panicked"))
    })??;
    Ok((child, log))
}

fn ping_pong(core: Option<usize>, port: u16, seconds: f64) -> Result<BTreeMap<String, i64>> {
    let secs = (seconds.round() as u64).max(1).to_string();
    let (mut child, log) = sockperf_on(
        core,
        vec!["ping-pong".into(), "-i".into(), "127.0.0.1".into(), "-p".into(), port.to_string(), "-t".into(), secs, "-m".into(), "64".into()],
    )?;
    loop {
        if child.try_wait()?.is_some() {
            break;
        }
        if stop_requested() {
            let _ = child.kill();
            let _ = child.wait();
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    check_interrupted()?;
    let text = std::fs::read_to_string(&log)?;
    let _ = std::fs::remove_file(&log);
    parse_sockperf(&text).with_context(|| format!("no percentiles in sockperf's output:\n{text}"))
}

/// sockperf ping-pong (64-byte messages) between a client and a server on
/// the benchmark's core: directly, then through `netfi emulator --payload
/// raw` on its own core, the replies coming back through the return path.
///
/// With `halt_poll_ns`, the guest's halt polling is set to it for the
/// interval and put back after: on a VM where it is off, every message a
/// relay on another core hands to a sleeping end wakes a halted vCPU,
/// which costs more than the relay itself.
fn sockperf_interval(s: &Settings, seconds: f64, rep: usize, halt_poll_ns: Option<u64>) -> Result<Value> {
    check_interrupted()?;
    if Command::new("sockperf").arg("--version").stdout(Stdio::null()).stderr(Stdio::null()).status().is_err() {
        return Ok(json!({"skipped": "sockperf is not installed (Debian: apt install sockperf)"}));
    }
    let before = std::fs::read_to_string(HALT_POLL_NS).ok();
    if let Some(ns) = halt_poll_ns {
        std::fs::write(HALT_POLL_NS, ns.to_string()).with_context(|| format!("setting {HALT_POLL_NS}"))?;
    }
    let v = sockperf_measure(s, seconds, rep);
    if let (Some(_), Some(b)) = (halt_poll_ns, before) {
        let _ = std::fs::write(HALT_POLL_NS, b.trim());
    }
    v
}

/// The guest's halt polling now, and whether this process may change it.
fn halt_polling() -> (Option<u64>, bool) {
    let now = std::fs::read_to_string(HALT_POLL_NS).ok().and_then(|t| t.trim().parse().ok());
    let writable = now.is_some() && std::fs::OpenOptions::new().write(true).open(HALT_POLL_NS).is_ok();
    (now, writable)
}

fn sockperf_measure(s: &Settings, seconds: f64, rep: usize) -> Result<Value> {
    let halt_poll_ns: Option<u64> = std::fs::read_to_string(HALT_POLL_NS).ok().and_then(|t| t.trim().parse().ok());
    let host = HostTimer::start(s.quiet);
    let server_port = free_udp_port()?;
    let (mut server, server_log) = sockperf_on(s.driver_core, vec!["server".into(), "-i".into(), "127.0.0.1".into(), "-p".into(), server_port.to_string()])?;
    std::thread::sleep(Duration::from_millis(300));
    let result = (|| -> Result<Value> {
        let direct = ping_pong(s.driver_core, server_port, seconds)?;
        let dir = s.out_dir.join("runs").join(format!("sockperf-r{rep}"));
        let _ = std::fs::remove_dir_all(&dir);
        let args = emulator::args(s, "Normal", &dir, (seconds * 200_000.0) as u64, None);
        let udp: Vec<String> = vec![
            "--payload".into(),
            "raw".into(),
            "--ingress".into(),
            "udp://127.0.0.1:0".into(),
            "--egress".into(),
            format!("udp://127.0.0.1:{server_port}"),
        ];
        let emu = Emulator::spawn(&dir, &emulator::argv(&args, &udp))?;
        let ingress = emu.udp_ingress()?;
        let via = ping_pong(s.driver_core, ingress.port(), seconds)?;
        let report = emu.finish(Duration::ZERO)?;
        let udp: Value = serde_json::from_slice(&std::fs::read(dir.join("udp.json")).unwrap_or_default()).unwrap_or(Value::Null);
        let added: BTreeMap<String, i64> = via.iter().filter_map(|(k, v)| Some((k.clone(), v - direct.get(k)?))).collect();
        Ok(json!({
            "repetition": rep,
            "seconds": seconds,
            "message_bytes": 64,
            "what": "sockperf ping-pong latency (half the round trip), client and server on the benchmark's core, ns",
            "direct_ns": direct,
            "through_netfi_ns": via,
            "added_ns": added,
            "emulator_frames": report.process.frames,
            "emulator_release_lateness_ns": report.shaping.link.release_lateness_ns,
            "return_path": udp.get("return_path").cloned().unwrap_or(Value::Null),
            "guest_halt_poll_ns": halt_poll_ns,
        }))
    })();
    let _ = server.kill();
    let _ = server.wait();
    let _ = std::fs::remove_file(&server_log);
    let mut v = result?;
    v["host"] = json!(host.stop());
    Ok(v)
}

/// The sockperf part of repetition `rep`: as the machine is set up; and,
/// where guest halt polling is off and may be changed, once more with it
/// on (put back after).
pub fn sockperf_part(s: &Settings, rep: usize, res: &mut Results) -> Result<()> {
    let (now, writable) = halt_polling();
    let variants: Vec<Option<u64>> = if now == Some(0) && writable { vec![None, Some(SOCKPERF_HALT_POLL_NS)] } else { vec![None] };
    for variant in variants {
        let mut v = sockperf_interval(s, s.sockperf_s(), rep, variant)?;
        v["variant"] = json!(if variant.is_some() { "halt_polling_on" } else { "as_configured" });
        match v.get("skipped").and_then(Value::as_str) {
            Some(why) => println!("  rep {rep} sockperf: skipped: {why}"),
            None => {
                let g = |k: &str, q: &str| v[k][q].as_i64().map_or("–".to_string(), ns);
                println!(
                    "  rep {rep} sockperf ping-pong (half round trip): direct p50 {} p99 {}; through netfi p50 {} p99 {}; added p50 {} p99 {} (guest halt polling {} ns)",
                    g("direct_ns", "p50"),
                    g("direct_ns", "p99"),
                    g("through_netfi_ns", "p50"),
                    g("through_netfi_ns", "p99"),
                    g("added_ns", "p50"),
                    g("added_ns", "p99"),
                    v["guest_halt_poll_ns"].as_u64().map_or("unknown".to_string(), |n| n.to_string())
                );
            }
        }
        res.sockperfs.push(v);
    }
    Ok(())
}
