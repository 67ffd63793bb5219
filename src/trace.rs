//! The per-frame trace (docs/spec.md §6): one row per frame that reached the
//! emulator, written to disk as the run goes, off the hot path.
//!
//! The emulator's loop pushes fixed-size [`TraceEvent`]s into a wait-free
//! single-producer ring ([`TraceSink::push`]: no allocation, no lock, no
//! system call); a writer thread drains the ring every few milliseconds.
//! A frame's row is complete once its fate is final (dropped, or
//! released); complete rows are appended to the CSV in ingress order
//! (buffered, flushed at least once a second), so the writer holds only the
//! rows of frames still queued (at most [`MAX_PENDING_ROWS`]: a row older
//! than that is written as it stands). Memory stays flat however long the
//! run, and a killed emulator leaves its trace up to its last second.
//!
//! When given a directory for them, the writer also keeps the decision
//! time and the release lateness of the frames of each second and appends
//! them as one interval each to `decision.hlog` and `lateness.hlog`
//! (HdrHistogram interval logs, one interval per second): the loop records
//! nothing for it, the rows carry the values. The run's totals stay in the
//! link's own histograms.
//!
//! If the ring is ever full the event is counted in
//! [`TraceSink::overflowed`] and the frame's row stays incomplete — the
//! run's counts are unaffected. A write that fails (a full disk) is an
//! error naming the file, returned by [`TraceWriter::finish`]; the writer
//! keeps draining the ring so the loop is never held up.
//!
//! Every file here (the trace, the histogram logs, and a [`CsvLog`]'s) is
//! written as `NAME.partial` and renamed to `NAME` once whole, flushed and
//! synced ([`crate::durable`]): a file cut by a full disk or a killed
//! process keeps the `.partial` name, so a reader tells it from a whole one.
//!
//! # `trace.csv`
//! One header line, then one row per ingress index, in ingress order, and
//! after it one row per copy of that frame a `duplicate` stage made and
//! the queue took (docs/spec.md §3.8): a copy is released as a frame of its
//! own, under its original's ingress index. The rows of one frame then
//! account for it exactly: the copies made are its copy rows plus
//! `copies_dropped`, and every row has one fate. Summed over the file,
//! `entered + duplicated = delivered + dropped + held`, where `entered` is
//! the rows with `copy` 0, `duplicated` the other rows plus the sum of
//! `copies_dropped`, and `dropped` the `dropped` rows plus that sum.
//!
//! | column | meaning |
//! |---|---|
//! | `ingress_index` | the emulator's count of frames that entered (0, 1, …); a copy has its original's |
//! | `sequence` | the ITP frame's `sequence` field (empty if malformed) |
//! | `console_index` | the console's send counter |
//! | `send_ns` | console send time, CLOCK_MONOTONIC ns |
//! | `ingress_ns` | time the emulator took it off the console port |
//! | `fate` | `delivered`, `dropped`, or `held` (scheduled, still queued at the end) |
//! | `reason` | for `dropped`: the model that dropped it, `queue_full`, `wrong_size` or `bad_checksum` |
//! | `phase`, `stage` | for drops by a model: its phase and stage (from 1) |
//! | `delay_ns` | injected delay (scheduled release − ingress) |
//! | `release_sched_ns` | scheduled release time |
//! | `release_ns` | actual release time (just before publishing) |
//! | `recv_ns` | simulator receive time (empty if not received) |
//! | `copy` | 0 for the frame as it entered; k for its k-th copy the queue took |
//! | `copies_dropped` | on a `copy` 0 row: copies of the frame that a later stage or a full queue dropped (their reasons are in the report's drop counts) |
//! | `corrupted` | for a scheduled row: 1 if a `corrupt` stage flipped bits of it (docs/spec.md §3.9), else 0 |
//!
//! A copy row repeats its frame's `sequence`, `console_index`, `send_ns`
//! and `ingress_ns`. A release is matched to the row it belongs to by its
//! scheduled time (the original first when a copy is due at the same
//! time); a copy still held at the end shows the release time its stages
//! asked for.
//!
//! Times are integers; empty cells are missing values. `pandas.read_csv` and
//! `polars.read_csv` read it as it is.

use crate::durable::PartialFile;
use crate::injector::DropCause;
use crate::metrics::LatencyHistogram;
use anyhow::Context;
use hdrhistogram::serialization::interval_log::{IntervalLogWriter, IntervalLogWriterBuilder, Tag};
use hdrhistogram::serialization::V2DeflateSerializer;
use std::collections::VecDeque;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

/// What the emulator reports about a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceEvent {
    Ingress {
        ingress_index: u64,
        sequence: Option<u32>,
        console_index: u64,
        send_ns: u64,
        ingress_ns: u64,
        /// `None` if scheduled.
        dropped: Option<DropCause>,
        release_sched_ns: u64,
        /// Time taken to decide the frame's fate.
        decision_ns: u64,
        /// Copies of it the queue took; a [`TraceEvent::Copy`] follows for each.
        copies: u8,
        /// Copies of it that a later stage or a full queue dropped.
        copies_dropped: u8,
        /// Whether it was queued with bits flipped.
        corrupted: bool,
    },
    /// The `copy`-th copy (from 1) of the frame `ingress_index`, queued for
    /// `release_sched_ns`.
    Copy { ingress_index: u64, copy: u8, release_sched_ns: u64, corrupted: bool },
    /// A release of the frame `ingress_index` (or of one of its copies)
    /// scheduled for `release_sched_ns`.
    Release { ingress_index: u64, release_sched_ns: u64, release_ns: u64 },
}

/// One row of the trace table.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Row {
    pub present: bool,
    pub sequence: Option<u32>,
    pub console_index: u64,
    pub send_ns: u64,
    pub ingress_ns: u64,
    pub dropped: Option<DropCause>,
    pub release_sched_ns: u64,
    pub release_ns: Option<u64>,
    /// Copies of it not yet released (their rows are in [`Table::copies`]).
    pub copies_pending: u8,
    pub copies_dropped: u8,
    pub corrupted: bool,
}

