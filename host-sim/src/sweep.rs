//! Robotic US sweeps: simulated logs (`ribreg phantom sweep`), temporal calibration
//! (`ribreg calibrate temporal`) and compounding the logs into a US cloud
//! (`ribreg compound`) with the same core code the controller runs.
//!
//! # Files
//! * `probe.json` — the spatial calibration:
//!   ```json
//!   { "probe": { "width_px": 384, "height_px": 350, "footprint_mm": 38.4, "depth_mm": 35.0 },
//!     "tcp_T_us": { "rotation": [[1,0,0],[0,0,-1],[0,1,0]], "translation": [-19.2,0,0] },
//!     "ee_T_tcp": { "rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,165] } }
//!   ```
//!   Rotations row-major, translations mm; frames as in [`ribreg_core::acquisition::probe`].
//! * `poses.csv` — `t,x,y,z,qw,qx,qy,qz`: flange pose `b_T_ee` (s, mm, unit quaternion)
//!   at ~100 Hz, tracker clock.
//! * `frames.csv` — `frame,t,u,v`: one annotated bone pixel a line (frame number, video
//!   time stamp s, column and row in pixels); every line of a frame has its time stamp,
//!   frames without bone pixels have no line.
//! * `calib_tracker.csv` — `t,x,y,z` (TCP positions of the calibration sweep, ~100 Hz);
//!   `calib_video.csv` — `t,row` (landmark row per frame, ~30 fps).

use ribreg_core::acquisition::imaged::{ImagedArea, LineEnd};
use ribreg_core::limits::{IMAGED_LINES, TRACK_CAPACITY};
use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Vector3};
use ribreg_core::acquisition::compound::{
    Compounder, FrameStats, VoxelStats, DEFAULT_MAX_COARSENINGS,
};
use ribreg_core::acquisition::probe::{Calibration, ProbeModel};
use ribreg_core::acquisition::temporal::{self, LagEstimate, TrackerSample, VideoSample};
use ribreg_core::acquisition::track::TrackedPose;
use ribreg_core::math::geom::Rigid;
use ribreg_core::math::rng::Rng;
use ribreg_core::{Error, Vec3};
use serde::{Deserialize, Serialize};

use crate::error::CliError;
use crate::io::{self, Cloud, IoError, PlyFormat};
use crate::phantom::{
    HardPart, PhantomConfig, PhantomPair, Pose, SubjectGeometry, SubjectParams, MESH_EDGE_MM,
};

pub mod plus;
pub(crate) mod sim;

/// Voxel capacity of host compounding: 8192 × 12 B = 96 KiB, enough for a whole-chest
/// sweep at 2 mm (the phantom sweeps fill 5,500–7,900 voxels; larger ones coarsen to
/// 4 mm). The controller keeps [`ribreg_core::limits::CONTROLLER_VOXELS`] (3072) and
/// coarsens to 3 mm instead.
pub const HOST_VOXEL_CAPACITY: usize = 8192;

/// Columns of `poses.csv`.
pub const POSE_COLUMNS: [&str; 8] = ["t", "x", "y", "z", "qw", "qx", "qy", "qz"];
/// Columns of `frames.csv`.
pub const FRAME_COLUMNS: [&str; 4] = ["frame", "t", "u", "v"];
/// Columns of the imaged-lines file (`compound --imaged`, `register --imaged`): one row
/// per end of each line of the sweep (`end` 0 the first image, 1 the last), the image's
/// centre (robot base, mm), unit width axis and unit normal along the line's motion,
/// and the image's width (mm).
pub const IMAGED_COLUMNS: [&str; 12] = [
    "line", "end", "x", "y", "z", "across_x", "across_y", "across_z", "normal_x", "normal_y",
    "normal_z", "width_mm",
];
/// Columns of `calib_tracker.csv`.
pub const TRACKER_COLUMNS: [&str; 4] = ["t", "x", "y", "z"];
/// Columns of `calib_video.csv`.
pub const VIDEO_COLUMNS: [&str; 2] = ["t", "row"];

/// Least [`SweepConfig::margin_mm`]: lines stopping 60 mm inside the cartilages'
/// lateral extent on each side still cross the sternum and every rib's medial half (the
/// phantoms' chests span 200–260 mm).
pub const MIN_MARGIN_MM: f64 = -60.0;

