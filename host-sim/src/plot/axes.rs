//! Data → pixel mapping, "nice" ticks, axis drawing and legends.

use super::canvas::{fit_text, text_width, Anchor, Marker, Stroke, Svg, Text, AXIS, GRID, INK};

/// A plot box in pixels and the data range it shows.
#[derive(Clone, Copy, Debug)]
pub(super) struct Axes {
    /// Left, top, width, height of the plot box (px).
    pub x: f64,
    pub y: f64,
    pub w: f64,
    pub h: f64,
    pub xlim: (f64, f64),
    pub ylim: (f64, f64),
}

impl Axes {
    pub(super) fn px(&self, v: f64) -> f64 {
        self.x + (v - self.xlim.0) / (self.xlim.1 - self.xlim.0) * self.w
    }
    pub(super) fn py(&self, v: f64) -> f64 {
        self.y + self.h - (v - self.ylim.0) / (self.ylim.1 - self.ylim.0) * self.h
    }
    pub(super) fn p(&self, q: [f64; 2]) -> (f64, f64) {
        (self.px(q[0]), self.py(q[1]))
    }
    pub(super) fn bottom(&self) -> f64 {
        self.y + self.h
    }
    pub(super) fn right(&self) -> f64 {
        self.x + self.w
    }
}

/// The 1, 2 or 5 × 10^k nearest to `raw` (raw > 0), rounding like a person would.
pub(super) fn nice_step(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let m = if f < 1.5 {
        1.0
    } else if f < 3.0 {
        2.0
    } else if f < 7.0 {
        5.0
    } else {
        10.0
    };
    m * mag
}

/// The next coarser 1-2-5 step after `step`.
fn coarser(step: f64) -> f64 {
    let mag = 10f64.powf((step.log10() + 1e-9).floor());
    match (step / mag).round() as i64 {
        1 => 2.0 * mag,
        2 => 5.0 * mag,
        _ => 10.0 * mag,
    }
}

/// A nice step giving about `target` intervals over `range`, made coarser until ticks
/// are at least `min_px` apart on an axis `px` pixels long.
pub(super) fn choose_step(range: f64, px: f64, target: f64, min_px: f64) -> f64 {
    let mut step = nice_step(range / target);
    if !(range.is_finite() && range > 0.0 && px > 0.0) {
        return step;
    }
    for _ in 0..30 {
        if step / range * px >= min_px {
            break;
        }
        step = coarser(step);
    }
    step
}

/// Multiples of `step` inside [lo, hi] (with a little tolerance), at most 200 of them.
pub(super) fn ticks(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let mut out = Vec::new();
    if !(lo.is_finite() && hi.is_finite() && step.is_finite() && step > 0.0 && hi >= lo) {
        return out;
    }
    let first = (lo / step - 1e-9).ceil();
    let last = (hi / step + 1e-9).floor();
    if last - first > 200.0 {
        return out;
    }
    let mut k = first;
    while k <= last {
        let v = k * step;
        out.push(if v.abs() < step * 1e-9 { 0.0 } else { v });
        k += 1.0;
    }
    out
}

/// Tick label with as many decimals as `step` needs and a typographic minus.
pub(super) fn tick_label(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10() - 1e-9).ceil().clamp(0.0, 6.0) as usize
    };
    let s = format!("{:.*}", decimals, v.abs());
    let zero = s.chars().all(|c| c == '0' || c == '.');
    if v < 0.0 && !zero {
        format!("−{s}")
    } else {
        s
    }
}

/// Bounding box of the finite points, `None` if there are none.
pub(super) fn bounds<'a>(
    sets: impl IntoIterator<Item = &'a [[f64; 2]]>,
) -> Option<((f64, f64), (f64, f64))> {
    let mut b: Option<((f64, f64), (f64, f64))> = None;
    for set in sets {
        for q in set {
            if !(q[0].is_finite() && q[1].is_finite()) {
                continue;
            }
            b = Some(match b {
                None => ((q[0], q[0]), (q[1], q[1])),
                Some(((x0, x1), (y0, y1))) => {
                    ((x0.min(q[0]), x1.max(q[0])), (y0.min(q[1]), y1.max(q[1])))
                }
            });
        }
    }
    b
}