impl Row {
    /// Its fate is final: dropped or released (or its ingress event was
    /// lost, and it will never be), and so is every copy's.
    fn complete(&self) -> bool {
        !self.present || ((self.dropped.is_some() || self.release_ns.is_some()) && self.copies_pending == 0)
    }
}

/// One copy's row: its frame's ingress index, its number, its schedule,
/// its release.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CopyRow {
    pub ingress_index: u64,
    pub copy: u8,
    pub release_sched_ns: u64,
    pub release_ns: Option<u64>,
    pub corrupted: bool,
}

/// An observer of the trace's events, called by the writer thread (never
/// by the loop) as it drains the ring: the telemetry's interval
/// aggregation ([`crate::service::telemetry`]).
pub trait Tap: Send {
    /// A frame entered at `ingress_ns`; `dropped` if its fate was a drop.
    fn ingress(&mut self, ingress_ns: u64, dropped: bool);
    /// A frame was released at `release_ns` after `injected_ns` of injected
    /// delay, `lateness_ns` after its scheduled release.
    fn release(&mut self, release_ns: u64, injected_ns: u64, lateness_ns: u64);
    /// The writer's periodic wake-up (every few milliseconds).
    fn tick(&mut self);
}

/// The hot path's end of the ring.
pub struct TraceSink {
    tx: rtrb::Producer<TraceEvent>,
    overflowed: u64,
}

impl TraceSink {
    /// Pushes an event; never blocks or allocates.
    #[inline]
    pub fn push(&mut self, ev: TraceEvent) {
        if self.tx.push(ev).is_err() {
            self.overflowed += 1;
        }
    }

    /// Events lost because the ring was full.
    pub fn overflowed(&self) -> u64 {
        self.overflowed
    }
}

/// Where the writer writes: the CSV, and the histogram logs if asked.
struct Output {
    csv: PartialFile,
    hlogs: Option<[PartialFile; 2]>,
}

/// What the writer did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Written {
    /// Rows written (copy rows included).
    pub rows: u64,
    /// Rows written of frames (or copies) released with bits flipped.
    pub corrupted_released: u64,
    /// Intervals appended to each histogram log.
    pub intervals: u64,
    /// Rows written before their frame was released (the writer held too
    /// many).
    pub forced: u64,
}

/// The writer thread's handle.
pub struct TraceWriter {
    stop: Arc<AtomicBool>,
    output: Option<mpsc::Sender<Output>>,
    taps: mpsc::Sender<Box<dyn Tap>>,
    thread: std::thread::JoinHandle<anyhow::Result<Written>>,
}

/// Ring capacity in events: at 100 kHz two events per frame, ~1.3 s of
/// events before the writer must have drained.
pub const RING_CAPACITY: usize = 1 << 18;

/// Rows the writer holds at most while their frames are queued (≈ 64 B
/// each: 16 MiB); a row older than that is written as it stands.
pub const MAX_PENDING_ROWS: usize = 1 << 18;

/// Rows the writer has room for at first when streaming.
const PENDING_ROWS_START: usize = 4096;

/// How often the CSV is flushed and a histogram interval is appended.
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// The CSV's header line.
pub const CSV_HEADER: &str =
    "ingress_index,sequence,console_index,send_ns,ingress_ns,fate,reason,phase,stage,delay_ns,release_sched_ns,release_ns,recv_ns,copy,copies_dropped,corrupted";

/// The index of `recv_ns` among the CSV's columns: the emulator leaves it
/// empty and the runner fills it in.
pub const RECV_COLUMN: usize = 12;

/// Starts the writer thread (call before pinning the hot thread, so the
/// writer is not confined to its core) and returns the hot path's sink.
/// Rows are kept in memory until [`TraceWriter::stream_to`] gives files.
/// `expected_copies` reserves room for the rows of copies (`duplicate`
/// stages) likewise; 0 where the scenario makes none.
pub fn start(expected_frames: usize, expected_copies: usize) -> (TraceSink, TraceWriter) {
    let (mut tx, mut rx) = rtrb::RingBuffer::<TraceEvent>::new(RING_CAPACITY);
    // Write every slot once before the hot path starts, so the ring's pages
    // are resident: otherwise a fresh page is faulted in every few dozen
    // frames, on the hot thread, for the first pass through the ring.
    let blank = TraceEvent::Release { ingress_index: 0, release_sched_ns: 0, release_ns: 0 };
    while tx.push(blank).is_ok() {}
    while rx.pop().is_ok() {}
    let stop = Arc::new(AtomicBool::new(false));
    let stop2 = stop.clone();
    let (out_tx, out_rx) = mpsc::channel();
    let (tap_tx, tap_rx) = mpsc::channel::<Box<dyn Tap>>();
    // Allocated here, not in the thread, so that nothing the writer holds
    // is allocated while the loop runs. Room for every row while there is
    // nowhere to write them (reserved, not touched: pages become resident
    // only as rows are stored).
    let table = Table {
        base: 0,
        rows: VecDeque::with_capacity(expected_frames),
        copies: VecDeque::with_capacity(expected_copies),
        decision: LatencyHistogram::new(),
        lateness: LatencyHistogram::new(),
        tap: None,
        taps: tap_rx,
    };
    let thread = std::thread::Builder::new()
        .name("netfi-trace".into())
        .spawn(move || writer(rx, out_rx, stop2, table))
        .expect("spawning the trace writer thread");
    (TraceSink { tx, overflowed: 0 }, TraceWriter { stop, output: Some(out_tx), taps: tap_tx, thread })
}

/// The rows between the oldest incomplete one and the newest, and the
/// histograms of the current interval.
struct Table {
    base: u64,
    rows: VecDeque<Row>,
    /// The copies' rows, in ingress order (then copy order); only runs
    /// with `duplicate` stages have any.
    copies: VecDeque<CopyRow>,
    decision: LatencyHistogram,
    lateness: LatencyHistogram,
    tap: Option<Box<dyn Tap>>,
    taps: mpsc::Receiver<Box<dyn Tap>>,
}

