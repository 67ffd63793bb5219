//! The report's plots, from the run's inputs to [`plot::Figure`]s.

use super::inputs::{Latency, Law};
use super::plot::{self, Bars, Figure, Line, Scale};
use super::plot::Mark;
use super::trace::{Delays, TraceSummary};
use super::HtmlError;
use crate::metrics::fmt_ns;
use hdrhistogram::Histogram;
use std::collections::BTreeMap;

/// Points drawn per curve at most (a CDF of many distinct values is thinned).
const MAX_POINTS: usize = 400;

/// The usual HdrHistogram plot: value against percentile on a
/// `1/(1 − q)` axis, so that 90%, 99%, 99.9% … are evenly spaced.
pub fn percentiles(series: &[Latency]) -> Result<Option<String>, HtmlError> {
    let colors = [plot::BLUE, plot::ORANGE, plot::GREEN, plot::PURPLE];
    let mut lines = Vec::new();
    for (s, color) in series.iter().zip(colors) {
        let Some(h) = s.histogram.as_ref().filter(|h| !h.is_empty()) else { continue };
        let top = 1.0 - 1.0 / h.len() as f64;
        let points = h
            .iter_quantiles(4)
            .map(|v| (1.0 / (1.0 - v.quantile_iterated_to().min(top)), v.value_iterated_to().max(1) as f64))
            .collect();
        lines.push(Line { label: s.label.to_string(), color, points });
    }
    if lines.is_empty() {
        return Ok(None);
    }
    let (x, y) = extent(&lines);
    let x_top = 10f64.powf(x.end.log10().ceil()).max(10.0);
    plot::svg(&Figure {
        id: "plot-latency",
        title: "Latency by percentile",
        x_desc: "percentile",
        y_desc: "latency",
        x: Scale::log(1.0..x_top),
        y: Scale::log((y.start / 2.0).max(0.5)..y.end * 2.0),
        x_fmt: &percentile_label,
        y_fmt: &|v| fmt_ns(*v as u64),
        lines,
        bars: Vec::new(),
        marks: &[],
    })
    .map(Some)
}

/// A link stage's queue over time: the max packets queued in each second
/// of the run (from its first frame), with the run's switches and pauses.
pub fn link_occupancy(l: &crate::check::LinkReport, id: &str, marks: &[Mark]) -> Result<Option<String>, HtmlError> {
    if l.occupancy.is_empty() {
        return Ok(None);
    }
    let points: Vec<(f64, f64)> = l.occupancy.iter().map(|o| (o.second as f64 + 0.5, o.packets_max as f64)).collect();
    let end = l.occupancy.last().map_or(1.0, |o| o.second as f64 + 1.0);
    let top = points.iter().map(|p| p.1).fold(1.0, f64::max) * 1.1;
    over_time(id, &format!("Queue of phase {} {}, per second", l.phase, l.label), "packets queued, max", end, Scale::linear(0.0..top), vec![Line { label: "packets queued, max".into(), color: plot::GREEN, points }], marks)
}

/// A plot of `lines` over the run's time (s from its first frame, to
/// `end_s`), with the run's switches and pauses.
fn over_time(id: &str, title: &str, y_desc: &str, end_s: f64, y: Scale, lines: Vec<Line>, marks: &[Mark]) -> Result<Option<String>, HtmlError> {
    plot::svg(&Figure {
        id,
        title,
        x_desc: "time since the first frame (s)",
        y_desc,
        x: Scale::linear(0.0..end_s),
        y,
        x_fmt: &plot::short,
        y_fmt: &plot::short,
        lines,
        bars: Vec::new(),
        marks,
    })
    .map(Some)
}

/// `x = 1/(1 − q)` as the percentile it stands for: 10 → `90%`.
fn percentile_label(x: &f64) -> String {
    let p = 100.0 * (1.0 - 1.0 / x.max(1.0));
    let digits = x.log10().ceil().max(2.0) as usize - 2;
    let s = format!("{p:.digits$}");
    format!("{}%", if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.') } else { &s })
}

/// The smallest ranges holding every point of `lines`.
fn extent(lines: &[Line]) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let pts = lines.iter().flat_map(|l| l.points.iter());
    let (mut x, mut y) = (f64::INFINITY..f64::NEG_INFINITY, f64::INFINITY..f64::NEG_INFINITY);
    for &(px, py) in pts {
        (x.start, x.end, y.start, y.end) = (x.start.min(px), x.end.max(px), y.start.min(py), y.end.max(py));
    }
    (x, y)
}

