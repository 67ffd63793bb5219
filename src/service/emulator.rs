//! The emulator service: takes frames off the console port, decides each
//! one's fate with the sans-IO [`Injector`], holds survivors in its
//! preallocated release queue, and busy-waits to release each at its
//! scheduled time onto the simulator port.
//!
//! The loop, pinned to one core, does per iteration: release every frame
//! that is due; take at most one frame from the console port and decide it;
//! every 4096 iterations, look at the stop flag and the peers. Nothing in it
//! allocates, locks or makes a system call beyond the transport's own (the
//! clock is the vDSO's); the per-frame trace goes through a wait-free ring to
//! a writer thread.

use crate::check::{stage_reports, StageReport};
use crate::clock::now_ns;
use crate::frame::ItpView;
use crate::host::isolate::IsolationSummary;
use crate::host::StealTimer;
use crate::injector::{Fate, Injector, Invalid};
use crate::metrics::{LatencyHistogram, Summary};
use crate::sample::{FrameSample, ITP_FRAME_LEN};
use crate::scenario::{Scenario, ScenarioSpec};
use crate::service::ports::{FrameSink, FrameSource, PortError};
use crate::service::signals;
use crate::stats::BatchMeans;
use crate::trace::{self, TraceEvent};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// How the emulator is set up.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    pub scenario: ScenarioSpec,
    pub seed: u64,
    pub queue_capacity: usize,
    /// Core to pin the loop to (`None`: not pinned).
    pub core: Option<usize>,
    /// Drop frames whose ITP checksum does not match (else count and pass).
    pub drop_bad_checksum: bool,
    /// Frames expected, to size the trace table and the loss interval's
    /// batches (a guess is fine).
    pub expected_frames: u64,
    /// Where the trace, histograms and report go.
    pub out_dir: PathBuf,
    /// Run the loop at this SCHED_FIFO priority (needs root or CAP_SYS_NICE).
    pub rt_priority: Option<i32>,
    /// Clear the loop's core of other processes' threads, movable kernel
    /// threads and device interrupts for the run ([`crate::host::isolate`]).
    pub isolate: bool,
}

/// A change in a peer's presence, seen by the emulator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PeerEvent {
    /// Seconds since the emulator started.
    pub t_s: f64,
    /// `console` or `simulator`.
    pub peer: String,
    /// Connected peers now.
    pub connected: usize,
}

/// Frame accounting: `entered = delivered + dropped + held_at_end`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorFrames {
    pub entered: u64,
    pub delivered: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    /// Frames the console said it sent (from its end marker), if it ended.
    pub sent_by_console: Option<u64>,
    /// Frames that passed with a wrong checksum (when not dropped for it).
    pub bad_checksum_passed: u64,
}

/// The emulator's own report, written as `emulator.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorReport {
    pub scenario: String,
    pub seed: u64,
    pub core: Option<usize>,
    /// SCHED_FIFO priority the loop ran at, if any.
    pub realtime_priority: Option<i32>,
    /// What was moved off the loop's core for the run (`--isolate`), and
    /// put back after.
    #[serde(default)]
    pub isolation: Option<IsolationSummary>,
    pub queue_order: String,
    pub queue_capacity: usize,
    pub frames: EmulatorFrames,
    pub loss_rate: f64,
    pub loss_rate_ci95: [f64; 2],
    pub stages: Vec<StageReport>,
    /// Injected delay of delivered frames.
    pub injected_delay_ns: Summary,
    /// Console send → frame taken off the console port (the first hop plus
    /// any time the frame waited in the port for the emulator).
    pub ingress_wait_ns: Summary,
    /// Frame taken off the console port → fate decided.
    pub decision_ns: Summary,
    /// Actual − scheduled release.
    pub release_lateness_ns: Summary,
    pub peer_events: Vec<PeerEvent>,
    /// Why the loop ended: `end_marker` (the console finished and every held
    /// frame was released) or `signal`.
    pub ended_by: String,
    pub duration_s: f64,
    /// Turns of the busy loop, and the mean time of one: how often it looked
    /// for due releases and for a new frame.
    #[serde(default)]
    pub loop_iterations: u64,
    #[serde(default)]
    pub loop_iteration_ns_mean: f64,
    pub receive_errors: u64,
    pub send_errors: u64,
    pub trace_overflowed: u64,
    pub steal_ms: u64,
    pub steal_fraction: f64,
    pub trace_path: Option<PathBuf>,
    pub decision_hlog: Option<PathBuf>,
    pub lateness_hlog: Option<PathBuf>,
}

