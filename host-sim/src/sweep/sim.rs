//! The simulated robot and probe: a multi-line scan over the phantom chest and a
//! temporal-calibration sweep over a landmark.
//!
//! # Scan
//! The skin is the phantom's chest reference surface lifted by `skin_offset_mm`:
//! `z = s_z·(−(x/s_x)²/(2R_x) − (y/s_y)²/(2R_y)) + offset` (patient frame, the subject's
//! anisotropic scale `s`). Scan lines run laterally (along x) at cranio-caudal steps of
//! `line_spacing_mm`, serpentine, over the cartilages' extent plus `margin_mm`; the probe
//! stands on the skin, its beam along the inward skin normal and its footprint
//! cranio-caudal (the image plane is transverse to the motion). Each frame's image is
//! rendered by cutting the patient mesh with the image plane and keeping, per annotated
//! column, the first surface along the beam within the imaging depth: what an annotator
//! marks as the bone (cartilage or sternum) surface.
//!
//! # Clocks
//! The tracker stamps poses exactly at 100 Hz. A frame captured at `τ` is stamped
//! `τ + lag + jitter` by the video clock (positive lag: the video lags the tracker).

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use ribreg_core::acquisition::imaged::ImagedArea;
use ribreg_core::acquisition::probe::Calibration;
use ribreg_core::limits::IMAGED_LINES;
use ribreg_core::math::geom::Rigid;
use ribreg_core::math::rng::Rng;

use super::plus::CapturedFrame;
use super::{FrameRow, PoseRow, SweepConfig};
use crate::phantom::{gaussian, Mesh, SubjectParams};

type V3 = Vector3<f64>;

/// `Rigid` (f32) → f64 isometry.
pub(crate) fn isometry(r: &ribreg_core::math::geom::Rigid) -> Isometry3<f64> {
    let m: Matrix3<f64> = r.rotation.cast();
    Isometry3::from_parts(
        Translation3::from(r.translation.cast::<f64>()),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m)),
    )
}

/// The phantom's pose (patient → robot base) as an isometry.
pub(crate) fn pose_isometry(p: &crate::phantom::Pose) -> Isometry3<f64> {
    let r = Matrix3::from_fn(|i, j| p.rotation[i][j]);
    Isometry3::from_parts(
        Translation3::new(p.translation[0], p.translation[1], p.translation[2]),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    )
}

/// The skin surface of a subject.
struct Skin {
    scale: [f64; 3],
    radius: [f64; 2],
    offset: f64,
}

impl Skin {
    fn new(p: &SubjectParams, offset: f64) -> Skin {
        Skin {
            scale: p.scale,
            radius: p.chest_radius_mm,
            offset,
        }
    }

    /// Skin point above (x, y) and its outward unit normal.
    fn at(&self, x: f64, y: f64) -> (V3, V3) {
        let [sx, sy, sz] = self.scale;
        let [rx, ry] = self.radius;
        let z = sz * (-(x / sx).powi(2) / (2.0 * rx) - (y / sy).powi(2) / (2.0 * ry)) + self.offset;
        let dzdx = -sz * x / (sx * sx * rx);
        let dzdy = -sz * y / (sy * sy * ry);
        (V3::new(x, y, z), V3::new(-dzdx, -dzdy, 1.0).normalize())
    }

    /// The TCP pose (patient frame) standing at (x, y): beam along the inward normal,
    /// footprint cranio-caudal.
    fn tcp(&self, x: f64, y: f64) -> Isometry3<f64> {
        let (p, n) = self.at(x, y);
        let z = -n;
        let x_axis = (V3::y() - z * V3::y().dot(&z)).normalize();
        let y_axis = z.cross(&x_axis);
        let r = Matrix3::from_columns(&[x_axis, y_axis, z]);
        Isometry3::from_parts(
            Translation3::from(p),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
        )
    }
}

