//! A minimal SVG writer: shapes, text with measured widths, markers and colours.
//!
//! Every number is printed with at most two decimals, so the same figure always gives
//! the same bytes.

use std::fmt::{self, Write as _};

/// Font family written into the SVG; the PNG renderer has exactly this face loaded.
pub(super) const FONT_FAMILY: &str = "DejaVu Sans";

/// Colours for methods / ribs (matplotlib's `tab10`, colour-blind tolerant order).
pub(super) const PALETTE: [&str; 10] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
    "#bcbd22", "#17becf",
];
pub(super) const INK: &str = "#222222";
pub(super) const AXIS: &str = "#444444";
pub(super) const GRID: &str = "#e6e6e6";
pub(super) const CLOUD: &str = "#c4c4c4";

pub(super) fn palette(i: usize) -> &'static str {
    PALETTE[i % PALETTE.len()]
}

/// A coordinate or length in pixels, printed with at most two decimals.
#[derive(Clone, Copy)]
pub(super) struct N(pub f64);

impl fmt::Display for N {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = if self.0.is_finite() { self.0 } else { 0.0 };
        let r = (v * 100.0).round() / 100.0;
        if r == 0.0 {
            return f.write_str("0");
        }
        let s = format!("{r:.2}");
        f.write_str(s.trim_end_matches('0').trim_end_matches('.'))
    }
}

/// Advance widths of DejaVu Sans for ASCII 32..=126, in font units (2048 per em).
const ASCII_ADVANCE: [u16; 95] = [
    651, 821, 942, 1716, 1303, 1946, 1597, 563, 799, 799, 1024, 1716, 651, 739, 651, 690, 1303,
    1303, 1303, 1303, 1303, 1303, 1303, 1303, 1303, 1303, 690, 690, 1716, 1716, 1716, 1087, 2048,
    1401, 1405, 1430, 1577, 1294, 1178, 1587, 1540, 604, 604, 1343, 1141, 1767, 1532, 1612, 1235,
    1612, 1423, 1300, 1251, 1499, 1401, 2025, 1403, 1251, 1403, 799, 690, 799, 1716, 1024, 1024,
    1255, 1300, 1126, 1300, 1260, 721, 1300, 1298, 569, 569, 1186, 569, 1995, 1298, 1253, 1300,
    1300, 842, 1067, 803, 1298, 1212, 1675, 1212, 1212, 1075, 1303, 690, 1303, 1716,
];

fn advance(c: char) -> u16 {
    match c {
        ' '..='~' => ASCII_ADVANCE[c as usize - 32],
        '±' | '×' | '−' | '≈' | '≤' | '≥' => 1716,
        '°' | '–' => 1024,
        '·' => 651,
        '…' | '—' => 2048,
        _ => 1303,
    }
}

/// Width in pixels of `s` set in DejaVu Sans at `size` px (no kerning; DejaVu's is slight).
pub(super) fn text_width(s: &str, size: f64) -> f64 {
    s.chars().map(|c| f64::from(advance(c))).sum::<f64>() * size / 2048.0
}

/// Shortens `s` with an ellipsis so that it fits `max_width` px at `size` px.
pub(super) fn fit_text(s: &str, size: f64, max_width: f64) -> String {
    if text_width(s, size) <= max_width {
        return s.to_string();
    }
    let mut out = String::new();
    for c in s.chars() {
        out.push(c);
        if text_width(&out, size) + text_width("…", size) > max_width {
            out.pop();
            break;
        }
    }
    out.push('…');
    out
}

fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            // Control characters are not allowed in XML 1.0.
            c if (c as u32) < 0x20 => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Anchor {
    Start,
    Middle,
    End,
}

/// Text placement. `y` is the vertical centre of the digits/capitals, not the baseline.
#[derive(Clone, Copy)]
pub(super) struct Text<'a> {
    pub size: f64,
    pub anchor: Anchor,
    pub color: &'a str,
    /// Degrees, counter-clockwise positive (−90 for a y-axis label is `rotate = 90.0`).
    pub rotate: f64,
    /// White outline behind the glyphs so the text stays readable over data.
    pub halo: bool,
}

impl Text<'static> {
    pub(super) fn new(size: f64, anchor: Anchor) -> Self {
        Text {
            size,
            anchor,
            color: INK,
            rotate: 0.0,
            halo: false,
        }
    }
}

#[derive(Clone, Copy)]
pub(super) struct Stroke<'a> {
    pub color: &'a str,
    pub width: f64,
    pub dash: Option<&'a str>,
    pub opacity: f64,
}

