use super::*;
use std::f64::consts::PI;

/// PNG dimensions from the signature and IHDR chunk, checked by hand.
fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert!(bytes.len() > 33, "PNG too short");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |o: usize| u32::from_be_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    (be(16), be(20))
}

/// The `width`/`height` the SVG declares on its root element.
fn svg_size(svg: &str) -> (u32, u32) {
    let attr = |name: &str| -> u32 {
        let key = format!(" {name}=\"");
        let start = svg.find(&key).expect("attribute") + key.len();
        let end = start + svg[start..].find('"').expect("closing quote");
        svg[start..end].parse().expect("integer size")
    };
    (attr("width"), attr("height"))
}

/// Reads both outputs of `stem`, checks they are well formed and agree on the size,
/// that the directory holds nothing else, and returns (svg text, png size).
fn check_outputs(dir: &Path, stem: &Path) -> (String, (u32, u32)) {
    let svg = std::fs::read_to_string(with_suffix(stem, "svg")).expect("svg written");
    assert!(
        svg.starts_with("<svg") || svg.starts_with("<?xml"),
        "svg start"
    );
    assert!(svg.trim_end().ends_with("</svg>"), "svg end");
    assert!(!svg.contains("NaN"), "non-finite number in SVG");
    usvg::Tree::from_str(&svg, &usvg::Options::default()).expect("SVG parses");
    let png = std::fs::read(with_suffix(stem, "png")).expect("png written");
    let size = png_size(&png);
    let pixmap = tiny_skia::Pixmap::decode_png(&png).expect("PNG decodes");
    assert_eq!((pixmap.width(), pixmap.height()), size);
    assert_eq!(svg_size(&svg), size, "PNG and SVG sizes agree");
    // The figure is opaque (white background) and not blank.
    assert!(pixmap.pixels().iter().all(|p| p.alpha() == 255));
    assert!(pixmap.pixels().iter().any(|p| p.red() < 100));
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let base = stem
        .file_name()
        .expect("stem name")
        .to_string_lossy()
        .into_owned();
    assert_eq!(names, vec![format!("{base}.png"), format!("{base}.svg")]);
    (svg, size)
}

fn errors(seed: u64, n: usize, scale: f64) -> Vec<f64> {
    (0..n)
        .map(|k| {
            let u = unit_hash(seed * 1000 + k as u64).max(1e-12);
            let v = unit_hash(seed * 1000 + k as u64 + 500_000);
            // Rayleigh-like positive errors with a long tail.
            scale * (-2.0 * u.ln()).sqrt() * (1.0 + 0.3 * v)
        })
        .collect()
}

fn sample_series() -> Vec<Series> {
    vec![
        Series {
            label: "Skeleton graph (ours)".into(),
            values: errors(1, 60, 1.6),
        },
        Series {
            label: "CPD non-rigid".into(),
            values: errors(2, 60, 2.7),
        },
        Series {
            label: "ICP rigid".into(),
            values: errors(3, 60, 4.4),
        },
        Series {
            label: "Mean shape".into(),
            values: errors(4, 60, 6.0),
        },
    ]
}

/// A rib-cage-like cloud on the coronal plane: four arcs (one per rib), one side.
fn sample_ribs() -> Vec<Vec<[f64; 2]>> {
    (0..4)
        .map(|r| {
            let y0 = 40.0 - 28.0 * r as f64;
            (0..30)
                .map(|k| {
                    let t = k as f64 / 29.0;
                    [8.0 + 110.0 * t, y0 - 25.0 * t * t + 6.0 * (PI * t).sin()]
                })
                .collect()
        })
        .collect()
}

fn sample_cloud(ribs: &[Vec<[f64; 2]>], per_rib: usize) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    for (r, path) in ribs.iter().enumerate() {
        for k in 0..per_rib {
            let s = unit_hash((r * 100_000 + k) as u64) * (path.len() - 1) as f64;
            let i = (s.floor() as usize).min(path.len() - 2);
            let f = s - i as f64;
            let (a, b) = (path[i], path[i + 1]);
            let dy = (unit_hash((r * 100_000 + k) as u64 + 7) - 0.5) * 9.0;
            let dx = (unit_hash((r * 100_000 + k) as u64 + 13) - 0.5) * 3.0;
            out.push([a[0] + f * (b[0] - a[0]) + dx, a[1] + f * (b[1] - a[1]) + dy]);
        }
    }
    out
}

