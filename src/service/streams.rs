//! Many streams on one emulator (`netfi emulator --streams N`, what `netfi
//! run --streams N` starts): N console → robot pairs, each with its own
//! iceoryx2 services (those of run `<run>-s<K>`, stream 0 the run's own),
//! scenario, seed, link, feedback path, trace and `emulator.json` (in
//! `<out>/stream-K/`), served by one loop on one core.
//!
//! The loop turns each stream's [`Forward`] once per round, stream 0 first;
//! after each turn, if any stream's earliest release is due, every
//! stream's due frames go out, so a release waits behind at most one
//! stream's turn, not a round of N.
//! Every 4096 rounds it looks at the stop flag and serves live control,
//! which acts on stream 0 (its telemetry is stream 0's too). Standing
//! alone (not under `netfi run`, whose runner reaps), it also reaps one
//! stream's run for dead peers per look, each every 200 ms: a dead robot
//! ends its stream's feedback early, so its console ends its stream, as
//! with one stream; each stream's report names its dead peers. Nothing in
//! a round ([`round`]) allocates or locks: the streams are a slice fixed
//! before the loop starts.
//!
//! Besides each stream's own report, `<out>/emulator.json` holds every
//! stream's account and figures and their total ([`EmulatorStreams`]).

use crate::clock::now_ns;
use crate::host::StealTimer;
use crate::metrics::Summary;
use crate::service::args::{EmulatorArgs, StreamArgs};
use crate::service::emulator::{self, EmulatorFrames, EmulatorReport, Forward, Look, LoopEnd, PeerEvent};
use crate::service::plan::{parse_stream_scenario, stream_dir, stream_run_id, stream_seed};
use crate::service::signals;
use crate::transport::{Egress, FrameSink, FrameSource, Ingress, IpcNode, Role};
use anyhow::Context;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// One stream's part of the emulator's report of several streams.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorStream {
    pub stream: usize,
    /// The run id its services are named from.
    pub run_id: String,
    pub scenario: String,
    pub seed: u64,
    /// Its directory (its own `emulator.json`, trace and histograms).
    pub dir: PathBuf,
    pub frames: EmulatorFrames,
    pub loss_rate: f64,
    pub ingress_wait_ns: Summary,
    pub decision_ns: Summary,
    pub release_lateness_ns: Summary,
}

/// `emulator.json` of a run of several streams: each stream, the total,
/// and the one loop that served them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorStreams {
    pub streams: Vec<EmulatorStream>,
    /// The streams' accounts summed.
    pub total: EmulatorFrames,
    /// `entered + duplicated = delivered + dropped + held_at_end` holds for
    /// every stream.
    pub balanced: bool,
    pub core: Option<usize>,
    pub ended_by: String,
    pub duration_s: f64,
    /// Rounds of the loop (each turns every stream once), and the mean
    /// time of one.
    pub loop_rounds: u64,
    pub loop_round_ns_mean: f64,
    pub steal_fraction: f64,
    /// The loop's time on frames, all streams together
    /// ([`LoopBusy::total`] of the streams' own `busy`).
    #[serde(default)]
    pub busy: Option<emulator::LoopBusy>,
}

impl EmulatorFrames {
    /// Adds `o`'s counts to these.
    fn add(&mut self, o: &EmulatorFrames) {
        self.entered += o.entered;
        self.delivered += o.delivered;
        self.duplicated += o.duplicated;
        self.corrupted += o.corrupted;
        self.corrupted_delivered += o.corrupted_delivered;
        for (k, v) in &o.dropped {
            *self.dropped.entry(k.clone()).or_default() += v;
        }
        self.held_at_end += o.held_at_end;
        self.sent_by_console = match (self.sent_by_console, o.sent_by_console) {
            (Some(a), Some(b)) => Some(a + b),
            _ => None,
        };
        self.bad_checksum_passed += o.bad_checksum_passed;
        self.delivered_unsubscribed += o.delivered_unsubscribed;
    }

    /// Whether every frame that entered (and every copy) is accounted for.
    pub fn closes(&self) -> bool {
        self.entered + self.duplicated == self.delivered + self.dropped.values().sum::<u64>() + self.held_at_end
    }
}

