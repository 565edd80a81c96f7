//! `ribreg template` end to end, as a user with a CT segmentation goes: the phantom's CT
//! as a TotalSegmentator labelmap and as Slicer STL parts, with the plan as Slicer
//! markups → `template` → `register`, against the labelled-PLY path of the same phantom.

mod common;
use common::{ribreg, s, stdout};
use std::path::Path;

/// Mean distance between the waypoints of two CSV files (`x,y,z` first).
fn mean_error(a: &Path, b: &Path) -> f64 {
    let read = |p: &Path| -> Vec<[f64; 3]> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .skip(1)
            .filter(|l| !l.trim().is_empty())
            .map(|l| {
                let v: Vec<f64> = l.split(',').take(3).map(|t| t.parse().unwrap()).collect();
                [v[0], v[1], v[2]]
            })
            .collect()
    };
    let (a, b) = (read(a), read(b));
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(&b)
        .map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>().sqrt())
        .sum::<f64>()
        / a.len() as f64
}

/// `ribreg phantom --seed SEED` into `dir` (with `--ct`: its CT as a segmentation too).
fn phantom(dir: &Path, seed: &str, ct: bool) {
    let mut args = vec!["-q", "phantom", "--seed", seed, "--out-dir", s(dir)];
    if ct {
        args.push("--ct");
    }
    stdout(&ribreg(&args));
}

fn register(dir: &Path, template: &Path, waypoints: &Path, tag: &str) -> f64 {
    let out_wp = dir.join(format!("{tag}_waypoints.csv"));
    stdout(&ribreg(&[
        "-q",
        "register",
        "--template",
        s(template),
        "--target",
        s(&dir.join("target.ply")),
        "--waypoints",
        s(waypoints),
        "--out",
        s(&dir.join(format!("{tag}_out.ply"))),
        "--out-waypoints",
        s(&out_wp),
    ]));
    mean_error(&out_wp, &dir.join("true_waypoints.csv"))
}

/// The registration's own spread from one template sampling to another is about a
/// millimetre per pair (the same phantom, sampled as a labelmap, as meshes or as the
/// phantom's Poisson-disc cloud), so the paths are compared by their mean over pairs.
#[test]
fn labelmap_and_parts_register_as_well_as_the_labelled_cloud() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut sums = [0.0f64; 3];
    let seeds = ["0", "1", "2", "3", "4", "5"];
    for seed in seeds {
        phantom(d, seed, true);
        let reference = register(d, &d.join("template.ply"), &d.join("waypoints.csv"), "ply");
        let plan = d.join("ct/plan.mrk.json");
        let out = stdout(&ribreg(&[
            "-q",
            "template",
            "--labelmap",
            s(&d.join("ct/labelmap.nii.gz")),
            "--out",
            s(&d.join("from_labelmap.ply")),
        ]));
        assert!(out.contains("rib 5"), "{out}");
        let labelmap = register(d, &d.join("from_labelmap.ply"), &plan, "labelmap");
        let mut args = vec!["-q".to_owned(), "template".to_owned()];
        for (label, file) in [
            ("sternum", "sternum"),
            ("2", "rib2"),
            ("3", "rib3"),
            ("4", "rib4"),
            ("5", "rib5"),
        ] {
            args.push("--part".into());
            args.push(format!(
                "{label}={}",
                s(&d.join(format!("ct/parts/{file}.stl")))
            ));
        }
        args.push("--out".into());
        args.push(s(&d.join("from_parts.ply")).into());
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        stdout(&ribreg(&refs));
        let parts = register(d, &d.join("from_parts.ply"), &plan, "parts");
        eprintln!(
            "seed {seed}: waypoint error labelled PLY {reference:.2} mm, labelmap {labelmap:.2}, parts {parts:.2}"
        );
        for (sum, e) in sums.iter_mut().zip([reference, labelmap, parts]) {
            *sum += e / seeds.len() as f64;
        }
    }
    let [reference, labelmap, parts] = sums;
    eprintln!("mean: labelled PLY {reference:.2} mm, labelmap {labelmap:.2}, parts {parts:.2}");
    assert!(
        (labelmap - reference).abs() <= 0.5,
        "labelmap {labelmap:.2} vs {reference:.2} mm"
    );
    assert!(
        (parts - reference).abs() <= 0.5,
        "parts {parts:.2} vs {reference:.2} mm"
    );
}

