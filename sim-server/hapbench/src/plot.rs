//! Charts as SVG, written by hand: lines (time series side by side, in the
//! style of the paper's Figure 26) or markers (scatter), on linear,
//! logarithmic or percentile-tail axes with one unit each.
//!
//! Why not a plotting crate: plotters (the well-kept one) was weighed. Its
//! SVG backend would draw these four chart kinds, but it brings a font
//! stack into the default build, and what made the plots hard to read
//! (shared colours, a clipped legend, a linear percentile axis) is a
//! choice of styles and scales, not something a library fixes for us. This
//! file also writes the chart's structure as data (`class="series"` and
//! `class="legend-entry"` groups with `data-name`, `data-color` and
//! `data-marker`), which the system tests read back from every plot in
//! `docs/hapbench/` to check that the legend lists every series and that no
//! two series look alike.
//!
//! Style is the chart's, not the caller's: series `i` gets colour
//! `PALETTE[i % 11]` and marker `MARKERS[i % 7]`, so no two of the first 77
//! share both; a line carries its marker every few points (offset per
//! series) so it is told apart in grey print too.

use std::fmt::Write;

/// One curve.
pub struct Series<'a> {
    /// Legend text.
    pub name: &'a str,
    /// (x, y) points in order, in the axes' own units (the chart applies
    /// the scale).
    pub points: Vec<(f64, f64)>,
    /// Draw a marker at each point instead of joining them.
    pub markers: bool,
}

impl<'a> Series<'a> {
    /// A curve through `points`.
    pub fn line(name: &'a str, points: Vec<(f64, f64)>) -> Self {
        Self {
            name,
            points,
            markers: false,
        }
    }

    /// A marker at each of `points`.
    pub fn markers(name: &'a str, points: Vec<(f64, f64)>) -> Self {
        Self {
            name,
            points,
            markers: true,
        }
    }
}

/// How an axis maps its values onto the page.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Scale {
    /// Values as they are.
    #[default]
    Linear,
    /// log10 of the value (ticks at powers of ten, labelled with the plain
    /// numbers); values at or below zero are not drawn.
    Log10,
    /// A percentile axis given as fractions p in [0, 1): drawn at
    /// -log10(1 - p), so p90, p99, p99.9 and p99.99 are equally spaced and
    /// the tail is not squeezed against the edge.
    Tail,
}

impl Scale {
    /// The value's position on the axis (None: not drawable).
    fn map(self, v: f64) -> Option<f64> {
        if !v.is_finite() {
            return None;
        }
        match self {
            Scale::Linear => Some(v),
            Scale::Log10 => (v > 0.0).then(|| v.log10()),
            Scale::Tail => (0.0..1.0).contains(&v).then(|| -(1.0 - v).log10()),
        }
    }
}

/// The scales of both axes.
#[derive(Clone, Copy, Debug, Default)]
pub struct Axes {
    /// The x axis.
    pub x: Scale,
    /// The y axis.
    pub y: Scale,
}

/// Colours (black, then the Tableau 10 set).
pub const PALETTE: [&str; 11] = [
    "#000000", "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
    "#7f7f7f", "#bcbd22", "#17becf",
];

/// Marker shapes, by name (the name is written to `data-marker`).
pub const MARKERS: [&str; 7] = [
    "circle",
    "square",
    "triangle",
    "diamond",
    "triangle-down",
    "cross",
    "plus",
];

/// Series `i`'s colour and marker.
pub fn style(i: usize) -> (&'static str, &'static str) {
    (PALETTE[i % PALETTE.len()], MARKERS[i % MARKERS.len()])
}

/// Width of a legend character at 12 px sans-serif, generous (so the
/// legend is never clipped: the tests check names against it).
pub const LEGEND_CHAR_PX: f64 = 7.5;

/// Width of a title character at 15 px, generous likewise.
pub const TITLE_CHAR_PX: f64 = 8.5;

const PLOT_W: f64 = 660.0;
const PLOT_H: f64 = 330.0;
const L: f64 = 70.0;
const T: f64 = 40.0;
const B: f64 = 50.0;
/// Legend: gap after the plot, marker sample width, gap before the text.
const LEGEND_GAP: f64 = 10.0;
const LEGEND_SAMPLE: f64 = 26.0;
const LEGEND_ROW: f64 = 18.0;
/// Markers drawn along a line.
const LINE_MARKERS: usize = 12;