/// The empirical distribution function of `h` (ns) in ms, thinned.
fn cdf_ms(h: &Histogram<u64>) -> Vec<(f64, f64)> {
    let n = h.len() as f64;
    let recorded: Vec<(f64, f64)> = h
        .iter_recorded()
        .scan(0u64, |cum, v| {
            *cum += v.count_since_last_iteration();
            Some((h.highest_equivalent(v.value_iterated_to()) as f64 / 1e6, *cum as f64 / n))
        })
        .collect();
    let step = recorded.len().div_ceil(MAX_POINTS).max(1);
    let last = recorded.last().copied();
    let mut pts: Vec<(f64, f64)> = recorded.into_iter().step_by(step).collect();
    pts.extend(last.filter(|l| pts.last() != Some(l)));
    pts
}

/// Delays seen and drawn against the law's distribution function, as the
/// plot `id` titled `title`.
pub fn delay_law(t: &Delays, law: Option<&Law>, id: &str, title: &str) -> Result<Option<String>, HtmlError> {
    if t.drawn_ns.is_empty() || t.drawn_ns.max() <= 1 {
        return Ok(None);
    }
    let mut lines = vec![Line { label: "drawn by the emulator".into(), color: plot::ORANGE, points: cdf_ms(&t.drawn_ns) }];
    if !t.seen_ns.is_empty() {
        lines.push(Line { label: "seen by the robot".into(), color: plot::BLUE, points: cdf_ms(&t.seen_ns) });
    }
    // The axis ends at the 99.9th percentile seen: one straggler would squeeze the rest.
    // An empty histogram's minimum reads 0: only the recorded ones count.
    let lo = [&t.drawn_ns, &t.seen_ns].iter().filter(|h| !h.is_empty()).map(|h| h.min()).min().unwrap_or(0) as f64 / 1e6;
    let hi = (t.drawn_ns.value_at_quantile(0.999).max(t.seen_ns.value_at_quantile(0.999)) as f64 / 1e6).max(lo + 1e-3);
    let (lo, hi) = (lo - 0.02 * (hi - lo), hi + 0.02 * (hi - lo));
    if let Some(law) = law {
        let points = (0..=300).map(|i| lo + (hi - lo) * i as f64 / 300.0).map(|x| (x, law.cdf_ms(x))).collect();
        lines.push(Line { label: "analytic law".into(), color: plot::GREY, points });
    }
    for l in &mut lines {
        l.points.retain(|p| p.0 <= hi);
    }
    plot::svg(&Figure {
        id,
        title,
        x_desc: "delay (ms)",
        y_desc: "fraction of frames ≤ delay",
        x: Scale::linear(lo..hi),
        y: Scale::linear(0.0..1.0),
        x_fmt: &plot::short,
        y_fmt: &plot::short,
        lines,
        bars: Vec::new(),
        marks: &[],
    })
    .map(Some)
}

/// A bin width as read: `100 ms`, `2 s`.
fn bin_label(ns: u64) -> String {
    match ns {
        ns if ns >= 1_000_000_000 => format!("{} s", plot::short(&(ns as f64 / 1e9))),
        ns => format!("{} ms", plot::short(&(ns as f64 / 1e6))),
    }
}

/// Loss rate per time bin, with the run's switches and pauses.
pub fn loss_over_time(t: &TraceSummary, marks: &[Mark]) -> Result<Option<String>, HtmlError> {
    let points: Vec<(f64, f64)> =
        t.bins.iter().enumerate().filter(|(_, b)| b.frames > 0).map(|(i, b)| (t.centre_s(i), b.dropped as f64 / b.frames as f64)).collect();
    if points.len() < 2 {
        return Ok(None);
    }
    over_time("plot-loss-over-time", &format!("Loss per {} bin", bin_label(t.bin_ns)), "fraction of frames dropped", t.end_s(), Scale::linear(0.0..1.0), vec![Line { label: "loss rate".into(), color: plot::PURPLE, points }], marks)
}

