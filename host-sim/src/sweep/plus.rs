//! Real sweeps in: PLUS sequence files whose images are bone masks, with a PLUS
//! calibration (`ribreg compound --sequence`, `ribreg calibrate temporal --sequence`);
//! and the phantom's sweeps written the same way (`ribreg phantom sweep` writes
//! `sweep.seq.mha`, `calib.seq.mha` and `plus_config.xml`) so the two paths can be
//! compared. The files are read and written by [`crate::io::plus`].
//!
//! # Frames: PLUS → ribreg
//! PLUS places an image pixel in the tracker frame by
//! `ImageToTracker = ProbeToTracker · ImageToProbe`; ribreg by
//! `b_T_us = b_T_ee · ee_T_tcp · tcp_T_us` after the pixel scale
//! ([`ribreg_core::acquisition::probe`]). Read from a sequence:
//! * `Tracker` (or `Reference`, whatever the transform's `To` names) is the base `{b}`;
//! * the per-frame transform (`ProbeToTracker` by default) is the pose chain
//!   `b_T_ee · ee_T_tcp`, so `ee_T_tcp` = identity and `b_T_ee` = `ProbeToTracker`
//!   (with `--probe probe.json` instead of a PLUS configuration, the transform is taken
//!   as the flange pose `b_T_ee` and `probe.json`'s `ee_T_tcp` and `tcp_T_us` apply);
//! * `ImageToProbe` = `[A | t]`, `A = R · diag(s_x, s_y, s_z)`, is `tcp_T_us` with the
//!   pixel scale inside it: `s_x = |a₀|`, `s_y = |a₁|` (mm per pixel along a row and down
//!   a column; the columns `aᵢ` of `A`), `R` = the normalised columns (a proper rotation,
//!   within [`ribreg_core::math::geom::ROTATION_TOLERANCE`]; a zero third column is completed
//!   by `a₀ × a₁`).
//!
//! The pixel origins differ by half a pixel. PLUS's `Image` frame has its origin at the
//! *centre* of the first pixel of the `MF` image (PLUS: "position of the pixel that is in
//! the origin of the MF oriented image"; VTK image coordinates put pixel `(i, j)` at
//! `(i, j)`), `x` along increasing column (towards the marked side), `y` along increasing
//! row (away from the probe), in pixels. ribreg's image frame has its origin at the
//! top-left *corner*: pixel `(i, j)` covers `[i, i+1) × [j, j+1)`, its centre is
//! `(u, v) = (i + ½, j + ½)`, and `(u, v)` maps to `(u·s_x, v·s_y, 0)` mm. So PLUS's
//! `(x, y)` is ribreg's `(u, v) = (x + ½, y + ½)`, and
//! `ImageToProbe · (u − ½, v − ½, 0, 1) = R · (u·s_x, v·s_y, 0) + t − ½(a₀ + a₁)`:
//! `tcp_T_us = (R, t − ½(a₀ + a₁))`, `footprint = width · s_x`, `depth = height · s_y`
//! ([`calibration_from_plus`]; [`plus_image_to_probe`] is its inverse). The Python fixture
//! of `tests/plus.rs` checks this against PLUS's own formula, pixel by pixel.
//!
//! # Bone pixels
//! Each mask frame (re-oriented to `MF` by the reader: row 0 at the probe face) gives, per
//! column, its first mask pixel (non-zero) counted from the probe side (the near field):
//! the bone surface the beam meets first, exactly as `ribreg phantom sweep` annotates a
//! frame (per column, the first surface along the beam). The pixel `(i, j)` becomes the
//! bone pixel `(u, v) = (i + ½, j + ½)` (its centre). Deeper mask pixels of the column
//! (the bone's thickness, acoustic shadow painted in) are ignored.
//!
//! # Time
//! In a PLUS file the image and the pose of a frame share one time stamp: PLUS has
//! already interpolated the tracker stream at the frame's time (after applying the
//! devices' `LocalTimeOffsetSec`). ribreg feeds the same core path as the CSV logs
//! ([`super::compound`]): the per-frame transforms are the tracker stream (one pose per
//! frame, stamped `Timestamp`), the masks the video stream (stamped `Timestamp` as well),
//! and a frame is placed with the pose interpolated at `Timestamp − lag`, the CSV
//! convention (positive lag: the video lags the tracker). With `--lag-ms 0` each frame
//! gets exactly its own transform (the right choice when PLUS's temporal calibration was
//! applied at recording). With another lag the pose comes from the neighbouring frames'
//! transforms, so the pose stream is only as dense as the frame rate: across a gap above
//! [`ribreg_core::acquisition::track::MAX_TRACK_GAP_MS`] (a skipped frame at 30 fps; every interval
//! below 20 fps) the frame is refused and counted, never extrapolated.
//!
//! # Temporal calibration from a sequence
//! A calibration sweep recorded by PLUS *without* a time offset applied (both devices at
//! `LocalTimeOffsetSec = 0`) pairs each image, stamped `t` on the video clock, with the
//! tracker interpolated at `t` on the tracker clock, while the image shows the probe
//! where it was at `t − lag`: the two streams in the file still carry the lag, sampled
//! at the frame times only. [`calibrate_temporal_sequence`] takes the transforms'
//! translations as the tracker stream and each mask's landmark row (the mean over
//! columns of the first mask pixel's centre row) as the video stream and runs the core's
//! cross-correlation ([`ribreg_core::acquisition::temporal`]). What is lost against the raw streams
//! PLUS's own temporal calibration (fCal) uses: the tracker is sampled at ~30 Hz instead
//! of its own rate (linear interpolation between frames smooths a 1.3 Hz motion by
//! < 0.01 mm), and PLUS's interpolation of the tracker has already happened. A sequence
//! recorded *with* an offset applied yields the residual lag only. The phantom's
//! `calib.seq.mha` is written as the offset-free recording.

