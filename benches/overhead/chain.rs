//! Chain intervals: a real `netfi emulator` between the benchmark's two
//! ends, chain and direct hop alternating in one thread; and the latency
//! and delay parts built of them.

use crate::args::Settings;
use crate::drive::{drive, slots_for, Drive, Routes};
use crate::emulator::{self, Emulator};
use crate::ends::{loopback_port, IpcEnds, UdpEnds};
use crate::figures::{ns, rate_label, KEYS};
use crate::floor::floor_interval;
use crate::host::{pin, HostTimer, HostWindow};
use crate::{check_interrupted, write_hlog, Results, Transport, PLM2_DLM2};
use anyhow::Result;
use netfi::metrics::{difference, fmt_ns, Summary};
use netfi::service::emulator::{EmulatorReport, LoopBusy};
use netfi::service::plan::fresh_run_id;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// One chain interval's results.
#[derive(Debug, Clone, Serialize)]
pub struct ChainResult {
    pub name: String,
    pub repetition: usize,
    pub transport: Transport,
    pub scenario: String,
    pub rate_hz: f64,
    pub seconds: f64,
    /// From the first recorded send to the last.
    pub send_seconds: f64,
    pub host: HostWindow,
    pub chain_ns: Summary,
    pub direct_ns: Summary,
    /// `chain − direct`, percentile by percentile.
    pub added_ns: BTreeMap<String, i64>,
    pub hop1_ns: Option<Summary>,
    pub inside_ns: Option<Summary>,
    pub hop2_ns: Option<Summary>,
    pub send_lateness_ns: Summary,
    pub chain_sent: u64,
    pub chain_received: u64,
    pub direct_sent: u64,
    pub direct_received: u64,
    pub refused: u64,
    pub emulator: EmulatorFigures,
    pub hlogs: Vec<PathBuf>,
}

/// The emulator's own figures of an interval (from `emulator.json`).
#[derive(Debug, Clone, Serialize)]
pub struct EmulatorFigures {
    pub entered: u64,
    pub delivered: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    pub decision_ns: Summary,
    pub release_lateness_ns: Summary,
    pub ingress_wait_ns: Summary,
    pub steal_fraction: f64,
    pub realtime_priority: Option<i32>,
    /// The loop's own time on frames (see [`LoopBusy`]).
    pub busy: Option<LoopBusy>,
    /// Trace rows the emulator could not hand to its writer.
    pub trace_overflowed: u64,
    pub out_dir: PathBuf,
}

impl EmulatorFigures {
    fn from(r: &EmulatorReport, dir: &Path) -> EmulatorFigures {
        EmulatorFigures {
            entered: r.process.frames.account.entered,
            delivered: r.process.frames.account.delivered,
            dropped: r.process.frames.account.dropped.clone(),
            held_at_end: r.process.frames.account.held_at_end,
            decision_ns: r.shaping.link.decision_ns,
            release_lateness_ns: r.shaping.link.release_lateness_ns,
            ingress_wait_ns: r.shaping.link.ingress_wait_ns,
            steal_fraction: r.process.steal_fraction,
            realtime_priority: r.process.realtime_priority,
            busy: r.process.busy.clone(),
            trace_overflowed: r.process.trace_overflowed,
            out_dir: dir.to_path_buf(),
        }
    }
}

/// What a chain interval runs: the scenario, the rate per route, how long.
struct Interval<'a> {
    dir: &'a Path,
    scenario: &'a str,
    rate_hz: f64,
    seconds: f64,
    /// Frames the emulator should expect.
    expected: u64,
    /// A delay scenario: frames stay held after the last is sent, and the
    /// driving thread never sleeps.
    delayed: bool,
    routes: Routes,
    /// The emulator's release queue (`--queue-capacity`), when not its
    /// default.
    queue_capacity: Option<usize>,
}

impl Interval<'_> {
    /// How long to wait for the chain's last frames after the last send.
    fn drain_ns(&self) -> u64 {
        if self.delayed {
            5_000_000_000
        } else {
            200_000_000
        }
    }
}

/// A chain interval: the emulator between the benchmark's two ends over
/// `transport`, at `rate_hz` per route, for `seconds`.
pub fn chain_interval(s: &Settings, transport: Transport, scenario: &str, scenario_label: &str, rate_hz: f64, seconds: f64, rep: usize) -> Result<ChainResult> {
    let name = format!("chain-{}-{}-{}-r{rep}", transport.name(), scenario_label, rate_label(rate_hz));
    let delayed = scenario_label != "normal";
    run_interval(s, transport, name, rep, scenario, rate_hz, seconds, delayed, Routes::Alternate, None)
}