/// Simulated sweep settings (`ribreg phantom sweep`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SweepConfig {
    /// Video lag behind the tracker, ms (paper's rig: 268).
    pub lag_ms: f64,
    /// Distance between scan lines, mm.
    pub line_spacing_mm: f64,
    /// Probe speed along the path, mm/s.
    pub speed_mm_s: f64,
    /// Overrun of each line beyond the cartilages' lateral extent, mm (default 20: at
    /// the sides of a curved chest the probe stands tilted, and its image at the
    /// cartilage's depth reaches 5–10 mm less far out than the probe on the skin; at 10
    /// mm, 9 of 60 sweeps imaged less than 3 mm past a rib end, README "The sweep's
    /// edge"); negative, each line stops that far inside it (a sweep band too narrow:
    /// the tests of a sweep that stops short), down to [`MIN_MARGIN_MM`].
    pub margin_mm: f64,
    /// Soft tissue over the chest reference surface (skin height above it), mm.
    pub skin_offset_mm: f64,
    /// Annotation noise of a bone pixel's row (SD), pixels.
    pub pixel_noise_px: f64,
    /// Every this many image columns is annotated.
    pub column_step_px: u16,
    /// Fraction of frames lost (not in the log).
    pub frame_miss_rate: f64,
    /// Tracking noise per coordinate (SD), mm.
    pub tracker_noise_mm: f64,
    /// Video time-stamp jitter (SD), ms.
    pub timestamp_jitter_ms: f64,
    /// Frame rate, Hz.
    pub frame_rate_hz: f64,
    /// Tracker rate, Hz.
    pub pose_rate_hz: f64,
    /// Length of the temporal-calibration sweep, s.
    pub calibration_duration_s: f64,
    /// Peak amplitude of the calibration motion along the beam, mm.
    pub calibration_amplitude_mm: f64,
    /// Landmark row noise of the calibration sweep (SD), pixels.
    pub calibration_noise_px: f64,
    /// Where the robot stands: its base turned by this many degrees about the patient's
    /// anterior axis (through the chest), from where the phantom's pose variant places
    /// it (`hil --base-yaw`): beside the bed at 90°, at its other end at 180°. The sweep
    /// covers the same chest; only the frame it arrives in turns.
    #[serde(default)]
    pub base_yaw_deg: f64,
}

impl Default for SweepConfig {
    fn default() -> Self {
        SweepConfig {
            lag_ms: 268.0,
            line_spacing_mm: 10.0,
            speed_mm_s: 20.0,
            margin_mm: 20.0,
            skin_offset_mm: 10.0,
            pixel_noise_px: 2.0,
            column_step_px: 4,
            frame_miss_rate: 0.05,
            tracker_noise_mm: 0.05,
            timestamp_jitter_ms: 1.0,
            frame_rate_hz: 30.0,
            pose_rate_hz: 100.0,
            calibration_duration_s: 20.0,
            calibration_amplitude_mm: 10.0,
            calibration_noise_px: 0.5,
            base_yaw_deg: 0.0,
        }
    }
}

impl SweepConfig {
    /// Checks ranges: positive spacing, speed and rates, lag within ±1 s, rates below
    /// 10 kHz, probabilities in [0, 1), non-negative noises.
    pub fn validate(&self) -> Result<(), CliError> {
        let bad = |what: &str| Err(CliError::value(format!("sweep: {what}")));
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        if !(self.lag_ms.is_finite() && self.lag_ms.abs() <= 1000.0) {
            return bad("lag must be within ±1000 ms");
        }
        if !pos(self.line_spacing_mm) || !pos(self.speed_mm_s) || self.speed_mm_s > 500.0 {
            return bad("line spacing and speed must be positive (speed at most 500 mm/s)");
        }
        if !(pos(self.frame_rate_hz) && pos(self.pose_rate_hz))
            || self.frame_rate_hz > 1e4
            || self.pose_rate_hz > 1e4
        {
            return bad("frame and pose rates must be positive and below 10 kHz");
        }
        if !(0.0..1.0).contains(&self.frame_miss_rate) {
            return bad("frame miss rate must be in [0, 1)");
        }
        if !(self.margin_mm >= MIN_MARGIN_MM && self.margin_mm <= 1e4) {
            return Err(CliError::value(format!(
                "sweep: the margin must be at least {MIN_MARGIN_MM} mm (lines stopping short) \
                 and finite"
            )));
        }
        let noises = [
            self.skin_offset_mm,
            self.pixel_noise_px,
            self.tracker_noise_mm,
            self.timestamp_jitter_ms,
            self.calibration_noise_px,
            self.calibration_amplitude_mm,
        ];
        if !(self.base_yaw_deg.is_finite() && self.base_yaw_deg.abs() <= 360.0) {
            return bad("the robot base's yaw must be within ±360°");
        }
        if !noises.into_iter().all(nonneg) || !pos(self.calibration_duration_s) {
            return bad("offsets, noises and amplitudes must be non-negative");
        }
        Ok(())
    }
}