use ribreg_core::math::geom::ROTATION_TOLERANCE;
use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use ribreg_core::acquisition::probe::{Calibration, ProbeModel};
use ribreg_core::acquisition::temporal::{self, LagEstimate, TrackerSample, VideoSample};
use ribreg_core::math::geom::Rigid;
use ribreg_core::Vec3;

use super::{CompoundOutcome, FrameRow, PoseRow, ProbeFile, SweepLogs};
use crate::error::CliError;
use crate::io::plus::{
    read_plus_transform, write_plus_config, FrameOut, Matrix4, Orientation, PlusConfigError,
    SequenceError, SequenceInfo, SequenceReader, SequenceSpec, SequenceWriter, Status,
};

/// The per-frame transform read by default.
pub const DEFAULT_TRANSFORM: &str = "ProbeToTracker";
/// The phantom's scan as a PLUS sequence.
pub const SWEEP_SEQUENCE: &str = "sweep.seq.mha";
/// The phantom's temporal-calibration sweep as a PLUS sequence.
pub const CALIB_SEQUENCE: &str = "calib.seq.mha";
/// The phantom's spatial calibration as a PLUS device-set configuration.
pub const PLUS_CONFIG: &str = "plus_config.xml";
/// Mask value of a bone pixel in the sequences ribreg writes (any non-zero is read as
/// bone).
pub const BONE: u8 = 255;

impl From<SequenceError> for CliError {
    fn from(e: SequenceError) -> Self {
        CliError::value(e.to_string())
    }
}

impl From<PlusConfigError> for CliError {
    fn from(e: PlusConfigError) -> Self {
        CliError::value(e.to_string())
    }
}

/// A frame the simulated probe captured, lost or logged (the PLUS sequences hold every
/// one: a lost frame is written with status `INVALID` and an empty mask).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CapturedFrame {
    /// Frame number.
    pub frame: u32,
    /// Video time stamp, s.
    pub t: f64,
    /// Lost (not in `frames.csv` / `calib_video.csv`).
    pub lost: bool,
}

/// Where the spatial calibration of a sequence comes from.
#[derive(Clone, Copy, Debug)]
pub enum Spatial<'a> {
    /// A PLUS device-set configuration with `Image` → probe (the transform's `From`).
    PlusConfig(&'a Path),
    /// ribreg's `probe.json`; the per-frame transform is then the flange pose `b_T_ee`.
    Probe(&'a Path),
}

/// What became of a sequence's frames.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SequenceCounts {
    /// Frames in the file.
    pub frames: u32,
    /// Frames used (transform and image status OK).
    pub used: u32,
    /// Frames skipped because the transform's status is not OK, by status.
    pub skipped_status: BTreeMap<&'static str, u32>,
    /// Frames skipped because the image status is not OK.
    pub skipped_image: u32,
    /// Used frames whose mask has no bone pixel.
    pub without_bone: u32,
    /// Bone pixels (one per column at most).
    pub pixels: u64,
}

