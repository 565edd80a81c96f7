//! Least-squares rigid fit of paired points (Kabsch / Umeyama without scale).
//!
//! `fit(a, b)` returns the proper rotation `R` and translation `t` minimising
//! `Σ ‖R aᵢ + t − bᵢ‖²`. The rotation comes from the SVD of the cross-covariance
//! `H = Σ (aᵢ − ā)(bᵢ − b̄)ᵀ`: `R = V diag(1, 1, d) Uᵀ`, `d = sign det(V Uᵀ)` (the
//! reflection fix). nalgebra's SVD has a known accuracy issue in some 3-D alignment
//! cases (dimforge/nalgebra#1172), so the result is checked: the SVD must reconstruct
//! `H`, and `R` must be orthonormal with det +1. If the check fails, the rotation is
//! computed again by Horn's quaternion method (largest eigenvector of the symmetric 4×4
//! matrix built from `H`), which needs no SVD; if that too fails, [`Error::RigidFit`].
//!
//! Centroids, `H`, the SVD and the rotation are computed in `f64` (the inputs are `f32`):
//! an `f32` SVD of a nearly collinear set loses the rotation about the line to rounding
//! (its reconstruction error hides below any useful check), and `H` of points far from
//! the origin loses digits to cancellation. About a hundred fits per registration make
//! the soft-float cost on the Cortex-M4F small.
//!
//! Accuracy contract (tested against scipy `Rotation.align_vectors` golden vectors):
//! rotation within 1e-4 (max abs element) and translation within 1e-3 mm for point sets
//! of extent 10–300 mm.

use crate::error::{Error, Result};
use crate::math::geom::Rigid;
use crate::Vec3;
use nalgebra::{Matrix3, Matrix4, SymmetricEigen, Vector4, SVD};

/// Relative tolerance of the SVD reconstruction check `‖U S Vᵀ − H‖ ≤ tol ‖H‖` (f64).
const SVD_RECONSTRUCTION_TOL: f64 = 1e-9;
/// Tolerance of the orthonormality check `‖RᵀR − I‖_max` (f64).
const ORTHO_TOL: f64 = 1e-9;

type M3 = Matrix3<f64>;
type V3 = nalgebra::Vector3<f64>;

/// Best rigid transform taking `a[i]` onto `b[i]`. Needs equal, non-zero lengths and a
/// non-degenerate `a` (not all points coincident).
pub fn fit(a: &[Vec3], b: &[Vec3]) -> Result<Rigid> {
    if a.is_empty() || a.len() != b.len() {
        return Err(Error::RigidFit);
    }
    let mut sums = PairSums::new();
    for (p, q) in a.iter().zip(b) {
        sums.add(p, q);
    }
    sums.fit()
}

/// Running sums of point pairs `(aᵢ, bᵢ)` for a one-pass [`fit`]: pairs can be added one
/// at a time over several calls (the controller's bounded ICP steps) and nothing is
/// buffered. Coordinates are taken relative to the first pair, so `H = Σ aᵢbᵢᵀ − n ā b̄ᵀ`
/// loses no digits to points far from the origin. Each product is formed in `f32`
/// (exact to the inputs' own `f32` rounding) and summed in `f32` over at most
/// [`PAIRS_PER_FLUSH`] pairs, then added into `f64` totals: the `f64` work, soft-float on
/// the Cortex-M4F, is one addition per [`PAIRS_PER_FLUSH`] pairs instead of ten
/// multiply-adds per pair, and the cancellation in `H` happens in `f64`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairSums {
    n: u32,
    origin_a: Vec3,
    origin_b: Vec3,
    sum_a: V3,
    sum_b: V3,
    sum_ab: M3,
    part_n: u32,
    part_a: Vec3,
    part_b: Vec3,
    part_ab: Matrix3<f32>,
}

/// Pairs summed in `f32` before their sums go into the `f64` totals of [`PairSums`].
pub const PAIRS_PER_FLUSH: u32 = 8;

