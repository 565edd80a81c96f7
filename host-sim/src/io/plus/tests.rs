//! Unit tests of the PLUS reader and writer (the bad-file suite and the independent
//! fixtures are in `tests/plus.rs`).

use super::*;
use std::path::Path;

fn spec(orientation: Orientation, compressed: bool) -> SequenceSpec {
    SequenceSpec {
        width: 5,
        height: 3,
        orientation,
        compressed,
        transform: "ProbeToTracker".into(),
    }
}

fn translation(x: f64) -> Matrix4 {
    [
        [1.0, 0.0, 0.0, x],
        [0.0, 1.0, 0.0, 2.0],
        [0.0, 0.0, 1.0, -3.5],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

/// Three frames: the second INVALID; masks numbered so any flip shows.
fn write(path: &Path, s: SequenceSpec) {
    let mut w = SequenceWriter::create(path, s).unwrap();
    let m0 = translation(1e-7);
    let m2 = translation(123.456);
    for (k, m) in [Some(&m0), None, Some(&m2)].into_iter().enumerate() {
        let mask: Vec<u8> = (0..15).map(|i| (i + 16 * k) as u8).collect();
        w.push(&FrameOut {
            timestamp: 0.1 + k as f64 / 30.0,
            unfiltered_timestamp: 0.1 + k as f64 / 30.0 + 1e-4,
            frame_number: 100 + k as u64,
            transform: m,
            mask: &mask,
        })
        .unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn round_trip_every_orientation_raw_and_compressed() {
    let dir = tempfile::tempdir().unwrap();
    for o in [
        Orientation::Mf,
        Orientation::Mn,
        Orientation::Uf,
        Orientation::Un,
    ] {
        for compressed in [false, true] {
            let p = dir.path().join(format!("{}{compressed}.seq.mha", o.name()));
            write(&p, spec(o, compressed));
            let mut r = SequenceReader::open(&p, "ProbeToTracker").unwrap();
            let info = r.info().clone();
            assert_eq!(
                (info.width, info.height, info.frames, info.orientation),
                (5, 3, 3, o)
            );
            assert!(info.orientation_given && info.compressed == compressed);
            assert_eq!(info.transforms_available, vec!["ProbeToTracker"]);
            let mut k = 0;
            while let Some(f) = r.next_frame().unwrap() {
                let mask: Vec<u8> = (0..15).map(|i| (i + 16 * k) as u8).collect();
                assert_eq!(f.mask, &mask[..], "{o:?} {compressed} frame {k}");
                assert_eq!(f.index, k as u32);
                assert_eq!(f.timestamp, 0.1 + k as f64 / 30.0);
                assert_eq!(f.unfiltered_timestamp, Some(0.1 + k as f64 / 30.0 + 1e-4));
                assert_eq!(f.frame_number, Some(100 + k as i64));
                assert_eq!(f.image_status, Status::Ok);
                match k {
                    1 => assert_eq!((f.status, f.transform), (Status::Invalid, None)),
                    0 => assert_eq!(f.transform, Some(translation(1e-7))),
                    _ => assert_eq!(f.transform, Some(translation(123.456))),
                }
                k += 1;
            }
            assert_eq!(k, 3);
            // After the end: still the end.
            assert!(r.next_frame().unwrap().is_none());
        }
    }
}

#[test]
fn reorients_to_mf() {
    // 3 wide, 2 tall: stored rows "abc" / "def".
    let stored = *b"abcdef";
    let mut p = stored;
    Orientation::Uf.reorient(&mut p, 3);
    assert_eq!(&p, b"cbafed");
    let mut p = stored;
    Orientation::Mn.reorient(&mut p, 3);
    assert_eq!(&p, b"defabc");
    let mut p = stored;
    Orientation::Un.reorient(&mut p, 3);
    assert_eq!(&p, b"fedcba");
    assert_eq!(Orientation::parse("mfa"), Some(Orientation::Mf));
    assert_eq!(Orientation::parse("UND"), Some(Orientation::Un));
    assert_eq!(Orientation::parse("FM"), None);
    assert_eq!(Orientation::parse("MFX"), None);
}

/// The header of a written file with `edit` applied to its text, data unchanged.
fn edited(dir: &Path, name: &str, edit: impl Fn(String) -> String) -> std::path::PathBuf {
    let src = dir.join("src.seq.mha");
    write(&src, spec(Orientation::Mf, false));
    let bytes = std::fs::read(&src).unwrap();
    let end = bytes
        .windows(24)
        .position(|w| w == b"ElementDataFile = LOCAL\n")
        .unwrap()
        + 24;
    let header = String::from_utf8(bytes[..end].to_vec()).unwrap();
    let mut out = edit(header).into_bytes();
    out.extend_from_slice(&bytes[end..]);
    let p = dir.join(name);
    std::fs::write(&p, out).unwrap();
    p
}

fn open_err(p: &Path) -> SequenceError {
    match SequenceReader::open(p, "ProbeToTracker") {
        Ok(_) => panic!("{} opened", p.display()),
        Err(e) => e,
    }
}

#[test]
fn header_faults_are_typed_with_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    use SequenceErrorKind as K;
    let e = open_err(&edited(d, "a", |h| {
        h.replace("Seq_Frame0002_Timestamp", "Seq_Frame0002_Timestampx")
    }));
    assert!(matches!(e.kind, K::MissingTimestamp { frame: 2 }), "{e}");
    assert!(e.to_string().contains("frame 2: no Timestamp"), "{e}");
    let e = open_err(&edited(d, "b", |h| {
        h.replace("DimSize = 5 3 3\n", "DimSize = 5 3 3\nDimSize = 5 3 3\n")
    }));
    assert!(matches!(e.kind, K::DuplicateKey { .. }), "{e}");
    let e = open_err(&edited(d, "c", |h| {
        h.replace(
            "Seq_Frame0001_ImageStatus = OK",
            "Seq_Frame0000_ImageStatus = OK",
        )
    }));
    assert!(
        matches!(
            e.kind,
            K::FrameOrder {
                frame: 0,
                after: 1,
                ..
            }
        ),
        "{e}"
    );
    let e = open_err(&edited(d, "d", |h| {
        h.replace("Offset = 0 0 0", "Offset 0 0 0")
    }));
    assert!(matches!(e.kind, K::NotKeyValue { .. }), "{e}");
    let e = open_err(&edited(d, "e", |h| {
        h.replace("Offset = 0 0 0", &format!("Offset = {}", "0 ".repeat(3000)))
    }));
    assert!(matches!(e.kind, K::LineTooLong { .. }), "{e}");
    let e = open_err(&edited(d, "f", |h| {
        h.replace(
            "Seq_Frame0002_ProbeToTrackerTransform = 1 0 0 123.456 0 1 0 2 0 0 1 -3.5 0 0 0 1",
            "Seq_Frame0002_ProbeToTrackerTransform = 1 0 0 123.456 0 1 0 2 0 0 1 -3.5 0 0 1 1",
        )
    }));
    assert!(matches!(e.kind, K::BadValue { .. }), "{e}");
    assert!(e.to_string().contains("last row 0 0 0 1"), "{e}");
    let e = open_err(&edited(d, "g", |h| h.replace("NDims = 3", "NDims = 2")));
    assert!(
        matches!(e.kind, K::BadValue { .. } | K::Unsupported { .. }),
        "{e}"
    );
    let e = open_err(&edited(d, "h", |h| {
        h.replace(
            "UltrasoundImageOrientation = MF",
            "UltrasoundImageOrientation = FM",
        )
    }));
    assert!(
        matches!(
            e.kind,
            K::Unsupported {
                key: "UltrasoundImageOrientation",
                ..
            }
        ),
        "{e}"
    );
    let e = open_err(&edited(d, "i", |h| {
        h.replace("ElementDataFile = LOCAL", "ElementDataFile = data.raw")
    }));
    assert!(
        matches!(
            e.kind,
            K::Unsupported {
                key: "ElementDataFile",
                ..
            }
        ),
        "{e}"
    );
    // An INVALID frame may lack its transform; an OK one may not.
    let p = edited(d, "j", |h| {
        h.lines()
            .filter(|l| !l.starts_with("Seq_Frame0001_ProbeToTrackerTransform ="))
            .map(|l| format!("{l}\n"))
            .collect()
    });
    assert!(SequenceReader::open(&p, "ProbeToTracker").is_ok());
    match SequenceReader::open(&p, "ProbeToReference").map(|_| ()) {
        Err(SequenceError {
            kind:
                K::MissingTransform {
                    frame: 0,
                    name,
                    available,
                },
            ..
        }) => assert_eq!(
            (name.as_str(), available),
            ("ProbeToReference", vec!["ProbeToTracker".to_string()])
        ),
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        SequenceReader::open(&p, "Probe To").map(|_| ()),
        Err(SequenceError {
            kind: K::BadTransformName(_),
            ..
        })
    ));
}

#[test]
fn writer_refuses_what_it_cannot_write() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("w.seq.mha");
    let mut w = SequenceWriter::create(&p, spec(Orientation::Mf, true)).unwrap();
    let bad = w.push(&FrameOut {
        timestamp: 0.0,
        unfiltered_timestamp: 0.0,
        frame_number: 0,
        transform: None,
        mask: &[0; 4],
    });
    assert!(matches!(
        bad,
        Err(SequenceError {
            kind: SequenceErrorKind::Unwritable(_),
            ..
        })
    ));
    let nan = translation(f64::NAN);
    let bad = w.push(&FrameOut {
        timestamp: 0.0,
        unfiltered_timestamp: 0.0,
        frame_number: 0,
        transform: Some(&nan),
        mask: &[0; 15],
    });
    assert!(bad.is_err());
    assert!(w.finish().is_err(), "no frames");
    assert!(!p.exists());
    // No temporary file is left behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

const CONFIG: &str = r#"<PlusConfiguration version="2.1">
  <DataCollection StartupDelaySec="1.0" />
  <CoordinateDefinitions>
    <Transform From="Phantom" To="Reference" Matrix="1 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1" />
    <Transform From="Probe" To="Image"
      Matrix="
        0 -12.5 0 625
        12.5 0 0 -137.5
        0 0 12.5 0
        0 0 0 1" />
  </CoordinateDefinitions>
</PlusConfiguration>"#;

#[test]
fn config_transform_directly_or_inverted() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.xml");
    std::fs::write(&p, CONFIG).unwrap();
    // Only Probe→Image is given: Image→Probe is its inverse.
    let m = read_plus_transform(&p, "Image", "Probe").unwrap();
    let expected = [
        [0.0, 0.08, 0.0, 11.0],
        [-0.08, 0.0, 0.0, 50.0],
        [0.0, 0.0, 0.08, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    for i in 0..4 {
        for j in 0..4 {
            assert!((m[i][j] - expected[i][j]).abs() < 1e-12, "{m:?}");
        }
    }
    let direct = read_plus_transform(&p, "Probe", "Image").unwrap();
    assert_eq!(direct[0][3], 625.0);
    let e = read_plus_transform(&p, "Image", "Transducer").unwrap_err();
    assert!(matches!(e.problem, PlusConfigProblem::NoTransform { .. }));
    assert!(
        e.to_string()
            .contains("it defines: Phantom→Reference, Probe→Image"),
        "{e}"
    );
    std::fs::write(&p, "<PlusConfiguration><CoordinateDefinitions>").unwrap();
    let e = read_plus_transform(&p, "Image", "Probe").unwrap_err();
    assert!(matches!(e.problem, PlusConfigProblem::Xml(_)), "{e}");
    std::fs::write(&p, CONFIG.replace("12.5 0 0 -137.5", "12.5 0 0")).unwrap();
    let e = read_plus_transform(&p, "Image", "Probe").unwrap_err();
    assert!(matches!(e.problem, PlusConfigProblem::Matrix { .. }), "{e}");
    // The writer's file reads back exactly.
    let q = dir.path().join("w.xml");
    write_plus_config(&q, &expected, "Probe", "s&q.seq.mha", "a \"test\"").unwrap();
    assert_eq!(read_plus_transform(&q, "Image", "Probe").unwrap(), expected);
}
