//! Plots as inline SVG (plotters' SVG backend: text is left to the
//! browser's own fonts, nothing is rasterized, no system font is read).
//!
//! A [`Figure`] is data and scales; [`svg`] draws it and returns the
//! `<svg>` element, sized by its `viewBox` so the page's CSS scales it, and
//! without the `xmlns` attribute (an inline `<svg>` in HTML needs none, and
//! the page then names no URL at all).
//!
//! The legend is drawn below the plot area, never over a curve; a time
//! plot marks the run's live switches (dashed lines, named) and its pauses
//! (shaded).

use super::HtmlError;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::prelude::*;
use std::ops::Range;

/// Width and height of every figure, in SVG units.
pub const SIZE: (u32, u32) = (760, 360);

/// The palette: colour-blind safe (Okabe–Ito).
pub const BLUE: RGBColor = RGBColor(0, 114, 178);
pub const ORANGE: RGBColor = RGBColor(230, 159, 0);
pub const GREEN: RGBColor = RGBColor(0, 158, 115);
pub const PURPLE: RGBColor = RGBColor(204, 121, 167);
pub const GREY: RGBColor = RGBColor(90, 90, 90);
pub const VERMILLION: RGBColor = RGBColor(213, 94, 0);
pub const SKY: RGBColor = RGBColor(86, 180, 233);

/// One axis: its range and whether it is logarithmic.
#[derive(Debug, Clone)]
pub struct Scale {
    pub range: Range<f64>,
    pub log: bool,
}

impl Scale {
    pub fn linear(range: Range<f64>) -> Scale {
        Scale { range, log: false }
    }
    pub fn log(range: Range<f64>) -> Scale {
        Scale { range, log: true }
    }
}

/// A labelled polyline.
#[derive(Debug, Clone)]
pub struct Line {
    pub label: String,
    pub color: RGBColor,
    pub points: Vec<(f64, f64)>,
}

/// Labelled bars: `(x from, x to, height)` each.
#[derive(Debug, Clone)]
pub struct Bars {
    pub label: String,
    pub color: RGBColor,
    pub bars: Vec<(f64, f64, f64)>,
}

type Format<'a> = &'a dyn Fn(&f64) -> String;

/// What happened on a time axis: a switch (or a phase starting) at `x`,
/// named, or a pause from `x` to `to` (its end, or the axis's).
#[derive(Debug, Clone, PartialEq)]
pub enum Mark {
    At { x: f64, label: String },
    Paused { x: f64, to: Option<f64> },
}

/// What one plot shows.
pub struct Figure<'a> {
    /// The `id` of the `<svg>` element.
    pub id: &'a str,
    pub title: &'a str,
    pub x_desc: &'a str,
    pub y_desc: &'a str,
    pub x: Scale,
    pub y: Scale,
    pub x_fmt: Format<'a>,
    pub y_fmt: Format<'a>,
    pub lines: Vec<Line>,
    pub bars: Vec<Bars>,
    /// Switches and pauses, on a time axis.
    pub marks: &'a [Mark],
}