fn sample_panels() -> SkeletonPanels {
    let ribs = sample_ribs();
    let cloud = sample_cloud(&ribs, 900);
    let som1: Vec<[f64; 2]> = cloud.iter().step_by(9).copied().collect();
    let key_points: Vec<[f64; 2]> = ribs
        .iter()
        .flat_map(|p| p.iter().step_by(3).copied().collect::<Vec<_>>())
        .collect();
    let per = key_points.len() / 4;
    let mut edges = Vec::new();
    for r in 0..4 {
        for k in 0..per - 1 {
            edges.push((r * per + k, r * per + k + 1));
        }
        if r > 0 {
            edges.push(((r - 1) * per, r * per));
        }
    }
    let endpoints = vec![per - 1, 2 * per - 1, 3 * per - 1, 4 * per - 1, 3 * per];
    let skeleton = ribs
        .iter()
        .flat_map(|p| p.iter().step_by(2).copied())
        .collect();
    SkeletonPanels {
        cloud,
        som1,
        key_points,
        edges,
        endpoints,
        rib_paths: ribs,
        skeleton,
    }
}

fn sample_waypoints() -> (Vec<[f64; 2]>, Vec<[f64; 2]>, Vec<WaypointSet>) {
    let ribs = sample_ribs();
    let cloud = sample_cloud(&ribs, 700);
    let truth: Vec<[f64; 2]> = (0..3)
        .flat_map(|gap| {
            let (a, b) = (&ribs[gap], &ribs[gap + 1]);
            [6usize, 14, 22]
                .into_iter()
                .map(move |k| [(a[k][0] + b[k][0]) / 2.0, (a[k][1] + b[k][1]) / 2.0])
        })
        .collect();
    let offset = |m: u64, s: f64| -> Vec<[f64; 2]> {
        truth
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let a = unit_hash(m * 77 + i as u64) * 2.0 * PI;
                let r = s * (0.4 + unit_hash(m * 91 + i as u64));
                [t[0] + r * a.cos(), t[1] + r * a.sin()]
            })
            .collect()
    };
    let methods = vec![
        WaypointSet {
            label: "Skeleton graph (ours)".into(),
            points: offset(1, 2.0),
        },
        WaypointSet {
            label: "CPD non-rigid".into(),
            points: offset(2, 4.0),
        },
        WaypointSet {
            label: "ICP rigid".into(),
            points: offset(3, 7.0),
        },
    ];
    (cloud, truth, methods)
}

#[test]
fn plot_error_distributions_writes_svg_and_png() {
    let dir = tempfile::tempdir().expect("tempdir");
    let stem = dir.path().join("errors");
    error_distributions(
        &stem,
        "Waypoint error by method",
        "error (mm)",
        &sample_series(),
        Some((5.0, "5 mm clinical tolerance")),
    )
    .expect("plot");
    let (svg, size) = check_outputs(dir.path(), &stem);
    assert_eq!(size, (ERROR_PLOT_WIDTH, ERROR_PLOT_HEIGHT));
    assert!(svg.contains("5 mm clinical tolerance") && svg.contains("Skeleton graph (ours)"));
    assert!(svg.contains("mean "), "per-method mean printed");
}

#[test]
fn plot_skeleton_figure_writes_svg_and_png() {
    let dir = tempfile::tempdir().expect("tempdir");
    let stem = dir.path().join("skeleton");
    skeleton_figure(&stem, "Skeleton extraction", &sample_panels()).expect("plot");
    let (svg, (w, h)) = check_outputs(dir.path(), &stem);
    assert_eq!(w, SKELETON_WIDTH);
    assert!((400..=900).contains(&h), "height {h}");
    for s in ["(a)", "(b)", "(c)", "(d)", "rib path 4", "endpoints (5)"] {
        assert!(svg.contains(s), "missing {s}");
    }
}

