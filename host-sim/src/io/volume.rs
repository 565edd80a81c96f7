//! Labelmap volumes: NIfTI-1 (`.nii`, `.nii.gz`), NRRD (`.nrrd`, Slicer's `.seg.nrrd`) and
//! TotalSegmentator's per-class output directories, read into one [`LabelVolume`] in
//! ribreg's patient frame.
//!
//! # The voxel-to-patient transform
//!
//! Every format gives an affine map from a voxel index `(i, j, k)` (the voxel's centre,
//! `i` varying fastest in the data) to a world point in the system the file declares:
//!
//! - **NIfTI-1** (world = RAS, the standard's "scanner/aligned/talairach/MNI" spaces are all
//!   RAS+). Chosen as the standard's `nifti1.h` and nibabel's `get_best_affine` choose:
//!   method 3 when `sform_code > 0` — the rows `srow_x`, `srow_y`, `srow_z` are
//!   `[linear | offset]`; else method 2 when `qform_code > 0` — the rotation of the unit
//!   quaternion `(a, quatern_b, quatern_c, quatern_d)` with `a = √(1 − b² − c² − d²)`, times
//!   `diag(pixdim[1], pixdim[2], qfac · pixdim[3])` (`qfac = −1` when `pixdim[0] < 0`, else
//!   1), plus `(qoffset_x, qoffset_y, qoffset_z)`; else method 1 —
//!   `diag(pixdim[1..=3])` without offset (as the standard says; nibabel instead centres
//!   an Analyze-style affine there, so files relying on method 1 are better re-saved).
//! - **NRRD** (world = the `space` field, `left-posterior-superior` or
//!   `right-anterior-superior`): the `space directions` vectors are the columns of the
//!   linear part (one vector = one voxel step along that axis) and `space origin` is the
//!   offset. Files without a `space` are refused: nothing says where they are.
//!
//! The world affine is then carried into the patient frame by [`Space::to_patient`],
//! applied to each column of the linear part and to the offset (the conversion is a
//! proper rotation, so no mirror can creep in). [`LabelVolume::space`] keeps the system
//! the file declared, for messages and for writing results back in the file's terms.
//!
//! # Voxel values
//!
//! Labels are `u16`. Stored types `uint8`, `int8`, `uint16`, `int16`, `uint32`, `int32`,
//! `uint64`, `int64`, `float32` and `float64` are read; every value (after NIfTI's
//! `scl_slope`/`scl_inter`, applied when the slope is neither 0 nor the identity `(1, 0)`)
//! must be an integer in `0..=65535`, else a [`FormatError::NotIntegralLabel`] names the
//! voxel. Volumes larger than [`MAX_VOXELS`] are refused before anything is allocated, and
//! compressed data is inflated only up to the size the header declares.

use std::fs;
use std::path::Path;

use super::{read_bytes, FormatError, IoError, Space};

mod nifti;
mod nrrd;
#[cfg(test)]
mod tests;

pub use self::nifti::{nifti_bytes, parse_nifti, write_nifti};
pub use self::nrrd::parse_nrrd;

/// Most voxels a volume may have: 2^28 = 268,435,456, i.e. `labels` takes at most 512 MiB
/// as `u16` (a float64 file's data at most 2 GiB while it is converted). A whole-body CT
/// of 512 × 512 × 1,000 slices (262 Mi voxels) fits; the chest ribreg needs is far smaller.
pub const MAX_VOXELS: usize = 1 << 28;

/// The TotalSegmentator v2 `total` task classes ribreg reads, with their label ids: file
/// `NAME.nii.gz` of a per-class output directory becomes label `ID` of the merged volume.
pub const TOTALSEGMENTATOR: &[(&str, u16)] = &[
    ("rib_left_1", 92),
    ("rib_left_2", 93),
    ("rib_left_3", 94),
    ("rib_left_4", 95),
    ("rib_left_5", 96),
    ("rib_left_6", 97),
    ("rib_left_7", 98),
    ("rib_left_8", 99),
    ("rib_left_9", 100),
    ("rib_left_10", 101),
    ("rib_left_11", 102),
    ("rib_left_12", 103),
    ("rib_right_1", 104),
    ("rib_right_2", 105),
    ("rib_right_3", 106),
    ("rib_right_4", 107),
    ("rib_right_5", 108),
    ("rib_right_6", 109),
    ("rib_right_7", 110),
    ("rib_right_8", 111),
    ("rib_right_9", 112),
    ("rib_right_10", 113),
    ("rib_right_11", 114),
    ("rib_right_12", 115),
    ("sternum", 116),
    ("costal_cartilages", 117),
];

