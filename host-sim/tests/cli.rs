//! End-to-end tests of the `ribreg` binary: the CLI contract of SPEC.md, and bad input
//! giving one clear line on stderr, a non-zero exit and no output file.

mod common;
use common::{ribreg, s};
use ribreg_sim::io::{self, Cloud, PlyFormat};
use ribreg_sim::phantom::{PhantomConfig, PhantomPair};
use std::path::{Path, PathBuf};
use std::process::Output;

/// A phantom pair written as template.ply (labelled), target.ply and waypoints.csv.
fn inputs(dir: &Path) -> (PathBuf, PathBuf, PathBuf, PhantomPair) {
    let pair = PhantomPair::generate(&PhantomConfig {
        seed: 3,
        ..PhantomConfig::default()
    });
    let t = dir.join("template.ply");
    let u = dir.join("target.ply");
    let w = dir.join("waypoints.csv");
    let tc = Cloud {
        points: pair.template.points.clone(),
        labels: Some(pair.template.labels.clone()),
    };
    io::write_ply(&t, &tc, PlyFormat::Ascii).unwrap();
    io::write_ply(
        &u,
        &Cloud {
            points: pair.target.clone(),
            labels: None,
        },
        PlyFormat::BinaryLittleEndian,
    )
    .unwrap();
    io::write_points_csv(&w, &pair.template_waypoints).unwrap();
    (t, u, w, pair)
}

/// Asserts a failed run: exit code 2, exactly one stderr line starting with
/// "ribreg: error:" and containing `needle`, and none of `outputs` exists.
fn assert_refused(out: &Output, needle: &str, outputs: &[&Path]) {
    let err = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("ribreg: error:"))
        .collect();
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    assert_eq!(lines.len(), 1, "stderr: {err}");
    assert!(
        lines[0].contains(needle),
        "expected {needle:?} in {:?}",
        lines[0]
    );
    for p in outputs {
        assert!(!p.exists(), "{} was left behind", p.display());
    }
}

/// The outputs are written side by side (their `fsync`s overlap): when one cannot be
/// written, the others are removed again, whichever finished first.
#[test]
fn register_leaves_no_output_when_one_cannot_be_written() {
    let dir = tempfile::tempdir().unwrap();
    let (t, u, w, _) = inputs(dir.path());
    let (out, ow) = (dir.path().join("m.ply"), dir.path().join("m.csv"));
    for (ply, csv, report) in [
        (out.clone(), ow.clone(), dir.path().join("no-dir/r.json")),
        (
            dir.path().join("no-dir/m.ply"),
            ow.clone(),
            dir.path().join("r.json"),
        ),
    ] {
        let o = ribreg(&[
            "register",
            "--template",
            s(&t),
            "--target",
            s(&u),
            "--waypoints",
            s(&w),
            "--out",
            s(&ply),
            "--out-waypoints",
            s(&csv),
            "--report",
            s(&report),
            "--quiet",
        ]);
        assert_refused(&o, "no-dir", &[&ply, &csv, &report]);
    }
}