/// Where an isolating emulator keeps what it moved until it has put it
/// back, in its output directory; the runner restores from it when the
/// emulator died first.
pub const ISOLATION_STATE_FILE: &str = "isolation.json";

/// Runs the emulator until the console's end marker has been seen and every
/// held frame released, or until a stop is requested (SIGINT/SIGTERM). Then
/// writes `trace_emulator.csv`, `decision.hlog`, `lateness.hlog` and
/// `emulator.json` into `out_dir`, and returns the report.
/// `stop_requested` is polled off the hot path (every 4096 iterations).
pub fn run<S: FrameSource, K: FrameSink>(
    cfg: &EmulatorConfig,
    source: &mut S,
    sink: &mut K,
    mut stop_requested: impl FnMut() -> bool,
) -> anyhow::Result<EmulatorReport> {
    use anyhow::Context;
    std::fs::create_dir_all(&cfg.out_dir).with_context(|| format!("creating {}", cfg.out_dir.display()))?;
    let scenario = Scenario::new(&cfg.scenario, cfg.seed)?;
    let mut inj: Injector<FrameSample> = Injector::new(scenario, cfg.queue_capacity);
    // The writer thread starts before pinning, and is then kept off the
    // loop's core, so it runs elsewhere and never preempts the loop.
    let (mut tsink, twriter) = trace::start(cfg.expected_frames.min(50_000_000) as usize);
    if let Some(core) = cfg.core {
        let ok = core_affinity::set_for_current(core_affinity::CoreId { id: core });
        anyhow::ensure!(ok, "could not pin the emulator to core {core}");
        twriter.keep_off_core(core);
    }
    // After pinning: the loop's own threads are placed; everything else that
    // may run elsewhere leaves the core until the run ends.
    let mut isolation = match (cfg.isolate, cfg.core) {
        (true, Some(core)) => match crate::host::isolate::isolate(core, Some(&cfg.out_dir.join(ISOLATION_STATE_FILE))) {
            Ok(iso) => {
                eprintln!("emulator: {}", iso.summary());
                Some(iso)
            }
            Err(e) => {
                eprintln!("emulator: WARNING: could not clear core {core}: {e}");
                Some(crate::host::isolate::Isolation::not_cleared(core, format!("could not clear core {core}: {e}")))
            }
        },
        (true, None) => {
            let why = crate::host::isolate::pin_problem().unwrap_or_else(|| "--isolate needs a pinned core; nothing cleared".into());
            eprintln!("emulator: WARNING: {why}");
            Some(crate::host::isolate::Isolation::not_cleared(0, why))
        }
        _ => None,
    };
    let realtime_priority = match cfg.rt_priority {
        Some(p) => match crate::service::set_realtime(p) {
            Ok(()) => {
                if let Some((runtime, period)) = crate::service::rt_throttling() {
                    eprintln!(
                        "emulator: WARNING: real-time throttling is on (kernel.sched_rt_runtime_us = {runtime} of {period}): this busy loop at SCHED_FIFO will be stopped for {} ms of every {} ms; set it to -1, or use --isolate without --rt-priority",
                        (period - runtime) / 1000,
                        period / 1000
                    );
                }
                Some(p)
            }
            Err(e) => {
                eprintln!("emulator: staying at normal priority: SCHED_FIFO {p} refused ({e})");
                None
            }
        },
        None => None,
    };
    let mut decision = LatencyHistogram::new();
    let mut ingress_wait = LatencyHistogram::new();
    let mut lateness = LatencyHistogram::new();
    let mut injected = LatencyHistogram::new();
    let mut batches = BatchMeans::new(cfg.expected_frames.max(1));
    let mut bad_checksum_passed = 0u64;
    let mut receive_errors = 0u64;
    let mut send_errors = 0u64;
    let mut last_error: Option<PortError> = None;
    let mut sent_by_console = None;
    let mut peer_events = Vec::new();
    let mut peers = (source.peers(), sink.peers());
    let steal_timer = StealTimer::start();
    let t_start = now_ns();
    let mut sample = FrameSample::ZERO;
    let mut iter: u64 = 0;
    let ended_by = loop {
        // 1. Every release that is due, oldest first.
        let now = now_ns();
        while let Some(r) = inj.pop_due(now) {
            let mut release_ns = 0;
            let sent = sink.send_with(&r.item, |s| {
                s.release_sched_ns = r.release_ns;
                s.injected_delay_ns = r.release_ns - s.ingress_ns;
                release_ns = now_ns();
                s.release_ns = release_ns;
            });
            if let Err(e) = sent {
                send_errors += 1;
                last_error = Some(e);
                release_ns = now_ns();
            }
            lateness.record(release_ns.saturating_sub(r.release_ns));
            injected.record(r.release_ns - r.item.ingress_ns);
            tsink.push(TraceEvent::Release { ingress_index: r.ingress_index, release_ns });
        }
        // 2. At most one frame in.
        match source.try_recv(&mut sample) {
            Ok(true) if sample.is_end() => sent_by_console = Some(sample.console_index),
            Ok(true) => {
                let t_take = now_ns();
                let index = inj.next_ingress_index();
                sample.ingress_index = index;
                sample.ingress_ns = t_take;
                let (entered, sequence) = match classify(&sample, cfg.drop_bad_checksum) {
                    Ok(seq) => {
                        if seq.1 {
                            bad_checksum_passed += 1;
                        }
                        (inj.ingress(t_take, sample), Some(seq.0))
                    }
                    Err((why, seq)) => (inj.reject(t_take, why), seq),
                };
                let t_decided = now_ns();
                decision.record(t_decided - t_take);
                ingress_wait.record(t_take.saturating_sub(sample.send_ns));
                let (dropped, release_sched_ns) = match entered.fate {
                    Fate::Scheduled { release_ns, .. } => (None, release_ns),
                    Fate::Dropped(c) => {
                        source.dropped(&sample);
                        (Some(c), 0)
                    }
                };
                batches.record(dropped.is_some());
                tsink.push(TraceEvent::Ingress {
                    ingress_index: index,
                    sequence,
                    console_index: sample.console_index,
                    send_ns: sample.send_ns,
                    ingress_ns: t_take,
                    dropped,
                    release_sched_ns,
                });
            }
            Ok(false) => {}
            Err(e) => {
                receive_errors += 1;
                last_error = Some(e);
            }
        }
        // 3. Housekeeping, off the per-frame path.
        iter = iter.wrapping_add(1);
        if iter % 4096 == 0 {
            if stop_requested() {
                break "signal";
            }
            if sent_by_console.is_some() && inj.held() == 0 {
                break "end_marker";
            }
            if iter % (1 << 16) == 0 {
                let now_peers = (source.peers(), sink.peers());
                let t_s = (now_ns() - t_start) as f64 / 1e9;
                if now_peers.0 != peers.0 {
                    peer_events.push(PeerEvent { t_s, peer: "console".into(), connected: now_peers.0.unwrap_or(0) });
                }
                if now_peers.1 != peers.1 {
                    peer_events.push(PeerEvent { t_s, peer: "simulator".into(), connected: now_peers.1.unwrap_or(0) });
                }
                peers = now_peers;
            }
        }
    };
    let t_end = now_ns();
    let isolation = isolation.as_mut().map(|iso| iso.restore());
    // Tell the simulator the stream ended (best effort: it may be gone).
    let counts = inj.counts();
    let _ = sink.send_with(&FrameSample::end_marker(counts.released), |_| {});
    if let Some(e) = &last_error {
        eprintln!("emulator: last transport error: {e}");
    }
    let rows = twriter.finish();
    let trace_path = cfg.out_dir.join("trace_emulator.csv");
    trace::write_csv(&trace_path, &rows, &[]).with_context(|| format!("writing {}", trace_path.display()))?;
    let duration_s = (t_end - t_start) as f64 / 1e9;
    let decision_hlog = cfg.out_dir.join("decision.hlog");
    let lateness_hlog = cfg.out_dir.join("lateness.hlog");
    decision.write_log(&decision_hlog, "decision", 0.0, duration_s)?;
    lateness.write_log(&lateness_hlog, "release_lateness", 0.0, duration_s)?;
    let steal = steal_timer.stop();
    let (loss_rate, loss_rate_ci95) = batches.rate_ci95();
    let interval_ns = if counts.entered > 1 { (t_end - t_start) as f64 / counts.entered as f64 } else { 0.0 };
    let (stages, _) = stage_reports(inj.scenario(), interval_ns);
    let report = EmulatorReport {
        scenario: inj.scenario().name().to_string(),
        seed: cfg.seed,
        core: cfg.core,
        realtime_priority,
        isolation,
        queue_order: format!("{:?}", inj.queue_order()).to_lowercase(),
        queue_capacity: inj.queue_capacity(),
        frames: EmulatorFrames {
            entered: counts.entered,
            delivered: counts.released,
            dropped: inj.drops_by_reason().into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
            held_at_end: counts.held,
            sent_by_console,
            bad_checksum_passed,
        },
        loss_rate,
        loss_rate_ci95,
        stages,
        injected_delay_ns: injected.summary(),
        ingress_wait_ns: ingress_wait.summary(),
        decision_ns: decision.summary(),
        release_lateness_ns: lateness.summary(),
        peer_events,
        ended_by: ended_by.to_string(),
        duration_s,
        loop_iterations: iter,
        loop_iteration_ns_mean: if iter > 0 { (t_end - t_start) as f64 / iter as f64 } else { 0.0 },
        receive_errors,
        send_errors,
        trace_overflowed: tsink.overflowed(),
        steal_ms: steal.ms,
        steal_fraction: steal.fraction,
        trace_path: Some(trace_path),
        decision_hlog: Some(decision_hlog),
        lateness_hlog: Some(lateness_hlog),
    };
    assert!(counts.balanced(), "frame accounting broken: {counts:?}");
    let json = cfg.out_dir.join("emulator.json");
    std::fs::write(&json, serde_json::to_vec_pretty(&report)?).with_context(|| format!("writing {}", json.display()))?;
    Ok(report)
}