/// Largest difference of two class files' affines (linear part and offset, mm) still
/// taken as "the same grid": files of one TotalSegmentator run have identical headers,
/// this only absorbs float32 round trips through other tools.
const GRID_TOLERANCE_MM: f64 = 1e-4;

/// A labelled voxel volume in ribreg's patient frame.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelVolume {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// One label per voxel, i fastest: `index = i + dims[0] * (j + dims[1] * k)`.
    pub labels: Vec<u16>,
    /// Voxel (i, j, k) centre → patient frame, mm: p = linear · [i, j, k] + offset (row-major 3×3).
    pub linear: [[f64; 3]; 3],
    /// See `linear`.
    pub offset: [f64; 3],
    /// The world system the file declared (Ras for NIfTI; Lps/Ras for NRRD).
    pub space: Space,
    /// Segment names and their label values when the file names them (Slicer `.seg.nrrd`
    /// `SegmentN_Name` / `SegmentN_LabelValue`, in segment order; the classes found in a
    /// TotalSegmentator directory); empty otherwise.
    pub segments: Vec<(String, u16)>,
}

impl LabelVolume {
    /// Patient-frame position of voxel (i, j, k)'s centre.
    pub fn position(&self, ijk: [usize; 3]) -> [f64; 3] {
        let v = ijk.map(|c| c as f64);
        let mut p = self.offset;
        for (pr, row) in p.iter_mut().zip(&self.linear) {
            *pr += row[0] * v[0] + row[1] * v[1] + row[2] * v[2];
        }
        p
    }

    /// Voxel spacing along i, j, k (norms of the columns of `linear`), mm.
    pub fn spacing(&self) -> [f64; 3] {
        let l = &self.linear;
        [0, 1, 2].map(|c| (l[0][c] * l[0][c] + l[1][c] * l[1][c] + l[2][c] * l[2][c]).sqrt())
    }

    /// Index into `labels` of voxel (i, j, k).
    pub fn index(&self, ijk: [usize; 3]) -> usize {
        ijk[0] + self.dims[0] * (ijk[1] + self.dims[1] * ijk[2])
    }
}

