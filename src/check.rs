//! The simulated-time checker: runs a scenario through the injector over a
//! sequence of arrival times, with no clock, and reports what it realizes.
//!
//! Definitions used in the report:
//! - `loss_rate`: dropped / frames, with a 95% batch-means interval
//!   ([`crate::stats::BatchMeans`]) that accounts for bursts, its upper
//!   end raised by `loss_rate_unseen_model` ([`unseen_loss_rate`]): the
//!   loss in bursts longer than the run likely met, which heavy-tailed
//!   burst laws (`ge_lomax` with `α < 2`: infinite variance) hide from any
//!   spread of the run's own.
//! - `loss_run_mean`: mean length of maximal runs of consecutive dropped
//!   frames, in ingress order.
//! - `delay_ms`: the injected delay of delivered frames (release − ingress);
//!   mean, max and quantiles exact (the quantile `q` of `n` delays is the
//!   one of rank `max(1, ⌈q·n⌉)`). Beyond [`crate::stats::EXACT_VALUES_MAX`]
//!   delivered frames the quantiles come from an HDR histogram over every
//!   `u64`, and `delay_ms.error_fraction_max` says how far above the exact
//!   value they may be.
//! - `reordered_fraction`: delivered frames released after a frame that
//!   entered later (RFC 4737's reordered packets), over delivered frames.
//! - `outages`: windows opened by `outage` stages, and their mean length.
//! - `duplicated`: copies made by `duplicate` stages (only when there are
//!   any). Each copy is released or dropped like a frame, so
//!   `frames + duplicated = delivered + Σ dropped`, and `delivered` counts
//!   copies; `loss_rate`, `delay_ms` and `loss_run_mean` are over the
//!   original frames.
//! - `corruption`: delivered frames (originals and copies) that `corrupt`
//!   stages asked to flip bits in, and how many of those the ITP checksum
//!   catches or passes, found by applying the flips to a synthetic sealed
//!   frame ([`synthetic_frame`]) with [`crate::frame::checksum_catches`]
//!   (only when the scenario corrupts).
//! - `links`: each link stage's frames: admitted, dropped for its queue,
//!   and of the admitted those dropped after it (by a later stage or the
//!   release queue), so the section agrees with the frames' fates; its
//!   time-at-stage percentiles are HDR (`error_fraction_max`).
//! - `stages[].recording`: what a `replay` stage replays, and in which
//!   layout it was read.

use crate::injector::{Entered, Fate, Injector};
use crate::scenario::Scenario;
use crate::scheduler::Released;
use crate::stats::{BatchMeans, Quantiles, HDR_ERROR_FRACTION_MAX};
use serde::Serialize;
use std::collections::BTreeMap;

/// When frames arrive.
#[derive(Debug, Clone)]
pub enum Arrivals {
    /// `frames` frames at a fixed rate, the first at time 0.
    Rate { frames: u64, rate_hz: f64 },
    /// Explicit arrival times in ns, non-decreasing (e.g. a real capture).
    Times(Vec<u64>),
}

/// The slowest command rate simulated arrivals accept, in Hz.
pub const MIN_RATE_HZ: f64 = 0.1;
/// The fastest command rate simulated arrivals accept, in Hz: a frame every
/// microsecond.
pub const MAX_RATE_HZ: f64 = 1e6;
/// The longest span of simulated arrivals: one year, in seconds (as a phase
/// start, docs/spec.md §1).
pub const MAX_SPAN_S: f64 = crate::model::units::MAX_PHASE_START_MS / 1e3;

impl Arrivals {
    /// `frames` frames at `rate_hz`, checked against the physical range: a
    /// rate from [`MIN_RATE_HZ`] to [`MAX_RATE_HZ`], and at most
    /// [`MAX_SPAN_S`] from the first frame to the last.
    pub fn at_rate(frames: u64, rate_hz: f64) -> Result<Arrivals, String> {
        if !(rate_hz.is_finite() && (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&rate_hz)) {
            return Err(format!(
                "{} Hz is out of range: expected a command rate from {MIN_RATE_HZ} to {MAX_RATE_HZ} frames per second",
                crate::model::units::show(rate_hz)
            ));
        }
        let span_s = frames.saturating_sub(1) as f64 / rate_hz;
        if span_s > MAX_SPAN_S {
            return Err(format!(
                "{frames} frames at {} Hz span {} s: expected at most {MAX_SPAN_S} s (one year)",
                crate::model::units::show(rate_hz),
                crate::model::units::show(span_s.round())
            ));
        }
        Ok(Arrivals::Rate { frames, rate_hz })
    }