impl Table {
    /// Takes a tap if one was given, and wakes it.
    fn tick(&mut self) {
        if let Ok(t) = self.taps.try_recv() {
            self.tap = Some(t);
        }
        if let Some(t) = self.tap.as_mut() {
            t.tick();
        }
    }

    fn apply(&mut self, ev: TraceEvent) {
        match ev {
            TraceEvent::Ingress {
                ingress_index,
                sequence,
                console_index,
                send_ns,
                ingress_ns,
                dropped,
                release_sched_ns,
                decision_ns,
                copies,
                copies_dropped,
                corrupted,
            } => {
                let Some(row) = self.row_mut(ingress_index, true) else { return };
                let release_ns = row.release_ns;
                *row = Row {
                    present: true,
                    sequence,
                    console_index,
                    send_ns,
                    ingress_ns,
                    dropped,
                    release_sched_ns,
                    release_ns,
                    copies_pending: copies,
                    copies_dropped,
                    corrupted,
                };
                self.decision.record(decision_ns);
                if let Some(t) = self.tap.as_mut() {
                    t.ingress(ingress_ns, dropped.is_some());
                }
            }
            TraceEvent::Copy { ingress_index, copy, release_sched_ns, corrupted } => {
                if ingress_index >= self.base {
                    self.copies.push_back(CopyRow { ingress_index, copy, release_sched_ns, release_ns: None, corrupted });
                }
            }
            TraceEvent::Release { ingress_index, release_sched_ns, release_ns } => self.release(ingress_index, release_sched_ns, release_ns),
        }
    }

    /// The row of `ingress_index`, if it is still held (with `grow`, made
    /// room for if it is new).
    fn row_mut(&mut self, ingress_index: u64, grow: bool) -> Option<&mut Row> {
        let at = ingress_index.checked_sub(self.base)? as usize;
        if grow && self.rows.len() <= at {
            self.rows.resize(at + 1, Row::default());
        }
        self.rows.get_mut(at)
    }

    /// A release of `ingress_index` scheduled for `sched_ns`: the frame's
    /// own if it is due then and not yet released, else its first
    /// unreleased copy due then, else its first unreleased copy (a FIFO
    /// queue may have moved a copy later than its stages asked).
    fn release(&mut self, ingress_index: u64, sched_ns: u64, release_ns: u64) {
        let Some(row) = self.row_mut(ingress_index, false) else { return };
        let own = !row.present || (row.dropped.is_none() && row.release_ns.is_none() && (row.release_sched_ns == sched_ns || row.copies_pending == 0));
        if own {
            row.release_ns = Some(release_ns);
            if row.present {
                let late_ns = release_ns.saturating_sub(row.release_sched_ns);
                let injected_ns = row.release_sched_ns.saturating_sub(row.ingress_ns);
                self.lateness.record(late_ns);
                if let Some(t) = self.tap.as_mut() {
                    t.release(release_ns, injected_ns, late_ns);
                }
            }
            return;
        }
        let ingress_ns = row.ingress_ns;
        let from = self.copies.partition_point(|c| c.ingress_index < ingress_index);
        let to = self.copies.partition_point(|c| c.ingress_index <= ingress_index);
        let unreleased = |c: &CopyRow| c.release_ns.is_none();
        let mine = self.copies.range(from..to);
        let Some(at) = mine.clone().position(|c| unreleased(c) && c.release_sched_ns == sched_ns).or_else(|| mine.clone().position(unreleased)) else {
            // The copy's own event was lost (a full ring): its frame's row
            // must still complete.
            if let Some(row) = self.row_mut(ingress_index, false) {
                row.copies_pending = row.copies_pending.saturating_sub(1);
            }
            return;
        };
        let copy = &mut self.copies[from + at];
        copy.release_ns = Some(release_ns);
        copy.release_sched_ns = sched_ns;
        self.lateness.record(release_ns.saturating_sub(sched_ns));
        if let Some(t) = self.tap.as_mut() {
            t.release(release_ns, sched_ns.saturating_sub(ingress_ns), release_ns.saturating_sub(sched_ns));
        }
        if let Some(row) = self.row_mut(ingress_index, false) {
            row.copies_pending = row.copies_pending.saturating_sub(1);
        }
    }

    /// Takes the rows that are complete (or, past the bound, the oldest),
    /// oldest first, each followed by its copies' rows, into `f`; with
    /// `all`, every row.
    fn drain(&mut self, all: bool, mut f: impl FnMut(u64, &Row, Option<&CopyRow>, bool)) {
        while let Some(front) = self.rows.front() {
            let forced = self.rows.len() > MAX_PENDING_ROWS;
            if !(all || forced || front.complete()) {
                break;
            }
            let row = self.rows.pop_front().expect("a front row");
            let incomplete = forced && !row.complete();
            if row.present {
                f(self.base, &row, None, incomplete);
            }
            while self.copies.front().is_some_and(|c| c.ingress_index <= self.base) {
                let copy = self.copies.pop_front().expect("a front copy");
                if row.present && copy.ingress_index == self.base {
                    f(self.base, &row, Some(&copy), incomplete);
                }
            }
            self.base += 1;
        }
    }
}

/// One CSV line built in place: integers by `itoa`, nothing allocated. At a
/// million frames a second the trace writer formats a million rows, on a
/// core it shares with the emulator's peers; the `write!` of before (with a
/// `String` per empty-or-number field) cost it about a third of that core.
struct Line {
    buf: [u8; Line::CAP],
    len: usize,
}

impl Line {
    /// 14 numbers of at most 20 digits, the fate and reason words (under
    /// 32 bytes each), 15 commas and the newline: 359 bytes at most.
    const CAP: usize = 384;

    fn new() -> Line {
        Line { buf: [0; Line::CAP], len: 0 }
    }

    fn text(&mut self, t: &str) {
        self.buf[self.len..self.len + t.len()].copy_from_slice(t.as_bytes());
        self.len += t.len();
    }