/// Read a labelmap by path: `.nii`, `.nii.gz` (gzip), `.nrrd`, `.seg.nrrd`; or a
/// DIRECTORY of TotalSegmentator per-class files (`costal_cartilages.nii.gz`,
/// `sternum.nii.gz`, `rib_left_1.nii.gz` .. `rib_right_12.nii.gz`, any others ignored),
/// merged into one volume with the ids of [`TOTALSEGMENTATOR`] (sternum 116,
/// costal_cartilages 117, rib_left_1..12 = 92..103, rib_right_1..12 = 104..115) and those
/// classes in [`LabelVolume::segments`]. Extensions are matched without regard to case;
/// whether a NIfTI file is gzipped is told by its content (the gzip magic), not its name.
///
/// # Errors
///
/// [`IoError::Io`] if a file or the directory cannot be read; [`IoError::Format`] naming
/// the file for bad content (see [`parse_nifti`], [`parse_nrrd`]), an unknown extension,
/// a directory without class files, class files whose dims or affine differ from the
/// first one read, or two classes claiming one voxel.
pub fn read_labelmap(path: &Path) -> Result<LabelVolume, IoError> {
    if path.is_dir() {
        return read_totalsegmentator(path);
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let parse: fn(&[u8]) -> Result<LabelVolume, IoError> =
        if name.ends_with(".nii") || name.ends_with(".nii.gz") {
            // By content, not name: a `.nii` that is gzipped (or a `.nii.gz` that is not) is
            // common after renaming, and the gzip magic cannot start a NIfTI-1 header (whose
            // first four bytes are 348 in one byte order).
            |bytes: &[u8]| {
                if bytes.starts_with(&[0x1f, 0x8b]) {
                    nifti::parse_nifti_gz(bytes)
                } else {
                    parse_nifti(bytes)
                }
            }
        } else if name.ends_with(".nrrd") {
            parse_nrrd
        } else if name.ends_with(".hdr") || name.ends_with(".img") || name.ends_with(".img.gz") {
            return Err(IoError::from(FormatError::NiftiVersion(
                "a NIfTI/Analyze .hdr/.img pair".into(),
            ))
            .with_path(path));
        } else if name.ends_with(".nhdr") {
            return Err(IoError::from(nrrd::detached()).with_path(path));
        } else {
            return Err(IoError::from(FormatError::VolumeExtension(name)).with_path(path));
        };
    let bytes = read_bytes(path)?;
    parse(&bytes).map_err(|e| e.with_path(path))
}

/// The class files of a TotalSegmentator output directory, merged.
fn read_totalsegmentator(dir: &Path) -> Result<LabelVolume, IoError> {
    let io_err = |source| IoError::Io {
        path: dir.to_path_buf(),
        op: "cannot list",
        source,
    };
    // Class files by name, in TOTALSEGMENTATOR order (not directory order, which the file
    // system chooses), so the result and any error are the same everywhere.
    let mut found: Vec<(usize, std::path::PathBuf)> = Vec::new();
    for entry in fs::read_dir(dir).map_err(io_err)? {
        let entry = entry.map_err(io_err)?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let stem = name
            .strip_suffix(".nii.gz")
            .or_else(|| name.strip_suffix(".nii"));
        if let Some(class) = stem.and_then(|s| TOTALSEGMENTATOR.iter().position(|(n, _)| *n == s)) {
            found.push((class, entry.path()));
        }
    }
    found.sort();
    let mut merged: Option<(LabelVolume, String)> = None;
    for (class, file) in &found {
        let (name, id) = TOTALSEGMENTATOR[*class];
        let part = read_labelmap(file)?;
        let file_name = file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let (volume, reference) = merged.get_or_insert_with(|| {
            let mut first = part.clone();
            first.labels.iter_mut().for_each(|l| *l = 0);
            first.segments.clear();
            (first, file_name.clone())
        });
        let mismatch = |what: String| {
            IoError::from(FormatError::VolumeMismatch {
                what,
                reference: reference.clone(),
            })
            .with_path(file)
        };
        if part.dims != volume.dims {
            let d = |d: [usize; 3]| format!("{}x{}x{}", d[0], d[1], d[2]);
            return Err(mismatch(format!(
                "dims {} vs {}",
                d(part.dims),
                d(volume.dims)
            )));
        }
        let differs = (0..3).any(|r| {
            (part.offset[r] - volume.offset[r]).abs() > GRID_TOLERANCE_MM
                || (0..3)
                    .any(|c| (part.linear[r][c] - volume.linear[r][c]).abs() > GRID_TOLERANCE_MM)
        });
        if differs {
            return Err(mismatch(
                "voxel-to-world affine differs (not one segmentation's grid)".into(),
            ));
        }
        for (index, (out, &v)) in volume.labels.iter_mut().zip(&part.labels).enumerate() {
            if v == 0 {
                continue;
            }
            if *out != 0 {
                let first = TOTALSEGMENTATOR
                    .iter()
                    .find(|(_, l)| *l == *out)
                    .map_or("", |(n, _)| *n);
                return Err(IoError::from(FormatError::LabelOverlap {
                    index,
                    first,
                    second: name,
                })
                .with_path(file));
            }
            *out = id;
        }
        volume.segments.push((name.to_owned(), id));
    }
    match merged {
        Some((volume, _)) => Ok(volume),
        None => Err(IoError::from(FormatError::NoClassFiles).with_path(dir)),
    }
}

/// A voxel-to-world affine: the linear part (row-major) and the offset, mm.
type Affine = ([[f64; 3]; 3], [f64; 3]);

/// A stored voxel type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sample {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
}

impl Sample {
    /// Bytes per voxel.
    fn size(self) -> usize {
        match self {
            Sample::U8 | Sample::I8 => 1,
            Sample::U16 | Sample::I16 => 2,
            Sample::U32 | Sample::I32 | Sample::F32 => 4,
            Sample::U64 | Sample::I64 | Sample::F64 => 8,
        }
    }

