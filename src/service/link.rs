//! The link: one direction of the emulator, written once. It owns the
//! sans-IO [`Injector`] that decides each frame's fate, the histograms of
//! what the link costs (decision time, release lateness) and what it does
//! (injected delay), the loss interval's batch means, and the per-frame
//! trace. Every direction of the emulator is a path around one link
//! ([`super::emulator::path`]).
//!
//! A link never touches a transport itself: items come in through
//! [`Link::ingress`] (or [`Link::reject`]) with the time they were taken,
//! and leave through [`Link::release_due`] into a [`Release`]. Nothing on that
//! path allocates, locks or makes a system call: the queue is fixed at
//! start-up and the trace goes through a wait-free ring to a writer thread,
//! which streams it (and the histograms' interval logs) to disk.

use crate::check::{stage_reports, LinkSampler};
use crate::clock::now_ns;
use crate::durable::DurableError;
use crate::injector::{BuildError, Entered, Fate, Injector, Invalid};
use crate::metrics::LatencyHistogram;
use crate::model::ModelKind;
use crate::sample::FrameSample;
use crate::scenario::Scenario;
use crate::service::schema::path::{Account, LinkMeasures};
use crate::stats::BatchMeans;
use crate::trace::{self, TraceError, TraceEvent, TraceSink, TraceWriter};
use crate::transport::PortError;
use std::path::{Path, PathBuf};

/// Default release-queue capacity: 65,536 frames (65 s at 1 kHz).
pub const DEFAULT_QUEUE_CAPACITY: usize = 1 << 16;

/// Why a link could not be made.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// A stage the link's items cannot carry ([`Carried::UNSUPPORTED`]).
    #[error(
        "scenario `{scenario}`: the `{stage}` stage is simulated by `netfi scenario check` but not applied on this path (a copy is a second release of the same item, a corruption needs the frame's bytes in the item); remove it from this path's scenario"
    )]
    Unsupported {
        /// The scenario's name.
        scenario: String,
        /// The stage's model.
        stage: &'static str,
    },
    /// The release queue could not be built (its capacity).
    #[error(transparent)]
    Queue(#[from] BuildError),
}

/// A histogram log of a link that could not be written.
#[derive(Debug, thiserror::Error)]
#[error("writing {}: {source}", .path.display())]
pub struct HistogramWriteError {
    /// The log.
    pub path: PathBuf,
    /// The kernel's error.
    #[source]
    pub source: std::io::Error,
}

/// What a link holds in its queue: anything that remembers when it entered.
pub trait Carried: Copy + Default {
    /// The stages a link of these items cannot apply. By default the two
    /// that need the item to be its own bytes: a copy (`duplicate`) is a
    /// second release of the same item, which an item that owns something
    /// released with it (an arena slot) cannot be; a flip (`corrupt`) needs
    /// the frame's bytes in the item.
    const UNSUPPORTED: &'static [ModelKind] = &[ModelKind::Duplicate, ModelKind::Corrupt];

    /// The time the item was taken in, ns.
    fn ingress_ns(&self) -> u64;

    /// Flips the bits `bits` of the item's frame (a `corrupt` stage's,
    /// docs/spec.md §3.9). Called only where `corrupt` is not in
    /// [`Carried::UNSUPPORTED`].
    #[inline]
    fn flip(&mut self, _bits: &[u16]) {}
}

impl Carried for FrameSample {
    /// Copies and flips both apply: the sample holds the whole frame. (Raw
    /// samples, whose bytes live in the UDP bridge's arena, are refused by
    /// the emulator before the link is built.)
    const UNSUPPORTED: &'static [ModelKind] = &[];

    #[inline]
    fn ingress_ns(&self) -> u64 {
        self.ingress_ns
    }

    /// Flips bits of the 124 wire bytes, in place (no allocation).
    #[inline]
    fn flip(&mut self, bits: &[u16]) {
        crate::frame::flip_bits(&mut self.wire[..], bits);
    }
}

/// Where a link's released items go.
pub trait Release<T> {
    /// Sends `item`, due at `scheduled_ns`. Returns the time it went out
    /// (taken as late as possible), or that time and the error.
    fn release(&mut self, item: &T, scheduled_ns: u64) -> Result<u64, (u64, PortError)>;
}