/// Checks size and checksum. `Ok((sequence, checksum_bad))` for a frame to
/// decide; `Err` for one to reject, with its sequence if readable.
#[inline]
fn classify(s: &FrameSample, drop_bad_checksum: bool) -> Result<(u32, bool), (Invalid, Option<u32>)> {
    if s.is_raw() {
        // An opaque datagram: no protocol to check; its "sequence" is its console index.
        return Ok((s.console_index as u32, false));
    }
    if s.len as usize != ITP_FRAME_LEN {
        return Err((Invalid::WrongSize, None));
    }
    let view = ItpView::new_unchecked(&s.wire[..]);
    let seq = view.sequence();
    let bad = !view.verify_checksum();
    if bad && drop_bad_checksum {
        return Err((Invalid::BadChecksum, Some(seq)));
    }
    Ok((seq, bad))
}

/// Wires the emulator: arguments → scenario → ports → [`run`]. The ports
/// are iceoryx2's unless `--ingress` or `--egress` names a UDP endpoint
/// (then [`crate::service::udp::main`] wires them).
pub fn main(args: &crate::service::args::EmulatorArgs) -> anyhow::Result<EmulatorReport> {
    use anyhow::Context;
    let spec = crate::scenario::resolve(&args.scenario)?;
    let seed = args.seed.or(spec.seed).unwrap_or_else(crate::service::run::fresh_seed);
    let default_capacity = match args.payload {
        crate::service::udp::Payload::Raw => crate::service::udp::RAW_DEFAULT_QUEUE_CAPACITY,
        crate::service::udp::Payload::Itp => crate::service::run::DEFAULT_QUEUE_CAPACITY,
    };
    let queue_capacity = args.queue_capacity.or(spec.queue_capacity).unwrap_or(default_capacity);
    anyhow::ensure!(queue_capacity >= 1, "--queue-capacity must be at least 1 frame");
    let core = if args.no_pin {
        None
    } else {
        args.core.or_else(|| core_affinity::get_core_ids().and_then(|c| c.last().map(|c| c.id)))
    };
    crate::service::write_pid(&args.out, "emulator")?;
    let cfg = EmulatorConfig {
        scenario: spec,
        seed,
        queue_capacity,
        core,
        drop_bad_checksum: args.drop_bad_checksum,
        expected_frames: args.expected_frames,
        out_dir: args.out.clone(),
        rt_priority: args.rt_priority,
        isolate: args.isolate,
    };
    if args.ingress.is_udp() || args.egress.is_udp() {
        return crate::service::udp::main(args, cfg);
    }
    let run_id = args.run_id.as_deref().context("--run-id is required with the iceoryx2 ingress and egress")?;
    let node = crate::service::ipc::open_node(run_id, crate::transport::Role::Emulator)?;
    let mut source = node.subscriber(crate::transport::Channel::Console).context("opening the console → emulator port")?;
    let mut sink = node.publisher(crate::transport::Channel::Emulator).context("opening the emulator → simulator port")?;
    signals::install();
    eprintln!("emulator: scenario {} seed {seed}, queue {queue_capacity}, core {core:?}", cfg.scenario.name);
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    std::fs::write(args.out.join("emulator.ready"), b"").context("writing emulator.ready")?;
    // Polled every 4096 iterations; iceoryx2's own latch every 256th time.
    let mut stop = signals::StopCheck::new(256, || node.termination_requested());
    run(&cfg, &mut source, &mut sink, || stop.requested())
}