/// A serpentine path over the skin, parametrised by arc length in the (x, y) plane.
pub(crate) struct ScanPath {
    corners: Vec<[f64; 2]>,
    /// Cumulative (x, y) length at each corner.
    length: Vec<f64>,
}

impl ScanPath {
    /// Lines along x over `[x0, x1]` at y from `y0` down to `y1` every `spacing`.
    fn serpentine(x0: f64, x1: f64, y0: f64, y1: f64, spacing: f64) -> ScanPath {
        let lines = ((y0 - y1) / spacing).ceil().max(0.0) as usize + 1;
        let mut corners = Vec::with_capacity(2 * lines);
        for k in 0..lines {
            let y = y0 - k as f64 * spacing;
            let (a, b) = if k.is_multiple_of(2) {
                (x0, x1)
            } else {
                (x1, x0)
            };
            corners.push([a, y]);
            corners.push([b, y]);
        }
        let mut length = vec![0.0];
        for w in corners.windows(2) {
            let d = ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt();
            length.push(length.last().copied().unwrap_or(0.0) + d);
        }
        ScanPath { corners, length }
    }

    /// The scan's lines: along x from `x[0]` to `x[1]`, from half a line spacing above
    /// `y[1]` down to half one below `y[0]` (patient frame, mm).
    fn over(cfg: &SweepConfig, x: [f64; 2], y: [f64; 2]) -> ScanPath {
        let half = 0.5 * cfg.line_spacing_mm;
        ScanPath::serpentine(x[0], x[1], y[1] + half, y[0] - half, cfg.line_spacing_mm)
    }

    fn total(&self) -> f64 {
        self.length.last().copied().unwrap_or(0.0)
    }

    /// (x, y) at arc length `s` (clamped to the path).
    fn at(&self, s: f64) -> [f64; 2] {
        let s = s.clamp(0.0, self.total());
        let i = self
            .length
            .partition_point(|&l| l <= s)
            .clamp(1, self.corners.len().max(2) - 1);
        let (a, b) = (self.corners[i - 1], self.corners[i]);
        let seg = self.length[i] - self.length[i - 1];
        let w = if seg > 0.0 {
            (s - self.length[i - 1]) / seg
        } else {
            0.0
        };
        [a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1])]
    }
}

/// Triangles of a mesh binned on a 2-D (x, y) grid by their bounding boxes.
struct TriangleGrid<'a> {
    mesh: &'a Mesh,
    lo: [f64; 2],
    cell: f64,
    dims: [usize; 2],
    cells: Vec<Vec<u32>>,
}

impl<'a> TriangleGrid<'a> {
    const CELL_MM: f64 = 4.0;

    fn new(mesh: &'a Mesh) -> Self {
        let (verts, tris) = mesh;
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for v in verts {
            for a in 0..2 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        let cell = Self::CELL_MM;
        let dims = [0, 1].map(|a| (((hi[a] - lo[a]) / cell).floor() as usize + 1).max(1));
        let mut cells = vec![Vec::new(); dims[0] * dims[1]];
        for (t, tri) in tris.iter().enumerate() {
            let (mut tlo, mut thi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for &i in tri {
                let v = verts[i as usize];
                for a in 0..2 {
                    tlo[a] = tlo[a].min(v[a]);
                    thi[a] = thi[a].max(v[a]);
                }
            }
            let (c0, c1) = (
                Self::index(lo, cell, dims, tlo),
                Self::index(lo, cell, dims, thi),
            );
            for cy in c0[1]..=c1[1] {
                for cx in c0[0]..=c1[0] {
                    cells[cy * dims[0] + cx].push(t as u32);
                }
            }
        }
        TriangleGrid {
            mesh,
            lo,
            cell,
            dims,
            cells,
        }
    }

    fn index(lo: [f64; 2], cell: f64, dims: [usize; 2], p: [f64; 2]) -> [usize; 2] {
        [0, 1].map(|a| (((p[a] - lo[a]) / cell).floor().max(0.0) as usize).min(dims[a] - 1))
    }

    /// Every triangle whose bounding box may overlap the (x, y) box `[lo, hi]`, once.
    fn query(&self, lo: [f64; 2], hi: [f64; 2], stamp: &mut [u32], frame: u32, out: &mut Vec<u32>) {
        out.clear();
        let (c0, c1) = (
            Self::index(self.lo, self.cell, self.dims, lo),
            Self::index(self.lo, self.cell, self.dims, hi),
        );
        for cy in c0[1]..=c1[1] {
            for cx in c0[0]..=c1[0] {
                for &t in &self.cells[cy * self.dims[0] + cx] {
                    if stamp[t as usize] != frame {
                        stamp[t as usize] = frame;
                        out.push(t);
                    }
                }
            }
        }
    }
}

/// Renders one frame: per annotated column, the depth (mm) of the first mesh surface
/// along the beam within the imaging depth (`None`: nothing seen).
struct Renderer<'a> {
    grid: TriangleGrid<'a>,
    stamp: Vec<u32>,
    candidates: Vec<u32>,
    frame: u32,
}

impl<'a> Renderer<'a> {
    fn new(mesh: &'a Mesh) -> Self {
        Renderer {
            grid: TriangleGrid::new(mesh),
            stamp: vec![u32::MAX; mesh.1.len()],
            candidates: Vec::new(),
            frame: 0,
        }
    }