    pub fn len(&self) -> u64 {
        match self {
            Arrivals::Rate { frames, .. } => *frames,
            Arrivals::Times(t) => t.len() as u64,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    #[inline]
    fn at(&self, i: u64) -> u64 {
        match self {
            Arrivals::Rate { rate_hz, .. } => round_to_u64(i as f64 * 1e9 / rate_hz),
            Arrivals::Times(t) => t[i as usize],
        }
    }

    /// The mean interval between frames, in ns.
    pub fn mean_interval_ns(&self) -> f64 {
        match self {
            Arrivals::Rate { rate_hz, .. } => 1e9 / rate_hz,
            Arrivals::Times(t) if t.len() > 1 => (t[t.len() - 1] - t[0]) as f64 / (t.len() - 1) as f64,
            Arrivals::Times(_) => 0.0,
        }
    }
}

/// `x.round() as u64` (halves away from zero) without `round`, a libm call
/// on x86-64's baseline that costs about 24 instructions a frame: below
/// 2^53 the integer part `n` (a signed conversion, one instruction where
/// an unsigned one takes a dozen) plus one when the fraction `x − n`, exact
/// there, is at least ½. NaN and `x` in (−1, 0) give 0, as `round() as
/// u64` does; other values (never an arrival time at a rate in range) take
/// `round`.
#[inline]
fn round_to_u64(x: f64) -> u64 {
    let n = x as i64;
    if (0..1 << 53).contains(&n) {
        (if x - n as f64 >= 0.5 { n + 1 } else { n }) as u64
    } else {
        x.round() as u64
    }
}

#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct DelayStats {
    pub mean: f64,
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
    /// Absent when `p50` and `p99` are exact; else (a check of more
    /// delivered frames than are kept) the most each lies above the exact
    /// value, as a fraction of it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_fraction_max: Option<f64>,
}

impl DelayStats {
    /// The precision of `p50` and `p99` in words, for a text report.
    pub fn precision(&self) -> String {
        match self.error_fraction_max {
            None => "exact".into(),
            Some(f) => format!("p50, p99 each at most {:.3} % high", f * 100.0),
        }
    }
}

/// Corrupted frames and what the ITP checksum makes of them.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct CorruptionStats {
    /// Delivered frames with at least one flipped bit.
    pub corrupted: u64,
    /// Of those, frames whose checksum no longer matches.
    pub caught: u64,
    /// Of those, frames that still pass the checksum check (the flips were
    /// in bytes it does not cover, or cancelled out).
    pub passed: u64,
}

/// The frame `scenario check` corrupts to see what the checksum catches:
/// arbitrary non-zero fields, sealed. One flip is caught or not by its byte
/// alone; only cancelling multiple flips depend on the values.
pub fn synthetic_frame() -> [u8; crate::frame::FRAME_LEN] {
    crate::frame::ItpFrame {
        sequence: 12_345,
        delx: [17, -23],
        dely: [-5, 42],
        delz: [9, -1],
        qx: [0.01, -0.02],
        qy: [0.0, 0.03],
        qz: [-0.01, 0.0],
        qw: [1.0, 1.0],
        buttonstate: [0, 1],
        grasp: [250, -180],
        surgeon_mode: crate::frame::SURGEON_ENGAGED,
        ..Default::default()
    }
    .with_checksum()
    .to_bytes()
}

#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct OutageStats {
    pub count: u64,
    pub mean_ms: f64,
}

