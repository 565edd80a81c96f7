//! Figures for evaluation reports: error distributions, the skeleton-extraction stages
//! (paper Fig. 4) and waypoint transfer (paper Fig. 6).
//!
//! Plain data in, files out. Every function takes a path *stem* and writes exactly two
//! files, `<stem>.svg` and `<stem>.png` (the PNG is the SVG rasterised at 1 px per SVG
//! unit by the pure-Rust `resvg`, with the DejaVu Sans font embedded in the binary, so
//! both look the same and the output is byte-for-byte deterministic on every machine).
//! Nothing else is created: the parent directory must exist. Coordinates and errors
//! are in millimetres. Non-finite values (NaN, ±∞) are skipped; empty inputs give an
//! empty but well-formed figure. Errors are I/O failures (or, in principle, a
//! rasteriser failure), never panics.

mod axes;
mod canvas;
#[cfg(test)]
mod tests;

use axes::{
    choose_step, equal_aspect_panel, flow_row_count, frame, grid_and_ticks, legend_box,
    legend_box_width, legend_flow, Axes, AxisStyle, EqualAspectPanel, LegendEntry, Swatch,
};
use canvas::{
    fit_text, palette, text_width, Anchor, Marker, Stroke, Svg, Text, CLOUD, FONT_FAMILY, INK,
    METHOD_MARKERS,
};
use resvg::{tiny_skia, usvg};
use std::ffi::OsString;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

/// DejaVu Sans 2.37 (licence: `host-sim/assets/DejaVuSans.LICENSE`).
static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// Width of [`error_distributions`] figures (px); the height is [`ERROR_PLOT_HEIGHT`].
pub const ERROR_PLOT_WIDTH: u32 = 1200;
/// Height of [`error_distributions`] figures (px).
pub const ERROR_PLOT_HEIGHT: u32 = 700;
/// Width of [`skeleton_figure`] figures (px); the height follows the data's aspect.
pub const SKELETON_WIDTH: u32 = 1600;
/// Width of [`waypoint_transfer`] figures (px); the height follows the data's aspect.
pub const WAYPOINT_WIDTH: u32 = 1200;

/// Why a figure could not be written.
#[derive(Debug)]
pub enum PlotError {
    /// Writing `path` failed.
    Io {
        /// The file being written.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The SVG could not be rasterised (a bug in this module if it ever happens).
    Render(String),
}

impl fmt::Display for PlotError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PlotError::Io { path, source } => {
                write!(f, "cannot write {}: {source}", path.display())
            }
            PlotError::Render(msg) => write!(f, "cannot render figure: {msg}"),
        }
    }
}

impl std::error::Error for PlotError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            PlotError::Io { source, .. } => Some(source),
            PlotError::Render(_) => None,
        }
    }
}

/// One method's values (e.g. per-waypoint errors in mm).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Series {
    /// Method name shown under its box.
    pub label: String,
    /// The values, mm.
    pub values: Vec<f64>,
}

/// The stages of skeleton extraction, already projected to 2-D (mm), for
/// [`skeleton_figure`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SkeletonPanels {
    /// The input point cloud.
    pub cloud: Vec<[f64; 2]>,
    /// SOM-1 nodes (400 in the paper).
    pub som1: Vec<[f64; 2]>,
    /// SOM-2 nodes: the skeleton key points (40 in the paper).
    pub key_points: Vec<[f64; 2]>,
    /// MST edges as index pairs into `key_points` (out-of-range pairs are skipped).
    pub edges: Vec<(usize, usize)>,
    /// Indices into `key_points` of the MST endpoints (leaves), circled.
    pub endpoints: Vec<usize>,
    /// The optimised path of each rib, one polyline per rib.
    pub rib_paths: Vec<Vec<[f64; 2]>>,
    /// The resampled skeleton points.
    pub skeleton: Vec<[f64; 2]>,
}

/// Waypoints mapped by one method, index-matched with the true waypoints.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WaypointSet {
    /// Method name shown in the legend.
    pub label: String,
    /// Mapped waypoints, projected to 2-D (mm).
    pub points: Vec<[f64; 2]>,
}

