//! What a run left in its output directory, read for the page: the report
//! (`report.json`, or for a run started by hand the report assembled from
//! its services' own), the HdrHistogram logs, the scenario's delay law and
//! the trace's summary.
//!
//! Files are looked up in the directory by name (not by the absolute paths
//! the report holds), so a run directory that was moved or copied still
//! renders. A file the report says was written must be there; one it does
//! not name is shown as not recorded.

use super::trace::{self, TraceSummary};
use super::HtmlError;
use crate::service::report::RunReport;
use hdrhistogram::Histogram;
use std::path::{Path, PathBuf};

/// One latency distribution from an HdrHistogram log (all its intervals).
pub struct Latency {
    pub label: &'static str,
    pub file: &'static str,
    pub histogram: Option<Histogram<u64>>,
}

/// One interval of an HdrHistogram log: when it started (seconds from the
/// log's start), how long it lasted, its count and percentiles (ns).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntervalPoint {
    pub start_s: f64,
    pub duration_s: f64,
    pub count: u64,
    pub p50: u64,
    pub p99: u64,
    pub max: u64,
}

pub use crate::service::report::Law;

/// Everything the page shows.
pub struct RunInputs {
    pub dir: PathBuf,
    pub report: RunReport,
    pub latency: Vec<Latency>,
    /// The whole run's delay law: only where it ran one condition throughout.
    pub law: Option<Law>,
    pub trace: Option<TraceSummary>,
    /// The scenario the run started with, as TOML (its copy, or the preset
    /// it names), where known.
    pub scenario_toml: Option<String>,
    /// The delay law of each of the run's stretches (`report.phases`).
    pub phase_laws: Vec<Option<Law>>,
}

/// The first time bin is about a 100th of the run, rounded up to 1, 2 or
/// 5 × 10^k ns, and at least 10 ms.
const BINS_PER_RUN: f64 = 100.0;
const BIN_NS_MIN: u64 = 10_000_000;

pub fn bin_ns(duration_s: f64) -> u64 {
    let raw = (duration_s * 1e9 / BINS_PER_RUN).max(BIN_NS_MIN as f64);
    let decade = 10f64.powf(raw.log10().floor());
    let nice = [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * decade).find(|w| *w >= raw).unwrap_or(10.0 * decade);
    nice as u64
}

impl RunInputs {
    /// Reads the run directory `dir`.
    pub fn read(dir: &Path) -> Result<RunInputs, HtmlError> {
        let report = RunReport::of_dir(dir)?;
        let f = &report.files;
        // The simulator writes direct_hop.hlog beside end_to_end.hlog.
        let latency = vec![
            latency(dir, "emulator added (end-to-end extra)", "end_to_end.hlog", f.end_to_end_hlog.is_some())?,
            latency(dir, "direct hop", "direct_hop.hlog", f.end_to_end_hlog.is_some())?,
            latency(dir, "release lateness", "lateness.hlog", f.lateness_hlog.is_some())?,
            latency(dir, "decision", "decision.hlog", f.decision_hlog.is_some())?,
        ];
        let (spec, scenario_toml) = scenario(dir, &report)?;
        let one_condition = report.events.is_empty() && report.phases.is_empty() && report.phases_unknown.is_none();
        let law = match (&spec, one_condition) {
            (Some(spec), true) => {
                let scenario = crate::scenario::Scenario::new(spec, report.seed).map_err(|e| HtmlError::malformed(&dir.join("scenario.toml"), e.to_string()))?;
                Law::of_scenario(&scenario)
            }
            _ => None,
        };
        let phase_laws = phase_laws(spec.as_ref(), &report);
        let starts: Vec<u64> = report.phases.iter().map(|p| p.from_ns).collect();
        let trace = match &f.trace {
            Some(_) => Some(trace::summarize(&dir.join("trace.csv"), bin_ns(report.duration_s), &starts)?),
            None => None,
        };
        Ok(RunInputs { dir: dir.to_path_buf(), report, latency, law, trace, scenario_toml, phase_laws })
    }
}

/// The histogram of `dir/file`, all intervals added; `None` when the run
/// did not write it (`expected` false).
fn latency(dir: &Path, label: &'static str, file: &'static str, expected: bool) -> Result<Latency, HtmlError> {
    let histogram = if expected { Some(read_hlog(&dir.join(file))?) } else { None };
    Ok(Latency { label, file, histogram })
}

/// Adds up every interval of an HdrHistogram interval log.
pub fn read_hlog(path: &Path) -> Result<Histogram<u64>, HtmlError> {
    read_hlog_intervals(path).map(|(total, _)| total)
}