/// `f` of each bin that has a value, at the bin's middle, ns → ms.
fn per_bin(t: &TraceSummary, f: &dyn Fn(&super::trace::Bin) -> Option<f64>) -> Vec<(f64, f64)> {
    t.bins.iter().enumerate().filter_map(|(i, b)| f(b).map(|v| (t.centre_s(i), v / 1e6))).collect()
}

/// Mean drawn and seen delay, and the longest seen, per time bin, with
/// the run's switches and pauses.
pub fn delay_over_time(t: &TraceSummary, marks: &[Mark]) -> Result<Option<String>, HtmlError> {
    let lines = vec![
        Line { label: "drawn, mean".into(), color: plot::ORANGE, points: per_bin(t, &|b| (b.delivered > 0).then(|| b.drawn_sum_ns as f64 / b.delivered as f64)) },
        Line { label: "seen, mean".into(), color: plot::BLUE, points: per_bin(t, &|b| (b.received > 0).then(|| b.seen_sum_ns as f64 / b.received as f64)) },
        Line { label: "seen, max".into(), color: plot::GREY, points: per_bin(t, &|b| (b.received > 0).then_some(b.seen_max_ns as f64)) },
    ];
    if lines[0].points.len() < 2 || t.delays.drawn_ns.max() <= 1 {
        return Ok(None);
    }
    let (_, y) = extent(&lines);
    over_time("plot-delay-over-time", &format!("Delay per {} bin", bin_label(t.bin_ns)), "delay (ms)", t.end_s(), Scale::linear(0.0..y.end * 1.1), lines, marks)
}

/// What netfi added per time bin, from the trace: release lateness (actual
/// − scheduled release) and end to end (receive − send − injected delay),
/// mean and max, with the run's switches and pauses.
pub fn added_over_time(t: &TraceSummary, marks: &[Mark]) -> Result<Option<String>, HtmlError> {
    let lines = vec![
        Line { label: "end to end, mean".into(), color: plot::BLUE, points: per_bin(t, &|b| (b.received > 0).then(|| b.added_sum_ns as f64 / b.received as f64)) },
        Line { label: "end to end, max".into(), color: plot::SKY, points: per_bin(t, &|b| (b.received > 0).then_some(b.added_max_ns as f64)) },
        Line { label: "release lateness, mean".into(), color: plot::VERMILLION, points: per_bin(t, &|b| (b.released > 0).then(|| b.late_sum_ns as f64 / b.released as f64)) },
        Line { label: "release lateness, max".into(), color: plot::ORANGE, points: per_bin(t, &|b| (b.released > 0).then_some(b.late_max_ns as f64)) },
    ];
    let lines: Vec<Line> = lines.into_iter().filter(|l| l.points.len() >= 2).collect();
    if lines.is_empty() {
        return Ok(None);
    }
    let (_, y) = extent(&lines);
    // Milliseconds on a log axis: microseconds and a preempted frame's
    // tens of milliseconds in one plot.
    over_time("plot-added-over-time", &format!("What netfi added per {} bin", bin_label(t.bin_ns)), "added (ms)", t.end_s(), Scale::log((y.start.max(1e-6) / 2.0)..(y.end.max(1e-5) * 2.0)), lines, marks)
}

/// Lengths up to this are one bar each; longer runs are grouped in powers of two.
const RUN_LENGTHS_ONE_BY_ONE: u64 = 40;

/// How many loss runs of each length; bars.
pub fn loss_runs(runs: &BTreeMap<u64, u64>) -> Result<Option<String>, HtmlError> {
    loss_runs_as(runs, "plot-loss-runs", "Loss runs (consecutive frames dropped)")
}

