//! Latency histograms (HDR) and their summaries, as every report shows them.
//!
//! Values are nanoseconds, every `u64` (0 ns to 584 years: nothing a run
//! can measure or a scenario can inject is out of range), 3 significant
//! digits: each percentile and the maximum is the top of the histogram's
//! bucket holding it, at most [`ERROR_FRACTION_MAX`] (2^-10, under 0.1 %)
//! above the exact value and never below; [`Summary`] says so where it is
//! written. Recording never allocates.
//! Histograms are saved in HdrHistogram's interval-log format (V2, deflate),
//! which HdrHistogram's own plotting tools and `hdr-plot` read.

use hdrhistogram::serialization::interval_log::IntervalLogWriterBuilder;
use hdrhistogram::serialization::V2DeflateSerializer;
use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// Largest value recorded: any `u64` of ns. (Kept for its users: no value
/// is ever beyond the range.)
pub const MAX_NS: u64 = u64::MAX;

/// The most a percentile or maximum of a [`LatencyHistogram`] lies above
/// the exact value, as a fraction of it: with 3 significant digits
/// HdrHistogram's buckets are at most 2^-10 of their values wide, and it
/// reports a bucket's top.
pub const ERROR_FRACTION_MAX: f64 = crate::stats::HDR_ERROR_FRACTION_MAX;

/// A latency histogram in ns.
#[derive(Debug, Clone)]
pub struct LatencyHistogram {
    h: Histogram<u64>,
    clamped: u64,
    /// Values below zero (e.g. a negative end-to-end extra from clock
    /// granularity) are recorded as 0 and counted here.
    negative: u64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl LatencyHistogram {
    pub fn new() -> Self {
        // The whole u64 range costs about 450 KiB of counts (60 s took
        // half): a trace link's wait may be days, and a figure must not
        // be clamped without a word.
        let mut h = Histogram::new_with_bounds(1, MAX_NS, 3).expect("static bounds are valid");
        // Writing every counter once makes the counts resident now rather
        // than page by page on the hot path, as values reach new buckets.
        h.clear();
        LatencyHistogram { h, clamped: 0, negative: 0 }
    }

    #[inline]
    pub fn record(&mut self, ns: u64) {
        // Every u64 is in range: nothing saturates.
        self.h.saturating_record(ns);
    }

    /// Empties the histogram (its counts stay allocated).
    pub fn reset(&mut self) {
        self.h.reset();
        self.clamped = 0;
        self.negative = 0;
    }

    /// Records a signed value; negatives are recorded as 0 and counted.
    #[inline]
    pub fn record_signed(&mut self, ns: i64) {
        if ns < 0 {
            self.negative += 1;
            self.h.saturating_record(0);
        } else {
            self.record(ns as u64);
        }
    }

    pub fn len(&self) -> u64 {
        self.h.len()
    }

    pub fn is_empty(&self) -> bool {
        self.h.is_empty()
    }

    pub fn add(&mut self, other: &LatencyHistogram) {
        self.h.add(&other.h).expect("same bounds");
        self.clamped += other.clamped;
        self.negative += other.negative;
    }

    pub fn inner(&self) -> &Histogram<u64> {
        &self.h
    }

    pub fn summary(&self) -> Summary {
        let q = |q: f64| if self.h.is_empty() { 0 } else { self.h.value_at_quantile(q) };
        Summary {
            count: self.h.len(),
            mean: if self.h.is_empty() { 0.0 } else { self.h.mean() },
            p50: q(0.5),
            p90: q(0.9),
            p99: q(0.99),
            p999: q(0.999),
            p9999: q(0.9999),
            max: self.h.max(),
            clamped: self.clamped,
            negative: self.negative,
            error_fraction_max: Some(ERROR_FRACTION_MAX),
        }
    }

    /// Writes the histogram as one interval of an HdrHistogram log, tagged
    /// `tag`, covering `[start_s, start_s + duration_s)`.
    pub fn write_log(&self, path: &Path, tag: &str, start_s: f64, duration_s: f64) -> std::io::Result<()> {
        let mut file = std::io::BufWriter::new(std::fs::File::create(path)?);
        let mut ser = V2DeflateSerializer::new();
        {
            let mut w = IntervalLogWriterBuilder::new()
                .add_comment(&format!("netfi {tag} latency, ns"))
                .with_start_time(std::time::SystemTime::now())
                .with_max_value_divisor(1.0)
                .begin_log_with(&mut file, &mut ser)
                .map_err(std::io::Error::other)?;
            let tag = hdrhistogram::serialization::interval_log::Tag::new(tag)
                .ok_or_else(|| std::io::Error::other(format!("invalid histogram tag {tag}")))?;
            w.write_histogram(
                &self.h,
                std::time::Duration::from_secs_f64(start_s.max(0.0)),
                std::time::Duration::from_secs_f64(duration_s.max(0.0)),
                Some(tag),
            )
            .map_err(std::io::Error::other)?;
        }
        file.flush()
    }
}

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
}