impl<'a> Stroke<'a> {
    pub(super) fn solid(color: &'a str, width: f64) -> Self {
        Stroke {
            color,
            width,
            dash: None,
            opacity: 1.0,
        }
    }
    pub(super) fn dashed(color: &'a str, width: f64, dash: &'a str) -> Self {
        Stroke {
            color,
            width,
            dash: Some(dash),
            opacity: 1.0,
        }
    }
    fn attrs(&self) -> String {
        let mut s = format!(
            r#" stroke="{}" stroke-width="{}""#,
            self.color,
            N(self.width)
        );
        if let Some(d) = self.dash {
            let _ = write!(s, r#" stroke-dasharray="{d}""#);
        }
        if self.opacity < 1.0 {
            let _ = write!(s, r#" stroke-opacity="{}""#, N(self.opacity));
        }
        s
    }
}

/// Marker shapes; `size` is the nominal diameter in px.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Marker {
    Circle,
    Square,
    TriangleUp,
    Diamond,
    TriangleDown,
    Pentagon,
    /// Stroked "×".
    Cross,
}

/// Filled markers cycled through for the methods.
pub(super) const METHOD_MARKERS: [Marker; 6] = [
    Marker::Circle,
    Marker::Square,
    Marker::TriangleUp,
    Marker::Diamond,
    Marker::TriangleDown,
    Marker::Pentagon,
];

pub(super) struct Svg {
    buf: String,
    pub width: u32,
}

impl Svg {
    /// A white canvas of `width` × `height` px.
    pub(super) fn new(width: u32, height: u32) -> Self {
        let mut buf = String::with_capacity(64 * 1024);
        let _ = write!(
            buf,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="{FONT_FAMILY}, sans-serif">"#
        );
        buf.push('\n');
        let _ = writeln!(
            buf,
            r#"<rect width="{width}" height="{height}" fill="white"/>"#
        );
        Svg { buf, width }
    }

    pub(super) fn finish(mut self) -> String {
        self.buf.push_str("</svg>\n");
        self.buf
    }

    /// Opens a `<g>` with the given presentation attributes (already escaped).
    pub(super) fn group(&mut self, attrs: &str) {
        let _ = writeln!(self.buf, "<g {attrs}>");
    }

    /// Markup written as is (must be well formed).
    pub(super) fn raw(&mut self, markup: &str) {
        self.buf.push_str(markup);
    }

    pub(super) fn end_group(&mut self) {
        self.buf.push_str("</g>\n");
    }

    pub(super) fn comment(&mut self, s: &str) {
        let _ = writeln!(self.buf, "<!-- {} -->", escape(s).replace("--", "- -"));
    }

    pub(super) fn line(&mut self, x1: f64, y1: f64, x2: f64, y2: f64, stroke: Stroke) {
        let _ = writeln!(
            self.buf,
            r#"<line x1="{}" y1="{}" x2="{}" y2="{}"{}/>"#,
            N(x1),
            N(y1),
            N(x2),
            N(y2),
            stroke.attrs()
        );
    }