/// Equal-aspect limits: the data box padded by `pad` (fraction) and grown along one
/// axis so that one mm is the same number of pixels along x and y in a `w` × `h` box.
/// Degenerate or missing data gets a 100 mm square around its centre (or the origin).
pub(super) fn equal_aspect_limits(
    b: Option<((f64, f64), (f64, f64))>,
    pad: f64,
    w: f64,
    h: f64,
) -> ((f64, f64), (f64, f64)) {
    let ((x0, x1), (y0, y1)) = b.unwrap_or(((-50.0, 50.0), (-50.0, 50.0)));
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let mut xr = (x1 - x0) * (1.0 + 2.0 * pad);
    let mut yr = (y1 - y0) * (1.0 + 2.0 * pad);
    if !(xr.is_finite() && yr.is_finite() && cx.is_finite() && cy.is_finite()) {
        return ((-50.0, 50.0), (-50.0, 50.0));
    }
    if xr < 1e-9 && yr < 1e-9 {
        xr = 100.0;
        yr = 100.0;
    }
    let scale = (xr / w).max(yr / h); // mm per px
    xr = scale * w;
    yr = scale * h;
    (
        (cx - xr / 2.0, cx + xr / 2.0),
        (cy - yr / 2.0, cy + yr / 2.0),
    )
}

/// Layout of an equal-aspect spatial panel `pw` px wide showing `sets`: its height (the
/// data's aspect, clamped to `height`), x and y limits, and a tick step aiming at
/// `ticks` ticks at least `min_px` apart.
pub(super) struct EqualAspectPanel {
    pub height: f64,
    pub xlim: (f64, f64),
    pub ylim: (f64, f64),
    pub step: f64,
}

pub(super) fn equal_aspect_panel<'a>(
    sets: impl IntoIterator<Item = &'a [[f64; 2]]>,
    pw: f64,
    height: (f64, f64),
    ticks: f64,
    min_px: f64,
) -> EqualAspectPanel {
    let b = bounds(sets);
    let aspect = b
        .map(|((x0, x1), (y0, y1))| (y1 - y0) / (x1 - x0))
        .filter(|a| a.is_finite() && *a > 0.0)
        .unwrap_or(1.0);
    let ph = (pw * aspect).clamp(height.0, height.1);
    let (xlim, ylim) = equal_aspect_limits(b, 0.05, pw, ph);
    let range = (xlim.1 - xlim.0).max(ylim.1 - ylim.0);
    let step = choose_step(range, range / (xlim.1 - xlim.0) * pw, ticks, min_px);
    EqualAspectPanel {
        height: ph,
        xlim,
        ylim,
        step,
    }
}

/// Which decorations an axis gets.
pub(super) struct AxisStyle<'a> {
    pub xstep: Option<f64>,
    pub ystep: f64,
    pub x_tick_labels: bool,
    pub y_tick_labels: bool,
    pub x_label: Option<&'a str>,
    pub y_label: Option<&'a str>,
    pub tick_size: f64,
    pub label_size: f64,
}

/// Gridlines, ticks, tick labels, axis labels and frame. Call before drawing data for
/// the grid and [`frame`] after it so the spines stay on top.
pub(super) fn grid_and_ticks(svg: &mut Svg, ax: &Axes, st: &AxisStyle) {
    let grid = Stroke::solid(GRID, 1.0);
    let tick = Stroke::solid(AXIS, 1.0);
    let yt = ticks(ax.ylim.0, ax.ylim.1, st.ystep);
    let xt = st
        .xstep
        .map(|s| ticks(ax.xlim.0, ax.xlim.1, s))
        .unwrap_or_default();
    for &v in &yt {
        let y = ax.py(v);
        svg.line(ax.x, y, ax.right(), y, grid);
    }
    for &v in &xt {
        let x = ax.px(v);
        svg.line(x, ax.y, x, ax.bottom(), grid);
    }
    let mut widest_y = 0.0f64;
    for &v in &yt {
        let y = ax.py(v);
        svg.line(ax.x - 5.0, y, ax.x, y, tick);
        if st.y_tick_labels {
            let s = tick_label(v, st.ystep);
            widest_y = widest_y.max(text_width(&s, st.tick_size));
            svg.text(ax.x - 8.0, y, &s, Text::new(st.tick_size, Anchor::End));
        }
    }
    for &v in &xt {
        let x = ax.px(v);
        svg.line(x, ax.bottom(), x, ax.bottom() + 5.0, tick);
        if st.x_tick_labels {
            let s = tick_label(v, st.xstep.unwrap_or(1.0));
            svg.text(
                x,
                ax.bottom() + 8.0 + st.tick_size * 0.6,
                &s,
                Text::new(st.tick_size, Anchor::Middle),
            );
        }
    }
    if let Some(l) = st.x_label {
        let y = ax.bottom() + 8.0 + st.tick_size * 1.2 + 6.0 + st.label_size * 0.6;
        let l = fit_text(l, st.label_size, ax.w);
        svg.text(
            ax.x + ax.w / 2.0,
            y,
            &l,
            Text::new(st.label_size, Anchor::Middle),
        );
    }
    if let Some(l) = st.y_label {
        let x = ax.x - 8.0 - widest_y - 10.0 - st.label_size * 0.6;
        let l = fit_text(l, st.label_size, ax.h);
        svg.text(
            x,
            ax.y + ax.h / 2.0,
            &l,
            Text {
                rotate: 90.0,
                ..Text::new(st.label_size, Anchor::Middle)
            },
        );
    }
}