    fn num(&mut self, v: u64) {
        let mut b = itoa::Buffer::new();
        self.text(b.format(v));
    }

    fn opt(&mut self, v: Option<u64>) {
        if let Some(v) = v {
            self.num(v);
        }
    }

    /// A comma, then the field.
    fn then_text(&mut self, t: &str) {
        self.text(",");
        self.text(t);
    }

    fn then_opt(&mut self, v: Option<u64>) {
        self.text(",");
        self.opt(v);
    }
}

/// Formats one row: the frame `r`, or with `copy` one of its copies
/// (`recv_ns` empty: the runner joins it later).
pub fn format_row(w: &mut impl Write, i: u64, r: &Row, copy: Option<&CopyRow>, recv: Option<u64>) -> std::io::Result<()> {
    let (dropped, sched, released, corrupted) = match copy {
        None => (r.dropped, r.release_sched_ns, r.release_ns, r.corrupted),
        Some(c) => (None, c.release_sched_ns, c.release_ns, c.corrupted),
    };
    let (fate, reason, where_) = match dropped {
        None if released.is_some() => ("delivered", "", None),
        None => ("held", "", None),
        Some(c) => {
            let at = match c {
                DropCause::Stage { phase, stage, .. } => Some((u64::from(phase) + 1, u64::from(stage) + 1)),
                _ => None,
            };
            ("dropped", c.reason(), at)
        }
    };
    let scheduled = dropped.is_none();
    let (copy_no, copies_dropped) = match copy {
        None => (0, Some(u64::from(r.copies_dropped))),
        Some(c) => (u64::from(c.copy), None),
    };
    let mut l = Line::new();
    l.num(i);
    l.then_opt(r.sequence.map(u64::from));
    for v in [r.console_index, r.send_ns, r.ingress_ns] {
        l.then_opt(Some(v));
    }
    l.then_text(fate);
    l.then_text(reason);
    l.then_opt(where_.map(|w| w.0));
    l.then_opt(where_.map(|w| w.1));
    l.then_opt(scheduled.then(|| sched.saturating_sub(r.ingress_ns)));
    l.then_opt(scheduled.then_some(sched));
    l.then_opt(released);
    l.then_opt(recv);
    l.then_opt(Some(copy_no));
    l.then_opt(copies_dropped);
    l.then_opt(scheduled.then_some(u64::from(corrupted)));
    l.text("\n");
    w.write_all(&l.buf[..l.len])
}

/// The writer thread: until it has files, it keeps rows in memory; then it
/// appends, flushing every second; at the stop, it writes what is left.
fn writer(mut rx: rtrb::Consumer<TraceEvent>, out_rx: mpsc::Receiver<Output>, stop: Arc<AtomicBool>, mut table: Table) -> anyhow::Result<Written> {
    let tick = Duration::from_millis(5);
    // Until the files come: events applied, nothing written.
    let out = loop {
        let stopping = stop.load(Ordering::Acquire);
        while let Ok(ev) = rx.pop() {
            table.apply(ev);
        }
        table.tick();
        match out_rx.try_recv() {
            Ok(out) => break out,
            // The handle was dropped without `finish`: nobody will ask.
            Err(mpsc::TryRecvError::Disconnected) if !stopping => return Ok(Written::default()),
            Err(_) => {}
        }
        if stopping {
            // Nowhere to write: the rows are dropped with the thread.
            return Ok(Written::default());
        }
        std::thread::sleep(tick);
    };
    let Output { csv, hlogs } = out;
    // Errors name the file as it stands on disk: cut, it keeps this name.
    let csv_path = csv.partial().to_path_buf();
    // From now on only the rows of frames in flight are held: a small
    // ring, grown by doubling (off the hot path) when more are.
    table.rows.shrink_to(PENDING_ROWS_START.max(table.rows.len()));
    let t0 = Instant::now();
    let mut written = Written::default();
    // The first failed write, naming its file; later writes are skipped
    // but the ring is still drained.
    let mut failed: Option<anyhow::Error> = None;
    let mut csv = std::io::BufWriter::with_capacity(1 << 20, csv);
    if let Err(e) = writeln!(csv, "{CSV_HEADER}") {
        failed = Some(anyhow::Error::new(e).context(format!("writing {}", csv_path.display())));
    }
    let hpaths = hlogs.as_ref().map(|[d, l]| (d.partial().to_path_buf(), l.partial().to_path_buf()));
    let mut hfiles = hlogs.map(|[d, l]| (d, l));
    let mut ser = (V2DeflateSerializer::new(), V2DeflateSerializer::new());
    let mut logs: Option<(IntervalLogWriter<'_, '_, PartialFile, V2DeflateSerializer>, IntervalLogWriter<'_, '_, PartialFile, V2DeflateSerializer>)> = None;
    if let (Some((d, l)), Some((dp, lp))) = (hfiles.as_mut(), hpaths.as_ref()) {
        let begin = |f, s, what: &str, p: &Path| {
            IntervalLogWriterBuilder::new()
                .add_comment(&format!("netfi {what} latency, ns; one interval per second"))
                .with_start_time(std::time::SystemTime::now())
                .with_max_value_divisor(1.0)
                .begin_log_with(f, s)
                .map_err(|e| anyhow::anyhow!("writing {}: {e:?}", p.display()))
        };
        let (sd, sl) = (&mut ser.0, &mut ser.1);
        match (begin(d, sd, "decision", dp), begin(l, sl, "release lateness", lp)) {
            (Ok(a), Ok(b)) => logs = Some((a, b)),
            (Err(e), _) | (_, Err(e)) => failed = failed.or(Some(e)),
        }
    }
    let mut interval_start = Duration::ZERO;
    let mut last_flush = Instant::now();
    loop {
        let stopping = stop.load(Ordering::Acquire);
        while let Ok(ev) = rx.pop() {
            table.apply(ev);
        }
        table.tick();
        let mut write_rows = |table: &mut Table, all: bool, failed: &mut Option<anyhow::Error>| {
            table.drain(all, |i, row, copy, forced| {
                written.forced += u64::from(forced);
                if failed.is_none() {
                    match format_row(&mut csv, i, row, copy, None) {
                        Ok(()) => {
                            written.rows += 1;
                            let (corrupted, released) = match copy {
                                None => (row.corrupted, row.release_ns.is_some()),
                                Some(c) => (c.corrupted, c.release_ns.is_some()),
                            };
                            written.corrupted_released += u64::from(corrupted && released);
                        }
                        Err(e) => *failed = Some(anyhow::Error::new(e).context(format!("writing {}", csv_path.display()))),
                    }
                }
            })
        };
        write_rows(&mut table, stopping, &mut failed);
        if stopping || last_flush.elapsed() >= FLUSH_EVERY {
            last_flush = Instant::now();
            let now = t0.elapsed();
            if failed.is_none() {
                if let Err(e) = csv.flush() {
                    failed = Some(anyhow::Error::new(e).context(format!("writing {}", csv_path.display())));
                }
            }
            if let (Some((dl, ll)), Some((dp, lp))) = (logs.as_mut(), hpaths.as_ref()) {
                if failed.is_none() {
                    let span = now.saturating_sub(interval_start);
                    let r1 = dl.write_histogram(table.decision.inner(), interval_start, span, Tag::new("decision"));
                    let r2 = ll.write_histogram(table.lateness.inner(), interval_start, span, Tag::new("release_lateness"));
                    match (r1, r2) {
                        (Ok(()), Ok(())) => written.intervals += 1,
                        (Err(e), _) => failed = Some(anyhow::anyhow!("writing {}: {e:?}", dp.display())),
                        (_, Err(e)) => failed = Some(anyhow::anyhow!("writing {}: {e:?}", lp.display())),
                    }
                }
                table.decision.reset();
                table.lateness.reset();
            }
            interval_start = now;
        }
        if stopping {
            break;
        }
        std::thread::sleep(tick);
    }
    // Whole: flushed, synced and under their own names; otherwise each
    // keeps its `.partial` name.
    drop(logs);
    if failed.is_none() {
        match csv.into_inner() {
            Ok(f) => {
                if let Err(e) = f.commit() {
                    failed = Some(e.into());
                }
            }
            Err(e) => failed = Some(anyhow::Error::new(e.into_error()).context(format!("writing {}", csv_path.display()))),
        }
    }
    if let (None, Some((d, l))) = (&failed, hfiles) {
        if let Err(e) = d.commit().and_then(|_| l.commit()) {
            failed = Some(e.into());
        }
    }
    match failed {
        Some(e) => Err(e),
        None => Ok(written),
    }
}