impl EmulatorStreams {
    /// The joint report of the streams' reports.
    pub fn of(reports: &[EmulatorReport], run_ids: &[String], dirs: &[PathBuf]) -> EmulatorStreams {
        let mut total = EmulatorFrames {
            entered: 0,
            delivered: 0,
            duplicated: 0,
            corrupted: 0,
            corrupted_delivered: 0,
            dropped: BTreeMap::new(),
            held_at_end: 0,
            sent_by_console: Some(0),
            bad_checksum_passed: 0,
            bad_input: Default::default(),
            delivered_unsubscribed: 0,
        };
        let mut streams = Vec::new();
        for (k, r) in reports.iter().enumerate() {
            total.add(&r.process.frames);
            let l = &r.shaping.link;
            streams.push(EmulatorStream {
                stream: k,
                run_id: run_ids[k].clone(),
                scenario: r.process.scenario.clone(),
                seed: r.process.seed,
                dir: dirs[k].clone(),
                frames: r.process.frames.clone(),
                loss_rate: l.loss_rate,
                ingress_wait_ns: l.ingress_wait_ns,
                decision_ns: l.decision_ns,
                release_lateness_ns: l.release_lateness_ns,
            });
        }
        let p = &reports[0].process;
        let balanced = reports.iter().all(|r| r.process.frames.closes());
        let loop_round_ns_mean = p.loop_iteration_ns_mean;
        EmulatorStreams {
            streams,
            total,
            balanced,
            core: p.core,
            ended_by: p.ended_by.clone(),
            duration_s: p.duration_s,
            loop_rounds: p.loop_iterations,
            loop_round_ns_mean,
            steal_fraction: p.steal_fraction,
            busy: emulator::LoopBusy::total(reports.iter().filter_map(|r| r.process.busy.as_ref())),
        }
    }
}

/// One stream in the loop: its loop state, where its frames come from and
/// where they go, and what the loop saw of its peers.
pub struct Lane<S, K> {
    pub fwd: Forward,
    pub source: S,
    pub sink: K,
    /// Consoles and robots connected, as last seen.
    peers: (Option<usize>, Option<usize>),
    peer_events: Vec<PeerEvent>,
    /// Its robot was found dead.
    robot_died: bool,
}

impl<S: FrameSource, K: FrameSink> Lane<S, K> {
    /// The stream of `fwd` between `source` and `sink`.
    pub fn new(fwd: Forward, source: S, sink: K) -> Self {
        Lane { fwd, source, sink, peers: (None, None), peer_events: Vec::new(), robot_died: false }
    }

    /// Its robot is gone: its console is told through the feedback path
    /// (whose end marker comes early, so the console ends its stream) and
    /// the stream drains as usual, every frame accounted for; without a
    /// feedback path the stream has nothing left to wait for.
    fn robot_died(&mut self) {
        self.robot_died = true;
        if let Some(f) = self.fwd.feedback.as_deref_mut() {
            f.forward_end();
        }
    }

    /// Off the hot path: whether the stream may end (once drained, its
    /// robot is sent the end marker, once).
    fn finished(&mut self) -> bool {
        let done = self.fwd.finished(&mut self.sink);
        done || (self.robot_died && self.fwd.feedback.is_none())
    }

    /// Notes a change in the consoles or robots connected, `t_s` seconds
    /// into the loop.
    fn watch_peers(&mut self, t_s: f64) {
        let now = (self.source.peers(), self.sink.peers());
        if now.0 != self.peers.0 {
            self.peer_events.push(PeerEvent { t_s, peer: "console".into(), connected: now.0.unwrap_or(0) });
        }
        if now.1 != self.peers.1 {
            self.peer_events.push(PeerEvent { t_s, peer: "simulator".into(), connected: now.1.unwrap_or(0) });
        }
        self.peers = now;
    }
}

/// The iceoryx2 lanes, and each stream's node apart (the stop check and
/// the reaper read them while the loop holds the lanes).
type Opened = (Vec<emulator::EmulatorConfig>, Vec<Lane<Ingress, Egress>>, Vec<Option<IpcNode>>);