/// What the trace keeps of a frame's arrival, besides the link's own times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Arrival {
    /// The frame's protocol sequence number, when it has one.
    pub sequence: Option<u32>,
    /// The sender's count of the frame.
    pub console_index: u64,
    /// When the sender sent it (or, where the sender does not say, when it
    /// was received), ns.
    pub send_ns: u64,
}

/// One direction of the emulator: scenario, queue, measurements, trace.
pub struct Link<T> {
    inj: Injector<T>,
    trace: TraceSink,
    writer: TraceWriter,
    decision: LatencyHistogram,
    ingress_wait: LatencyHistogram,
    lateness: LatencyHistogram,
    injected: LatencyHistogram,
    batches: BatchMeans,
    send_errors: u64,
    last_error: Option<PortError>,
    /// The histogram logs streamed by the trace writer.
    hlogs: Option<[PathBuf; 2]>,
    /// The link stages' (`rate`, `trace`) queue occupancy, second by second.
    links: LinkSampler,
}

/// The first stage of `scenario` among `unsupported`.
pub fn unsupported_stage(scenario: &Scenario, unsupported: &[ModelKind]) -> Option<ModelKind> {
    scenario.phases().iter().flat_map(|p| p.stages()).map(|s| s.kind()).find(|k| unsupported.contains(k))
}

impl<T: Carried> Link<T> {
    /// A link through `scenario` holding at most `queue_capacity` items;
    /// `expected_frames` sizes the trace table and the loss interval's
    /// batches (a guess is fine). Starts the trace's writer thread: create
    /// the link before pinning the loop's core, then
    /// [`keep_trace_off_core`](Self::keep_trace_off_core).
    /// A capacity out of range is an error that names the field and the
    /// memory it would need; so is a stage this link's items cannot carry
    /// ([`Carried::UNSUPPORTED`]).
    pub fn new(scenario: Scenario, queue_capacity: usize, expected_frames: u64) -> Result<Link<T>, LinkError> {
        if let Some(kind) = unsupported_stage(&scenario, T::UNSUPPORTED) {
            return Err(LinkError::Unsupported { scenario: scenario.name().to_string(), stage: kind.name() });
        }
        let rows = expected_frames.min(50_000_000) as usize;
        let copies = if unsupported_stage(&scenario, &[ModelKind::Duplicate]).is_some() { rows } else { 0 };
        // Room for a day of occupancy per link stage, reserved (its pages
        // are touched only as seconds pass): no allocation while sampling.
        let links = LinkSampler::new(&scenario, crate::check::MAX_OCCUPANCY_SECONDS);
        let inj = Injector::try_new(scenario, queue_capacity)?;
        let (trace, writer) = trace::start(rows, copies);
        Ok(Link {
            inj,
            trace,
            writer,
            decision: LatencyHistogram::new(),
            ingress_wait: LatencyHistogram::new(),
            lateness: LatencyHistogram::new(),
            injected: LatencyHistogram::new(),
            batches: BatchMeans::new(expected_frames.max(1)),
            send_errors: 0,
            last_error: None,
            hlogs: None,
            links,
        })
    }

    /// Keeps the trace's writer thread off `core` (the loop's); `false`
    /// where it may use no other core.
    pub fn keep_trace_off_core(&self, core: usize) -> bool {
        self.writer.keep_off_core(core)
    }

    /// Asks the trace writer to finish once it has written what was pushed
    /// so far, without waiting ([`TraceWriter::close`]); push nothing
    /// after. [`Link::finish`] then waits for it.
    pub fn close_trace(&self) {
        self.writer.close();
    }

    /// The ingress index the next frame will get.
    #[inline]
    pub fn next_ingress_index(&self) -> u64 {
        self.inj.next_ingress_index()
    }

    /// Items scheduled and not yet released.
    #[inline]
    pub fn held(&self) -> usize {
        self.inj.held()
    }

    /// The scenario, with its stages' counts.
    pub fn scenario(&self) -> &Scenario {
        self.inj.scenario()
    }

    /// The injector, for live control ([`super::control::ControlPort`]).
    pub fn injector_mut(&mut self) -> &mut Injector<T> {
        &mut self.inj
    }