    /// The value of one voxel's bytes (`b.len() == self.size()`).
    fn value(self, b: &[u8], big_endian: bool) -> f64 {
        let mut a = [0u8; 8];
        let n = self.size();
        a[..n].copy_from_slice(&b[..n]);
        if big_endian {
            a[..n].reverse();
        }
        let [b0, b1, b2, b3, ..] = a;
        match self {
            Sample::U8 => f64::from(a[0]),
            Sample::I8 => f64::from(a[0] as i8),
            Sample::U16 => f64::from(u16::from_le_bytes([b0, b1])),
            Sample::I16 => f64::from(i16::from_le_bytes([b0, b1])),
            Sample::U32 => f64::from(u32::from_le_bytes([b0, b1, b2, b3])),
            Sample::I32 => f64::from(i32::from_le_bytes([b0, b1, b2, b3])),
            // Labels are at most 65535; larger 64-bit values are refused either way, so the
            // rounding of huge ones to f64 does not matter.
            Sample::U64 => u64::from_le_bytes(a) as f64,
            Sample::I64 => i64::from_le_bytes(a) as f64,
            Sample::F32 => f64::from(f32::from_le_bytes([b0, b1, b2, b3])),
            Sample::F64 => f64::from_le_bytes(a),
        }
    }
}

/// The number of voxels of `dims`, refusing empty and too large volumes.
fn voxel_count(dims: [u64; 3]) -> Result<usize, FormatError> {
    let voxels = dims.iter().fold(1u64, |n, &d| n.saturating_mul(d));
    if voxels == 0 {
        return Err(FormatError::EmptyVolume);
    }
    match usize::try_from(voxels) {
        Ok(n) if n <= MAX_VOXELS => Ok(n),
        _ => Err(FormatError::VolumeTooLarge {
            voxels,
            max: MAX_VOXELS,
        }),
    }
}

/// Labels from raw voxel `data` (exactly `voxels × sample.size()` bytes), each value
/// mapped by `scale` first.
fn labels_from(
    data: &[u8],
    sample: Sample,
    big_endian: bool,
    scale: Option<(f64, f64)>,
) -> Result<Vec<u16>, FormatError> {
    let mut labels = Vec::with_capacity(data.len() / sample.size());
    for (index, b) in data.chunks_exact(sample.size()).enumerate() {
        let mut value = sample.value(b, big_endian);
        if let Some((slope, inter)) = scale {
            value = value * slope + inter;
        }
        labels.push(label(index, value)?);
    }
    Ok(labels)
}

/// `value` as a label: an integer in `0..=65535`.
fn label(index: usize, value: f64) -> Result<u16, FormatError> {
    if value.fract() == 0.0 && (0.0..=65535.0).contains(&value) {
        Ok(value as u16)
    } else {
        Err(FormatError::NotIntegralLabel { index, value })
    }
}

/// The world affine `linear`/`offset` (in `space`) carried into the patient frame, after
/// checking it is finite and invertible.
fn to_patient(
    space: Space,
    linear: [[f64; 3]; 3],
    offset: [f64; 3],
) -> Result<Affine, FormatError> {
    if !linear
        .iter()
        .flatten()
        .chain(&offset)
        .all(|v| v.is_finite())
    {
        return Err(FormatError::VolumeAffine("not finite".into()));
    }
    let l = &linear;
    let det = l[0][0] * (l[1][1] * l[2][2] - l[1][2] * l[2][1])
        - l[0][1] * (l[1][0] * l[2][2] - l[1][2] * l[2][0])
        + l[0][2] * (l[1][0] * l[2][1] - l[1][1] * l[2][0]);
    // Voxels of 1 µm³ have det 1e-9; anything smaller is a degenerate (flat) grid.
    if det.abs() < 1e-12 || !det.is_finite() {
        return Err(FormatError::VolumeAffine(format!(
            "not invertible (determinant {det:e})"
        )));
    }
    let mut out = [[0.0; 3]; 3];
    for c in 0..3 {
        let column = space.to_patient([l[0][c], l[1][c], l[2][c]]);
        for (row, v) in out.iter_mut().zip(column) {
            row[c] = v;
        }
    }
    Ok((out, space.to_patient(offset)))
}