/// Stream `k`'s own arguments: its run id, scenario, seed and directory;
/// live control and the clearing of the core belong to stream 0.
fn stream_args(args: &EmulatorArgs, scenarios: &BTreeMap<usize, String>, seed: u64, k: usize) -> EmulatorArgs {
    let mut control = args.control.clone();
    control.no_control |= k > 0;
    EmulatorArgs {
        run_id: args.run_id.as_deref().map(|r| stream_run_id(r, k)),
        scenario: scenarios.get(&k).unwrap_or(&args.scenario).clone(),
        seed: Some(stream_seed(seed, k)),
        return_seed: args.return_seed.map(|s| stream_seed(s, k)),
        out: stream_dir(&args.out, args.stream.streams as usize, k),
        isolate: args.isolate && k == 0,
        control,
        stream: StreamArgs::default(),
        ..args.clone()
    }
}

/// Opens every stream's transports and sets up its loop state.
fn lanes(args: &EmulatorArgs) -> anyhow::Result<Opened> {
    let n = args.stream.streams as usize;
    let mut scenarios = BTreeMap::new();
    for text in &args.stream.stream_scenario {
        let (k, what) = parse_stream_scenario(text, args.stream.streams)?;
        scenarios.insert(k, what);
    }
    let seed = emulator::config(args)?.seed;
    let (mut cfgs, mut lanes, mut nodes) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    for k in 0..n {
        let a = stream_args(args, &scenarios, seed, k);
        let cfg = emulator::config(&a).with_context(|| format!("stream {k}"))?;
        let t = crate::transport::open(&a.ingress, &a.egress, &a.wiring(cfg.queue_capacity)).with_context(|| format!("stream {k}"))?;
        let fb = emulator::feedback_path(&a, &t, cfg.seed, cfg.expected_frames)?;
        let mut fwd = emulator::forward(&cfg, fb)?;
        // One stream's wait for its release would hold up the others.
        fwd.release_spin_ns = 0;
        if k > 0 && cfg.reorder_queue {
            fwd.link.reorder_queue()?;
        }
        eprintln!("emulator: stream {k}: run {} scenario {} seed {}", a.run_id.as_deref().unwrap_or("?"), cfg.scenario.name, cfg.seed);
        cfgs.push(cfg);
        lanes.push(Lane::new(fwd, t.ingress, t.egress));
        nodes.push(t.node);
    }
    Ok((cfgs, lanes, nodes))
}

/// How often each stream's run is searched for dead peers when the
/// emulator stands alone, as the emulator of one stream does.
const REAP_EVERY_NS: u64 = 200_000_000;

/// Each stream's dead peers, found when the emulator stands alone (under
/// `netfi run` the runner reaps, off the loop's core; two reapers may wait
/// on each other). One stream's run is reaped per look, in turn, so a
/// look costs one stream's scan and each stream is reaped every 200 ms.
struct Reaper<'a> {
    nodes: Vec<Option<&'a IpcNode>>,
    next: usize,
    next_ns: u64,
    /// The dead peers found, per stream.
    dead: Vec<Vec<String>>,
}

impl<'a> Reaper<'a> {
    /// A reaper of the streams of `nodes`; one that never reaps unless `alone`.
    fn new(nodes: &'a [Option<IpcNode>], alone: bool) -> Self {
        let dead = vec![Vec::new(); nodes.len()];
        let nodes = if alone { nodes.iter().map(Option::as_ref).collect() } else { Vec::new() };
        Reaper { nodes, next: 0, next_ns: now_ns(), dead }
    }

    /// Reaps the next stream's run if its time has come; marks in
    /// `robot_died` the stream whose robot was found dead. A dead console
    /// is reported, and its stream goes on (a restarted console may take
    /// over).
    fn look(&mut self, robot_died: &mut [bool]) {
        let now = now_ns();
        if self.nodes.is_empty() || now < self.next_ns {
            return;
        }
        let k = self.next;
        self.next = (k + 1) % self.nodes.len();
        self.next_ns = now + REAP_EVERY_NS / self.nodes.len() as u64;
        let Some(Ok(r)) = self.nodes[k].map(IpcNode::reap_dead_peers) else { return };
        for p in r.dead() {
            eprintln!("emulator: stream {k}: a peer died: {p}");
            self.dead[k].push(p.to_string());
            robot_died[k] |= p.role == Some(Role::Simulator);
        }
    }
}