#[test]
fn register_writes_every_output_in_template_order() {
    let dir = tempfile::tempdir().unwrap();
    let (t, u, w, pair) = inputs(dir.path());
    let (out, ow, rep) = (
        dir.path().join("m.ply"),
        dir.path().join("m.csv"),
        dir.path().join("r.json"),
    );
    let o = ribreg(&[
        "register",
        "--template",
        s(&t),
        "--target",
        s(&u),
        "--waypoints",
        s(&w),
        "--out",
        s(&out),
        "--out-waypoints",
        s(&ow),
        "--report",
        s(&rep),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let reg = io::read_ply(&out).unwrap();
    assert_eq!(reg.points.len(), pair.template.points.len());
    assert_eq!(reg.labels.as_deref(), Some(&pair.template.labels[..]));
    // Same order: registered point i is where template point i really is on the patient.
    let truth = pair.true_positions();
    let mean: f64 = reg
        .points
        .iter()
        .zip(&truth)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .sum::<f64>()
        / truth.len() as f64;
    assert!(mean < 6.0, "dense error {mean} mm");
    let wps = io::read_points_csv(&ow).unwrap();
    assert_eq!(wps.len(), 10);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    assert_eq!(
        report["skeleton"]["template"].as_array().map(Vec::len),
        Some(30)
    );
    assert_eq!(
        report["skeleton"]["target"].as_array().map(Vec::len),
        Some(30)
    );
    assert!(report["metrics"]["hausdorff_mm"].as_f64().unwrap() > 0.0);
    assert!(report["timings_ms"]["register"].as_f64().is_some());
    // How clearly the pose was found: within the accepted bounds.
    let pose = &report["pose_hypotheses"];
    let residual = pose["residual_mm"].as_f64().unwrap();
    assert!(residual > 0.0 && residual <= pose["max_residual_mm"].as_f64().unwrap());
    // Either the sweep supports the whole template closely, or no distinct pose comes
    // near (the coverage, in "coverage", is then checked too).
    let support = pose["support_mm"].as_f64().unwrap();
    let supported = support > 0.0 && support <= pose["max_support_mm"].as_f64().unwrap();
    let clear = pose["margin"]
        .as_f64()
        .is_none_or(|m| m >= pose["min_margin"].as_f64().unwrap());
    assert!(supported || clear, "{pose}");
    assert!(pose["hypotheses"].as_u64().unwrap() >= 1);
    // The rib coverage beside its bounds: an accepted sweep is within every one.
    let cov = &report["coverage"];
    let means = &cov["means"];
    let at = |v: &serde_json::Value| v.as_f64().unwrap();
    assert!(at(&means["all"]) >= at(&cov["min_mean_share"]), "{cov}");
    assert!(
        at(&means["ribs_4_5"]) >= at(&cov["min_lower_share"]),
        "{cov}"
    );
    let (r, l) = (at(&means["right"]), at(&means["left"]));
    assert!((at(&means["all"]) - 0.5 * (r + l)).abs() < 1e-6, "{cov}");
    let min_ratio = if r.min(l) < at(&cov["short_side_share"]) {
        at(&cov["min_side_ratio"])
    } else {
        at(&cov["min_long_side_ratio"])
    };
    assert!(r.min(l) >= min_ratio * r.max(l), "{cov}");
}

#[test]
fn missing_file() {
    let dir = tempfile::tempdir().unwrap();
    let (_, u, _, _) = inputs(dir.path());
    let out = dir.path().join("m.ply");
    let o = ribreg(&[
        "register",
        "--template",
        "/nonexistent/ct.ply",
        "--target",
        s(&u),
        "--out",
        s(&out),
    ]);
    assert_refused(&o, "/nonexistent/ct.ply", &[&out]);
}

#[test]
fn malformed_and_truncated_ply() {
    let dir = tempfile::tempdir().unwrap();
    let (t, u, _, _) = inputs(dir.path());
    let out = dir.path().join("m.ply");
    let bad = dir.path().join("bad.ply");
    std::fs::write(
        &bad,
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n3\n",
    )
    .unwrap();
    assert_refused(
        &ribreg(&[
            "register",
            "--template",
            s(&t),
            "--target",
            s(&bad),
            "--out",
            s(&out),
        ]),
        "bad.ply",
        &[&out],
    );
    let bytes = std::fs::read(&u).unwrap();
    let cut = dir.path().join("cut.ply");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    assert_refused(
        &ribreg(&[
            "register",
            "--template",
            s(&t),
            "--target",
            s(&cut),
            "--out",
            s(&out),
        ]),
        "cut.ply",
        &[&out],
    );
}

fn write_points(path: &Path, pts: &[[f64; 3]]) {
    let body: String = pts
        .iter()
        .map(|p| format!("{} {} {}\n", p[0], p[1], p[2]))
        .collect();
    let text = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nend_header\n{body}",
        pts.len()
    );
    std::fs::write(path, text).unwrap();
}

#[test]
fn nan_huge_and_too_few_points() {
    let dir = tempfile::tempdir().unwrap();
    let (t, u, _, pair) = inputs(dir.path());
    let out = dir.path().join("m.ply");
    let run = |target: &Path| {
        ribreg(&[
            "register",
            "--template",
            s(&t),
            "--target",
            s(target),
            "--out",
            s(&out),
        ])
    };
    let p = dir.path().join("nan.ply");
    let mut pts = pair.target.clone();
    pts[7][1] = f64::NAN;
    write_points(&p, &pts);
    assert_refused(&run(&p), "not finite", &[&out]);
    let mut pts = pair.target.clone();
    pts[11][2] = 1e9;
    write_points(&p, &pts);
    assert_refused(&run(&p), "point 11", &[&out]);
    write_points(&p, &pair.target[..1]);
    assert_refused(&run(&p), "target cloud has 1 points, at least 100", &[&out]);
    write_points(&p, &vec![[1.0, 2.0, 3.0]; 500]);
    assert_refused(&run(&p), "degenerate", &[&out]);
    // The good target still works with the same template.
    assert!(run(&u).status.success());
}

#[test]
fn wrong_rib_count_in_the_template() {
    let dir = tempfile::tempdir().unwrap();
    let (_, u, _, pair) = inputs(dir.path());
    let out = dir.path().join("m.ply");
    // Drop rib 5 (both sides): three ribs instead of four.
    let keep: Vec<usize> = (0..pair.template.points.len())
        .filter(|&i| pair.template.labels[i] != 5)
        .collect();
    let t3 = dir.path().join("three_ribs.ply");
    let cloud = Cloud {
        points: keep.iter().map(|&i| pair.template.points[i]).collect(),
        labels: Some(keep.iter().map(|&i| pair.template.labels[i]).collect()),
    };
    io::write_ply(&t3, &cloud, PlyFormat::Ascii).unwrap();
    assert_refused(
        &ribreg(&[
            "register",
            "--template",
            s(&t3),
            "--target",
            s(&u),
            "--out",
            s(&out),
        ]),
        "rib 5",
        &[&out],
    );
    // A label that is no rib number.
    let mut bad = cloud.clone();
    bad.labels.as_mut().unwrap()[0] = 9;
    io::write_ply(&t3, &bad, PlyFormat::Ascii).unwrap();
    assert_refused(
        &ribreg(&[
            "register",
            "--template",
            s(&t3),
            "--target",
            s(&u),
            "--out",
            s(&out),
        ]),
        "label 9",
        &[&out],
    );
}

#[test]
fn improved_method_needs_labels_and_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (t, u, w, pair) = inputs(dir.path());
    let out = dir.path().join("m.ply");
    let unl = dir.path().join("unlabelled.ply");
    io::write_ply(
        &unl,
        &Cloud {
            points: pair.template.points.clone(),
            labels: None,
        },
        PlyFormat::Ascii,
    )
    .unwrap();
    assert_refused(
        &ribreg(&[
            "register",
            "--template",
            s(&unl),
            "--target",
            s(&u),
            "--out",
            s(&out),
        ]),
        "labelled",
        &[&out],
    );
    let ow = dir.path().join("m.csv");
    assert_refused(
        &ribreg(&[
            "register",
            "--template",
            s(&t),
            "--target",
            s(&u),
            "--out",
            s(&out),
            "--out-waypoints",
            s(&ow),
        ]),
        "--out-waypoints needs --waypoints",
        &[&out, &ow],
    );
    // An output in a missing folder: nothing else is left behind either.
    let deep = dir.path().join("missing/dir/m.csv");
    assert_refused(
        &ribreg(&[
            "register",
            "--template",
            s(&t),
            "--target",
            s(&u),
            "--waypoints",
            s(&w),
            "--out",
            s(&out),
            "--out-waypoints",
            s(&deep),
        ]),
        "m.csv",
        &[&out, &deep],
    );
}