/// One stage's share of the outcome.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct StageReport {
    /// Its phase and its place in the phase, both counted from 1, as in the
    /// text report, the trace's `phase`/`stage` columns and the parser's
    /// messages.
    pub phase: usize,
    pub stage: usize,
    pub label: String,
    pub model: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preset: Option<String>,
    /// Frames that reached the stage.
    pub reached: u64,
    pub dropped: u64,
    /// dropped / reached.
    pub loss_rate: f64,
    /// The model's long-run loss at this frame rate, where known exactly.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub loss_rate_model: Option<f64>,
    /// The model's mean delay in ms (delay and jitter stages; the jitter's
    /// clamp at 0 included).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delay_ms_model: Option<f64>,
    /// The model's exact 99th percentile of the drawn delay in ms (jitter
    /// stages).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_ms_p99_model: Option<f64>,
    /// The model's lag-1 correlation of normal scores, and the Spearman rank
    /// correlation of successive delays it implies (jitter stages).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correlation_model: Option<CorrelationModel>,
    /// Frames the stage corrupted, the model's exact fraction of the frames
    /// reaching it, and the exact fraction of its flips the checksum catches
    /// (corrupt stages).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corrupted: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corrupt_rate_model: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub caught_fraction_model: Option<f64>,
    /// The exact fraction of frames sent at once (reorder stages).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub early_fraction_model: Option<f64>,
    /// Slots opened, the exact mean slot spacing in ms, and the most frames a
    /// slot releases (slot stages; `null` when unlimited).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slots: Option<SlotStats>,
    /// Copies the stage made, and the model's exact copies per frame reaching
    /// it (duplicate stages).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duplicated: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duplicate_rate_model: Option<f64>,
    /// What the stage replays and the layout it was read in (replay
    /// stages).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recording: Option<RecordingReport>,
}

/// A replay stage's recording (docs/spec.md §3.14).
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct RecordingReport {
    /// The file, as the scenario names it.
    pub file: String,
    /// `trace.csv` or `delay capture`.
    pub kind: String,
    /// The layout the fates were read from: a trace's columns, or a
    /// capture's records (`time | length | delay (s) | frame`).
    pub layout: String,
    /// Fates recorded, and times the recording ran out and started again.
    pub fates: u64,
    pub wraps: u64,
}

impl RecordingReport {
    fn of(m: &crate::model::Replay) -> RecordingReport {
        let r = m.recording();
        RecordingReport {
            file: m.file().to_string(),
            kind: r.kind().name().to_string(),
            layout: r.kind().layout().to_string(),
            fates: r.len() as u64,
            wraps: m.wraps(),
        }
    }

    /// One line for a text report.
    pub fn text(&self) -> String {
        format!("replays `{}`: {} ({}), {} fates, started again {} times", self.file, self.kind, self.layout, self.fates, self.wraps)
    }
}

/// A slot stage's slots.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct SlotStats {
    pub opened: u64,
    pub spacing_ms_mean_model: f64,
    pub frames_per_slot_max: Option<u64>,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// A jitter stage's correlation: the AR(1) coefficient of its normal scores
/// and the exact lag-1 rank correlation of the delays, `(6/π)·asin(ρ/2)`.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct CorrelationModel {
    pub normal_scores_lag1: f64,
    pub rank_lag1: f64,
}

/// What a scenario realized over a run in simulated time.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct CheckReport {
    pub scenario: String,
    pub seed: u64,
    pub frames: u64,
    /// Mean arrival rate.
    pub rate_hz: f64,
    pub delivered: u64,
    /// Copies made by `duplicate` stages (absent when none).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub duplicated: u64,
    pub dropped: BTreeMap<String, u64>,
    pub loss_rate: f64,
    pub loss_rate_ci95: [f64; 2],
    /// The models' long-run loss in bursts longer than a run of this
    /// length likely met ([`unseen_loss_rate`]), included in the upper end
    /// of `loss_rate_ci95`; absent where no stage has such bursts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_rate_unseen_model: Option<f64>,
    pub loss_run_mean: f64,
    pub delay_ms: DelayStats,
    pub reordered_fraction: f64,
    pub outages: OutageStats,
    /// Only when the scenario has `corrupt` stages.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corruption: Option<CorruptionStats>,
    pub queue_capacity: usize,
    /// The most frames held at once.
    pub queue_depth_max: usize,
    pub stages: Vec<StageReport>,
    /// The link stages (`rate`, `trace`): utilisation, queue occupancy over
    /// time, time-at-stage percentiles (absent when none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub links: Vec<LinkReport>,
}