/// `netfi emulator --streams N`: sets up every stream, runs the one loop,
/// writes each stream's report and the joint `emulator.json`; returns
/// stream 0's report.
pub fn main(args: &EmulatorArgs) -> anyhow::Result<EmulatorReport> {
    anyhow::ensure!(args.run_id.is_some(), "--streams needs --run-id");
    crate::service::write_pid(&args.out, "emulator")?;
    let (cfgs, mut lanes, nodes) = lanes(args)?;
    let mut control = emulator::start_control(&cfgs[0], &mut lanes[0].fwd.link)?;
    let mut placement = emulator::place(&cfgs[0], &lanes[0].fwd.link, lanes[0].fwd.feedback.as_deref(), None)?;
    if let Some(core) = cfgs[0].core {
        if let Some((_, h)) = control.as_ref() {
            emulator::warn_unless_off(h.keep_off_core(core), "the control thread", core);
        }
        for l in &lanes[1..] {
            emulator::warn_unless_off(l.fwd.link.keep_trace_off_core(core), "a stream's trace writer", core);
            if let Some(f) = l.fwd.feedback.as_deref() {
                emulator::warn_unless_off(f.keep_trace_off_core(core), "a stream's feedback trace writer", core);
            }
        }
    }
    signals::install();
    std::fs::write(args.out.join("emulator.ready"), b"").context("writing emulator.ready")?;
    let term = nodes[0].as_ref();
    let mut stop = signals::StopCheck::new(256, || term.is_some_and(|n| n.termination_requested()));
    let mut reaper = Reaper::new(&nodes, std::env::var_os(crate::host::isolate::RUNNER_PID_ENV).is_none());
    let look = |died: &mut [bool]| {
        if stop.requested() {
            return Look::Stop;
        }
        reaper.look(died);
        Look::Go
    };
    let steal_timer = StealTimer::start();
    let end = spin(&mut lanes, look, control.as_mut().map(|(p, _)| p));
    let mut events = control.map(|(_, h)| h.finish());
    let mut isolation = placement.isolation.as_mut().map(|iso| iso.restore());
    let steal = steal_timer.stop();
    let dead = reaper.dead;
    let mut reports = Vec::with_capacity(cfgs.len());
    for ((cfg, lane), dead) in cfgs.iter().zip(lanes).zip(dead) {
        let Lane { fwd, mut sink, peer_events, robot_died, .. } = lane;
        // Each stream's own end: a stop, its robot's death, or its end marker.
        let ended_by = match (end.ended_by, robot_died) {
            ("signal", _) => "signal",
            (_, true) => "peer_died",
            _ => "end_marker",
        };
        let own = LoopEnd { ended_by, peer_events, ..end.clone() };
        let mut r = emulator::conclude(cfg, fwd, &mut sink, own, isolation.take(), placement.realtime_priority, steal, events.take().unwrap_or_default())?;
        if !dead.is_empty() {
            r.process.dead_peers = dead;
            let json = cfg.out_dir.join("emulator.json");
            std::fs::write(&json, serde_json::to_vec_pretty(&r)?).with_context(|| format!("writing {}", json.display()))?;
        }
        reports.push(r);
    }
    // The nodes outlive the ports.
    drop(nodes);
    write_joint(args, &cfgs, &reports, end.ended_by)?;
    Ok(reports.swap_remove(0))
}

/// Writes `<out>/emulator.json`, every stream's account and their total.
fn write_joint(args: &EmulatorArgs, cfgs: &[emulator::EmulatorConfig], reports: &[EmulatorReport], ended_by: &str) -> anyhow::Result<()> {
    let run_ids: Vec<String> = (0..reports.len()).map(|k| stream_run_id(args.run_id.as_deref().unwrap_or_default(), k)).collect();
    let dirs: Vec<PathBuf> = cfgs.iter().map(|c| c.out_dir.clone()).collect();
    let mut joint = EmulatorStreams::of(reports, &run_ids, &dirs);
    joint.ended_by = ended_by.to_string();
    let path = args.out.join("emulator.json");
    std::fs::write(&path, serde_json::to_vec_pretty(&joint)?).with_context(|| format!("writing {}", path.display()))?;
    eprintln!(
        "emulator: {} streams: {} entered, {} delivered, {} held at end; balanced {}; ended by {}",
        reports.len(),
        joint.total.entered,
        joint.total.delivered,
        joint.total.held_at_end,
        joint.balanced,
        joint.ended_by
    );
    Ok(())
}