impl Default for PairSums {
    fn default() -> Self {
        Self::new()
    }
}

impl PairSums {
    /// No pairs.
    pub fn new() -> Self {
        PairSums {
            n: 0,
            origin_a: Vec3::zeros(),
            origin_b: Vec3::zeros(),
            sum_a: V3::zeros(),
            sum_b: V3::zeros(),
            sum_ab: M3::zeros(),
            part_n: 0,
            part_a: Vec3::zeros(),
            part_b: Vec3::zeros(),
            part_ab: Matrix3::zeros(),
        }
    }

    /// Pairs added.
    pub fn len(&self) -> u32 {
        self.n + self.part_n
    }

    /// True before the first pair.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Adds the pair `a → b`.
    pub fn add(&mut self, a: &Vec3, b: &Vec3) {
        if self.is_empty() {
            (self.origin_a, self.origin_b) = (*a, *b);
        }
        let (a, b) = (a - self.origin_a, b - self.origin_b);
        self.part_a += a;
        self.part_b += b;
        self.part_ab += a * b.transpose();
        self.part_n += 1;
        if self.part_n >= PAIRS_PER_FLUSH {
            self.flush();
        }
    }

    fn flush(&mut self) {
        self.sum_a += self.part_a.cast::<f64>();
        self.sum_b += self.part_b.cast::<f64>();
        self.sum_ab += self.part_ab.cast::<f64>();
        self.n = self.n.saturating_add(self.part_n);
        self.part_n = 0;
        self.part_a = Vec3::zeros();
        self.part_b = Vec3::zeros();
        self.part_ab = Matrix3::zeros();
    }

    /// The best rigid transform of the pairs added ([`fit`]).
    pub fn fit(&self) -> Result<Rigid> {
        let mut all = *self;
        all.flush();
        if all.n == 0 {
            return Err(Error::RigidFit);
        }
        let n = f64::from(all.n);
        let (ca, cb) = (all.sum_a / n, all.sum_b / n);
        let h = all.sum_ab - ca * cb.transpose() * n;
        let (ca, cb) = (
            ca + all.origin_a.cast::<f64>(),
            cb + all.origin_b.cast::<f64>(),
        );
        let scale = h.abs().max();
        if !scale.is_finite() || scale <= 1e-12 * (1.0 + ca.norm_squared()) {
            return Err(Error::RigidFit);
        }
        // Normalise H: the rotation does not depend on its scale, and the check gets easier.
        let h = h / scale;
        let rotation = rotation_svd(&h)
            .or_else(|| rotation_horn(&h))
            .ok_or(Error::RigidFit)?;
        let translation = cb - rotation * ca;
        Ok(Rigid {
            rotation: rotation.cast::<f32>(),
            translation: translation.cast::<f32>(),
        })
    }
}

/// Mean of a slice (zero for an empty one).
pub fn centroid(points: &[Vec3]) -> Vec3 {
    let sum = points.iter().fold(Vec3::zeros(), |s, p| s + p);
    sum / points.len().max(1) as f32
}