/// The default spatial calibration of the simulations: [`ProbeModel::LINEAR_38MM`],
/// centred image, a 165 mm holder along the flange axis.
pub fn default_calibration() -> Calibration {
    Calibration::centred(
        ProbeModel::LINEAR_38MM,
        Rigid {
            rotation: Matrix3::identity(),
            translation: Vec3::new(0.0, 0.0, 165.0),
        },
    )
}

/// `probe.json`: see the module docs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProbeFile {
    /// Image geometry.
    pub probe: ProbeModel,
    /// Image frame in the TCP frame.
    #[serde(rename = "tcp_T_us")]
    pub tcp_t_us: Pose,
    /// TCP frame in the flange frame (the holder).
    #[serde(rename = "ee_T_tcp")]
    pub ee_t_tcp: Pose,
}

fn rigid_of(p: &Pose) -> Rigid {
    Rigid {
        rotation: Matrix3::from_fn(|i, j| p.rotation[i][j] as f32),
        translation: Vec3::new(
            p.translation[0] as f32,
            p.translation[1] as f32,
            p.translation[2] as f32,
        ),
    }
}

fn pose_of(r: &Rigid) -> Pose {
    Pose {
        rotation: std::array::from_fn(|i| std::array::from_fn(|j| f64::from(r.rotation[(i, j)]))),
        translation: std::array::from_fn(|i| f64::from(r.translation[i])),
    }
}

impl ProbeFile {
    /// The file of a calibration.
    pub fn from_calibration(c: &Calibration) -> ProbeFile {
        ProbeFile {
            probe: c.probe,
            tcp_t_us: pose_of(&c.tcp_t_us),
            ee_t_tcp: pose_of(&c.ee_t_tcp),
        }
    }

    /// The calibration, validated.
    pub fn calibration(&self) -> Result<Calibration, Error> {
        let c = Calibration {
            probe: self.probe,
            tcp_t_us: rigid_of(&self.tcp_t_us),
            ee_t_tcp: rigid_of(&self.ee_t_tcp),
        };
        c.validate()?;
        Ok(c)
    }

    /// Reads and validates `probe.json`.
    pub fn read(path: &Path) -> Result<Calibration, CliError> {
        let text = std::fs::read_to_string(path).map_err(|source| IoError::Io {
            path: path.to_owned(),
            op: "cannot read",
            source,
        })?;
        let file: ProbeFile =
            serde_json::from_str(&text).map_err(|e| CliError::input(path, e.to_string()))?;
        file.calibration()
            .map_err(|e| CliError::input(path, e.to_string()))
    }
}

/// One line of `poses.csv`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseRow {
    /// Time, s.
    pub t: f64,
    /// Flange position, mm.
    pub position: [f64; 3],
    /// Flange orientation `[w, x, y, z]`.
    pub quaternion: [f64; 4],
}

impl PoseRow {
    fn from_isometry(t: f64, iso: &Isometry3<f64>, noise: Vector3<f64>) -> PoseRow {
        let p = iso.translation.vector + noise;
        let q = iso.rotation.into_inner();
        PoseRow {
            t,
            position: [p.x, p.y, p.z],
            quaternion: [q.w, q.i, q.j, q.k],
        }
    }

    fn row(&self) -> [f64; 8] {
        let [x, y, z] = self.position;
        let [w, i, j, k] = self.quaternion;
        [self.t, x, y, z, w, i, j, k]
    }
}

/// One line of `frames.csv`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameRow {
    /// Frame number.
    pub frame: u32,
    /// Video time stamp, s.
    pub t: f64,
    /// Column, pixels.
    pub u: f64,
    /// Row, pixels.
    pub v: f64,
}

/// Reads `poses.csv`.
pub fn read_poses(path: &Path) -> Result<Vec<PoseRow>, CliError> {
    Ok(io::read_table_csv(path, POSE_COLUMNS)?
        .into_iter()
        .map(|r| PoseRow {
            t: r[0],
            position: [r[1], r[2], r[3]],
            quaternion: [r[4], r[5], r[6], r[7]],
        })
        .collect())
}

/// Reads `frames.csv`; frame numbers must be whole numbers in `u32`.
pub fn read_frames(path: &Path) -> Result<Vec<FrameRow>, CliError> {
    io::read_table_csv(path, FRAME_COLUMNS)?
        .into_iter()
        .enumerate()
        .map(|(i, r)| {
            if r[0].fract() != 0.0 || !(0.0..=f64::from(u32::MAX)).contains(&r[0]) {
                return Err(CliError::input(
                    path,
                    format!(
                        "row {}: frame number {} is not a whole number ≥ 0",
                        i + 1,
                        r[0]
                    ),
                ));
            }
            Ok(FrameRow {
                frame: r[0] as u32,
                t: r[1],
                u: r[2],
                v: r[3],
            })
        })
        .collect()
}