    /// `patient_t_us`: the image frame in the patient frame. `columns[k]` is the column
    /// (pixels, continuous) of annotated column `k`; `depth` receives its first-hit depth.
    fn render(
        &mut self,
        patient_t_us: &Isometry3<f64>,
        cal: &Calibration,
        columns: &[f64],
        depth: &mut [Option<f64>],
    ) {
        let probe = cal.probe;
        let (sx, _) = probe.scale();
        let (sx, width, max_depth) = (
            f64::from(sx),
            f64::from(probe.footprint_mm),
            f64::from(probe.depth_mm),
        );
        let origin = patient_t_us.translation.vector;
        let r = patient_t_us.rotation.to_rotation_matrix();
        let (ax, ay, an) = (
            r.matrix().column(0).into_owned(),
            r.matrix().column(1).into_owned(),
            r.matrix().column(2).into_owned(),
        );
        depth.iter_mut().for_each(|d| *d = None);

        let corners = [
            origin,
            origin + ax * width,
            origin + ay * max_depth,
            origin + ax * width + ay * max_depth,
        ];
        let lo = [0, 1].map(|a| corners.iter().map(|c| c[a]).fold(f64::INFINITY, f64::min));
        let hi = [0, 1].map(|a| {
            corners
                .iter()
                .map(|c| c[a])
                .fold(f64::NEG_INFINITY, f64::max)
        });
        self.frame = self.frame.wrapping_add(1);
        if self.frame == u32::MAX {
            self.stamp.iter_mut().for_each(|s| *s = u32::MAX);
            self.frame = 0;
        }
        self.grid
            .query(lo, hi, &mut self.stamp, self.frame, &mut self.candidates);

        let (verts, tris) = self.grid.mesh;
        for &t in &self.candidates {
            let v = tris[t as usize].map(|i| V3::from(verts[i as usize]) - origin);
            // Signed distances to the image plane; a vertex on the plane counts as positive.
            let d = v.map(|p| p.dot(&an));
            let mut ends = [(0.0, 0.0); 2];
            let mut n = 0;
            for (a, b) in [(0, 1), (1, 2), (2, 0)] {
                if (d[a] >= 0.0) != (d[b] >= 0.0) && n < 2 {
                    let q = v[a] + (v[b] - v[a]) * (d[a] / (d[a] - d[b]));
                    ends[n] = (q.dot(&ax) / sx, q.dot(&ay));
                    n += 1;
                }
            }
            if n < 2 {
                continue;
            }
            let ((u0, z0), (u1, z1)) = if ends[0].0 <= ends[1].0 {
                (ends[0], ends[1])
            } else {
                (ends[1], ends[0])
            };
            let first = columns.partition_point(|&c| c < u0);
            for (k, &c) in columns.iter().enumerate().skip(first) {
                if c > u1 {
                    break;
                }
                let z = if u1 > u0 {
                    z0 + (z1 - z0) * (c - u0) / (u1 - u0)
                } else {
                    z0.min(z1)
                };
                if (0.0..=max_depth).contains(&z) && depth[k].is_none_or(|old| z < old) {
                    depth[k] = Some(z);
                }
            }
        }
    }
}

/// Where the probe's images pass on the scan's path over lateral `x` and cranio-caudal
/// `y` (patient frame, mm: [`ScanPath::over`]) of `patient`'s skin with the robot base at
/// `base_t_patient`, placed every [`TRACK_STEP_MM`] as the controller places tracked poses
/// ([`ImagedArea::place`]; robot base frame). Nothing is rendered and nothing is noisy:
/// the lines a sweep of that band gives (`eval --robustness --imaged`).
pub(crate) fn imaged(
    cfg: &SweepConfig,
    cal: &Calibration,
    patient: &SubjectParams,
    x: [f64; 2],
    y: [f64; 2],
    base_t_patient: &Isometry3<f64>,
) -> ImagedArea<IMAGED_LINES> {
    let skin = Skin::new(patient, cfg.skin_offset_mm);
    let path = ScanPath::over(cfg, x, y);
    let tcp_t_us = isometry(&cal.tcp_t_us);
    let mut area = ImagedArea::new();
    let steps = (path.total() / TRACK_STEP_MM).ceil() as usize;
    for k in 0..=steps {
        let [x, y] = path.at(k as f64 * TRACK_STEP_MM);
        let b_t_us = base_t_patient * skin.tcp(x, y) * tcp_t_us;
        area.place(&rigid(&b_t_us), &cal.probe);
    }
    area
}

/// The probe's step between two placed images in [`imaged`], mm: a 100 Hz tracker's at
/// 50 mm/s, a quarter of [`ribreg_core::acquisition::imaged::STEP_MM`].
const TRACK_STEP_MM: f64 = 0.5;

/// An f64 isometry as a `Rigid` (f32).
fn rigid(iso: &Isometry3<f64>) -> Rigid {
    Rigid {
        rotation: iso.rotation.to_rotation_matrix().matrix().cast(),
        translation: iso.translation.vector.cast(),
    }
}

/// The patient mesh's (x, y) extent, patient frame.
pub(crate) fn extent(mesh: &Mesh) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for v in &mesh.0 {
        for a in 0..2 {
            lo[a] = lo[a].min(v[a]);
            hi[a] = hi[a].max(v[a]);
        }
    }
    (lo, hi)
}

