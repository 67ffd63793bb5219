//! A chain interval: a real `netfi emulator` (its trace, histograms and
//! report as in `netfi run`) between the benchmark's two ends, both played
//! by one thread on the bench core, over iceoryx2 or UDP. The thread sends
//! frame after frame at the interval's rate, through the emulator (the
//! chain) and, alternately, straight to its own other end (the direct
//! route), and busy-polls both between sends: no arrival waits for a
//! sender to give up a core, and both routes see the same moments.

use crate::common::args::{check_interrupted, Placement};
use crate::common::drive::{drive, slots_for, Drive, Routes};
use crate::common::ends::{loopback_port, IpcEnds, UdpEnds};
use crate::common::host::{pin, HostTimer, HostWindow};
use crate::common::out::Out;
use crate::common::process::{at, fresh_run_id, summary, Build, EmulatorSpec, ForgetRuns};
use crate::common::table::{Map, KEYS};
use anyhow::Result;
use netfi::metrics::{difference, Summary};
use netfi::service::args::EndsArgs;
use netfi::transport::udp::UdpArgs;
use netfi::transport::Payload;
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The transport of a chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Transport {
    Iceoryx2,
    Udp,
}

impl Transport {
    pub fn name(self) -> &'static str {
        match self {
            Transport::Iceoryx2 => "iceoryx2",
            Transport::Udp => "udp",
        }
    }
}

/// What a chain interval runs.
pub struct Interval<'a> {
    /// Its name: the directory of its files under `runs/`.
    pub name: String,
    pub transport: Transport,
    pub scenario: &'a str,
    /// Frames a second on each route.
    pub rate_hz: f64,
    pub seconds: f64,
    pub routes: Routes,
    /// A delay scenario: frames are held after the last send, and the
    /// driving thread never sleeps (a frame may come back at any time).
    pub delayed: bool,
    /// The emulator's release queue (`--queue-capacity`), when not its
    /// default.
    pub queue_capacity: Option<usize>,
}

/// The emulator's own figures of an interval, from its `emulator.json`.
#[derive(Debug, Clone, Serialize)]
pub struct EmulatorFigures {
    pub entered: u64,
    pub delivered: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    pub decision_ns: Option<Summary>,
    pub release_lateness_ns: Option<Summary>,
    pub ingress_wait_ns: Option<Summary>,
    pub steal_fraction: f64,
    /// The loop's own time on frames (`busy`; absent in older builds).
    pub busy: Value,
    /// Trace rows the emulator could not hand to its writer.
    pub trace_overflowed: u64,
    /// What was cleared off its core.
    pub isolation: Value,
    pub dir: PathBuf,
}

impl EmulatorFigures {
    pub fn from(r: &Value, dir: &Path) -> EmulatorFigures {
        let n = |p: &str| at(r, p).as_u64().unwrap_or(0);
        EmulatorFigures {
            entered: n("frames.entered"),
            delivered: n("frames.delivered"),
            dropped: serde_json::from_value(at(r, "frames.dropped").clone()).unwrap_or_default(),
            held_at_end: n("frames.held_at_end"),
            decision_ns: summary(r, "decision_ns"),
            release_lateness_ns: summary(r, "release_lateness_ns"),
            ingress_wait_ns: summary(r, "ingress_wait_ns"),
            steal_fraction: at(r, "steal_fraction").as_f64().unwrap_or(f64::NAN),
            busy: at(r, "busy").clone(),
            trace_overflowed: n("trace_overflowed"),
            isolation: at(r, "isolation").clone(),
            dir: dir.to_path_buf(),
        }
    }

    /// The loop's busy ns a frame, if the build measures it.
    pub fn busy_ns_per_frame(&self) -> Option<f64> {
        self.busy["busy_ns_per_frame"].as_f64()
    }
}

/// One chain interval's results.
#[derive(Debug, Clone, Serialize)]
pub struct ChainResult {
    pub name: String,
    pub transport: Transport,
    pub scenario: String,
    pub rate_hz: f64,
    pub seconds: f64,
    /// From the first recorded send to the last: the rate the thread really
    /// offered is the frames it sent over this.
    pub send_seconds: f64,
    pub host: HostWindow,
    pub chain_ns: Summary,
    pub direct_ns: Summary,
    /// `chain − direct`, percentile by percentile.
    pub added_ns: Map,
    /// The chain split by the emulator's stamps (iceoryx2): send → taken
    /// off its port; taken → released; released → received.
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
}

