//! Issue 17, real sweeps in: PLUS sequence files with bone masks and PLUS calibrations.
//! The phantom's sweep as a sequence against its CSV logs, fixtures of an independent
//! (Python) writer, bad files, temporal calibration from a sequence, and the CLI.

mod common;
use common::{ribreg, s, stdout};
use std::path::{Path, PathBuf};
use std::process::Output;

use nalgebra::Matrix3;
use ribreg_core::math::geom::Rigid;
use ribreg_core::Vec3;
use ribreg_sim::io::plus::{
    read_plus_transform, Orientation, SequenceError, SequenceErrorKind as K, SequenceReader, Status,
};
use ribreg_sim::phantom::PhantomConfig;
use ribreg_sim::sweep::plus::{
    bone_pixels, calibrate_temporal_sequence, calibration_from_plus, compound_sequence,
    phantom_calibration_frames, phantom_sequence_logs, read_sweep_sequence, write_phantom_sequence,
    Spatial, CALIB_SEQUENCE, DEFAULT_TRANSFORM, PLUS_CONFIG, SWEEP_SEQUENCE,
};
use ribreg_sim::sweep::{self, SweepConfig};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/plus")
        .join(name)
}

/// Asserts exit 2 with one `ribreg: error:` line containing every needle.
fn assert_refused(o: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "stderr: {err}");
    let lines: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("ribreg: error:"))
        .collect();
    assert_eq!(lines.len(), 1, "stderr: {err}");
    for n in needles {
        assert!(lines[0].contains(n), "expected {n:?} in {:?}", lines[0]);
    }
}

fn rigid_of(m: &[[f64; 4]; 4]) -> Rigid {
    Rigid {
        rotation: Matrix3::from_fn(|i, j| m[i][j] as f32),
        translation: Vec3::new(m[0][3] as f32, m[1][3] as f32, m[2][3] as f32),
    }
}

fn matrix_json(v: &serde_json::Value) -> [[f64; 4]; 4] {
    std::array::from_fn(|i| std::array::from_fn(|j| v[i][j].as_f64().unwrap()))
}

/// Equal up to the last bit or two: serde_json's default number parser is not always
/// correctly rounded (the files themselves are read exactly: Rust's `f64::from_str` is).
fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 4.0 * f64::EPSILON * a.abs().max(b.abs()).max(1.0)
}

fn close_matrix(a: &[[f64; 4]; 4], b: &[[f64; 4]; 4]) -> bool {
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .all(|(x, y)| close(*x, *y))
}