impl IntervalLog {
    /// Creates `path` (an error at once if it cannot be) and starts its
    /// writer thread; intervals are tagged `tag` and timed from `origin_ns`
    /// (a clock reading, ns), the first starting there.
    pub fn create(path: &Path, tag: &str, origin_ns: u64) -> std::io::Result<IntervalLog> {
        let file = std::fs::File::create(path)?;
        let tag_ok = hdrhistogram::serialization::interval_log::Tag::new(tag).is_some();
        if !tag_ok {
            return Err(std::io::Error::other(format!("invalid histogram tag {tag}")));
        }
        let (full_tx, full_rx) = std::sync::mpsc::sync_channel::<FullInterval>(SPARE_HISTOGRAMS + 1);
        let (empty_tx, empty_rx) = std::sync::mpsc::sync_channel::<LatencyHistogram>(SPARE_HISTOGRAMS + 1);
        for _ in 0..SPARE_HISTOGRAMS {
            let _ = empty_tx.send(LatencyHistogram::new());
        }
        let tag = tag.to_string();
        let thread = std::thread::Builder::new()
            .name("netfi-hlog".into())
            .spawn(move || interval_writer(file, &tag, full_rx, empty_tx))?;
        Ok(IntervalLog {
            current: LatencyHistogram::new(),
            origin_ns,
            started_ns: origin_ns,
            full: full_tx,
            empty: empty_rx,
            thread,
            path: path.to_path_buf(),
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
    /// returns the run's total (the sum of every interval written). A
    /// failed write is an error naming the file.
    pub fn finish(mut self, now_ns: u64) -> std::io::Result<LatencyHistogram> {
        if let Ok(empty) = self.empty.recv() {
            self.hand_over(empty, now_ns);
        }
        let IntervalLog { full, thread, path, .. } = self;
        drop(full);
        let result = thread.join().unwrap_or_else(|_| Err(std::io::Error::other("the interval log writer panicked")));
        result.map_err(|e| std::io::Error::new(e.kind(), format!("writing {}: {e}", path.display())))
    }
}

/// The writer thread of an [`IntervalLog`]: appends each full interval,
/// flushes, adds it to the total, and sends the histogram back emptied.
/// After a failed write it keeps taking intervals (so the recorder never
/// waits) and returns the error at the end.
fn interval_writer(
    file: std::fs::File,
    tag: &str,
    full: std::sync::mpsc::Receiver<FullInterval>,
    empty: std::sync::mpsc::SyncSender<LatencyHistogram>,
) -> std::io::Result<LatencyHistogram> {
    // Unbuffered: an interval is a few writes once a second, on disk as
    // soon as it is written.
    let mut out = file;
    let mut ser = V2DeflateSerializer::new();
    let mut total = LatencyHistogram::new();
    let mut failed: Option<std::io::Error> = None;
    let tag_ = hdrhistogram::serialization::interval_log::Tag::new(tag);
    let mut log = IntervalLogWriterBuilder::new()
        .add_comment(&format!("netfi {tag} latency, ns; one interval per second"))
        .with_start_time(std::time::SystemTime::now())
        .with_max_value_divisor(1.0)
        .begin_log_with(&mut out, &mut ser)
        .map_err(std::io::Error::other);
    while let Ok(mut f) = full.recv() {
        total.add(&f.h);
        if let (Ok(w), None) = (log.as_mut(), failed.as_ref()) {
            let written = w.write_histogram(f.h.inner(), f.start, f.span, tag_);
            failed = written.err().map(|e| std::io::Error::other(format!("{e:?}")));
        }
        f.h.reset();
        let _ = empty.send(f.h);
    }
    match (log, failed) {
        (Err(e), _) | (_, Some(e)) => Err(e),
        (Ok(_), None) => Ok(total),
    }
}

/// Percentiles of a latency histogram, in ns.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub count: u64,
    pub mean: f64,
    pub p50: u64,
    pub p90: u64,
    pub p99: u64,
    pub p999: u64,
    pub p9999: u64,
    pub max: u64,
    /// Values above the histogram's range (recorded as its maximum): 0
    /// since the range is every u64.
    pub clamped: u64,
    /// Negative values (recorded as 0).
    pub negative: u64,
    /// The precision of the percentiles and the maximum: each is at most
    /// this fraction above the exact value, never below
    /// ([`ERROR_FRACTION_MAX`]; `null` in files written before it was
    /// said).
    #[serde(default)]
    pub error_fraction_max: Option<f64>,
}

impl Summary {
    /// The percentile or maximum named `key`: `p50`, `p90`, `p99`, `p999`,
    /// `p9999` or `max`.
    pub fn get(&self, key: &str) -> Option<u64> {
        Some(match key {
            "p50" => self.p50,
            "p90" => self.p90,
            "p99" => self.p99,
            "p999" => self.p999,
            "p9999" => self.p9999,
            "max" => self.max,
            _ => return None,
        })
    }

    /// One line: `p50 1.2 µs  p90 …  max …` in readable units, with the
    /// count and the precision ([`Summary::precision`]).
    pub fn line(&self) -> String {
        format!(
            "p50 {}  p90 {}  p99 {}  p99.9 {}  p99.99 {}  max {}  (n={}{})",
            fmt_ns(self.p50),
            fmt_ns(self.p90),
            fmt_ns(self.p99),
            fmt_ns(self.p999),
            fmt_ns(self.p9999),
            fmt_ns(self.max),
            self.count,
            self.precision().map(|p| format!("; {p}")).unwrap_or_default()
        )
    }

    /// The precision in words, for a text report: `each at most 0.1 %
    /// high` (and what was clamped or negative, if anything was); `None`
    /// when unknown (a file written before it was said).
    pub fn precision(&self) -> Option<String> {
        let mut words = vec![format!("each at most {} high", fmt_fraction(self.error_fraction_max?))];
        if self.clamped > 0 {
            words.push(format!("{} values above the range counted at its top", self.clamped));
        }
        if self.negative > 0 {
            words.push(format!("{} negative values counted as 0", self.negative));
        }
        Some(words.join(", "))
    }
}

/// A duration in ns, in the unit that reads best.
pub fn fmt_ns(ns: u64) -> String {
    match ns {
        0..=999 => format!("{ns} ns"),
        1_000..=999_999 => format!("{:.2} µs", ns as f64 / 1e3),
        1_000_000..=999_999_999 => format!("{:.3} ms", ns as f64 / 1e6),
        _ => format!("{:.3} s", ns as f64 / 1e9),
    }
}

/// A fraction as a percentage to two significant digits (`0.098 %`).
pub fn fmt_fraction(f: f64) -> String {
    let pct = f * 100.0;
    let digits = (1 - pct.abs().log10().floor() as i32).max(0) as usize;
    format!("{pct:.digits$} %")
}

/// `a − b` at each of `keys` (see [`Summary::get`]; an unknown key is left
/// out).
pub fn difference(a: &Summary, b: &Summary, keys: &[&str]) -> std::collections::BTreeMap<String, i64> {
    keys.iter()
        .filter_map(|k| Some((k.to_string(), a.get(k)? as i64 - b.get(k)? as i64)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use hdrhistogram::serialization::interval_log::{IntervalLogIterator, LogEntry};

    #[test]
    fn summary_percentiles_within_three_digits() {
        let mut h = LatencyHistogram::new();
        for v in 1..=100_000u64 {
            h.record(v * 10);
        }
        h.record_signed(-5);
        let s = h.summary();
        assert_eq!(s.count, 100_001);
        assert_eq!(s.negative, 1);
        for (got, want) in [(s.p50, 500_000u64), (s.p99, 990_000), (s.p999, 999_000)] {
            assert!((got as f64 - want as f64).abs() <= want as f64 * 1e-3, "{got} vs {want}");
        }
        assert!((s.max as f64 - 1e6).abs() <= 1e3);
    }

    #[test]
    fn values_of_years_are_recorded_within_the_stated_precision() {
        // A trace link's frames may wait days or years: nothing clamps.
        let mut h = LatencyHistogram::new();
        let year_ns = 31_557_600_000_000_000u64;
        for k in 1..=1_000u64 {
            h.record(k * (year_ns / 100));
        }
        h.record(u64::MAX);
        let s = h.summary();
        assert_eq!(s.clamped, 0);
        for (got, want) in [(s.p50, 501 * (year_ns / 100)), (s.p99, 991 * (year_ns / 100)), (s.max, u64::MAX)] {
            assert!(got >= want && (got - want) as f64 <= want as f64 * ERROR_FRACTION_MAX, "{got} vs {want}");
        }
        assert_eq!(s.error_fraction_max, Some(ERROR_FRACTION_MAX));
        assert!(s.line().ends_with("(n=1001; each at most 0.098 % high)"), "{}", s.line());
        // A summary read from an older file says nothing of its precision.
        let old: Summary = serde_json::from_str(r#"{"count":1,"mean":1.0,"p50":1,"p90":1,"p99":1,"p999":1,"p9999":1,"max":1,"clamped":0,"negative":0}"#).unwrap();
        assert_eq!((old.error_fraction_max, old.precision()), (None, None));
    }

    #[test]
    fn the_log_reads_back() {
        let mut h = LatencyHistogram::new();
        for v in [100u64, 200, 300, 5_000_000] {
            h.record(v);
        }
        let path = std::env::temp_dir().join(format!("netfi-hlog-{}.hlog", std::process::id()));
        h.write_log(&path, "decision", 0.0, 1.0).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).ok();
        let intervals: Vec<_> = IntervalLogIterator::new(&bytes)
            .filter_map(|e| match e {
                Ok(LogEntry::Interval(i)) => Some(i),
                _ => None,
            })
            .collect();
        assert_eq!(intervals.len(), 1);
        assert_eq!(intervals[0].tag().map(|t| t.as_str().to_string()), Some("decision".to_string()));
    }

    #[test]
    fn an_interval_log_streams_one_interval_per_second_and_totals_them() {
        let path = std::env::temp_dir().join(format!("netfi-intervals-{}.hlog", std::process::id()));
        let s = 1_000_000_000u64;
        let mut log = IntervalLog::create(&path, "end_to_end_extra", 5 * s).unwrap();
        let mut whole = LatencyHistogram::new();
        // Three and a half seconds, a value every 10 ms, ticks every 100 ms.
        for k in 0..350u64 {
            let t = 5 * s + k * 10_000_000;
            if k % 10 == 0 {
                log.tick(t);
            }
            let v = 1_000 + k * 37;
            log.record_signed(v as i64 - 2_000);
            whole.record_signed(v as i64 - 2_000);
        }
        // Before the end, the full intervals are on disk already.
        let mut on_disk = 0;
        for _ in 0..200 {
            on_disk = read_intervals(&path).len();
            if on_disk == 3 {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        assert_eq!(on_disk, 3);
        let total = log.finish(5 * s + 3_500_000_000).unwrap();
        let intervals = read_intervals(&path);
        std::fs::remove_file(&path).ok();
        assert_eq!(intervals.len(), 4);
        let counts: Vec<u64> = intervals.iter().map(|(_, _, n)| *n).collect();
        assert_eq!(counts, [100, 100, 100, 50]);
        let starts: Vec<f64> = intervals.iter().map(|(t, _, _)| *t).collect();
        assert_eq!(starts, [0.0, 1.0, 2.0, 3.0]);
        assert_eq!(total.summary(), whole.summary());
    }

    /// (start s, duration s, count) of each interval in the log at `path`.
    fn read_intervals(path: &Path) -> Vec<(f64, f64, u64)> {
        use base64::Engine;
        let bytes = std::fs::read(path).unwrap_or_default();
        let mut de = hdrhistogram::serialization::Deserializer::new();
        IntervalLogIterator::new(&bytes)
            .filter_map(|e| match e {
                Ok(LogEntry::Interval(i)) => {
                    let raw = base64::engine::general_purpose::STANDARD.decode(i.encoded_histogram()).unwrap();
                    let h: Histogram<u64> = de.deserialize(&mut raw.as_slice()).unwrap();
                    Some((i.start_timestamp().as_secs_f64(), i.duration().as_secs_f64(), h.len()))
                }
                _ => None,
            })
            .collect()
    }
}
