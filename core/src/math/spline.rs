//! A 3-D thin-plate spline through up to [`SPLINE_POINTS`] point pairs (a registration's
//! skeleton and sternum stations): the smooth map that takes every source point exactly
//! onto its target and bends least in between.
//!
//! `f(p) = A·p + b + Σᵢ wᵢ ‖p − sᵢ‖` (the biharmonic kernel of three dimensions), with
//! `Σ wᵢ = 0` and `Σ wᵢ sᵢᵀ = 0` so that far from the points the map is the affine part.
//! An affine map of the pairs is reproduced exactly (the weights come out zero); a map
//! that stretches one region and not another bends smoothly between them, which one
//! rigid transform per neighbourhood cannot do.
//!
//! # Accuracy
//! The `(n + 4)²` system of `n` pairs is solved in `f32` by Gaussian elimination with
//! partial pivoting, on coordinates taken about the source's centroid and divided by its
//! RMS radius (the target's about its own centroid, by the same factor), so every entry is
//! of order one. Contract, against the textbook `f64` solve on raw coordinates
//! (`tests/tests/steps.rs`, `thin_plate_agrees`: registered and bent skeletons of
//! ~250 mm, targets up to 400 mm away): mapped points within 0.02 mm, each source point
//! within 0.01 mm of its target; measured 6.3e-4 and 3.5e-4 mm.
//!
//! # Cost
//! The system and its three right-hand sides take `(C + 4) · (C + 7) · 4` bytes for the
//! capacity `C` = [`SPLINE_POINTS`] (38 · 41 · 4 = 6,232 B), held by a [`ThinPlateFit`]
//! that eliminates it a few columns a call on the controller (about `(n + 4)³ / 3`
//! multiply-adds in all, 18 k for 34 pairs); a solved spline holds its centres and
//! weights and the affine part (872 B), and maps a point in `n` square roots.

use crate::error::{Error, Result};
use crate::limits::SPLINE_POINTS;
use crate::Vec3;
use core::cmp::Ordering;
use nalgebra::Matrix3;

/// Pair capacity.
const C: usize = SPLINE_POINTS;
/// Unknowns at capacity: a weight per pair, the linear part's three columns and the
/// constant.
const M: usize = C + 4;
/// Columns of the augmented system: the unknowns at capacity, then three right-hand sides
/// (columns `M..W`, whatever the pair count).
const W: usize = M + 3;

/// A solved thin-plate spline (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThinPlate {
    /// Pairs used (the first `n` centres and weights).
    n: usize,
    /// Source points, centred and scaled.
    centres: [Vec3; C],
    /// Kernel weights (scaled target units).
    weights: [Vec3; C],
    /// Linear part (scaled units) and constant (scaled target units).
    linear: Matrix3<f32>,
    constant: Vec3,
    /// Source centroid, target centroid, and the scale (1 / source RMS radius).
    source_mean: Vec3,
    target_mean: Vec3,
    scale: f32,
}

impl ThinPlate {
    /// The spline taking `source[i]` onto `target[i]` ([`ThinPlateFit`] in one go).
    pub fn fit(source: &[Vec3], target: &[Vec3]) -> Result<Self> {
        let mut fit = ThinPlateFit::IDLE;
        fit.start(source, target)?;
        loop {
            if let Some(spline) = fit.step(M)? {
                return Ok(spline);
            }
        }
    }

    /// Point pairs it was fitted to.
    pub fn pairs(&self) -> usize {
        self.n
    }

    /// Where the spline takes `p`.
    pub fn apply(&self, p: &Vec3) -> Vec3 {
        let q = (p - self.source_mean) * self.scale;
        let mut f = self.linear * q + self.constant;
        for (c, w) in self.centres[..self.n].iter().zip(&self.weights) {
            f += w * (q - c).norm();
        }
        self.target_mean + f / self.scale
    }
}

/// A [`ThinPlate`] being solved in bounded steps (the controller's per-call budget):
/// [`ThinPlateFit::start`] sets the system up, each [`ThinPlateFit::step`] eliminates a
/// given number of its `n + 4` columns, and the last one back-substitutes. Both work in
/// place: the 6 KB system never passes through the stack (the controller keeps it in its
/// registration's state).
#[derive(Clone, Debug, PartialEq)]
pub struct ThinPlateFit {
    /// The augmented system (Gaussian elimination with partial pivoting, in place).
    rows: [[f32; W]; M],
    /// Pairs, and columns eliminated so far.
    n: usize,
    col: usize,
    /// The system's largest entry (the pivot threshold's scale).
    largest: f32,
    /// The spline's centring and scale, and its centres.
    centres: [Vec3; C],
    source_mean: Vec3,
    target_mean: Vec3,
    scale: f32,
    /// Started and not yet solved.
    solving: bool,
}

