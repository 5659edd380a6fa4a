//! Charts as SVG, written by hand: lines (time series side by side, in the
//! style of the paper's Figure 26) or markers (scatter), linear or
//! logarithmic axes with one unit each. A plotting crate (plotters) was
//! weighed: it would add a font stack to the default build for four chart
//! kinds this file draws in 200 lines.

use std::fmt::Write;

/// One curve.
pub struct Series<'a> {
    /// Legend text.
    pub name: &'a str,
    /// CSS colour.
    pub color: &'a str,
    /// (x, y) points in order.
    pub points: Vec<(f64, f64)>,
    /// Draw a marker at each point instead of joining them.
    pub markers: bool,
}

impl<'a> Series<'a> {
    /// A curve through `points`.
    pub fn line(name: &'a str, color: &'a str, points: Vec<(f64, f64)>) -> Self {
        Self {
            name,
            color,
            points,
            markers: false,
        }
    }

    /// A marker at each of `points`.
    pub fn markers(name: &'a str, color: &'a str, points: Vec<(f64, f64)>) -> Self {
        Self {
            name,
            color,
            points,
            markers: true,
        }
    }
}

/// Which axes are logarithmic (values given as log10, ticks at powers of
/// ten labelled with the plain numbers).
#[derive(Clone, Copy, Debug, Default)]
pub struct Log {
    /// The x axis.
    pub x: bool,
    /// The y axis.
    pub y: bool,
}

const W: f64 = 900.0;
const H: f64 = 420.0;
const L: f64 = 70.0;
const R: f64 = 170.0;
const T: f64 = 40.0;
const B: f64 = 50.0;

/// A tick's label: at most six decimals, never "-0"; on a log axis the
/// number 10^t.
fn tick_label(t: f64, log: bool) -> String {
    let v = if log { 10f64.powf(t) } else { t };
    let v = if log {
        // Round to three significant digits of the power.
        let m = 10f64.powf(v.log10().floor() - 2.0);
        (v / m).round() * m
    } else {
        (v * 1e6).round() / 1e6
    };
    // -0.0 + 0.0 is +0.0: no "-0" label.
    let v = v + 0.0;
    if log && !(1e-3..1e6).contains(&v) {
        format!("{v:.0e}")
    } else {
        format!("{v}")
    }
}