/// The files `gen_plus.py` wrote (numpy + zlib, from the PLUS documentation) read as the
/// script says: header, per-frame fields, masks re-oriented to MF (one stored UF, one
/// MN), bone pixels, and every bone pixel placed where PLUS's own
/// `ProbeToTracker · ImageToProbe · (column, row, 0, 1)` puts it.
#[test]
fn python_fixtures_read_as_the_script_wrote_them() {
    let exp: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("expected.json")).unwrap()).unwrap();
    let config = fixture("tiny_config.xml");
    let m = read_plus_transform(&config, "Image", "Probe").unwrap();
    assert!(
        close_matrix(&m, &matrix_json(&exp["image_to_probe"])),
        "{m:?}"
    );
    let mut worst: f64 = 0.0;
    for (name, orientation) in [
        ("tiny_raw.seq.mha", Orientation::Uf),
        ("tiny_compressed.seq.mha", Orientation::Mn),
    ] {
        let e = &exp[name];
        let mut r = SequenceReader::open(&fixture(name), "ProbeToTracker").unwrap();
        let info = r.info().clone();
        assert_eq!(u64::from(info.width), e["width"].as_u64().unwrap());
        assert_eq!(u64::from(info.height), e["height"].as_u64().unwrap());
        assert_eq!(u64::from(info.frames), e["frames"].as_u64().unwrap());
        assert_eq!(info.orientation, orientation);
        assert_eq!(info.compressed, e["compressed"].as_bool().unwrap());
        assert_eq!(
            info.transforms_available,
            vec!["ProbeToTracker", "ReferenceToTracker"]
        );
        let cal = calibration_from_plus(&m, info.width, info.height).unwrap();
        let (sx, sy) = cal.probe.scale();
        assert!((f64::from(sx) - exp["scale_mm_per_px"][0].as_f64().unwrap()).abs() < 1e-6);
        assert!((f64::from(sy) - exp["scale_mm_per_px"][1].as_f64().unwrap()).abs() < 1e-6);
        assert!(
            (f64::from(cal.probe.footprint_mm) - exp["footprint_mm"].as_f64().unwrap()).abs()
                < 1e-5
        );
        let mut px = Vec::new();
        let mut k = 0;
        while let Some(f) = r.next_frame().unwrap() {
            let ef = &e["frame_list"][k];
            assert!(close(f.timestamp, ef["timestamp"].as_f64().unwrap()));
            assert!(close(
                f.unfiltered_timestamp.unwrap(),
                ef["unfiltered_timestamp"].as_f64().unwrap()
            ));
            assert_eq!(f.frame_number, ef["frame_number"].as_i64());
            let status_ok = ef["status"] == "OK";
            assert_eq!(f.status == Status::Ok, status_ok, "{name} frame {k}");
            let mask: Vec<u8> = ef["mask_mf"]
                .as_array()
                .unwrap()
                .iter()
                .flat_map(|row| row.as_array().unwrap().iter())
                .map(|v| v.as_u64().unwrap() as u8)
                .collect();
            assert_eq!(f.mask, &mask[..], "{name} frame {k}: mask (MF)");
            bone_pixels(f.mask, usize::from(info.width), &mut px);
            let expected: Vec<(u16, u16)> = ef["bone_pixels"]
                .as_array()
                .unwrap()
                .iter()
                .map(|p| (p[0].as_u64().unwrap() as u16, p[1].as_u64().unwrap() as u16))
                .collect();
            assert_eq!(px, expected, "{name} frame {k}: bone pixels");
            if status_ok {
                let t = f.transform.unwrap();
                assert!(close_matrix(&t, &matrix_json(&ef["transform"])), "{t:?}");
                let b_t_ee = rigid_of(&t);
                for (i, &(c, r)) in px.iter().enumerate() {
                    let p = cal
                        .pixel_to_base(&b_t_ee, f32::from(c) + 0.5, f32::from(r) + 0.5)
                        .unwrap();
                    let q = &ef["bone_points_tracker"][i];
                    let d = (0..3)
                        .map(|a| (f64::from(p[a]) - q[a].as_f64().unwrap()).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    worst = worst.max(d);
                }
            } else {
                assert_eq!(f.transform, None);
            }
            k += 1;
        }
        assert_eq!(k, e["frames"].as_u64().unwrap() as usize);
    }
    // f32 arithmetic at ~200 mm from the origin: a few 1e-5 mm.
    println!("bone pixels vs PLUS's ImageToTracker: worst {worst:.2e} mm");
    assert!(worst < 1e-3, "{worst}");

    // The compounding path: the INVALID frame skipped and counted.
    let seq = read_sweep_sequence(
        &fixture("tiny_raw.seq.mha"),
        DEFAULT_TRANSFORM,
        Spatial::PlusConfig(&config),
    )
    .unwrap();
    assert_eq!((seq.counts.frames, seq.counts.used), (4, 3));
    assert_eq!(seq.counts.skipped_status.get("INVALID"), Some(&1));
    assert_eq!(seq.poses.len(), 3);
    let raw = &exp["tiny_raw.seq.mha"]["frame_list"];
    let expected_rows: usize = (0..4)
        .filter(|&k| raw[k]["status"] == "OK")
        .map(|k| raw[k]["bone_pixels"].as_array().unwrap().len())
        .sum();
    assert_eq!(seq.frames.len(), expected_rows);
}

/// A copy of fixture `name` with its header edited by `edit` (text before the data) and
/// its data by `data`.
fn variant(
    dir: &Path,
    name: &str,
    out: &str,
    edit: impl Fn(&str) -> String,
    data: impl Fn(&mut Vec<u8>),
) -> PathBuf {
    let bytes = std::fs::read(fixture(name)).unwrap();
    let key = b"ElementDataFile = LOCAL\n";
    let end = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len();
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    let mut body = bytes[end..].to_vec();
    data(&mut body);
    let mut file = edit(header).into_bytes();
    file.extend_from_slice(&body);
    let p = dir.join(out);
    std::fs::write(&p, file).unwrap();
    p
}