impl ThinPlateFit {
    /// Nothing to solve (the state before [`ThinPlateFit::start`]).
    pub const IDLE: ThinPlateFit = ThinPlateFit {
        rows: [[0.0; W]; M],
        n: 0,
        col: 0,
        largest: 0.0,
        centres: [Vec3::new(0.0, 0.0, 0.0); C],
        source_mean: Vec3::new(0.0, 0.0, 0.0),
        target_mean: Vec3::new(0.0, 0.0, 0.0),
        scale: 0.0,
        solving: false,
    };

    /// True from [`ThinPlateFit::start`] until [`ThinPlateFit::step`] returns the spline
    /// or an error.
    pub fn solving(&self) -> bool {
        self.solving
    }

    /// Sets up, in place, the system of the spline taking `source[i]` onto `target[i]`
    /// (`n²` distances). [`Error::Config`] unless both have the same length, 4 to
    /// [`SPLINE_POINTS`] points; [`Error::RigidFit`] for a non-finite or coincident source.
    pub fn start(&mut self, source: &[Vec3], target: &[Vec3]) -> Result<()> {
        self.solving = false;
        let n = source.len();
        if n != target.len() || !(4..=C).contains(&n) {
            return Err(Error::Config(
                "a thin-plate spline takes 4 to 34 point pairs, as many targets as sources",
            ));
        }
        let mean = |p: &[Vec3]| p.iter().fold(Vec3::zeros(), |a, q| a + q) / n as f32;
        let (source_mean, target_mean) = (mean(source), mean(target));
        let spread = source
            .iter()
            .map(|p| (p - source_mean).norm_squared())
            .sum::<f32>()
            / n as f32;
        let scale = 1.0 / libm::sqrtf(spread);
        if !scale.is_finite() {
            return Err(Error::RigidFit);
        }
        for (c, p) in self.centres.iter_mut().zip(source) {
            *c = (p - source_mean) * scale;
        }
        // [K P; Pᵀ 0] [w; a] = [v; 0], K = ‖sᵢ − sⱼ‖, P = [sᵢᵀ 1], v = scaled targets.
        let (rows, centres) = (&mut self.rows, &self.centres[..n]);
        for row in rows.iter_mut() {
            *row = [0.0; W];
        }
        for (i, ci) in centres.iter().enumerate() {
            for (j, cj) in centres.iter().enumerate() {
                rows[i][j] = (ci - cj).norm();
            }
            let v = (target[i] - target_mean) * scale;
            for k in 0..3 {
                rows[i][n + k] = ci[k];
                rows[n + k][i] = ci[k];
                rows[i][M + k] = v[k];
            }
            rows[i][n + 3] = 1.0;
            rows[n + 3][i] = 1.0;
        }
        self.largest = rows
            .iter()
            .flat_map(|r| r[..M].iter())
            .fold(0.0f32, |a, v| a.max(v.abs()));
        (self.n, self.col) = (n, 0);
        (self.source_mean, self.target_mean) = (source_mean, target_mean);
        self.scale = scale;
        self.solving = true;
        Ok(())
    }

    /// Eliminates up to `columns` more columns (at least one; each costs at most
    /// `(n + 4) · (C + 7)` multiply-adds); once all are, back-substitutes and returns the
    /// spline. [`Error::RigidFit`] when the system is singular: two coincident source
    /// points (equal rows), sources on one plane, or a pivot below [`MIN_PIVOT`] of the
    /// largest entry (or NaN).
    pub fn step(&mut self, columns: usize) -> Result<Option<ThinPlate>> {
        if !self.solving {
            return Err(Error::Config("no thin-plate spline is being solved"));
        }
        // Whatever comes back, this system is done with unless more columns remain.
        self.solving = false;
        let (n, rows) = (self.n, &mut self.rows);
        let m = n + 4;
        let stop = self.col.saturating_add(columns.max(1)).min(m);
        for col in self.col..stop {
            let pivot = (col..m)
                .max_by(|&a, &b| rows[a][col].abs().total_cmp(&rows[b][col].abs()))
                .unwrap_or(col);
            // A NaN pivot compares as nothing: singular too.
            let threshold = MIN_PIVOT * self.largest;
            if rows[pivot][col].abs().partial_cmp(&threshold) != Some(Ordering::Greater) {
                return Err(Error::RigidFit);
            }
            rows.swap(col, pivot);
            let (head, tail) = rows[..m].split_at_mut(col + 1);
            let p = &head[col];
            let inv = 1.0 / p[col];
            for r in tail.iter_mut() {
                let factor = r[col] * inv;
                if factor != 0.0 {
                    // Columns m..M are zero in every row: skipped. Zipped slices, no
                    // index checks: this loop is the solve's cost on the controller.
                    for (a, b) in r[col..m].iter_mut().zip(&p[col..m]) {
                        *a -= factor * b;
                    }
                    for (a, b) in r[M..].iter_mut().zip(&p[M..]) {
                        *a -= factor * b;
                    }
                }
            }
        }
        self.col = stop;
        if stop < m {
            self.solving = true;
            return Ok(None);
        }
        for col in (0..m).rev() {
            // Rows below `col` hold their unknowns already.
            let (upper, solved) = rows[..m].split_at_mut(col + 1);
            let row = &mut upper[col];
            for k in M..W {
                let mut v = row[k];
                for (a, r) in row[col + 1..m].iter().zip(solved.iter()) {
                    v -= a * r[k];
                }
                row[k] = v / row[col];
            }
        }
        let x = |r: usize| Vec3::new(rows[r][M], rows[r][M + 1], rows[r][M + 2]);
        let mut weights = [Vec3::zeros(); C];
        for (i, w) in weights[..n].iter_mut().enumerate() {
            *w = x(i);
        }
        Ok(Some(ThinPlate {
            n,
            centres: self.centres,
            weights,
            // Row n + k of the solution is the coefficient of coordinate k (3 outputs).
            linear: Matrix3::from_columns(&[x(n), x(n + 1), x(n + 2)]),
            constant: x(n + 3),
            source_mean: self.source_mean,
            target_mean: self.target_mean,
            scale: self.scale,
        }))
    }
}

