//! Least-squares polynomial fit `y = f(x)` of degree ≤ 3 (paper Eq. 5) and the equal-step
//! resampling of a rib path.
//!
//! The abscissa is centred and scaled to `s = (x − c) / h ∈ [−1, 1]` (a raw cubic in
//! millimetres spans twelve orders of magnitude), and the 4×4 normal equations are
//! formed, solved (Cholesky) and evaluated in `f64`: forming them squares the condition
//! number, which `f32` cannot afford when the abscissae cluster. The cost is a few hundred
//! soft-float operations per rib on the Cortex-M4F.
//!
//! Accuracy contract (tested against `numpy.polyfit`/`polyval` golden vectors): fitted
//! values within `1e-3 · max|y| + 1e-3` mm over the fitted range.

use crate::error::{Error, Result};
use nalgebra::{Matrix4, Vector4};

/// Highest degree fitted.
pub const MAX_DEGREE: usize = 3;

/// A fitted polynomial in the scaled abscissa `s = (x − center) / half_range`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Poly {
    center: f64,
    half_range: f64,
    /// Coefficients of `s⁰..s³` (unused ones are 0).
    coeffs: [f64; MAX_DEGREE + 1],
}

/// Streaming least squares of polynomials of degree ≤ 3 in one abscissa, for `M`
/// ordinates at once (a rib's `y(x)` and `z(x)`): add points one at a time (no buffer,
/// any number), then [`PolyFit::solve`]. The abscissa range must be known first.
///
/// The normal equations are kept as power sums `Σ sᵏ` (k ≤ 6, shared by the ordinates)
/// and `Σ yₘ sᵏ` (k ≤ 3), all in `f64`: about 12 + 8·M soft-float operations per point
/// on the Cortex-M4F. (`f32` sums, tried, fail the clustered-abscissae reference test.)
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PolyFit<const M: usize = 1> {
    center: f64,
    half_range: f64,
    inverse_half_range: f64,
    powers: [f64; 2 * MAX_DEGREE + 1],
    weighted: [[f64; MAX_DEGREE + 1]; M],
    count: usize,
}

impl<const M: usize> PolyFit<M> {
    /// An empty fit for abscissae in `lo..=hi` (`lo < hi`, finite).
    pub fn new(lo: f32, hi: f32) -> Result<Self> {
        let (lo, hi) = (f64::from(lo), f64::from(hi));
        let center = 0.5 * (lo + hi);
        let half_range = 0.5 * (hi - lo);
        if !half_range.is_finite() || half_range <= 0.0 {
            return Err(Error::Config("polynomial fit needs distinct abscissae"));
        }
        Ok(PolyFit {
            center,
            half_range,
            inverse_half_range: 1.0 / half_range,
            powers: [0.0; 2 * MAX_DEGREE + 1],
            weighted: [[0.0; MAX_DEGREE + 1]; M],
            count: 0,
        })
    }

    /// Adds the point `(x, y₁..y_M)`.
    pub fn add(&mut self, x: f32, y: [f32; M]) {
        let s = (f64::from(x) - self.center) * self.inverse_half_range;
        let mut power = 1.0f64;
        for k in 0..=2 * MAX_DEGREE {
            self.powers[k] += power;
            if k <= MAX_DEGREE {
                for (w, &ym) in self.weighted.iter_mut().zip(&y) {
                    w[k] += power * f64::from(ym);
                }
            }
            power *= s;
        }
        self.count += 1;
    }

