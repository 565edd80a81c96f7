//! The simulated robot and its probe: the sweep it drives (poses at 100 Hz and annotated
//! frames at 30 fps from [`crate::sweep`], in arrival order), its flange standing still
//! while the controller registers, and while executing a TCP that follows each setpoint
//! with a first-order lag of [`ROBOT_LAG_S`]. Where the probe aims is the TCP plus
//! [`STANDOFF_MM`] along the beam.

use ribreg_core::acquisition::track::TrackedPose;
use ribreg_core::math::geom::Rigid;
use ribreg_core::wire::{FrameW, PoseW, SetpointW, ToController, PIXEL_SUBDIVISIONS};
use ribreg_core::{Error, Vec3};

use crate::sweep;

/// The simulated robot follows setpoints with this time constant, s.
pub const ROBOT_LAG_S: f32 = 0.05;
/// Probe standoff above the bone surface, mm.
pub const STANDOFF_MM: f32 = 15.0;

/// The rows of a phantom sweep as wire messages in arrival order (time-sorted).
pub fn sweep_messages(logs: &sweep::SweepLogs) -> Vec<ToController> {
    let mut events: Vec<(f64, ToController)> = logs
        .poses
        .iter()
        .map(|p| {
            (
                p.t,
                ToController::Pose(PoseW {
                    t_us: (p.t * 1e6).round() as u64,
                    position: p.position.map(|v| v as f32),
                    quat: p.quaternion.map(|v| v as f32),
                }),
            )
        })
        .collect();
    let mut i = 0;
    while i < logs.frames.len() {
        let f = logs.frames[i];
        let mut pixels = heapless::Vec::new();
        while i < logs.frames.len() && logs.frames[i].frame == f.frame {
            let r = logs.frames[i];
            let q = |v: f64| {
                (v * f64::from(PIXEL_SUBDIVISIONS))
                    .round()
                    .clamp(0.0, f64::from(u16::MAX)) as u16
            };
            let _ = pixels.push([q(r.u), q(r.v)]);
            i += 1;
        }
        events.push((
            f.t,
            ToController::Frame(FrameW {
                t_us: (f.t.max(0.0) * 1e6).round() as u64,
                frame: f.frame,
                pixels,
            }),
        ));
    }
    // Stable: a pose and a frame stamped alike arrive pose first.
    events.sort_by(|a, b| a.0.total_cmp(&b.0));
    events.into_iter().map(|(_, m)| m).collect()
}

/// The robot after the sweep: its flange, and its TCP once executing.
pub struct Robot {
    flange: Rigid,
    tcp: Rigid,
    ee_t_tcp: Rigid,
    tcp_t_ee: Rigid,
    alpha: f32,
}

impl Robot {
    /// Standing where the sweep ended (`standing`: position, wxyz quaternion; the base
    /// frame when there was no sweep), with the probe's flange → TCP transform.
    pub fn standing(
        standing: Option<([f64; 3], [f64; 4])>,
        ee_t_tcp: Rigid,
    ) -> Result<Self, Error> {
        let flange = match standing {
            Some((p, q)) => {
                TrackedPose::new(0.0, Vec3::from(p.map(|v| v as f32)), q.map(|v| v as f32))?
                    .to_rigid()
            }
            None => Rigid::identity(),
        };
        Ok(Robot {
            flange,
            tcp: flange.after(&ee_t_tcp),
            ee_t_tcp,
            tcp_t_ee: ee_t_tcp.inverse(),
            alpha: 1.0 - (-0.01 / ROBOT_LAG_S).exp(),
        })
    }

    /// The flange pose report stamped `t_us`.
    pub fn pose(&self, t_us: u64) -> ToController {
        let q = TrackedPose::from_rigid(0.0, &self.flange)
            .orientation
            .into_inner();
        ToController::Pose(PoseW {
            t_us,
            position: self.flange.translation.into(),
            quat: [q.w, q.i, q.j, q.k],
        })
    }

    /// Starts executing: the TCP is where the standing flange holds it.
    pub fn start_executing(&mut self) {
        self.tcp = self.flange.after(&self.ee_t_tcp);
    }

    /// Moves the TCP 10 ms toward setpoint `sp`.
    pub fn follow(&mut self, sp: &SetpointW) -> Result<(), Error> {
        let target = TrackedPose::new(0.0, Vec3::from(sp.position), sp.quat)?.to_rigid();
        let q0 = TrackedPose::from_rigid(0.0, &self.tcp);
        let q1 = TrackedPose::from_rigid(1.0, &target);
        self.tcp = q0.interpolate(&q1, self.alpha);
        Ok(())
    }

    /// Updates the flange from the TCP (before a pose report while executing).
    pub fn update_flange(&mut self) {
        self.flange = self.tcp.after(&self.tcp_t_ee);
    }

    /// The TCP now.
    pub fn tcp(&self) -> Rigid {
        self.tcp
    }
}

/// Where a probe with TCP `tcp` aims: [`STANDOFF_MM`] along its beam (TCP z), mm.
pub fn aim_point(tcp: &Rigid) -> [f64; 3] {
    let p = tcp.translation + tcp.rotation.column(2) * STANDOFF_MM;
    [f64::from(p.x), f64::from(p.y), f64::from(p.z)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};
    use ribreg_core::acquisition::track::QUATERNION_NORM_TOLERANCE;
    use ribreg_core::math::rng::Rng;

    /// Hard phantom 49's execution (`hil --in-process --seed 49 --preset hard`) stalled:
    /// resting at a target, the TCP's quaternion, taken from its rotation matrix at every
    /// setpoint, grew off unit norm (1.0002 → 1.065 within 1.6 s of dwell) until the
    /// controller refused the robot's pose reports and stopped its setpoints.
    #[test]
    fn the_reported_pose_stays_a_rotation_while_resting_at_targets() {
        let ee_t_tcp = crate::sweep::default_calibration().ee_t_tcp;
        let standing = ([117.6, -22.0, -24.8], [0.5, -0.5, -0.5, 0.5]);
        let mut robot = Robot::standing(Some(standing), ee_t_tcp).unwrap();
        robot.start_executing();
        let mut rng = Rng::new(49);
        let mut t_us = 0;
        // 40 targets in random orientations, each held for 3 s of 100 Hz setpoints.
        for target in 0..40u8 {
            let axis = Vector3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            );
            let q = UnitQuaternion::from_scaled_axis(axis.normalize() * 3.0 * rng.next_f32());
            let sp = SetpointW {
                t_us,
                position: [
                    (rng.next_f32() - 0.5) * 50.0,
                    (rng.next_f32() - 0.5) * 50.0,
                    -30.0,
                ],
                quat: [q.w, q.i, q.j, q.k],
                waypoint: target,
            };
            for _ in 0..300 {
                t_us += 10_000;
                robot.follow(&sp).unwrap();
                robot.update_flange();
                let ToController::Pose(p) = robot.pose(t_us) else {
                    unreachable!()
                };
                let norm = p.quat.iter().map(|v| v * v).sum::<f32>().sqrt();
                assert!(
                    (norm - 1.0).abs() < 1e-2 * QUATERNION_NORM_TOLERANCE,
                    "target {target}, {t_us} µs: quaternion norm {norm}"
                );
                let rot = robot.tcp().rotation;
                let off = (rot.transpose() * rot - nalgebra::Matrix3::identity()).amax();
                assert!(
                    off < 1e-5,
                    "target {target}, {t_us} µs: R^T R − I up to {off}"
                );
            }
        }
    }
}