#[test]
fn plot_waypoint_transfer_writes_svg_and_png() {
    let dir = tempfile::tempdir().expect("tempdir");
    let stem = dir.path().join("waypoints");
    let (cloud, truth, methods) = sample_waypoints();
    waypoint_transfer(&stem, "Waypoint transfer", &cloud, &truth, &methods).expect("plot");
    let (svg, (w, h)) = check_outputs(dir.path(), &stem);
    assert_eq!(w, WAYPOINT_WIDTH);
    assert!((400..=900).contains(&h), "height {h}");
    assert!(svg.contains("ICP rigid") && svg.contains("true waypoints (9)"));
}

#[test]
fn plot_empty_inputs_do_not_panic() {
    let dir = tempfile::tempdir().expect("tempdir");
    error_distributions(&dir.path().join("e0"), "", "", &[], None).expect("no series");
    let empty = [Series {
        label: "empty".into(),
        values: vec![],
    }];
    error_distributions(&dir.path().join("e1"), "t", "mm", &empty, Some((5.0, ""))).expect("empty");
    skeleton_figure(&dir.path().join("s0"), "", &SkeletonPanels::default()).expect("skeleton");
    waypoint_transfer(&dir.path().join("w0"), "", &[], &[], &[]).expect("waypoints");
    let m = [WaypointSet {
        label: String::new(),
        points: vec![],
    }];
    waypoint_transfer(&dir.path().join("w1"), "t", &[], &[[1.0, 2.0]], &m).expect("one point");
    assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 10);
}

#[test]
fn plot_nan_and_degenerate_inputs_do_not_panic() {
    let dir = tempfile::tempdir().expect("tempdir");
    let nan = f64::NAN;
    let inf = f64::INFINITY;
    let series = [
        Series {
            label: "nan".into(),
            values: vec![nan, nan],
        },
        Series {
            label: "mixed".into(),
            values: vec![1.0, nan, inf, -inf, 2.0, 3.0],
        },
        Series {
            label: "constant".into(),
            values: vec![4.0; 5],
        },
        Series {
            label: "huge".into(),
            values: vec![1e300, -1e300],
        },
    ];
    error_distributions(
        &dir.path().join("e"),
        "non-finite",
        "mm",
        &series,
        Some((nan, "x")),
    )
    .expect("e");
    let (svg, _) = check_outputs_of(&dir.path().join("e"));
    assert!(svg.contains("no data"));

    let bad = [nan, inf];
    let panels = SkeletonPanels {
        cloud: vec![bad, [0.0, 0.0], [nan, 1.0]],
        som1: vec![[0.0, 0.0]; 3],
        key_points: vec![[0.0, 0.0], bad],
        edges: vec![(0, 1), (0, 7), (usize::MAX, 0)],
        endpoints: vec![0, 1, 99],
        rib_paths: vec![
            vec![[0.0, 0.0], bad, [1.0, 1.0], [2.0, 1.0]],
            vec![],
            vec![bad],
        ],
        skeleton: vec![bad],
    };
    skeleton_figure(&dir.path().join("s"), "non-finite", &panels).expect("s");
    check_outputs_of(&dir.path().join("s"));
    let m = [WaypointSet {
        label: "m".into(),
        points: vec![bad, [1.0, 1.0], [2.0, 2.0]],
    }];
    waypoint_transfer(
        &dir.path().join("w"),
        "non-finite",
        &[bad],
        &[[0.0, 0.0], bad],
        &m,
    )
    .expect("w");
    check_outputs_of(&dir.path().join("w"));
}

/// [`check_outputs`] without the "only these two files" check.
fn check_outputs_of(stem: &Path) -> (String, (u32, u32)) {
    let svg = std::fs::read_to_string(with_suffix(stem, "svg")).expect("svg written");
    assert!(svg.trim_end().ends_with("</svg>") && !svg.contains("NaN"));
    let png = std::fs::read(with_suffix(stem, "png")).expect("png written");
    let size = png_size(&png);
    assert_eq!(svg_size(&svg), size);
    (svg, size)
}

#[test]
fn plot_output_is_deterministic_and_stem_keeps_dots() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (a, b) = (dir.path().join("fig.v1"), dir.path().join("fig.v2"));
    for stem in [&a, &b] {
        skeleton_figure(stem, "same", &sample_panels()).expect("plot");
    }
    for ext in ["svg", "png"] {
        let x = std::fs::read(with_suffix(&a, ext)).expect("a");
        let y = std::fs::read(with_suffix(&b, ext)).expect("b");
        assert!(x == y, "{ext} differs between identical calls");
    }
    assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 4);
}