    /// Points added so far.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The least-squares polynomials (one per ordinate) of degree `degree ≤ 3`; needs
    /// more points than the degree, at distinct abscissae.
    pub fn solve(&self, degree: usize) -> Result<[Poly; M]> {
        if degree > MAX_DEGREE || self.count <= degree {
            return Err(Error::Config(
                "polynomial fit needs degree <= 3 and more points than the degree",
            ));
        }
        // Unused degrees: identity rows keep the matrix SPD and their coefficients 0.
        let ata = Matrix4::from_fn(|r, c| match (r > degree || c > degree, r == c) {
            (true, true) => 1.0,
            (true, false) => 0.0,
            (false, _) => self.powers[r + c],
        });
        let chol = ata
            .cholesky()
            .ok_or(Error::Config("polynomial fit is singular"))?;
        let mut out = [Poly {
            center: self.center,
            half_range: self.half_range,
            coeffs: [0.0; MAX_DEGREE + 1],
        }; M];
        for (poly, w) in out.iter_mut().zip(&self.weighted) {
            let mut aty = Vector4::from(*w);
            for v in aty.iter_mut().skip(degree + 1) {
                *v = 0.0;
            }
            let sol = chol.solve(&aty);
            if sol.iter().any(|v| !v.is_finite()) {
                return Err(Error::Config("polynomial fit is singular"));
            }
            poly.coeffs = [sol[0], sol[1], sol[2], sol[3]];
        }
        Ok(out)
    }
}

impl Poly {
    /// Least-squares polynomial of degree `degree ≤ 3` through `(x[i], y[i])`. Needs at
    /// least `degree + 1` points with distinct abscissae.
    pub fn fit(x: &[f32], y: &[f32], degree: usize) -> Result<Poly> {
        if x.len() != y.len() {
            return Err(Error::Config(
                "polynomial fit needs as many ordinates as abscissae",
            ));
        }
        let lo = x.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = x.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let mut fit = PolyFit::<1>::new(lo, hi)?;
        for (&xi, &yi) in x.iter().zip(y) {
            fit.add(xi, [yi]);
        }
        let [poly] = fit.solve(degree)?;
        Ok(poly)
    }

    /// Value at `x`.
    pub fn eval(&self, x: f32) -> f32 {
        let s = (f64::from(x) - self.center) / self.half_range;
        let [c0, c1, c2, c3] = self.coeffs;
        (((c3 * s + c2) * s + c1) * s + c0) as f32
    }
}

/// `n` abscissae from `from` to `to` (both included) in equal steps.
pub fn equal_steps(from: f32, to: f32, n: usize) -> impl Iterator<Item = f32> {
    let step = if n > 1 {
        (to - from) / (n - 1) as f32
    } else {
        0.0
    };
    (0..n).map(move |k| from + step * k as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_cubic_is_reproduced() {
        let f = |x: f32| 0.0001 * x * x * x - 0.02 * x * x + 0.5 * x + 12.0;
        let x: [f32; 12] = core::array::from_fn(|i| -110.0 + 20.0 * i as f32);
        let y = x.map(f);
        let p = Poly::fit(&x, &y, 3).unwrap();
        for xi in equal_steps(-110.0, 110.0, 9) {
            assert!(
                (p.eval(xi) - f(xi)).abs() < 2e-3,
                "{xi}: {} vs {}",
                p.eval(xi),
                f(xi)
            );
        }
    }

    #[test]
    fn lower_degrees_and_errors() {
        let x = [0.0, 1.0, 2.0];
        let p = Poly::fit(&x, &[1.0, 3.0, 5.0], 1).unwrap();
        assert!((p.eval(10.0) - 21.0).abs() < 1e-4);
        assert!(Poly::fit(&x, &[1.0, 3.0, 5.0], 3).is_err());
        assert!(Poly::fit(&[1.0, 1.0], &[1.0, 2.0], 1).is_err());
        assert!(Poly::fit(&x, &[1.0, 2.0], 1).is_err());
        assert!(Poly::fit(&[0.0, f32::NAN], &[1.0, 2.0], 1).is_err());
    }

    #[test]
    fn steps_include_both_ends() {
        let mut it = equal_steps(-5.0, 5.0, 6);
        assert_eq!(it.next(), Some(-5.0));
        assert_eq!(it.last(), Some(5.0));
        assert_eq!(
            equal_steps(2.0, 3.0, 1)
                .collect::<heapless::Vec<f32, 2>>()
                .as_slice(),
            &[2.0]
        );
    }
}