/// A capacity trial: every frame through the emulator over iceoryx2 at
/// `rate_hz`, for `seconds`, the release queue holding a second of frames
/// (so a delay scenario tests the emulator's speed, not the queue's size).
pub fn capacity_interval(s: &Settings, scenario: &str, scenario_label: &str, rate_hz: f64, seconds: f64) -> Result<ChainResult> {
    let name = format!("capacity-{scenario_label}-{}", rate_label(rate_hz));
    let queue = (rate_hz as usize).max(1 << 16);
    run_interval(s, Transport::Iceoryx2, name, 0, scenario, rate_hz, seconds, scenario_label != "normal", Routes::ChainOnly, Some(queue))
}

#[allow(clippy::too_many_arguments)]
fn run_interval(
    s: &Settings,
    transport: Transport,
    name: String,
    rep: usize,
    scenario: &str,
    rate_hz: f64,
    seconds: f64,
    delayed: bool,
    routes: Routes,
    queue_capacity: Option<usize>,
) -> Result<ChainResult> {
    check_interrupted()?;
    let dir = s.out_dir.join("runs").join(&name);
    let _ = std::fs::remove_dir_all(&dir);
    let (_, slots) = slots_for(rate_hz, seconds, routes);
    let expected = slots / if routes == Routes::Alternate { 2 } else { 1 } + 16;
    let iv = Interval { dir: &dir, scenario, rate_hz, seconds, expected, delayed, routes, queue_capacity };
    let host = HostTimer::start(s.quiet);
    let (drive, report) = match transport {
        Transport::Iceoryx2 => drive_ipc(s, &iv)?,
        Transport::Udp => drive_udp(s, &iv, slots)?,
    };
    let host = host.stop();
    let stamped = transport == Transport::Iceoryx2;
    let hlogs = chain_hlogs(s, &name, &dir, &drive, stamped)?;
    let (chain_ns, direct_ns) = (drive.chain.summary(), drive.direct.summary());
    Ok(ChainResult {
        name,
        repetition: rep,
        transport,
        scenario: report.process.scenario.clone(),
        rate_hz,
        seconds: drive.seconds,
        send_seconds: drive.send_seconds,
        host,
        added_ns: difference(&chain_ns, &direct_ns, &KEYS),
        chain_ns,
        direct_ns,
        hop1_ns: stamped.then(|| drive.hop1.summary()),
        inside_ns: stamped.then(|| drive.inside.summary()),
        hop2_ns: stamped.then(|| drive.hop2.summary()),
        send_lateness_ns: drive.send_lateness.summary(),
        chain_sent: drive.chain_sent,
        chain_received: drive.chain_received,
        direct_sent: drive.direct_sent,
        direct_received: drive.direct_received,
        refused: drive.refused,
        emulator: EmulatorFigures::from(&report, &dir),
        hlogs,
    })
}

/// The iceoryx2 chain: the emulator on the run's ports, the ends a console
/// and a simulator node in the driving thread.
fn drive_ipc(s: &Settings, iv: &Interval) -> Result<(Drive, EmulatorReport)> {
    let run_id = fresh_run_id();
    let mut args = emulator::args(s, iv.scenario, iv.dir, iv.expected, Some(run_id.clone()));
    args.scenario.queue_capacity = iv.queue_capacity;
    let _forget = emulator::ForgetRuns(vec![run_id.clone()]);
    let emu = Emulator::spawn(iv.dir, &emulator::argv(&args, &[]))?;
    let (core, rt) = (s.driver_core, s.rt_priority);
    let (rate_hz, seconds, drain_ns, may_sleep, routes) = (iv.rate_hz, iv.seconds, iv.drain_ns(), !iv.delayed, iv.routes);
    let rid = run_id.clone();
    let handle = std::thread::spawn(move || -> Result<Drive> {
        pin(core, rt);
        let mut ends = IpcEnds::open(&rid)?;
        let d = drive(&mut ends, rate_hz, seconds, drain_ns, may_sleep, routes);
        ends.end(d.chain_sent);
        // Keep the ports open until the emulator has seen the end.
        std::thread::sleep(Duration::from_millis(50));
        Ok(d)
    });
    let d = handle.join().map_err(|_| anyhow::anyhow!("the driving thread panicked"))?;
    check_interrupted()?;
    let d = match d {
        Ok(d) => d,
        Err(e) => {
            let _ = emu.finish(Duration::ZERO);
            return Err(e);
        }
    };
    Ok((d, emu.finish(Duration::from_secs(10))?))
}

