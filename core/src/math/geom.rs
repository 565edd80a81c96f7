//! Small geometric building blocks: input checks, principal axes, rigid transforms.

use crate::error::{Cloud, Error, Result};
use crate::limits::MAX_COORD_MM;
use crate::math::rng::Rng;
use crate::Vec3;
use nalgebra::{Matrix3, SymmetricEigen};

/// Checks that every coordinate is finite and within ±[`MAX_COORD_MM`], and that the
/// point count is in `min..=max`.
pub fn validate(points: &[Vec3], cloud: Cloud, min: usize, max: usize) -> Result<()> {
    validate_count(points.len(), cloud, min, max)?;
    validate_points(points, cloud, 0)
}

/// The count half of [`validate`]: `n` in `min..=max`.
pub fn validate_count(n: usize, cloud: Cloud, min: usize, max: usize) -> Result<()> {
    if n < min {
        return Err(Error::TooFewPoints {
            cloud,
            found: sat_u32(n),
            min: sat_u32(min),
        });
    }
    if n > max {
        return Err(Error::TooManyPoints {
            cloud,
            found: sat_u32(n),
            max: sat_u32(max),
        });
    }
    Ok(())
}

/// The coordinate half of [`validate`], for a chunk of a cloud that starts at index
/// `first` (errors name the index in the whole cloud).
pub fn validate_points(points: &[Vec3], cloud: Cloud, first: usize) -> Result<()> {
    for (i, p) in points.iter().enumerate() {
        if p.iter().any(|c| !c.is_finite()) {
            return Err(Error::NonFinite {
                cloud,
                index: sat_u32(first.saturating_add(i)),
            });
        }
        if p.iter().any(|c| c.abs() > MAX_COORD_MM) {
            return Err(Error::OutOfRange {
                cloud,
                index: sat_u32(first.saturating_add(i)),
            });
        }
    }
    Ok(())
}

/// `n` as `u32`, saturating (for error reports).
pub(crate) fn sat_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// Principal axes of a point set: `origin` is the centroid, `axes` holds the unit axes as
/// columns sorted by decreasing spread, right-handed, and `spread` the standard deviation
/// along each axis (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Centroid.
    pub origin: Vec3,
    /// Columns: first, second and third principal axis (a rotation matrix).
    pub axes: Matrix3<f32>,
    /// Standard deviation along each axis, decreasing.
    pub spread: Vec3,
}

impl Frame {
    /// The coordinate axes at the origin, no spread (a placeholder before a real frame).
    pub fn identity() -> Self {
        Frame {
            origin: Vec3::zeros(),
            axes: Matrix3::identity(),
            spread: Vec3::zeros(),
        }
    }
}

/// At most this many points enter a principal-axes estimate; larger clouds are estimated
/// from a seeded sample of this size (the axes only steer initialisation and orientation).
pub const PCA_SAMPLE: usize = 1024;

impl Frame {
    /// Principal axes of `points` (all of them if at most [`PCA_SAMPLE`], else a seeded
    /// sample), signs fixed by the third moments (see the code). Returns `None` for an
    /// empty slice.
    pub fn principal(points: &[Vec3], seed: u64) -> Option<Frame> {
        let first = *points.first()?;
        let n = points.len();
        let mut rng = Rng::new(seed);
        let take = n.min(PCA_SAMPLE);
        let pick = |rng: &mut Rng, k: usize| {
            if n <= PCA_SAMPLE {
                points[k]
            } else {
                points[rng.below(sat_u32(n)) as usize]
            }
        };
        // Centre on the first point so f32 sums stay small.
        let mut sum = Vec3::zeros();
        let mut outer = Matrix3::<f32>::zeros();
        for k in 0..take {
            let d = pick(&mut rng, k) - first;
            sum += d;
            outer += d * d.transpose();
        }
        let m = take as f32;
        let mean = sum / m;
        let cov = outer / m - mean * mean.transpose();
        let origin = first + mean;
        let eig = SymmetricEigen::new(cov);
        let mut order = [0usize, 1, 2];
        order.sort_unstable_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let mut axes = Matrix3::zeros();
        let mut spread = Vec3::zeros();
        for (col, &k) in order.iter().enumerate() {
            axes.set_column(col, &eig.eigenvectors.column(k));
            spread[col] = libm::sqrtf(eig.eigenvalues[k].max(0.0));
        }
        // Canonical signs: the second and third axes point toward the long tail of the
        // distribution (positive third moment), the first completes a right-handed frame.
        // A rotated copy of a cloud thus gets rotated axes, whatever the eigen-solver's
        // signs, and anything initialised from the frame (the SOM grid) rotates with it.
        let mut skew = [0.0f32; 3];
        let mut rng = Rng::new(seed);
        for k in 0..take {
            let d = axes.transpose() * (pick(&mut rng, k) - origin);
            for (s, v) in skew.iter_mut().zip(d.iter()) {
                *s += v * v * v;
            }
        }
        for col in [1, 2] {
            if skew[col] < 0.0 {
                axes.set_column(col, &(-axes.column(col)));
            }
        }
        let first = axes.column(1).cross(&axes.column(2));
        axes.set_column(0, &first);
        Some(Frame {
            origin,
            axes,
            spread,
        })
    }