impl SequenceCounts {
    /// Counts one frame; its transform when both statuses are OK, else `None` (the
    /// frame is skipped and counted by reason).
    fn admit(
        &mut self,
        status: Status,
        image: Status,
        transform: Option<Matrix4>,
    ) -> Option<Matrix4> {
        self.frames += 1;
        match (status, image, transform) {
            (Status::Ok, Status::Ok, Some(m)) => {
                self.used += 1;
                Some(m)
            }
            (Status::Ok, _, _) => {
                self.skipped_image += 1;
                None
            }
            (s, _, _) => {
                *self.skipped_status.entry(s.name()).or_insert(0) += 1;
                None
            }
        }
    }

    /// Frames skipped for a status.
    pub fn skipped(&self) -> u32 {
        self.skipped_status.values().sum::<u32>() + self.skipped_image
    }

    /// One line for the user.
    pub fn summary(&self) -> String {
        let by: Vec<String> = self
            .skipped_status
            .iter()
            .map(|(k, v)| format!("{v} {k}"))
            .collect();
        format!(
            "{} frames: {} used, {} skipped (transform status not OK: {}; image status not OK: \
             {}); {} used frames without a bone pixel; {} bone pixels",
            self.frames,
            self.used,
            self.skipped(),
            if by.is_empty() {
                "0".to_string()
            } else {
                by.join(", ")
            },
            self.skipped_image,
            self.without_bone,
            self.pixels
        )
    }
}

/// Per column of a `width`-wide `MF` mask, the first non-zero pixel from row 0 (the probe
/// face): `(column, row)` pairs in column order, into `out` (cleared first).
pub fn bone_pixels(mask: &[u8], width: usize, out: &mut Vec<(u16, u16)>) {
    out.clear();
    if width == 0 {
        return;
    }
    let mut row_of: Vec<Option<u16>> = vec![None; width];
    let mut left = width;
    for (r, row) in mask.chunks_exact(width).enumerate() {
        if row.iter().all(|&b| b == 0) {
            continue;
        }
        for (c, &b) in row.iter().enumerate() {
            if b != 0 && row_of[c].is_none() {
                // Note: rows and columns fit u16 (the reader caps them at 4,096).
                row_of[c] = Some(r as u16);
                left -= 1;
            }
        }
        if left == 0 {
            break;
        }
    }
    out.extend(
        row_of
            .iter()
            .enumerate()
            .filter_map(|(c, r)| r.map(|r| (c as u16, r))),
    );
}

/// The `From` frame of a transform name `<From>To<To>` (`ProbeToTracker` → `Probe`): the
/// text before the first `To` that starts a capitalised word after the first character.
pub fn from_frame(transform: &str) -> Option<&str> {
    let b = transform.as_bytes();
    (1..b.len().saturating_sub(2))
        .find(|&i| b[i] == b'T' && b[i + 1] == b'o' && b[i + 2].is_ascii_uppercase())
        .map(|i| &transform[..i])
}

/// ribreg's calibration of a PLUS `ImageToProbe` for `width × height` images (module
/// docs: `tcp_T_us = (R, t − ½(a₀ + a₁))`, `ee_T_tcp` = identity).
pub fn calibration_from_plus(
    image_to_probe: &Matrix4,
    width: u16,
    height: u16,
) -> Result<Calibration, String> {
    let m = image_to_probe;
    let col = |j: usize| Vector3::new(m[0][j], m[1][j], m[2][j]);
    let (a0, a1, a2) = (col(0), col(1), col(2));
    let (sx, sy) = (a0.norm(), a1.norm());
    if !(sx > 0.0 && sy > 0.0 && sx.is_finite() && sy.is_finite()) {
        return Err(format!(
            "ImageToProbe has no pixel scale (column norms {sx:.4}, {sy:.4} mm/pixel)"
        ));
    }
    let z = if a2.norm() > 1e-12 * sx.max(sy) {
        a2.normalize()
    } else {
        a0.cross(&a1).normalize()
    };
    let r = Matrix3::from_columns(&[a0 / sx, a1 / sy, z]);
    let ortho = (r.transpose() * r - Matrix3::identity()).amax();
    let det = r.determinant();
    if ortho > f64::from(ROTATION_TOLERANCE) || (det - 1.0).abs() > f64::from(ROTATION_TOLERANCE) {
        let angle = (a0.dot(&a1) / (sx * sy))
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        return Err(format!(
            "ImageToProbe's rotation part is not a rotation times a pixel scale: its normalised \
             columns deviate from orthonormal by {ortho:.2e} (image x and y {angle:.3}° apart), \
             determinant {det:.4} (expected within {ROTATION_TOLERANCE} of orthonormal and of \
             +1; a negative determinant is a mirror: the image orientation or the calibration \
             is flipped)"
        ));
    }
    let t = Vector3::new(m[0][3], m[1][3], m[2][3]) - 0.5 * (a0 + a1);
    let probe = ProbeModel {
        width_px: width,
        height_px: height,
        footprint_mm: (f64::from(width) * sx) as f32,
        depth_mm: (f64::from(height) * sy) as f32,
    };
    let cal = Calibration {
        probe,
        tcp_t_us: Rigid {
            rotation: r.cast::<f32>(),
            translation: t.cast::<f32>(),
        },
        ee_t_tcp: Rigid::identity(),
    };
    cal.validate().map_err(|e| format!("ImageToProbe: {e}"))?;
    Ok(cal)
}