/// Runs the interval `iv` with `build`'s emulator.
pub fn run_chain(build: &Build, out: &Out, p: &Placement, iv: &Interval) -> Result<ChainResult> {
    check_interrupted()?;
    let dir = out.run_dir(&iv.name)?;
    let (_, slots) = slots_for(iv.rate_hz, iv.seconds, iv.routes);
    let expected = slots / if iv.routes == Routes::Alternate { 2 } else { 1 } + 16;
    let spec = EmulatorSpec {
        scenario: iv.scenario,
        dir: &dir,
        expected_frames: expected,
        run_id: None,
        feedback: false,
        queue_capacity: iv.queue_capacity,
        ends: EndsArgs::default(),
        udp: UdpArgs::default(),
        streams: 1,
    };
    let host = HostTimer::start(p.quiet);
    let (d, report) = match iv.transport {
        Transport::Iceoryx2 => drive_ipc(build, p, iv, spec)?,
        Transport::Udp => drive_udp(build, p, iv, spec, slots)?,
    };
    let host = host.stop();
    let stamped = iv.transport == Transport::Iceoryx2;
    let (chain_ns, direct_ns) = (d.chain.summary(), d.direct.summary());
    Ok(ChainResult {
        name: iv.name.clone(),
        transport: iv.transport,
        scenario: at(&report, "scenario").as_str().unwrap_or(iv.scenario).to_string(),
        rate_hz: iv.rate_hz,
        seconds: d.seconds,
        send_seconds: d.send_seconds,
        host,
        added_ns: difference(&chain_ns, &direct_ns, &KEYS),
        chain_ns,
        direct_ns,
        hop1_ns: stamped.then(|| d.hop1.summary()),
        inside_ns: stamped.then(|| d.inside.summary()),
        hop2_ns: stamped.then(|| d.hop2.summary()),
        send_lateness_ns: d.send_lateness.summary(),
        chain_sent: d.chain_sent,
        chain_received: d.chain_received,
        direct_sent: d.direct_sent,
        direct_received: d.direct_received,
        refused: d.refused,
        emulator: EmulatorFigures::from(&report, &dir),
    })
}

/// How long to wait for the chain's last frames after the last send.
fn drain_ns(iv: &Interval) -> u64 {
    if iv.delayed {
        5_000_000_000
    } else {
        200_000_000
    }
}

/// Over iceoryx2: the emulator on a run's ports, the ends a console and a
/// simulator node in the driving thread.
fn drive_ipc(build: &Build, p: &Placement, iv: &Interval, spec: EmulatorSpec) -> Result<(Drive, Value)> {
    let run_id = fresh_run_id();
    let spec = EmulatorSpec { run_id: Some(&run_id), ..spec };
    let _forget = ForgetRuns(vec![run_id.clone()]);
    let emu = build.emulator(&spec, p)?;
    let (core, rt, rid) = (p.bench_core, p.rt_priority, run_id.clone());
    let (rate_hz, seconds, drain, may_sleep, routes) = (iv.rate_hz, iv.seconds, drain_ns(iv), !iv.delayed, iv.routes);
    let handle = std::thread::spawn(move || -> Result<Drive> {
        pin(core, rt);
        let mut ends = IpcEnds::open(&rid)?;
        let d = drive(std::slice::from_mut(&mut ends), rate_hz, seconds, drain, may_sleep, routes);
        ends.end(d.chain_sent);
        // Keep the ports open until the emulator has seen the end.
        std::thread::sleep(Duration::from_millis(50));
        Ok(d)
    });
    let d = handle.join().map_err(|_| anyhow::anyhow!("the driving thread panicked"))??;
    check_interrupted()?;
    Ok((d, emu.finish(Duration::from_secs(10))?))
}

/// Over UDP: the emulator between two loopback sockets (ITP payloads, no
/// return path), the ends non-blocking sockets; UDP carries no metadata, so
/// the send times are kept in a table by sequence.
fn drive_udp(build: &Build, p: &Placement, iv: &Interval, mut spec: EmulatorSpec, slots: u64) -> Result<(Drive, Value)> {
    let rx_chain = loopback_port()?;
    spec.ends = EndsArgs { ingress: "udp://127.0.0.1:0".parse()?, egress: format!("udp://{}", rx_chain.local_addr()).parse()?, idle_end_ms: Some(300.0) };
    spec.udp = UdpArgs { payload: Payload::Itp, no_return: true, console_from: Some("first".parse()?), ..UdpArgs::default() };
    let emu = build.emulator(&spec, p)?;
    let ingress = emu.udp_ingress()?;
    let (core, rt) = (p.bench_core, p.rt_priority);
    let (rate_hz, seconds, drain, may_sleep, routes) = (iv.rate_hz, iv.seconds, drain_ns(iv), !iv.delayed, iv.routes);
    let handle = std::thread::spawn(move || -> Result<Drive> {
        pin(core, rt);
        let mut ends = UdpEnds::new(rx_chain, ingress, slots)?;
        Ok(drive(std::slice::from_mut(&mut ends), rate_hz, seconds, drain, may_sleep, routes))
    });
    let d = handle.join().map_err(|_| anyhow::anyhow!("the driving thread panicked"))??;
    check_interrupted()?;
    Ok((d, emu.finish(Duration::from_secs(10))?))
}