fn with_suffix(stem: &Path, ext: &str) -> PathBuf {
    let mut s: OsString = stem.as_os_str().to_owned();
    s.push(".");
    s.push(ext);
    PathBuf::from(s)
}

fn font_db() -> Arc<usvg::fontdb::Database> {
    static DB: OnceLock<Arc<usvg::fontdb::Database>> = OnceLock::new();
    DB.get_or_init(|| {
        let mut db = usvg::fontdb::Database::new();
        db.load_font_data(FONT.to_vec());
        db.set_sans_serif_family(FONT_FAMILY);
        Arc::new(db)
    })
    .clone()
}

/// Rasterises an SVG produced by this module to PNG bytes.
fn rasterise(svg: &str) -> Result<Vec<u8>, PlotError> {
    let opt = usvg::Options {
        font_family: FONT_FAMILY.to_string(),
        fontdb: font_db(),
        ..Default::default()
    };
    let tree = usvg::Tree::from_str(svg, &opt).map_err(|e| PlotError::Render(e.to_string()))?;
    let size = tree.size().to_int_size();
    let mut pixmap = tiny_skia::Pixmap::new(size.width(), size.height())
        .ok_or_else(|| PlotError::Render(format!("bad canvas size {size:?}")))?;
    resvg::render(
        &tree,
        tiny_skia::Transform::identity(),
        &mut pixmap.as_mut(),
    );
    pixmap
        .encode_png()
        .map_err(|e| PlotError::Render(e.to_string()))
}

/// Renders first, so a render failure leaves no files behind; then writes both.
fn write_figure(stem: &Path, svg: Svg) -> Result<(), PlotError> {
    let svg = svg.finish();
    let png = rasterise(&svg)?;
    for (ext, bytes) in [("svg", svg.as_bytes()), ("png", png.as_slice())] {
        let path = with_suffix(stem, ext);
        std::fs::write(&path, bytes).map_err(|source| PlotError::Io { path, source })?;
    }
    Ok(())
}

fn finite2(q: &[f64; 2]) -> bool {
    q[0].is_finite() && q[1].is_finite()
}

fn title(svg: &mut Svg, s: &str) {
    let w = f64::from(svg.width);
    let s = fit_text(s, 22.0, w - 40.0);
    svg.text(w / 2.0, 30.0, &s, Text::new(22.0, Anchor::Middle));
}

/// Greedy word wrap to `max_w` px, at most `max_lines` lines (the last one shortened
/// with an ellipsis if needed).
fn wrap(s: &str, size: f64, max_w: f64, max_lines: usize) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    let mut cur = String::new();
    for word in s.split_whitespace() {
        let candidate = if cur.is_empty() {
            word.to_string()
        } else {
            format!("{cur} {word}")
        };
        if cur.is_empty() || text_width(&candidate, size) <= max_w {
            cur = candidate;
        } else {
            lines.push(std::mem::replace(&mut cur, word.to_string()));
        }
    }
    if !cur.is_empty() {
        lines.push(cur);
    }
    if lines.len() > max_lines {
        let rest = lines.split_off(max_lines - 1).join(" ");
        lines.push(rest);
    }
    lines
        .into_iter()
        .map(|l| fit_text(&l, size, max_w))
        .collect()
}

// ---------------------------------------------------------------- error distributions

fn reference_label(v: f64, label: &str) -> String {
    if label.trim().is_empty() {
        format!("{v} mm")
    } else {
        label.to_string()
    }
}

/// Box-plot statistics of the finite values of one series.
#[derive(Debug, Clone, PartialEq)]
struct BoxStats {
    sorted: Vec<f64>,
    mean: f64,
    q1: f64,
    median: f64,
    q3: f64,
    /// Most extreme values within 1.5 IQR of the box (Tukey whiskers).
    whisker_lo: f64,
    whisker_hi: f64,
}