fn nice_ticks(lo: f64, hi: f64, log: bool) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    if log && span < 2.0 {
        // Under two decades: 1, 2 and 5 times the powers of ten.
        let mut out = Vec::new();
        for decade in (lo.floor() as i32)..=(hi.ceil() as i32) {
            for m in [1.0f64, 2.0, 5.0] {
                let t = f64::from(decade) + m.log10();
                if t >= lo - 1e-12 && t <= hi + 1e-12 {
                    out.push(t);
                }
            }
        }
        return out;
    }
    if log {
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

/// An SVG chart of `series` over x in `[x0, x1]` (log10 values on a log
/// axis).
pub fn chart(
    title: &str,
    x_label: &str,
    y_label: &str,
    x0: f64,
    x1: f64,
    series: &[Series],
    log: Log,
) -> String {
    let visible = |p: &&(f64, f64)| p.0 >= x0 && p.0 <= x1 && p.1.is_finite();
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for s in series {
        for p in s.points.iter().filter(visible) {
            y0 = y0.min(p.1);
            y1 = y1.max(p.1);
        }
    }
    if y0.is_nan() || y1.is_nan() || y0 >= y1 {
        (y0, y1) = (y0.min(0.0) - 1.0, y1.max(0.0) + 1.0);
    }
    let pad = 0.05 * (y1 - y0);
    let (y0, y1) = (y0 - pad, y1 + pad);
    let sx = |x: f64| L + (x - x0) / (x1 - x0).max(1e-12) * (W - L - R);
    let sy = |y: f64| H - B - (y - y0) / (y1 - y0) * (H - T - B);
    let mut svg = String::new();
    let _ = write!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="12"><rect width="100%" height="100%" fill="white"/><text x="{}" y="22" text-anchor="middle" font-size="15">{title}</text>"#,
        (L + W - R) / 2.0
    );
    for t in nice_ticks(x0, x1, log.x) {
        let x = sx(t);
        let _ = write!(
            svg,
            r##"<line x1="{x:.1}" y1="{T}" x2="{x:.1}" y2="{}" stroke="#ddd"/><text x="{x:.1}" y="{}" text-anchor="middle">{}</text>"##,
            H - B,
            H - B + 16.0,
            tick_label(t, log.x)
        );
    }
    for t in nice_ticks(y0, y1, log.y) {
        let y = sy(t);
        let _ = write!(
            svg,
            r##"<line x1="{L}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
            W - R,
            L - 6.0,
            y + 4.0,
            tick_label(t, log.y)
        );
    }
    let _ = write!(
        svg,
        r##"<rect x="{L}" y="{T}" width="{}" height="{}" fill="none" stroke="#444"/><text x="{}" y="{}" text-anchor="middle">{x_label}</text><text x="16" y="{}" transform="rotate(-90 16 {})" text-anchor="middle">{y_label}</text>"##,
        W - L - R,
        H - T - B,
        (L + W - R) / 2.0,
        H - 10.0,
        (T + H - B) / 2.0,
        (T + H - B) / 2.0
    );
    for (i, s) in series.iter().enumerate() {
        let ly = T + 14.0 + 18.0 * i as f64;
        let (lx, lw) = (W - R + 10.0, W - R + 30.0);
        if s.markers {
            for p in s.points.iter().filter(visible) {
                let _ = write!(
                    svg,
                    r#"<circle cx="{:.1}" cy="{:.1}" r="3.5" fill="{}" fill-opacity="0.8"/>"#,
                    sx(p.0),
                    sy(p.1),
                    s.color
                );
            }
            let _ = write!(
                svg,
                r#"<circle cx="{}" cy="{ly}" r="3.5" fill="{}"/><text x="{}" y="{}">{}</text>"#,
                (lx + lw) / 2.0,
                s.color,
                W - R + 36.0,
                ly + 4.0,
                s.name
            );
            continue;
        }
        let mut d = String::new();
        for (k, p) in s.points.iter().filter(visible).enumerate() {
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
            r#"<path d="{d}" fill="none" stroke="{}" stroke-width="1.4"/>"#,
            s.color
        );
        let _ = write!(
            svg,
            r#"<line x1="{}" y1="{ly}" x2="{}" y2="{ly}" stroke="{}" stroke-width="2"/><text x="{}" y="{}">{}</text>"#,
            lx,
            lw,
            s.color,
            W - R + 36.0,
            ly + 4.0,
            s.name
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
        assert_eq!(tick_label(-0.0, false), "0");
        assert_eq!(tick_label(-1e-9, false), "0");
        assert_eq!(tick_label(0.25, false), "0.25");
        assert_eq!(tick_label(3.0, true), "1000");
        assert_eq!(tick_label(-2.0, true), "0.01");
        assert_eq!(tick_label(-5.0, true), "1e-5");
        assert_eq!(nice_ticks(-2.3, 1.2, true), [-2.0, -1.0, 0.0, 1.0]);
        let short: Vec<String> = nice_ticks(-1.5, -0.1, true)
            .iter()
            .map(|t| tick_label(*t, true))
            .collect();
        assert_eq!(short, ["0.05", "0.1", "0.2", "0.5"]);
        let svg = chart(
            "t",
            "x",
            "y",
            -1.0,
            1.0,
            &[Series::markers("m", "#000", vec![(-0.5, 0.0), (0.5, 1.0)])],
            Log::default(),
        );
        assert_eq!(
            svg.matches("<circle").count(),
            3,
            "two points and the legend"
        );
        assert!(!svg.contains(">-0<"), "{svg}");
    }
}