impl TraceWriter {
    /// Keeps the writer thread off `core`: a busy-polling loop pinned there
    /// would otherwise be preempted whenever the writer wakes on it (every
    /// few milliseconds, and for most of a millisecond at high rates) and
    /// its releases would be late by as much. `false` where `core` is the
    /// only core the thread may use.
    pub fn keep_off_core(&self, core: usize) -> bool {
        use std::os::unix::thread::JoinHandleExt;
        crate::host::keep_thread_off_core(self.thread.as_pthread_t(), core)
    }

    /// Streams the trace to `csv_path` from now on (and the histogram logs
    /// `decision.hlog` and `lateness.hlog` into `hlog_dir`, if given), each
    /// as `NAME.partial` until [`TraceWriter::finish`] has written it whole.
    /// The files are created here, so that one that cannot be is an error
    /// at once. Only the first call counts. Returns the histogram logs'
    /// names once whole.
    pub fn stream_to(&mut self, csv_path: &Path, hlog_dir: Option<&Path>) -> anyhow::Result<Option<[PathBuf; 2]>> {
        let Some(tx) = self.output.take() else { return Ok(None) };
        let csv = PartialFile::create(csv_path)?;
        let hlogs = match hlog_dir {
            Some(dir) => Some([PartialFile::create(&dir.join("decision.hlog"))?, PartialFile::create(&dir.join("lateness.hlog"))?]),
            None => None,
        };
        let paths = hlogs.as_ref().map(|[d, l]| [d.path().to_path_buf(), l.path().to_path_buf()]);
        // The thread is alive until `finish`; a send cannot fail before.
        let _ = tx.send(Output { csv, hlogs });
        Ok(paths)
    }

    /// Hands every trace event from now on to `tap` as well, on the writer
    /// thread.
    pub fn tap(&self, tap: Box<dyn Tap>) {
        // The thread is alive until `finish`; a send cannot fail before.
        let _ = self.taps.send(tap);
    }

    /// Stops the writer after it has written everything pushed so far
    /// (rows of frames still queued as `held`), and gives its files their
    /// own names once whole; call after the hot loop has ended. A trace
    /// never given files is written to `csv_path`. An error names the file
    /// that was cut (it keeps its `.partial` name).
    pub fn finish(mut self, csv_path: &Path) -> anyhow::Result<Written> {
        self.stream_to(csv_path, None)?;
        self.stop.store(true, Ordering::Release);
        self.thread.join().expect("the trace writer thread panicked")
    }
}

/// Writes a table as CSV, joined with receive times (`recv_ns[i]` for
/// ingress index i; 0 = not received): as `path.partial`, renamed to
/// `path` once whole.
pub fn write_csv(path: &Path, rows: &[Row], recv_ns: &[u64]) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::with_capacity(1 << 20, PartialFile::create(path).map_err(std::io::Error::other)?);
    writeln!(w, "{CSV_HEADER}")?;
    for (i, r) in rows.iter().enumerate() {
        if r.present {
            format_row(&mut w, i as u64, r, None, recv_ns.get(i).copied().filter(|t| *t != 0))?;
        }
    }
    w.into_inner().map_err(|e| e.into_error())?.commit().map_err(std::io::Error::other)?;
    Ok(())
}