    /// An open polyline; fewer than two points draws nothing.
    pub(super) fn polyline(&mut self, pts: &[(f64, f64)], stroke: Stroke) {
        if pts.len() < 2 {
            return;
        }
        self.buf.push_str(
            r#"<polyline fill="none" stroke-linejoin="round" stroke-linecap="round" points=""#,
        );
        for (i, (x, y)) in pts.iter().enumerate() {
            if i > 0 {
                self.buf.push(' ');
            }
            let _ = write!(self.buf, "{},{}", N(*x), N(*y));
        }
        let _ = writeln!(self.buf, r#""{}/>"#, stroke.attrs());
    }

    pub(super) fn rect(
        &mut self,
        x: f64,
        y: f64,
        w: f64,
        h: f64,
        fill: Option<(&str, f64)>,
        stroke: Option<Stroke>,
    ) {
        let _ = write!(
            self.buf,
            r#"<rect x="{}" y="{}" width="{}" height="{}""#,
            N(x),
            N(y),
            N(w.max(0.0)),
            N(h.max(0.0))
        );
        self.fill_stroke(fill, stroke);
    }

    /// A circle; inside a `<g>` that sets fill/stroke pass `None` for both.
    pub(super) fn circle(
        &mut self,
        cx: f64,
        cy: f64,
        r: f64,
        fill: Option<(&str, f64)>,
        stroke: Option<Stroke>,
    ) {
        let _ = write!(
            self.buf,
            r#"<circle cx="{}" cy="{}" r="{}""#,
            N(cx),
            N(cy),
            N(r)
        );
        self.fill_stroke(fill, stroke);
    }

    /// A circle that takes its paint from the enclosing `<g>`.
    pub(super) fn dot(&mut self, cx: f64, cy: f64, r: f64) {
        let _ = writeln!(
            self.buf,
            r#"<circle cx="{}" cy="{}" r="{}"/>"#,
            N(cx),
            N(cy),
            N(r)
        );
    }

    fn fill_stroke(&mut self, fill: Option<(&str, f64)>, stroke: Option<Stroke>) {
        match fill {
            Some((c, o)) => {
                let _ = write!(self.buf, r#" fill="{c}""#);
                if o < 1.0 {
                    let _ = write!(self.buf, r#" fill-opacity="{}""#, N(o));
                }
            }
            None => self.buf.push_str(r#" fill="none""#),
        }
        if let Some(s) = stroke {
            self.buf.push_str(&s.attrs());
        }
        self.buf.push_str("/>\n");
    }

    /// A marker centred on (x, y): filled markers get `color` and a thin white edge,
    /// the stroked `Cross` are drawn in `color`.
    pub(super) fn marker(&mut self, m: Marker, x: f64, y: f64, size: f64, color: &str) {
        let r = size / 2.0;
        let edge = r#" stroke="white" stroke-width="0.8""#;
        let poly = |pts: &[(f64, f64)]| -> String {
            let mut s = String::from("M");
            for (i, (dx, dy)) in pts.iter().enumerate() {
                if i > 0 {
                    s.push('L');
                }
                let _ = write!(s, "{} {}", N(x + dx * r), N(y + dy * r));
            }
            s.push('Z');
            s
        };
        match m {
            Marker::Circle => {
                let _ = writeln!(
                    self.buf,
                    r#"<circle cx="{}" cy="{}" r="{}" fill="{color}"{edge}/>"#,
                    N(x),
                    N(y),
                    N(r)
                );
            }
            Marker::Cross => {
                let k = r * 0.8;
                let d = format!(
                    "M{} {}L{} {}M{} {}L{} {}",
                    N(x - k),
                    N(y - k),
                    N(x + k),
                    N(y + k),
                    N(x - k),
                    N(y + k),
                    N(x + k),
                    N(y - k)
                );
                let _ = writeln!(
                    self.buf,
                    r#"<path d="{d}" fill="none" stroke="{color}" stroke-width="{}" stroke-linecap="round"/>"#,
                    N((size / 5.0).clamp(1.5, 3.0))
                );
            }
            _ => {
                let s = 0.886; // square of the same area as the circle
                let pts: Vec<(f64, f64)> = match m {
                    Marker::Square => vec![(-s, -s), (s, -s), (s, s), (-s, s)],
                    Marker::TriangleUp => vec![(0.0, -1.15), (1.05, 0.75), (-1.05, 0.75)],
                    Marker::TriangleDown => vec![(0.0, 1.15), (1.05, -0.75), (-1.05, -0.75)],
                    Marker::Diamond => vec![(0.0, -1.2), (0.95, 0.0), (0.0, 1.2), (-0.95, 0.0)],
                    _ => (0..5)
                        .map(|k| {
                            let a = -std::f64::consts::FRAC_PI_2
                                + f64::from(k) * 2.0 * std::f64::consts::PI / 5.0;
                            (1.1 * a.cos(), 1.1 * a.sin())
                        })
                        .collect(),
                };
                let _ = writeln!(
                    self.buf,
                    r#"<path d="{}" fill="{color}"{edge}/>"#,
                    poly(&pts)
                );
            }
        }
    }

    /// Text whose capitals are vertically centred on `y`.
    pub(super) fn text(&mut self, x: f64, y: f64, s: &str, t: Text) {
        if s.is_empty() {
            return;
        }
        let anchor = match t.anchor {
            Anchor::Start => "start",
            Anchor::Middle => "middle",
            Anchor::End => "end",
        };
        // DejaVu Sans cap height is 0.73 em: the baseline sits 0.36 em below the centre.
        let (bx, by) = if t.rotate == 0.0 {
            (x, y + 0.36 * t.size)
        } else {
            let a = t.rotate.to_radians();
            (x + 0.36 * t.size * a.sin(), y + 0.36 * t.size * a.cos())
        };
        let _ = write!(
            self.buf,
            r#"<text x="{}" y="{}" font-size="{}" text-anchor="{anchor}" fill="{}""#,
            N(bx),
            N(by),
            N(t.size),
            t.color
        );
        if t.rotate != 0.0 {
            let _ = write!(
                self.buf,
                r#" transform="rotate({} {} {})""#,
                N(-t.rotate),
                N(bx),
                N(by)
            );
        }
        if t.halo {
            self.buf.push_str(
                r#" stroke="white" stroke-width="3" stroke-linejoin="round" paint-order="stroke""#,
            );
        }
        let _ = writeln!(self.buf, ">{}</text>", escape(s));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_short_and_finite() {
        assert_eq!(N(1.0).to_string(), "1");
        assert_eq!(N(1.5).to_string(), "1.5");
        assert_eq!(N(-0.001).to_string(), "0");
        assert_eq!(N(2.456).to_string(), "2.46");
        assert_eq!(N(f64::NAN).to_string(), "0");
    }

    #[test]
    fn text_is_escaped_and_measured() {
        assert_eq!(escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
        assert!((text_width("0", 2048.0) - 1303.0).abs() < 1e-9);
        let short = fit_text("a very long method name indeed", 12.0, 60.0);
        assert!(short.ends_with('…') && text_width(&short, 12.0) <= 60.0);
    }
}
