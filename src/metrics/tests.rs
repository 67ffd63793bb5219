use super::*;
use hdrhistogram::serialization::interval_log::{IntervalLogIterator, LogEntry};
use hdrhistogram::Histogram;
use std::path::Path;

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
    // Before the end, the full intervals are on disk already, under the
    // log's cut name until it is whole.
    let mut on_disk = 0;
    for _ in 0..200 {
        on_disk = read_intervals(&crate::durable::partial_path(&path)).len();
        if on_disk == 3 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    assert_eq!(on_disk, 3);
    let total = log.finish(5 * s + 3_500_000_000).unwrap();
    assert!(!crate::durable::partial_path(&path).exists(), "the whole log keeps a cut name");
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

#[test]
fn an_interval_log_dropped_unfinished_stays_cut() {
    let path = std::env::temp_dir().join(format!("netfi-hlog-dropped-{}.hlog", std::process::id()));
    let mut log = IntervalLog::create(&path, "t", 0).unwrap();
    log.record(5);
    log.tick(2_000_000_000);
    drop(log);
    let cut = crate::durable::partial_path(&path);
    // The writer thread ends on its own once the log is dropped.
    for _ in 0..200 {
        if !read_intervals(&cut).is_empty() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    std::thread::sleep(std::time::Duration::from_millis(50));
    let (whole, intervals) = (path.exists(), read_intervals(&cut).len());
    std::fs::remove_file(&cut).ok();
    std::fs::remove_file(&path).ok();
    assert!(!whole, "a log whose last interval never came is under its own name");
    assert_eq!(intervals, 1, "what was written is kept");
}
