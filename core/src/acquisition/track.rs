//! Robot pose tracking: a fixed-capacity window of time-stamped flange poses and their
//! interpolation (position lerp, orientation slerp) at any time inside it.
//!
//! Poses arrive at 100 Hz; a US frame is placed with the pose at its time minus the
//! temporal-calibration lag (paper: 268 ms), so the window must reach that far back plus
//! the frame delivery latency. A time outside the window is refused
//! ([`Error::OutsideTrack`]), never extrapolated, and so is a time between two poses more
//! than [`MAX_TRACK_GAP_MS`] apart ([`Error::TrackGap`]: the robot stream dropped out).

use crate::error::{Error, Result, Stream};
use crate::math::geom::Rigid;
use crate::Vec3;
use nalgebra::{Quaternion, Rotation3, UnitQuaternion};

/// Largest gap between consecutive poses interpolated over, ms (five 100 Hz periods).
pub const MAX_TRACK_GAP_MS: f32 = 50.0;
/// Largest deviation of a received quaternion's norm from 1 before it is refused rather
/// than normalised (a garbled or unnormalised pose, not rounding).
pub const QUATERNION_NORM_TOLERANCE: f32 = 1e-2;

/// A robot flange pose `b_T_ee` at time `t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackedPose {
    /// Time stamp, s (the tracker's clock).
    pub t: f64,
    /// Flange position in the base frame, mm.
    pub position: Vec3,
    /// Flange orientation in the base frame.
    pub orientation: UnitQuaternion<f32>,
}

impl TrackedPose {
    /// A pose from a time, a position and a quaternion `[w, x, y, z]`; the quaternion is
    /// normalised if its norm is within [`QUATERNION_NORM_TOLERANCE`] of 1. Anything not
    /// finite, or a quaternion further from unit norm, is [`Error::Sample`] (index 0: the
    /// caller knows which sample it is).
    pub fn new(t: f64, position: Vec3, wxyz: [f32; 4]) -> Result<TrackedPose> {
        let bad = Error::Sample {
            stream: Stream::Poses,
            index: 0,
        };
        let q = Quaternion::new(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
        let finite = t.is_finite()
            && position
                .iter()
                .chain(q.coords.iter())
                .all(|v| v.is_finite());
        if !finite || position.amax() > crate::limits::MAX_COORD_MM {
            return Err(bad);
        }
        if (q.norm() - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
            return Err(bad);
        }
        Ok(TrackedPose {
            t,
            position,
            orientation: UnitQuaternion::from_quaternion(q),
        })
    }

    /// The pose of a rigid transform (its rotation must be proper).
    pub fn from_rigid(t: f64, pose: &Rigid) -> TrackedPose {
        // Normalised: `from_rotation_matrix` of a rotation that f32 products have left a
        // little off orthonormal is a little off unit norm, and that quaternion's matrix
        // further off still (its scale squared). A pose taken from its own matrix at
        // every step, as a robot's TCP following setpoints, then diverged (the simulated
        // robot's reports reached norm 1.065 within 1.6 s of resting at a target, and
        // the controller refused them).
        let q =
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(pose.rotation));
        TrackedPose {
            t,
            position: pose.translation,
            orientation: UnitQuaternion::new_normalize(q.into_inner()),
        }
    }

    /// The pose as a rigid transform `b_T_ee`.
    pub fn to_rigid(&self) -> Rigid {
        Rigid {
            rotation: self.orientation.to_rotation_matrix().into_inner(),
            translation: self.position,
        }
    }

    /// Position lerp and orientation slerp (along the shorter arc) from `self` (s = 0) to
    /// `next` (s = 1).
    pub fn interpolate(&self, next: &TrackedPose, s: f32) -> Rigid {
        let q0 = self.orientation;
        let mut q1 = next.orientation;
        if q0.coords.dot(&q1.coords) < 0.0 {
            q1 = UnitQuaternion::new_unchecked(-q1.into_inner());
        }
        // The shorter arc is at most 90° in quaternion space, so slerp is well defined;
        // nlerp is the fallback should it ever refuse. Between two orientations less
        // than a degree apart f32 slerp's weights (from `acos` and `sqrt` of a cosine
        // rounded near 1) miss unit norm by up to ~1e-4, so the result is normalised.
        let q = q0
            .try_slerp(&q1, s, 1e-6)
            .unwrap_or_else(|| q0.nlerp(&q1, s));
        let q = UnitQuaternion::new_normalize(q.into_inner());
        Rigid {
            rotation: q.to_rotation_matrix().into_inner(),
            translation: self.position.lerp(&next.position, s),
        }
    }
}