fn rotation_svd(h: &M3) -> Option<M3> {
    let svd = SVD::new(*h, true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let rebuilt = u * Matrix3::from_diagonal(&svd.singular_values) * v_t;
    if (rebuilt - h).abs().max() > SVD_RECONSTRUCTION_TOL * h.abs().max() {
        return None;
    }
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * M3::from_diagonal(&V3::new(1.0, 1.0, d)) * u.transpose();
    is_rotation(&r).then_some(r)
}

/// Horn (1987): the unit quaternion maximising `Σ (R aᵢ)·bᵢ` is the eigenvector of the
/// largest eigenvalue of a symmetric 4×4 matrix of the entries of `H`.
fn rotation_horn(h: &M3) -> Option<M3> {
    let (sxx, sxy, sxz) = (h[(0, 0)], h[(0, 1)], h[(0, 2)]);
    let (syx, syy, syz) = (h[(1, 0)], h[(1, 1)], h[(1, 2)]);
    let (szx, szy, szz) = (h[(2, 0)], h[(2, 1)], h[(2, 2)]);
    #[rustfmt::skip]
    let n = Matrix4::new(
        sxx + syy + szz, syz - szy,       szx - sxz,       sxy - syx,
        syz - szy,       sxx - syy - szz, sxy + syx,       szx + sxz,
        szx - sxz,       sxy + syx,       -sxx + syy - szz, syz + szy,
        sxy - syx,       szx + sxz,       syz + szy,       -sxx - syy + szz,
    );
    let eig = SymmetricEigen::new(n);
    let k = eig.eigenvalues.imax();
    let q: Vector4<f64> = eig.eigenvectors.column(k).normalize();
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    #[rustfmt::skip]
    let r = M3::new(
        w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z),         2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),         w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),         2.0 * (y * z + w * x),         w * w - x * x - y * y + z * z,
    );
    is_rotation(&r).then_some(r)
}

fn is_rotation(r: &M3) -> bool {
    let ortho = (r.transpose() * r - M3::identity()).abs().max();
    ortho <= ORTHO_TOL
        && (r.determinant() - 1.0).abs() <= ORTHO_TOL
        && r.iter().all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};

    fn centroid64(points: &[Vec3]) -> V3 {
        let sum = points.iter().fold(V3::zeros(), |s, p| s + p.cast::<f64>());
        sum / points.len().max(1) as f64
    }

    fn cloud() -> [Vec3; 10] {
        core::array::from_fn(|i| {
            let t = i as f32;
            Vec3::new(
                10.0 * t,
                30.0 * (t * 0.7).sin(),
                20.0 * (t * 1.3).cos() + 0.5 * t * t,
            )
        })
    }

    #[test]
    fn recovers_a_known_motion() {
        let a = cloud();
        let rot = Rotation3::from_axis_angle(&Unit::new_normalize(Vec3::new(1.0, 2.0, -0.5)), 2.5);
        let t = Vec3::new(30.0, -12.0, 8.0);
        let b: [Vec3; 10] = core::array::from_fn(|i| rot * a[i] + t);
        let fit = fit(&a, &b).unwrap();
        assert!((fit.rotation - rot.matrix()).abs().max() < 1e-4);
        assert!((fit.translation - t).norm() < 1e-3);
    }

    #[test]
    fn horn_agrees_with_svd() {
        let a = cloud();
        let rot = Rotation3::from_euler_angles(0.3, -1.1, 2.9);
        let b: [Vec3; 10] = core::array::from_fn(|i| rot * a[i]);
        let ca = centroid64(&a);
        let cb = centroid64(&b);
        let mut h = M3::zeros();
        for (p, q) in a.iter().zip(&b) {
            h += (p.cast::<f64>() - ca) * (q.cast::<f64>() - cb).transpose();
        }
        let h = h / h.abs().max();
        let r1 = rotation_svd(&h).unwrap();
        let r2 = rotation_horn(&h).unwrap();
        assert!((r1 - r2).abs().max() < 1e-9);
        assert!((r1.cast::<f32>() - rot.matrix()).abs().max() < 1e-5);
    }

    #[test]
    fn mirror_image_gives_a_proper_rotation() {
        let a = cloud();
        let b: [Vec3; 10] = core::array::from_fn(|i| Vec3::new(-a[i].x, a[i].y, a[i].z));
        let fit = fit(&a, &b).unwrap();
        assert!((fit.rotation.determinant() - 1.0).abs() < 1e-4);
    }

    #[test]
    fn degenerate_sets_are_errors() {
        let p = [Vec3::new(1.0, 2.0, 3.0); 4];
        assert_eq!(fit(&p, &p), Err(Error::RigidFit));
        assert_eq!(fit(&[], &[]), Err(Error::RigidFit));
        assert_eq!(fit(&p[..2], &p[..3]), Err(Error::RigidFit));
    }
}
