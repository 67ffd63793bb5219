//! The emulator service: takes frames off its ingress, decides each one's
//! fate in the [`Link`] (the sans-IO injector with its measurements and
//! trace), holds survivors in its preallocated release queue, and
//! busy-waits to release each at its scheduled time onto its egress.
//! Ingress and egress are transport values ([`crate::transport::open`]):
//! iceoryx2, UDP, or any combination.
//!
//! The loop, pinned to one core, does per turn ([`Forward::turn`]): release
//! every frame that is due; poll the UDP return path, if there is one; take
//! every frame waiting at the ingress, up to [`TAKE_MAX`], and decide each
//! (the batch ends early when a release falls due). Every 4096 turns it
//! looks at the stop flag and the peers. Nothing in it
//! allocates, locks or makes a system call beyond the transport's own (the
//! clock is the vDSO's); the per-frame trace goes through a wait-free ring to
//! a writer thread.

use crate::clock::now_ns;
use crate::frame::ItpView;
use crate::host::isolate::IsolationSummary;
use crate::host::StealTimer;
use crate::injector::{Fate, Invalid};
use crate::sample::{FrameSample, ITP_FRAME_LEN};
use crate::scenario::{Scenario, ScenarioSpec};
use crate::service::args::EmulatorArgs;
use crate::service::feedback::{FeedbackPath, FeedbackReport};
use crate::service::link::{Arrival, Link, LinkMeasures, OnTime};
use crate::service::udp::{self, ReturnPath};
use crate::service::signals;
use crate::transport::{FrameSink, FrameSource, PortError};
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
    /// Samples may carry opaque datagrams (the UDP bridge's raw mode); on
    /// any other ingress a sample flagged raw is bad input.
    pub accept_raw: bool,
    /// Serve live control (and telemetry, every `telemetry_ms`; 0: none)
    /// for this run ([`crate::service::control`]).
    pub control: Option<(crate::transport::IpcConfig, u64)>,
    /// Use the reordering release queue whatever the scenario.
    pub reorder_queue: bool,
}

/// Bad input from the sender, by kind: each also a drop (`wrong_size` for
/// the lengths, `bad_flags`), and who was sending when it came.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BadInput {
    /// `len` 0.
    pub len_zero: u64,
    /// `len` between 1 and 123: a payload shorter than an ITP frame.
    pub len_short: u64,
    /// `len` above 124: more than the sample can carry.
    pub len_oversize: u64,
    /// Control bits no sender may set (garbage), a raw flag on an ingress
    /// without raw payloads, or a malformed end marker.
    pub bad_flags: u64,
    /// The senders on the ingress when bad input was seen (node, executable
    /// and pid; or address).
    pub from: Vec<String>,
}

impl BadInput {
    fn total(&self) -> u64 {
        self.len_zero + self.len_short + self.len_oversize + self.bad_flags
    }
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

/// Frame accounting: `entered + duplicated = delivered + dropped +
/// held_at_end` (`duplicated` is 0 without `duplicate` stages).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorFrames {
    pub entered: u64,
    pub delivered: u64,
    /// Copies made by `duplicate` stages; delivered copies are in `delivered`.
    #[serde(default)]
    pub duplicated: u64,
    /// Frames and copies queued with bits flipped by `corrupt` stages, and
    /// of those the ones delivered.
    #[serde(default)]
    pub corrupted: u64,
    #[serde(default)]
    pub corrupted_delivered: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    /// Frames the console said it sent (from its end marker), if it ended.
    pub sent_by_console: Option<u64>,
    /// Frames that passed with a wrong checksum (when not dropped for it).
    pub bad_checksum_passed: u64,
    /// Bad input, by kind, and who sent it.
    #[serde(default)]
    pub bad_input: BadInput,
    /// Of the delivered frames, those released while no robot was
    /// subscribed: they went nowhere (a stand-alone emulator started before
    /// its robot; see `--wait-for-peer-s`).
    #[serde(default)]
    pub delivered_unsubscribed: u64,
}

/// The emulator's own report, written as `emulator.json`: one flat JSON
/// object of two parts. What the run report shows at its top level (the
/// shaping) is kept apart from the rest (the process), so that the run
/// report carries each field once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorReport {
    #[serde(flatten)]
    pub shaping: Shaping,
    #[serde(flatten)]
    pub process: EmulatorProcess,
}

/// What the link did to the stream, and where its files are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Shaping {
    #[serde(flatten)]
    pub link: LinkMeasures,
    pub peer_events: Vec<PeerEvent>,
    /// Live control actions that took effect (`netfi ctl`), in order; also
    /// streamed to `events.jsonl` as they happen.
    #[serde(default)]
    pub events: Vec<crate::service::control::ControlEvent>,
    pub trace_path: Option<PathBuf>,
    pub decision_hlog: Option<PathBuf>,
    pub lateness_hlog: Option<PathBuf>,
}

/// The emulator as a process: its set-up, its own frame account, how its
/// loop ran and ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorProcess {
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
    /// Why the loop ended: `end_marker` (the console finished and every held
    /// frame was released), `signal`, or `peer_died` (see `dead_peers`).
    pub ended_by: String,
    /// Peers of the run found dead by the emulator (role, executable, pid).
    #[serde(default)]
    pub dead_peers: Vec<String>,
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
    /// The feedback path robot → console, when it was open.
    #[serde(default)]
    pub feedback: Option<FeedbackReport>,
    /// The video path robot → console, when the run has video.
    #[serde(default)]
    pub video: Option<crate::service::video::VideoLinkReport>,
    /// The loop's time on frames, and the rate it implies ([`LoopBusy`]).
    #[serde(default)]
    pub busy: Option<LoopBusy>,
}

