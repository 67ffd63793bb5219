//! Latency histograms (HDR) and their summaries, as every report shows them.
//!
//! Values are nanoseconds, 1 ns to 60 s, 3 significant digits. Recording
//! never allocates; a value beyond the range is clamped to it and counted.
//! Histograms are saved in HdrHistogram's interval-log format (V2, deflate),
//! which HdrHistogram's own plotting tools and `hdr-plot` read.

use hdrhistogram::serialization::interval_log::IntervalLogWriterBuilder;
use hdrhistogram::serialization::V2DeflateSerializer;
use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// Largest value recorded exactly: 60 s.
pub const MAX_NS: u64 = 60_000_000_000;

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
        let mut h = Histogram::new_with_bounds(1, MAX_NS, 3).expect("static bounds are valid");
        // Writing every counter once makes the counts resident now rather
        // than page by page on the hot path, as values reach new buckets.
        h.clear();
        LatencyHistogram { h, clamped: 0, negative: 0 }
    }

    #[inline]
    pub fn record(&mut self, ns: u64) {
        if ns > MAX_NS {
            self.clamped += 1;
        }
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
    /// Values above the histogram's range (recorded as its maximum).
    pub clamped: u64,
    /// Negative values (recorded as 0).
    pub negative: u64,
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

    /// One line: `p50 1.2 µs  p90 …  max …` in readable units.
    pub fn line(&self) -> String {
        format!(
            "p50 {}  p90 {}  p99 {}  p99.9 {}  p99.99 {}  max {}  (n={})",
            fmt_ns(self.p50),
            fmt_ns(self.p90),
            fmt_ns(self.p99),
            fmt_ns(self.p999),
            fmt_ns(self.p9999),
            fmt_ns(self.max),
            self.count
        )
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
}