/// Linear-interpolation quantile (R type 7) of sorted, non-empty data.
fn quantile(sorted: &[f64], p: f64) -> f64 {
    let h = (sorted.len() - 1) as f64 * p;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

fn box_stats(values: &[f64]) -> Option<BoxStats> {
    let mut sorted: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if sorted.is_empty() {
        return None;
    }
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len() as f64;
    let mean = sorted.iter().map(|v| v / n).sum::<f64>();
    let (q1, median, q3) = (
        quantile(&sorted, 0.25),
        quantile(&sorted, 0.5),
        quantile(&sorted, 0.75),
    );
    let iqr = q3 - q1;
    let (lo_fence, hi_fence) = (q1 - 1.5 * iqr, q3 + 1.5 * iqr);
    let whisker_lo = sorted
        .iter()
        .copied()
        .find(|&v| v >= lo_fence)
        .unwrap_or(q1);
    let whisker_hi = sorted
        .iter()
        .rev()
        .copied()
        .find(|&v| v <= hi_fence)
        .unwrap_or(q3);
    Some(BoxStats {
        sorted,
        mean,
        q1,
        median,
        q3,
        whisker_lo,
        whisker_hi,
    })
}

/// Deterministic pseudo-random number in [0, 1) (SplitMix64 of `seed`).
fn unit_hash(seed: u64) -> f64 {
    let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// Above this many values per method the individual points are not drawn, only the
/// outliers.
const MAX_JITTER_POINTS: usize = 1500;

/// Box plot of error distributions per method (y in mm): box = interquartile range,
/// line = median, whiskers = Tukey's 1.5 IQR, black diamond = mean, individual values
/// jittered behind (outliers only above 1500 values), an optional dashed horizontal
/// reference line with its label (e.g. `Some((5.0, "5 mm clinical tolerance"))`), and
/// each method's mean and count printed under its name. 1200 × 700 px.
pub fn error_distributions(
    stem: &Path,
    title: &str,
    y_label: &str,
    series: &[Series],
    reference_line: Option<(f64, &str)>,
) -> Result<(), PlotError> {
    write_figure(
        stem,
        error_distributions_svg(title, y_label, series, reference_line),
    )
}

fn error_distributions_svg(
    title_text: &str,
    y_label: &str,
    series: &[Series],
    reference_line: Option<(f64, &str)>,
) -> Svg {
    let (w, h) = (f64::from(ERROR_PLOT_WIDTH), f64::from(ERROR_PLOT_HEIGHT));
    let mut svg = Svg::new(ERROR_PLOT_WIDTH, ERROR_PLOT_HEIGHT);
    svg.comment("ribreg error distributions");
    title(&mut svg, title_text);

    let stats: Vec<Option<BoxStats>> = series.iter().map(|s| box_stats(&s.values)).collect();
    let reference = reference_line.filter(|(v, _)| v.is_finite());
    let any_points = stats
        .iter()
        .flatten()
        .any(|s| s.sorted.len() <= MAX_JITTER_POINTS);

    // Legend row under the title.
    let neutral = "#555555".to_string();
    let mut legend = vec![
        LegendEntry {
            swatch: Swatch::BoxGlyph {
                color: neutral.clone(),
            },
            label: "interquartile range and median".into(),
        },
        LegendEntry {
            swatch: Swatch::Whisker {
                color: neutral.clone(),
            },
            label: "whiskers: 1.5 × IQR".into(),
        },
        LegendEntry {
            swatch: Swatch::Marker {
                marker: Marker::Diamond,
                size: 11.0,
                color: INK.into(),
            },
            label: "mean".into(),
        },
        LegendEntry {
            swatch: Swatch::Marker {
                marker: Marker::Circle,
                size: 5.0,
                color: "#888888".into(),
            },
            label: if any_points {
                "individual values".into()
            } else {
                "outliers".into()
            },
        },
    ];
    if let Some((v, label)) = reference {
        let label = reference_label(v, label);
        legend.push(LegendEntry {
            swatch: Swatch::Line {
                color: "#d62728".into(),
                width: 2.0,
                dash: Some("8 5"),
                marker: None,
            },
            label,
        });
    }
    let legend_size = 13.0;
    let legend_y = 62.0;
    let legend_bottom = legend_flow(&mut svg, &legend, w / 2.0, legend_y, w - 120.0, legend_size);

    // Y range: all finite values and the reference; errors start at 0.
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in stats.iter().flatten() {
        lo = lo.min(s.sorted[0]);
        hi = hi.max(s.sorted[s.sorted.len() - 1]);
    }
    if let Some((v, _)) = reference {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !(lo.is_finite() && hi.is_finite()) || hi - lo > 1e12 {
        (lo, hi) = (0.0, 1.0);
    }
    if lo >= 0.0 {
        lo = 0.0;
    }
    if hi - lo < 1e-9 {
        hi = lo + 1.0;
    }
    hi += 0.04 * (hi - lo);
    let ystep = choose_step(hi - lo, 500.0, 7.0, 40.0);
    let ylim = ((lo / ystep).floor() * ystep, (hi / ystep).ceil() * ystep);

    let tick_size = 13.0;
    let widest = axes::ticks(ylim.0, ylim.1, ystep)
        .iter()
        .map(|&v| text_width(&axes::tick_label(v, ystep), tick_size))
        .fold(0.0, f64::max);
    let left = 24.0 + 16.0 + 10.0 + widest + 8.0;
    let top = legend_bottom + 22.0;
    // The reference line's label goes in the right margin, wrapped to three short lines.
    let ref_size = 13.0;
    let ref_lines: Vec<String> = reference
        .map(|(v, label)| wrap(&reference_label(v, label), ref_size, 130.0, 3))
        .unwrap_or_default();
    let right_margin = ref_lines
        .iter()
        .map(|l| text_width(l, ref_size) + 20.0)
        .fold(30.0, f64::max);
    // Method names wrap to two lines under narrow categories; the rows below align.
    let n = series.len().max(1);
    let cat_w = (w - right_margin - left) / n as f64;
    let name_size = 15.0;
    let names: Vec<Vec<String>> = series
        .iter()
        .map(|s| wrap(&s.label, name_size, cat_w - 8.0, 2))
        .collect();
    let name_lines = names.iter().map(Vec::len).max().unwrap_or(1).max(1);
    let name_h = name_size * 1.25;
    let bottom = h - 60.0 - name_h * name_lines as f64;
    let ax = Axes {
        x: left,
        y: top,
        w: w - right_margin - left,
        h: bottom - top,
        xlim: (0.0, 1.0),
        ylim,
    };
    let style = AxisStyle {
        xstep: None,
        ystep,
        x_tick_labels: false,
        y_tick_labels: true,
        x_label: None,
        y_label: Some(y_label),
        tick_size,
        label_size: 16.0,
    };
    grid_and_ticks(&mut svg, &ax, &style);

    let box_w = (cat_w * 0.5).min(90.0);
    for (i, st) in stats.iter().enumerate() {
        let cx = ax.x + cat_w * (i as f64 + 0.5);
        let color = palette(i);
        svg.line(
            cx,
            ax.bottom(),
            cx,
            ax.bottom() + 5.0,
            Stroke::solid(canvas::AXIS, 1.0),
        );
        for (k, line) in names[i].iter().enumerate() {
            let y = ax.bottom() + 20.0 + k as f64 * name_h;
            svg.text(cx, y, line, Text::new(name_size, Anchor::Middle));
        }
        let below = ax.bottom() + 20.0 + name_h * (name_lines as f64 - 1.0);
        let Some(st) = st else {
            let t = Text {
                color: "#777777",
                ..Text::new(13.0, Anchor::Middle)
            };
            svg.text(cx, below + 22.0, "no data", t);
            continue;
        };
        let mean_text = fit_text(&format!("mean {:.2} mm", st.mean), 14.0, cat_w - 6.0);
        svg.text(
            cx,
            below + 22.0,
            &mean_text,
            Text::new(14.0, Anchor::Middle),
        );
        let count = fit_text(&format!("n = {}", st.sorted.len()), 12.0, cat_w - 6.0);
        let grey = Text {
            color: "#666666",
            ..Text::new(12.0, Anchor::Middle)
        };
        svg.text(cx, below + 41.0, &count, grey);

        // Points (jittered) or outliers, behind the box.
        let draw_all = st.sorted.len() <= MAX_JITTER_POINTS;
        let r = if st.sorted.len() > 300 { 1.6 } else { 2.4 };
        svg.group(&format!(r#"fill="{color}" fill-opacity="0.45""#));
        for (k, &v) in st.sorted.iter().enumerate() {
            let outlier = v < st.whisker_lo || v > st.whisker_hi;
            if !(draw_all || outlier) {
                continue;
            }
            let jitter = if draw_all {
                (unit_hash(((i as u64) << 32) | k as u64) - 0.5) * box_w * 0.8
            } else {
                0.0
            };
            svg.dot(cx + jitter, ax.py(v), r);
        }
        svg.end_group();

        // Whiskers, box, median, mean.
        let wk = Stroke::solid(color, 1.6);
        let (y_q1, y_q3) = (ax.py(st.q1), ax.py(st.q3));
        svg.line(cx, ax.py(st.whisker_lo), cx, y_q1, wk);
        svg.line(cx, y_q3, cx, ax.py(st.whisker_hi), wk);
        for wv in [st.whisker_lo, st.whisker_hi] {
            let y = ax.py(wv);
            svg.line(cx - box_w * 0.25, y, cx + box_w * 0.25, y, wk);
        }
        svg.rect(
            cx - box_w / 2.0,
            y_q3,
            box_w,
            (y_q1 - y_q3).max(0.5),
            Some((color, 0.18)),
            Some(Stroke::solid(color, 1.8)),
        );
        let ym = ax.py(st.median);
        svg.line(
            cx - box_w / 2.0,
            ym,
            cx + box_w / 2.0,
            ym,
            Stroke::solid(color, 3.0),
        );
        svg.marker(Marker::Diamond, cx, ax.py(st.mean), 11.0, INK);
    }

    if let Some((v, _)) = reference {
        let y = ax.py(v);
        let dashed = Stroke::dashed("#d62728", 2.0, "8 5");
        svg.line(ax.x, y, ax.right() + 6.0, y, dashed);
        let line_h = ref_size * 1.3;
        let block = line_h * (ref_lines.len() as f64 - 1.0).max(0.0);
        let y0 = (y - block / 2.0).clamp(ax.y, (ax.bottom() - block).max(ax.y));
        let t = Text {
            color: "#b01e1e",
            ..Text::new(ref_size, Anchor::Start)
        };
        for (k, l) in ref_lines.iter().enumerate() {
            svg.text(ax.right() + 12.0, y0 + k as f64 * line_h, l, t);
        }
    }
    frame(&mut svg, &ax, false);
    svg
}

// ------------------------------------------------------------------- skeleton figure

/// The four stages of skeleton extraction side by side, like Fig. 4 of the paper, on
/// shared, equal-aspect axes: (a) cloud + SOM-1 nodes, (b) cloud + SOM-2 key points,
/// (c) key points + MST edges with the endpoints circled, (d) cloud + the optimised
/// rib paths (one colour per rib) and the resampled skeleton points. 1600 px wide; the
/// height follows the data's aspect ratio.
pub fn skeleton_figure(stem: &Path, title: &str, panels: &SkeletonPanels) -> Result<(), PlotError> {
    write_figure(stem, skeleton_svg(title, panels))
}

/// Rib path colours: the palette without orange, which marks key points.
fn rib_color(i: usize) -> &'static str {
    const ORDER: [usize; 9] = [0, 2, 3, 4, 5, 6, 8, 9, 7];
    palette(ORDER[i % ORDER.len()])
}

const KEY_COLOR: &str = "#ff7f0e";
const ENDPOINT_COLOR: &str = "#d62728";

fn cloud_entry(n: usize) -> LegendEntry {
    LegendEntry {
        swatch: Swatch::Marker {
            marker: Marker::Circle,
            size: 6.0,
            color: CLOUD.into(),
        },
        label: format!("point cloud ({n})"),
    }
}

fn count_finite(pts: &[[f64; 2]]) -> usize {
    pts.iter().filter(|q| finite2(q)).count()
}

fn draw_cloud(svg: &mut Svg, ax: &Axes, cloud: &[[f64; 2]], r: f64) {
    svg.group(&format!(r#"fill="{CLOUD}""#));
    cloud_dots(svg, ax, cloud, r);
    svg.end_group();
}

fn cloud_dots(svg: &mut Svg, ax: &Axes, cloud: &[[f64; 2]], r: f64) {
    for q in cloud.iter().filter(|q| finite2(q)) {
        let (x, y) = ax.p(*q);
        svg.dot(x, y, r);
    }
}

fn skeleton_svg(title_text: &str, p: &SkeletonPanels) -> Svg {
    let w = f64::from(SKELETON_WIDTH);
    let (left, right, gap) = (84.0, 18.0, 28.0);
    let pw = (w - left - right - 3.0 * gap) / 4.0;

    let rib_refs: Vec<&[[f64; 2]]> = p.rib_paths.iter().map(Vec::as_slice).collect();
    let mut sets: Vec<&[[f64; 2]]> = vec![&p.cloud, &p.som1, &p.key_points, &p.skeleton];
    sets.extend(rib_refs.iter().copied());
    let EqualAspectPanel {
        height: ph,
        xlim,
        ylim,
        step,
    } = equal_aspect_panel(sets, pw, (260.0, 560.0), 6.0, 50.0);
    let top = 92.0;

    // Legends first, to size the canvas.
    let key_n = count_finite(&p.key_points);
    let valid_edges: Vec<(usize, usize)> = p
        .edges
        .iter()
        .copied()
        .filter(|&(a, b)| {
            a < p.key_points.len()
                && b < p.key_points.len()
                && finite2(&p.key_points[a])
                && finite2(&p.key_points[b])
        })
        .collect();
    let valid_ends: Vec<usize> = p
        .endpoints
        .iter()
        .copied()
        .filter(|&i| i < p.key_points.len() && finite2(&p.key_points[i]))
        .collect();
    let cloud_n = count_finite(&p.cloud);
    let key_entry = LegendEntry {
        swatch: Swatch::Marker {
            marker: Marker::Circle,
            size: 10.0,
            color: KEY_COLOR.into(),
        },
        label: format!("key points ({key_n})"),
    };
    let mut legends: Vec<Vec<LegendEntry>> = vec![
        vec![
            cloud_entry(cloud_n),
            LegendEntry {
                swatch: Swatch::Marker {
                    marker: Marker::Circle,
                    size: 6.0,
                    color: palette(0).into(),
                },
                label: format!("SOM-1 nodes ({})", count_finite(&p.som1)),
            },
        ],
        vec![cloud_entry(cloud_n), key_entry.clone()],
        vec![
            LegendEntry {
                swatch: Swatch::Line {
                    color: "#555555".into(),
                    width: 2.0,
                    dash: None,
                    marker: None,
                },
                label: format!("MST edges ({})", valid_edges.len()),
            },
            key_entry,
            LegendEntry {
                swatch: Swatch::Ring {
                    color: ENDPOINT_COLOR.into(),
                    r: 7.0,
                },
                label: format!("endpoints ({})", valid_ends.len()),
            },
        ],
        vec![cloud_entry(cloud_n)],
    ];
    for (i, _) in p.rib_paths.iter().enumerate() {
        legends[3].push(LegendEntry {
            swatch: Swatch::Line {
                color: rib_color(i).into(),
                width: 3.0,
                dash: None,
                marker: None,
            },
            label: format!("rib path {}", i + 1),
        });
    }
    legends[3].push(LegendEntry {
        swatch: Swatch::Marker {
            marker: Marker::Circle,
            size: 5.0,
            color: INK.into(),
        },
        label: format!("skeleton points ({})", count_finite(&p.skeleton)),
    });
    let legend_size = 13.0;
    let rows = legends
        .iter()
        .map(|l| flow_row_count(l, legend_size, pw))
        .max()
        .unwrap_or(1);
    let legend_top = top + ph + 74.0;
    let h = (legend_top + rows as f64 * legend_size * 1.75 + 4.0).ceil();

    let mut svg = Svg::new(SKELETON_WIDTH, h as u32);
    svg.comment("ribreg skeleton extraction stages");
    title(&mut svg, title_text);
    let subtitles = [
        "(a) Point cloud and SOM-1 nodes",
        "(b) SOM-2 skeleton key points",
        "(c) Minimum spanning tree",
        "(d) Optimised rib paths",
    ];
    // The cloud is drawn once, for the first panel, and reused (shifted) in the others.
    let first = Axes {
        x: left,
        y: top,
        w: pw,
        h: ph,
        xlim,
        ylim,
    };
    svg.raw("<defs>\n");
    svg.group(&format!(r#"id="cloud" fill="{CLOUD}""#));
    cloud_dots(&mut svg, &first, &p.cloud, 1.5);
    svg.end_group();
    svg.raw("</defs>\n");
    for (k, legend) in legends.iter().enumerate() {
        let shift = k as f64 * (pw + gap);
        let cloud = format!("<use href=\"#cloud\" x=\"{}\"/>\n", canvas::N(shift));
        let ax = Axes {
            x: left + shift,
            y: top,
            w: pw,
            h: ph,
            xlim,
            ylim,
        };
        let sub = fit_text(subtitles[k], 16.0, pw);
        svg.text(
            ax.x + pw / 2.0,
            top - 16.0,
            &sub,
            Text::new(16.0, Anchor::Middle),
        );
        let style = AxisStyle {
            xstep: Some(step),
            ystep: step,
            x_tick_labels: true,
            y_tick_labels: k == 0,
            x_label: Some("x (mm)"),
            y_label: if k == 0 { Some("y (mm)") } else { None },
            tick_size: 13.0,
            label_size: 15.0,
        };
        grid_and_ticks(&mut svg, &ax, &style);
        match k {
            0 => {
                svg.raw(&cloud);
                svg.group(&format!(r#"fill="{}""#, palette(0)));
                for q in p.som1.iter().filter(|q| finite2(q)) {
                    let (x, y) = ax.p(*q);
                    svg.dot(x, y, 2.6);
                }
                svg.end_group();
            }
            1 => {
                svg.raw(&cloud);
                for q in p.key_points.iter().filter(|q| finite2(q)) {
                    let (x, y) = ax.p(*q);
                    svg.marker(Marker::Circle, x, y, 10.0, KEY_COLOR);
                }
            }
            2 => {
                for &(a, b) in &valid_edges {
                    let (x1, y1) = ax.p(p.key_points[a]);
                    let (x2, y2) = ax.p(p.key_points[b]);
                    svg.line(x1, y1, x2, y2, Stroke::solid("#555555", 2.0));
                }
                for q in p.key_points.iter().filter(|q| finite2(q)) {
                    let (x, y) = ax.p(*q);
                    svg.marker(Marker::Circle, x, y, 10.0, KEY_COLOR);
                }
                for &i in &valid_ends {
                    let (x, y) = ax.p(p.key_points[i]);
                    svg.circle(x, y, 9.0, None, Some(Stroke::solid(ENDPOINT_COLOR, 2.2)));
                }
            }
            _ => {
                svg.raw(&cloud);
                for (i, path) in p.rib_paths.iter().enumerate() {
                    // Non-finite points break the polyline into pieces.
                    for piece in path.split(|q| !finite2(q)) {
                        let pts: Vec<(f64, f64)> = piece.iter().map(|q| ax.p(*q)).collect();
                        svg.polyline(&pts, Stroke::solid(rib_color(i), 3.0));
                    }
                }
                svg.group(&format!(r#"fill="{INK}""#));
                for q in p.skeleton.iter().filter(|q| finite2(q)) {
                    let (x, y) = ax.p(*q);
                    svg.dot(x, y, 2.2);
                }
                svg.end_group();
            }
        }
        frame(&mut svg, &ax, true);
        legend_flow(
            &mut svg,
            legend,
            ax.x + pw / 2.0,
            legend_top,
            pw,
            legend_size,
        );
    }
    svg
}

// ------------------------------------------------------------------ waypoint transfer

/// Waypoint transfer like Fig. 6 of the paper: the target cloud (grey), the true
/// waypoints (black ×), and for each method its mapped waypoints (one marker shape and
/// colour per method) joined to the true waypoint of the same index by a thin line.
/// Equal-aspect axes in mm, legend on the right. 1200 px wide; the height follows the
/// data's aspect ratio.
pub fn waypoint_transfer(
    stem: &Path,
    title: &str,
    cloud: &[[f64; 2]],
    truth: &[[f64; 2]],
    methods: &[WaypointSet],
) -> Result<(), PlotError> {
    write_figure(stem, waypoint_svg(title, cloud, truth, methods))
}

fn waypoint_svg(
    title_text: &str,
    cloud: &[[f64; 2]],
    truth: &[[f64; 2]],
    methods: &[WaypointSet],
) -> Svg {
    let w = f64::from(WAYPOINT_WIDTH);
    let legend_size = 14.0;
    let mut legend = vec![
        LegendEntry {
            swatch: Swatch::Marker {
                marker: Marker::Circle,
                size: 6.0,
                color: CLOUD.into(),
            },
            label: format!("target cloud ({})", count_finite(cloud)),
        },
        LegendEntry {
            swatch: Swatch::Marker {
                marker: Marker::Cross,
                size: 12.0,
                color: INK.into(),
            },
            label: format!("true waypoints ({})", count_finite(truth)),
        },
    ];
    for (i, m) in methods.iter().enumerate() {
        legend.push(LegendEntry {
            swatch: Swatch::Line {
                color: palette(i).into(),
                width: 1.5,
                dash: None,
                marker: Some((METHOD_MARKERS[i % METHOD_MARKERS.len()], 11.0)),
            },
            label: m.label.clone(),
        });
    }
    let lw = legend_box_width(&legend, legend_size, 300.0).max(200.0);
    let (left, top) = (84.0, 64.0);
    let right = w - 20.0 - lw - 24.0;
    let pw = right - left;

    let mut sets: Vec<&[[f64; 2]]> = vec![cloud, truth];
    sets.extend(methods.iter().map(|m| m.points.as_slice()));
    let EqualAspectPanel {
        height: ph,
        xlim,
        ylim,
        step,
    } = equal_aspect_panel(sets, pw, (360.0, 640.0), 10.0, 60.0);
    let h = (top + ph + 66.0).ceil();

    let mut svg = Svg::new(WAYPOINT_WIDTH, h as u32);
    svg.comment("ribreg waypoint transfer");
    title(&mut svg, title_text);
    let ax = Axes {
        x: left,
        y: top,
        w: pw,
        h: ph,
        xlim,
        ylim,
    };
    let style = AxisStyle {
        xstep: Some(step),
        ystep: step,
        x_tick_labels: true,
        y_tick_labels: true,
        x_label: Some("x (mm)"),
        y_label: Some("y (mm)"),
        tick_size: 13.0,
        label_size: 16.0,
    };
    grid_and_ticks(&mut svg, &ax, &style);
    draw_cloud(&mut svg, &ax, cloud, 1.6);

    for (i, m) in methods.iter().enumerate() {
        let st = Stroke {
            color: palette(i),
            width: 1.5,
            dash: None,
            opacity: 0.85,
        };
        for (t, q) in truth.iter().zip(&m.points) {
            if finite2(t) && finite2(q) {
                let (x1, y1) = ax.p(*t);
                let (x2, y2) = ax.p(*q);
                svg.line(x1, y1, x2, y2, st);
            }
        }
    }
    for (i, m) in methods.iter().enumerate() {
        let marker = METHOD_MARKERS[i % METHOD_MARKERS.len()];
        for q in m.points.iter().filter(|q| finite2(q)) {
            let (x, y) = ax.p(*q);
            svg.marker(marker, x, y, 11.0, palette(i));
        }
    }
    for t in truth.iter().filter(|q| finite2(q)) {
        let (x, y) = ax.p(*t);
        svg.marker(Marker::Cross, x, y, 12.0, INK);
    }
    frame(&mut svg, &ax, true);

    let lx = right + 24.0;
    legend_box(&mut svg, &legend, lx, top, lw, legend_size);
    let note_y = top + legend.len() as f64 * legend_size * 1.9 + 12.0 + 20.0;
    let note = Text {
        color: "#555555",
        ..Text::new(12.5, Anchor::Start)
    };
    svg.text(lx + 2.0, note_y, "Lines join each true waypoint", note);
    svg.text(lx + 2.0, note_y + 18.0, "to its mapped position.", note);
    svg
}