    /// Flips axes so that the first points along `+x` and the second along `+y` of the
    /// cloud's own coordinates (keeps the frame right-handed). Used for the template,
    /// which lives in the patient frame (x lateral, y cranial, z anterior).
    pub fn oriented_to_patient(mut self) -> Frame {
        if self.axes[(0, 0)] < 0.0 {
            self.axes.set_column(0, &(-self.axes.column(0)));
        }
        if self.axes[(1, 1)] < 0.0 {
            self.axes.set_column(1, &(-self.axes.column(1)));
        }
        let third = self.axes.column(0).cross(&self.axes.column(1));
        self.axes.set_column(2, &third);
        self
    }

    /// Coordinates of `p` in this frame.
    pub fn local(&self, p: &Vec3) -> Vec3 {
        self.axes.transpose() * (p - self.origin)
    }

    /// World coordinates of a point given in this frame.
    pub fn world(&self, q: &Vec3) -> Vec3 {
        self.origin + self.axes * q
    }
}

/// A rigid transform `x ↦ R x + t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    /// Rotation (proper: orthonormal, det +1).
    pub rotation: Matrix3<f32>,
    /// Translation, mm.
    pub translation: Vec3,
}

impl Rigid {
    /// The identity.
    pub fn identity() -> Rigid {
        Rigid {
            rotation: Matrix3::identity(),
            translation: Vec3::zeros(),
        }
    }

    /// Applies the transform to a point.
    pub fn apply(&self, p: &Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Rigid {
        let rt = self.rotation.transpose();
        Rigid {
            rotation: rt,
            translation: -(rt * self.translation),
        }
    }

    /// `self ∘ first`: apply `first`, then `self`.
    pub fn after(&self, first: &Rigid) -> Rigid {
        Rigid {
            rotation: self.rotation * first.rotation,
            translation: self.rotation * first.translation + self.translation,
        }
    }

    /// Rotation angle in degrees.
    pub fn angle_deg(&self) -> f32 {
        let c = ((self.rotation.trace() - 1.0) * 0.5).clamp(-1.0, 1.0);
        libm::acosf(c).to_degrees()
    }
}

/// Index and squared distance of the point of `set` nearest to `p` (`None` if empty).
pub fn nearest(set: &[Vec3], p: &Vec3) -> Option<(usize, f32)> {
    set.iter()
        .map(|q| (q - p).norm_squared())
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// Largest deviation of a calibration rotation from orthonormality (`|RᵀR − I|`, any
/// entry) and of its determinant from +1.
pub const ROTATION_TOLERANCE: f32 = 1e-3;

/// Finite, orthonormal with determinant +1 (within [`ROTATION_TOLERANCE`]) and a
/// translation within [`crate::limits::MAX_COORD_MM`].
pub fn is_proper_rigid(t: &Rigid) -> bool {
    let r = &t.rotation;
    if !r.iter().chain(t.translation.iter()).all(|v| v.is_finite()) {
        return false;
    }
    let ortho = (r.transpose() * r - Matrix3::identity()).amax() <= ROTATION_TOLERANCE;
    let det = (r.determinant() - 1.0).abs() <= ROTATION_TOLERANCE;
    ortho && det && t.translation.amax() <= crate::limits::MAX_COORD_MM
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validate_reports_first_bad_point() {
        let mut pts = [Vec3::new(1.0, 2.0, 3.0); 5];
        assert_eq!(validate(&pts, Cloud::Target, 1, 10), Ok(()));
        assert_eq!(
            validate(&pts, Cloud::Target, 6, 10),
            Err(Error::TooFewPoints {
                cloud: Cloud::Target,
                found: 5,
                min: 6
            })
        );
        assert_eq!(
            validate(&pts, Cloud::Target, 1, 4),
            Err(Error::TooManyPoints {
                cloud: Cloud::Target,
                found: 5,
                max: 4
            })
        );
        pts[3].y = f32::NAN;
        pts[4].x = 1e9;
        assert_eq!(
            validate(&pts, Cloud::Template, 1, 10),
            Err(Error::NonFinite {
                cloud: Cloud::Template,
                index: 3
            })
        );
        pts[3].y = 0.0;
        assert_eq!(
            validate(&pts, Cloud::Template, 1, 10),
            Err(Error::OutOfRange {
                cloud: Cloud::Template,
                index: 4
            })
        );
    }

    #[test]
    fn principal_axes_of_a_box() {
        let mut pts = [Vec3::zeros(); 60];
        for (i, p) in pts.iter_mut().enumerate() {
            let (a, b, c) = ((i % 5) as f32, ((i / 5) % 4) as f32, (i / 20) as f32);
            *p = Vec3::new(10.0 * a, 3.0 * b, 0.5 * c) + Vec3::new(100.0, -50.0, 7.0);
        }
        let f = Frame::principal(&pts, 1).unwrap().oriented_to_patient();
        assert!((f.axes.column(0) - Vec3::x()).norm() < 1e-4);
        assert!((f.axes.column(1) - Vec3::y()).norm() < 1e-4);
        assert!((f.axes.determinant() - 1.0).abs() < 1e-5);
        assert!((f.origin - Vec3::new(120.0, -45.5, 7.5)).norm() < 1e-3);
        let q = Vec3::new(3.0, 4.0, 5.0);
        assert!((f.world(&f.local(&q)) - q).norm() < 1e-4);
    }
}