/// [`loss_runs`] as the plot `id` titled `title`.
pub fn loss_runs_as(runs: &BTreeMap<u64, u64>, id: &str, title: &str) -> Result<Option<String>, HtmlError> {
    let Some(&longest) = runs.keys().next_back() else { return Ok(None) };
    let (bars, labels): (Vec<(f64, f64, f64)>, Vec<String>) = if longest <= RUN_LENGTHS_ONE_BY_ONE {
        runs.iter().map(|(&l, &n)| ((l as f64 - 0.4, l as f64 + 0.4, n as f64), l.to_string())).unzip()
    } else {
        let mut buckets: BTreeMap<u32, u64> = BTreeMap::new();
        for (&l, &n) in runs {
            *buckets.entry(l.ilog2()).or_default() += n;
        }
        (0..=longest.ilog2())
            .map(|k| {
                let (a, b) = (1u64 << k, (1u64 << (k + 1)) - 1);
                let label = if a == b { a.to_string() } else { format!("{a}–{b}") };
                ((k as f64 - 0.4, k as f64 + 0.4, buckets.get(&k).copied().unwrap_or(0) as f64), label)
            })
            .unzip()
    };
    let grouped = longest > RUN_LENGTHS_ONE_BY_ONE;
    let x_fmt = |v: &f64| -> String {
        match plot::whole(*v) {
            Some(k) if grouped => usize::try_from(k).ok().and_then(|k| labels.get(k).cloned()).unwrap_or_default(),
            Some(k) => k.to_string(),
            None => String::new(),
        }
    };
    let x_end = bars.last().map_or(1.0, |b| b.1 + 0.6);
    let y_end = bars.iter().map(|b| b.2).fold(1.0, f64::max) * 1.1;
    plot::svg(&Figure {
        id,
        title,
        x_desc: if grouped { "run length (frames, grouped)" } else { "run length (frames)" },
        y_desc: "runs",
        x: Scale::linear(if grouped { -0.6 } else { 0.4 }..x_end),
        y: Scale::linear(0.0..y_end),
        x_fmt: &x_fmt,
        y_fmt: &plot::short,
        lines: Vec::new(),
        bars: vec![Bars { label: "runs".into(), color: plot::PURPLE, bars }],
        marks: &[],
    })
    .map(Some)
}

/// Divergence between the console's and the robot's pose per arm, mm:
/// at the end and the max, as bars.
pub fn divergence(final_mm: [f64; 2], max_mm: [f64; 2]) -> Result<String, HtmlError> {
    let bars = |v: [f64; 2], from: f64, to: f64| (0..2).map(|a| (a as f64 + from, a as f64 + to, v[a])).collect();
    let y_end = max_mm.iter().chain(final_mm.iter()).fold(1.0f64, |a, b| a.max(*b)) * 1.15;
    plot::svg(&Figure {
        id: "plot-divergence",
        title: "Console vs robot pose, per arm",
        x_desc: "",
        y_desc: "divergence (mm)",
        x: Scale::linear(-0.6..1.6),
        y: Scale::linear(0.0..y_end),
        x_fmt: &|v| plot::whole(*v).filter(|a| (0..2).contains(a)).map_or(String::new(), |a| format!("arm {a}")),
        y_fmt: &plot::short,
        lines: Vec::new(),
        bars: vec![
            Bars { label: "at the end".into(), color: plot::BLUE, bars: bars(final_mm, -0.35, -0.02) },
            Bars { label: "max".into(), color: plot::ORANGE, bars: bars(max_mm, 0.02, 0.35) },
        ],
        marks: &[],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_labels() {
        let l: Vec<String> = [1.0, 2.0, 10.0, 100.0, 1000.0, 1e4, 1e6].iter().map(percentile_label).collect();
        assert_eq!(l, ["0%", "50%", "90%", "99%", "99.9%", "99.99%", "99.9999%"]);
    }

    #[test]
    fn cdf_ends_at_one_and_is_thinned() {
        let mut h = Histogram::<u64>::new_with_bounds(1, 3_600_000_000_000, 3).unwrap();
        for v in 1..=100_000u64 {
            h.record(v * 1000).unwrap();
        }
        let pts = cdf_ms(&h);
        assert!(pts.len() <= MAX_POINTS + 1, "{}", pts.len());
        assert_eq!(pts.last().unwrap().1, 1.0);
        assert!(pts.windows(2).all(|w| w[0].0 < w[1].0 && w[0].1 <= w[1].1));
    }
}
