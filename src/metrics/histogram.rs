//! One latency histogram: every `u64` of ns to 3 significant digits.

use super::{begin_interval_log, Summary, ERROR_FRACTION_MAX, MAX_NS};
use hdrhistogram::serialization::V2DeflateSerializer;
use hdrhistogram::Histogram;
use std::path::Path;

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
    /// `tag`, covering `[start_s, start_s + duration_s)`: as
    /// `path.partial`, renamed to `path` once whole (see
    /// [`crate::durable`]); a failed write leaves it cut and is an error.
    pub fn write_log(&self, path: &Path, tag: &str, start_s: f64, duration_s: f64) -> std::io::Result<()> {
        let mut file = std::io::BufWriter::new(crate::durable::PartialFile::create(path).map_err(std::io::Error::other)?);
        let mut ser = V2DeflateSerializer::new();
        {
            let mut w = begin_interval_log(&mut file, &mut ser, &format!("netfi {tag} latency, ns"))?;
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
        let file = file.into_inner().map_err(|e| e.into_error())?;
        file.commit().map(|_| ()).map_err(std::io::Error::other)
    }
}