/// Axis spines.
pub(super) fn frame(svg: &mut Svg, ax: &Axes, full_box: bool) {
    let s = Stroke::solid(AXIS, 1.2);
    svg.line(ax.x, ax.y, ax.x, ax.bottom(), s);
    svg.line(ax.x, ax.bottom(), ax.right(), ax.bottom(), s);
    if full_box {
        svg.line(ax.x, ax.y, ax.right(), ax.y, s);
        svg.line(ax.right(), ax.y, ax.right(), ax.bottom(), s);
    }
}

/// What a legend entry shows left of its label.
#[derive(Clone, Debug)]
pub(super) enum Swatch {
    Marker {
        marker: Marker,
        size: f64,
        color: String,
    },
    /// A short line, optionally with a marker in its middle.
    Line {
        color: String,
        width: f64,
        dash: Option<&'static str>,
        marker: Option<(Marker, f64)>,
    },
    /// An open circle (ring), e.g. for circled endpoints.
    Ring { color: String, r: f64 },
    /// A small box plot glyph.
    BoxGlyph { color: String },
    /// A whisker (vertical line with caps).
    Whisker { color: String },
}

#[derive(Clone, Debug)]
pub(super) struct LegendEntry {
    pub swatch: Swatch,
    pub label: String,
}

const SWATCH_W: f64 = 26.0;
const SWATCH_GAP: f64 = 7.0;

fn draw_swatch(svg: &mut Svg, sw: &Swatch, x: f64, y: f64) {
    let cx = x + SWATCH_W / 2.0;
    match sw {
        Swatch::Marker {
            marker,
            size,
            color,
        } => svg.marker(*marker, cx, y, *size, color),
        Swatch::Line {
            color,
            width,
            dash,
            marker,
        } => {
            let st = Stroke {
                color,
                width: *width,
                dash: *dash,
                opacity: 1.0,
            };
            svg.line(x, y, x + SWATCH_W, y, st);
            if let Some((m, s)) = marker {
                svg.marker(*m, cx, y, *s, color);
            }
        }
        Swatch::Ring { color, r } => svg.circle(cx, y, *r, None, Some(Stroke::solid(color, 2.0))),
        Swatch::BoxGlyph { color } => {
            svg.rect(
                x + 4.0,
                y - 7.0,
                SWATCH_W - 8.0,
                14.0,
                Some((color, 0.25)),
                Some(Stroke::solid(color, 1.5)),
            );
            svg.line(
                x + 4.0,
                y + 1.0,
                x + SWATCH_W - 4.0,
                y + 1.0,
                Stroke::solid(color, 2.5),
            );
        }
        Swatch::Whisker { color } => {
            let s = Stroke::solid(color, 1.5);
            svg.line(cx, y - 8.0, cx, y + 8.0, s);
            svg.line(cx - 5.0, y - 8.0, cx + 5.0, y - 8.0, s);
            svg.line(cx - 5.0, y + 8.0, cx + 5.0, y + 8.0, s);
        }
    }
}

fn entry_width(e: &LegendEntry, size: f64) -> f64 {
    SWATCH_W + SWATCH_GAP + text_width(&e.label, size)
}

/// Row layout of a flowing legend: indices of the entries on each row.
fn flow_rows(entries: &[LegendEntry], size: f64, max_w: f64, spacing: f64) -> Vec<Vec<usize>> {
    let mut rows: Vec<Vec<usize>> = Vec::new();
    let mut cur: Vec<usize> = Vec::new();
    let mut w = 0.0;
    for (i, e) in entries.iter().enumerate() {
        let ew = entry_width(e, size).min(max_w);
        let add = if cur.is_empty() { ew } else { spacing + ew };
        if !cur.is_empty() && w + add > max_w {
            rows.push(std::mem::take(&mut cur));
            w = ew;
        } else {
            w += add;
        }
        cur.push(i);
    }
    if !cur.is_empty() {
        rows.push(cur);
    }
    rows
}

/// Rows a flowing legend needs at `max_w` px.
pub(super) fn flow_row_count(entries: &[LegendEntry], size: f64, max_w: f64) -> usize {
    flow_rows(entries, size, max_w, 22.0).len()
}