/// Opens and reads every frame; the error if any.
fn read_all(p: &Path) -> Result<u32, SequenceError> {
    let mut r = SequenceReader::open(p, "ProbeToTracker")?;
    let mut n = 0;
    while r.next_frame()?.is_some() {
        n += 1;
    }
    Ok(n)
}

/// Bad files: each one error naming the file, with what was found and what was expected;
/// an INVALID frame is not an error.
#[test]
fn bad_sequences_are_refused_with_one_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let raw = "tiny_raw.seq.mha";
    let comp = "tiny_compressed.seq.mha";
    let same = |h: &str| h.to_string();
    let keep = |_: &mut Vec<u8>| {};
    let check = |p: &Path, want: &dyn Fn(&K) -> bool, needles: &[&str]| {
        let e = read_all(p).unwrap_err();
        let msg = e.to_string();
        assert!(want(&e.kind), "{msg}");
        assert!(msg.starts_with(s(p)), "{msg}");
        assert!(!msg.contains('\n'), "{msg}");
        for n in needles {
            assert!(msg.contains(n), "expected {n:?} in {msg}");
        }
        println!("{msg}");
    };

    // The header lies about the sizes: DimSize bigger than the data.
    let p = variant(
        d,
        raw,
        "tall.mha",
        |h| h.replace("DimSize = 6 4 4", "DimSize = 6 5 4"),
        keep,
    );
    check(
        &p,
        &|k| {
            matches!(
                k,
                K::DataSize {
                    expected: 120,
                    found: 96,
                    ..
                }
            )
        },
        &["DimSize 6 5 4 needs 120 bytes", "holds 96"],
    );
    // ... more frames than it has fields for.
    let p = variant(
        d,
        raw,
        "frames.mha",
        |h| h.replace("DimSize = 6 4 4", "DimSize = 6 4 5"),
        keep,
    );
    check(
        &p,
        &|k| {
            matches!(
                k,
                K::FrameCount {
                    declared: 5,
                    in_header: 4
                }
            )
        },
        &["declares 5 frames", "fields for 4"],
    );
    // Truncated data, raw and compressed.
    let p = variant(d, raw, "cut.mha", same, |b| b.truncate(90));
    check(
        &p,
        &|k| {
            matches!(
                k,
                K::DataSize {
                    expected: 96,
                    found: 90,
                    ..
                }
            )
        },
        &["truncated"],
    );
    let p = variant(d, comp, "cutz.mha", same, |b| b.truncate(b.len() - 5));
    check(
        &p,
        &|k| {
            matches!(
                k,
                K::CompressedSize {
                    declared: 39,
                    found: 34
                }
            )
        },
        &["CompressedDataSize = 39", "holds 34"],
    );
    // Compressed size mismatch, either way.
    let p = variant(
        d,
        comp,
        "bigz.mha",
        |h| h.replace("CompressedDataSize = 39", "CompressedDataSize = 45"),
        keep,
    );
    check(
        &p,
        &|k| {
            matches!(
                k,
                K::CompressedSize {
                    declared: 45,
                    found: 39
                }
            )
        },
        &[],
    );
    let p = variant(
        d,
        comp,
        "smallz.mha",
        |h| h.replace("CompressedDataSize = 39", "CompressedDataSize = 30"),
        |b| b.truncate(30),
    );
    check(
        &p,
        &|k| {
            matches!(
                k,
                K::Truncated {
                    frames: 3,
                    compressed: true,
                    ..
                }
            )
        },
        &[],
    );
    // Missing transforms: frame 1 of the raw file has none (its status is OK).
    let p = variant(
        d,
        raw,
        "notransform.mha",
        |h| {
            h.lines()
                .filter(|l| !l.starts_with("Seq_Frame0001_ProbeToTrackerTransform ="))
                .map(|l| format!("{l}\n"))
                .collect()
        },
        keep,
    );
    check(
        &p,
        &|k| matches!(k, K::MissingTransform { frame: 1, .. }),
        &[
            "frame 1: no ProbeToTrackerTransform",
            "transforms of frame 0: ProbeToTracker, ReferenceToTracker",
        ],
    );
    // Missing time stamps.
    let p = variant(
        d,
        raw,
        "notime.mha",
        |h| h.replace("Seq_Frame0003_Timestamp", "Seq_Frame0003_TimeStamp"),
        keep,
    );
    check(
        &p,
        &|k| matches!(k, K::MissingTimestamp { frame: 3 }),
        &["frame 3: no Timestamp"],
    );
    // Unknown and unsupported element types.
    let p = variant(
        d,
        raw,
        "type.mha",
        |h| h.replace("MET_UCHAR", "MET_FOO"),
        keep,
    );
    check(
        &p,
        &|k| matches!(k, K::ElementType { .. }),
        &["ElementType MET_FOO is unknown", "expected MET_UCHAR"],
    );
    let p = variant(
        d,
        raw,
        "short.mha",
        |h| h.replace("MET_UCHAR", "MET_SHORT"),
        keep,
    );
    check(
        &p,
        &|k| matches!(k, K::ElementType { .. }),
        &["MET_SHORT is not supported"],
    );
    // Garbage: a file of random bytes, and garbage instead of the zlib stream.
    let mut x = 0x2545_f491_4f6c_dd1du64;
    let junk: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect();
    let p = d.join("junk.mha");
    std::fs::write(&p, &junk).unwrap();
    check(
        &p,
        &|k| matches!(k, K::NotMetaImage { .. }),
        &["expected the line \"ObjectType = Image\""],
    );
    let p = variant(d, comp, "junkz.mha", same, |b| {
        b.iter_mut().zip(&junk).for_each(|(a, j)| *a = *j)
    });
    check(
        &p,
        &|k| matches!(k, K::Corrupt { frame: 0, .. } | K::Truncated { .. }),
        &["frame 0"],
    );
    // Huge DimSize: refused before anything is allocated, or (within the caps) costs one
    // frame and ends at the data.
    let p = variant(
        d,
        comp,
        "wide.mha",
        |h| h.replace("DimSize = 6 4 1 3", "DimSize = 100000 100000 1 3"),
        keep,
    );
    check(
        &p,
        &|k| {
            matches!(
                k,
                K::OverCap {
                    what: "image width",
                    found: 100_000,
                    ..
                }
            )
        },
        &["nothing was allocated"],
    );
    let p = variant(
        d,
        comp,
        "long.mha",
        |h| h.replace("DimSize = 6 4 1 3", "DimSize = 6 4 1 3000000000"),
        keep,
    );
    check(&p, &|k| matches!(k, K::OverCap { what: "frames", .. }), &[]);
    let p = variant(
        d,
        comp,
        "big.mha",
        |h| h.replace("DimSize = 6 4 1 3", "DimSize = 4096 4096 1 3"),
        keep,
    );
    check(
        &p,
        &|k| {
            matches!(
                k,
                K::Truncated {
                    frame: 0,
                    frames: 3,
                    compressed: true
                }
            )
        },
        &["ends inside frame 0"],
    );

    // INVALID frames are skipped and counted, through the CLI too.
    let out = d.join("us.ply");
    let o = ribreg(&[
        "compound",
        "--sequence",
        s(&fixture(raw)),
        "--plus-config",
        s(&fixture("tiny_config.xml")),
        "--lag-ms",
        "0",
        "-o",
        s(&out),
    ]);
    let text = stdout(&o);
    assert!(
        text.contains("4 frames: 3 used, 1 skipped (transform status not OK: 1 INVALID"),
        "{text}"
    );
    // A bad file through the CLI: exit 2, one line.
    let p = variant(
        d,
        raw,
        "tall2.mha",
        |h| h.replace("DimSize = 6 4 4", "DimSize = 6 5 4"),
        keep,
    );
    let o = ribreg(&[
        "compound",
        "--sequence",
        s(&p),
        "--plus-config",
        s(&fixture("tiny_config.xml")),
        "--lag-ms",
        "0",
        "-o",
        s(&out),
    ]);
    assert_refused(&o, &[s(&p), "needs 120 bytes"]);
    // A calibration the config does not hold.
    let o = ribreg(&[
        "compound",
        "--sequence",
        s(&fixture(raw)),
        "--transform",
        "ReferenceToTracker",
        "--plus-config",
        s(&fixture("tiny_config.xml")),
        "--lag-ms",
        "0",
        "-o",
        s(&out),
    ]);
    assert_refused(
        &o,
        &[
            "no <Transform From=\"Image\" To=\"Reference\">",
            "StylusTip→Stylus, Image→Probe",
        ],
    );
}