/// Adds up every interval of an HdrHistogram interval log, and returns
/// each interval's count and percentiles too.
pub fn read_hlog_intervals(path: &Path) -> Result<(Histogram<u64>, Vec<IntervalPoint>), HtmlError> {
    use base64::Engine;
    use hdrhistogram::serialization::interval_log::{IntervalLogIterator, LogEntry};
    let bytes = crate::load::read_file(path).map_err(|e| HtmlError::read(path, e))?;
    let mut total: Option<Histogram<u64>> = None;
    let mut points = Vec::new();
    let mut de = hdrhistogram::serialization::Deserializer::new();
    for entry in IntervalLogIterator::new(&bytes) {
        let entry = entry.map_err(|e| HtmlError::malformed(path, format!("not an HdrHistogram interval log: {e:?}")))?;
        let LogEntry::Interval(i) = entry else { continue };
        let raw = base64::engine::general_purpose::STANDARD
            .decode(i.encoded_histogram())
            .map_err(|e| HtmlError::malformed(path, format!("an interval's histogram is not base64: {e}")))?;
        let h: Histogram<u64> = de.deserialize(&mut raw.as_slice()).map_err(|e| HtmlError::malformed(path, format!("an interval's histogram does not decode: {e:?}")))?;
        let q = |q: f64| if h.is_empty() { 0 } else { h.value_at_quantile(q) };
        points.push(IntervalPoint {
            start_s: i.start_timestamp().as_secs_f64(),
            duration_s: i.duration().as_secs_f64(),
            count: h.len(),
            p50: q(0.5),
            p99: q(0.99),
            max: h.max(),
        });
        match &mut total {
            Some(t) => t.add(&h).map_err(|e| HtmlError::malformed(path, format!("intervals of different ranges: {e:?}")))?,
            None => {
                let mut t = h;
                t.auto(true);
                total = Some(t);
            }
        }
    }
    let total = total.ok_or_else(|| HtmlError::malformed(path, "no histogram interval in it"))?;
    Ok((total, points))
}

/// The scenario the run started with and its text: the run's own copy,
/// which must be there when the report names one; else (a run started by
/// hand) the preset the report names, if it is one.
fn scenario(dir: &Path, report: &RunReport) -> Result<(Option<crate::scenario::ScenarioSpec>, Option<String>), HtmlError> {
    match &report.files.scenario {
        Some(_) => {
            let path = dir.join("scenario.toml");
            let text = crate::load::open_regular(&path).and_then(std::io::read_to_string).map_err(|e| HtmlError::read(&path, e))?;
            let spec = crate::load::parse_file(&path).map_err(|e| HtmlError::malformed(&path, e.to_string()))?;
            Ok((Some(spec), Some(text)))
        }
        None => Ok(match crate::scenario::preset(&report.scenario) {
            Some(spec) => {
                let text = spec.to_toml();
                (Some(spec), Some(text))
            }
            None => (None, None),
        }),
    }
}

/// The delay law of each stretch of the run (`report.phases`), from the
/// timeline its scenario and control events make.
fn phase_laws(spec: Option<&crate::scenario::ScenarioSpec>, report: &RunReport) -> Vec<Option<Law>> {
    let timeline = spec.and_then(|s| crate::service::report::RunTimeline::of(s, &report.events).ok());
    report
        .phases
        .iter()
        .map(|p| {
            let t = timeline.as_ref()?;
            let phase = t.phases.get(p.run_phase.checked_sub(1)?)?;
            let built = crate::scenario::Timeline::new(&phase.spec, phase.phase).ok()?;
            if p.paused {
                return None;
            }
            Law::of_phase(built.phases().first()?)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #[test]
    fn an_hlog_reads_back_as_written() {
        let mut h = crate::metrics::LatencyHistogram::new();
        for v in 1..=1000u64 {
            h.record(v * 1000);
        }
        let path = std::env::temp_dir().join(format!("netfi-html-hlog-{}.hlog", std::process::id()));
        h.write_log(&path, "t", 0.0, 1.0).unwrap();
        let back = super::read_hlog(&path);
        std::fs::remove_file(&path).ok();
        let back = back.unwrap();
        assert_eq!(back.len(), 1000);
        assert_eq!(back.max(), h.inner().max());
        assert_eq!(back.value_at_quantile(0.5), h.inner().value_at_quantile(0.5));
    }

    #[test]
    fn bin_widths_are_round() {
        assert_eq!(super::bin_ns(0.0), 10_000_000);
        assert_eq!(super::bin_ns(6.11), 100_000_000);
        assert_eq!(super::bin_ns(3600.0), 50_000_000_000);
    }
}
