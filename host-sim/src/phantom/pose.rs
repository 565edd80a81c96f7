//! Rigid poses `x' = R x + t`.

use serde::{Deserialize, Serialize};

use super::*;

// ---------------------------------------------------------------------------------------
// Pose
// ---------------------------------------------------------------------------------------

/// A rigid transform `x' = R x + t` (rotation row-major: `rotation[i][j] = R_ij`; mm).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Rotation matrix, row-major.
    pub rotation: [[f64; 3]; 3],
    /// Translation, mm.
    pub translation: [f64; 3],
}

impl Pose {
    /// The identity transform.
    pub fn identity() -> Self {
        Self {
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation: [0.0; 3],
        }
    }

    /// Rotation by `angle_rad` about the unit `axis` (Rodrigues), then translation.
    pub fn from_axis_angle(axis: [f64; 3], angle_rad: f64, translation: [f64; 3]) -> Self {
        let k = normalize_or(axis, [0.0, 0.0, 1.0]);
        let (s, c) = angle_rad.sin_cos();
        let v = 1.0 - c;
        let rotation = [
            [
                c + k[0] * k[0] * v,
                k[0] * k[1] * v - k[2] * s,
                k[0] * k[2] * v + k[1] * s,
            ],
            [
                k[1] * k[0] * v + k[2] * s,
                c + k[1] * k[1] * v,
                k[1] * k[2] * v - k[0] * s,
            ],
            [
                k[2] * k[0] * v - k[1] * s,
                k[2] * k[1] * v + k[0] * s,
                c + k[2] * k[2] * v,
            ],
        ];
        Self {
            rotation,
            translation,
        }
    }

    /// Rotation by `angle_rad` about the unit `axis` through the point `centre`.
    pub fn about(axis: [f64; 3], angle_rad: f64, centre: [f64; 3]) -> Self {
        let turn = Self::from_axis_angle(axis, angle_rad, [0.0; 3]);
        let rc = turn.apply(centre);
        Self {
            translation: [0, 1, 2].map(|i| centre[i] - rc[i]),
            ..turn
        }
    }

    /// `R v` (a direction: no translation).
    pub fn apply_vector(&self, v: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        [dot(r[0], v), dot(r[1], v), dot(r[2], v)]
    }

    /// `R p + t`.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        add(self.apply_vector(p), self.translation)
    }

    /// The inverse transform `x = Rᵀ (x' − t)`.
    pub fn inverse(&self) -> Self {
        let r = &self.rotation;
        let rt = [
            [r[0][0], r[1][0], r[2][0]],
            [r[0][1], r[1][1], r[2][1]],
            [r[0][2], r[1][2], r[2][2]],
        ];
        let t = self.translation;
        let ti = [-dot(rt[0], t), -dot(rt[1], t), -dot(rt[2], t)];
        Self {
            rotation: rt,
            translation: ti,
        }
    }

    /// `self ∘ other`: apply `other` first, then `self`.
    pub fn compose(&self, other: &Pose) -> Self {
        let a = &self.rotation;
        let b = &other.rotation;
        let mut rotation = [[0.0; 3]; 3];
        for (i, row) in rotation.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        Self {
            rotation,
            translation: self.apply(other.translation),
        }
    }

    /// Rotation angle, degrees (0..=180).
    pub fn rotation_angle_deg(&self) -> f64 {
        // atan2 of sin and cos (from the skew and symmetric parts) stays accurate near 0°
        // and 180°, where acos of the trace alone loses half the digits.
        let r = &self.rotation;
        let cos = 0.5 * (r[0][0] + r[1][1] + r[2][2] - 1.0);
        let sin = 0.5 * norm([r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]]);
        sin.atan2(cos).to_degrees()
    }

    /// Length of the translation, mm.
    pub fn translation_norm(&self) -> f64 {
        norm(self.translation)
    }

    /// A random pose of the given variant (see [`Variant`]).
    pub fn random(variant: Variant, rng: &mut Rng) -> Self {
        let (angle_deg, shift) = match variant {
            Variant::Aligned => (
                uniform(rng, 0.0, ALIGNED_MAX_ROTATION_DEG),
                uniform(rng, 0.0, ALIGNED_MAX_TRANSLATION_MM),
            ),
            Variant::Misaligned => (
                uniform(rng, MISALIGNED_ROTATION_DEG.0, MISALIGNED_ROTATION_DEG.1),
                uniform(
                    rng,
                    MISALIGNED_TRANSLATION_MM.0,
                    MISALIGNED_TRANSLATION_MM.1,
                ),
            ),
        };
        let axis = random_unit(rng);
        let direction = random_unit(rng);
        Self::from_axis_angle(axis, angle_deg.to_radians(), mul(direction, shift))
    }
}