/// The emulator loop's time on frames, measured in every run from the clock
/// read each turn already makes ([`BusyClock`]), and the capacity it
/// implies.
///
/// A turn is *busy* when it took at least one frame off the ingress or
/// released at least one (the stream's own frames; feedback and video alone
/// do not make a turn busy). A busy turn's time runs from its start to the
/// start of the next turn (or the loop's end), so it holds everything the
/// turn did: the iceoryx2 (or UDP) receive and send, the copies of the
/// sample into the loop, the queue and the publisher's sample, the
/// decision, the trace and histograms, the feedback and video polls of that
/// turn, and the loop's own bookkeeping every 4096 turns when it falls in
/// one. It leaves out every idle turn (polling an empty ingress with nothing
/// due), and the wait of a release prepared ahead of its time
/// ([`RELEASE_SPIN_NS`]; the preparation overlapping that wait, one pop and
/// copy, is left out with it: this only happens on an idle loop, never on a
/// busy stream). Anything that takes the core during a busy turn (another
/// thread, an interrupt, the hypervisor) is counted in it, so the time is an
/// upper bound on what the frames cost, and the capacity a lower bound on
/// the rate this loop could carry with the core to itself. When one loop
/// serves several streams, each stream's turn ends at the clock read right
/// after it, and the releases made for every stream between turns are in
/// no stream's time.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LoopBusy {
    /// Turns of the loop (of this stream, when one loop serves several).
    pub turns: u64,
    /// Of those, turns that took or released at least one frame.
    pub busy_turns: u64,
    /// Their time, ns.
    pub busy_ns: u64,
    /// Frames taken off the ingress (entered, rejected ones included).
    pub frames: u64,
    /// `busy_ns / frames`: the loop's time per frame, taking and releasing.
    pub busy_ns_per_frame: Option<f64>,
    /// `1e9 / busy_ns_per_frame`: the frames a second the loop could take
    /// and release if it did nothing but busy turns.
    pub capacity_frames_per_s: Option<f64>,
    /// Of the busy turns, those longer than [`LONG_TURN_NS`], and their
    /// time (also in `busy_turns` and `busy_ns`): the loop most likely lost
    /// its core inside them (a turn's own work is far shorter).
    #[serde(default)]
    pub long_turns: u64,
    #[serde(default)]
    pub long_ns: u64,
    /// The time per frame of the busy turns but the long ones, over the
    /// frames taken and released in them, scaled to every frame: the cost
    /// with the time the core was lost for mostly left out, a better
    /// estimate than `busy_ns_per_frame` where other work shares the core.
    /// A long turn that did not lose its core is a large batch, which pays
    /// the turn's fixed work once for many frames, so leaving it out can
    /// only raise this figure: it still leans towards the cost's high side.
    #[serde(default)]
    pub short_turns_ns_per_frame: Option<f64>,
    /// `1e9 / short_turns_ns_per_frame`.
    #[serde(default)]
    pub short_turns_capacity_frames_per_s: Option<f64>,
}

/// A busy turn longer than this is taken to have lost its core
/// ([`LoopBusy::long_turns`]): more than a full batch ([`TAKE_MAX`] frames
/// at 3 µs each) takes, less than a scheduler's time slice (milliseconds)
/// or a descheduled vCPU.
pub const LONG_TURN_NS: u64 = 200_000;

impl LoopBusy {
    /// The figures of `clock` over `frames` frames taken, and `work`
    /// frames taken and released in all.
    pub fn of(clock: &BusyClock, frames: u64, work: u64) -> LoopBusy {
        let short_work = work.saturating_sub(clock.long_work);
        let short = (frames > 0 && short_work > 0)
            .then(|| (clock.busy_ns - clock.long_ns) as f64 / short_work as f64 * work as f64 / frames as f64);
        LoopBusy {
            turns: clock.turns,
            busy_turns: clock.busy_turns,
            busy_ns: clock.busy_ns,
            frames,
            long_turns: clock.long_turns,
            long_ns: clock.long_ns,
            ..LoopBusy::default()
        }
        .with_rates(short)
    }

    /// The figures derived from the counts: time a frame and the capacity
    /// it implies, and `short` (the time a frame without the long turns)
    /// with its own.
    fn with_rates(mut self, short: Option<f64>) -> LoopBusy {
        let rate = |ns: Option<f64>| ns.filter(|&n| n > 0.0).map(|n| 1e9 / n);
        self.busy_ns_per_frame = (self.frames > 0).then(|| self.busy_ns as f64 / self.frames as f64);
        self.capacity_frames_per_s = rate(self.busy_ns_per_frame);
        self.short_turns_ns_per_frame = short;
        self.short_turns_capacity_frames_per_s = rate(short);
        self
    }
}

impl LoopBusy {
    /// The figures of one loop that served several streams, from each
    /// stream's: a stream's busy turns are its own turns of the loop
    /// (`streams::round` closes each at the next clock read), so their
    /// counts and times add up. The figure without the long turns is the
    /// streams' own, weighted by their frames (each stream's frames in
    /// long turns are not kept apart in its figures). `None` without
    /// streams.
    pub fn total<'a>(parts: impl IntoIterator<Item = &'a LoopBusy>) -> Option<LoopBusy> {
        let mut t: Option<LoopBusy> = None;
        let mut short_weighted = (0.0f64, 0u64);
        for p in parts {
            let s = t.get_or_insert_with(LoopBusy::default);
            s.turns += p.turns;
            s.busy_turns += p.busy_turns;
            s.busy_ns += p.busy_ns;
            s.frames += p.frames;
            s.long_turns += p.long_turns;
            s.long_ns += p.long_ns;
            if let Some(short) = p.short_turns_ns_per_frame {
                short_weighted.0 += short * p.frames as f64;
                short_weighted.1 += p.frames;
            }
        }
        Some(t?.with_rates((short_weighted.1 > 0).then(|| short_weighted.0 / short_weighted.1 as f64)))
    }
}

/// Counts the loop's busy turns and their time ([`LoopBusy`]) with the
/// clock read each turn makes anyway: a turn's start closes the turn before
/// it, whose work is told by a count of frames taken and released that the
/// link keeps anyway. Per turn: one compare, and an add when it was busy; no
/// clock read, allocation or lock of its own.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BusyClock {
    /// Turns begun.
    pub turns: u64,
    /// Turns closed that took or released a frame.
    pub busy_turns: u64,
    /// Their time, ns.
    pub busy_ns: u64,
    /// Of those, the turns longer than [`LONG_TURN_NS`], their time, and
    /// the frames they took and released.
    pub long_turns: u64,
    pub long_ns: u64,
    long_work: u64,
    /// The open turn's start (0: none open) and the work count then.
    start_ns: u64,
    work: u64,
}

impl BusyClock {
    /// A turn begins at `now` with `work` frames taken and released so
    /// far: the turn before it, if still open, ends here.
    #[inline]
    pub fn begin(&mut self, now: u64, work: u64) {
        self.end(now, work);
        self.start_ns = now;
        self.work = work;
        self.turns += 1;
    }

    /// The open turn, if any, ends at `now` with `work` frames taken and
    /// released so far; it was busy if that count moved.
    #[inline]
    pub fn end(&mut self, now: u64, work: u64) {
        if self.start_ns != 0 && work != self.work {
            let ns = now.saturating_sub(self.start_ns);
            self.busy_turns += 1;
            self.busy_ns += ns;
            if ns > LONG_TURN_NS {
                self.long_turns += 1;
                self.long_ns += ns;
                self.long_work += work.wrapping_sub(self.work);
            }
        }
        self.start_ns = 0;
    }