#[test]
fn plot_io_error_is_typed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let stem = dir.path().join("missing-dir").join("fig");
    let err = error_distributions(&stem, "t", "mm", &sample_series(), None).unwrap_err();
    assert!(matches!(err, PlotError::Io { .. }));
    let msg = err.to_string();
    assert!(
        msg.contains("missing-dir") && msg.contains("fig.svg"),
        "{msg}"
    );
    assert!(std::error::Error::source(&err).is_some());
    assert!(!dir.path().join("missing-dir").exists());
}

#[test]
fn plot_box_stats_match_hand_computation() {
    let s = box_stats(&[1.0, 2.0, 3.0, 4.0, 100.0, f64::NAN]).expect("stats");
    assert_eq!((s.q1, s.median, s.q3), (2.0, 3.0, 4.0));
    assert_eq!(s.mean, 22.0);
    assert_eq!((s.whisker_lo, s.whisker_hi), (1.0, 4.0));
    assert!(box_stats(&[f64::NAN]).is_none());
}

/// Writes the sample figures to `$RIBREG_PLOT_SAMPLES` (default `/tmp/ribreg-plots`) for
/// a look by eye: `cargo test -p ribreg-sim plot_samples -- --ignored`.
#[test]
#[ignore]
fn plot_samples() {
    let dir = std::env::var_os("RIBREG_PLOT_SAMPLES")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/tmp/ribreg-plots"));
    std::fs::create_dir_all(&dir).expect("sample dir");
    error_distributions(
        &dir.join("errors"),
        "Waypoint error by method (simulated, 60 waypoints)",
        "waypoint error (mm)",
        &sample_series(),
        Some((5.0, "5 mm clinical tolerance")),
    )
    .expect("errors");
    skeleton_figure(
        &dir.join("skeleton"),
        "Skeleton extraction (coronal projection)",
        &sample_panels(),
    )
    .expect("skeleton");
    let (cloud, truth, methods) = sample_waypoints();
    waypoint_transfer(
        &dir.join("waypoints"),
        "Waypoint transfer (coronal projection)",
        &cloud,
        &truth,
        &methods,
    )
    .expect("waypoints");

    // Harder cases: many methods with long names and a large sample, a wide two-sided
    // rib cage with a big cloud, and empty inputs.
    let mut many = sample_series();
    many.extend((5..9).map(|k| Series {
        label: format!("Baseline method number {k} with a long name"),
        values: errors(k, if k == 5 { 5000 } else { 25 }, k as f64),
    }));
    error_distributions(
        &dir.join("errors_many"),
        "Eight methods",
        "error (mm)",
        &many,
        Some((5.0, "5 mm")),
    )
    .expect("errors_many");
    let mut wide = sample_panels();
    let mirror = |v: &[[f64; 2]]| -> Vec<[f64; 2]> { v.iter().map(|q| [-q[0], q[1]]).collect() };
    let big: Vec<[f64; 2]> = sample_cloud(&wide.rib_paths, 2500);
    wide.cloud = big.iter().copied().chain(mirror(&big)).collect();
    wide.som1 = wide
        .som1
        .iter()
        .copied()
        .chain(mirror(&wide.som1))
        .collect();
    let ribs: Vec<Vec<[f64; 2]>> = wide.rib_paths.iter().map(|p| mirror(p)).collect();
    wide.rib_paths.extend(ribs);
    skeleton_figure(
        &dir.join("skeleton_wide"),
        "Both sides, 20 000 points",
        &wide,
    )
    .expect("wide");
    waypoint_transfer(
        &dir.join("waypoints_wide"),
        "Both sides",
        &wide.cloud,
        &truth,
        &methods,
    )
    .expect("waypoints_wide");
    error_distributions(
        &dir.join("errors_empty"),
        "Empty",
        "error (mm)",
        &[],
        Some((5.0, "5 mm clinical tolerance")),
    )
    .expect("errors_empty");
    skeleton_figure(
        &dir.join("skeleton_empty"),
        "Empty",
        &SkeletonPanels::default(),
    )
    .expect("empty");
}