/// PLUS's `ImageToProbe` of a calibration whose probe frame is the TCP (inverse of
/// [`calibration_from_plus`]; the third column gets the mean in-plane scale).
pub fn plus_image_to_probe(cal: &Calibration) -> Matrix4 {
    let (sx, sy) = cal.probe.scale();
    let (sx, sy) = (f64::from(sx), f64::from(sy));
    let r: Matrix3<f64> = cal.tcp_t_us.rotation.cast();
    let a0 = r.column(0) * sx;
    let a1 = r.column(1) * sy;
    let a2 = r.column(2) * (0.5 * (sx + sy));
    let t = cal.tcp_t_us.translation.cast::<f64>() + 0.5 * (a0 + a1);
    let mut m = [[0.0; 4]; 4];
    for i in 0..3 {
        m[i] = [a0[i], a1[i], a2[i], t[i]];
    }
    m[3][3] = 1.0;
    m
}

/// A matrix's rotation and translation, if the rotation part is proper within
/// [`ROTATION_TOLERANCE`].
fn rigid_parts(m: &Matrix4) -> Result<(UnitQuaternion<f64>, Vector3<f64>), String> {
    let r = Matrix3::from_fn(|i, j| m[i][j]);
    let ortho = (r.transpose() * r - Matrix3::identity()).amax();
    let det = r.determinant();
    if ortho > f64::from(ROTATION_TOLERANCE) || (det - 1.0).abs() > f64::from(ROTATION_TOLERANCE) {
        let norms: Vec<String> = (0..3)
            .map(|j| format!("{:.4}", r.column(j).norm()))
            .collect();
        return Err(format!(
            "not a rigid transform (column norms {}, determinant {det:.4}): a tracker pose has \
             no scale and no mirror; is it an image transform (ImageTo...)?",
            norms.join(", ")
        ));
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Ok((q, Vector3::new(m[0][3], m[1][3], m[2][3])))
}

/// A `poses.csv` row of a per-frame transform.
pub fn pose_row(t: f64, m: &Matrix4) -> Result<PoseRow, String> {
    let (q, p) = rigid_parts(m)?;
    Ok(PoseRow {
        t,
        position: [p.x, p.y, p.z],
        quaternion: [q.w, q.i, q.j, q.k],
    })
}

/// The 4 × 4 matrix of an isometry.
pub fn matrix_of(iso: &Isometry3<f64>) -> Matrix4 {
    let h = iso.to_homogeneous();
    std::array::from_fn(|i| std::array::from_fn(|j| h[(i, j)]))
}

/// A sweep read from a sequence: what [`super::compound`] takes, and the counts.
#[derive(Clone, Debug)]
pub struct SweepSequence {
    /// What the header says.
    pub info: SequenceInfo,
    /// The spatial calibration.
    pub calibration: Calibration,
    /// One pose per used frame (`b_T_ee`, stamped `Timestamp`).
    pub poses: Vec<PoseRow>,
    /// The bone pixels of the used frames (stamped `Timestamp`).
    pub frames: Vec<FrameRow>,
    /// What became of the frames.
    pub counts: SequenceCounts,
}

/// Reads a sweep sequence (module docs): every frame with transform and image status OK
/// gives a pose and its bone pixels; the others are skipped and counted.
pub fn read_sweep_sequence(
    path: &Path,
    transform: &str,
    spatial: Spatial<'_>,
) -> Result<SweepSequence, CliError> {
    let mut reader = SequenceReader::open(path, transform)?;
    let info = reader.info().clone();
    let calibration = match spatial {
        Spatial::PlusConfig(config) => {
            let probe = from_frame(transform).ok_or_else(|| {
                CliError::value(format!(
                    "--transform {transform}: expected a name <From>To<To> such as \
                     ProbeToTracker (the config's Image → <From> is the calibration)"
                ))
            })?;
            let m = read_plus_transform(config, "Image", probe)?;
            calibration_from_plus(&m, info.width, info.height)
                .map_err(|e| CliError::input(config, e.to_string()))?
        }
        Spatial::Probe(probe) => {
            let cal = ProbeFile::read(probe)?;
            if (cal.probe.width_px, cal.probe.height_px) != (info.width, info.height) {
                return Err(CliError::value(format!(
                    "{}: the probe image is {} × {} pixels, the frames of {} are {} × {}",
                    probe.display(),
                    cal.probe.width_px,
                    cal.probe.height_px,
                    path.display(),
                    info.width,
                    info.height
                )));
            }
            cal
        }
    };
    let width = usize::from(info.width);
    let mut counts = SequenceCounts::default();
    let mut poses = Vec::new();
    let mut frames = Vec::new();
    let mut pixels = Vec::new();
    while let Some(f) = reader.next_frame()? {
        let Some(m) = counts.admit(f.status, f.image_status, f.transform) else {
            continue;
        };
        let pose = pose_row(f.timestamp, &m).map_err(|e| {
            CliError::value(format!(
                "{}: frame {}: {transform}Transform is {e}",
                path.display(),
                f.index
            ))
        })?;
        poses.push(pose);
        bone_pixels(f.mask, width, &mut pixels);
        if pixels.is_empty() {
            counts.without_bone += 1;
        }
        counts.pixels += pixels.len() as u64;
        frames.extend(pixels.iter().map(|&(c, r)| FrameRow {
            frame: f.index,
            t: f.timestamp,
            u: f64::from(c) + 0.5,
            v: f64::from(r) + 0.5,
        }));
    }
    Ok(SweepSequence {
        info,
        calibration,
        poses,
        frames,
        counts,
    })
}

/// [`read_sweep_sequence`] then [`super::compound`], the CSV path's compounder.
pub fn compound_sequence(
    path: &Path,
    transform: &str,
    spatial: Spatial<'_>,
    lag_s: f64,
    voxel_mm: f32,
) -> Result<(CompoundOutcome, SweepSequence), CliError> {
    let s = read_sweep_sequence(path, transform, spatial)?;
    let o = super::compound(&s.calibration, lag_s, voxel_mm, &s.poses, &s.frames)?;
    Ok((o, s))
}

/// The landmark row of a mask: the mean centre row of the first mask pixel of every
/// column that has one, `None` if none has.
pub fn landmark_row(pixels: &[(u16, u16)]) -> Option<f64> {
    (!pixels.is_empty())
        .then(|| pixels.iter().map(|&(_, r)| f64::from(r) + 0.5).sum::<f64>() / pixels.len() as f64)
}

/// The tracker samples (the transforms' translations) and video samples (landmark rows)
/// of a calibration sequence, and the counts.
pub fn calibration_sequence_samples(
    path: &Path,
    transform: &str,
) -> Result<(Vec<TrackerSample>, Vec<VideoSample>, SequenceCounts), CliError> {
    let mut reader = SequenceReader::open(path, transform)?;
    let width = usize::from(reader.info().width);
    let (mut tracker, mut video, mut counts) = (Vec::new(), Vec::new(), SequenceCounts::default());
    let mut pixels = Vec::new();
    while let Some(f) = reader.next_frame()? {
        let Some(m) = counts.admit(f.status, f.image_status, f.transform) else {
            continue;
        };
        tracker.push(TrackerSample {
            t: f.timestamp,
            position: Vec3::new(m[0][3] as f32, m[1][3] as f32, m[2][3] as f32),
        });
        bone_pixels(f.mask, width, &mut pixels);
        counts.pixels += pixels.len() as u64;
        match landmark_row(&pixels) {
            Some(row) => video.push(VideoSample {
                t: f.timestamp,
                row: row as f32,
            }),
            None => counts.without_bone += 1,
        }
    }
    Ok((tracker, video, counts))
}

/// Temporal calibration from a calibration sequence (module docs).
pub fn calibrate_temporal_sequence(
    path: &Path,
    transform: &str,
) -> Result<(LagEstimate, SequenceCounts), CliError> {
    let (tracker, video, counts) = calibration_sequence_samples(path, transform)?;
    let est =
        temporal::calibrate(&tracker, &video).map_err(|e| CliError::input(path, e.to_string()))?;
    Ok((est, counts))
}

/// One frame of a phantom sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct PhantomFrame {
    /// Frame number.
    pub frame: u32,
    /// Video time stamp, s.
    pub t: f64,
    /// `ProbeToTracker` (`None`: status `INVALID`).
    pub transform: Option<Matrix4>,
    /// Mask pixels `(column, row)` set to [`BONE`].
    pub pixels: Vec<(u16, u16)>,
}