/// A CSV written as its rows come, by the thread that has them (the
/// simulator's `received.csv`, the console's `video_received.csv`):
/// buffered, flushed at least once a second when rows keep coming
/// ([`CsvLog::tick`]), so that memory stays flat however long the run and
/// a killed process leaves its rows up to its last second. Nothing is
/// allocated per row. The file is `NAME.partial` until [`CsvLog::finish`]
/// has written it whole (a killed process leaves it so). The first failed
/// write is kept, later rows are skipped, and [`CsvLog::finish`] reports it
/// naming the file, which keeps its `.partial` name: a full disk is an
/// error and a file marked cut.
pub struct CsvLog {
    path: PathBuf,
    w: std::io::BufWriter<PartialFile>,
    error: Option<std::io::Error>,
    rows: u64,
    last_flush_ns: u64,
}

impl CsvLog {
    /// Creates `path.partial` with its `header` line; an error names the
    /// file.
    pub fn create(path: PathBuf, header: &str) -> anyhow::Result<CsvLog> {
        let file = PartialFile::create(&path)?;
        let partial = file.partial().to_path_buf();
        let mut w = std::io::BufWriter::with_capacity(1 << 16, file);
        writeln!(w, "{header}").with_context(|| format!("writing {}", partial.display()))?;
        Ok(CsvLog { path, w, error: None, rows: 0, last_flush_ns: 0 })
    }

    /// Appends one row, which `write` writes (its line's end included).
    #[inline]
    pub fn push(&mut self, write: impl FnOnce(&mut std::io::BufWriter<PartialFile>) -> std::io::Result<()>) {
        if self.error.is_none() {
            match write(&mut self.w) {
                Ok(()) => self.rows += 1,
                Err(e) => self.error = Some(e),
            }
        }
    }

    /// Flushes what is buffered if the last flush was a second or more
    /// before `now_ns` (any clock, as long as the caller keeps to one).
    #[inline]
    pub fn tick(&mut self, now_ns: u64) {
        if now_ns.saturating_sub(self.last_flush_ns) >= FLUSH_EVERY.as_nanos() as u64 {
            self.last_flush_ns = now_ns;
            if self.error.is_none() {
                if let Err(e) = self.w.flush() {
                    self.error = Some(e);
                }
            }
        }
    }