/// A link stage's outcome (`rate`, `trace`; docs/spec.md §3.12, §3.13).
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct LinkReport {
    /// Its phase, from 1.
    pub phase: usize,
    pub label: String,
    pub model: String,
    /// Frames (payloads) admitted and dropped for the queue (`link_queue`),
    /// and the packets they went as.
    pub frames: u64,
    pub frames_dropped: u64,
    /// Of the frames admitted, those dropped after the link (by a later
    /// stage, or because the release queue was full): the link passed on
    /// `frames − frames_dropped_after`.
    #[serde(default)]
    pub frames_dropped_after: u64,
    pub packets: u64,
    pub packets_dropped: u64,
    /// Wire bytes admitted.
    pub bytes: u64,
    /// The link's capacity: its rate, or the trace's mean.
    pub capacity_bit_s: f64,
    /// Bytes admitted over the time from the first frame to the last
    /// departure, bit/s.
    pub carried_bit_s: f64,
    /// The fraction of that time (`rate`) or of the opportunities' bytes
    /// (`trace`) the link used.
    pub utilisation: f64,
    /// Time at the stage of the frames admitted (queueing and
    /// serialization), ms.
    pub delay_ms: LinkDelay,
    /// The most packets and bytes queued at once.
    pub queue_packets_max: u64,
    pub queue_bytes_max: u64,
    /// Queue occupancy over time: per second of the run (from its first
    /// frame), the most packets and bytes queued when a frame came.
    pub occupancy: Vec<Occupancy>,
}

impl LinkReport {
    /// The link's frames in words: admitted, dropped for its queue, dropped
    /// after it, passed on.
    pub fn frames_text(&self) -> String {
        let mut s = format!("{} of {} frames dropped for the queue", self.frames_dropped, self.frames + self.frames_dropped);
        if self.frames_dropped_after > 0 {
            s += &format!(
                "; of the {} admitted, {} dropped after the link (later stage or queue_full), {} passed on",
                self.frames,
                self.frames_dropped_after,
                self.frames - self.frames_dropped_after
            );
        }
        s
    }
}

/// Percentiles of a link stage's time at the stage, ms, from an HDR
/// histogram over every `u64` of ns.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct LinkDelay {
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub max: f64,
    /// The most each figure lies above the exact value, as a fraction of
    /// it (`null` in reports written before it was said).
    #[serde(default)]
    pub error_fraction_max: Option<f64>,
}

/// One second of a link's queue.
#[derive(Debug, Clone, Copy, Serialize, serde::Deserialize, PartialEq)]
pub struct Occupancy {
    pub second: u64,
    pub packets_max: u64,
    pub bytes_max: u64,
}

/// The most seconds of occupancy a report keeps per link (a day).
pub const MAX_OCCUPANCY_SECONDS: usize = 86_400;

/// Queue occupancy of every link stage, second by second: the checker's
/// and the emulator's ([`crate::service::link`]) alike. Sampling after
/// each frame reads one queue length per link stage and allocates nothing
/// while the seconds fit the room reserved at the start.
#[derive(Debug, Clone)]
pub struct LinkSampler {
    /// (phase, stage) of each link stage.
    at: Vec<(u16, u16)>,
    seconds: Vec<Vec<Occupancy>>,
    /// Frames each stage had seen (admitted or dropped) at the last sample:
    /// a stage is sampled only after a frame reached it (not while its
    /// phase is over, or an earlier stage dropped the frame).
    seen: Vec<u64>,
    /// The first frame's time: second 0 starts there.
    origin_ns: Option<u64>,
}

impl LinkSampler {
    /// The link stages of `scenario`, with room for `reserve_seconds` of
    /// occupancy each (at most [`MAX_OCCUPANCY_SECONDS`]).
    pub fn new(scenario: &Scenario, reserve_seconds: usize) -> LinkSampler {
        let mut at = Vec::new();
        for (pi, phase) in scenario.phases().iter().enumerate() {
            for (si, st) in phase.stages().iter().enumerate() {
                if st.kind().is_link() {
                    at.push((pi as u16, si as u16));
                }
            }
        }
        let reserve = reserve_seconds.min(MAX_OCCUPANCY_SECONDS);
        let seconds = (0..at.len()).map(|_| Vec::with_capacity(reserve)).collect();
        let seen = vec![0; at.len()];
        LinkSampler { at, seconds, seen, origin_ns: None }
    }

