//! Motion: straight segments from target to target with a trapezoidal speed profile
//! (configured speed and acceleration limits) and a dwell at each target, position lerp
//! and orientation slerp along them, setpoints streamed every [`SETPOINT_PERIOD_US`], and
//! the pose watchdog that stops them after [`POSE_TIMEOUT_US`] without a robot pose and
//! resumes them, from where they stopped, when poses come back.

use super::Controller;
use crate::acquisition::track::TrackedPose;
use crate::math::geom::Rigid;
use crate::wire::{FromController, SetpointW, State};

/// Robot poses may pause this long while executing before setpoints stop, µs.
pub const POSE_TIMEOUT_US: u64 = 50_000;
/// Setpoint period while executing, µs (100 Hz).
pub const SETPOINT_PERIOD_US: u64 = 10_000;
/// Time the probe rests at each target, µs.
pub const DWELL_US: u64 = 500_000;

/// One straight move with a trapezoidal speed profile, then a dwell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Segment {
    pub(super) from: Rigid,
    pub(super) to: Rigid,
    pub(super) start_us: u64,
    pub(super) target: u8,
}

impl<const VOXELS: usize> Controller<VOXELS> {
    pub(super) fn execute(&mut self, now_us: u64) {
        let fresh = self
            .last_pose
            .is_some_and(|(at, _)| now_us.saturating_sub(at) <= POSE_TIMEOUT_US);
        if !fresh {
            if self.paused_since.is_none() {
                self.paused_since = Some(now_us);
                self.send(FromController::Fault(crate::wire::Fault::PoseTimeout));
            }
            return;
        }
        if let Some(since) = self.paused_since.take() {
            // Resume where the setpoints stopped: the profile clock skips the pause.
            if let Some(seg) = &mut self.segment {
                seg.start_us = seg.start_us.saturating_add(now_us.saturating_sub(since));
            }
            self.next_setpoint_us = now_us;
        }
        if now_us < self.next_setpoint_us {
            return;
        }
        self.next_setpoint_us = now_us.saturating_add(SETPOINT_PERIOD_US);
        let (Some(seg), Some(s)) = (self.segment, self.settings) else {
            return;
        };
        let d = (seg.to.translation - seg.from.translation).norm();
        let move_us = trapezoid_duration_us(d, s.max_speed, s.max_accel);
        let elapsed = now_us.saturating_sub(seg.start_us);
        let pose = if elapsed >= move_us {
            seg.to
        } else {
            let travelled = trapezoid_distance(elapsed as f32 * 1e-6, d, s.max_speed, s.max_accel);
            interpolate(
                &seg.from,
                &seg.to,
                if d > 0.0 { travelled / d } else { 1.0 },
            )
        };
        self.waypoint = seg.target;
        let q = TrackedPose::from_rigid(0.0, &pose).orientation;
        self.send(FromController::Setpoint(SetpointW {
            t_us: now_us,
            position: pose.translation.into(),
            quat: [q.w, q.i, q.j, q.k],
            waypoint: seg.target,
        }));
        if elapsed >= move_us.saturating_add(DWELL_US) {
            // The next waypoint the sweep reaches (a partial plan skips the rest).
            let after = usize::from(seg.target) + 1;
            let mut rest = self.targets.iter().enumerate().skip(after);
            match rest.find(|(_, t)| t.supported).map(|(i, t)| (i, t.tcp)) {
                Some((next, tcp)) => {
                    self.segment = Some(Segment {
                        from: seg.to,
                        to: tcp,
                        start_us: now_us,
                        target: next as u8,
                    });
                }
                None => {
                    self.segment = None;
                    self.state = State::Done;
                }
            }
        }
    }
}

/// Time of a rest-to-rest move of `d` mm under speed and acceleration limits, µs.
fn trapezoid_duration_us(d: f32, v: f32, a: f32) -> u64 {
    let t = if d * a <= v * v {
        2.0 * libm::sqrtf(d / a)
    } else {
        d / v + v / a
    };
    (t * 1e6) as u64
}

/// Distance covered after `t` s of that move.
fn trapezoid_distance(t: f32, d: f32, v: f32, a: f32) -> f32 {
    let (t_acc, v_peak) = if d * a <= v * v {
        (libm::sqrtf(d / a), libm::sqrtf(d * a))
    } else {
        (v / a, v)
    };
    let d_acc = 0.5 * v_peak * t_acc;
    let t_cruise = (d - 2.0 * d_acc) / v_peak;
    let s = if t <= t_acc {
        0.5 * a * t * t
    } else if t <= t_acc + t_cruise {
        d_acc + v_peak * (t - t_acc)
    } else {
        let td = (t - t_acc - t_cruise).min(t_acc);
        d - d_acc + v_peak * td - 0.5 * a * td * td
    };
    s.clamp(0.0, d)
}

/// Position lerp and orientation slerp from `a` (s = 0) to `b` (s = 1).
fn interpolate(a: &Rigid, b: &Rigid, s: f32) -> Rigid {
    let ta = TrackedPose::from_rigid(0.0, a);
    let tb = TrackedPose::from_rigid(1.0, b);
    ta.interpolate(&tb, s.clamp(0.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trapezoid_profile_respects_limits() {
        for (d, v, a) in [(100.0f32, 20.0, 50.0), (2.0, 20.0, 50.0), (0.0, 10.0, 10.0)] {
            let total = trapezoid_duration_us(d, v, a) as f32 * 1e-6;
            let mut prev = 0.0;
            let mut prev_speed = 0.0;
            let dt = 0.01;
            let mut t = 0.0;
            while t <= total + dt {
                let s = trapezoid_distance(t, d, v, a);
                let speed = (s - prev) / dt;
                assert!(speed <= v * 1.01 + 1e-3, "{d} {t}: {speed}");
                assert!(
                    (speed - prev_speed).abs() / dt <= a * 1.05 + 1e-2 || t < 2.0 * dt,
                    "{d} {t}"
                );
                prev = s;
                prev_speed = speed;
                t += dt;
            }
            assert!((trapezoid_distance(total, d, v, a) - d).abs() < 1e-3);
        }
    }
}
