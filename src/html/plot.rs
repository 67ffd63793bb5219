//! Plots as inline SVG (plotters' SVG backend: text is left to the
//! browser's own fonts, nothing is rasterized, no system font is read).
//!
//! A [`Figure`] is data and scales; [`svg`] draws it and returns the
//! `<svg>` element, sized by its `viewBox` so the page's CSS scales it, and
//! without the `xmlns` attribute (an inline `<svg>` in HTML needs none, and
//! the page then names no URL at all).

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
    /// Where the legend goes (drawn when there are two series or more).
    pub legend: SeriesLabelPosition,
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
    Ok(with_own_root(&body, fig.id, fig.title))
}

/// Replaces plotters' root element with one that scales with the page.
fn with_own_root(svg: &str, id: &str, title: &str) -> String {
    let rest = svg.find('>').map_or(svg, |end| &svg[end + 1..]);
    let (w, h) = SIZE;
    format!(
        "<svg id=\"{id}\" class=\"plot\" viewBox=\"0 0 {w} {h}\" role=\"img\" aria-label=\"{}\">{rest}",
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
        let mut chart = ChartBuilder::on(&root)
            .caption(fig.title, ("sans-serif", 18))
            .margin(12)
            .margin_right(36)
            .x_label_area_size(44)
            .y_label_area_size(76)
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
        for b in &fig.bars {
            let color = b.color;
            let rects = b.bars.iter().map(move |&(x0, x1, h)| Rectangle::new([(x0, 0.0), (x1, h)], color.filled()));
            chart.draw_series(rects).map_err(|e| e.to_string())?.label(b.label.as_str()).legend(move |(x, y)| {
                Rectangle::new([(x, y - 5), (x + 16, y + 5)], color.filled())
            });
        }
        for l in &fig.lines {
            let color = l.color;
            chart
                .draw_series(LineSeries::new(l.points.iter().copied(), color.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label(l.label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2)));
        }
        if fig.lines.len() + fig.bars.len() > 1 {
            chart
                .configure_series_labels()
                .position(fig.legend.clone())
            .background_style(WHITE.mix(0.85))
                .border_style(GREY)
                .draw()
                .map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(buf)
}