    /// Whether the scenario has no link stage (sampling is then a no-op).
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.at.is_empty()
    }

    /// The link stage at (`p`, `s`) of `scenario`, if it is still one
    /// (a live switch may have cut its phase).
    fn stage<'a>(scenario: &'a Scenario, p: u16, s: u16) -> Option<&'a crate::scenario::Stage> {
        let st = scenario.phases().get(usize::from(p))?.stages().get(usize::from(s))?;
        st.kind().is_link().then_some(st)
    }

    /// Records the queue of each link the frame that came at `t_ns` reached.
    #[inline]
    pub fn sample(&mut self, scenario: &Scenario, t_ns: u64) {
        let second = t_ns.saturating_sub(*self.origin_ns.get_or_insert(t_ns)) / 1_000_000_000;
        for ((&(p, s), series), seen) in self.at.iter().zip(&mut self.seconds).zip(&mut self.seen) {
            let Some(model) = Self::stage(scenario, p, s).map(|st| st.model()) else { continue };
            let (Some(stats), Some((packets, bytes))) = (model.link_stats(), model.link_queued()) else { continue };
            let reached = stats.frames + stats.frames_dropped;
            if reached == *seen {
                continue;
            }
            *seen = reached;
            let full = series.len() >= MAX_OCCUPANCY_SECONDS;
            match series.last_mut() {
                Some(o) if o.second == second => {
                    o.packets_max = o.packets_max.max(packets);
                    o.bytes_max = o.bytes_max.max(bytes);
                }
                _ if !full => series.push(Occupancy { second, packets_max: packets, bytes_max: bytes }),
                _ => {}
            }
        }
    }

    /// One report per link stage of `scenario`, in timeline order. A stage
    /// at a place the sampler did not follow (switched in by live control
    /// after the start) has its counts, utilisation and delays but no
    /// occupancy series. (A phase cut by a switch had not started, so a
    /// series kept at its place is its successor's.)
    pub fn reports(&self, scenario: &Scenario) -> Vec<LinkReport> {
        let mut out = Vec::new();
        for (pi, phase) in scenario.phases().iter().enumerate() {
            for (si, st) in phase.stages().iter().enumerate().filter(|(_, st)| st.kind().is_link()) {
                let at = (pi as u16, si as u16);
                let occupancy = self.at.iter().position(|a| *a == at).map(|i| self.seconds[i].clone()).unwrap_or_default();
                out.push(link_report(st, at.0, occupancy));
            }
        }
        out
    }
}

fn link_report(st: &crate::scenario::Stage, p: u16, occupancy: Vec<Occupancy>) -> LinkReport {
    let stats = st.model().link_stats().expect("a link stage");
    let span_ns = stats.first_ns.map_or(0, |f| stats.last_departure_ns.saturating_sub(f));
    let capacity_bit_s = match st.model() {
        crate::model::AnyModel::Rate(m) => m.rate_bit_s() as f64,
        crate::model::AnyModel::LinkTrace(m) => m.schedule().mean_rate_bit_s(m.opportunity_bytes()),
        _ => 0.0,
    };
    LinkReport {
        phase: usize::from(p) + 1,
        label: st.label().to_string(),
        model: st.kind().name().to_string(),
        frames: stats.frames,
        frames_dropped: stats.frames_dropped,
        frames_dropped_after: stats.frames_dropped_after,
        packets: stats.packets,
        packets_dropped: stats.packets_dropped,
        bytes: stats.bytes,
        capacity_bit_s,
        carried_bit_s: if span_ns > 0 { stats.bytes as f64 * 8.0 / (span_ns as f64 / 1e9) } else { 0.0 },
        utilisation: st.model().link_utilisation().unwrap_or(0.0),
        delay_ms: LinkDelay {
            p50: stats.delay_ms_quantile(0.5),
            p90: stats.delay_ms_quantile(0.9),
            p99: stats.delay_ms_quantile(0.99),
            max: stats.delay_ns.max() as f64 / 1e6,
            error_fraction_max: Some(HDR_ERROR_FRACTION_MAX),
        },
        queue_packets_max: stats.queue_packets_max,
        queue_bytes_max: stats.queue_bytes_max,
        occupancy,
    }
}

