//! Writing a [`LabelVolume`] as NIfTI-1 (`.nii`, or `.nii.gz` by the extension): a
//! single-file `n+1` image of `uint8` (labels ≤ 255) or `uint16` labels, with the
//! voxel → RAS affine in the `sform` (code 1, scanner) and the `qform` unset — how
//! TotalSegmentator writes its masks.

use std::io::Write;
use std::path::Path;

use super::volume::LabelVolume;
use super::{write_atomic, FormatError, IoError, Space};

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
