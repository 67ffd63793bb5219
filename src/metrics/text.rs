//! Figures as a report's text writes them: a count that may be unknown,
//! drops by reason, a distribution's percentiles on one line.

use super::{fmt_ns, Summary};
use std::collections::BTreeMap;

/// A count, or `?` where it is unknown.
pub fn opt(v: Option<u64>) -> String {
    v.map_or("?".to_string(), |x| x.to_string())
}

/// `N by CAUSE, …`, or `none`.
pub fn dropped_list(dropped: &BTreeMap<String, u64>) -> String {
    let d: Vec<String> = dropped.iter().map(|(k, v)| format!("{v} by {k}")).collect();
    if d.is_empty() {
        "none".into()
    } else {
        d.join(", ")
    }
}

/// A summary's percentiles on one line, `-` when there is none.
pub fn line(p: &Option<Summary>) -> String {
    match p {
        Some(p) => format!(
            "p50 {}  p90 {}  p99 {}  p99.9 {}  p99.99 {}  max {}",
            fmt_ns(p.p50),
            fmt_ns(p.p90),
            fmt_ns(p.p99),
            fmt_ns(p.p999),
            fmt_ns(p.p9999),
            fmt_ns(p.max)
        ),
        None => "unavailable".into(),
    }
}