#[test]
fn paper_method_runs_on_an_unlabelled_template() {
    let dir = tempfile::tempdir().unwrap();
    let (_, u, _, pair) = inputs(dir.path());
    let unl = dir.path().join("unlabelled.ply");
    io::write_ply(
        &unl,
        &Cloud {
            points: pair.template.points.clone(),
            labels: None,
        },
        PlyFormat::Ascii,
    )
    .unwrap();
    let out = dir.path().join("m.ply");
    let o = ribreg(&[
        "register",
        "--method",
        "paper",
        "--template",
        s(&unl),
        "--target",
        s(&u),
        "--out",
        s(&out),
    ]);
    // The paper's endpoint rule may or may not find 8 endpoints on this pair; either way
    // the run ends cleanly: success with an output, or one error line and no output.
    if o.status.success() {
        assert_eq!(
            io::read_ply(&out).unwrap().points.len(),
            pair.template.points.len()
        );
    } else {
        assert_refused(&o, "", &[&out]);
    }
}

#[test]
fn phantom_then_sample_its_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let ph = dir.path().join("ph");
    assert!(ribreg(&["phantom", "--seed", "2", "--out-dir", s(&ph)])
        .status
        .success());
    for f in [
        "template.ply",
        "template_mesh.ply",
        "template_mesh.obj",
        "target.ply",
        "waypoints.csv",
        "true_waypoints.csv",
        "params.json",
    ] {
        assert!(ph.join(f).exists(), "{f}");
    }
    let out = dir.path().join("sampled.ply");
    let o = ribreg(&[
        "sample",
        s(&ph.join("template_mesh.obj")),
        "--spacing",
        "3",
        "-o",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cloud = io::read_ply(&out).unwrap();
    // The same surface as the phantom's own 2.5 mm sample: about (2.5 / 3)² as many points.
    let direct = io::read_ply(&ph.join("template.ply")).unwrap().points.len() as f64;
    let ratio = cloud.points.len() as f64 / direct;
    assert!(
        (0.55..0.85).contains(&ratio),
        "{} sampled vs {direct}",
        cloud.points.len()
    );
    let bad = dir.path().join("bad.ply");
    assert_refused(
        &ribreg(&[
            "sample",
            s(&ph.join("template_mesh.obj")),
            "--spacing=-1",
            "-o",
            s(&bad),
        ]),
        "spacing",
        &[&bad],
    );
}
