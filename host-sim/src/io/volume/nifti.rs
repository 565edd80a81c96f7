//! The NIfTI-1 labelmap reader (module docs of [`super`]).
//!
//! The 348-byte header is decoded by the `nifti` crate (both byte orders); which flavours
//! are read (only the `n+1` single file), the dims, the voxel data, the scaling and the
//! affine are checked and computed here.

use std::io::{self, Read, Write};
use std::path::Path;

use flate2::bufread::GzDecoder;
use nifti::{Endianness, NiftiHeader};

use super::{labels_from, to_patient, voxel_count, Affine, LabelVolume, Sample};
use crate::io::{write_atomic, FormatError, IoError, Space};

/// Size of a NIfTI-1 header (its `sizeof_hdr`).
const HEADER_BYTES: usize = 348;
/// `sizeof_hdr` of a NIfTI-2 header.
const NIFTI2_HEADER_BYTES: i32 = 540;
/// Largest `|w|²` deficit of a qform quaternion accepted as rounding (nibabel's: three
/// float32 epsilons), below which `a` is taken as 0.
const QUATERNION_TOLERANCE: f64 = 3.0 * f32::EPSILON as f64;

/// Parse a NIfTI-1 single-file (`n+1`) labelmap from the bytes of a `.nii` file (already
/// gunzipped; [`super::read_labelmap`] handles `.nii.gz`).
///
/// Both byte orders; 3-D volumes (`dim[0]` = 3, or 4..7 with the extra dims 1); datatypes
/// uint8, int8, uint16, int16, uint32, int32, uint64, int64, float32 and float64; the
/// affine from the sform, else the qform, else `pixdim` (module docs of [`super`]), in
/// RAS, converted to the patient frame.
///
/// # Errors
///
/// [`IoError::Format`] (without a path): [`FormatError::NotNifti`] for other data,
/// [`FormatError::NiftiVersion`] for NIfTI-2 and `.hdr`/`.img` headers,
/// [`FormatError::VolumeDimension`], [`FormatError::EmptyVolume`],
/// [`FormatError::VolumeTooLarge`] (before allocating), [`FormatError::VolumeDatatype`],
/// [`FormatError::NiftiField`], [`FormatError::VolumeTruncated`],
/// [`FormatError::NotIntegralLabel`], [`FormatError::VolumeAffine`].
pub fn parse_nifti(bytes: &[u8]) -> Result<LabelVolume, IoError> {
    read(bytes).map_err(IoError::from)
}

/// [`parse_nifti`] of gzip-compressed bytes (a `.nii.gz` file), inflating only as much as
/// the header declares.
pub(super) fn parse_nifti_gz(bytes: &[u8]) -> Result<LabelVolume, IoError> {
    read(GzDecoder::new(bytes)).map_err(IoError::from)
}

/// Read into `buf` until it is full or the input ends; the bytes read.
fn fill(input: &mut impl Read, buf: &mut [u8]) -> Result<usize, FormatError> {
    let mut n = 0;
    while n < buf.len() {
        match input.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            // A slice never fails; only the gzip decoder does.
            Err(e) => return Err(FormatError::Gzip(e.to_string())),
        }
    }
    Ok(n)
}