/// Least pivot, relative to the system's largest entry, of a system taken as regular:
/// `f32` keeps 7 digits, so a system this close to singular has lost them all but two.
pub const MIN_PIVOT: f32 = 1e-5;

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    use crate::math::curved_skeleton as curves;

    #[test]
    fn an_affine_map_is_reproduced_everywhere() {
        let src = curves();
        let rot = Rotation3::from_euler_angles(0.2, -0.3, 0.4);
        let shear = Matrix3::new(1.1, 0.05, 0.0, 0.0, 0.95, 0.02, 0.0, 0.0, 1.0);
        let t = Vec3::new(500.0, -7.0, 30.0);
        let f = |p: &Vec3| rot * (shear * p) + t;
        let spline = ThinPlate::fit(&src, &src.map(|p| f(&p))).unwrap();
        for i in 0..200 {
            let p = Vec3::new(i as f32 - 100.0, -(i % 90) as f32, (i % 7) as f32);
            assert!((spline.apply(&p) - f(&p)).norm() < 2e-3, "{p}");
        }
    }

    #[test]
    fn every_pair_is_interpolated_and_the_map_is_smooth_between() {
        let src = curves();
        // Stretch the lateral ends only.
        let dst = src.map(|p| p + Vec3::new(0.002 * p.x * p.x.abs() / 10.0, 0.0, 0.0));
        let spline = ThinPlate::fit(&src, &dst).unwrap();
        for (s, d) in src.iter().zip(&dst) {
            assert!((spline.apply(s) - d).norm() < 1e-2, "{s}");
        }
        // Halfway between two stations the map lies between their images.
        let (a, b) = (src[20], src[21]);
        let mid = spline.apply(&((a + b) / 2.0));
        assert!(mid.x > dst[20].x && mid.x < dst[21].x);
    }

    #[test]
    fn bounded_steps_give_the_one_go_spline() {
        let src = curves();
        let dst = src.map(|p| p * 1.1 + Vec3::new(0.0, 0.01 * p.x * p.x / 10.0, 3.0));
        let mut fit = ThinPlateFit::IDLE;
        fit.start(&src, &dst).unwrap();
        let mut calls = 0;
        let spline = loop {
            calls += 1;
            if let Some(s) = fit.step(3).unwrap() {
                break s;
            }
        };
        assert_eq!(calls, (30 + 4usize).div_ceil(3));
        assert_eq!(spline, ThinPlate::fit(&src, &dst).unwrap());
        assert!(!fit.solving());
        assert!(fit.step(1).is_err(), "solved: nothing left to step");
    }

    #[test]
    fn pair_counts_outside_4_to_capacity_are_refused() {
        let src = curves();
        // Four points not on one plane (the first rib's lie on one).
        let four = [src[0], src[8], src[14], src[25]];
        assert!(ThinPlate::fit(&four, &four).is_ok());
        assert!(matches!(
            ThinPlate::fit(&src[..3], &src[..3]),
            Err(Error::Config(_))
        ));
        assert!(matches!(
            ThinPlate::fit(&src, &src[..29]),
            Err(Error::Config(_))
        ));
        let many = [Vec3::zeros(); SPLINE_POINTS + 1];
        assert!(matches!(
            ThinPlate::fit(&many, &many),
            Err(Error::Config(_))
        ));
    }

    #[test]
    fn coincident_or_flat_sources_are_refused() {
        let mut src = curves();
        src[3] = src[4];
        assert_eq!(ThinPlate::fit(&src, &src), Err(Error::RigidFit));
        let flat = curves().map(|p| Vec3::new(p.x, p.y, 0.0));
        assert_eq!(ThinPlate::fit(&flat, &flat), Err(Error::RigidFit));
        let nan = curves().map(|p| p * f32::NAN);
        assert_eq!(ThinPlate::fit(&nan, &nan), Err(Error::RigidFit));
    }
}