/// The scan: flange poses (robot base frame) at the pose rate and frame annotations.
pub(crate) struct Scan {
    pub poses: Vec<PoseRow>,
    pub frames: Vec<FrameRow>,
    /// Frames captured (before misses).
    pub captured: usize,
    /// Duration, s.
    pub duration_s: f64,
    /// Scan lines.
    pub lines: usize,
    /// Every captured frame, lost or logged, with its video stamp (`sweep.seq.mha`).
    pub captured_frames: Vec<CapturedFrame>,
}

/// Simulates the multi-line scan of `patient` (mesh in the patient frame) with the robot
/// base at `base_t_patient`.
pub(crate) fn scan(
    cfg: &SweepConfig,
    cal: &Calibration,
    patient: &SubjectParams,
    mesh: &Mesh,
    base_t_patient: &Isometry3<f64>,
    rng: &mut Rng,
) -> Scan {
    let skin = Skin::new(patient, cfg.skin_offset_mm);
    let (lo, hi) = extent(mesh);
    let path = ScanPath::over(
        cfg,
        [lo[0] - cfg.margin_mm, hi[0] + cfg.margin_mm],
        [lo[1], hi[1]],
    );
    let duration = path.total() / cfg.speed_mm_s;
    let tcp_at = |t: f64| {
        let [x, y] = path.at(t * cfg.speed_mm_s);
        skin.tcp(x, y)
    };
    let ee_t_tcp = isometry(&cal.ee_t_tcp);
    let tcp_t_us = isometry(&cal.tcp_t_us);
    let tcp_t_ee = ee_t_tcp.inverse();

    let n_poses = (duration * cfg.pose_rate_hz).floor() as usize + 1;
    let poses = (0..n_poses)
        .map(|k| {
            let t = k as f64 / cfg.pose_rate_hz;
            let b_t_ee = base_t_patient * tcp_at(t) * tcp_t_ee;
            let noise = V3::new(gaussian(rng), gaussian(rng), gaussian(rng)) * cfg.tracker_noise_mm;
            PoseRow::from_isometry(t, &b_t_ee, noise)
        })
        .collect();

    let probe = cal.probe;
    let (_, sy) = probe.scale();
    let step = usize::from(cfg.column_step_px.max(1));
    let columns: Vec<f64> = (0..usize::from(probe.width_px))
        .step_by(step)
        .map(|c| c as f64 + 0.5)
        .collect();
    let mut depth = vec![None; columns.len()];
    let mut renderer = Renderer::new(mesh);
    let n_frames = (duration * cfg.frame_rate_hz).floor() as usize + 1;
    let mut frames = Vec::new();
    let mut captured_frames = Vec::with_capacity(n_frames);
    for i in 0..n_frames {
        let tau = i as f64 / cfg.frame_rate_hz;
        let stamp = tau + cfg.lag_ms * 1e-3 + gaussian(rng) * cfg.timestamp_jitter_ms * 1e-3;
        let missed = rng.next_f64() < cfg.frame_miss_rate;
        captured_frames.push(CapturedFrame {
            frame: i as u32,
            t: stamp,
            lost: missed,
        });
        if missed {
            continue;
        }
        renderer.render(&(tcp_at(tau) * tcp_t_us), cal, &columns, &mut depth);
        for (c, d) in columns.iter().zip(&depth) {
            if let Some(d) = d {
                let v = d / f64::from(sy) + gaussian(rng) * cfg.pixel_noise_px;
                if (0.0..=f64::from(probe.height_px)).contains(&v) {
                    frames.push(FrameRow {
                        frame: i as u32,
                        t: stamp,
                        u: *c,
                        v,
                    });
                }
            }
        }
    }
    Scan {
        poses,
        frames,
        captured: n_frames,
        duration_s: duration,
        lines: path.corners.len() / 2,
        captured_frames,
    }
}

