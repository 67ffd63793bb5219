//! The writer thread: it drains the ring into the table, appends complete
//! rows to the CSV, flushes every second and cuts the histogram intervals;
//! and its handle, [`TraceWriter`].

use super::ring::{ring, TraceEvent, TraceSink};
use super::column::CSV_HEADER;
use super::row::format_row;
use super::table::{CopyRow, Row, Table, Tap};
use super::FLUSH_EVERY;
use crate::durable::{DurableError, PartialFile};
use crate::metrics::begin_interval_log;
use hdrhistogram::serialization::interval_log::{IntervalLogWriter, IntervalLogWriterError, Tag};
use hdrhistogram::serialization::{V2DeflateSerializeError, V2DeflateSerializer};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

/// Rows the writer has room for at first when streaming.
const PENDING_ROWS_START: usize = 4096;

/// The shortest and the longest the writer sleeps between two looks at
/// the ring.
const TICK_MIN: Duration = Duration::from_millis(5);
const TICK_MAX: Duration = Duration::from_millis(20);

/// How long the writer sleeps: long, because each wake takes a core from
/// whatever else runs there (at a wake every 5 ms, a sockperf ping-pong
/// through the UDP bridge lost about 10 µs at p99 to the two writers on its
/// core; every 100 ms, the longer batches cost its p99.99 instead), but no
/// longer than would fill a quarter of the ring at the rate just seen. A
/// jump from nothing to 10⁶ frames/s within the longest sleep (4·10⁴
/// events) still fits in the ring. [`TraceWriter`]'s `close` and `finish`
/// wake it at once.
struct Pace {
    last: Instant,
}

impl Pace {
    fn new() -> Pace {
        Pace { last: Instant::now() }
    }

    /// Sleeps after a look that found `events` waiting.
    fn sleep(&mut self, events: usize) {
        let now = Instant::now();
        let per_s = events as f64 / now.duration_since(self.last).as_secs_f64().max(1e-6);
        self.last = now;
        let quarter = Duration::from_secs_f64((super::ring::RING_CAPACITY / 4) as f64 / per_s.max(1.0));
        std::thread::park_timeout(quarter.clamp(TICK_MIN, TICK_MAX));
    }
}