/// Releases every stream's due frames; the earliest release left.
#[inline]
fn release_all<S: FrameSource, K: FrameSink>(lanes: &mut [Lane<S, K>]) -> u64 {
    let now = now_ns();
    let mut next = u64::MAX;
    for l in lanes.iter_mut() {
        l.fwd.link.release_due(now, &mut l.sink);
        next = next.min(l.fwd.link.next_release_ns().unwrap_or(u64::MAX));
    }
    next
}

/// One round of the loop: each stream's turn, stream 0 first; after each
/// turn, if any stream's earliest release is due (a frame just taken with
/// no delay, or another stream's), every stream's due frames go out now,
/// not a round later. `due` is the earliest release of any stream as last
/// seen (`u64::MAX` at first); returns it as the round leaves it. Nothing
/// in it allocates or locks.
#[inline]
pub fn round<S: FrameSource, K: FrameSink>(lanes: &mut [Lane<S, K>], mut due: u64) -> u64 {
    for k in 0..lanes.len() {
        let l = &mut lanes[k];
        l.fwd.turn(&mut l.source, &mut l.sink, None);
        due = due.min(l.fwd.link.next_release_ns().unwrap_or(u64::MAX));
        // The clock read that follows the turn ends it: its busy time is
        // its own, not the other streams' turns after it.
        let now = now_ns();
        l.fwd.end_turn(now);
        if due <= now {
            due = release_all(lanes);
        }
    }
    due
}

/// Turns every stream once per round until each has ended and drained, or
/// a stop is requested; everything else happens every 4096 rounds: live
/// control, the `look` (a stop; each stream whose robot died, marked in
/// the slice it is given), the streams' end, and every 65 536 rounds the
/// peers connected.
fn spin<S: FrameSource, K: FrameSink>(
    lanes: &mut [Lane<S, K>],
    mut look: impl FnMut(&mut [bool]) -> Look,
    mut control: Option<&mut crate::service::control::ControlPort>,
) -> LoopEnd {
    let t_start = now_ns();
    for l in lanes.iter_mut() {
        l.peers = (l.source.peers(), l.sink.peers());
    }
    let mut died = vec![false; lanes.len()];
    let (mut rounds, mut due) = (0u64, u64::MAX);
    let ended_by = loop {
        due = round(lanes, due);
        rounds = rounds.wrapping_add(1);
        if rounds % 4096 != 0 {
            continue;
        }
        if let Some(c) = control.as_deref_mut() {
            c.poll(&mut lanes[0].fwd.link);
        }
        if look(&mut died) == Look::Stop {
            break "signal";
        }
        for (l, d) in lanes.iter_mut().zip(died.iter_mut()) {
            if std::mem::take(d) {
                l.robot_died();
            }
        }
        if rounds % (1 << 16) == 0 {
            let t_s = (now_ns() - t_start) as f64 / 1e9;
            lanes.iter_mut().for_each(|l| l.watch_peers(t_s));
        }
        // Every stream is asked, so each sends its end marker once drained.
        if lanes.iter_mut().fold(true, |all, l| l.finished() && all) {
            break if lanes.iter().any(|l| l.robot_died) { "peer_died" } else { "end_marker" };
        }
    };
    LoopEnd { ended_by, iterations: rounds, t_start, t_end: now_ns(), peer_events: Vec::new() }
}

/// One stream of a run of several, as the run report gives it (its full
/// report is `report_json`, in its directory).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunStream {
    pub stream: usize,
    pub run_id: String,
    pub scenario: String,
    pub seed: u64,
    pub frames: crate::service::report::FrameAccount,
    pub loss_rate: Option<f64>,
    pub loss_rate_ci95: Option<[f64; 2]>,
    pub release_lateness_ns: Option<Summary>,
    pub end_to_end_extra_ns: Option<Summary>,
    pub added_over_direct_ns: Option<BTreeMap<String, i64>>,
    pub faults: Vec<String>,
    pub report_json: PathBuf,
}