/// The phantom's scan as `sweep.seq.mha` + `plus_config.xml`, compounded:
/// (a) bit for bit what the same frames give through the CSV compounder in memory
///     (the file round trip, the masks, the statuses and the bone-pixel rule lose
///     nothing);
/// (b) against the phantom's own CSV logs (100 Hz poses, continuous rows) the cloud
///     differs only as explained: rows quantised to pixel centres (≤ 0.05 mm along the
///     beam), and the pose stream sampled at the frame times, so a frame whose
///     lag-corrected time falls in a > 50 ms gap (around a lost frame) is refused.
#[test]
fn phantom_sequence_compounds_like_the_csv_logs() {
    let cfg = SweepConfig::default();
    let phantom = PhantomConfig {
        seed: 1,
        ..PhantomConfig::default()
    };
    let logs = sweep::simulate(&phantom, &cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    logs.write(d).unwrap();
    let lag = cfg.lag_ms * 1e-3;
    let (seq_out, seq) = compound_sequence(
        &d.join(SWEEP_SEQUENCE),
        DEFAULT_TRANSFORM,
        Spatial::PlusConfig(&d.join(PLUS_CONFIG)),
        lag,
        2.0,
    )
    .unwrap();

    // (a) Bit for bit.
    let (cal, poses, rows) = phantom_sequence_logs(&logs).unwrap();
    assert_eq!(seq.calibration, cal);
    assert_eq!(seq.poses, poses);
    assert_eq!(seq.frames, rows);
    let mem = sweep::compound(&cal, lag, 2.0, &poses, &rows).unwrap();
    assert_eq!(seq_out.points, mem.points);
    assert_eq!(seq_out.frames, mem.frames);
    // Skipped: the lost frames, plus the few stamped after the last tracked pose.
    let lost = logs.scan_captured.iter().filter(|c| c.lost).count() as u32;
    let invalid = seq
        .counts
        .skipped_status
        .get("INVALID")
        .copied()
        .unwrap_or(0);
    assert!(
        (lost..=lost + 12).contains(&invalid),
        "{invalid} INVALID, {lost} lost"
    );

    // (b) Against the CSV logs as written.
    let csv = sweep::compound(
        &sweep::ProbeFile::read(&d.join("probe.json")).unwrap(),
        lag,
        2.0,
        &sweep::read_poses(&d.join("poses.csv")).unwrap(),
        &sweep::read_frames(&d.join("frames.csv")).unwrap(),
    )
    .unwrap();
    let nearest = |a: &[[f64; 3]], b: &[[f64; 3]]| -> Vec<f64> {
        let mut d: Vec<f64> = a
            .iter()
            .map(|p| {
                b.iter()
                    .map(|q| (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>())
                    .fold(f64::INFINITY, f64::min)
                    .sqrt()
            })
            .collect();
        d.sort_by(f64::total_cmp);
        d
    };
    let (ab, ba) = (
        nearest(&seq_out.points, &csv.points),
        nearest(&csv.points, &seq_out.points),
    );
    let q = |d: &[f64], f: f64| d[((d.len() - 1) as f64 * f) as usize];
    let gaps = seq_out
        .refusals
        .get("across a gap in the pose stream")
        .copied()
        .unwrap_or(0);
    println!(
        "sequence vs CSV: points {} vs {}, frames placed {} vs {} ({} refused across a gap, \
         {} lost frames); nearest distance sequence→CSV median {:.3} / 95 % {:.3} / max \
         {:.3} mm, CSV→sequence median {:.3} / 95 % {:.3} / max {:.3} mm",
        seq_out.points.len(),
        csv.points.len(),
        seq_out.frames.placed,
        csv.frames.placed,
        gaps,
        lost,
        q(&ab, 0.5),
        q(&ab, 0.95),
        q(&ab, 1.0),
        q(&ba, 0.5),
        q(&ba, 0.95),
        q(&ba, 1.0),
    );
    // Every frame the CSV path places is placed here too unless it is lost-adjacent or
    // at the ends; each lost frame opens one gap catching about two frames.
    assert!(csv.frames.placed - seq_out.frames.placed <= gaps + 12);
    assert!(
        gaps <= 3 * lost,
        "{gaps} gap refusals for {lost} lost frames"
    );
    // Bounds (measured: see the README): same surface within a voxel's quantisation.
    assert!(q(&ab, 0.5) < 0.15 && q(&ba, 0.5) < 0.15);
    assert!(q(&ab, 0.95) < 0.6 && q(&ba, 0.95) < 0.6);
    assert!(q(&ab, 1.0) < 2.0 && q(&ba, 1.0) < 2.0);
    let n = |o: &sweep::CompoundOutcome| o.points.len() as f64;
    assert!((n(&seq_out) - n(&csv)).abs() / n(&csv) < 0.03);
}

/// Issue 4's goal from a sequence: the lag within ±2 ms (as the CSV test) at 30 fps with
/// the same noise, for lags of 0–400 ms on three sweeps each, the tracker stream being
/// the per-frame transforms (sampled at the frame times) and the video stream the
/// landmark rows of the masks (quantised to pixel centres).
#[test]
fn temporal_calibration_from_a_sequence_within_2_ms() {
    let dir = tempfile::tempdir().unwrap();
    let probe = sweep::default_calibration().probe;
    let mut worst: f64 = 0.0;
    for lag_ms in [0.0, 50.0, 100.0, 150.0, 200.0, 268.0, 300.0, 350.0, 400.0] {
        for seed in 0..3 {
            let cfg = SweepConfig {
                lag_ms,
                ..SweepConfig::default()
            };
            let ((tr, vi), captured) = sweep::simulate_calibration_captured(&cfg, seed).unwrap();
            let frames = phantom_calibration_frames(&tr, &vi, &captured, &probe);
            let p = dir.path().join(CALIB_SEQUENCE);
            write_phantom_sequence(&p, &frames, &probe, true).unwrap();
            let (est, counts) = calibrate_temporal_sequence(&p, DEFAULT_TRANSFORM).unwrap();
            let err = est.lag_s * 1e3 - lag_ms;
            assert!(
                err.abs() <= 2.0,
                "lag {lag_ms} ms seed {seed}: {est:?} {counts:?}"
            );
            worst = worst.max(err.abs());
        }
    }
    println!("worst lag error from sequences {worst:.3} ms");
}

/// The CLI: `phantom sweep` writes the PLUS files, `calibrate temporal --sequence`
/// finds the lag, `compound --sequence --plus-config --lag-file` compounds.
#[test]
fn phantom_sequences_through_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    stdout(&ribreg(&[
        "-q",
        "phantom",
        "sweep",
        "--out-dir",
        s(d),
        "--seed",
        "2",
        "--line-spacing-mm",
        "40",
        "--speed-mm-s",
        "80",
    ]));
    for f in [SWEEP_SEQUENCE, CALIB_SEQUENCE, PLUS_CONFIG] {
        assert!(d.join(f).exists(), "{f}");
    }
    let json = stdout(&ribreg(&[
        "calibrate",
        "temporal",
        "--sequence",
        s(&d.join(CALIB_SEQUENCE)),
        "--json",
    ]));
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    let lag = v["lag_ms"].as_f64().unwrap();
    assert!((lag - 268.0).abs() <= 2.0, "{json}");
    ribreg_sim::io::write_text(&d.join("lag.json"), &json).unwrap();
    let out = stdout(&ribreg(&[
        "compound",
        "--sequence",
        s(&d.join(SWEEP_SEQUENCE)),
        "--plus-config",
        s(&d.join(PLUS_CONFIG)),
        "--lag-file",
        s(&d.join("lag.json")),
        "-o",
        s(&d.join("us.ply")),
    ]));
    assert!(out.contains("skipped (transform status not OK:"), "{out}");
    let cloud = ribreg_sim::io::read_ply(&d.join("us.ply")).unwrap();
    assert!(cloud.points.len() > 500, "{}", cloud.points.len());
    // --probe with the sequence: the transform is then the flange pose, so the phantom's
    // probe.json (165 mm holder) puts the cloud 165 mm off; the size check still holds.
    let out = stdout(&ribreg(&[
        "compound",
        "--sequence",
        s(&d.join(SWEEP_SEQUENCE)),
        "--probe",
        s(&d.join("probe.json")),
        "--lag-ms",
        "268",
        "-o",
        s(&d.join("us_probe.ply")),
    ]));
    assert!(out.contains("frames placed"), "{out}");
    // Arguments that do not go together.
    let o = ribreg(&[
        "compound",
        "--sequence",
        s(&d.join(SWEEP_SEQUENCE)),
        "--lag-ms",
        "0",
        "-o",
        s(&d.join("x.ply")),
    ]);
    assert!(!o.status.success());
}