/// The NIfTI-1 reader over plain or inflating input.
fn read(mut input: impl Read) -> Result<LabelVolume, FormatError> {
    let mut raw = [0u8; HEADER_BYTES];
    let n = fill(&mut input, &mut raw)?;
    if n < 4 {
        return Err(FormatError::NotNifti(format!(
            "{n} bytes, shorter than a header"
        )));
    }
    let sizeof_hdr = [raw[0], raw[1], raw[2], raw[3]];
    let (le, be) = (
        i32::from_le_bytes(sizeof_hdr),
        i32::from_be_bytes(sizeof_hdr),
    );
    if le == NIFTI2_HEADER_BYTES || be == NIFTI2_HEADER_BYTES {
        return Err(FormatError::NiftiVersion("NIfTI-2 (sizeof_hdr 540)".into()));
    }
    if raw.starts_with(&[0x1f, 0x8b]) {
        return Err(FormatError::NotNifti(
            "gzip data (a .nii.gz): decompress it first".into(),
        ));
    }
    if le != HEADER_BYTES as i32 && be != HEADER_BYTES as i32 {
        return Err(FormatError::NotNifti(format!(
            "sizeof_hdr is {le}, not 348 in either byte order"
        )));
    }
    if n < HEADER_BYTES {
        return Err(FormatError::NotNifti(format!(
            "the data ends after {n} of the 348 header bytes"
        )));
    }
    match &raw[344..348] {
        b"n+1\0" => {}
        b"ni1\0" => {
            return Err(FormatError::NiftiVersion(
                "a .hdr/.img pair (magic \"ni1\")".into(),
            ))
        }
        _ => return Err(FormatError::NotNifti("no \"n+1\" magic at byte 344".into())),
    }
    let h = NiftiHeader::from_reader(&raw[..]).map_err(|e| FormatError::NotNifti(e.to_string()))?;
    let big_endian = h.endianness == Endianness::Big;

    let dims = dims(&h)?;
    let voxels = voxel_count(dims.map(|d| d as u64))?;
    let sample = sample(h.datatype)?;
    let scale = scale(&h)?;
    let (linear, offset) = affine(&h)?;
    let (linear, offset) = to_patient(Space::Ras, linear, offset)?;

    let vox_offset = f64::from(h.vox_offset);
    if !(vox_offset.is_finite()
        && vox_offset.fract() == 0.0
        && (HEADER_BYTES as f64..=f64::from(u32::MAX)).contains(&vox_offset))
    {
        return Err(FormatError::NiftiField {
            field: "vox_offset",
            problem: format!("{vox_offset} is not a byte offset of at least 348"),
        });
    }
    // Extensions between the header and the data are skipped, not read.
    let skip = vox_offset as u64 - HEADER_BYTES as u64;
    let expected = (voxels * sample.size()) as u64;
    let skipped = io::copy(&mut input.by_ref().take(skip), &mut io::sink())
        .map_err(|e| FormatError::Gzip(e.to_string()))?;
    if skipped < skip {
        return Err(FormatError::VolumeTruncated { expected, found: 0 });
    }
    // Grows with the bytes actually present, never beyond what the header declares.
    let mut data = Vec::new();
    input
        .take(expected)
        .read_to_end(&mut data)
        .map_err(|e| FormatError::Gzip(e.to_string()))?;
    if (data.len() as u64) < expected {
        return Err(FormatError::VolumeTruncated {
            expected,
            found: data.len() as u64,
        });
    }
    Ok(LabelVolume {
        dims,
        labels: labels_from(&data, sample, big_endian, scale)?,
        linear,
        offset,
        space: Space::Ras,
        segments: Vec::new(),
    })
}

/// The three voxel counts, for a 3-D volume (`dim[0]` of 3, or more with the extra dims 1).
fn dims(h: &NiftiHeader) -> Result<[usize; 3], FormatError> {
    // NIfTI-1 stores dims as signed shorts; the crate hands them out as `u16`.
    let dim = h.dim.map(|d| d as i16);
    let rank = dim[0];
    if !(3..=7).contains(&rank) {
        return Err(FormatError::VolumeDimension(format!(
            "NIfTI dim[0] is {rank}: not a 3-D volume (a labelmap has dim[0] = 3)"
        )));
    }
    for (axis, &d) in dim.iter().enumerate().take(rank as usize + 1).skip(4) {
        if d != 1 {
            return Err(FormatError::VolumeDimension(format!(
                "NIfTI dim[{axis}] is {d}: a {rank}-D series, not one labelmap \
                 (save a single 3-D volume)"
            )));
        }
    }
    let mut out = [0; 3];
    for (axis, o) in out.iter_mut().enumerate() {
        let d = dim[axis + 1];
        *o = usize::try_from(d).map_err(|_| FormatError::NiftiField {
            field: "dim",
            problem: format!("dim[{}] is {d}", axis + 1),
        })?;
    }
    Ok(out)
}