    /// Rebuilds the (still unused) release queue as a reorder queue, so that
    /// the run can be switched to a scenario that reorders.
    pub fn reorder_queue(&mut self) -> Result<(), BuildError> {
        let (scenario, capacity) = (self.inj.scenario().clone(), self.inj.queue_capacity());
        self.inj = Injector::try_with_order(scenario, capacity, crate::scheduler::QueueOrder::Reorder)?;
        Ok(())
    }

    /// Hands the trace's events to `tap` as well (on the writer thread).
    pub fn tap_trace(&self, tap: Box<dyn crate::trace::Tap>) {
        self.writer.tap(tap);
    }

    /// An item taken in at `now`: its fate is decided and, if it survives,
    /// it is queued. The caller frees whatever a dropped item holds.
    /// Bits a `corrupt` stage flips are applied to the item (and to each
    /// copy its own) before it is queued; each copy a `duplicate` stage
    /// makes is queued under the same ingress index and released as an
    /// item of its own.
    #[inline]
    pub fn ingress(&mut self, now: u64, item: T, arrival: Arrival) -> Entered {
        self.ingress_len(now, item, None, arrival)
    }

    /// [`Link::ingress`] for a payload of `len` bytes when given (the link
    /// stages cut it into packets of their MTU: variable-size payloads).
    #[inline]
    pub fn ingress_len(&mut self, now: u64, item: T, len: Option<u64>, arrival: Arrival) -> Entered {
        let entered = self.inj.ingress_len_with(now, item, len, |it, flips| it.flip(flips.bits()));
        if !self.links.is_empty() {
            self.links.sample(self.inj.scenario(), now);
        }
        let copies = self.inj.scenario().copies();
        // Copies a later stage or a full queue dropped.
        let copies_dropped = (copies.made() - u64::from(entered.copies)) as u8;
        // The loss figure is over the frames the scenario decided: a
        // malformed frame ([`Link::reject`]) never reached it.
        self.batches.record(matches!(entered.fate, Fate::Dropped(_)));
        self.record(now, entered, arrival, copies_dropped);
        for k in 0..usize::from(entered.copies) {
            // The copies that fit the queue are the first ones made: once
            // it is full, it stays full for the rest of this frame.
            let copies = self.inj.scenario().copies();
            self.trace.push(TraceEvent::Copy {
                ingress_index: entered.ingress_index,
                copy: k as u8 + 1,
                release_sched_ns: now.saturating_add(copies.delays_ns()[k]),
                corrupted: !copies.flips()[k].is_empty(),
            });
        }
        entered
    }

    /// A frame taken in at `now` that is invalid: it enters and is dropped
    /// for `why`.
    #[inline]
    pub fn reject(&mut self, now: u64, why: Invalid, arrival: Arrival) -> Entered {
        let entered = self.inj.reject(now, why);
        self.record(now, entered, arrival, 0);
        entered
    }

    #[inline]
    fn record(&mut self, now: u64, entered: Entered, a: Arrival, copies_dropped: u8) {
        let decision_ns = now_ns().saturating_sub(now);
        self.decision.record(decision_ns);
        self.ingress_wait.record(now.saturating_sub(a.send_ns));
        let (dropped, release_sched_ns) = match entered.fate {
            Fate::Scheduled { release_ns, .. } => (None, release_ns),
            Fate::Dropped(cause) => (Some(cause), 0),
        };
        self.trace.push(TraceEvent::Ingress {
            ingress_index: entered.ingress_index,
            sequence: a.sequence,
            console_index: a.console_index,
            send_ns: a.send_ns,
            ingress_ns: now,
            dropped,
            release_sched_ns,
            decision_ns,
            copies: entered.copies,
            copies_dropped,
            corrupted: entered.corrupted,
        });
    }

    /// Releases into `sink` every item due at `now`, oldest first.
    #[inline]
    pub fn release_due(&mut self, now: u64, sink: &mut impl Release<T>) {
        while let Some(r) = self.inj.pop_due_ref(now) {
            let release_ns = match sink.release(r.item, r.release_ns) {
                Ok(t) => t,
                Err((t, e)) => {
                    self.send_errors += 1;
                    self.last_error = Some(e);
                    t
                }
            };
            self.lateness.record(release_ns.saturating_sub(r.release_ns));
            self.injected.record(r.release_ns - r.item.ingress_ns());
            self.trace.push(TraceEvent::Release { ingress_index: r.ingress_index, release_sched_ns: r.release_ns, release_ns });
        }
    }