/// The mask pixel of a bone pixel `(u, v)`: the pixel containing it (a row on the bottom
/// edge, `v = height`, goes to the last row).
fn mask_pixel(u: f64, v: f64, probe: &ProbeModel) -> (u16, u16) {
    let c = (u.floor().max(0.0) as u16).min(probe.width_px - 1);
    let r = (v.floor().max(0.0) as u16).min(probe.height_px - 1);
    (c, r)
}

/// `b_T_ee` interpolated at `t` between the pose rows around it (lerp, slerp: what PLUS
/// does to the tracker stream at a frame's time), `None` outside them.
fn pose_at(poses: &[PoseRow], t: f64) -> Option<Isometry3<f64>> {
    let iso = |p: &PoseRow| {
        let [w, i, j, k] = p.quaternion;
        Isometry3::from_parts(
            Translation3::new(p.position[0], p.position[1], p.position[2]),
            UnitQuaternion::new_normalize(nalgebra::Quaternion::new(w, i, j, k)),
        )
    };
    let n = poses.partition_point(|p| p.t <= t);
    if n == 0 || (n == poses.len() && t > poses[n - 1].t) {
        return None;
    }
    if n == poses.len() || poses[n - 1].t == t {
        return Some(iso(&poses[n - 1]));
    }
    let (a, b) = (&poses[n - 1], &poses[n]);
    let s = (t - a.t) / (b.t - a.t);
    Some(iso(a).lerp_slerp(&iso(b), s))
}