/// How often the progress callback is called, in frames.
pub const PROGRESS_EVERY: u64 = 1 << 16;

/// Runs `scenario` over `arrivals` and reports. `progress(done)` is called
/// every [`PROGRESS_EVERY`] frames.
pub fn run(scenario: Scenario, arrivals: &Arrivals, queue_capacity: usize, progress: impl FnMut(u64)) -> CheckReport {
    run_observed(scenario, arrivals, queue_capacity, progress, |_, _, _| {})
}

/// [`run`], and `observe(ingress index, arrival ns, entered)` for every
/// frame as it is decided: the per-frame fates a preview or a trace of the
/// check is drawn from.
pub fn run_observed(
    scenario: Scenario,
    arrivals: &Arrivals,
    queue_capacity: usize,
    mut progress: impl FnMut(u64),
    mut observe: impl FnMut(u64, u64, &Entered),
) -> CheckReport {
    let frames = arrivals.len();
    let mut tally = Tally::new(&scenario, frames);
    let mut links = LinkSampler::new(&scenario, 64);
    let mut inj: Injector<()> = Injector::new(scenario, queue_capacity);
    for i in 0..frames {
        let t = arrivals.at(i);
        while let Some(r) = inj.pop_due(t) {
            tally.release.record(&r);
        }
        let e = inj.ingress_with(t, (), |_, flips| tally.corruption.record(&tally.frame, flips.bits()));
        observe(i, t, &e);
        tally.decided(&e, inj.held());
        if !links.is_empty() {
            links.sample(inj.scenario(), t);
        }
        if (i + 1) % PROGRESS_EVERY == 0 {
            progress(i + 1);
        }
    }
    // Drain: every scheduled frame is released in simulated time.
    while let Some(r) = inj.pop_due(u64::MAX) {
        tally.release.record(&r);
    }
    progress(frames);
    tally.report(&inj, &links, arrivals)
}

/// What [`run_observed`] counts frame by frame, and the report it makes of
/// it at the end.
struct Tally {
    frames: u64,
    corrupts_any: bool,
    batches: BatchMeans,
    delays: Quantiles,
    delay_sum_ns: u128,
    delay_max_ns: u64,
    /// Runs of drops (over the originals' fates), and whether the last
    /// frame was dropped.
    runs: u64,
    in_run: bool,
    depth_max: usize,
    release: ReleaseTally,
    /// The frame flips are applied to, to see what the checksum catches.
    frame: [u8; crate::frame::FRAME_LEN],
    corruption: CorruptionStats,
}

impl CorruptionStats {
    #[inline]
    fn record(&mut self, frame: &[u8; crate::frame::FRAME_LEN], bits: &[u16]) {
        self.corrupted += 1;
        if crate::frame::checksum_catches(frame, bits) {
            self.caught += 1;
        } else {
            self.passed += 1;
        }
    }
}

impl Tally {
    fn new(scenario: &Scenario, frames: u64) -> Tally {
        Tally {
            frames,
            corrupts_any: scenario.phases().iter().flat_map(|p| p.stages()).any(|s| s.kind() == crate::model::ModelKind::Corrupt),
            batches: BatchMeans::new(frames),
            delays: Quantiles::new(frames),
            delay_sum_ns: 0,
            delay_max_ns: 0,
            runs: 0,
            in_run: false,
            depth_max: 0,
            release: ReleaseTally::default(),
            frame: synthetic_frame(),
            corruption: CorruptionStats { corrupted: 0, caught: 0, passed: 0 },
        }
    }