/// Why the trace could not be written whole. Each names the file as it is
/// on disk: cut, it keeps its `.partial` name.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    /// The CSV or a histogram log could not be created, written, synced or
    /// renamed (a full disk: `No space left on device`).
    #[error(transparent)]
    File(#[from] DurableError),
    /// A histogram log's interval could not be written.
    #[error("writing {}: {source}", .path.display())]
    Histogram {
        /// The histogram log.
        path: PathBuf,
        /// What the HdrHistogram log writer said.
        #[source]
        source: IntervalLogWriterError<V2DeflateSerializeError>,
    },
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

/// Where the writer writes: the CSV, and the histogram logs if asked.
struct Output {
    csv: PartialFile,
    hlogs: Option<[PartialFile; 2]>,
}

/// The writer thread's handle.
pub struct TraceWriter {
    stop: Arc<AtomicBool>,
    output: Option<mpsc::Sender<Output>>,
    taps: mpsc::Sender<Box<dyn Tap>>,
    thread: std::thread::JoinHandle<Result<Written, TraceError>>,
}

/// Starts the writer thread (call before pinning the hot thread, so the
/// writer is not confined to its core) and returns the hot path's sink.
/// Rows are kept in memory until [`TraceWriter::stream_to`] gives files.
/// `expected_copies` reserves room for the rows of copies (`duplicate`
/// stages) likewise; 0 where the scenario makes none.
pub fn start(expected_frames: usize, expected_copies: usize) -> (TraceSink, TraceWriter) {
    let (sink, rx) = ring();
    let stop = Arc::new(AtomicBool::new(false));
    let stop2 = stop.clone();
    let (out_tx, out_rx) = mpsc::channel();
    let (tap_tx, tap_rx) = mpsc::channel::<Box<dyn Tap>>();
    // Allocated here, not in the thread, so that nothing the writer holds
    // is allocated while the loop runs. Room for every row while there is
    // nowhere to write them.
    let table = Table::with_capacity(expected_frames, expected_copies, tap_rx);
    let thread = std::thread::Builder::new()
        .name("netfi-trace".into())
        .spawn(move || writer(rx, out_rx, stop2, table))
        .expect("spawning the trace writer thread");
    (sink, TraceWriter { stop, output: Some(out_tx), taps: tap_tx, thread })
}

/// The writer thread: until it has files, it keeps rows in memory; then it
/// appends, flushing every second; at the stop, it writes what is left.
fn writer(mut rx: rtrb::Consumer<TraceEvent>, out_rx: mpsc::Receiver<Output>, stop: Arc<AtomicBool>, mut table: Table) -> Result<Written, TraceError> {
    let Some(Output { csv, hlogs }) = wait_for_files(&mut rx, &out_rx, &stop, &mut table) else {
        return Ok(Written::default());
    };
    // From now on only the rows of frames in flight are held: a small
    // ring, grown by doubling (off the hot path) when more are.
    table.rows.shrink_to(PENDING_ROWS_START.max(table.rows.len()));
    let mut csv = CsvOut::begin(csv);
    let mut hfiles = hlogs;
    let mut ser = [V2DeflateSerializer::new(), V2DeflateSerializer::new()];
    let mut logs = match hfiles.as_mut() {
        Some(files) => csv.keep(HistLogs::begin(files, &mut ser)),
        None => None,
    };
    stream(&mut rx, &stop, &mut table, &mut csv, logs.as_mut());
    // Whole: flushed, synced and under their own names; otherwise each
    // keeps its `.partial` name.
    drop(logs);
    csv.commit(hfiles)
}

/// Applies events, writing nothing, until the files come; `None` if the
/// writer is stopped (or its handle dropped) first: nowhere to write, the
/// rows are dropped with the thread.
fn wait_for_files(rx: &mut rtrb::Consumer<TraceEvent>, out_rx: &mpsc::Receiver<Output>, stop: &AtomicBool, table: &mut Table) -> Option<Output> {
    let mut pace = Pace::new();
    loop {
        let stopping = stop.load(Ordering::Acquire);
        let events = rx.slots();
        table.take(rx);
        match out_rx.try_recv() {
            Ok(out) => return Some(out),
            // The handle was dropped without `finish`: nobody will ask.
            Err(mpsc::TryRecvError::Disconnected) if !stopping => return None,
            Err(_) => {}
        }
        if stopping {
            return None;
        }
        pace.sleep(events);
    }
}

/// Until the stop: complete rows appended as they come; every second the
/// CSV flushed and a histogram interval cut; at the stop, every row.
fn stream(rx: &mut rtrb::Consumer<TraceEvent>, stop: &AtomicBool, table: &mut Table, csv: &mut CsvOut, mut logs: Option<&mut HistLogs<'_>>) {
    let t0 = Instant::now();
    let mut interval_start = Duration::ZERO;
    let mut last_flush = Instant::now();
    let mut pace = Pace::new();
    loop {
        let stopping = stop.load(Ordering::Acquire);
        let events = rx.slots();
        table.take(rx);
        table.drain(stopping, |i, row, copy, forced| csv.row(i, row, copy, forced));
        if stopping || last_flush.elapsed() >= FLUSH_EVERY {
            last_flush = Instant::now();
            let now = t0.elapsed();
            csv.flush();
            if let Some(l) = logs.as_deref_mut() {
                if csv.failed.is_none() {
                    let r = l.append(table, interval_start, now.saturating_sub(interval_start));
                    if let Some(()) = csv.keep(r) {
                        csv.written.intervals += 1;
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
        pace.sleep(events);
    }
}

/// The CSV being written, what was written, and the first failure (naming
/// its file): after it, writes are skipped but the ring is still drained,
/// so the loop is never held up.
struct CsvOut {
    w: BufWriter<PartialFile>,
    /// The file as it stands on disk: cut, it keeps this name.
    path: PathBuf,
    written: Written,
    failed: Option<TraceError>,
}

impl CsvOut {
    /// The CSV with its header line.
    fn begin(file: PartialFile) -> CsvOut {
        let path = file.partial().to_path_buf();
        let mut out = CsvOut { w: BufWriter::with_capacity(1 << 20, file), path, written: Written::default(), failed: None };
        let r = writeln!(out.w, "{CSV_HEADER}");
        out.io(r);
        out
    }

    /// `r`'s value, or `None` with its error kept if it is the first.
    fn keep<T>(&mut self, r: Result<T, TraceError>) -> Option<T> {
        match r {
            Ok(v) => Some(v),
            Err(e) => {
                self.failed = self.failed.take().or(Some(e));
                None
            }
        }
    }

    /// Keeps a failed write to the CSV, naming it.
    fn io(&mut self, r: std::io::Result<()>) -> Option<()> {
        let path = &self.path;
        let r = r.map_err(|source| TraceError::from(DurableError::Write { path: path.clone(), source }));
        self.keep(r)
    }

    /// Appends one row (the frame's, or with `copy` one of its copies'),
    /// unless a write has failed.
    fn row(&mut self, i: u64, row: &Row, copy: Option<&CopyRow>, forced: bool) {
        self.written.forced += u64::from(forced);
        if self.failed.is_some() {
            return;
        }
        let r = format_row(&mut self.w, i, row, copy, None);
        if self.io(r).is_some() {
            self.written.rows += 1;
            let (corrupted, released) = match copy {
                None => (row.corrupted, row.release_ns.is_some()),
                Some(c) => (c.corrupted, c.release_ns.is_some()),
            };
            self.written.corrupted_released += u64::from(corrupted && released);
        }
    }

    fn flush(&mut self) {
        if self.failed.is_none() {
            let r = self.w.flush();
            self.io(r);
        }
    }

    /// Gives the CSV, then the histogram logs, their own names once whole;
    /// the first failure, if any, is the result. Their directory is synced
    /// by the report written there after them (the path's owner's), not
    /// once per file: a stop with many lanes waits on the disk once per
    /// lane, not four times.
    fn commit(mut self, hlogs: Option<[PartialFile; 2]>) -> Result<Written, TraceError> {
        if self.failed.is_none() {
            match self.w.into_inner() {
                Ok(f) => {
                    if let Err(e) = f.commit_unsynced_name() {
                        self.failed = Some(e.into());
                    }
                }
                Err(e) => self.failed = Some(DurableError::Write { path: self.path, source: e.into_error() }.into()),
            }
        }
        if let (None, Some([d, l])) = (&self.failed, hlogs) {
            if let Err(e) = d.commit_unsynced_name().and_then(|_| l.commit_unsynced_name()) {
                self.failed = Some(e.into());
            }
        }
        match self.failed {
            Some(e) => Err(e),
            None => Ok(self.written),
        }
    }
}

/// The two histogram logs, decision time and release lateness: one interval
/// of each a second.
struct HistLogs<'a> {
    decision: IntervalLogWriter<'a, 'a, PartialFile, V2DeflateSerializer>,
    lateness: IntervalLogWriter<'a, 'a, PartialFile, V2DeflateSerializer>,
    paths: [PathBuf; 2],
}

impl<'a> HistLogs<'a> {
    /// Writes each log's header.
    fn begin(files: &'a mut [PartialFile; 2], ser: &'a mut [V2DeflateSerializer; 2]) -> Result<HistLogs<'a>, TraceError> {
        let paths = [files[0].partial().to_path_buf(), files[1].partial().to_path_buf()];
        let [d, l] = files;
        let [sd, sl] = ser;
        let begin = |f, s, what: &str, p: &Path| {
            begin_interval_log(f, s, &format!("netfi {what} latency, ns; one interval per second"))
                .map_err(|source| TraceError::from(DurableError::Write { path: p.to_path_buf(), source }))
        };
        let decision = begin(d, sd, "decision", &paths[0]);
        let lateness = begin(l, sl, "release lateness", &paths[1]);
        Ok(HistLogs { decision: decision?, lateness: lateness?, paths })
    }

    /// Appends the table's histograms as the interval from `start` lasting
    /// `span`.
    fn append(&mut self, table: &Table, start: Duration, span: Duration) -> Result<(), TraceError> {
        let r1 = self.decision.write_histogram(table.decision.inner(), start, span, Tag::new("decision"));
        let r2 = self.lateness.write_histogram(table.lateness.inner(), start, span, Tag::new("release_lateness"));
        r1.map_err(|source| TraceError::Histogram { path: self.paths[0].clone(), source })?;
        r2.map_err(|source| TraceError::Histogram { path: self.paths[1].clone(), source })
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
    pub fn stream_to(&mut self, csv_path: &Path, hlog_dir: Option<&Path>) -> Result<Option<[PathBuf; 2]>, DurableError> {
        let Some(tx) = self.output.take() else { return Ok(None) };
        let csv = PartialFile::create(csv_path)?;
        let hlogs = match hlog_dir {
            Some(dir) => Some([PartialFile::create(&dir.join("decision.hlog"))?, PartialFile::create(&dir.join("lateness.hlog"))?]),
            None => None,
        };
        let paths = hlogs.as_ref().map(|[d, l]| [d.path().to_path_buf(), l.path().to_path_buf()]);
        // The thread is alive until `finish`; a send cannot fail before.
        let _ = tx.send(Output { csv, hlogs });
        self.thread.thread().unpark();
        Ok(paths)
    }

    /// Hands every trace event from now on to `tap` as well, on the writer
    /// thread.
    pub fn tap(&self, tap: Box<dyn Tap>) {
        // The thread is alive until `finish`; a send cannot fail before.
        let _ = self.taps.send(tap);
    }

    /// Asks the writer to stop once it has written everything pushed so
    /// far and to give its files their own names, without waiting: several
    /// writers closed at once write and sync at once. Nothing may be pushed
    /// after; [`TraceWriter::finish`] waits for it. A writer never given
    /// its files is left to [`TraceWriter::finish`], which gives them.
    pub fn close(&self) {
        if self.output.is_none() {
            self.stop.store(true, Ordering::Release);
            self.thread.thread().unpark();
        }
    }

    /// Stops the writer after it has written everything pushed so far
    /// (rows of frames still queued as `held`), and gives its files their
    /// own names once whole; call after the hot loop has ended. A trace
    /// never given files is written to `csv_path`. An error names the file
    /// that was cut (it keeps its `.partial` name).
    pub fn finish(mut self, csv_path: &Path) -> Result<Written, TraceError> {
        self.stream_to(csv_path, None)?;
        self.stop.store(true, Ordering::Release);
        self.thread.thread().unpark();
        self.thread.join().expect("the trace writer thread panicked")
    }
}
