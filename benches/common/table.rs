//! Percentile tables: the keys every table shows, the median and spread of
//! a percentile over repetitions, and Markdown rows.

use netfi::metrics::{fmt_ns, Summary};
use serde::Serialize;
use std::collections::BTreeMap;

/// The percentiles and the maximum a table shows.
pub const KEYS: [&str; 6] = ["p50", "p90", "p99", "p999", "p9999", "max"];

/// One value per key of [`KEYS`].
pub type Map = BTreeMap<String, i64>;

/// The least, the median and the largest of a figure over repetitions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spread {
    pub min: f64,
    pub median: f64,
    pub max: f64,
    pub n: usize,
}

impl Spread {
    /// The spread of the finite values of `v`; `None` when there are none.
    pub fn of(v: impl IntoIterator<Item = f64>) -> Option<Spread> {
        let mut v: Vec<f64> = v.into_iter().filter(|x| x.is_finite()).collect();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        (n > 0).then(|| Spread { min: v[0], median: if n % 2 == 1 { v[n / 2] } else { (v[n / 2 - 1] + v[n / 2]) / 2.0 }, max: v[n - 1], n })
    }

    /// "1.20 µs (0.98 µs – 1.49 µs)": the median, then the range, of
    /// durations; one value alone where there is one.
    pub fn ns(&self) -> String {
        if self.n == 1 {
            return ns(self.median as i64);
        }
        format!("{} ({} – {})", ns(self.median as i64), ns(self.min as i64), ns(self.max as i64))
    }
}

impl Spread {
    /// "0.01–0.12%": the range of fractions, in per cent.
    pub fn percent(&self) -> String {
        format!("{:.2}–{:.2}%", self.min * 100.0, self.max * 100.0)
    }
}

/// [`Spread::ns`] of an optional spread ("–" where there is none).
pub fn spread_ns(s: Option<Spread>) -> String {
    s.map_or("–".to_string(), |s| s.ns())
}

/// A summary's keys of [`KEYS`] as a map.
pub fn summary_map(s: &Summary) -> Map {
    KEYS.iter().filter_map(|k| Some((k.to_string(), s.get(k)? as i64))).collect()
}

/// Per key: the median over `maps`.
pub fn median_map(maps: &[Map]) -> Map {
    KEYS.iter()
        .filter_map(|k| {
            let s = Spread::of(maps.iter().filter_map(|m| m.get(*k)).map(|v| *v as f64))?;
            Some((k.to_string(), s.median.round() as i64))
        })
        .collect()
}

/// Per key: the spread over `maps`.
pub fn spread_map(maps: &[Map]) -> BTreeMap<String, Spread> {
    KEYS.iter().filter_map(|k| Some((k.to_string(), Spread::of(maps.iter().filter_map(|m| m.get(*k)).map(|v| *v as f64))?))).collect()
}

/// A signed duration in the unit that reads best.
pub fn ns(v: i64) -> String {
    if v < 0 {
        format!("−{}", fmt_ns(v.unsigned_abs()))
    } else {
        fmt_ns(v as u64)
    }
}

/// The header of a percentile table whose first column is `what`.
pub fn header(what: &str) -> String {
    format!("| {what} | p50 | p90 | p99 | p99.9 | p99.99 | max |\n|---|---|---|---|---|---|---|")
}

/// One row of a percentile table.
pub fn row(label: &str, m: &Map) -> String {
    let cells: Vec<String> = KEYS.iter().map(|k| m.get(*k).map_or("–".to_string(), |v| ns(*v))).collect();
    format!("| {label} | {} |", cells.join(" | "))
}

/// `1k`, `100k`, or the rate itself.
pub fn rate_label(rate_hz: f64) -> String {
    if rate_hz >= 1000.0 && (rate_hz / 1000.0).fract() == 0.0 {
        format!("{}k", rate_hz / 1000.0)
    } else {
        format!("{rate_hz}")
    }
}