    /// The open turn waits `ns` for a release prepared ahead: that wait is
    /// not the frames' cost.
    #[inline]
    fn waited(&mut self, ns: u64) {
        self.start_ns += ns;
    }
}

/// The most frames one turn takes in. A burst is taken whole up to this, so
/// a fast stream pays the turn's fixed work (the release check, the return
/// and feedback polls, the loop's own bookkeeping) once per batch rather than
/// per frame; the bound keeps those polls at least every 64 decisions (about
/// 10 µs at 150 ns a frame), and releases do not wait for the batch at all:
/// it ends as soon as one is due.
pub const TAKE_MAX: usize = 64;

/// How close a release must be for an idle loop to prepare it now and wait
/// for its moment on the clock alone rather than poll its ports once more.
/// A release is then stamped within a clock read of its time, after the
/// queue's pop and the copy into the publisher's sample, instead of anywhere
/// in the turn that straddles it. The window is a few idle turns (150–350 ns
/// each here, longer when a frame comes in), so that the loop sees every
/// release inside it at least once. The loop only prepares when its last
/// look at the ingress found nothing, so a busy stream never waits; an idle
/// one may take in a frame up to this much later.
pub const RELEASE_SPIN_NS: u64 = 1_000;

/// What one receive gave.
enum Taken {
    /// A frame, taken in at this time and decided.
    Frame(u64),
    /// The console's end marker.
    EndMarker,
    /// Nothing waited (or the port failed).
    Nothing,
}

/// The forward direction's loop state: the link, and what the loop counts
/// around it.
pub struct Forward {
    /// The link every frame goes through.
    pub link: Link<FrameSample>,
    drop_bad_checksum: bool,
    sample: FrameSample,
    bad_checksum_passed: u64,
    receive_errors: u64,
    last_error: Option<PortError>,
    sent_by_console: Option<u64>,
    /// The feedback path, polled once per turn.
    pub feedback: Option<Box<FeedbackPath>>,
    /// The video path, polled once per turn.
    pub video: Option<Box<crate::service::video::VideoPath>>,
    /// When the forward stream ended and its end marker went to the robot.
    forward_end_ns: Option<u64>,
    /// Frames released to no robot, counted before the end marker.
    delivered_unsubscribed: u64,
    /// Bad input by kind.
    pub bad_input: BadInput,
    /// Whether raw (opaque) samples are accepted.
    pub accept_raw: bool,
    /// How near a release an idle turn waits for it on the clock
    /// ([`RELEASE_SPIN_NS`]; 0: never, as when one loop serves several
    /// streams, where a wait would delay the others).
    pub release_spin_ns: u64,
    /// The last turn found nothing waiting at the ingress.
    idle: bool,
    /// The loop's busy turns and their time.
    pub busy: BusyClock,
}

impl Forward {
    /// The loop around `link`; frames with a wrong ITP checksum are dropped
    /// when `drop_bad_checksum`, else counted and passed.
    pub fn new(link: Link<FrameSample>, drop_bad_checksum: bool) -> Forward {
        Forward {
            link,
            drop_bad_checksum,
            sample: FrameSample::ZERO,
            bad_checksum_passed: 0,
            receive_errors: 0,
            last_error: None,
            sent_by_console: None,
            feedback: None,
            video: None,
            forward_end_ns: None,
            delivered_unsubscribed: 0,
            bad_input: BadInput::default(),
            accept_raw: true,
            release_spin_ns: RELEASE_SPIN_NS,
            idle: false,
            busy: BusyClock::default(),
        }
    }

    /// The loop with the feedback path `fb` polled in each turn.
    pub fn with_feedback(mut self, fb: FeedbackPath) -> Forward {
        self.feedback = Some(Box::new(fb));
        self
    }

    /// One turn of the loop: every release that is due, oldest first; the
    /// return path (UDP) or the feedback path (iceoryx2); every frame that
    /// waits at the ingress, up to [`TAKE_MAX`] ([`Forward::take`]).
    #[inline]
    pub fn turn<S: FrameSource, K: FrameSink>(&mut self, source: &mut S, sink: &mut K, ret: Option<&mut ReturnPath>) {
        let now = now_ns();
        self.busy.begin(now, self.work());
        match self.due_until(now) {
            t if t > now => {
                self.busy.waited(t - now);
                self.link.release_due(t, &mut OnTime(sink))
            }
            _ => self.link.release_due(now, sink),
        }
        if let Some(r) = ret {
            r.poll(source.sender());
        }
        if let Some(f) = self.feedback.as_deref_mut() {
            f.poll();
        }
        if let Some(v) = self.video.as_deref_mut() {
            v.poll();
        }
        self.idle = self.take(source, now_ns);
    }

    /// Frames taken and released so far: a turn that moved it was busy.
    #[inline]
    fn work(&self) -> u64 {
        self.link.next_ingress_index().wrapping_add(self.link.released())
    }

    /// Ends the loop's current turn at `now` (read after it by a loop that
    /// does other work between turns, as one serving several streams does);
    /// else the next turn's start ends it.
    #[inline]
    pub fn end_turn(&mut self, now: u64) {
        self.busy.end(now, self.work());
    }

    /// The loop's busy turns so far and the capacity they imply.
    pub fn loop_busy(&self) -> LoopBusy {
        LoopBusy::of(&self.busy, self.link.next_ingress_index(), self.work())
    }

    /// The time up to which releases are due in this turn: `now`, or, when
    /// the loop is idle and its next release falls within
    /// `release_spin_ns`, that release's time. The release is then taken
    /// out of the queue and written into its sample ahead of time, and its
    /// stamp waits on the clock for the moment itself ([`OnTime`]: never
    /// sent before the scheduled time). Nothing is taken in meanwhile, so
    /// no frame can come due earlier.
    #[inline]
    fn due_until(&self, now: u64) -> u64 {
        match self.link.next_release_ns() {
            Some(t) if self.idle && t > now && t - now <= self.release_spin_ns => t,
            _ => now,
        }
    }

    /// Off the hot path: once the stream has drained, sends the robot the
    /// end marker (once); then whether the loop may end, i.e. the feedback
    /// path, if any, has ended too.
    pub fn finished<K: FrameSink>(&mut self, sink: &mut K) -> bool {
        if !self.drained() {
            return false;
        }
        let now = now_ns();
        let end = match self.forward_end_ns {
            Some(t) => t,
            None => {
                self.delivered_unsubscribed = sink.unsubscribed();
                let _ = sink.send_with(&FrameSample::end_marker(self.link.released()), |_| {});
                self.forward_end_ns = Some(now);
                now
            }
        };
        let video = self.video.as_deref_mut().map_or(true, |v| v.finished(now, end));
        match self.feedback.as_deref_mut() {
            Some(f) => f.finished(now, end) && video,
            None => video,
        }
    }