    /// Rows written so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// The file, as it is named once whole.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes what is buffered and gives the file its own name; returns
    /// it. The first failed write is the error, naming the file, which
    /// then stays `NAME.partial`.
    pub fn finish(mut self) -> anyhow::Result<PathBuf> {
        let partial = self.w.get_ref().partial().to_path_buf();
        let named = || format!("writing {}", partial.display());
        if let Some(e) = self.error.take() {
            return Err(anyhow::Error::new(e).context(named()));
        }
        let file = self.w.into_inner().map_err(|e| anyhow::Error::new(e.into_error()).context(named()))?;
        Ok(file.commit()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelKind;

    fn ingress(i: u64, seq: Option<u32>, send: u64, at: u64, dropped: Option<DropCause>, sched: u64) -> TraceEvent {
        TraceEvent::Ingress { ingress_index: i, sequence: seq, console_index: i, send_ns: send, ingress_ns: at, dropped, release_sched_ns: sched, decision_ns: 50, copies: 0, copies_dropped: 0, corrupted: false }
    }

    /// The row format as it was written with `write!` (one `String` per
    /// optional field): the reference the allocation-free [`format_row`]
    /// must match byte for byte.
    fn format_row_reference(i: u64, r: &Row, copy: Option<&CopyRow>, recv: Option<u64>) -> String {
        let (dropped, sched, released, corrupted) = match copy {
            None => (r.dropped, r.release_sched_ns, r.release_ns, r.corrupted),
            Some(c) => (None, c.release_sched_ns, c.release_ns, c.corrupted),
        };
        let (fate, reason, phase, stage) = match dropped {
            None if released.is_some() => ("delivered", "", String::new(), String::new()),
            None => ("held", "", String::new(), String::new()),
            Some(c) => {
                let (p, s) = match c {
                    DropCause::Stage { phase, stage, .. } => ((phase + 1).to_string(), (stage + 1).to_string()),
                    _ => (String::new(), String::new()),
                };
                ("dropped", c.reason(), p, s)
            }
        };
        let opt = |v: Option<u64>| v.map(|x| x.to_string()).unwrap_or_default();
        let scheduled = dropped.is_none();
        let (copy_no, copies_dropped) = match copy {
            None => (0, Some(u64::from(r.copies_dropped))),
            Some(c) => (c.copy, None),
        };
        format!(
            "{i},{},{},{},{},{fate},{reason},{phase},{stage},{},{},{},{},{copy_no},{},{}\n",
            r.sequence.map(|s| s.to_string()).unwrap_or_default(),
            r.console_index,
            r.send_ns,
            r.ingress_ns,
            opt(scheduled.then(|| sched.saturating_sub(r.ingress_ns))),
            opt(scheduled.then_some(sched)),
            opt(released),
            opt(recv),
            opt(copies_dropped),
            opt(scheduled.then_some(u64::from(corrupted))),
        )
    }

    #[test]
    fn rows_are_formatted_as_before_byte_for_byte() {
        let causes = [
            None,
            Some(DropCause::Stage { phase: 0, stage: 0, kind: ModelKind::GeLomax }),
            Some(DropCause::Stage { phase: 7, stage: 300, kind: ModelKind::Rate }),
            Some(DropCause::QueueFull),
            Some(DropCause::Invalid(crate::injector::Invalid::BadChecksum)),
        ];
        let (big, mut n) = (u64::MAX, 0);
        for dropped in causes {
            for released in [None, Some(0), Some(big)] {
                for sequence in [None, Some(0), Some(u32::MAX)] {
                    for (sched, ingress) in [(0, 0), (5, 9), (big, 1), (big, big)] {
                        let r = Row { present: true, sequence, console_index: big - 1, send_ns: 3, ingress_ns: ingress, dropped, release_sched_ns: sched, release_ns: released, copies_pending: 0, copies_dropped: 255, corrupted: sched % 2 == 1 };
                        let copies = [None, Some(CopyRow { ingress_index: 1, copy: 255, release_sched_ns: sched, release_ns: released, corrupted: true })];
                        for copy in copies {
                            for recv in [None, Some(big)] {
                                let mut got = Vec::new();
                                format_row(&mut got, big, &r, copy.as_ref(), recv).unwrap();
                                assert_eq!(String::from_utf8(got).unwrap(), format_row_reference(big, &r, copy.as_ref(), recv));
                                n += 1;
                            }
                        }
                    }
                }
            }
        }
        assert_eq!(n, 5 * 3 * 3 * 4 * 2 * 2);
    }

    #[test]
    fn events_become_rows_in_ingress_order_as_they_complete() {
        let dir = std::env::temp_dir().join(format!("netfi-trace-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("trace.csv");
        let (mut sink, mut writer) = start(4, 0);
        writer.stream_to(&path, Some(&dir)).unwrap();
        sink.push(ingress(0, Some(7), 10, 20, None, 120));
        let ge = DropCause::Stage { phase: 0, stage: 1, kind: ModelKind::GeLomax };
        sink.push(ingress(1, Some(8), 30, 40, Some(ge), 0));
        // Row 1 is complete but row 0 is not: nothing is written yet. Until
        // the end the file says it is not whole.
        let partial = crate::durable::partial_path(&path);
        std::thread::sleep(std::time::Duration::from_millis(1200));
        let text = std::fs::read_to_string(&partial).unwrap();
        assert_eq!(text.lines().count(), 1, "{text}");
        sink.push(TraceEvent::Release { ingress_index: 0, release_sched_ns: 120, release_ns: 121 });
        // Within the flush period both are on disk, before the end.
        std::thread::sleep(std::time::Duration::from_millis(1200));
        let text = std::fs::read_to_string(&partial).unwrap();
        assert_eq!(text.lines().count(), 3, "{text}");
        assert!(!path.exists() && !dir.join("decision.hlog").exists());
        sink.push(ingress(2, None, 50, 60, None, 70));
        let w = writer.finish(&path).unwrap();
        assert!(!partial.exists() && crate::durable::cut_files(&dir).unwrap().is_empty(), "whole files under their own names");
        assert_eq!((w.rows, w.forced), (3, 0));
        assert!(w.intervals >= 2);
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<_> = text.lines().collect();
        assert_eq!(lines[1], "0,7,0,10,20,delivered,,,,100,120,121,,0,0,0");
        assert_eq!(lines[2], "1,8,1,30,40,dropped,ge_lomax,1,2,,,,,0,0,");
        assert_eq!(lines[3], "2,,2,50,60,held,,,,10,70,,,0,0,0");
        assert_eq!(sink.overflowed(), 0);
        // One interval per flush in each histogram log, tagged.
        for (file, tag) in [("decision.hlog", "decision"), ("lateness.hlog", "release_lateness")] {
            let log = std::fs::read(dir.join(file)).unwrap();
            let tags: Vec<String> = hdrhistogram::serialization::interval_log::IntervalLogIterator::new(&log)
                .filter_map(|e| match e {
                    Ok(hdrhistogram::serialization::interval_log::LogEntry::Interval(i)) => i.tag().map(|t| t.as_str().to_string()),
                    _ => None,
                })
                .collect();
            assert_eq!(tags.len() as u64, w.intervals, "{file}");
            assert!(tags.iter().all(|t| t == tag), "{tags:?}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_csv_log_streams_its_rows_and_is_whole_once_finished() {
        let path = std::env::temp_dir().join(format!("netfi-csvlog-{}.csv", std::process::id()));
        let partial = crate::durable::partial_path(&path);
        let mut log = CsvLog::create(path.clone(), "a,b").unwrap();
        log.push(|w| writeln!(w, "1,2"));
        // Not yet a second since the last flush (none: at 0): nothing asked.
        log.tick(1);
        log.tick(FLUSH_EVERY.as_nanos() as u64);
        // Flushed while the log is still open: a killed process keeps it,
        // under the name that says it is cut.
        assert_eq!(std::fs::read_to_string(&partial).unwrap(), "a,b\n1,2\n");
        assert!(!path.exists());
        log.push(|w| writeln!(w, "3,4"));
        assert_eq!(log.rows(), 2);
        assert_eq!(log.finish().unwrap(), path);
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "a,b\n1,2\n3,4\n");
        assert!(!partial.exists());
        std::fs::remove_file(&path).ok();
    }

    /// A tmpfs of `size` mounted at a fresh directory, unmounted and
    /// removed when dropped; `None` (the test then says so and passes)
    /// where this process may not mount, unless `NETFI_REQUIRE_ROOT=1`
    /// demands it (`.ci/run` runs as root).
    struct Tmpfs(PathBuf);

    impl Tmpfs {
        fn mount(name: &str, size: &str) -> Option<Tmpfs> {
            let dir = std::env::temp_dir().join(format!("netfi-tmpfs-{}-{name}", std::process::id()));
            let _ = std::fs::create_dir_all(&dir);
            let mounted = std::process::Command::new("mount")
                .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
                .arg(&dir)
                .stderr(std::process::Stdio::piped())
                .output();
            match mounted {
                Ok(o) if o.status.success() => Some(Tmpfs(dir)),
                other => {
                    let why = match other {
                        Ok(o) => String::from_utf8_lossy(&o.stderr).trim().to_string(),
                        Err(e) => e.to_string(),
                    };
                    let _ = std::fs::remove_dir(&dir);
                    assert!(std::env::var("NETFI_REQUIRE_ROOT").as_deref() != Ok("1"), "NETFI_REQUIRE_ROOT=1 but a tmpfs cannot be mounted: {why}");
                    eprintln!("SKIP: cannot mount a tmpfs here ({why}; not root?): the full-disk test did not run");
                    None
                }
            }
        }
    }

    impl Drop for Tmpfs {
        fn drop(&mut self) {
            let _ = std::process::Command::new("umount").arg(&self.0).status();
            let _ = std::fs::remove_dir(&self.0);
        }
    }

    #[test]
    fn a_full_disk_leaves_every_file_it_cut_marked_and_named() {
        let Some(fs) = Tmpfs::mount("full", "64k") else { return };
        let dir = fs.0.clone();
        // The trace: 4,000 rows of about 60 bytes do not fit in 64 KiB.
        let (mut sink, mut writer) = start(4000, 0);
        writer.stream_to(&dir.join("trace_emulator.csv"), Some(&dir)).unwrap();
        let ge = DropCause::Stage { phase: 0, stage: 0, kind: ModelKind::GeLomax };
        for i in 0..4000 {
            sink.push(ingress(i, Some(i as u32), 1_000_000_000 + i, 2_000_000_000 + i, Some(ge), 0));
        }
        assert_eq!(sink.overflowed(), 0);
        let e = format!("{:#}", writer.finish(&dir.join("trace_emulator.csv")).unwrap_err());
        assert!(e.contains("trace_emulator.csv.partial") && e.contains("No space left on device"), "{e}");
        assert!(!dir.join("trace_emulator.csv").exists(), "a cut trace is not under its own name");
        // A CSV log on the full disk: its rows cannot be flushed.
        let mut log = CsvLog::create(dir.join("received.csv"), "ingress_index,recv_ns").unwrap();
        for i in 0..2000u64 {
            log.push(|w| writeln!(w, "{i},{}", 3_000_000_000 + i));
        }
        let e = format!("{:#}", log.finish().unwrap_err());
        assert!(e.contains("received.csv.partial") && e.contains("No space left on device"), "{e}");
        // A JSON report written whole, or not at all under its name.
        let e = crate::durable::write_whole(&dir.join("report.json"), &vec![b' '; 1 << 16]).unwrap_err();
        assert!(e.to_string().contains("report.json.partial"), "{e}");
        assert!(!dir.join("report.json").exists());
        // The run's cut files, every one named.
        let names: Vec<String> = crate::durable::cut_files(&dir)
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        for cut in ["trace_emulator.csv.partial", "decision.hlog.partial", "lateness.hlog.partial", "received.csv.partial", "report.json.partial"] {
            assert!(names.iter().any(|n| n == cut), "{cut} not among the cut files {names:?}");
        }
        // What was written before the disk filled is there to read.
        let kept = std::fs::read_to_string(dir.join("trace_emulator.csv.partial")).unwrap();
        assert!(kept.starts_with(CSV_HEADER) && kept.lines().count() > 100, "{} bytes kept", kept.len());
    }

    #[test]
    fn write_csv_joins_receive_times() {
        let rows = [Row { present: true, sequence: Some(1), console_index: 0, send_ns: 1, ingress_ns: 2, dropped: None, release_sched_ns: 3, release_ns: Some(4), ..Row::default() }];
        let path = std::env::temp_dir().join(format!("netfi-trace-join-{}.csv", std::process::id()));
        write_csv(&path, &rows, &[9]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(text.lines().nth(1), Some("0,1,0,1,2,delivered,,,,1,3,4,9,0,0,0"));
    }

    #[test]
    fn copies_get_rows_of_their_own_matched_by_scheduled_release() {
        let mut t = Table { base: 0, rows: VecDeque::new(), copies: VecDeque::new(), decision: LatencyHistogram::new(), lateness: LatencyHistogram::new(), tap: None, taps: std::sync::mpsc::channel().1 };
        // Frame 0: scheduled for 100, corrupted; two copies taken (for 300
        // and 200, the second corrupted) and one dropped.
        let mut ev = ingress(0, Some(5), 1, 10, None, 100);
        if let TraceEvent::Ingress { copies, copies_dropped, corrupted, .. } = &mut ev {
            (*copies, *copies_dropped, *corrupted) = (2, 1, true);
        }
        t.apply(ev);
        t.apply(TraceEvent::Copy { ingress_index: 0, copy: 1, release_sched_ns: 300, corrupted: false });
        t.apply(TraceEvent::Copy { ingress_index: 0, copy: 2, release_sched_ns: 200, corrupted: true });
        // Frame 1: dropped, but its one copy is taken.
        let ge = DropCause::Stage { phase: 0, stage: 2, kind: ModelKind::Bernoulli };
        let mut ev = ingress(1, Some(6), 20, 30, Some(ge), 0);
        if let TraceEvent::Ingress { copies, .. } = &mut ev {
            *copies = 1;
        }
        t.apply(ev);
        t.apply(TraceEvent::Copy { ingress_index: 1, copy: 1, release_sched_ns: 130, corrupted: false });
        let write = |t: &mut Table, all| {
            let mut out = Vec::new();
            t.drain(all, |i, r, c, _| format_row(&mut out, i, r, c, None).unwrap());
            out
        };
        t.apply(TraceEvent::Release { ingress_index: 0, release_sched_ns: 100, release_ns: 101 });
        t.apply(TraceEvent::Release { ingress_index: 1, release_sched_ns: 130, release_ns: 131 });
        t.apply(TraceEvent::Release { ingress_index: 0, release_sched_ns: 200, release_ns: 202 });
        assert!(write(&mut t, false).is_empty(), "frame 0 still has a copy queued");
        t.apply(TraceEvent::Release { ingress_index: 0, release_sched_ns: 300, release_ns: 303 });
        let out = write(&mut t, false);
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines,
            [
                "0,5,0,1,10,delivered,,,,90,100,101,,0,1,1",
                "0,5,0,1,10,delivered,,,,290,300,303,,1,,0",
                "0,5,0,1,10,delivered,,,,190,200,202,,2,,1",
                "1,6,1,20,30,dropped,bernoulli,1,3,,,,,0,0,",
                "1,6,1,20,30,delivered,,,,100,130,131,,1,,0",
            ]
        );
        assert!(t.rows.is_empty() && t.copies.is_empty());
    }
}