/// Text safe inside SVG (names such as "sim -> daemon").
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A tick's label: at most six decimals, never "-0"; on a log axis the
/// number 10^t; on a tail axis the percentile ("p99.9").
fn tick_label(t: f64, scale: Scale) -> String {
    match scale {
        Scale::Tail => {
            let pct = 100.0 * (1.0 - 10f64.powf(-t));
            let pct = (pct * 1e8).round() / 1e8 + 0.0;
            format!("p{pct}")
        }
        Scale::Log10 => {
            let v = 10f64.powf(t);
            // Round to three significant digits of the power.
            let m = 10f64.powf(v.log10().floor() - 2.0);
            let v = (v / m).round() * m;
            if (1e-3..1e6).contains(&v) {
                format!("{v}")
            } else {
                format!("{v:.0e}")
            }
        }
        Scale::Linear => {
            // -0.0 + 0.0 is +0.0: no "-0" label.
            let v = (t * 1e6).round() / 1e6 + 0.0;
            format!("{v}")
        }
    }
}

fn nice_ticks(lo: f64, hi: f64, scale: Scale) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    let within = |t: f64| t >= lo - 1e-12 && t <= hi + 1e-12;
    match scale {
        Scale::Tail => {
            // p0, p50, then every added nine.
            let mut out: Vec<f64> = [0.0, 2f64.log10()]
                .into_iter()
                .chain((1..=9).map(f64::from))
                .filter(|t| within(*t))
                .collect();
            if out.len() > 9 {
                out.retain(|t| t.fract() == 0.0);
            }
            return out;
        }
        Scale::Log10 if span < 2.0 => {
            // Under two decades: 1, 2 and 5 times the powers of ten.
            let mut out = Vec::new();
            for decade in (lo.floor() as i32)..=(hi.ceil() as i32) {
                for m in [1.0f64, 2.0, 5.0] {
                    let t = f64::from(decade) + m.log10();
                    if within(t) {
                        out.push(t);
                    }
                }
            }
            return out;
        }
        Scale::Log10 => {
            // Powers of ten only, every k-th when there are many.
            let k = (span / 6.0).ceil().max(1.0);
            let mut t = (lo / k).ceil() * k;
            let mut out = Vec::new();
            while t <= hi + 1e-12 {
                out.push(t);
                t += k;
            }
            return out;
        }
        Scale::Linear => {}
    }
    let raw = span / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + 1e-12 * span {
        out.push(t);
        t += step;
    }
    out
}

