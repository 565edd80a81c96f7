//! Least-squares rigid fit of paired points (Kabsch / Umeyama without scale).
//!
//! `fit(a, b)` returns the proper rotation `R` and translation `t` minimising
//! `Σ ‖R aᵢ + t − bᵢ‖²`, from the cross-covariance `H = Σ (aᵢ − ā)(bᵢ − b̄)ᵀ`. The
//! rotation is the unit quaternion of the largest eigenvalue of Horn's symmetric 4×4 key
//! matrix of `H` (Horn 1987), found without an eigen-decomposition: Newton's method on its
//! characteristic polynomial, then the eigenvector from an adjugate column (Theobald
//! 2005's "QCP"; `rotation_newton`). Where that eigenvalue is nearly repeated (a
//! collinear set, whose rotation about the line is ill-determined) or the result fails the
//! check below, the SVD decides: `R = V diag(1, 1, d) Uᵀ`, `d = sign det(V Uᵀ)` (the
//! reflection fix). nalgebra's SVD has a known accuracy issue in some 3-D alignment cases
//! (dimforge/nalgebra#1172), so its result is checked too: it must reconstruct `H`, and
//! `R` must be orthonormal with det +1. If that fails, Horn's matrix is decomposed by
//! nalgebra's symmetric eigen-solver; if that too fails, [`Error::RigidFit`].
//!
//! Centroids, `H` and the rotation are computed in `f64` (the inputs are `f32`): an
//! `f32` SVD of a nearly collinear set loses the rotation about the line to rounding (its
//! reconstruction error hides below any useful check), and `H` of points far from the
//! origin loses digits to cancellation. A registration fits hundreds of times (the coarse
//! and refining ICP iterations, the guided rounds and the mapping's local transforms);
//! the Cortex-M4F does `f64` in software, and taking the rotation from the polynomial
//! instead of the SVD saved 17.1 M of the controller's instructions (`ribreg hil
//! --quick`, MPS2: registration 148.9 → 131.8 M, the same probe errors).
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
        let rotation = rotation_newton(&h)
            .or_else(|| rotation_svd(&h))
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

/// Horn's 4×4 key matrix of `h` (symmetric, trace 0): its largest eigenvalue's unit
/// eigenvector is the quaternion of the best rotation.
fn horn_matrix(h: &M3) -> Matrix4<f64> {
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
    n
}

/// The rotation matrix of the unit quaternion `(w, x, y, z)`.
fn quaternion_matrix(q: &Vector4<f64>) -> M3 {
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    #[rustfmt::skip]
    let r = M3::new(
        w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z),         2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),         w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),         2.0 * (y * z + w * x),         w * w - x * x - y * y + z * z,
    );
    r
}

/// Newton steps at most for the largest eigenvalue ([`rotation_newton`]).
const NEWTON_STEPS: usize = 50;
/// Least norm of the chosen adjugate column of `N − λI` (with `H` scaled to max |·| = 1):
/// below it the largest eigenvalue is (nearly) repeated, the rotation is ill-determined
/// (a collinear set), and [`rotation_svd`] decides.
const MIN_ADJUGATE: f64 = 1e-8;

/// Horn's quaternion without an eigen-decomposition (the "quaternion characteristic
/// polynomial" of Theobald 2005). Horn's key matrix `N` is symmetric with trace 0, so its
/// characteristic polynomial is `λ⁴ + c₂λ² + c₁λ + c₀` with `c₂ = −2‖H‖²_F`, `c₁ =
/// −8 det H` and `c₀ = det N`. Its eigenvalues are sums `±σ₁ ± σ₂ ± σ₃` of `H`'s singular
/// values, so `√3 ‖H‖_F` lies above the largest, and Newton's method from there descends
/// to it monotonically (the polynomial is convex above its largest root). The
/// eigenvector is the largest column of the adjugate of `N − λI`. The same rotation as
/// [`rotation_svd`] (within 1e-9 in the tests) for far less `f64` work, which the
/// Cortex-M4F does in software. `None` where the largest eigenvalue is nearly repeated
/// (the rotation is ill-determined: a collinear set) or the result is no rotation.
fn rotation_newton(h: &M3) -> Option<M3> {
    let n = horn_matrix(h);
    let frobenius2 = h.norm_squared();
    let (c2, c1, c0) = (-2.0 * frobenius2, -8.0 * h.determinant(), det4(&n));
    let mut lambda = libm::sqrt(3.0 * frobenius2);
    for _ in 0..NEWTON_STEPS {
        let l2 = lambda * lambda;
        let p = (l2 + c2) * l2 + c1 * lambda + c0;
        let dp = 4.0 * l2 * lambda + 2.0 * c2 * lambda + c1;
        if dp <= 0.0 || !dp.is_finite() {
            break;
        }
        let step = p / dp;
        lambda -= step;
        if step.abs() <= 1e-14 * (1.0 + lambda.abs()) {
            break;
        }
    }
    let m = n - Matrix4::identity() * lambda;
    let mut best = Vector4::zeros();
    for j in 0..4 {
        let column = adjugate_column(&m, j);
        if column.norm_squared() > best.norm_squared() {
            best = column;
        }
    }
    if best.norm() < MIN_ADJUGATE {
        return None;
    }
    let r = quaternion_matrix(&best.normalize());
    is_rotation(&r).then_some(r)
}

