//! A histogram's percentiles as reports show them, and their units.

use serde::{Deserialize, Serialize};

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
    /// ([`ERROR_FRACTION_MAX`](super::ERROR_FRACTION_MAX); `null` in files written before it was
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

/// A signed duration in ns (a difference of two), as [`fmt_ns`] writes
/// its size.
pub fn fmt_ns_signed(ns: i64) -> String {
    let size = fmt_ns(ns.unsigned_abs());
    if ns < 0 {
        format!("-{size}")
    } else {
        size
    }
}

/// A rate in [0, 1] to `decimals` places, or, for one above 0 that those
/// places would show as 0 (the upper bound of a loss-free run's interval,
/// about 3/n), to two significant digits: a bound never reads as 0 when it
/// is not.
pub fn fmt_rate(rate: f64, decimals: usize) -> String {
    let text = format!("{rate:.decimals$}");
    if rate > 0.0 && text.parse::<f64>() == Ok(0.0) {
        let digits = (1 - rate.log10().floor() as i32).max(0) as usize;
        return format!("{rate:.digits$}");
    }
    text
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

    #[test]
    fn durations_and_rates_read_in_their_units() {
        assert_eq!([fmt_ns_signed(106), fmt_ns_signed(1_038_200), fmt_ns_signed(-4_702_720)], ["106 ns", "1.038 ms", "-4.703 ms"]);
        assert_eq!(fmt_ns_signed(i64::MIN), "-9223372036.855 s");
        // A bound above 0 never reads as 0; one that reads as itself keeps its places.
        assert_eq!([fmt_rate(0.0, 4), fmt_rate(0.0003, 4), fmt_rate(3.0e-6, 4), fmt_rate(2.9957e-6, 5), fmt_rate(1.0, 4)], ["0.0000", "0.0003", "0.0000030", "0.0000030", "1.0000"]);
        assert_eq!(fmt_rate(0.00004999, 4), "0.000050");
    }
}