/// What [`compound`] built.
#[derive(Clone, Debug)]
pub struct CompoundOutcome {
    /// The US cloud (voxel centroids), robot base frame.
    pub points: Vec<[f64; 3]>,
    /// Frames placed and refused.
    pub frames: FrameStats,
    /// Points accepted, merged and refused.
    pub voxels: VoxelStats,
    /// Final voxel edge, mm.
    pub voxel_mm: f32,
    /// Poses refused (not finite, not later than the one before, not a unit quaternion).
    pub poses_refused: u32,
    /// Refused frames by reason (the core error's message with numbers stripped).
    pub refusals: BTreeMap<&'static str, u32>,
    /// Where the sweep's images passed (from every pose, `write_imaged`).
    pub imaged: Box<ImagedArea<IMAGED_LINES>>,
}

/// Replays logs through the core [`Compounder`] in arrival order, as the controller
/// receives them: every frame is placed once the first pose at or after its lag-corrected
/// time has arrived (the window holds [`TRACK_CAPACITY`] poses, the cloud
/// [`HOST_VOXEL_CAPACITY`] voxels).
pub fn compound(
    cal: &Calibration,
    lag_s: f64,
    voxel_mm: f32,
    poses: &[PoseRow],
    frames: &[FrameRow],
) -> Result<CompoundOutcome, CliError> {
    let mut c: Box<Compounder<TRACK_CAPACITY, HOST_VOXEL_CAPACITY>> = Box::new(Compounder::new(
        *cal,
        lag_s,
        voxel_mm,
        DEFAULT_MAX_COARSENINGS,
    )?);
    // Group the pixel rows into frames (consecutive lines of one frame number).
    let mut groups: Vec<(f64, Vec<[f32; 2]>)> = Vec::new();
    let mut last: Option<u32> = None;
    for (i, f) in frames.iter().enumerate() {
        if last == Some(f.frame) {
            let g = groups
                .last_mut()
                .expect("a group exists after the first row");
            if g.0 != f.t {
                return Err(CliError::value(format!(
                    "frames: row {}: frame {} has two time stamps ({} and {})",
                    i + 1,
                    f.frame,
                    g.0,
                    f.t
                )));
            }
            g.1.push([f.u as f32, f.v as f32]);
        } else {
            groups.push((f.t, vec![[f.u as f32, f.v as f32]]));
            last = Some(f.frame);
        }
    }
    groups.sort_by(|a, b| a.0.total_cmp(&b.0));

    let mut refusals = BTreeMap::new();
    let mut refuse = |e: Error| {
        let reason = match e {
            Error::OutsideTrack { .. } => "outside the tracked time range",
            Error::TrackGap { .. } => "across a gap in the pose stream",
            Error::Pixel { .. } => "a pixel outside the image",
            _ => "invalid frame",
        };
        *refusals.entry(reason).or_insert(0u32) += 1;
    };
    let mut next = 0usize;
    let mut place = |c: &mut Compounder<TRACK_CAPACITY, HOST_VOXEL_CAPACITY>,
                     upto: f64,
                     next: &mut usize|
     -> Result<(), CliError> {
        while let Some((t, pixels)) = groups.get(*next) {
            if t - lag_s > upto {
                break;
            }
            match c.add_frame(*t, pixels) {
                Ok(_) => {}
                Err(
                    e @ (Error::OutsideTrack { .. }
                    | Error::TrackGap { .. }
                    | Error::Pixel { .. }
                    | Error::Sample { .. }),
                ) => refuse(e),
                Err(e) => return Err(e.into()),
            }
            *next += 1;
        }
        Ok(())
    };
    for p in poses {
        let q = p.quaternion.map(|v| v as f32);
        let pos = Vec3::new(
            p.position[0] as f32,
            p.position[1] as f32,
            p.position[2] as f32,
        );
        // A bad pose is refused and counted, as the controller does; it is not fatal.
        match TrackedPose::new(p.t, pos, q) {
            Ok(pose) => {
                if c.add_pose(pose).is_ok() {
                    place(&mut c, p.t, &mut next)?;
                }
            }
            Err(_) => c.track.refused += 1,
        }
    }
    place(&mut c, f64::INFINITY, &mut next)?;
    let frames = c.frames;
    let imaged = Box::new(c.imaged.clone());
    let poses_refused = c.track.refused;
    let voxels = c.cloud.stats;
    let voxel_mm = c.cloud.voxel_mm();
    let points = c
        .cloud
        .finish()
        .iter()
        .map(|p| p.cast::<f64>().into())
        .collect();
    Ok(CompoundOutcome {
        points,
        frames,
        voxels,
        voxel_mm,
        poses_refused,
        refusals,
        imaged,
    })
}