/// Determinant of a 4×4 matrix by its 2×2 minors (Laplace along the first two rows).
fn det4(m: &Matrix4<f64>) -> f64 {
    let minor =
        |r: usize, a: usize, b: usize| m[(r, a)] * m[(r + 1, b)] - m[(r, b)] * m[(r + 1, a)];
    let (s0, s1, s2) = (minor(0, 0, 1), minor(0, 0, 2), minor(0, 0, 3));
    let (s3, s4, s5) = (minor(0, 1, 2), minor(0, 1, 3), minor(0, 2, 3));
    let (c5, c4, c3) = (minor(2, 2, 3), minor(2, 1, 3), minor(2, 1, 2));
    let (c2, c1, c0) = (minor(2, 0, 3), minor(2, 0, 2), minor(2, 0, 1));
    s0 * c5 - s1 * c4 + s2 * c3 + s3 * c2 - s4 * c1 + s5 * c0
}

/// Column `j` of the adjugate of `m` (the cofactors of row `j`): for `m = N − λI` with
/// `λ` a simple eigenvalue of the symmetric `N`, a multiple of its eigenvector.
fn adjugate_column(m: &Matrix4<f64>, j: usize) -> Vector4<f64> {
    Vector4::from_fn(|i, _| {
        // Cofactor (j, i): the 3×3 minor without row j and column i, signed.
        let rows: [usize; 3] = core::array::from_fn(|k| if k < j { k } else { k + 1 });
        let cols: [usize; 3] = core::array::from_fn(|k| if k < i { k } else { k + 1 });
        let e = |a: usize, b: usize| m[(rows[a], cols[b])];
        let minor = e(0, 0) * (e(1, 1) * e(2, 2) - e(1, 2) * e(2, 1))
            - e(0, 1) * (e(1, 0) * e(2, 2) - e(1, 2) * e(2, 0))
            + e(0, 2) * (e(1, 0) * e(2, 1) - e(1, 1) * e(2, 0));
        if (i + j).is_multiple_of(2) {
            minor
        } else {
            -minor
        }
    })
}

/// Horn (1987): the unit quaternion maximising `Σ (R aᵢ)·bᵢ` is the eigenvector of the
/// largest eigenvalue of a symmetric 4×4 matrix of the entries of `H`.
fn rotation_horn(h: &M3) -> Option<M3> {
    let eig = SymmetricEigen::new(horn_matrix(h));
    let k = eig.eigenvalues.imax();
    let q: Vector4<f64> = eig.eigenvectors.column(k).normalize();
    let r = quaternion_matrix(&q);
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

    /// `H` of the pairs `a → b` in f64, scaled to max |·| = 1 as [`PairSums::fit`] does.
    fn scaled_cross_covariance(a: &[Vec3], b: &[Vec3]) -> M3 {
        let (ca, cb) = (centroid64(a), centroid64(b));
        let mut h = M3::zeros();
        for (p, q) in a.iter().zip(b) {
            h += (p.cast::<f64>() - ca) * (q.cast::<f64>() - cb).transpose();
        }
        h / h.abs().max()
    }

    #[test]
    fn horn_agrees_with_svd() {
        let a = cloud();
        let rot = Rotation3::from_euler_angles(0.3, -1.1, 2.9);
        let b: [Vec3; 10] = core::array::from_fn(|i| rot * a[i]);
        let h = scaled_cross_covariance(&a, &b);
        let r1 = rotation_svd(&h).unwrap();
        let r2 = rotation_horn(&h).unwrap();
        let r3 = rotation_newton(&h).unwrap();
        assert!((r1 - r2).abs().max() < 1e-9);
        assert!((r1 - r3).abs().max() < 1e-9);
        assert!((r1.cast::<f32>() - rot.matrix()).abs().max() < 1e-5);
    }

    /// The polynomial's rotation is the SVD's on random sets, motions and mirror images
    /// (whose best proper rotation needs the SVD's reflection fix).
    #[test]
    fn newton_agrees_with_svd_on_random_sets() {
        let mut state = 0x1234_5678_u32;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32 * 2.0 - 1.0
        };
        for case in 0..500 {
            let n = 3 + case % 20;
            let a: std::vec::Vec<Vec3> = (0..n)
                .map(|_| Vec3::new(100.0 * next(), 60.0 * next(), 20.0 * next()))
                .collect();
            let axis = Vec3::new(next(), next(), next());
            let rot = Rotation3::from_axis_angle(&Unit::new_normalize(axis), 3.1 * next());
            let mirror = if case % 3 == 0 { -1.0 } else { 1.0 };
            let b: std::vec::Vec<Vec3> = a
                .iter()
                .map(|p| {
                    rot * Vec3::new(mirror * p.x, p.y, p.z) + Vec3::new(5.0 * next(), 0.0, 1.0)
                })
                .collect();
            let h = scaled_cross_covariance(&a, &b);
            let svd = rotation_svd(&h).unwrap();
            let newton = rotation_newton(&h).unwrap();
            assert!((svd - newton).abs().max() < 1e-9, "case {case}");
        }
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
