//! Tests of the labelmap readers: the independent fixtures of
//! `tests/fixtures/formats/gen_volumes.py` (nibabel, pynrrd, a Slicer-style `.seg.nrrd`)
//! against the values Python computed, and the bad-input suite.

use super::*;
use std::collections::BTreeMap;
use std::io::Read;
use std::path::PathBuf;

use serde_json::Value;

const DIR: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../tests/fixtures/formats/volumes"
);

fn fixture(name: &str) -> PathBuf {
    Path::new(DIR).join(name)
}

fn expected() -> Value {
    let text = fs::read_to_string(fixture("expected.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn bytes(name: &str) -> Vec<u8> {
    fs::read(fixture(name)).unwrap()
}

fn kind(e: &IoError) -> &FormatError {
    e.kind()
        .unwrap_or_else(|| panic!("not a format error: {e}"))
}

/// The volume matches what Python found: dims, label counts, layout checksum, and the
/// labels and patient-frame positions of the sample voxels to 1e-9 mm.
fn check(volume: &LabelVolume, want: &Value, name: &str) {
    let dims: Vec<usize> = serde_json::from_value(want["dims"].clone()).unwrap();
    assert_eq!(volume.dims.to_vec(), dims, "{name}");
    assert_eq!(
        volume.labels.len(),
        dims.iter().product::<usize>(),
        "{name}"
    );
    let mut counts: BTreeMap<String, u64> = BTreeMap::new();
    for &l in &volume.labels {
        *counts.entry(l.to_string()).or_default() += 1;
    }
    let want_counts: BTreeMap<String, u64> =
        serde_json::from_value(want["label_counts"].clone()).unwrap();
    assert_eq!(counts, want_counts, "{name}");
    let checksum: u64 = volume
        .labels
        .iter()
        .enumerate()
        .map(|(i, &l)| (i as u64 + 1) * u64::from(l))
        .sum();
    assert_eq!(checksum, want["checksum"].as_u64().unwrap(), "{name}");
    for voxel in want["voxels"].as_array().unwrap() {
        let ijk: [usize; 3] = serde_json::from_value(voxel["ijk"].clone()).unwrap();
        let p: [f64; 3] = serde_json::from_value(voxel["patient"].clone()).unwrap();
        let label = voxel["label"].as_u64().unwrap();
        assert_eq!(
            u64::from(volume.labels[volume.index(ijk)]),
            label,
            "{name} {ijk:?}"
        );
        let got = volume.position(ijk);
        for c in 0..3 {
            assert!(
                (got[c] - p[c]).abs() < 1e-9,
                "{name} voxel {ijk:?}: {got:?} vs {p:?}"
            );
        }
    }
}

#[test]
fn nifti_fixtures_match_nibabel() {
    let want = expected();
    for name in [
        "oblique.nii",
        "oblique.nii.gz",
        "qform.nii",
        "int16_be.nii",
        "int16.nii",
        "float32.nii",
        "uint16.nii.gz",
        "scaled.nii",
    ] {
        let volume = read_labelmap(&fixture(name)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(volume.space, Space::Ras, "{name}");
        assert!(volume.segments.is_empty(), "{name}");
        check(&volume, &want[name], name);
    }
    // Gzip is told by content: a gzipped file named .nii is read; parse_nifti refuses it.
    let dir = tempfile::tempdir().unwrap();
    let renamed = dir.path().join("renamed.nii");
    fs::copy(fixture("oblique.nii.gz"), &renamed).unwrap();
    assert_eq!(
        read_labelmap(&renamed).unwrap(),
        read_labelmap(&fixture("oblique.nii")).unwrap()
    );
    let e = parse_nifti(&bytes("oblique.nii.gz")).unwrap_err();
    assert!(e.to_string().contains("decompress it first"), "{e}");
    // parse_nifti on the bytes gives the same as the reader by path.
    let by_path = read_labelmap(&fixture("oblique.nii")).unwrap();
    assert_eq!(parse_nifti(&bytes("oblique.nii")).unwrap(), by_path);
    assert_eq!(read_labelmap(&fixture("oblique.nii.gz")).unwrap(), by_path);
}

#[test]
fn oblique_anisotropic_spacing_and_frame() {
    let v = read_labelmap(&fixture("oblique.nii")).unwrap();
    let s = v.spacing();
    for (got, want) in s.iter().zip([0.7, 0.9, 2.5]) {
        // The sform is stored as float32.
        assert!((got - want).abs() < 1e-6, "{s:?}");
    }
    // Not axis-aligned: every column has at least two non-zero components.
    for c in 0..3 {
        assert!((0..3).filter(|&r| v.linear[r][c].abs() > 1e-3).count() >= 2);
    }
    // Voxel (0,0,0) is the sform offset (-101.3, 42.7, 12.9) RAS, in the patient frame.
    let p = v.position([0, 0, 0]);
    let want = Space::Ras.to_patient([-101.3, 42.7, 12.9]);
    for c in 0..3 {
        assert!((p[c] - want[c]).abs() < 1e-4, "{p:?}");
    }
}

#[test]
fn nrrd_fixtures_match_pynrrd() {
    let want = expected();
    for (name, space) in [
        ("lps_gzip.nrrd", Space::Lps),
        ("ras_raw_be.nrrd", Space::Ras),
        ("slicer.seg.nrrd", Space::Lps),
    ] {
        let volume = read_labelmap(&fixture(name)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(volume.space, space, "{name}");
        check(&volume, &want[name], name);
        assert_eq!(parse_nrrd(&bytes(name)).unwrap(), volume);
    }
    let seg = read_labelmap(&fixture("slicer.seg.nrrd")).unwrap();
    let segments: Vec<(String, u16)> =
        serde_json::from_value(want["slicer.seg.nrrd"]["segments"].clone()).unwrap();
    assert_eq!(seg.segments, segments);
    assert!(read_labelmap(&fixture("lps_gzip.nrrd"))
        .unwrap()
        .segments
        .is_empty());
}

#[test]
fn totalsegmentator_directory_is_merged_with_v2_ids() {
    let want = expected();
    let volume = read_labelmap(&fixture("totalseg")).unwrap();
    check(&volume, &want["totalseg"], "totalseg");
    let segments: Vec<(String, u16)> =
        serde_json::from_value(want["totalseg"]["segments"].clone()).unwrap();
    assert_eq!(volume.segments, segments);
    // liver.nii.gz covers every voxel and is ignored.
    assert!(volume.labels.contains(&0));
}

#[test]
fn totalsegmentator_table() {
    assert_eq!(TOTALSEGMENTATOR.len(), 26);
    let id = |n: &str| TOTALSEGMENTATOR.iter().find(|(m, _)| *m == n).unwrap().1;
    assert_eq!(id("sternum"), 116);
    assert_eq!(id("costal_cartilages"), 117);
    for r in 1..=12u16 {
        assert_eq!(id(&format!("rib_left_{r}")), 91 + r);
        assert_eq!(id(&format!("rib_right_{r}")), 103 + r);
    }
}

#[test]
fn totalsegmentator_directory_errors() {
    let copy = |dir: &Path, from: &str, to: &str| {
        fs::copy(fixture(from), dir.join(to)).unwrap();
    };
    let empty = tempfile::tempdir().unwrap();
    fs::write(empty.path().join("liver.nii.gz"), b"ignored").unwrap();
    let err = read_labelmap(empty.path()).unwrap_err();
    assert_eq!(kind(&err), &FormatError::NoClassFiles);
    assert_eq!(err.path(), Some(empty.path()));

    // Other dims: rib_left_2 is read first (table order), sternum is named.
    let dims = tempfile::tempdir().unwrap();
    copy(dims.path(), "totalseg/sternum.nii.gz", "sternum.nii.gz");
    copy(dims.path(), "uint16.nii.gz", "rib_left_2.nii.gz");
    let err = read_labelmap(dims.path()).unwrap_err();
    assert!(
        matches!(kind(&err), FormatError::VolumeMismatch { what, reference }
            if what == "dims 6x5x4 vs 7x6x5" && reference == "rib_left_2.nii.gz"),
        "{err}"
    );
    assert_eq!(
        err.path(),
        Some(dims.path().join("sternum.nii.gz").as_path())
    );

    // Same dims, grid moved by 5 mm (srow_x[3], byte 292), as a plain .nii.
    let moved = tempfile::tempdir().unwrap();
    copy(
        moved.path(),
        "totalseg/rib_left_1.nii.gz",
        "rib_left_1.nii.gz",
    );
    let mut plain = Vec::new();
    flate2::read::GzDecoder::new(&bytes("totalseg/sternum.nii.gz")[..])
        .read_to_end(&mut plain)
        .unwrap();
    let x = f32::from_le_bytes(plain[292..296].try_into().unwrap()) + 5.0;
    plain[292..296].copy_from_slice(&x.to_le_bytes());
    fs::write(moved.path().join("sternum.nii"), &plain).unwrap();
    let err = read_labelmap(moved.path()).unwrap_err();
    assert!(
        matches!(kind(&err), FormatError::VolumeMismatch { what, .. } if what.contains("affine")),
        "{err}"
    );
    assert_eq!(err.path(), Some(moved.path().join("sternum.nii").as_path()));

    // Two classes on one voxel.
    let overlap = tempfile::tempdir().unwrap();
    copy(
        overlap.path(),
        "totalseg/rib_left_1.nii.gz",
        "rib_left_1.nii.gz",
    );
    copy(
        overlap.path(),
        "totalseg/liver.nii.gz",
        "costal_cartilages.nii.gz",
    );
    let err = read_labelmap(overlap.path()).unwrap_err();
    assert!(
        matches!(kind(&err), FormatError::LabelOverlap { first, second, .. }
            if *first == "rib_left_1" && *second == "costal_cartilages"),
        "{err}"
    );
}

/// A NIfTI fixture's bytes with `edit` applied.
fn edited_nifti(name: &str, edit: impl FnOnce(&mut Vec<u8>)) -> Result<LabelVolume, IoError> {
    let mut b = bytes(name);
    edit(&mut b);
    parse_nifti(&b)
}

fn put_i16(b: &mut [u8], at: usize, v: i16) {
    b[at..at + 2].copy_from_slice(&v.to_le_bytes());
}

#[test]
fn nifti_refusals() {
    // Truncated header, truncated data, no data at all.
    let b = bytes("oblique.nii");
    assert!(matches!(
        kind(&parse_nifti(&b[..200]).unwrap_err()),
        FormatError::NotNifti(_)
    ));
    assert!(matches!(
        kind(&parse_nifti(&b[..2]).unwrap_err()),
        FormatError::NotNifti(_)
    ));
    assert_eq!(
        kind(&parse_nifti(&b[..b.len() - 1]).unwrap_err()),
        &FormatError::VolumeTruncated {
            expected: 960,
            found: 959
        }
    );
    assert!(matches!(
        kind(&parse_nifti(&b[..348]).unwrap_err()),
        FormatError::VolumeTruncated { found: 0, .. }
    ));
    // Wrong magic, NIfTI-2, a .hdr/.img header.
    let e = edited_nifti("oblique.nii", |b| b[344..348].copy_from_slice(b"abc\0")).unwrap_err();
    assert!(matches!(kind(&e), FormatError::NotNifti(_)), "{e}");
    let e = edited_nifti("oblique.nii", |b| b[344..348].copy_from_slice(b"ni1\0")).unwrap_err();
    assert!(matches!(kind(&e), FormatError::NiftiVersion(s) if s.contains(".hdr")));
    let e = edited_nifti("oblique.nii", |b| {
        b[..4].copy_from_slice(&540i32.to_le_bytes())
    })
    .unwrap_err();
    assert!(matches!(kind(&e), FormatError::NiftiVersion(s) if s.contains("NIfTI-2")));
    let e = parse_nifti(b"NRRD0004\ntype: uchar\n\n0123456789").unwrap_err();
    assert!(matches!(kind(&e), FormatError::NotNifti(_)), "{e}");
    let e = read_labelmap(Path::new("x.hdr")).unwrap_err();
    assert!(matches!(kind(&e), FormatError::NiftiVersion(_)), "{e}");

    // A 4-D series, and 4-D with one time point (read).
    let e = edited_nifti("oblique.nii", |b| {
        put_i16(b, 40, 4);
        put_i16(b, 48, 2);
    })
    .unwrap_err();
    assert!(matches!(kind(&e), FormatError::VolumeDimension(_)), "{e}");
    let v = edited_nifti("oblique.nii", |b| {
        put_i16(b, 40, 4);
        put_i16(b, 48, 1);
    })
    .unwrap();
    assert_eq!(v.dims, [12, 10, 8]);
    let e = edited_nifti("oblique.nii", |b| put_i16(b, 40, 2)).unwrap_err();
    assert!(matches!(kind(&e), FormatError::VolumeDimension(_)), "{e}");
    // Empty, negative, too large (refused before allocating: the file is 1.3 KB).
    let e = edited_nifti("oblique.nii", |b| put_i16(b, 44, 0)).unwrap_err();
    assert_eq!(kind(&e), &FormatError::EmptyVolume);
    let e = edited_nifti("oblique.nii", |b| put_i16(b, 44, -3)).unwrap_err();
    assert!(
        matches!(kind(&e), FormatError::NiftiField { field: "dim", .. }),
        "{e}"
    );
    let e = edited_nifti("oblique.nii", |b| {
        for at in [42, 44, 46] {
            put_i16(b, at, 32767);
        }
    })
    .unwrap_err();
    assert_eq!(
        kind(&e),
        &FormatError::VolumeTooLarge {
            voxels: 32767u64.pow(3),
            max: MAX_VOXELS
        }
    );
    assert!(e.to_string().contains("too large"));
    // Unsupported datatype (complex64), bad vox_offset.
    let e = edited_nifti("oblique.nii", |b| put_i16(b, 70, 32)).unwrap_err();
    assert!(matches!(kind(&e), FormatError::VolumeDatatype(s) if s.contains("complex64")));
    let e = edited_nifti("oblique.nii", |b| {
        b[108..112].copy_from_slice(&100.0f32.to_le_bytes())
    })
    .unwrap_err();
    assert!(
        matches!(
            kind(&e),
            FormatError::NiftiField {
                field: "vox_offset",
                ..
            }
        ),
        "{e}"
    );
    // A singular sform.
    let e = edited_nifti("oblique.nii", |b| b[280..332].fill(0)).unwrap_err();
    assert!(matches!(kind(&e), FormatError::VolumeAffine(_)), "{e}");
}

#[test]
fn nifti_labels_must_be_integral_and_in_range() {
    let want = expected();
    let e = read_labelmap(&fixture("bad_float.nii")).unwrap_err();
    assert_eq!(
        kind(&e),
        &FormatError::NotIntegralLabel {
            index: want["bad_float.nii"]["index"].as_u64().unwrap() as usize,
            value: want["bad_float.nii"]["value"].as_f64().unwrap(),
        }
    );
    assert!(
        e.to_string().contains("bad_float.nii: voxel 9 holds 2.5"),
        "{e}"
    );
    // A negative int16.
    let e = edited_nifti("int16.nii", |b| {
        b[352..354].copy_from_slice(&(-1i16).to_le_bytes())
    })
    .unwrap_err();
    assert_eq!(
        kind(&e),
        &FormatError::NotIntegralLabel {
            index: 0,
            value: -1.0
        }
    );
    // Scaling to a fraction.
    let e = edited_nifti("scaled.nii", |b| {
        b[112..116].copy_from_slice(&0.5f32.to_le_bytes())
    })
    .unwrap_err();
    assert!(
        matches!(kind(&e), FormatError::NotIntegralLabel { .. }),
        "{e}"
    );
}

#[test]
fn nifti_method_1_uses_pixdim_without_offset() {
    // sform_code = qform_code = 0.
    let v = edited_nifti("oblique.nii", |b| {
        put_i16(b, 252, 0);
        put_i16(b, 254, 0);
        for (k, d) in [0.7f32, 0.9, 2.5].iter().enumerate() {
            b[80 + 4 * k..84 + 4 * k].copy_from_slice(&d.to_le_bytes());
        }
    })
    .unwrap();
    assert_eq!(v.position([0, 0, 0]), [0.0; 3]);
    let p = v.position([1, 1, 1]);
    let want = Space::Ras.to_patient([0.7f32, 0.9, 2.5].map(f64::from));
    assert_eq!(p, want);
}

#[test]
fn bad_gzip_is_a_typed_error() {
    let mut b = bytes("oblique.nii.gz");
    let mid = b.len() / 2;
    b[mid..].iter_mut().for_each(|x| *x = !*x);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.nii.gz");
    fs::write(&path, &b).unwrap();
    let e = read_labelmap(&path).unwrap_err();
    assert!(
        matches!(
            kind(&e),
            FormatError::Gzip(_) | FormatError::VolumeTruncated { .. }
        ),
        "{e}"
    );
    fs::write(&path, b"not gzip at all").unwrap();
    let e = read_labelmap(&path).unwrap_err();
    assert!(
        matches!(kind(&e), FormatError::Gzip(_) | FormatError::NotNifti(_)),
        "{e}"
    );

    // A gzip NRRD body that is not gzip.
    let mut n = bytes("lps_gzip.nrrd");
    let len = n.len();
    n[len - 40..].fill(0x55);
    let e = parse_nrrd(&n).unwrap_err();
    assert!(
        matches!(
            kind(&e),
            FormatError::Gzip(_) | FormatError::VolumeTruncated { .. }
        ),
        "{e}"
    );
    let e = parse_nrrd(&n[..len - 60]).unwrap_err();
    assert!(
        matches!(
            kind(&e),
            FormatError::Gzip(_) | FormatError::VolumeTruncated { .. }
        ),
        "{e}"
    );
}

/// A minimal NRRD with `fields` and a raw uchar body of `body`.
fn nrrd(fields: &str, body: &[u8]) -> Result<LabelVolume, IoError> {
    let mut b = format!("NRRD0004\n{fields}\n").into_bytes();
    b.extend_from_slice(body);
    parse_nrrd(&b)
}

const GOOD: &str = "type: uchar\ndimension: 3\nsizes: 2 2 1\nspace: LPS\n\
                    space directions: (1,0,0) (0,2,0) (0,0,3)\nspace origin: (10,20,30)\n\
                    encoding: raw\n";

#[test]
fn nrrd_hand_written() {
    let v = nrrd(GOOD, &[0, 1, 2, 3]).unwrap();
    assert_eq!(v.labels, vec![0, 1, 2, 3]);
    assert_eq!(v.space, Space::Lps);
    assert_eq!(
        v.position([0, 0, 0]),
        Space::Lps.to_patient([10.0, 20.0, 30.0])
    );
    assert_eq!(
        v.position([1, 1, 0]),
        Space::Lps.to_patient([11.0, 22.0, 30.0])
    );
    assert_eq!(v.spacing(), [1.0, 2.0, 3.0]);
    // Aliases, ascii, CRLF, comments.
    let text = GOOD
        .replace("uchar", "unsigned short int")
        .replace("raw", "ascii")
        .replace('\n', "\r\n");
    let v = nrrd(&format!("# comment\r\n{text}\r"), b"0 1\n2 300\n").unwrap();
    assert_eq!(v.labels, vec![0, 1, 2, 300]);
}

#[test]
fn nrrd_refusals() {
    let k = |fields: &str, body: &[u8]| {
        let e = nrrd(fields, body).unwrap_err();
        e.kind().unwrap().clone()
    };
    let body = [0u8, 1, 2, 3];
    // No space, unknown space.
    let e = read_labelmap(&fixture("nospace.nrrd")).unwrap_err();
    assert_eq!(kind(&e), &FormatError::NoSpace);
    assert!(e.to_string().contains("refusing to guess"), "{e}");
    assert_eq!(
        k(&GOOD.replace("LPS", "scanner-xyz"), &body),
        FormatError::UnknownSpace("scanner-xyz".into())
    );
    // 4-D multi-layer segmentation.
    let e = read_labelmap(&fixture("multilayer.seg.nrrd")).unwrap_err();
    assert!(
        matches!(kind(&e), FormatError::VolumeDimension(s) if s.contains("export a labelmap")),
        "{e}"
    );
    // Wrong magic, detached data, unsupported encoding, missing endian for shorts.
    assert_eq!(
        kind(&parse_nrrd(b"NRRX0004\n\n").unwrap_err()),
        &FormatError::NotNrrd
    );
    assert_eq!(
        kind(&parse_nrrd(b"NRR").unwrap_err()),
        &FormatError::NotNrrd
    );
    assert!(matches!(
        k(&format!("{GOOD}data file: x.raw\n"), &[]),
        FormatError::NrrdField { field, .. } if field == "data file"
    ));
    let e = parse_nrrd(format!("NRRD0004\n{GOOD}data file: x.raw\n").as_bytes()).unwrap_err();
    assert!(matches!(kind(&e), FormatError::NrrdField { field, .. } if field == "data file"));
    assert!(matches!(
        k(&GOOD.replace("raw", "bzip2"), &body),
        FormatError::NrrdField { field, .. } if field == "encoding"
    ));
    assert!(matches!(
        k(&GOOD.replace("uchar", "short"), &[0; 8]),
        FormatError::NrrdField { field, .. } if field == "endian"
    ));
    assert!(matches!(
        k(&GOOD.replace("uchar", "block"), &body),
        FormatError::VolumeDatatype(_)
    ));
    // Sizes: truncated, trailing, inconsistent count, empty, too large (the body is 4 bytes).
    assert_eq!(
        k(GOOD, &body[..3]),
        FormatError::VolumeTruncated {
            expected: 4,
            found: 3
        }
    );
    assert_eq!(k(GOOD, &[0; 5]), FormatError::TrailingData);
    assert!(matches!(
        k(&GOOD.replace("2 2 1", "2 2"), &body),
        FormatError::NrrdField { field, .. } if field == "sizes"
    ));
    assert_eq!(
        k(&GOOD.replace("2 2 1", "2 0 1"), &body),
        FormatError::EmptyVolume
    );
    assert!(matches!(
        k(&GOOD.replace("2 2 1", "100000 100000 100000"), &body),
        FormatError::VolumeTooLarge { .. }
    ));
    assert!(matches!(
        k(
            &GOOD.replace("2 2 1", "18446744073709551615 18446744073709551615 3"),
            &body
        ),
        FormatError::VolumeTooLarge { .. }
    ));
    // Directions: too few, "none", malformed, singular; origin missing.
    assert!(matches!(
        k(&GOOD.replace(" (0,0,3)", ""), &body),
        FormatError::NrrdField { field, .. } if field == "space directions"
    ));
    assert!(matches!(
        k(&GOOD.replace("(0,0,3)", "none"), &body),
        FormatError::NrrdField { .. }
    ));
    assert!(matches!(
        k(&GOOD.replace("(0,0,3)", "(0,0,x)"), &body),
        FormatError::NrrdField { .. }
    ));
    assert!(matches!(
        k(&GOOD.replace("(0,0,3)", "(0,0,0)"), &body),
        FormatError::VolumeAffine(_)
    ));
    assert!(matches!(
        k(&GOOD.replace("space origin: (10,20,30)\n", ""), &body),
        FormatError::NrrdField { field, problem } if field == "space origin" && problem == "missing"
    ));
    // Labels out of range.
    assert_eq!(
        k(&GOOD.replace("uchar", "char"), &[0, 1, 0xff, 3]),
        FormatError::NotIntegralLabel {
            index: 2,
            value: -1.0
        }
    );
    // A segment in a second layer, a segment without a label value.
    assert!(matches!(
        k(
            &format!("{GOOD}Segment0_Name:=a\nSegment0_LabelValue:=1\nSegment0_Layer:=1\n"),
            &body
        ),
        FormatError::NrrdField { .. }
    ));
    assert!(matches!(
        k(&format!("{GOOD}Segment3_Name:=a\n"), &body),
        FormatError::NrrdField { field, .. } if field == "Segment3_LabelValue"
    ));
    // No blank line before the data, a garbage line, a field twice.
    assert!(matches!(
        kind(&parse_nrrd(format!("NRRD0004\n{GOOD}").as_bytes()).unwrap_err()),
        FormatError::NrrdField { .. }
    ));
    let e = nrrd(&format!("{GOOD}what is this\n"), &body).unwrap_err();
    assert!(e.to_string().starts_with("line 9: "), "{e}");
    assert!(matches!(
        k(&format!("{GOOD}sizes: 2 2 1\n"), &body),
        FormatError::NrrdField { .. }
    ));
}

#[test]
fn unknown_extension_and_missing_file() {
    let e = read_labelmap(Path::new("labels.mha")).unwrap_err();
    assert!(matches!(kind(&e), FormatError::VolumeExtension(_)), "{e}");
    let e = read_labelmap(&fixture("no_such.nii.gz")).unwrap_err();
    assert!(matches!(e, IoError::Io { .. }), "{e}");
}

/// Every prefix and many single-byte corruptions of each fixture give a result or a
/// typed error, never a panic.
#[test]
fn corrupted_fixtures_never_panic() {
    for name in [
        "oblique.nii",
        "int16_be.nii",
        "lps_gzip.nrrd",
        "slicer.seg.nrrd",
    ] {
        let b = bytes(name);
        let parse = |b: &[u8]| {
            if name.ends_with(".nrrd") {
                let _ = parse_nrrd(b);
            } else {
                let _ = parse_nifti(b);
            }
        };
        for cut in (0..b.len()).step_by(7) {
            parse(&b[..cut]);
        }
        for at in (0..b.len().min(600)).step_by(3) {
            for x in [0x00, 0xff, 0x80] {
                let mut c = b.clone();
                c[at] = x;
                parse(&c);
            }
        }
    }
}

/// ribreg's own NIfTI writer (the phantom's labelmap), read back by the reader whose
/// header decoding is the `nifti` crate's: the same voxels at the same places.
#[test]
fn written_nifti_reads_back() {
    let v = crate::phantom::ct::labelmap(&crate::phantom::SubjectParams::template());
    let dir = tempfile::tempdir().unwrap();
    for name in ["seg.nii", "seg.nii.gz"] {
        let path = dir.path().join(name);
        super::write_nifti(&path, &v).unwrap();
        let back = super::read_labelmap(&path).unwrap();
        assert_eq!(back.dims, v.dims);
        assert!(back.labels == v.labels, "labels differ");
        // The affine is stored as f32: within 1e-4 mm over the volume.
        for ijk in [
            [0, 0, 0],
            [v.dims[0] - 1, v.dims[1] - 1, v.dims[2] - 1],
            [17, 3, 40],
        ] {
            let (a, b) = (v.position(ijk), back.position(ijk));
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-3, "{ijk:?}: {a:?} vs {b:?}");
            }
        }
    }
}