#[test]
fn a_prepared_template_registers_bit_for_bit_like_its_cloud() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    phantom(d, "5", false);
    stdout(&ribreg(&[
        "-q",
        "template",
        "--cloud",
        s(&d.join("template.ply")),
        "--out",
        s(&d.join("t.ply")),
        "--prepared",
        s(&d.join("prepared.ply")),
    ]));
    let wp = d.join("waypoints.csv");
    register(d, &d.join("t.ply"), &wp, "cloud");
    register(d, &d.join("prepared.ply"), &wp, "prepared");
    for f in ["_out.ply", "_waypoints.csv"] {
        let a = std::fs::read(d.join(format!("cloud{f}"))).unwrap();
        let b = std::fs::read(d.join(format!("prepared{f}"))).unwrap();
        assert!(a == b, "{f} differs");
    }
    // An output that is an input or the other output is refused before anything is read.
    for (out, prepared) in [("template.ply", "p2.ply"), ("t2.ply", "t2.ply")] {
        let o = ribreg(&[
            "template",
            "--cloud",
            s(&d.join("template.ply")),
            "--out",
            s(&d.join(out)),
            "--prepared",
            s(&d.join(prepared)),
        ]);
        assert_eq!(o.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&o.stderr).contains("used twice"));
    }
    assert!(!d.join("p2.ply").exists() && !d.join("t2.ply").exists());
    // The paper's method cannot take a prepared template.
    let o = ribreg(&[
        "register",
        "--method",
        "paper",
        "--template",
        s(&d.join("prepared.ply")),
        "--target",
        s(&d.join("target.ply")),
        "--out",
        s(&d.join("x.ply")),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("prepared"));
}

/// The phantom template's labelmap, changed by `edit`, written to `path`.
fn labelmap_with(path: &Path, edit: impl Fn(&mut ribreg_sim::io::volume::LabelVolume)) {
    let mut v = ribreg_sim::phantom::ct::labelmap(&ribreg_sim::phantom::SubjectParams::template());
    edit(&mut v);
    ribreg_sim::io::volume::write_nifti(path, &v).unwrap();
}

fn refused(args: &[&str], out: &Path, expect: &str) {
    let o = ribreg(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains(expect), "expected \"{expect}\" in: {err}");
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    assert!(!out.exists(), "{} left behind", out.display());
}