    /// The earliest scheduled release, if an item is held.
    #[inline]
    pub fn next_release_ns(&self) -> Option<u64> {
        self.inj.next_release_ns()
    }

    /// Items released so far.
    pub fn released(&self) -> u64 {
        self.inj.counts().released
    }

    /// Streams the trace to `trace_path` as the run goes, and, with
    /// `hlog_dir`, the decision-time and release-lateness histograms as
    /// interval logs `decision.hlog` and `lateness.hlog` there (one
    /// interval per second). Call once, before the loop starts.
    pub fn stream_to(&mut self, trace_path: &Path, hlog_dir: Option<&Path>) -> Result<(), DurableError> {
        self.hlogs = self.writer.stream_to(trace_path, hlog_dir)?;
        Ok(())
    }

    /// The decision-time and release-lateness histogram logs
    /// `decision.hlog` and `lateness.hlog` in `out_dir`: the interval logs
    /// streamed there, or else the run's totals written now as one
    /// interval each. Returns their paths.
    pub fn write_histograms(&self, out_dir: &Path, duration_s: f64) -> Result<(PathBuf, PathBuf), HistogramWriteError> {
        if let Some([d, l]) = &self.hlogs {
            return Ok((d.clone(), l.clone()));
        }
        let (decision, lateness) = (out_dir.join("decision.hlog"), out_dir.join("lateness.hlog"));
        for (h, path, tag) in [(&self.decision, &decision, "decision"), (&self.lateness, &lateness, "release_lateness")] {
            h.write_log(path, tag, 0.0, duration_s).map_err(|source| HistogramWriteError { path: path.clone(), source })?;
        }
        Ok((decision, lateness))
    }

    /// Stops the trace writer, writes the trace to `trace_path`, checks
    /// that every item is accounted for, and reports. `duration_ns` is the
    /// time the link ran (for the stages' model rates).
    pub fn finish(self, trace_path: &Path, duration_ns: u64) -> Result<LinkEnd, TraceError> {
        let counts = self.inj.counts();
        assert!(counts.balanced(), "frame accounting broken: {counts:?}");
        let written = self.writer.finish(trace_path)?;
        let unseen = crate::check::unseen_loss_rate(self.inj.scenario(), self.batches.trials());
        let (loss_rate, loss_rate_ci95) = self.batches.rate_ci95_with(unseen);
        let interval_ns = if counts.entered > 1 { duration_ns as f64 / counts.entered as f64 } else { 0.0 };
        let (stages, _) = stage_reports(self.inj.scenario(), interval_ns);
        Ok(LinkEnd {
            scenario: self.inj.scenario().name().to_string(),
            queue_order: format!("{:?}", self.inj.queue_order()).to_lowercase(),
            queue_capacity: self.inj.queue_capacity(),
            account: Account {
                entered: counts.entered,
                delivered: counts.released,
                duplicated: counts.duplicated,
                corrupted: counts.corrupted,
                corrupted_delivered: written.corrupted_released,
                dropped: self.inj.drops_by_reason().into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
                held_at_end: counts.held,
            },
            measures: LinkMeasures {
                loss_rate,
                loss_rate_ci95,
                loss_rate_unseen_model: (unseen > 0.0).then_some(unseen),
                stages,
                injected_delay_ns: self.injected.summary(),
                ingress_wait_ns: self.ingress_wait.summary(),
                decision_ns: self.decision.summary(),
                release_lateness_ns: self.lateness.summary(),
                links: self.links.reports(self.inj.scenario()),
            },
            send_errors: self.send_errors,
            last_error: self.last_error,
            trace_overflowed: self.trace.overflowed(),
            trace_path: trace_path.to_path_buf(),
        })
    }
}