/// The voxel type of a NIfTI `datatype` code.
fn sample(datatype: i16) -> Result<Sample, FormatError> {
    Ok(match datatype {
        2 => Sample::U8,
        4 => Sample::I16,
        8 => Sample::I32,
        16 => Sample::F32,
        64 => Sample::F64,
        256 => Sample::I8,
        512 => Sample::U16,
        768 => Sample::U32,
        1024 => Sample::I64,
        1280 => Sample::U64,
        other => {
            let name = match other {
                1 => " (binary)",
                32 => " (complex64)",
                128 => " (rgb24)",
                1536 => " (float128)",
                1792 => " (complex128)",
                2048 => " (complex256)",
                2304 => " (rgba32)",
                _ => "",
            };
            return Err(FormatError::VolumeDatatype(format!(
                "NIfTI datatype {other}{name}"
            )));
        }
    })
}

/// `(slope, intercept)` when the header scales its values: a slope other than 0 (which
/// the standard reserves for "no scaling") and than the identity `(1, 0)`. A non-finite
/// slope is taken as no scaling, as nibabel does.
fn scale(h: &NiftiHeader) -> Result<Option<(f64, f64)>, FormatError> {
    let (slope, inter) = (f64::from(h.scl_slope), f64::from(h.scl_inter));
    if slope == 0.0 || !slope.is_finite() || (slope == 1.0 && inter == 0.0) {
        return Ok(None);
    }
    if !inter.is_finite() {
        return Err(FormatError::NiftiField {
            field: "scl_inter",
            problem: format!("{inter} is not finite"),
        });
    }
    Ok(Some((slope, inter)))
}

/// `pixdim[1..=3]`, each finite and positive.
fn voxel_size(h: &NiftiHeader) -> Result<[f64; 3], FormatError> {
    let mut out = [0.0; 3];
    for (axis, o) in out.iter_mut().enumerate() {
        let d = f64::from(h.pixdim[axis + 1]);
        if !(d.is_finite() && d > 0.0) {
            return Err(FormatError::NiftiField {
                field: "pixdim",
                problem: format!("pixdim[{}] is {d}, not a positive voxel size", axis + 1),
            });
        }
        *o = d;
    }
    Ok(out)
}

/// The voxel-to-RAS affine `(linear, offset)`: sform, else qform, else pixdim.
fn affine(h: &NiftiHeader) -> Result<Affine, FormatError> {
    if h.sform_code > 0 {
        let rows = [h.srow_x, h.srow_y, h.srow_z].map(|r| r.map(f64::from));
        let linear = rows.map(|r| [r[0], r[1], r[2]]);
        return Ok((linear, rows.map(|r| r[3])));
    }
    let size = voxel_size(h)?;
    if h.qform_code <= 0 {
        let mut linear = [[0.0; 3]; 3];
        for (axis, row) in linear.iter_mut().enumerate() {
            row[axis] = size[axis];
        }
        return Ok((linear, [0.0; 3]));
    }
    let [b, c, d] = [h.quatern_b, h.quatern_c, h.quatern_d].map(f64::from);
    let w2 = 1.0 - (b * b + c * c + d * d);
    if w2 < -QUATERNION_TOLERANCE {
        return Err(FormatError::NiftiField {
            field: "quatern_b/c/d",
            problem: format!("({b}, {c}, {d}) is longer than a unit quaternion's"),
        });
    }
    let a = w2.max(0.0).sqrt();
    // The rotation of the unit quaternion (a, b, c, d), normalised as nibabel's quat2mat.
    let s = 2.0 / (a * a + b * b + c * c + d * d);
    let (x, y, z) = (b * s, c * s, d * s);
    let rotation = [
        [1.0 - (c * y + d * z), b * y - a * z, b * z + a * y],
        [b * y + a * z, 1.0 - (b * x + d * z), c * z - a * x],
        [b * z - a * y, c * z + a * x, 1.0 - (b * x + c * y)],
    ];
    let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
    let scale = [size[0], size[1], qfac * size[2]];
    let linear = rotation.map(|row| [0, 1, 2].map(|col| row[col] * scale[col]));
    let offset = [h.quatern_x, h.quatern_y, h.quatern_z].map(f64::from);
    Ok((linear, offset))
}

