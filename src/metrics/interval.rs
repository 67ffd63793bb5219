//! A latency histogram streamed to an interval log, one interval a
//! second, by a writer thread.

use super::{begin_interval_log, LatencyHistogram};
use crate::durable::PartialFile;
use hdrhistogram::serialization::V2DeflateSerializer;
use std::path::{Path, PathBuf};

/// Length of one interval of an [`IntervalLog`]: one second.
pub const INTERVAL_NS: u64 = 1_000_000_000;

/// Histograms an [`IntervalLog`] circulates between its recorder and its
/// writer thread, besides the one being recorded.
const SPARE_HISTOGRAMS: usize = 3;

/// A full interval on its way to the writer thread.
struct FullInterval {
    h: LatencyHistogram,
    start: std::time::Duration,
    span: std::time::Duration,
}

/// An interval log that could not be created or written whole, naming it.
#[derive(Debug, thiserror::Error)]
#[error("writing {}: {source}", .path.display())]
pub struct IntervalLogError {
    /// The log.
    pub path: PathBuf,
    /// The kernel's error (or the writer thread's end).
    #[source]
    pub source: std::io::Error,
}

/// A latency histogram streamed to an HdrHistogram interval log, one
/// interval per second, as the run goes.
///
/// Values are recorded into the current interval's histogram only (as
/// cheap as [`LatencyHistogram::record`]). [`IntervalLog::tick`], called
/// off the per-value path, hands a full interval to a writer thread and
/// takes an emptied one back: a fixed set of histograms circulates, so
/// nothing is allocated after [`IntervalLog::create`] and memory stays
/// flat however long the run. The thread appends and flushes each
/// interval as it comes (a killed process leaves its log up to its last
/// second) and adds it to the run's total, which [`IntervalLog::finish`]
/// returns: the whole-run figures are exactly those of the intervals'
/// sum. If the writer has no empty histogram to give back yet, the current
/// interval simply goes on until it has.
pub struct IntervalLog {
    current: LatencyHistogram,
    origin_ns: u64,
    started_ns: u64,
    full: std::sync::mpsc::SyncSender<FullInterval>,
    empty: std::sync::mpsc::Receiver<LatencyHistogram>,
    thread: std::thread::JoinHandle<std::io::Result<LatencyHistogram>>,
    path: std::path::PathBuf,
    /// Set by [`IntervalLog::finish`]: only then is the log whole. A log
    /// dropped without it (its process failed first) keeps its `.partial`
    /// name, its last interval missing.
    finished: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

impl IntervalLog {
    /// Creates `path` as `path.partial` (an error at once if it cannot
    /// be; see [`crate::durable`]) and starts its writer thread; intervals
    /// are tagged `tag` and timed from `origin_ns` (a clock reading, ns),
    /// the first starting there. [`IntervalLog::finish`] gives the log its
    /// own name once whole; a log whose writer failed or was killed keeps
    /// its `.partial` name.
    pub fn create(path: &Path, tag: &str, origin_ns: u64) -> Result<IntervalLog, IntervalLogError> {
        let named = |source| IntervalLogError { path: crate::durable::partial_path(path), source };
        let file = PartialFile::create(path).map_err(|e| named(std::io::Error::other(e)))?;
        let tag_ok = hdrhistogram::serialization::interval_log::Tag::new(tag).is_some();
        if !tag_ok {
            return Err(named(std::io::Error::other(format!("invalid histogram tag {tag}"))));
        }
        let (full_tx, full_rx) = std::sync::mpsc::sync_channel::<FullInterval>(SPARE_HISTOGRAMS + 1);
        let (empty_tx, empty_rx) = std::sync::mpsc::sync_channel::<LatencyHistogram>(SPARE_HISTOGRAMS + 1);
        for _ in 0..SPARE_HISTOGRAMS {
            let _ = empty_tx.send(LatencyHistogram::new());
        }
        let tag = tag.to_string();
        let finished = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let whole = finished.clone();
        let thread = std::thread::Builder::new()
            .name("netfi-hlog".into())
            .spawn(move || interval_writer(file, &tag, full_rx, empty_tx, &whole))
            .map_err(named)?;
        Ok(IntervalLog {
            current: LatencyHistogram::new(),
            origin_ns,
            started_ns: origin_ns,
            full: full_tx,
            empty: empty_rx,
            thread,
            path: path.to_path_buf(),
            finished,
        })
    }