    /// The original frame's fate, with `held` frames in the queue after it.
    #[inline]
    fn decided(&mut self, e: &Entered, held: usize) {
        let dropped = match e.fate {
            Fate::Scheduled { delay_ns, .. } => {
                self.delays.record(delay_ns);
                self.delay_sum_ns += u128::from(delay_ns);
                self.delay_max_ns = self.delay_max_ns.max(delay_ns);
                false
            }
            Fate::Dropped(_) => true,
        };
        if dropped && !self.in_run {
            self.runs += 1;
        }
        self.in_run = dropped;
        self.batches.record(dropped);
        self.depth_max = self.depth_max.max(held);
    }

    fn delay_ms(&mut self, delivered: u64) -> DelayStats {
        let ms = |ns: f64| ns / 1e6;
        if delivered == 0 {
            return DelayStats { mean: 0.0, p50: 0.0, p99: 0.0, max: 0.0, error_fraction_max: None };
        }
        let q = self.delays.quantiles(&[0.5, 0.99]);
        DelayStats {
            mean: ms(self.delay_sum_ns as f64 / delivered as f64),
            p50: ms(q[0] as f64),
            p99: ms(q[1] as f64),
            max: ms(self.delay_max_ns as f64),
            error_fraction_max: self.delays.error_fraction_max(),
        }
    }

    fn report(mut self, inj: &Injector<()>, links: &LinkSampler, arrivals: &Arrivals) -> CheckReport {
        let counts = inj.counts();
        debug_assert!(counts.balanced() && counts.held == 0);
        let delivered = counts.released;
        // Runs of drops are counted over the originals' fates, copies apart.
        let dropped_total = self.batches.events();
        let scenario = inj.scenario();
        let unseen = unseen_loss_rate(scenario, self.batches.trials());
        let (loss_rate, loss_rate_ci95) = self.batches.rate_ci95_with(unseen);
        let delay_ms = self.delay_ms(delivered);
        let interval_ns = arrivals.mean_interval_ns();
        let (stages, outages) = stage_reports(scenario, interval_ns);
        CheckReport {
            scenario: scenario.name().to_string(),
            seed: scenario.seed(),
            frames: self.frames,
            rate_hz: if interval_ns > 0.0 { 1e9 / interval_ns } else { 0.0 },
            delivered,
            duplicated: counts.duplicated,
            dropped: inj.drops_by_reason().into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
            loss_rate,
            loss_rate_ci95,
            loss_rate_unseen_model: (unseen > 0.0).then_some(unseen),
            loss_run_mean: if self.runs > 0 { dropped_total as f64 / self.runs as f64 } else { 0.0 },
            delay_ms,
            reordered_fraction: if delivered > 0 { self.release.reordered as f64 / delivered as f64 } else { 0.0 },
            outages,
            corruption: self.corrupts_any.then_some(self.corruption),
            queue_capacity: inj.queue_capacity(),
            queue_depth_max: self.depth_max,
            stages,
            links: links.reports(scenario),
        }
    }
}

/// The long-run loss that `frames` frames through `scenario` (as far as they
/// went: each stage's own frames) are unlikely to have sampled, as a
/// fraction of `frames`: each stage's [`crate::model::AnyModel::unseen_loss_rate`]
/// over the frames that reached it, weighted by their share. What a loss
/// interval from the run's own spread adds to its upper end (a
/// heavy-tailed `ge_lomax`'s longest bursts; 0 for other models).
pub fn unseen_loss_rate(scenario: &Scenario, frames: u64) -> f64 {
    if frames == 0 {
        return 0.0;
    }
    let stages = scenario.phases().iter().flat_map(|p| p.stages());
    stages.map(|st| st.reached() as f64 / frames as f64 * st.model().unseen_loss_rate(st.reached())).sum()
}