/// A legend laid out in centred rows within `max_w` px around `cx`, first row centred
/// on `y`; returns the y just below the last row.
pub(super) fn legend_flow(
    svg: &mut Svg,
    entries: &[LegendEntry],
    cx: f64,
    y: f64,
    max_w: f64,
    size: f64,
) -> f64 {
    let spacing = 22.0;
    let row_h = size * 1.75;
    let rows = flow_rows(entries, size, max_w, spacing);
    for (r, row) in rows.iter().enumerate() {
        let widths: Vec<f64> = row
            .iter()
            .map(|&i| entry_width(&entries[i], size).min(max_w))
            .collect();
        let total = widths.iter().sum::<f64>() + spacing * (row.len().saturating_sub(1)) as f64;
        let mut x = cx - total / 2.0;
        let yy = y + r as f64 * row_h;
        for (k, &i) in row.iter().enumerate() {
            let e = &entries[i];
            draw_swatch(svg, &e.swatch, x, yy);
            let label = fit_text(&e.label, size, widths[k] - SWATCH_W - SWATCH_GAP);
            svg.text(
                x + SWATCH_W + SWATCH_GAP,
                yy,
                &label,
                Text::new(size, Anchor::Start),
            );
            x += widths[k] + spacing;
        }
    }
    y + rows.len() as f64 * row_h - row_h / 2.0
}

/// Width of a boxed, one-entry-per-row legend.
pub(super) fn legend_box_width(entries: &[LegendEntry], size: f64, max_w: f64) -> f64 {
    let inner = entries
        .iter()
        .map(|e| entry_width(e, size))
        .fold(0.0, f64::max);
    (inner + 24.0).min(max_w)
}

/// A framed legend, one entry per row, top-left corner at (x, y), `w` px wide.
pub(super) fn legend_box(
    svg: &mut Svg,
    entries: &[LegendEntry],
    x: f64,
    y: f64,
    w: f64,
    size: f64,
) {
    if entries.is_empty() {
        return;
    }
    let row_h = size * 1.9;
    let h = entries.len() as f64 * row_h + 12.0;
    svg.rect(
        x,
        y,
        w,
        h,
        Some(("white", 0.92)),
        Some(Stroke::solid("#bbbbbb", 1.0)),
    );
    for (i, e) in entries.iter().enumerate() {
        let yy = y + 6.0 + row_h * (i as f64 + 0.5);
        draw_swatch(svg, &e.swatch, x + 12.0, yy);
        let label = fit_text(&e.label, size, w - 24.0 - SWATCH_W - SWATCH_GAP);
        let t = Text {
            color: INK,
            ..Text::new(size, Anchor::Start)
        };
        svg.text(x + 12.0 + SWATCH_W + SWATCH_GAP, yy, &label, t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_steps() {
        assert_eq!(nice_step(0.9), 1.0);
        assert_eq!(nice_step(1.3), 1.0);
        assert_eq!(nice_step(2.9), 2.0);
        assert_eq!(nice_step(3.0), 5.0);
        assert_eq!(nice_step(7.0), 10.0);
        assert_eq!(nice_step(23.0), 20.0);
        assert_eq!(coarser(0.2), 0.5);
        assert_eq!(coarser(5.0), 10.0);
        assert_eq!(coarser(10.0), 20.0);
        assert_eq!(choose_step(100.0, 100.0, 10.0, 40.0), 50.0);
        assert_eq!(choose_step(100.0, 1000.0, 5.0, 40.0), 20.0);
        assert_eq!(nice_step(f64::NAN), 1.0);
        assert_eq!(nice_step(0.0), 1.0);
    }

    #[test]
    fn ticks_and_labels() {
        assert_eq!(ticks(-0.1, 10.1, 2.5), vec![0.0, 2.5, 5.0, 7.5, 10.0]);
        assert!(ticks(0.0, f64::INFINITY, 1.0).is_empty());
        assert!(ticks(0.0, 1e12, 1.0).is_empty());
        assert_eq!(tick_label(-20.0, 10.0), "−20");
        assert_eq!(tick_label(0.5, 0.5), "0.5");
        assert_eq!(tick_label(-0.0, 0.5), "0.0");
        assert_eq!(tick_label(0.25, 0.05), "0.25");
    }

    #[test]
    fn equal_aspect_is_equal() {
        let ((x0, x1), (y0, y1)) =
            equal_aspect_limits(Some(((0.0, 200.0), (0.0, 50.0))), 0.0, 400.0, 200.0);
        assert!(((x1 - x0) / 400.0 - (y1 - y0) / 200.0).abs() < 1e-12);
        assert!((x1 - x0 - 200.0).abs() < 1e-9 && y0 <= 0.0 && y1 >= 50.0);
        let d = equal_aspect_limits(None, 0.05, 100.0, 100.0);
        assert!(d.0 .1 > d.0 .0 && d.1 .1 > d.1 .0);
        let p = equal_aspect_limits(Some(((3.0, 3.0), (4.0, 4.0))), 0.05, 100.0, 50.0);
        assert!(p.0 .1 > p.0 .0 && p.1 .1 > p.1 .0);
    }
}