    /// Records a value into the current interval.
    #[inline]
    pub fn record(&mut self, ns: u64) {
        self.current.record(ns);
    }

    /// Records a signed value into the current interval (see
    /// [`LatencyHistogram::record_signed`]).
    #[inline]
    pub fn record_signed(&mut self, ns: i64) {
        self.current.record_signed(ns);
    }

    /// Ends the current interval if it has lasted [`INTERVAL_NS`] by
    /// `now_ns` and the writer has an empty histogram to give back.
    pub fn tick(&mut self, now_ns: u64) {
        if now_ns.saturating_sub(self.started_ns) >= INTERVAL_NS {
            if let Ok(empty) = self.empty.try_recv() {
                self.hand_over(empty, now_ns);
            }
        }
    }

    fn hand_over(&mut self, empty: LatencyHistogram, now_ns: u64) {
        let h = std::mem::replace(&mut self.current, empty);
        let ns = |t: u64| std::time::Duration::from_nanos(t);
        let full = FullInterval { h, start: ns(self.started_ns.saturating_sub(self.origin_ns)), span: ns(now_ns.saturating_sub(self.started_ns)) };
        self.started_ns = now_ns;
        // At most SPARE_HISTOGRAMS + 1 are ever in flight: the channel has
        // room. A writer gone (it panicked) is reported by `finish`.
        let _ = self.full.send(full);
    }

    /// Ends the last interval at `now_ns`, waits for the writer, and
    /// returns the run's total (the sum of every interval written), the
    /// log whole under its own name. A failed write is an error naming the
    /// file, which keeps its `.partial` name (cut).
    pub fn finish(mut self, now_ns: u64) -> Result<LatencyHistogram, IntervalLogError> {
        if let Ok(empty) = self.empty.recv() {
            self.hand_over(empty, now_ns);
        }
        let IntervalLog { full, thread, path, finished, .. } = self;
        finished.store(true, std::sync::atomic::Ordering::Release);
        drop(full);
        let result = thread.join().unwrap_or_else(|_| Err(std::io::Error::other("the interval log writer panicked")));
        result.map_err(|source| IntervalLogError { path: crate::durable::partial_path(&path), source })
    }
}

/// The writer thread of an [`IntervalLog`]: appends each full interval,
/// flushes, adds it to the total, and sends the histogram back emptied;
/// at the end, once `finished` says the last interval came, syncs the log
/// and gives it its own name. After a failed write it keeps taking
/// intervals (so the recorder never waits) and returns the error at the
/// end, the log left cut (as one whose recorder was dropped unfinished).
fn interval_writer(
    file: PartialFile,
    tag: &str,
    full: std::sync::mpsc::Receiver<FullInterval>,
    empty: std::sync::mpsc::SyncSender<LatencyHistogram>,
    finished: &std::sync::atomic::AtomicBool,
) -> std::io::Result<LatencyHistogram> {
    // Unbuffered: an interval is a few writes once a second, on disk as
    // soon as it is written.
    let mut out = file;
    let mut ser = V2DeflateSerializer::new();
    let mut total = LatencyHistogram::new();
    let mut failed: Option<std::io::Error> = None;
    let tag_ = hdrhistogram::serialization::interval_log::Tag::new(tag);
    let mut log = begin_interval_log(&mut out, &mut ser, &format!("netfi {tag} latency, ns; one interval per second"));
    while let Ok(mut f) = full.recv() {
        total.add(&f.h);
        if let (Ok(w), None) = (log.as_mut(), failed.as_ref()) {
            let written = w.write_histogram(f.h.inner(), f.start, f.span, tag_);
            failed = written.err().map(|e| std::io::Error::other(format!("{e:?}")));
        }
        f.h.reset();
        let _ = empty.send(f.h);
    }
    let written = match (log, failed) {
        (Err(e), _) | (_, Some(e)) => Err(e),
        (Ok(_), None) if !finished.load(std::sync::atomic::Ordering::Acquire) => Err(std::io::Error::other("the log was dropped before its last interval")),
        (Ok(_), None) => Ok(()),
    };
    written.and_then(|()| out.commit().map(|_| total).map_err(std::io::Error::other))
}