/// Per-stage outcome of a scenario so far, and its outage windows, with the
/// models' long-run values at a mean frame interval of `interval_ns`.
pub fn stage_reports(scenario: &Scenario, interval_ns: f64) -> (Vec<StageReport>, OutageStats) {
    let mut outage_count = 0u64;
    let mut outage_ns = 0f64;
    let mut stages = Vec::new();
    for (pi, phase) in scenario.phases().iter().enumerate() {
        for (si, st) in phase.stages().iter().enumerate() {
            let w = st.model().outage_windows();
            outage_count += w.count;
            outage_ns += w.total_ns as f64 + w.total_frames as f64 * interval_ns;
            let reached = st.reached();
            stages.push(StageReport {
                phase: pi + 1,
                stage: si + 1,
                label: st.label().to_string(),
                model: st.kind().name().to_string(),
                preset: st.preset().map(str::to_string),
                reached,
                dropped: st.dropped(),
                loss_rate: if reached > 0 { st.dropped() as f64 / reached as f64 } else { 0.0 },
                loss_rate_model: st.model().loss_rate_exact(interval_ns.round() as u64),
                delay_ms_model: st.model().is_delay().then(|| st.model().mean_delay_ms_exact()),
                delay_ms_p99_model: match st.model() {
                    crate::model::AnyModel::Jitter(j) => Some(j.quantile_ms(0.99)),
                    _ => None,
                },
                correlation_model: match st.model() {
                    crate::model::AnyModel::Jitter(j) if j.correlation() > 0.0 => Some(CorrelationModel {
                        normal_scores_lag1: j.correlation(),
                        rank_lag1: j.rank_correlation_exact(),
                    }),
                    _ => None,
                },
                corrupted: (st.kind() == crate::model::ModelKind::Corrupt).then(|| st.corrupted()),
                corrupt_rate_model: st.model().corrupt_rate_exact(),
                caught_fraction_model: match st.model() {
                    crate::model::AnyModel::Corrupt(m) => m.caught_fraction_model(),
                    _ => None,
                },
                early_fraction_model: match st.model() {
                    crate::model::AnyModel::Reorder(m) => Some(m.early_fraction_exact()),
                    _ => None,
                },
                slots: match st.model() {
                    crate::model::AnyModel::Slot(m) => Some(SlotStats {
                        opened: m.slots_opened(),
                        spacing_ms_mean_model: m.spacing_ms_mean_exact(),
                        frames_per_slot_max: Some(m.frames_per_slot_max()).filter(|&n| n != u64::MAX),
                    }),
                    _ => None,
                },
                duplicated: (st.kind() == crate::model::ModelKind::Duplicate).then(|| st.duplicated()),
                duplicate_rate_model: st.model().duplicate_rate_exact(),
                recording: match st.model() {
                    crate::model::AnyModel::Replay(m) => Some(RecordingReport::of(m)),
                    _ => None,
                },
            });
        }
    }
    let mean_ms = if outage_count > 0 { outage_ns / outage_count as f64 / 1e6 } else { 0.0 };
    (stages, OutageStats { count: outage_count, mean_ms })
}

#[derive(Default)]
struct ReleaseTally {
    max_ingress: Option<u64>,
    reordered: u64,
}

impl ReleaseTally {
    #[inline]
    fn record(&mut self, r: &Released<()>) {
        match self.max_ingress {
            Some(m) if r.ingress_index < m => self.reordered += 1,
            _ => self.max_ingress = Some(r.ingress_index),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn round_to_u64_is_round_as_u64() {
        let edges = [
            0.0, -0.0, 0.5, 0.49999999999999994, 1.5, 2.5, -0.5, -0.7, -1.5, 4503599627370495.5, 4503599627370496.0,
            9007199254740993.0, 9223372036854775808.0, 18446744073709549568.0, 18446744073709551616.0, 1e30, f64::MAX,
            f64::MIN_POSITIVE, f64::INFINITY, f64::NEG_INFINITY, f64::NAN,
        ];
        for x in edges {
            assert_eq!(round_to_u64(x), x.round() as u64, "{x:e}");
        }
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(26);
        for _ in 0..1_000_000 {
            // Any bit pattern, and arrival times at rates in range.
            let x = f64::from_bits(rng.random::<u64>());
            assert_eq!(round_to_u64(x), x.round() as u64, "{x:e}");
            let i = rng.random::<u64>() >> rng.random_range(20..64);
            let rate_hz = rng.random_range(MIN_RATE_HZ..=MAX_RATE_HZ);
            let t = i as f64 * 1e9 / rate_hz;
            assert_eq!(round_to_u64(t), t.round() as u64, "{t:e}");
        }
    }
}