/// What a link did, at its end: its account and measures, and what its
/// sends and trace met.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkEnd {
    pub scenario: String,
    pub queue_order: String,
    pub queue_capacity: usize,
    pub account: Account,
    pub measures: LinkMeasures,
    pub send_errors: u64,
    /// The last send error, for the log.
    pub last_error: Option<PortError>,
    pub trace_overflowed: u64,
    pub trace_path: PathBuf,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sample::FrameSample;

    #[test]
    fn items_that_cannot_carry_copies_or_flips_refuse_those_stages_by_name() {
        #[derive(Clone, Copy, Default)]
        struct Slot(u64);
        impl Carried for Slot {
            fn ingress_ns(&self) -> u64 {
                self.0
            }
        }
        for model in ["duplicate", "corrupt"] {
            let text = format!("name = \"x\"\n[[stage]]\nmodel = \"{model}\"\np = 0.1\n");
            let spec = crate::scenario::parse_str(&text, "x.toml", "x").unwrap();
            let err = Link::<Slot>::new(Scenario::new(&spec, 1).unwrap(), 16, 16).err().expect("refused");
            assert!(err.to_string().contains(&format!("`{model}` stage")), "{err}");
            // A sample holds its frame's bytes: both apply.
            assert!(Link::<FrameSample>::new(Scenario::new(&spec, 1).unwrap(), 16, 16).is_ok());
        }
        let spec = crate::scenario::parse_str("name = \"ok\"\n[[stage]]\npreset = \"PLM-2\"\n", "ok.toml", "ok").unwrap();
        assert!(Link::<Slot>::new(Scenario::new(&spec, 1).unwrap(), 16, 16).is_ok());
    }

    /// Releases into a vector.
    struct Collect(Vec<FrameSample>);
    impl Release<FrameSample> for Collect {
        fn release(&mut self, item: &FrameSample, _scheduled_ns: u64) -> Result<u64, (u64, PortError)> {
            self.0.push(*item);
            Ok(now_ns())
        }
    }

    #[test]
    fn copies_are_released_as_frames_and_flips_reach_the_bytes() {
        let text = "name = \"dc\"\n[[stage]]\nmodel = \"duplicate\"\np = 0.3\n[[stage]]\nmodel = \"corrupt\"\np = 0.4\n[[stage]]\nmodel = \"bernoulli\"\np = 0.1\n";
        let spec = crate::scenario::parse_str(text, "dc.toml", "dc").unwrap();
        let mut link = Link::<FrameSample>::new(Scenario::new(&spec, 7).unwrap(), 1 << 12, 4000).unwrap();
        let mut clean = FrameSample::ZERO;
        clean.wire = crate::check::synthetic_frame();
        clean.len = crate::sample::ITP_FRAME_LEN as u32;
        let mut out = Collect(Vec::new());
        let n = 3000u64;
        for i in 0..n {
            let mut s = clean;
            s.ingress_index = i;
            link.ingress(i, s, Arrival { sequence: None, console_index: i, send_ns: i });
            link.release_due(u64::MAX, &mut out);
        }
        let dir = std::env::temp_dir().join(format!("netfi-link-dc-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("trace.csv");
        let r = link.finish(&path, n).unwrap();
        let r = r.account;
        let dropped = r.dropped_total();
        assert!(r.closes());
        assert_eq!(out.0.len() as u64, r.delivered);
        assert!(r.delivered > r.entered - dropped, "copies add releases: {r:?}");
        let flipped = out.0.iter().filter(|s| s.wire != clean.wire).count() as u64;
        assert_eq!(flipped, r.corrupted_delivered);
        assert_eq!(r.corrupted, r.corrupted_delivered);
        // The trace: one row per frame and per copy taken, fates exact.
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        let rows: Vec<Vec<&str>> = text.lines().skip(1).map(|l| l.split(',').collect()).collect();
        let originals = rows.iter().filter(|c| c[13] == "0").count() as u64;
        let copy_rows = rows.len() as u64 - originals;
        let copies_dropped: u64 = rows.iter().filter_map(|c| c[14].parse::<u64>().ok()).sum();
        assert_eq!(originals, r.entered);
        assert_eq!(copy_rows + copies_dropped, r.duplicated);
        assert_eq!(rows.iter().filter(|c| c[5] == "delivered").count() as u64, r.delivered);
        assert_eq!(rows.iter().filter(|c| c[5] == "delivered" && c[15] == "1").count() as u64, r.corrupted_delivered);
    }
}