/// Writes the lines of `area` ([`IMAGED_COLUMNS`]), atomically.
pub fn write_imaged(path: &Path, area: &ImagedArea<IMAGED_LINES>) -> Result<(), CliError> {
    let mut rows = Vec::new();
    for (i, ends) in area.lines().enumerate() {
        for (k, e) in ends.iter().enumerate() {
            let v = |v: &Vec3| v.map(f64::from);
            let (c, a, n) = (v(&e.centre), v(&e.across), v(&e.normal));
            rows.push([
                i as f64,
                k as f64,
                c.x,
                c.y,
                c.z,
                a.x,
                a.y,
                a.z,
                n.x,
                n.y,
                n.z,
                f64::from(area.width_mm()),
            ]);
        }
    }
    Ok(io::write_table_csv(path, IMAGED_COLUMNS, &rows)?)
}

/// Reads the lines [`write_imaged`] wrote ([`lines_from_rows`]).
pub fn read_imaged(path: &Path) -> Result<ImagedArea<IMAGED_LINES>, CliError> {
    let rows = io::read_table_csv(path, IMAGED_COLUMNS)?;
    lines_from_rows(&rows).map_err(|e| CliError::input(path, e))
}

/// [`read_imaged`] of text: the table's error or the lines' (for the fuzz target).
pub fn parse_imaged(text: &str) -> Result<ImagedArea<IMAGED_LINES>, String> {
    let rows = io::parse_table_csv(text, IMAGED_COLUMNS).map_err(|e| e.to_string())?;
    lines_from_rows(&rows)
}

/// The lines of [`IMAGED_COLUMNS`] rows: each line's two ends in order (rows `line` k,
/// `end` 0 and 1), unit axes, one width. Refused with the row: a line not made of its
/// two ends in order, bad axes or widths ([`ImagedArea::push_line`]), more than
/// [`IMAGED_LINES`] lines, or none.
pub fn lines_from_rows(rows: &[[f64; 12]]) -> Result<ImagedArea<IMAGED_LINES>, String> {
    if rows.is_empty() {
        return Err("no sweep line (only the header)".into());
    }
    let mut area = ImagedArea::new();
    for (i, pair) in rows.chunks(2).enumerate() {
        let bad = |what: String| format!("row {}: {what}", 2 * i + 1);
        let [a, b] = pair else {
            return Err(bad("a line needs two rows (end 0 and end 1)".into()));
        };
        if a[0] != i as f64 || b[0] != i as f64 || a[1] != 0.0 || b[1] != 1.0 {
            return Err(bad(format!("expected line {i}, end 0 then end 1")));
        }
        let end = |r: &[f64; 12]| {
            let v = |k: usize| Vec3::new(r[k] as f32, r[k + 1] as f32, r[k + 2] as f32);
            LineEnd {
                centre: v(2),
                across: v(5),
                normal: v(8),
            }
        };
        if a[11] != b[11] {
            return Err(bad("the two ends of a line give different widths".into()));
        }
        area.push_line([end(a), end(b)], a[11] as f32)
            .map_err(|e| match e {
                Error::Capacity { capacity } => bad(format!("more than {capacity} sweep lines")),
                e => bad(e.to_string()),
            })?;
    }
    Ok(area)
}

/// Calibration-sweep rows (`t,x,y,z` and `t,row`) as the core's samples.
pub fn calibration_samples(
    tracker: &[[f64; 4]],
    video: &[[f64; 2]],
) -> (Vec<TrackerSample>, Vec<VideoSample>) {
    let tr = tracker
        .iter()
        .map(|r| TrackerSample {
            t: r[0],
            position: Vec3::new(r[1] as f32, r[2] as f32, r[3] as f32),
        })
        .collect();
    let vi = video
        .iter()
        .map(|r| VideoSample {
            t: r[0],
            row: r[1] as f32,
        })
        .collect();
    (tr, vi)
}

/// Temporal calibration from the two CSV files.
pub fn calibrate_temporal(tracker: &Path, video: &Path) -> Result<LagEstimate, CliError> {
    let (tr, vi) = calibration_samples(
        &io::read_table_csv(tracker, TRACKER_COLUMNS)?,
        &io::read_table_csv(video, VIDEO_COLUMNS)?,
    );
    Ok(temporal::calibrate(&tr, &vi)?)
}

/// Rows of `calib_tracker.csv` (`t,x,y,z`) and `calib_video.csv` (`t,row`).
pub type CalibrationLogs = (Vec<[f64; 4]>, Vec<[f64; 2]>);

/// A simulated temporal-calibration sweep alone (`calib_tracker.csv` and
/// `calib_video.csv` rows) for `seed`.
pub fn simulate_calibration(cfg: &SweepConfig, seed: u64) -> Result<CalibrationLogs, CliError> {
    Ok(simulate_calibration_captured(cfg, seed)?.0)
}