/// The scan of `logs` as PLUS would record it with no time offset applied: every
/// captured frame, stamped with its video time, with `ProbeToTracker = b_T_ee · ee_T_tcp`
/// of the tracker interpolated at that time (`INVALID` if the time is outside the tracked
/// range or the frame was lost) and its bone pixels as mask pixels.
pub fn phantom_scan_frames(logs: &SweepLogs) -> Vec<PhantomFrame> {
    let cal = &logs.calibration;
    let ee_t_tcp = super::sim::isometry(&cal.ee_t_tcp);
    let mut rows = logs.frames.iter().peekable();
    logs.scan_captured
        .iter()
        .map(|c| {
            let mut pixels = Vec::new();
            while let Some(r) = rows.next_if(|r| r.frame <= c.frame) {
                if r.frame == c.frame {
                    pixels.push(mask_pixel(r.u, r.v, &cal.probe));
                }
            }
            let transform = (!c.lost)
                .then(|| pose_at(&logs.poses, c.t))
                .flatten()
                .map(|b_t_ee| matrix_of(&(b_t_ee * ee_t_tcp)));
            PhantomFrame {
                frame: c.frame,
                t: c.t,
                transform,
                pixels,
            }
        })
        .collect()
}

/// The calibration sweep of `logs` as PLUS would record it with no time offset applied:
/// the tracked TCP position interpolated at each frame's time (identity rotation; the
/// probe only translates), the landmark as one mask pixel at the middle column.
pub fn phantom_calibration_frames(
    calib_tracker: &[[f64; 4]],
    calib_video: &[[f64; 2]],
    captured: &[CapturedFrame],
    probe: &ProbeModel,
) -> Vec<PhantomFrame> {
    let mut rows = calib_video.iter();
    captured
        .iter()
        .map(|c| {
            let row = if c.lost { None } else { rows.next() };
            let position = calib_tracker
                .windows(2)
                .find(|w| w[0][0] <= c.t && c.t <= w[1][0])
                .map(|w| {
                    let s = (c.t - w[0][0]) / (w[1][0] - w[0][0]);
                    [1, 2, 3].map(|i| w[0][i] + s * (w[1][i] - w[0][i]))
                });
            let transform = row.and(position).map(|p| {
                matrix_of(&Isometry3::from_parts(
                    Translation3::new(p[0], p[1], p[2]),
                    UnitQuaternion::identity(),
                ))
            });
            let pixels = row
                .filter(|r| (0.0..f64::from(probe.height_px)).contains(&r[1]))
                .map(|r| vec![mask_pixel(f64::from(probe.width_px / 2) + 0.5, r[1], probe)])
                .unwrap_or_default();
            PhantomFrame {
                frame: c.frame,
                t: c.t,
                transform,
                pixels,
            }
        })
        .collect()
}