/// A number as short as it reads well: `0.25`, `12`, `1.5e6`.
pub fn short(v: &f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e6).contains(&a) {
        format!("{v:.1e}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// `v` as a whole number, or `None` where it is not one (an axis tick
/// between two categories).
pub fn whole(v: f64) -> Option<i64> {
    ((v - v.round()).abs() < 1e-9).then(|| v.round() as i64)
}

/// Draws `fig` as an `<svg>` element.
pub fn svg(fig: &Figure) -> Result<String, HtmlError> {
    let (x, y) = (fig.x.range.clone(), fig.y.range.clone());
    let body = match (fig.x.log, fig.y.log) {
        (false, false) => draw(fig, RangedCoordf64::from(x), RangedCoordf64::from(y)),
        (true, false) => draw(fig, LogCoord::from(x.log_scale()), RangedCoordf64::from(y)),
        (false, true) => draw(fig, RangedCoordf64::from(x), LogCoord::from(y.log_scale())),
        (true, true) => draw(fig, LogCoord::from(x.log_scale()), LogCoord::from(y.log_scale())),
    }
    .map_err(|message| HtmlError::Plot { id: fig.id.to_string(), message })?;
    Ok(with_own_root(&body, fig.id, fig.title, &legend(fig)))
}

/// One entry of the legend: a line, a filled box, a dashed line or a shade.
enum Swatch {
    Line(RGBColor),
    Box(RGBColor),
    Dashed,
    Shade,
}

/// The legend's entries: every series when there are two or more, and
/// what the marks mean.
fn legend(fig: &Figure) -> Vec<(Swatch, String)> {
    let mut out = Vec::new();
    if fig.lines.len() + fig.bars.len() > 1 {
        out.extend(fig.bars.iter().map(|b| (Swatch::Box(b.color), b.label.clone())));
        out.extend(fig.lines.iter().map(|l| (Swatch::Line(l.color), l.label.clone())));
    }
    if fig.marks.iter().any(|m| matches!(m, Mark::At { .. })) {
        out.push((Swatch::Dashed, "switch".into()));
    }
    if fig.marks.iter().any(|m| matches!(m, Mark::Paused { .. })) {
        out.push((Swatch::Shade, "faults paused".into()));
    }
    out
}

/// Height of a legend row below the plot, SVG units.
const LEGEND_ROW: u32 = 22;

/// The legend below the plot area, in rows as wide as the figure; its
/// height.
fn legend_svg(entries: &[(Swatch, String)]) -> (String, u32) {
    let (w, h) = SIZE;
    let mut svg = String::from("<g class=\"legend\" font-family=\"sans-serif\" font-size=\"13\">");
    let (mut x, mut row) = (84u32, 0u32);
    for (swatch, label) in entries {
        // About 7 units a character at 13 units a font.
        let width = 28 + 7 * label.chars().count() as u32 + 18;
        if x + width > w && x > 84 {
            (x, row) = (84, row + 1);
        }
        let y = h + 6 + row * LEGEND_ROW + LEGEND_ROW / 2;
        let c = |c: &RGBColor| format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2);
        svg += &match swatch {
            Swatch::Line(col) => format!("<line x1=\"{x}\" y1=\"{y}\" x2=\"{}\" y2=\"{y}\" stroke=\"{}\" stroke-width=\"3\"/>", x + 20, c(col)),
            Swatch::Box(col) => format!("<rect x=\"{x}\" y=\"{}\" width=\"20\" height=\"10\" fill=\"{}\"/>", y - 5, c(col)),
            Swatch::Dashed => format!("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"#333\" stroke-dasharray=\"4 3\"/>", x + 10, y - 8, x + 10, y + 8),
            Swatch::Shade => format!("<rect x=\"{x}\" y=\"{}\" width=\"20\" height=\"14\" fill=\"#999\" fill-opacity=\"0.25\"/>", y - 7),
        };
        svg += &format!("<text x=\"{}\" y=\"{}\">{}</text>", x + 26, y + 4, super::escape(label));
        x += width;
    }
    svg += "</g>";
    let rows = if entries.is_empty() { 0 } else { row + 1 };
    (svg, if rows == 0 { 0 } else { rows * LEGEND_ROW + 10 })
}

/// Replaces plotters' root element with one that scales with the page,
/// and adds the legend below the plot.
fn with_own_root(svg: &str, id: &str, title: &str, legend: &[(Swatch, String)]) -> String {
    let rest = svg.find('>').map_or(svg, |end| &svg[end + 1..]);
    let (w, h) = SIZE;
    let (legend, extra) = legend_svg(legend);
    let body = match rest.rfind("</svg>") {
        Some(end) => format!("{}<rect y=\"{h}\" width=\"{w}\" height=\"{extra}\" fill=\"#fff\"/>{legend}</svg>", &rest[..end]),
        None => rest.to_string(),
    };
    format!(
        "<svg id=\"{id}\" class=\"plot\" viewBox=\"0 0 {w} {}\" role=\"img\" aria-label=\"{}\">{body}",
        h + extra,
        super::escape(title)
    )
}

fn draw<X, Y>(fig: &Figure, x: X, y: Y) -> Result<String, String>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let mut chart = chart_on(&root, fig.title)
            .build_cartesian_2d(x, y)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc(fig.x_desc)
            .y_desc(fig.y_desc)
            .x_label_formatter(fig.x_fmt)
            .y_label_formatter(fig.y_fmt)
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(|e| e.to_string())?;
        let (x_range, y_range) = (fig.x.range.clone(), fig.y.range.clone());
        // Pauses under the data, switches over it.
        for m in fig.marks {
            if let Mark::Paused { x, to } = m {
                let (a, b) = (x.max(x_range.start), to.unwrap_or(x_range.end).min(x_range.end));
                if a < b {
                    let shade = Rectangle::new([(a, y_range.start), (b, y_range.end)], RGBColor(153, 153, 153).mix(0.25).filled());
                    chart.draw_series(std::iter::once(shade)).map_err(|e| e.to_string())?;
                }
            }
        }
        for b in &fig.bars {
            let color = b.color;
            let rects = b.bars.iter().map(move |&(x0, x1, h)| Rectangle::new([(x0, 0.0), (x1, h)], color.filled()));
            chart.draw_series(rects).map_err(|e| e.to_string())?;
        }
        for l in &fig.lines {
            chart.draw_series(LineSeries::new(l.points.iter().copied(), l.color.stroke_width(2))).map_err(|e| e.to_string())?;
        }
        for m in fig.marks {
            if let Mark::At { x, label } = m {
                if !x_range.contains(x) {
                    continue;
                }
                let dashes = DashedLineSeries::new([(*x, y_range.start), (*x, y_range.end)], 4, 3, RGBColor(51, 51, 51).stroke_width(1));
                chart.draw_series(dashes).map_err(|e| e.to_string())?;
                let text = Text::new(label.clone(), (*x, y_range.end), ("sans-serif", 12).into_font().color(&RGBColor(51, 51, 51)));
                chart.draw_series(std::iter::once(text)).map_err(|e| e.to_string())?;
            }
        }
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(buf)
}

/// A chart as the reports draw them: `title` above, room for both axes'
/// labels.
pub(crate) fn chart_on<'a, 'b, DB: DrawingBackend>(root: &'a DrawingArea<DB, plotters::coord::Shift>, title: &str) -> ChartBuilder<'a, 'b, DB> {
    let mut chart = ChartBuilder::on(root);
    chart.caption(title, ("sans-serif", 18)).margin(12).margin_right(36).x_label_area_size(44).y_label_area_size(76);
    chart
}