/// The streams' frames summed.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StreamsTotal {
    pub sent: u64,
    pub entered: u64,
    pub delivered: u64,
    pub received: u64,
    pub duplicated: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    /// Every stream balanced.
    pub balanced: bool,
    /// Dropped over entered, all streams together.
    pub loss_rate: f64,
    /// The highest of the streams' release lateness p99, ns.
    pub release_lateness_p99_max_ns: Option<u64>,
}

/// `streams` of the run report: each stream and the total.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunStreams {
    pub streams: Vec<RunStream>,
    pub total: StreamsTotal,
}

impl RunStream {
    /// Stream `k`'s line of its own report.
    pub fn of(k: usize, r: &crate::service::report::RunReport) -> RunStream {
        RunStream {
            stream: k,
            run_id: r.run_id.clone(),
            scenario: r.scenario.clone(),
            seed: r.seed,
            frames: r.frames.clone(),
            loss_rate: r.loss_rate,
            loss_rate_ci95: r.loss_rate_ci95,
            release_lateness_ns: r.overhead_ns.release_lateness,
            end_to_end_extra_ns: r.overhead_ns.end_to_end_extra,
            added_over_direct_ns: r.overhead_ns.added_over_direct.clone(),
            faults: r.faults.clone(),
            report_json: r.files.report_json.clone(),
        }
    }
}

impl RunStreams {
    /// The streams' lines and their total.
    pub fn of(streams: Vec<RunStream>) -> RunStreams {
        let mut t = StreamsTotal { balanced: true, ..StreamsTotal::default() };
        for s in &streams {
            let f = &s.frames;
            t.sent += f.sent.unwrap_or(0);
            t.entered += f.entered.unwrap_or(0);
            t.delivered += f.delivered.unwrap_or(0);
            t.received += f.received.unwrap_or(0);
            t.duplicated += f.duplicated.unwrap_or(0);
            t.held_at_end += f.held_at_end.unwrap_or(0);
            for (k, v) in &f.dropped {
                *t.dropped.entry(k.clone()).or_default() += v;
            }
            t.balanced &= f.balanced;
        }
        let dropped: u64 = t.dropped.values().sum();
        t.loss_rate = if t.entered > 0 { dropped as f64 / t.entered as f64 } else { 0.0 };
        t.release_lateness_p99_max_ns = streams.iter().filter_map(|s| s.release_lateness_ns.map(|p| p.p99)).max();
        RunStreams { streams, total: t }
    }

    /// The table of streams, for the text report.
    pub fn to_text(&self) -> String {
        let opt = |v: Option<u64>| v.map_or("?".to_string(), |x| x.to_string());
        let mut s = format!("streams    {} (the figures above are stream 0's)\n", self.streams.len());
        s += "  stream  scenario          sent  entered  delivered  received  dropped  held  loss     lateness p99  balanced\n";
        for st in &self.streams {
            let f = &st.frames;
            s += &format!(
                "  {:<6}  {:<16} {:>6} {:>8} {:>10} {:>9} {:>8} {:>5}  {:<7.4}  {:>12}  {}\n",
                st.stream,
                st.scenario,
                opt(f.sent),
                opt(f.entered),
                opt(f.delivered),
                opt(f.received),
                f.dropped.values().sum::<u64>(),
                opt(f.held_at_end),
                st.loss_rate.unwrap_or(f64::NAN),
                st.release_lateness_ns.map_or("?".into(), |p| crate::metrics::fmt_ns(p.p99)),
                if f.balanced { "yes" } else { "NO" }
            );
        }
        let t = &self.total;
        s += &format!(
            "  total   {:<16} {:>6} {:>8} {:>10} {:>9} {:>8} {:>5}  {:<7.4}  {:>12}  {}\n",
            "",
            t.sent,
            t.entered,
            t.delivered,
            t.received,
            t.dropped.values().sum::<u64>(),
            t.held_at_end,
            t.loss_rate,
            t.release_lateness_p99_max_ns.map_or("?".into(), crate::metrics::fmt_ns),
            if t.balanced { "yes" } else { "NO" }
        );
        s
    }
}
