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

mod histogram;
mod interval;
mod summary;

pub use histogram::LatencyHistogram;
pub use interval::{IntervalLog, IntervalLogError, INTERVAL_NS};
pub use summary::{difference, fmt_fraction, fmt_ns, fmt_ns_signed, fmt_rate, Summary};

use hdrhistogram::serialization::interval_log::{IntervalLogWriter, IntervalLogWriterBuilder};
use hdrhistogram::serialization::V2DeflateSerializer;

/// Largest value recorded: any `u64` of ns. (Kept for its users: no value
/// is ever beyond the range.)
pub const MAX_NS: u64 = u64::MAX;

/// The most a percentile or maximum of a [`LatencyHistogram`] lies above
/// the exact value, as a fraction of it: with 3 significant digits
/// HdrHistogram's buckets are at most 2^-10 of their values wide, and it
/// reports a bucket's top.
pub const ERROR_FRACTION_MAX: f64 = crate::stats::HDR_ERROR_FRACTION_MAX;


/// Begins an HdrHistogram interval log in `out` (its header, with
/// `comment` and the wall-clock start): every log netfi writes starts so.
pub(crate) fn begin_interval_log<'a, 'b, W: std::io::Write>(
    out: &'a mut W,
    ser: &'b mut V2DeflateSerializer,
    comment: &str,
) -> std::io::Result<IntervalLogWriter<'a, 'b, W, V2DeflateSerializer>> {
    IntervalLogWriterBuilder::new().add_comment(comment).with_start_time(std::time::SystemTime::now()).with_max_value_divisor(1.0).begin_log_with(out, ser)
}

#[cfg(test)]
mod tests;