    /// Takes every frame waiting in `source`, up to [`TAKE_MAX`], each
    /// stamped taken at `clock()` (read once per frame that came) and
    /// decided. The batch ends early once a held frame is due at the time
    /// read for the last frame, so that a release waits behind at most one
    /// decision (no clock is read for the check). Returns whether nothing
    /// waited at all.
    #[inline]
    pub fn take<S: FrameSource>(&mut self, source: &mut S, mut clock: impl FnMut() -> u64) -> bool {
        for i in 0..TAKE_MAX {
            match self.take_one(source, &mut clock) {
                Taken::Frame(t_take) if self.link.next_release_ns().is_some_and(|t| t <= t_take) => return false,
                Taken::Frame(_) | Taken::EndMarker => {}
                Taken::Nothing => return i == 0,
            }
        }
        false
    }

    /// Takes at most one frame from `source` and decides it.
    #[inline]
    fn take_one<S: FrameSource>(&mut self, source: &mut S, clock: &mut impl FnMut() -> u64) -> Taken {
        let sample = &mut self.sample;
        match source.try_recv(sample) {
            // An end marker is the flag alone, with no payload.
            Ok(true) if sample.flags == FrameSample::FLAG_END && sample.len == 0 => {
                self.sent_by_console = Some(sample.console_index);
                Taken::EndMarker
            }
            Ok(true) => {
                let t_take = clock();
                sample.ingress_index = self.link.next_ingress_index();
                sample.ingress_ns = t_take;
                let arrival = |sequence| Arrival { sequence, console_index: sample.console_index, send_ns: sample.send_ns };
                let entered = match classify(sample, self.drop_bad_checksum, self.accept_raw, &mut self.bad_input) {
                    Ok((seq, bad)) => {
                        self.bad_checksum_passed += u64::from(bad);
                        self.link.ingress(t_take, *sample, arrival(Some(seq)))
                    }
                    Err((why, seq)) => self.link.reject(t_take, why, arrival(seq)),
                };
                // A copy still queued shares what the sample holds.
                if matches!(entered.fate, Fate::Dropped(_)) && entered.copies == 0 {
                    source.dropped(sample);
                }
                Taken::Frame(t_take)
            }
            Ok(false) => Taken::Nothing,
            Err(e) => {
                // Counted, and the batch ends: a failing port is not spun on.
                self.receive_errors += 1;
                self.last_error = Some(e);
                Taken::Nothing
            }
        }
    }

    /// The console has ended its stream and every held frame is released.
    #[inline]
    pub fn drained(&self) -> bool {
        self.sent_by_console.is_some() && self.link.held() == 0
    }
}