/// An SVG marker of `shape` centred at (x, y).
fn marker(shape: &str, x: f64, y: f64, color: &str) -> String {
    let r = 3.6;
    match shape {
        "square" => format!(
            r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="{color}"/>"#,
            x - r,
            y - r,
            2.0 * r,
            2.0 * r
        ),
        "triangle" => format!(
            r#"<path d="M{x:.1},{:.1} L{:.1},{:.1} L{:.1},{:.1} Z" fill="{color}"/>"#,
            y - 1.2 * r,
            x + r,
            y + r,
            x - r,
            y + r
        ),
        "triangle-down" => format!(
            r#"<path d="M{x:.1},{:.1} L{:.1},{:.1} L{:.1},{:.1} Z" fill="{color}"/>"#,
            y + 1.2 * r,
            x + r,
            y - r,
            x - r,
            y - r
        ),
        "diamond" => format!(
            r#"<path d="M{x:.1},{:.1} L{:.1},{y:.1} L{x:.1},{:.1} L{:.1},{y:.1} Z" fill="{color}"/>"#,
            y - 1.3 * r,
            x + r,
            y + 1.3 * r,
            x - r
        ),
        "cross" => format!(
            r#"<path d="M{:.1},{:.1} L{:.1},{:.1} M{:.1},{:.1} L{:.1},{:.1}" stroke="{color}" stroke-width="2"/>"#,
            x - r,
            y - r,
            x + r,
            y + r,
            x - r,
            y + r,
            x + r,
            y - r
        ),
        "plus" => format!(
            r#"<path d="M{:.1},{y:.1} L{:.1},{y:.1} M{x:.1},{:.1} L{x:.1},{:.1}" stroke="{color}" stroke-width="2"/>"#,
            x - 1.2 * r,
            x + 1.2 * r,
            y - 1.2 * r,
            y + 1.2 * r
        ),
        _ => format!(r#"<circle cx="{x:.1}" cy="{y:.1}" r="{r}" fill="{color}"/>"#),
    }
}

/// An SVG chart of `series` over x in `[x0, x1]` (in the x axis's own
/// units: fractions for a tail axis).
pub fn chart(
    title: &str,
    x_label: &str,
    y_label: &str,
    x0: f64,
    x1: f64,
    series: &[Series],
    axes: Axes,
) -> String {
    let (Some(x0), Some(x1)) = (axes.x.map(x0), axes.x.map(x1)) else {
        return chart(title, x_label, y_label, 0.0, 1.0, &[], Axes::default());
    };
    // Each series' points on the page's axes, those outside [x0, x1] or not
    // drawable on the scale left out.
    let mapped: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|s| {
            s.points
                .iter()
                .filter_map(|p| Some((axes.x.map(p.0)?, axes.y.map(p.1)?)))
                .filter(|p| p.0 >= x0 - 1e-12 && p.0 <= x1 + 1e-12)
                .collect()
        })
        .collect();
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in mapped.iter().flatten() {
        y0 = y0.min(p.1);
        y1 = y1.max(p.1);
    }
    if !y0.is_finite() || !y1.is_finite() || y0 >= y1 {
        let c = if y0.is_finite() { y0 } else { 0.0 };
        (y0, y1) = (c - 1.0, c + 1.0);
    }
    let pad = 0.05 * (y1 - y0);
    let (y0, y1) = (y0 - pad, y1 + pad);
    // The legend sized by its longest name, the page by the legend.
    let longest = series
        .iter()
        .map(|s| s.name.chars().count())
        .max()
        .unwrap_or(0);
    let legend_w = LEGEND_SAMPLE + 8.0 + LEGEND_CHAR_PX * longest as f64 + LEGEND_GAP;
    let title_w = 20.0 + TITLE_CHAR_PX * title.chars().count() as f64;
    let w = (L + PLOT_W + LEGEND_GAP + legend_w).max(title_w);
    let h = (T + PLOT_H + B).max(T + 14.0 + LEGEND_ROW * series.len() as f64 + B);
    let plot_h = h - T - B;
    let sx = |x: f64| L + (x - x0) / (x1 - x0).max(1e-12) * PLOT_W;
    let sy = |y: f64| h - B - (y - y0) / (y1 - y0) * plot_h;
    let title = escape(title);
    let mut svg = String::new();
    let _ = write!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12"><rect width="100%" height="100%" fill="white"/><text x="10" y="22" font-size="15">{title}</text>"#
    );
    for t in nice_ticks(x0, x1, axes.x) {
        let x = sx(t);
        let _ = write!(
            svg,
            r##"<line x1="{x:.1}" y1="{T}" x2="{x:.1}" y2="{}" stroke="#ddd"/><text x="{x:.1}" y="{}" text-anchor="middle">{}</text>"##,
            h - B,
            h - B + 16.0,
            tick_label(t, axes.x)
        );
    }
    for t in nice_ticks(y0, y1, axes.y) {
        let y = sy(t);
        let _ = write!(
            svg,
            r##"<line x1="{L}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
            L + PLOT_W,
            L - 6.0,
            y + 4.0,
            tick_label(t, axes.y)
        );
    }
    let _ = write!(
        svg,
        r##"<rect x="{L}" y="{T}" width="{PLOT_W}" height="{plot_h}" fill="none" stroke="#444"/><text x="{}" y="{}" text-anchor="middle">{}</text><text x="16" y="{}" transform="rotate(-90 16 {})" text-anchor="middle">{}</text>"##,
        L + PLOT_W / 2.0,
        h - 10.0,
        escape(x_label),
        T + plot_h / 2.0,
        T + plot_h / 2.0,
        escape(y_label)
    );
    let lx = L + PLOT_W + LEGEND_GAP;
    for (i, (s, pts)) in series.iter().zip(&mapped).enumerate() {
        let (color, shape) = style(i);
        let name = escape(s.name);
        let _ = write!(
            svg,
            r#"<g class="series" data-name="{name}" data-color="{color}" data-marker="{shape}">"#
        );
        if s.markers {
            for p in pts {
                svg.push_str(&marker(shape, sx(p.0), sy(p.1), color));
            }
        } else {
            let mut d = String::new();
            for (k, p) in pts.iter().enumerate() {
                let _ = write!(
                    d,
                    "{}{:.1},{:.1}",
                    if k == 0 { "M" } else { " L" },
                    sx(p.0),
                    sy(p.1)
                );
            }
            let _ = write!(
                svg,
                r#"<path d="{d}" fill="none" stroke="{color}" stroke-width="1.4"/>"#
            );
            // Markers every few points, shifted per series so lines that
            // run together still show each one's.
            if !pts.is_empty() {
                let every = (pts.len() / LINE_MARKERS).max(1);
                let offset = (i * every) / series.len().max(1);
                for p in pts.iter().skip(offset % every).step_by(every) {
                    svg.push_str(&marker(shape, sx(p.0), sy(p.1), color));
                }
            }
        }
        svg.push_str("</g>");
        let ly = T + 14.0 + LEGEND_ROW * i as f64;
        let _ = write!(
            svg,
            r#"<g class="legend-entry" data-name="{name}" data-color="{color}" data-marker="{shape}">"#
        );
        if !s.markers {
            let _ = write!(
                svg,
                r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{color}" stroke-width="2"/>"#,
                lx + LEGEND_SAMPLE
            );
        }
        svg.push_str(&marker(shape, lx + LEGEND_SAMPLE / 2.0, ly, color));
        let _ = write!(
            svg,
            r#"<text x="{}" y="{}">{name}</text></g>"#,
            lx + LEGEND_SAMPLE + 8.0,
            ly + 4.0
        );
    }
    svg.push_str("</svg>\n");
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_have_no_negative_zero_and_log_axes_read_plain_numbers() {
        assert_eq!(tick_label(-0.0, Scale::Linear), "0");
        assert_eq!(tick_label(-1e-9, Scale::Linear), "0");
        assert_eq!(tick_label(0.25, Scale::Linear), "0.25");
        assert_eq!(tick_label(3.0, Scale::Log10), "1000");
        assert_eq!(tick_label(-2.0, Scale::Log10), "0.01");
        assert_eq!(tick_label(-5.0, Scale::Log10), "1e-5");
        assert_eq!(nice_ticks(-2.3, 1.2, Scale::Log10), [-2.0, -1.0, 0.0, 1.0]);
        let short: Vec<String> = nice_ticks(-1.5, -0.1, Scale::Log10)
            .iter()
            .map(|t| tick_label(*t, Scale::Log10))
            .collect();
        assert_eq!(short, ["0.05", "0.1", "0.2", "0.5"]);
    }

    #[test]
    fn a_tail_axis_spaces_the_nines_evenly_and_names_them_as_percentiles() {
        let x = |p: f64| Scale::Tail.map(p).unwrap();
        assert!((x(0.99) - x(0.9) - (x(0.999) - x(0.99))).abs() < 1e-9);
        assert_eq!(Scale::Tail.map(1.0), None, "p100 is off the axis");
        let labels: Vec<String> = nice_ticks(0.0, x(0.9999), Scale::Tail)
            .iter()
            .map(|t| tick_label(*t, Scale::Tail))
            .collect();
        assert_eq!(labels, ["p0", "p50", "p90", "p99", "p99.9", "p99.99"]);
    }

    #[test]
    fn every_series_has_its_own_style_and_its_legend_entry() {
        let names: Vec<String> = (0..20).map(|i| format!("series {i} a -> b")).collect();
        let series: Vec<Series> = names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let pts = vec![(0.0, i as f64), (1.0, i as f64 + 1.0)];
                if i % 2 == 0 {
                    Series::line(n, pts)
                } else {
                    Series::markers(n, pts)
                }
            })
            .collect();
        let svg = chart("t", "x", "y", 0.0, 1.0, &series, Axes::default());
        assert_eq!(svg.matches(r#"class="series""#).count(), 20);
        assert_eq!(svg.matches(r#"class="legend-entry""#).count(), 20);
        assert!(svg.contains("series 3 a -&gt; b"), "names escaped");
        let styles: std::collections::HashSet<_> = (0..77).map(style).collect();
        assert_eq!(styles.len(), 77, "77 series before a style repeats");
        // Twenty legend rows do not fit the default height: the page grows.
        assert!(!svg.contains(r#"height="420""#), "{}", &svg[..200]);
        assert!(!svg.contains(">-0<"));
    }

    #[test]
    fn log_axes_leave_out_what_they_cannot_draw() {
        let s = [Series::markers(
            "m",
            vec![(1.0, 0.0), (10.0, 5.0), (100.0, 50.0)],
        )];
        let axes = Axes {
            x: Scale::Log10,
            y: Scale::Log10,
        };
        let svg = chart("t", "x", "y", 1.0, 100.0, &s, axes);
        // Two points and the legend's sample.
        assert_eq!(svg.matches("<circle").count(), 3);
    }
}