/// Writes `frames` as a compressed `MF` sequence of `probe`-sized bone masks.
pub fn write_phantom_sequence(
    path: &Path,
    frames: &[PhantomFrame],
    probe: &ProbeModel,
    compressed: bool,
) -> Result<(), CliError> {
    let (w, h) = (probe.width_px, probe.height_px);
    let mut writer = SequenceWriter::create(
        path,
        SequenceSpec {
            width: w,
            height: h,
            orientation: Orientation::Mf,
            compressed,
            transform: DEFAULT_TRANSFORM.into(),
        },
    )?;
    let mut mask = vec![0u8; usize::from(w) * usize::from(h)];
    for f in frames {
        for &(c, r) in &f.pixels {
            mask[usize::from(r) * usize::from(w) + usize::from(c)] = BONE;
        }
        writer.push(&FrameOut {
            timestamp: f.t,
            unfiltered_timestamp: f.t,
            frame_number: u64::from(f.frame),
            transform: f.transform.as_ref(),
            mask: &mask,
        })?;
        for &(c, r) in &f.pixels {
            mask[usize::from(r) * usize::from(w) + usize::from(c)] = 0;
        }
    }
    writer.finish()?;
    Ok(())
}

/// Writes the phantom's `sweep.seq.mha`, `calib.seq.mha` (compressed) and
/// `plus_config.xml` (`Image` → `Probe` = the TCP) to `dir`.
pub fn write_phantom_sequences(logs: &SweepLogs, dir: &Path) -> Result<(), CliError> {
    let cal = &logs.calibration;
    write_plus_config(
        &dir.join(PLUS_CONFIG),
        &plus_image_to_probe(cal),
        "Probe",
        SWEEP_SEQUENCE,
        "ribreg phantom sweep: a robot-held linear probe; Tracker = the robot base, \
         Probe = the TCP (ProbeToTracker = b_T_ee . ee_T_tcp)",
    )?;
    write_phantom_sequence(
        &dir.join(SWEEP_SEQUENCE),
        &phantom_scan_frames(logs),
        &cal.probe,
        true,
    )?;
    write_phantom_sequence(
        &dir.join(CALIB_SEQUENCE),
        &phantom_calibration_frames(
            &logs.calib_tracker,
            &logs.calib_video,
            &logs.calib_captured,
            &cal.probe,
        ),
        &cal.probe,
        true,
    )
}

/// What [`read_sweep_sequence`] must read from the phantom's files, computed in memory:
/// the calibration through [`calibration_from_plus`], one pose per frame with status OK,
/// the mask pixels' centres as bone pixels (for the bit-for-bit check of `tests/plus.rs`).
pub fn phantom_sequence_logs(
    logs: &SweepLogs,
) -> Result<(Calibration, Vec<PoseRow>, Vec<FrameRow>), String> {
    let cal = &logs.calibration;
    let calibration = calibration_from_plus(
        &plus_image_to_probe(cal),
        cal.probe.width_px,
        cal.probe.height_px,
    )?;
    let (mut poses, mut rows) = (Vec::new(), Vec::new());
    for f in phantom_scan_frames(logs) {
        let Some(m) = f.transform else { continue };
        poses.push(pose_row(f.t, &m)?);
        let mut px = f.pixels.clone();
        px.sort_unstable();
        px.dedup_by_key(|p| p.0);
        rows.extend(px.iter().map(|&(c, r)| FrameRow {
            frame: f.frame,
            t: f.t,
            u: f64::from(c) + 0.5,
            v: f64::from(r) + 0.5,
        }));
    }
    Ok((calibration, poses, rows))
}