/// The datagram classifier: checks size and checksum. `Ok((sequence,
/// checksum_bad))` for a frame to decide; `Err` for one to reject, with
/// its sequence if readable. Total over any sample (property-tested in
/// `tests/input_prop.rs`).
#[inline]
pub fn classify(s: &FrameSample, drop_bad_checksum: bool, accept_raw: bool, bad: &mut BadInput) -> Result<(u32, bool), (Invalid, Option<u32>)> {
    const KNOWN: u32 = FrameSample::FLAG_END | FrameSample::FLAG_RAW;
    if s.flags & !KNOWN != 0 || s.is_end() || (s.is_raw() && !accept_raw) {
        // Garbage control bits, an end marker with a payload, or an opaque
        // datagram where none may come.
        bad.bad_flags += 1;
        return Err((Invalid::BadFlags, None));
    }
    if s.is_raw() {
        // An opaque datagram: no protocol to check; its "sequence" is its console index.
        return Ok((s.console_index as u32, false));
    }
    if s.len as usize != ITP_FRAME_LEN {
        match s.len {
            0 => bad.len_zero += 1,
            n if (n as usize) < ITP_FRAME_LEN => bad.len_short += 1,
            _ => bad.len_oversize += 1,
        }
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

/// How the loop's thread was placed.
pub(crate) struct Placement {
    pub(crate) isolation: Option<crate::host::isolate::Isolation>,
    pub(crate) realtime_priority: Option<i32>,
}

/// Pins the loop's thread (keeping the trace writers off its core), clears
/// the core if asked, and raises the thread's priority if asked.
pub(crate) fn place(cfg: &EmulatorConfig, link: &Link<FrameSample>, fb: Option<&FeedbackPath>, ret: Option<&ReturnPath>) -> anyhow::Result<Placement> {
    if let Some(core) = cfg.core {
        let ok = core_affinity::set_for_current(core_affinity::CoreId { id: core });
        anyhow::ensure!(ok, "could not pin the emulator to core {core}");
        warn_unless_off(link.keep_trace_off_core(core), "the trace writer", core);
        if let Some(f) = fb {
            warn_unless_off(f.keep_trace_off_core(core), "the feedback trace writer", core);
        }
        if let Some(r) = ret {
            warn_unless_off(r.keep_trace_off_core(core), "the return path's trace writer", core);
        }
    }
    // After pinning: the loop's own threads are placed; everything else that
    // may run elsewhere leaves the core until the run ends.
    let isolation = match (cfg.isolate, cfg.core) {
        (true, Some(core)) => match crate::host::isolate::isolate(core) {
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
    let realtime_priority = cfg.rt_priority.and_then(realtime);
    Ok(Placement { isolation, realtime_priority })
}

/// Says loudly that one of the emulator's own threads (`what`) could not
/// be kept off the loop's core: it may use no other core, so each time it
/// runs it takes the core from the loop.
pub(crate) fn warn_unless_off(kept: bool, what: &str, core: usize) {
    if !kept {
        eprintln!("emulator: WARNING: {what} could not be kept off core {core} (it may use no other): the loop loses its core whenever that thread runs");
    }
}

/// Moves the loop to SCHED_FIFO `p`, warning of real-time throttling; the
/// priority it got, if any.
fn realtime(p: i32) -> Option<i32> {
    match crate::service::set_realtime(p) {
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
    }
}

/// What the loop's look off the hot path (every 4096 turns) found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Look {
    /// Nothing new: go on.
    Go,
    /// SIGINT/SIGTERM: stop now.
    Stop,
    /// The robot died: the console is told through the feedback loop (its
    /// end marker comes early) and the stream drains as usual, so every
    /// frame stays accounted for; without a feedback loop, stop now.
    RobotDied,
}

/// How the loop ended.
#[derive(Debug, Clone)]
pub(crate) struct LoopEnd {
    pub(crate) ended_by: &'static str,
    pub(crate) iterations: u64,
    pub(crate) t_start: u64,
    pub(crate) t_end: u64,
    pub(crate) peer_events: Vec<PeerEvent>,
}

/// Turns the loop until the stream has ended and drained, or a stop is
/// requested. Everything but the turn itself happens every 4096 turns.
fn spin<S: FrameSource, K: FrameSink>(
    fwd: &mut Forward,
    source: &mut S,
    sink: &mut K,
    mut ret: Option<&mut ReturnPath>,
    mut look: impl FnMut() -> Look,
    mut control: Option<&mut crate::service::control::ControlPort>,
) -> LoopEnd {
    let mut robot_died = false;
    let mut bad_seen = 0u64;
    let mut peer_events = Vec::new();
    let mut peers = (source.peers(), sink.peers());
    let t_start = now_ns();
    let mut iter: u64 = 0;
    let ended_by = loop {
        fwd.turn(source, sink, ret.as_deref_mut());
        iter = iter.wrapping_add(1);
        if iter % 4096 == 0 {
            if let Some(c) = control.as_deref_mut() {
                c.poll(&mut fwd.link);
            }
            if fwd.bad_input.total() != bad_seen {
                // Off the hot path: who is sending now.
                bad_seen = fwd.bad_input.total();
                for who in source.senders() {
                    if !fwd.bad_input.from.contains(&who) {
                        fwd.bad_input.from.push(who);
                    }
                }
            }
            match look() {
                Look::Go => {}
                Look::Stop => break "signal",
                Look::RobotDied => match fwd.feedback.as_deref_mut() {
                    Some(f) => {
                        robot_died = true;
                        f.forward_end();
                    }
                    None => break "peer_died",
                },
            }
            if fwd.finished(sink) {
                break if robot_died { "peer_died" } else { "end_marker" };
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
    LoopEnd { ended_by, iterations: iter, t_start, t_end: now_ns(), peer_events }
}

/// Runs the emulator until the console's end marker has been seen and every
/// held frame released, or until a stop is requested (SIGINT/SIGTERM). Then
/// writes `trace_emulator.csv`, `decision.hlog`, `lateness.hlog` and
/// `emulator.json` into `out_dir`, and returns the report. `emulator.ready`
/// is written there once the loop is set up and placed, just before it
/// starts. `ret`, the UDP
/// return path, is polled once per turn. `stop_requested` is polled off the
/// hot path (every 4096 iterations).
pub fn run<S: FrameSource, K: FrameSink>(
    cfg: &EmulatorConfig,
    source: &mut S,
    sink: &mut K,
    ret: Option<&mut ReturnPath>,
    feedback: Option<FeedbackPath>,
    video: Option<crate::service::video::VideoPath>,
    look: impl FnMut() -> Look,
) -> anyhow::Result<EmulatorReport> {
    use anyhow::Context;
    let mut fwd = forward(cfg, feedback)?;
    fwd.video = video.map(Box::new);
    let mut control = start_control(cfg, &mut fwd.link)?;
    let mut placement = place(cfg, &fwd.link, fwd.feedback.as_deref(), ret.as_deref())?;
    if let (Some(core), Some((_, h))) = (cfg.core, control.as_ref()) {
        warn_unless_off(h.keep_off_core(core), "the control thread", core);
    }
    if let (Some(core), Some(v)) = (cfg.core, fwd.video.as_deref()) {
        warn_unless_off(v.keep_trace_off_core(core), "the video trace writer", core);
    }
    // Ready only now, set up and placed: a console started on it is taken
    // in at once. Said before the set-up, frames queued at the ingress for
    // its length (0.1–0.3 s with a cleared core and a queue and trace sized
    // for 10⁵–10⁶ frames/s) and beyond the subscriber's buffer were lost.
    std::fs::write(cfg.out_dir.join("emulator.ready"), b"").context("writing emulator.ready")?;
    let steal_timer = StealTimer::start();
    let end = spin(&mut fwd, source, sink, ret, look, control.as_mut().map(|(p, _)| p));
    let events = control.map(|(_, h)| h.finish()).unwrap_or_default();
    let isolation = placement.isolation.as_mut().map(|iso| iso.restore());
    conclude(cfg, fwd, sink, end, isolation, placement.realtime_priority, steal_timer.stop(), events)
}

/// The loop state of one stream as `cfg` sets it up: its directory, its
/// link (the trace and the histograms going to disk as the run goes), the
/// feedback path `feedback`.
pub(crate) fn forward(cfg: &EmulatorConfig, feedback: Option<FeedbackPath>) -> anyhow::Result<Forward> {
    use anyhow::Context;
    std::fs::create_dir_all(&cfg.out_dir).with_context(|| format!("creating {}", cfg.out_dir.display()))?;
    let scenario = Scenario::new(&cfg.scenario, cfg.seed)?;
    if cfg.accept_raw {
        if let Some(kind) = crate::service::link::unsupported_stage(&scenario, RAW_UNSUPPORTED) {
            anyhow::bail!("scenario `{}`: the `{}` stage applies to ITP frames, not to raw datagrams (--payload raw)", scenario.name(), kind.name());
        }
    }
    // The trace's writer thread starts before pinning, and is then kept off
    // the loop's core, so it runs elsewhere and never preempts the loop.
    let mut fwd = Forward::new(Link::new(scenario, cfg.queue_capacity, cfg.expected_frames)?, cfg.drop_bad_checksum);
    fwd.link.stream_to(&cfg.out_dir.join("trace_emulator.csv"), Some(&cfg.out_dir))?;
    fwd.accept_raw = cfg.accept_raw;
    if let Some(f) = feedback {
        fwd = fwd.with_feedback(f);
    }
    Ok(fwd)
}

/// After the loop: tells the robot the stream ended (best effort: it may be
/// gone) unless the loop already did, then writes the stream's trace,
/// histograms and `emulator.json`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn conclude<K: FrameSink>(
    cfg: &EmulatorConfig,
    mut fwd: Forward,
    sink: &mut K,
    end: LoopEnd,
    isolation: Option<IsolationSummary>,
    realtime_priority: Option<i32>,
    steal: crate::host::Steal,
    events: Vec<crate::service::control::ControlEvent>,
) -> anyhow::Result<EmulatorReport> {
    use anyhow::Context;
    if fwd.forward_end_ns.is_none() {
        fwd.delivered_unsubscribed = sink.unsubscribed();
        let _ = sink.send_with(&FrameSample::end_marker(fwd.link.released()), |_| {});
    }
    let delivered_unsubscribed = fwd.delivered_unsubscribed;
    let mut report = EmulatorReport::assemble(cfg, fwd, end, isolation, realtime_priority, steal)?;
    report.shaping.events = events;
    report.process.frames.delivered_unsubscribed = delivered_unsubscribed;
    let json = cfg.out_dir.join("emulator.json");
    std::fs::write(&json, serde_json::to_vec_pretty(&report)?).with_context(|| format!("writing {}", json.display()))?;
    Ok(report)
}

/// What a raw sample (`--payload raw`) cannot go through: its bytes live
/// in the UDP source's arena, freed at its release, so a copy would be sent
/// from a freed slot, and a flip would miss.
const RAW_UNSUPPORTED: &[crate::model::ModelKind] = &[crate::model::ModelKind::Duplicate, crate::model::ModelKind::Corrupt];

/// The live control of the run, when it has one: the queue as asked, room
/// for switched phases, the control thread started and its telemetry
/// tapped from the trace (before the loop's core is pinned).
pub(crate) fn start_control(
    cfg: &EmulatorConfig,
    link: &mut Link<FrameSample>,
) -> anyhow::Result<Option<(crate::service::control::ControlPort, crate::service::control::ControlHandle)>> {
    use crate::service::control;
    if cfg.reorder_queue {
        link.reorder_queue()?;
    }
    let Some((run, telemetry_ms)) = cfg.control.clone() else { return Ok(None) };
    link.injector_mut().reserve_phases(control::PHASE_ROOM);
    let interval_ns = (telemetry_ms > 0).then(|| telemetry_ms.saturating_mul(1_000_000));
    let settings = control::Settings {
        run,
        spec: cfg.scenario.clone(),
        queue_order: link.injector_mut().queue_order(),
        out_dir: cfg.out_dir.clone(),
        telemetry_interval_ns: interval_ns,
        unsupported: if cfg.accept_raw { RAW_UNSUPPORTED } else { <FrameSample as crate::service::link::Carried>::UNSUPPORTED },
    };
    let (port, handle) = control::start(settings)?;
    if let Some(tap) = interval_ns.and_then(|ns| handle.aggregator(ns)) {
        link.tap_trace(tap);
    }
    Ok(Some((port, handle)))
}

impl EmulatorReport {
    /// The report of a loop that has ended: writes the trace and the
    /// histograms.
    fn assemble(
        cfg: &EmulatorConfig,
        mut fwd: Forward,
        end: LoopEnd,
        isolation: Option<IsolationSummary>,
        realtime_priority: Option<i32>,
        steal: crate::host::Steal,
    ) -> anyhow::Result<EmulatorReport> {
        let duration_s = (end.t_end - end.t_start) as f64 / 1e9;
        fwd.end_turn(end.t_end);
        let busy = fwd.loop_busy();
        let (decision_hlog, lateness_hlog) = fwd.link.write_histograms(&cfg.out_dir, duration_s)?;
        let Forward { link, bad_checksum_passed, receive_errors, last_error, sent_by_console, feedback, video, bad_input, .. } = fwd;
        let l = link.finish(&cfg.out_dir.join("trace_emulator.csv"), end.t_end - end.t_start)?;
        let feedback = feedback.map(|f| f.finish(&cfg.out_dir, end.t_end - end.t_start)).transpose()?;
        let video = video.map(|v| v.finish(&cfg.out_dir, end.t_end - end.t_start)).transpose()?;
        if let Some(e) = l.last_error.as_ref().or(last_error.as_ref()) {
            eprintln!("emulator: last transport error: {e}");
        }
        let iter = end.iterations;
        let shaping = Shaping {
            link: l.measures,
            peer_events: end.peer_events,
            events: Vec::new(),
            trace_path: Some(l.trace_path),
            decision_hlog: Some(decision_hlog),
            lateness_hlog: Some(lateness_hlog),
        };
        let process = EmulatorProcess {
            scenario: l.scenario,
            seed: cfg.seed,
            core: cfg.core,
            realtime_priority,
            isolation,
            queue_order: l.queue_order,
            queue_capacity: l.queue_capacity,
            frames: EmulatorFrames {
                entered: l.entered,
                delivered: l.delivered,
                duplicated: l.duplicated,
                corrupted: l.corrupted,
                corrupted_delivered: l.corrupted_delivered,
                dropped: l.dropped,
                held_at_end: l.held_at_end,
                sent_by_console,
                bad_checksum_passed,
                bad_input,
                delivered_unsubscribed: 0,
            },
            ended_by: end.ended_by.to_string(),
            dead_peers: Vec::new(),
            duration_s,
            loop_iterations: iter,
            loop_iteration_ns_mean: if iter > 0 { (end.t_end - end.t_start) as f64 / iter as f64 } else { 0.0 },
            receive_errors,
            send_errors: l.send_errors,
            trace_overflowed: l.trace_overflowed,
            steal_ms: steal.ms,
            steal_fraction: steal.fraction,
            feedback,
            video,
            busy: Some(busy),
        };
        Ok(EmulatorReport { shaping, process })
    }
}

/// Wires the emulator: arguments → scenario → transports → [`run`], with
/// the UDP return path when both sides are UDP; then `udp.json` when a side
/// is UDP.
pub fn main(args: &EmulatorArgs) -> anyhow::Result<EmulatorReport> {
    use anyhow::Context;
    args.validate()?;
    if args.stream.several() {
        return crate::service::streams::main(args);
    }
    let cfg = config(args)?;
    crate::service::write_pid(&args.out, "emulator")?;
    let mut t = crate::transport::open(&args.ingress, &args.egress, &args.wiring(cfg.queue_capacity))?;
    let mut ret = udp::return_path(args, &t, cfg.seed, cfg.expected_frames)?;
    let fb = feedback_path(args, &t, cfg.seed, cfg.expected_frames)?;
    let video = t.node.as_ref().map(|n| crate::service::video::path(&args.video, n, cfg.seed, &args.out)).transpose()?.flatten();
    let bound = udp::BoundEndpoints::of(&t, args);
    let any_udp = args.ingress.is_udp() || args.egress.is_udp();
    if any_udp {
        eprintln!(
            "emulator: scenario {} seed {}, queue {}, core {:?}; ingress {}{}, egress {}{}, payload {:?}",
            cfg.scenario.name,
            cfg.seed,
            cfg.queue_capacity,
            cfg.core,
            args.ingress,
            bound.ingress.map_or(String::new(), |a| format!(" (bound {a})")),
            args.egress,
            bound.egress_local.map_or(String::new(), |a| format!(" (from {a})")),
            args.payload,
        );
    } else {
        eprintln!("emulator: scenario {} seed {}, queue {}, core {:?}", cfg.scenario.name, cfg.seed, cfg.queue_capacity, cfg.core);
    }
    signals::install();
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    if any_udp {
        let p = args.out.join("udp_endpoints.json");
        std::fs::write(&p, serde_json::to_vec_pretty(&bound)?).with_context(|| format!("writing {}", p.display()))?;
    }
    // Polled every 4096 iterations; iceoryx2's own latch (once a node is
    // open, it may take SIGINT/SIGTERM for itself) every 256th time; the
    // run's dead peers every 200 ms when stand-alone (under `netfi run` the
    // runner reaps them, off this core; two reapers may wait on each other).
    let node = t.node.as_ref().filter(|_| std::env::var_os(crate::host::isolate::RUNNER_PID_ENV).is_none());
    let term = t.node.as_ref();
    let mut stop = signals::StopCheck::new(256, || term.is_some_and(|n| n.termination_requested()));
    let dead = std::cell::RefCell::new(Vec::<String>::new());
    let mut next_reap = now_ns();
    let look = || {
        if stop.requested() {
            return Look::Stop;
        }
        let now = now_ns();
        let Some(n) = node.filter(|_| now >= next_reap) else { return Look::Go };
        next_reap = now + 200_000_000;
        let Ok(r) = n.reap_dead_peers() else { return Look::Go };
        let mut found = Look::Go;
        for p in r.dead() {
            eprintln!("emulator: a peer died: {p}");
            dead.borrow_mut().push(p.to_string());
            // A dead console is reported, and the run goes on as before
            // (until SIGINT/SIGTERM): a restarted console may take over.
            if p.role == Some(crate::transport::Role::Simulator) {
                found = Look::RobotDied;
            }
        }
        found
    };
    let mut report = run(&cfg, &mut t.ingress, &mut t.egress, ret.as_mut(), fb, video, look)?;
    let dead = dead.into_inner();
    if !dead.is_empty() {
        report.process.dead_peers = dead;
        let json = cfg.out_dir.join("emulator.json");
        std::fs::write(&json, serde_json::to_vec_pretty(&report)?).with_context(|| format!("writing {}", json.display()))?;
    }
    if any_udp {
        let return_path = ret.map(|r| r.finish(&cfg.out_dir)).transpose()?;
        let u = udp::UdpReport::new(args, &t, &bound, return_path);
        let path = cfg.out_dir.join("udp.json");
        std::fs::write(&path, serde_json::to_vec_pretty(&u)?).with_context(|| format!("writing {}", path.display()))?;
        eprintln!("{}", summary_line(&report, &u));
    }
    Ok(report)
}

/// The feedback path the arguments ask for: with iceoryx2 on both sides and
/// unless `--no-feedback`, through `--return-scenario` (default Normal).
pub(crate) fn feedback_path(args: &EmulatorArgs, t: &crate::transport::Transports, seed: u64, expected: u64) -> anyhow::Result<Option<FeedbackPath>> {
    use anyhow::Context;
    let Some(node) = t.node.as_ref().filter(|_| !args.ingress.is_udp() && !args.egress.is_udp() && !args.no_feedback) else {
        return Ok(None);
    };
    let name = args.return_scenario.as_deref().unwrap_or("Normal");
    let spec = crate::load::resolve(name).with_context(|| format!("--return-scenario {name}"))?;
    let seed = args.return_seed.or(spec.seed).unwrap_or_else(|| crate::scenario::splitmix64(seed ^ 0x6665_6564_6261_636b));
    let capacity = spec.queue_capacity.unwrap_or(crate::service::plan::DEFAULT_QUEUE_CAPACITY);
    anyhow::ensure!(capacity >= 1, "the return scenario's queue_capacity must be at least 1");
    let scenario = Scenario::new(&spec, seed).with_context(|| format!("--return-scenario {name}"))?;
    let (source, sink) = crate::transport::open_feedback(node)?;
    eprintln!("emulator: feedback path through scenario {} seed {seed}, queue {capacity}", spec.name);
    let mut path = crate::service::feedback::path(scenario, seed, capacity, expected, source, sink)?;
    // Its trace goes to disk as the run goes, as the forward one's does.
    path.link.stream_to(&args.out.join("trace_feedback.csv"), None)?;
    Ok(Some(path))
}

/// The emulator's set-up from its arguments: the scenario resolved, the
/// seed, queue capacity and core chosen.
pub(crate) fn config(args: &EmulatorArgs) -> anyhow::Result<EmulatorConfig> {
    let spec = crate::load::resolve(&args.scenario)?;
    let seed = args.seed.or(spec.seed).unwrap_or_else(crate::service::plan::fresh_seed);
    let default_capacity = match args.payload {
        crate::transport::Payload::Raw => udp::RAW_DEFAULT_QUEUE_CAPACITY,
        crate::transport::Payload::Itp => crate::service::plan::DEFAULT_QUEUE_CAPACITY,
    };
    let queue_capacity = args.queue_capacity.or(spec.queue_capacity).unwrap_or(default_capacity);
    anyhow::ensure!(queue_capacity >= 1, "--queue-capacity must be at least 1 frame");
    let core = if args.no_pin {
        None
    } else {
        args.core.or_else(|| core_affinity::get_core_ids().and_then(|c| c.last().map(|c| c.id)))
    };
    Ok(EmulatorConfig {
        scenario: spec,
        seed,
        queue_capacity,
        core,
        drop_bad_checksum: args.drop_bad_checksum,
        expected_frames: args.expected_frames,
        out_dir: args.out.clone(),
        rt_priority: args.rt_priority,
        isolate: args.isolate,
        accept_raw: args.payload == crate::transport::Payload::Raw,
        control: match (&args.run_id, args.control.no_control) {
            (Some(run), false) => Some((crate::transport::IpcConfig::new(crate::transport::RunId::new(run)?), args.control.telemetry_ms)),
            _ => None,
        },
        reorder_queue: args.control.reorder_queue,
    })
}

/// One line for the log: what came in, what went out, what the kernel and
/// the return path did.
fn summary_line(r: &EmulatorReport, u: &udp::UdpReport) -> String {
    let (f, r) = (&r.process.frames, &r.process);
    let dropped: u64 = f.dropped.values().sum();
    let mut s = format!(
        "emulator: {} entered, {} delivered, {} dropped {:?}, {} held at end; ended by {}",
        f.entered, f.delivered, dropped, f.dropped, f.held_at_end, r.ended_by
    );
    if let Some(k) = u.ingress_kernel_drops.filter(|k| *k > 0) {
        s += &format!("; {k} datagrams dropped by the kernel before ingress");
    }
    if u.foreign_sender > 0 {
        let who: Vec<String> = u.foreign_senders.iter().map(|f| format!("{} ({})", f.addr, f.datagrams)).collect();
        s += &format!("; {} datagrams from foreign senders dropped (foreign_sender): {}", u.foreign_sender, who.join(", "));
    }
    if let Some(rp) = &u.return_path {
        let rd: u64 = rp.dropped.values().sum();
        s += &format!(
            "; return path ({}): {} received, {} delivered, {} dropped, {} held, {} unroutable",
            rp.mode, rp.received, rp.delivered, rd, rp.held_at_end, rp.unroutable
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::MemoryPort;

    /// A Normal link's loop: every frame is due the moment it is taken.
    fn normal_loop() -> Forward {
        let spec = crate::scenario::parse_str("", "normal.toml", "normal").unwrap();
        Forward::new(Link::new(Scenario::new(&spec, 1).unwrap(), 16, 16).unwrap(), false)
    }

    fn frames(port: &mut MemoryPort, n: u64) {
        let mut s = FrameSample::ZERO;
        crate::frame::ItpFrame::default().write_to_sample(&mut s);
        for i in 0..n {
            s.console_index = i;
            port.queue.push_back(s);
        }
    }

    /// One turn; whether it took or released a frame, seen from the ports.
    fn turn(fwd: &mut Forward, console: &mut MemoryPort, robot: &mut MemoryPort) -> bool {
        let before = (console.queue.len(), robot.queue.len());
        fwd.turn(console, robot, None);
        before != (console.queue.len(), robot.queue.len())
    }

    #[test]
    fn busy_turns_are_the_turns_that_took_or_released_a_frame() {
        let mut fwd = normal_loop();
        let (mut console, mut robot) = (MemoryPort::with_capacity(8), MemoryPort::with_capacity(8));
        let t0 = now_ns();
        for _ in 0..10 {
            assert!(!turn(&mut fwd, &mut console, &mut robot));
        }
        assert_eq!((fwd.busy.turns, fwd.busy.busy_turns, fwd.busy.busy_ns), (10, 0, 0));
        frames(&mut console, 3);
        let mut busy = 0;
        while robot.queue.len() < 3 {
            busy += u64::from(turn(&mut fwd, &mut console, &mut robot));
            assert!(fwd.busy.turns < 1000, "three frames never came through");
        }
        // The last busy turn is closed by the next one, which is idle.
        assert!(!turn(&mut fwd, &mut console, &mut robot));
        let closed = fwd.busy;
        assert!(busy >= 2, "a frame is taken in one turn and released in a later one");
        assert_eq!(closed.busy_turns, busy);
        assert!(closed.busy_ns > 0 && closed.busy_ns <= now_ns() - t0);
        for _ in 0..100 {
            assert!(!turn(&mut fwd, &mut console, &mut robot));
        }
        fwd.end_turn(now_ns());
        assert_eq!((fwd.busy.turns, fwd.busy.busy_turns, fwd.busy.busy_ns), (closed.turns + 100, closed.busy_turns, closed.busy_ns));
        let b = fwd.loop_busy();
        assert_eq!((b.turns, b.busy_turns, b.busy_ns, b.frames), (closed.turns + 100, busy, closed.busy_ns, 3));
        let per_frame = closed.busy_ns as f64 / 3.0;
        assert_eq!(b.busy_ns_per_frame, Some(per_frame));
        assert_eq!(b.capacity_frames_per_s, Some(1e9 / per_frame));
    }

    #[test]
    fn a_turn_ended_by_the_loop_is_counted_once() {
        let mut fwd = normal_loop();
        let (mut console, mut robot) = (MemoryPort::with_capacity(8), MemoryPort::with_capacity(8));
        frames(&mut console, 1);
        // Taken in one turn, released in the next; each ended by the loop
        // (as one serving several streams does), then the next turn begins.
        let mut busy = 0;
        for _ in 0..4 {
            busy += u64::from(turn(&mut fwd, &mut console, &mut robot));
            fwd.end_turn(now_ns());
            let ns = fwd.busy.busy_ns;
            fwd.end_turn(now_ns());
            assert_eq!(fwd.busy.busy_ns, ns, "a turn ended twice");
        }
        assert_eq!(robot.queue.len(), 1);
        assert_eq!((fwd.busy.turns, fwd.busy.busy_turns), (4, busy));
        assert_eq!(busy, 2);
        assert_eq!(fwd.loop_busy().frames, 1);
    }

    #[test]
    fn the_streams_busy_figures_add_up_in_the_total() {
        let clock = |busy_ns, long_ns, long_work| BusyClock { turns: 100, busy_turns: 40, busy_ns, long_turns: u64::from(long_ns > 0), long_ns, long_work, ..BusyClock::default() };
        // 1 000 frames in 2 ms, none in long turns; 3 000 in 9 ms, 1 ms of it
        // one long turn that took 500 of 6 000 takes and releases.
        let a = LoopBusy::of(&clock(2_000_000, 0, 0), 1_000, 2_000);
        let b = LoopBusy::of(&clock(9_000_000, 1_000_000, 500), 3_000, 6_000);
        let t = LoopBusy::total([&a, &b]).unwrap();
        assert_eq!((t.turns, t.busy_turns, t.busy_ns, t.frames, t.long_turns, t.long_ns), (200, 80, 11_000_000, 4_000, 1, 1_000_000));
        assert_eq!(t.busy_ns_per_frame, Some(2_750.0));
        assert_eq!(t.capacity_frames_per_s, Some(1e9 / 2_750.0));
        // a: 2 000 ns a frame; b: 8 ms over 5 500 short works, scaled by 2:
        // 2 909.09 ns; weighted by frames (1 000, 3 000).
        let b_short = 8_000_000.0 / 5_500.0 * 2.0;
        assert!((b.short_turns_ns_per_frame.unwrap() - b_short).abs() < 1e-9);
        let want = (2_000.0 * 1_000.0 + b_short * 3_000.0) / 4_000.0;
        assert!((t.short_turns_ns_per_frame.unwrap() - want).abs() < 1e-9, "{t:?}");
        assert_eq!(LoopBusy::total([]), None);
    }
}
