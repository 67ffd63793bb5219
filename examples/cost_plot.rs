//! Draws docs/performance.md's "cost as the work grows" figures from the
//! measured points in `docs/cost.csv`: one SVG per axis (rate, queue depth,
//! stream count, payload size), one line per series.
//!
//! ```sh
//! cargo run --example cost_plot            # writes docs/cost-<axis>.svg
//! ```
//!
//! `docs/cost.csv` has a header and the columns `axis,x,series,ns,machine,
//! cores,load,steal,command`: `ns` is the cost of one frame (or one packet)
//! in ns at `x`, measured on `machine` (`cores` of them) under that load
//! average and steal (%) by `command`, the last column, which may hold
//! commas. The benchmarks that measure a curve write rows of it into their
//! results (`target/netfi-bench/<program>/cost.csv`). The figures are
//! rebuilt from it, never edited by hand; where an axis has points of more
//! than one machine, each line names its machine.

use netfi::html::plot::{self, Figure, Line, Scale};
use std::collections::BTreeMap;
use std::path::Path;

/// One axis: its name in the CSV, its title and label, whether it is
/// logarithmic.
const AXES: [(&str, &str, &str, bool); 4] = [
    ("rate", "Emulator's CPU per frame against the rate", "frames per second", true),
    ("depth", "Release queue: push + pop against its depth", "frames held", true),
    ("streams", "Release lateness and ingress wait against the stream count (1 kHz each)", "streams", true),
    ("payload", "Emulator's cost per payload against its size", "payload bytes", true),
];

const COLORS: [plotters::style::RGBColor; 7] = [plot::BLUE, plot::ORANGE, plot::GREEN, plot::PURPLE, plot::GREY, plot::VERMILLION, plot::SKY];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs");
    let csv = std::fs::read_to_string(docs.join("cost.csv")).map_err(|e| format!("docs/cost.csv: {e}"))?;
    let points = parse(&csv)?;
    for (axis, title, x_desc, log) in AXES {
        let Some(series) = points.get(axis) else { continue };
        let svg = figure(axis, title, x_desc, log, series)?;
        let path = docs.join(format!("cost-{axis}.svg"));
        // A file of its own needs the namespace an inline <svg> does without.
        let svg = svg.replacen("<svg ", "<svg xmlns=\"http://www.w3.org/2000/svg\" ", 1);
        std::fs::write(&path, svg).map_err(|e| format!("{}: {e}", path.display()))?;
        println!("{}", path.display());
    }
    Ok(())
}

/// axis → series → points (x, ns), in file order.
type Points = BTreeMap<String, BTreeMap<String, Vec<(f64, f64)>>>;

/// The columns before `command`.
const COLUMNS: usize = 8;

fn parse(csv: &str) -> Result<Points, String> {
    let mut rows = Vec::new();
    for (i, line) in csv.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.splitn(COLUMNS + 1, ',').collect();
        if f.len() <= COLUMNS {
            return Err(format!("docs/cost.csv line {}: {} columns, expected {}", i + 1, f.len(), COLUMNS + 1));
        }
        let num = |k: usize| f[k].trim().parse::<f64>().map_err(|_| format!("docs/cost.csv line {}: column {} is not a number", i + 1, k + 1));
        rows.push((f[0], f[2], f[4], num(1)?, num(3)?));
    }
    // Lines name their machine where an axis has more than one.
    let machines = |axis: &str| rows.iter().filter(|r| r.0 == axis).map(|r| r.2).collect::<std::collections::BTreeSet<_>>().len();
    let mut out = Points::new();
    for &(axis, series, machine, x, ns) in &rows {
        let label = if machines(axis) > 1 { format!("{series}, {machine}") } else { series.to_string() };
        out.entry(axis.to_string()).or_default().entry(label).or_default().push((x, ns));
    }
    Ok(out)
}

fn figure(axis: &str, title: &str, x_desc: &str, log: bool, series: &BTreeMap<String, Vec<(f64, f64)>>) -> Result<String, String> {
    let all = || series.values().flatten();
    let (x0, x1) = all().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (y0, y1) = all().fold((f64::MAX, 0.0_f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
    // Figures that span more than a decade are read on a log scale.
    let y = if y1 > 20.0 * y0 { Scale::log(y0 / 1.5..y1 * 1.5) } else { Scale::linear(0.0..y1 * 1.15) };
    let scale = |lo: f64, hi: f64| if log { Scale::log(lo / 1.5..hi * 1.5) } else { Scale::linear(lo..hi) };
    let lines = series
        .iter()
        .zip(COLORS.iter().cycle())
        .map(|((label, pts), &color)| Line { label: label.clone(), color, points: pts.clone() })
        .collect();
    let id = format!("cost-{axis}");
    let fig = Figure {
        id: &id,
        title,
        x_desc,
        y_desc: "ns",
        x: scale(x0, x1),
        y,
        x_fmt: &plot::short,
        y_fmt: &plot::short,
        lines,
        bars: Vec::new(),
        // The legend goes below the plot, clear of every point.
        marks: &[],
    };
    plot::svg(&fig).map_err(|e| e.to_string())
}