/// The UDP chain: the emulator between two loopback sockets (ITP
/// payloads, no return path), the ends non-blocking sockets.
fn drive_udp(s: &Settings, iv: &Interval, slots: u64) -> Result<(Drive, EmulatorReport)> {
    let rx_chain = loopback_port()?;
    let mut args = emulator::args(s, iv.scenario, iv.dir, iv.expected, None);
    args.scenario.queue_capacity = iv.queue_capacity;
    let udp: Vec<String> = vec![
        "--ingress".into(),
        "udp://127.0.0.1:0".into(),
        "--egress".into(),
        format!("udp://{}", rx_chain.local_addr()),
        "--payload".into(),
        "itp".into(),
        "--no-return".into(),
        "--idle-end-ms".into(),
        "300".into(),
    ];
    let emu = Emulator::spawn(iv.dir, &emulator::argv(&args, &udp))?;
    let ingress = emu.udp_ingress()?;
    let (core, rt) = (s.driver_core, s.rt_priority);
    let (rate_hz, seconds, drain_ns, may_sleep, routes) = (iv.rate_hz, iv.seconds, iv.drain_ns(), !iv.delayed, iv.routes);
    let handle = std::thread::spawn(move || -> Result<Drive> {
        pin(core, rt);
        let mut ends = UdpEnds::new(rx_chain, ingress, slots)?;
        Ok(drive(&mut ends, rate_hz, seconds, drain_ns, may_sleep, routes))
    });
    let d = handle.join().map_err(|_| anyhow::anyhow!("the driving thread panicked"))??;
    check_interrupted()?;
    Ok((d, emu.finish(Duration::from_secs(10))?))
}

/// Writes the interval's histograms as HdrHistogram logs; lists them with
/// the emulator's own.
fn chain_hlogs(s: &Settings, name: &str, dir: &Path, drive: &Drive, stamped: bool) -> Result<Vec<PathBuf>> {
    let hdir = s.out_dir.join("hlog");
    let mut hlogs = vec![
        write_hlog(&drive.chain, &hdir, &format!("{name}-chain"), "chain", drive.seconds)?,
        write_hlog(&drive.direct, &hdir, &format!("{name}-direct"), "direct", drive.seconds)?,
    ];
    if stamped {
        hlogs.push(write_hlog(&drive.hop1, &hdir, &format!("{name}-hop1"), "hop1", drive.seconds)?);
        hlogs.push(write_hlog(&drive.inside, &hdir, &format!("{name}-inside"), "inside", drive.seconds)?);
        hlogs.push(write_hlog(&drive.hop2, &hdir, &format!("{name}-hop2"), "hop2", drive.seconds)?);
    }
    hlogs.push(dir.join("lateness.hlog"));
    hlogs.push(dir.join("decision.hlog"));
    Ok(hlogs)
}

/// The latency part of repetition `rep`: per rate and transport, a floor
/// interval and a chain interval back to back (the same moment of the
/// host).
pub fn latency_part(s: &Settings, rep: usize, res: &mut Results) -> Result<()> {
    for &rate in &s.rates_hz {
        for t in Transport::ALL {
            let f = floor_interval(s, t, rate, s.floor_s, rep)?;
            println!(
                "  rep {rep} {:<8} {:>6}  floor (one cross-core hop)     {}  steal {:.2}%  others {:.2} cores",
                t.name(),
                rate_label(rate),
                f.hop_ns.line(),
                f.host.steal_fraction * 100.0,
                f.host.others_busy_cores
            );
            res.floors.push(f);
            let c = chain_interval(s, t, "Normal", "normal", rate, s.interval_s, rep)?;
            print_chain(rep, t, rate, &c);
            res.chains.push(c);
        }
    }
    Ok(())
}

fn print_chain(rep: usize, t: Transport, rate: f64, c: &ChainResult) {
    println!(
        "  rep {rep} {:<8} {:>6}  chain                          {}  steal {:.2}%  others {:.2} cores",
        t.name(),
        rate_label(rate),
        c.chain_ns.line(),
        c.host.steal_fraction * 100.0,
        c.host.others_busy_cores
    );
    println!("  rep {rep} {:<8} {:>6}  direct (same run, alternating) {}", t.name(), rate_label(rate), c.direct_ns.line());
    println!(
        "  rep {rep} {:<8} {:>6}  added p50 {}  p99 {}  p99.9 {}; release lateness p99 {}; lost chain {} direct {}",
        t.name(),
        rate_label(rate),
        ns(c.added_ns["p50"]),
        ns(c.added_ns["p99"]),
        ns(c.added_ns["p999"]),
        fmt_ns(c.emulator.release_lateness_ns.p99),
        c.chain_sent.saturating_sub(c.chain_received),
        c.direct_sent.saturating_sub(c.direct_received)
    );
}

/// The delay part of repetition `rep`: the iceoryx2 chain through PLM-2
/// then DLM-2 at 1 kHz.
pub fn delay_part(s: &Settings, rep: usize, res: &mut Results) -> Result<()> {
    let c = chain_interval(s, Transport::Iceoryx2, PLM2_DLM2, "plm2_dlm2", 1000.0, s.interval_s, rep)?;
    println!(
        "  rep {rep} iceoryx2 PLM-2 + DLM-2 1k: release lateness {}; end-to-end beyond the injected delay {}",
        c.emulator.release_lateness_ns.line(),
        c.chain_ns.line()
    );
    res.chains.push(c);
    Ok(())
}