/// A temporal-calibration sweep: the probe moved up and down along its beam above a
/// point landmark (three incommensurate sines, never periodic within ±0.5 s), tracked
/// TCP positions at the pose rate and the landmark row per frame; and every captured
/// frame, lost or logged (`calib.seq.mha`), the logged ones in the order of the rows.
pub(crate) fn calibration_sweep(
    cfg: &SweepConfig,
    cal: &Calibration,
    rng: &mut Rng,
) -> (super::CalibrationLogs, Vec<CapturedFrame>) {
    let landmark = Point3::new(350.0, -120.0, -40.0);
    let beam = V3::new(0.12, -0.05, -1.0).normalize();
    let mid = 0.5 * f64::from(cal.probe.depth_mm);
    let a = cfg.calibration_amplitude_mm;
    let depth_at = |t: f64| {
        use std::f64::consts::TAU;
        mid + a
            * (0.6 * (TAU * 0.23 * t).sin()
                + 0.3 * (TAU * 0.61 * t + 1.0).sin()
                + 0.1 * (TAU * 1.3 * t + 2.0).sin())
    };
    let duration = cfg.calibration_duration_s;
    let n = (duration * cfg.pose_rate_hz).floor() as usize + 1;
    let tracker = (0..n)
        .map(|k| {
            let t = k as f64 / cfg.pose_rate_hz;
            let p = landmark - beam * depth_at(t);
            let e = V3::new(gaussian(rng), gaussian(rng), gaussian(rng)) * cfg.tracker_noise_mm;
            [t, p.x + e.x, p.y + e.y, p.z + e.z]
        })
        .collect();
    let (_, sy) = cal.probe.scale();
    let frames = (duration * cfg.frame_rate_hz).floor() as usize + 1;
    let mut video = Vec::with_capacity(frames);
    let mut captured = Vec::with_capacity(frames);
    for i in 0..frames {
        let tau = i as f64 / cfg.frame_rate_hz;
        let stamp = tau + cfg.lag_ms * 1e-3 + gaussian(rng) * cfg.timestamp_jitter_ms * 1e-3;
        let mut lost = true;
        if rng.next_f64() >= cfg.frame_miss_rate {
            let row = depth_at(tau) / f64::from(sy) + gaussian(rng) * cfg.calibration_noise_px;
            // Jitter may swap two stamps of neighbouring frames only if it exceeds half a
            // frame period; keep the stream strictly increasing as a frame grabber would.
            if video.last().is_none_or(|l: &[f64; 2]| stamp > l[0]) {
                video.push([stamp, row]);
                lost = false;
            }
        }
        captured.push(CapturedFrame {
            frame: i as u32,
            t: stamp,
            lost,
        });
    }
    ((tracker, video), captured)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::phantom::SubjectGeometry;
    use ribreg_core::acquisition::probe::ProbeModel;
    use ribreg_core::math::geom::Rigid;

    #[test]
    fn skin_normal_is_perpendicular_to_the_surface() {
        let skin = Skin::new(&SubjectParams::template(), 10.0);
        let (p, n) = skin.at(40.0, -20.0);
        let h = 1e-4;
        let (px, _) = skin.at(40.0 + h, -20.0);
        let (py, _) = skin.at(40.0, -20.0 + h);
        assert!(((px - p) / h).dot(&n).abs() < 1e-6);
        assert!(((py - p) / h).dot(&n).abs() < 1e-6);
        assert!(n.z > 0.0);
        // TCP: beam into the body, right-handed.
        let tcp = skin.tcp(40.0, -20.0);
        let r = tcp.rotation.to_rotation_matrix();
        assert!((r.matrix().column(2) + n).norm() < 1e-9);
        assert!((r.matrix().determinant() - 1.0).abs() < 1e-9);
    }

    /// A negative margin stops the lines inside the cartilages' extent, down to
    /// [`crate::sweep::MIN_MARGIN_MM`]; below it, or not finite, the settings are refused,
    /// and so is a robot base's yaw that is not a number within a turn.
    #[test]
    fn the_margin_may_stop_the_lines_short_within_bounds() {
        use crate::sweep::{SweepConfig, MIN_MARGIN_MM};
        let with = |margin_mm| SweepConfig {
            margin_mm,
            ..SweepConfig::default()
        };
        for ok in [10.0, 0.0, -20.0, MIN_MARGIN_MM] {
            assert!(with(ok).validate().is_ok(), "{ok}");
        }
        for bad in [MIN_MARGIN_MM - 1.0, f64::NAN, f64::INFINITY] {
            let e = with(bad).validate().unwrap_err().to_string();
            assert!(e.contains("margin"), "{bad}: {e}");
        }
        // The robot base's yaw likewise: any turn, but a number.
        let yaw = |base_yaw_deg| SweepConfig {
            base_yaw_deg,
            ..SweepConfig::default()
        };
        for ok in [0.0, -90.0, 180.0, 360.0] {
            assert!(yaw(ok).validate().is_ok(), "{ok}");
        }
        for bad in [361.0, f64::NAN, f64::NEG_INFINITY] {
            let e = yaw(bad).validate().unwrap_err().to_string();
            assert!(e.contains("yaw"), "{bad}: {e}");
        }
    }

    /// The lines a band's images give are the path's: one per pass, each from one lateral
    /// end to the other (its end images' centres within the beam's tilt of them).
    #[test]
    fn a_band_s_images_make_one_line_per_pass() {
        let patient = SubjectParams::template();
        let cfg = SweepConfig::default();
        let cal = super::super::default_calibration();
        let (x, y) = ([-90.0, 60.0], [-80.0, 40.0]);
        let area = imaged(&cfg, &cal, &patient, x, y, &Isometry3::identity());
        let passes = ScanPath::over(&cfg, x, y).corners.len() / 2;
        assert_eq!(passes, 14);
        assert_eq!((area.line_count(), area.dropped), (passes, 0));
        for (k, [first, last]) in area.lines().enumerate() {
            let ends = if k % 2 == 0 { x } else { [x[1], x[0]] };
            let off = [
                first.centre.x - ends[0] as f32,
                last.centre.x - ends[1] as f32,
            ];
            assert!(off.iter().all(|d| d.abs() < 15.0), "line {k}: {off:?}");
        }
    }

    #[test]
    fn serpentine_path_visits_every_line() {
        let p = ScanPath::serpentine(-100.0, 100.0, 50.0, -30.0, 10.0);
        assert_eq!(p.corners.len(), 18);
        assert_eq!(p.at(0.0), [-100.0, 50.0]);
        assert_eq!(p.at(200.0), [100.0, 50.0]);
        assert_eq!(p.at(205.0), [100.0, 45.0]);
        assert_eq!(p.at(1e9), *p.corners.last().unwrap());
    }

    /// Straight down on a flat square at 20 mm: every column sees it at 20 mm.
    #[test]
    fn renders_the_first_surface_along_the_beam() {
        let verts = vec![
            [-50.0, -50.0, -20.0],
            [50.0, -50.0, -20.0],
            [50.0, 50.0, -20.0],
            [-50.0, 50.0, -20.0],
            [-50.0, -50.0, -25.0],
            [50.0, -50.0, -25.0],
            [50.0, 50.0, -25.0],
            [-50.0, 50.0, -25.0],
        ];
        let tris = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let mesh: Mesh = (verts, tris);
        let cal = Calibration::centred(ProbeModel::LINEAR_38MM, Rigid::identity());
        // TCP at the origin, beam along −z, footprint along y.
        let tcp = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.0),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
                Matrix3::from_columns(&[V3::y(), V3::x(), -V3::z()]),
            )),
        );
        let columns: Vec<f64> = (0..384).step_by(8).map(|c| c as f64 + 0.5).collect();
        let mut depth = vec![None; columns.len()];
        Renderer::new(&mesh).render(&(tcp * isometry(&cal.tcp_t_us)), &cal, &columns, &mut depth);
        assert!(
            depth
                .iter()
                .all(|d| d.is_some_and(|d| (d - 20.0).abs() < 1e-9)),
            "{depth:?}"
        );
    }

    #[test]
    fn phantom_scan_sees_cartilage_on_both_sides() {
        let patient = SubjectParams::template();
        let mesh = SubjectGeometry::new(&patient).mesh(crate::phantom::MESH_EDGE_MM);
        let cfg = SweepConfig {
            line_spacing_mm: 30.0,
            speed_mm_s: 60.0,
            ..SweepConfig::default()
        };
        let cal = super::super::default_calibration();
        let scan = scan(
            &cfg,
            &cal,
            &patient,
            &mesh,
            &Isometry3::identity(),
            &mut Rng::new(1),
        );
        assert!(scan.frames.len() > 1000, "{}", scan.frames.len());
        assert!(scan.poses.len() as f64 > scan.duration_s * 99.0);
        let frames = scan
            .frames
            .iter()
            .map(|f| f.frame)
            .collect::<std::collections::BTreeSet<_>>();
        assert!(
            frames.len() > scan.captured / 4,
            "{} of {}",
            frames.len(),
            scan.captured
        );
    }
}