/// The last `N` tracked poses, in time order; when full, a new pose replaces the oldest.
#[derive(Clone)]
pub struct PoseTrack<const N: usize> {
    buf: [TrackedPose; N],
    /// Index of the oldest pose in `buf`.
    head: usize,
    len: usize,
    /// Poses accepted since creation.
    pub received: u32,
    /// Poses refused by [`PoseTrack::push`] (not finite, or not later than the newest).
    pub refused: u32,
}

impl<const N: usize> Default for PoseTrack<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> PoseTrack<N> {
    /// An empty window.
    pub const fn new() -> Self {
        const ZERO: TrackedPose = TrackedPose {
            t: 0.0,
            position: Vec3::new(0.0, 0.0, 0.0),
            orientation: UnitQuaternion::new_unchecked(Quaternion::new(1.0, 0.0, 0.0, 0.0)),
        };
        PoseTrack {
            buf: [ZERO; N],
            head: 0,
            len: 0,
            received: 0,
            refused: 0,
        }
    }

    /// Forgets every pose (and the counters).
    pub fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
        self.received = 0;
        self.refused = 0;
    }

    /// Poses held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// No pose held yet.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The `i`-th oldest pose held.
    fn get(&self, i: usize) -> &TrackedPose {
        &self.buf[(self.head + i) % N]
    }

    /// Time span held, `(oldest, newest)`, s.
    pub fn span(&self) -> Option<(f64, f64)> {
        (self.len > 0).then(|| (self.get(0).t, self.get(self.len - 1).t))
    }

    /// Appends a pose. It must be finite and later than the newest held, else
    /// [`Error::Sample`] (index = poses received so far) and the window is unchanged.
    pub fn push(&mut self, pose: TrackedPose) -> Result<()> {
        let later = self.span().is_none_or(|(_, newest)| pose.t > newest);
        let finite = pose.t.is_finite()
            && pose.position.iter().all(|v| v.is_finite())
            && pose.orientation.coords.iter().all(|v| v.is_finite());
        if N == 0 || !later || !finite {
            self.refused = self.refused.saturating_add(1);
            return Err(Error::Sample {
                stream: Stream::Poses,
                index: self.received,
            });
        }
        if self.len == N {
            self.buf[self.head] = pose;
            self.head = (self.head + 1) % N;
        } else {
            self.buf[(self.head + self.len) % N] = pose;
            self.len += 1;
        }
        self.received = self.received.saturating_add(1);
        Ok(())
    }

    /// The flange pose at time `t`, interpolated between the two poses around it.
    pub fn at(&self, t: f64) -> Result<Rigid> {
        let Some((oldest, newest)) = self.span() else {
            return Err(Error::OutsideTrack { by_ms: 0.0 });
        };
        if !t.is_finite() {
            return Err(Error::Sample {
                stream: Stream::Frames,
                index: 0,
            });
        }
        if t < oldest || t > newest {
            let by = if t < oldest { t - oldest } else { t - newest };
            return Err(Error::OutsideTrack {
                by_ms: (by * 1e3) as f32,
            });
        }
        // Binary search for the last pose at or before t (times strictly increase).
        let (mut lo, mut hi) = (0, self.len - 1);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if self.get(mid).t <= t {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let (a, b) = (self.get(lo), self.get(hi));
        if lo == hi || t == a.t {
            return Ok(a.to_rigid());
        }
        // Exactly on the newer pose (the search never lands `lo` on the newest): that
        // pose, whatever the gap before it. A sequence with one pose per frame places
        // each frame at its own pose's time.
        if t == b.t {
            return Ok(b.to_rigid());
        }
        let gap_ms = ((b.t - a.t) * 1e3) as f32;
        if gap_ms > MAX_TRACK_GAP_MS {
            return Err(Error::TrackGap {
                gap_ms,
                max_ms: MAX_TRACK_GAP_MS,
            });
        }
        Ok(a.interpolate(b, ((t - a.t) / (b.t - a.t)) as f32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(t: f64, x: f32, yaw_deg: f32) -> TrackedPose {
        let q = UnitQuaternion::from_axis_angle(&Vec3::z_axis(), yaw_deg.to_radians());
        TrackedPose {
            t,
            position: Vec3::new(x, 0.0, 0.0),
            orientation: q,
        }
    }

    #[test]
    fn interpolates_between_and_refuses_outside() {
        let mut track = PoseTrack::<4>::new();
        assert_eq!(track.at(0.0), Err(Error::OutsideTrack { by_ms: 0.0 }));
        for i in 0..6 {
            track
                .push(pose(f64::from(i) * 0.01, i as f32 * 10.0, i as f32 * 20.0))
                .unwrap();
        }
        // The window kept the last four poses: t = 0.02 … 0.05.
        assert_eq!(track.len(), 4);
        assert_eq!(track.span(), Some((0.02, 0.05)));
        let r = track.at(0.0325).unwrap();
        assert!((r.translation.x - 32.5).abs() < 1e-4);
        let expected = UnitQuaternion::from_axis_angle(&Vec3::z_axis(), 65f32.to_radians());
        let got = UnitQuaternion::from_matrix(&r.rotation);
        assert!(got.angle_to(&expected) < 1e-5);
        // Exactly on a sample, and at both ends.
        assert!((track.at(0.05).unwrap().translation.x - 50.0).abs() < 1e-5);
        assert!((track.at(0.02).unwrap().translation.x - 20.0).abs() < 1e-5);
        match track.at(0.01) {
            Err(Error::OutsideTrack { by_ms }) => assert!((by_ms + 10.0).abs() < 1e-3),
            other => panic!("{other:?}"),
        }
        match track.at(0.06) {
            Err(Error::OutsideTrack { by_ms }) => assert!((by_ms - 10.0).abs() < 1e-3),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn refuses_stale_non_finite_and_gaps() {
        let mut track = PoseTrack::<8>::new();
        track.push(pose(1.0, 0.0, 0.0)).unwrap();
        assert!(track.push(pose(1.0, 0.0, 0.0)).is_err());
        assert!(track.push(pose(0.5, 0.0, 0.0)).is_err());
        assert!(track.push(pose(f64::NAN, 0.0, 0.0)).is_err());
        assert_eq!((track.len(), track.received, track.refused), (1, 1, 3));
        track.push(pose(1.2, 10.0, 0.0)).unwrap();
        assert!(matches!(track.at(1.1), Err(Error::TrackGap { .. })));
        // Exactly on either pose around a gap is that pose, not an interpolation.
        assert_eq!(track.at(1.2).unwrap().translation.x, 10.0);
        assert_eq!(track.at(1.0).unwrap().translation.x, 0.0);
        assert!(TrackedPose::new(0.0, Vec3::zeros(), [0.5, 0.0, 0.0, 0.0]).is_err());
        assert!(TrackedPose::new(0.0, Vec3::zeros(), [1.001, 0.0, 0.0, 0.0]).is_ok());
    }

    /// Slerp takes the shorter arc even when the two quaternions have opposite signs.
    #[test]
    fn slerp_takes_the_shorter_arc() {
        let a = pose(0.0, 0.0, 170.0);
        let mut b = pose(0.01, 0.0, -170.0);
        b.orientation = UnitQuaternion::new_unchecked(-b.orientation.into_inner());
        let r = a.interpolate(&b, 0.5);
        let got = UnitQuaternion::from_matrix(&r.rotation);
        let expected = UnitQuaternion::from_axis_angle(&Vec3::z_axis(), 180f32.to_radians());
        assert!(
            got.angle_to(&expected) < 1e-4,
            "{}",
            got.angle_to(&expected)
        );
    }

    /// The simulated robot's TCP, taken from its own matrix and slerped toward a target
    /// at every setpoint, drifted off unit norm and diverged (README "A robot pose that
    /// stays a rotation"): both steps now stay rotations.
    #[test]
    fn poses_stay_rotations_off_orthonormal_input_and_close_slerps() {
        let p = pose(0.0, 3.0, 33.0);
        let mut r = p.to_rigid();
        r.rotation *= 1.0003;
        let back = TrackedPose::from_rigid(0.0, &r);
        assert!((back.orientation.into_inner().norm() - 1.0).abs() < 1e-6);
        assert!(back.orientation.angle_to(&p.orientation) < 1e-3);
        let a = pose(0.0, 0.0, 33.0);
        for j in 1..=100 {
            let b = pose(0.01, 0.0, 33.0 + j as f32 * 0.02);
            for k in 1..10 {
                let r = a.interpolate(&b, k as f32 / 10.0).rotation;
                let off = (r.transpose() * r - nalgebra::Matrix3::identity()).amax();
                assert!(
                    off < 1e-6,
                    "{}°, s {k}/10: R^T R − I up to {off}",
                    j as f32 * 0.02
                );
            }
        }
    }

    #[test]
    fn rigid_round_trip() {
        let p = pose(0.0, 3.0, 33.0);
        let back = TrackedPose::from_rigid(0.0, &p.to_rigid());
        assert!(back.orientation.angle_to(&p.orientation) < 1e-5);
        assert_eq!(back.position, p.position);
    }
}