// ---------------------------------------------------------------------------------------
// Writing: a single-file `n+1` image of `uint8` (labels ≤ 255) or `uint16` labels, with
// the voxel → RAS affine in the `sform` (code 1, scanner) and the `qform` unset — how
// TotalSegmentator writes its masks.
// ---------------------------------------------------------------------------------------

/// The NIfTI-1 bytes of `volume` (uncompressed).
///
/// # Errors
/// [`FormatError::NoPoints`] for an empty volume; `TooManyVertices` for a dimension
/// above NIfTI-1's `i16` limit (32767).
pub fn nifti_bytes(volume: &LabelVolume) -> Result<Vec<u8>, IoError> {
    let n: usize = volume.dims.iter().product();
    if n == 0 || volume.labels.len() != n {
        return Err(FormatError::NoPoints.into());
    }
    let mut dims = [0i16; 3];
    for (d, &v) in dims.iter_mut().zip(&volume.dims) {
        *d = i16::try_from(v).map_err(|_| FormatError::TooManyVertices(v))?;
    }
    let wide = volume.labels.iter().any(|&l| l > 255);
    let mut h = vec![0u8; 352];
    let put_i16 = |h: &mut [u8], at: usize, v: i16| h[at..at + 2].copy_from_slice(&v.to_le_bytes());
    let put_f32 = |h: &mut [u8], at: usize, v: f32| h[at..at + 4].copy_from_slice(&v.to_le_bytes());
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    for (k, v) in [3, dims[0], dims[1], dims[2], 1, 1, 1, 1]
        .into_iter()
        .enumerate()
    {
        put_i16(&mut h, 40 + 2 * k, v);
    }
    // datatype: 2 = uint8, 512 = uint16; bitpix.
    put_i16(&mut h, 70, if wide { 512 } else { 2 });
    put_i16(&mut h, 72, if wide { 16 } else { 8 });
    let spacing = volume.spacing();
    put_f32(&mut h, 76, 1.0); // qfac
    for (k, s) in spacing.iter().enumerate() {
        put_f32(&mut h, 80 + 4 * k, *s as f32);
    }
    put_f32(&mut h, 108, 352.0); // vox_offset
    put_f32(&mut h, 112, 1.0); // scl_slope
    h[123] = 2; // xyzt_units: mm
    h[148..148 + 25].copy_from_slice(b"ribreg phantom labelmap\0\0");
    put_i16(&mut h, 254, 1); // sform_code: scanner
                             // The affine in RAS: the patient-frame columns and offset taken into RAS.
    let column = |a: usize| Space::Ras.from_patient([0, 1, 2].map(|r| volume.linear[r][a]));
    let offset = Space::Ras.from_patient(volume.offset);
    let cols = [column(0), column(1), column(2)];
    for r in 0..3 {
        for (a, col) in cols.iter().enumerate() {
            put_f32(&mut h, 280 + 16 * r + 4 * a, col[r] as f32);
        }
        put_f32(&mut h, 280 + 16 * r + 12, offset[r] as f32);
    }
    h[344..348].copy_from_slice(b"n+1\0");
    let mut out = h;
    out.reserve(n * if wide { 2 } else { 1 });
    for &l in &volume.labels {
        if wide {
            out.extend_from_slice(&l.to_le_bytes());
        } else {
            // ≤ 255: checked above.
            out.push(l as u8);
        }
    }
    Ok(out)
}

/// Write `volume` to `path` as NIfTI-1, gzip-compressed when the name ends in `.gz`,
/// atomically.
///
/// # Errors
/// Those of [`nifti_bytes`], with the path; [`IoError::Io`] if the file cannot be
/// written.
pub fn write_nifti(path: &Path, volume: &LabelVolume) -> Result<(), IoError> {
    let bytes = nifti_bytes(volume).map_err(|e| e.with_path(path))?;
    let gz = path.to_string_lossy().ends_with(".gz");
    write_atomic(path, |out| {
        if gz {
            let mut enc = flate2::write::GzEncoder::new(out, flate2::Compression::fast());
            enc.write_all(&bytes)?;
            enc.finish()?;
            Ok(())
        } else {
            out.write_all(&bytes)
        }
    })
}