#[test]
fn bad_labelmaps_are_refused_with_one_clear_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("t.ply");
    let nii = d.join("seg.nii.gz");
    let template = |extra: &[&str]| {
        let mut a = vec!["-q", "template", "--labelmap"];
        a.push(s(&nii));
        a.extend_from_slice(extra);
        a.push("--out");
        a.push(s(&out));
        a.into_iter().map(str::to_owned).collect::<Vec<String>>()
    };
    let run = |args: Vec<String>, expect: &str| {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(&refs, &out, expect);
    };
    // Rib 5's bone missing on the right: its cartilage touches no rib.
    labelmap_with(&nii, |v| {
        v.labels
            .iter_mut()
            .filter(|l| **l == 108)
            .for_each(|l| *l = 0)
    });
    run(template(&[]), "rib 5 not found on the right");
    // An empty mask.
    labelmap_with(&nii, |v| v.labels.iter_mut().for_each(|l| *l = 0));
    run(template(&[]), "no sternum voxels");
    // Wrong ids in a name map.
    labelmap_with(&nii, |_| {});
    let map = d.join("ids.json");
    std::fs::write(&map, r#"{"sternum": 1, "costal_cartilages": 2, "rib_left_2": 3, "rib_left_3": 4, "rib_left_4": 5, "rib_left_5": 6, "rib_right_2": 7, "rib_right_3": 8, "rib_right_4": 9, "rib_right_5": 10}"#).unwrap();
    run(template(&["--label-map", s(&map)]), "no sternum voxels");
    std::fs::write(&map, r#"{"sternum": 116, "heart": 51}"#).unwrap();
    run(
        template(&["--label-map", s(&map)]),
        "\"heart\" is not a class",
    );
    // Not a volume at all.
    std::fs::write(&nii, b"not gzip").unwrap();
    let o = ribreg(&template(&[]).iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(o.status.code(), Some(2));
    assert!(!out.exists());
}

#[test]
fn an_off_by_one_rib_numbering_is_reported_and_overridden() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (right, shifted) = (d.join("right.nii.gz"), d.join("shifted.nii.gz"));
    labelmap_with(&right, |_| {});
    // Every rib one number too high, as TotalSegmentator does on some scans.
    labelmap_with(&shifted, |v| {
        v.labels
            .iter_mut()
            .filter(|l| (92..=114).contains(*l) && **l != 103)
            .for_each(|l| *l += 1)
    });
    let make = |nii: &Path, out: &Path, extra: &[&str]| {
        let mut a = vec!["template", "--labelmap", s(nii), "--out", s(out)];
        a.extend_from_slice(extra);
        let o = ribreg(&a);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        err
    };
    let log = make(&right, &d.join("a.ply"), &[]);
    assert!(
        log.contains("rib 2 = the file's rib 2 (ids 93/105)"),
        "{log}"
    );
    let log = make(&shifted, &d.join("b.ply"), &["--rib2", "3"]);
    assert!(
        log.contains("rib 2 = the file's rib 3 (ids 94/106)"),
        "{log}"
    );
    assert_eq!(
        std::fs::read(d.join("a.ply")).unwrap(),
        std::fs::read(d.join("b.ply")).unwrap()
    );
}

#[test]
fn an_unlabelled_cloud_is_labelled_by_the_rule_or_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    phantom(d, "2", false);
    let truth = ribreg_sim::io::read_ply(&d.join("template.ply")).unwrap();
    // As Open3D would hand it over: an XYZ file, no labels.
    let xyz: String = truth
        .points
        .iter()
        .map(|p| format!("{} {} {}\n", p[0], p[1], p[2]))
        .collect();
    std::fs::write(d.join("t.xyz"), xyz).unwrap();
    let log = ribreg(&[
        "template",
        "--cloud",
        s(&d.join("t.xyz")),
        "--out",
        s(&d.join("t.ply")),
    ]);
    assert!(
        log.status.success(),
        "{}",
        String::from_utf8_lossy(&log.stderr)
    );
    assert!(String::from_utf8_lossy(&log.stderr).contains("labels found automatically"));
    let got = ribreg_sim::io::read_ply(&d.join("t.ply")).unwrap();
    let (a, b) = (truth.labels.unwrap(), got.labels.unwrap());
    let agree = a.iter().zip(&b).filter(|(x, y)| x == y).count() as f64 / a.len() as f64;
    assert!(agree >= 0.99, "{agree}");
    // Without rib 5's left cartilage the rule refuses instead of guessing.
    let xyz: String = truth
        .points
        .iter()
        .zip(&a)
        .filter(|(p, l)| !(**l == 5 && p[0] > 0.0))
        .map(|(p, _)| format!("{} {} {}\n", p[0], p[1], p[2]))
        .collect();
    std::fs::write(d.join("u.xyz"), xyz).unwrap();
    refused(
        &[
            "template",
            "--cloud",
            s(&d.join("u.xyz")),
            "--out",
            s(&d.join("u.ply")),
        ],
        &d.join("u.ply"),
        "cannot label it automatically",
    );
}