/// [`simulate_calibration`] and every captured frame, lost or logged (`calib.seq.mha`).
pub fn simulate_calibration_captured(
    cfg: &SweepConfig,
    seed: u64,
) -> Result<(CalibrationLogs, Vec<plus::CapturedFrame>), CliError> {
    cfg.validate()?;
    let mut rng = Rng::new(seed ^ STREAM_CALIBRATION.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    Ok(sim::calibration_sweep(
        cfg,
        &default_calibration(),
        &mut rng,
    ))
}

/// Everything `ribreg phantom sweep` writes, in memory.
pub struct SweepLogs {
    /// The phantom pair (its target is the ideal, noise-free US cloud).
    pub pair: PhantomPair,
    /// The spatial calibration.
    pub calibration: Calibration,
    /// Flange poses of the scan.
    pub poses: Vec<PoseRow>,
    /// Bone pixels of the scan.
    pub frames: Vec<FrameRow>,
    /// Calibration sweep: tracked TCP positions `t,x,y,z`.
    pub calib_tracker: Vec<[f64; 4]>,
    /// Calibration sweep: landmark rows `t,row`.
    pub calib_video: Vec<[f64; 2]>,
    /// Every captured frame of the scan, lost or logged (`sweep.seq.mha`).
    pub scan_captured: Vec<plus::CapturedFrame>,
    /// Every captured frame of the calibration sweep (`calib.seq.mha`).
    pub calib_captured: Vec<plus::CapturedFrame>,
    /// Summary for `sweep.json`.
    pub summary: serde_json::Value,
}

/// The chest's (x, y) extent in the frame of `patient`, mm (`[lo, hi]`, lateral then
/// cranio-caudal): what the simulated sweep's lines span before
/// [`SweepConfig::margin_mm`].
pub fn chest_extent(patient: &SubjectParams) -> [[f64; 2]; 2] {
    let (lo, hi) = sim::extent(&SubjectGeometry::new(patient).mesh(MESH_EDGE_MM));
    [lo, hi]
}

/// The lines the default sweep ([`SweepConfig::default`], [`default_calibration`]) images
/// when it runs laterally from `x[0]` to `x[1]` over cranio-caudal `y` (patient frame of
/// `patient`, mm) with the robot base at `base_t_patient`: what `compound --imaged` would
/// write for a sweep of that band (robot base frame), without rendering it.
pub fn imaged_band(
    patient: &SubjectParams,
    x: [f64; 2],
    y: [f64; 2],
    base_t_patient: &Pose,
) -> ImagedArea<IMAGED_LINES> {
    sim::imaged(
        &SweepConfig::default(),
        &default_calibration(),
        patient,
        x,
        y,
        &sim::pose_isometry(base_t_patient),
    )
}

/// Seed stream of the sweep simulation (distinct from the phantom's streams).
const STREAM_SWEEP: u64 = 0x5EE9;
/// Seed stream of the temporal-calibration sweep.
const STREAM_CALIBRATION: u64 = 0xCA1B;

/// Simulates the sweep of the phantom of `phantom` (its US target is generated noise-free,
/// without holes or outliers: the ideal cloud the compounded one is compared with). A
/// hard phantom keeps its patient's shape; the simulated sweep stands in for its sweep
/// defects ([`HardPart::SWEEP`]), which the ideal cloud leaves out.
pub fn simulate(phantom: &PhantomConfig, cfg: &SweepConfig) -> Result<SweepLogs, CliError> {
    cfg.validate()?;
    let mut hard_without = phantom.hard_without.clone();
    hard_without.extend(HardPart::SWEEP);
    let ideal = PhantomConfig {
        us_noise_mm: 0.0,
        outlier_fraction: 0.0,
        missing_patches: 0,
        hard_without,
        ..phantom.clone()
    };
    let pair = PhantomPair::generate(&ideal).turned(cfg.base_yaw_deg);
    let calibration = default_calibration();
    let mesh = SubjectGeometry::new(&pair.patient_params).mesh(MESH_EDGE_MM);
    let base_t_patient = sim::pose_isometry(&pair.pose);
    let mut rng = Rng::new(phantom.seed ^ STREAM_SWEEP.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let scan = sim::scan(
        cfg,
        &calibration,
        &pair.patient_params,
        &mesh,
        &base_t_patient,
        &mut rng,
    );
    let ((calib_tracker, calib_video), calib_captured) =
        simulate_calibration_captured(cfg, phantom.seed)?;
    let summary = serde_json::json!({
        "sweep": cfg,
        "phantom": ideal,
        "true_lag_ms": cfg.lag_ms,
        "scan": {
            "lines": scan.lines,
            "duration_s": scan.duration_s,
            "poses": scan.poses.len(),
            "frames_captured": scan.captured,
            "frames_logged": scan.frames.iter().map(|f| f.frame).collect::<std::collections::BTreeSet<_>>().len(),
            "pixels": scan.frames.len(),
        },
        "calibration_sweep": { "tracker": calib_tracker.len(), "frames": calib_video.len() },
    });
    Ok(SweepLogs {
        pair,
        calibration,
        poses: scan.poses,
        frames: scan.frames,
        calib_tracker,
        calib_video,
        scan_captured: scan.captured_frames,
        calib_captured,
        summary,
    })
}

impl SweepLogs {
    /// Writes the phantom files (`template.ply`, `waypoints.csv`, `true_waypoints.csv`,
    /// `target.ply` = ideal US cloud, `params.json`) and the sweep files (`probe.json`,
    /// `poses.csv`, `frames.csv`, `calib_tracker.csv`, `calib_video.csv`, `sweep.json`),
    /// and the same sweeps as PLUS files (`sweep.seq.mha`, `calib.seq.mha`,
    /// `plus_config.xml`: [`plus::write_phantom_sequences`]).
    pub fn write(&self, dir: &Path) -> Result<(), CliError> {
        crate::demo::write_phantom(&self.pair, dir)?;
        let probe = serde_json::to_string_pretty(&ProbeFile::from_calibration(&self.calibration))
            .map_err(|e| CliError::Output(format!("probe.json: {e}")))?;
        io::write_text(&dir.join("probe.json"), &probe)?;
        let poses: Vec<[f64; 8]> = self.poses.iter().map(PoseRow::row).collect();
        io::write_table_csv(&dir.join("poses.csv"), POSE_COLUMNS, &poses)?;
        let frames: Vec<[f64; 4]> = self
            .frames
            .iter()
            .map(|f| [f64::from(f.frame), f.t, f.u, (f.v * 100.0).round() / 100.0])
            .collect();
        io::write_table_csv(&dir.join("frames.csv"), FRAME_COLUMNS, &frames)?;
        io::write_table_csv(
            &dir.join("calib_tracker.csv"),
            TRACKER_COLUMNS,
            &self.calib_tracker,
        )?;
        io::write_table_csv(
            &dir.join("calib_video.csv"),
            VIDEO_COLUMNS,
            &self.calib_video,
        )?;
        let summary = serde_json::to_string_pretty(&self.summary)
            .map_err(|e| CliError::Output(format!("sweep.json: {e}")))?;
        io::write_text(&dir.join("sweep.json"), &summary)?;
        plus::write_phantom_sequences(self, dir)?;
        Ok(())
    }
}

/// Writes a compounded cloud as PLY (binary little-endian).
pub fn write_cloud(path: &Path, points: &[[f64; 3]]) -> Result<(), CliError> {
    io::write_ply(
        path,
        &Cloud {
            points: points.to_vec(),
            labels: None,
        },
        PlyFormat::BinaryLittleEndian,
    )?;
    Ok(())
}

/// End-to-end result of [`end_to_end`].
#[derive(Clone, Debug)]
pub struct EndToEnd {
    /// The temporal calibration.
    pub lag: LagEstimate,
    /// The compounded cloud and its counters.
    pub compound: CompoundOutcome,
    /// Waypoint error (mean, SD, max; mm) registering onto the compounded cloud.
    pub sweep_waypoints: (f64, f64, f64),
    /// Waypoint error registering onto the ideal cloud (`target.ply`).
    pub ideal_waypoints: (f64, f64, f64),
    /// How far past the nearest rib end the compounded cloud shows the sweep imaged
    /// (mm; the registration is refused below
    /// [`ribreg_core::registration::reach::MIN_EDGE_CLEARANCE_MM`], as the controller's
    /// and `register --imaged` are).
    pub min_edge_clearance_mm: f32,
    /// Points of the ideal cloud.
    pub ideal_points: usize,
}

impl EndToEnd {
    /// The summary written to `end_to_end.json`.
    pub fn json(&self, true_lag_ms: f64) -> serde_json::Value {
        let wp = |e: (f64, f64, f64)| serde_json::json!({ "mean": e.0, "sd": e.1, "max": e.2 });
        serde_json::json!({
            "lag_ms": self.lag.lag_s * 1e3,
            "true_lag_ms": true_lag_ms,
            "lag_error_ms": self.lag.lag_s * 1e3 - true_lag_ms,
            "lag_rmse_px": self.lag.rmse_px,
            "lag_pairs": self.lag.pairs,
            "compound": {
                "points": self.compound.points.len(),
                "voxel_mm": self.compound.voxel_mm,
                "frames_placed": self.compound.frames.placed,
                "frames_outside_track": self.compound.frames.outside_track,
                "frames_invalid": self.compound.frames.invalid,
                "points_accepted": self.compound.voxels.accepted,
                "points_merged": self.compound.voxels.merged,
                "points_refused_full": self.compound.voxels.refused_full,
                "coarsenings": self.compound.voxels.coarsenings,
                "poses_refused": self.compound.poses_refused,
            },
            "waypoint_error_mm": {
                "compounded": wp(self.sweep_waypoints),
                "ideal": wp(self.ideal_waypoints),
                "difference_of_means": self.sweep_waypoints.0 - self.ideal_waypoints.0,
            },
            "ideal_points": self.ideal_points,
            "min_edge_clearance_mm": self.min_edge_clearance_mm,
        })
    }
}

/// The whole chain on the files `ribreg phantom sweep` wrote to `dir`: temporal
/// calibration → compounding with the estimated lag → registration (improved method) of
/// `template.ply` onto the compounded cloud and onto the ideal `target.ply` → waypoint
/// errors against `true_waypoints.csv`. The registration onto the compounded cloud is
/// checked against where the sweep imaged, as the controller's is
/// ([`crate::register::check_edges`]): a rib end the probe did not image past is refused
/// ([`Error::SweepEdge`]). Writes `us_compounded.ply`, `lag.json` and
/// `mapped_waypoints*.csv` to `dir`.
pub fn end_to_end(
    dir: &Path,
    voxel_mm: f32,
    progress: &mut dyn FnMut(&str),
) -> Result<EndToEnd, CliError> {
    use crate::register::{check_edges, register_clouds, to_core, to_core_labels, to_file, Method};
    use ribreg_core::error::Cloud as Which;
    let lag = calibrate_temporal(&dir.join("calib_tracker.csv"), &dir.join("calib_video.csv"))?;
    progress(&format!(
        "temporal calibration: lag {:.1} ms, NCC {:.3}, residual {:.2} px over {} frames",
        lag.lag_s * 1e3,
        lag.ncc,
        lag.rmse_px,
        lag.pairs
    ));
    let cal = ProbeFile::read(&dir.join("probe.json"))?;
    let poses = read_poses(&dir.join("poses.csv"))?;
    let frames = read_frames(&dir.join("frames.csv"))?;
    let compound = compound(&cal, lag.lag_s, voxel_mm, &poses, &frames)?;
    progress(&format!(
        "compounded {} frames ({} refused) into {} points of {} mm",
        compound.frames.placed,
        compound.frames.outside_track + compound.frames.invalid,
        compound.points.len(),
        compound.voxel_mm
    ));
    write_cloud(&dir.join("us_compounded.ply"), &compound.points)?;
    let template_path = dir.join("template.ply");
    let template = io::read_ply(&template_path)?;
    let labels = to_core_labels(&template_path, &template.labels)?;
    let template_pts = to_core(&template.points, Which::Template)?;
    let waypoints = to_core(
        &io::read_points_csv(&dir.join("waypoints.csv"))?,
        Which::Query,
    )?;
    let truth = io::read_points_csv(&dir.join("true_waypoints.csv"))?;
    let mut least_clearance = f32::NAN;
    let mut errors = |target: &[[f64; 3]],
                      name: &str,
                      imaged: Option<&ImagedArea<IMAGED_LINES>>|
     -> Result<(f64, f64, f64), CliError> {
        let target = to_core(target, Which::Target)?;
        let o = register_clouds(
            &template_pts,
            labels.as_deref(),
            &target,
            Some(&waypoints),
            Method::Improved,
            &mut |_| {},
        )?;
        if let Some(area) = imaged {
            let (edges, _) = check_edges(&o.registration, &o.reach, area, false)?;
            least_clearance = ribreg_core::registration::reach::least_clearance(&edges);
            progress(&format!(
                "the sweep imaged at least {least_clearance:.1} mm past every rib end the \
                 {name} cloud shows"
            ));
        }
        let mapped = o.waypoints.unwrap_or_default();
        io::write_points_csv(
            &dir.join(format!("mapped_waypoints_{name}.csv")),
            &to_file(&mapped),
        )?;
        let e = crate::demo::paired_errors(&mapped, &truth);
        progress(&format!(
            "registered onto the {name} cloud: waypoint error {:.2} ± {:.2} mm (max {:.2})",
            e.0, e.1, e.2
        ));
        Ok(e)
    };
    let sweep_waypoints = errors(&compound.points, "compounded", Some(&compound.imaged))?;
    let ideal = io::read_ply(&dir.join("target.ply"))?;
    let ideal_waypoints = errors(&ideal.points, "ideal", None)?;
    Ok(EndToEnd {
        lag,
        compound,
        sweep_waypoints,
        ideal_waypoints,
        ideal_points: ideal.points.len(),
        min_edge_clearance_mm: least_clearance,
    })
}
