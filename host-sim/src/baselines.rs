//! Standard registration baselines the skeleton-graph method is compared with
//! (paper section IV: "standard ICP, non-rigid ICP, and CPD").
//!
//! Every baseline takes the CT template cloud (the *source*, moved) and the US target cloud
//! (fixed), both in mm, and returns a [`Mapping`] that carries any point of the template
//! frame (template points, planned waypoints) into the target frame.
//!
//! | [`Method`] | algorithm | maps a point by |
//! |---|---|---|
//! | [`Method::Icp`] | rigid point-to-point ICP, Besl & McKay 1992 ([`icp`]) | `R p + t` |
//! | [`Method::CpdRigid`] | rigid CPD, Myronenko & Song 2010 Fig. 2, scale fixed to 1 ([`cpd`]) | `R p + t` |
//! | [`Method::CpdNonRigid`] | non-rigid CPD, Fig. 4, Gaussian kernel ([`cpd`]) | `p + G(p, Y) W` |
//! | [`Method::NonRigidIcp`] | optimal-step non-rigid ICP, Amberg et al. 2007 ([`nricp`]) | interpolated per-node affine |
//!
//! [`run`] runs one method with its default parameters; each module also exposes its
//! parameter struct and a `fit` function for other settings. All of them:
//! * validate their input and return a typed [`BaselineError`] (empty cloud, NaN or
//!   infinite coordinate, too few points, degenerate geometry, bad parameter, numerical
//!   failure) — they never panic on data;
//! * are deterministic: the same inputs give bit-identical results (seeded subsampling,
//!   index-ordered tie-breaks, no threads);
//! * report how the iteration ended in a [`FitReport`]: hitting the iteration cap is not
//!   an error by default (the result is still the best estimate, as in the reference
//!   libraries), but `strict: true` in a method's parameters turns it into
//!   [`BaselineError::NotConverged`].
//!
//! The script `host-sim/scripts/baselines/compare.py` validates each baseline against a
//! reference library (Open3D, pycpd, probreg, trimesh) on the same phantom inputs; its
//! latest output is `host-sim/scripts/baselines/REPORT.md`.

use std::fmt;

pub mod cpd;
pub mod icp;
pub mod kdtree;
pub mod nricp;

#[cfg(test)]
mod eval;
#[cfg(test)]
mod tests;

/// A 3-D point, mm.
pub type P3 = [f64; 3];

/// The baselines, as the paper names them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    /// Rigid point-to-point ICP (Besl & McKay 1992).
    Icp,
    /// Rigid Coherent Point Drift (Myronenko & Song 2010), scale fixed to 1.
    CpdRigid,
    /// Non-rigid Coherent Point Drift (Myronenko & Song 2010).
    CpdNonRigid,
    /// Optimal-step non-rigid ICP (Amberg, Romdhani & Vetter 2007).
    NonRigidIcp,
}

impl Method {
    /// Every method, in table order.
    pub const ALL: [Method; 4] = [
        Method::Icp,
        Method::CpdRigid,
        Method::CpdNonRigid,
        Method::NonRigidIcp,
    ];

    /// Short stable name (used in reports and file names).
    pub fn name(self) -> &'static str {
        match self {
            Method::Icp => "icp",
            Method::CpdRigid => "cpd_rigid",
            Method::CpdNonRigid => "cpd_nonrigid",
            Method::NonRigidIcp => "nricp",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// How an iterative fit ended.
#[derive(Clone, Debug, PartialEq)]
pub struct FitReport {
    /// The method that produced the fit.
    pub method: Method,
    /// Iterations performed (ICP: transform updates; CPD: EM iterations; NRICP: linear
    /// solves over all stiffness steps).
    pub iterations: usize,
    /// `true` when the stopping tolerance was met before the iteration cap (NRICP: in every
    /// stiffness step).
    pub converged: bool,
    /// The method's final error measure: ICP the RMS closest-point distance (mm), CPD the
    /// final σ (mm, `sqrt` of the GMM variance, in the target's units), NRICP the mean
    /// weighted closest-point distance (mm).
    pub final_error: f64,
}

/// A fitted baseline: maps a point of the template frame into the target frame.
pub trait Mapping {
    /// The image of `p` (template frame, mm) in the target frame (mm).
    fn map(&self, p: P3) -> P3;

    /// How the fit ended.
    fn report(&self) -> &FitReport;

    /// The images of every point of `points`, in order.
    fn map_all(&self, points: &[P3]) -> Vec<P3> {
        points.iter().map(|&p| self.map(p)).collect()
    }
}

/// Which input a problem was found in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// The template (source) cloud.
    Template,
    /// The target (fixed) cloud.
    Target,
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Role::Template => "template",
            Role::Target => "target",
        })
    }
}

/// Why a baseline could not produce a mapping.
#[derive(Clone, Debug, PartialEq)]
pub enum BaselineError {
    /// A cloud has no point.
    Empty(Role),
    /// A coordinate is NaN or infinite.
    NonFinite {
        /// The cloud.
        role: Role,
        /// Index of the first bad point.
        index: usize,
    },
    /// A cloud has fewer points than the method needs.
    TooFewPoints {
        /// The cloud.
        role: Role,
        /// Points found.
        found: usize,
        /// Points needed.
        needed: usize,
    },
    /// The geometry does not determine the transform (all points coincident or collinear).
    Degenerate {
        /// The method.
        method: Method,
        /// What was degenerate.
        what: String,
    },
    /// A parameter is out of its valid range.
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The valid range, in words.
        expected: &'static str,
    },
    /// The iteration cap was reached before the tolerance (only with `strict: true`).
    NotConverged {
        /// The method.
        method: Method,
        /// Iterations performed.
        iterations: usize,
        /// The last change of the convergence measure.
        last_change: f64,
        /// The tolerance it had to fall below.
        tolerance: f64,
    },
    /// The computation broke down (non-finite intermediate, singular system, linear
    /// solver failure).
    Numerical {
        /// The method.
        method: Method,
        /// What failed.
        what: String,
    },
}

impl fmt::Display for BaselineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BaselineError::Empty(role) => write!(f, "the {role} cloud is empty"),
            BaselineError::NonFinite { role, index } => {
                write!(
                    f,
                    "the {role} cloud has a non-finite coordinate at point {index}"
                )
            }
            BaselineError::TooFewPoints {
                role,
                found,
                needed,
            } => write!(
                f,
                "the {role} cloud has {found} points, the method needs at least {needed}"
            ),
            BaselineError::Degenerate { method, what } => write!(f, "{method}: {what}"),
            BaselineError::InvalidParameter {
                name,
                value,
                expected,
            } => write!(
                f,
                "parameter {name} = {value} is invalid: expected {expected}"
            ),
            BaselineError::NotConverged {
                method,
                iterations,
                last_change,
                tolerance,
            } => write!(
                f,
                "{method} did not converge in {iterations} iterations \
                 (last change {last_change:e}, tolerance {tolerance:e})"
            ),
            BaselineError::Numerical { method, what } => write!(f, "{method}: {what}"),
        }
    }
}

impl std::error::Error for BaselineError {}

/// Run `method` with its default parameters: fit `template` (source) onto `target`.
///
/// # Errors
/// See [`BaselineError`]; each method's `fit` documents its own minimum point counts.
pub fn run(
    method: Method,
    template: &[P3],
    target: &[P3],
) -> Result<Box<dyn Mapping + Send + Sync>, BaselineError> {
    Ok(match method {
        Method::Icp => Box::new(icp::fit(template, target, &icp::IcpParams::default())?),
        Method::CpdRigid => Box::new(cpd::fit_rigid(
            template,
            target,
            &cpd::RigidParams::default(),
        )?),
        Method::CpdNonRigid => Box::new(cpd::fit_nonrigid(
            template,
            target,
            &cpd::NonRigidParams::default(),
        )?),
        Method::NonRigidIcp => Box::new(nricp::fit(
            template,
            target,
            &nricp::NricpParams::default(),
        )?),
    })
}

// ---------------------------------------------------------------------------------------
// Shared helpers
// ---------------------------------------------------------------------------------------

/// Check a cloud: non-empty, finite, at least `needed` points.
pub(crate) fn check_cloud(points: &[P3], role: Role, needed: usize) -> Result<(), BaselineError> {
    if points.is_empty() {
        return Err(BaselineError::Empty(role));
    }
    if let Some(index) = points
        .iter()
        .position(|p| !(p[0].is_finite() && p[1].is_finite() && p[2].is_finite()))
    {
        return Err(BaselineError::NonFinite { role, index });
    }
    if points.len() < needed {
        return Err(BaselineError::TooFewPoints {
            role,
            found: points.len(),
            needed,
        });
    }
    Ok(())
}

/// Check that `value` is finite and inside `[lo, hi]` (or `(lo, hi]` when `open_lo`).
pub(crate) fn check_param(
    name: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    open_lo: bool,
    expected: &'static str,
) -> Result<(), BaselineError> {
    let ok = value.is_finite() && value <= hi && if open_lo { value > lo } else { value >= lo };
    if ok {
        Ok(())
    } else {
        Err(BaselineError::InvalidParameter {
            name,
            value,
            expected,
        })
    }
}

/// `x` is finite and > 0 (false for NaN).
pub(crate) fn finite_positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

pub(crate) fn sub(a: P3, b: P3) -> P3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn add(a: P3, b: P3) -> P3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn scale(a: P3, k: f64) -> P3 {
    [a[0] * k, a[1] * k, a[2] * k]
}

pub(crate) fn dot(a: P3, b: P3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn dist2(a: P3, b: P3) -> f64 {
    let d = sub(a, b);
    dot(d, d)
}

pub(crate) fn centroid(points: &[P3]) -> P3 {
    let mut c = [0.0; 3];
    for p in points {
        c = add(c, *p);
    }
    scale(c, 1.0 / points.len() as f64)
}

/// A rigid transform `p ↦ R p + t` (R row-major).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    /// Rotation, row-major, proper (det = +1).
    pub rotation: [[f64; 3]; 3],
    /// Translation, mm.
    pub translation: P3,
}

impl Rigid {
    /// The identity.
    pub const IDENTITY: Rigid = Rigid {
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0; 3],
    };

    /// `R p + t`.
    pub fn apply(&self, p: P3) -> P3 {
        let r = &self.rotation;
        [
            dot(r[0], p) + self.translation[0],
            dot(r[1], p) + self.translation[1],
            dot(r[2], p) + self.translation[2],
        ]
    }

    /// `self ∘ other` (apply `other` first).
    pub fn compose(&self, other: &Rigid) -> Rigid {
        let a = &self.rotation;
        let b = &other.rotation;
        let mut r = [[0.0; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        Rigid {
            rotation: r,
            translation: self.apply(other.translation),
        }
    }

    /// Rotation angle, degrees.
    pub fn angle_deg(&self) -> f64 {
        let r = &self.rotation;
        let c = ((r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0).clamp(-1.0, 1.0);
        c.acos().to_degrees()
    }
}

/// The proper rotation `R` maximising `tr(Rᵀ A)` for a 3×3 cross-covariance
/// `A = Σ w (x − x̄)(y − ȳ)ᵀ` (Kabsch/Umeyama with the reflection fix), or `None` when
/// `A` is rank-deficient by more than one (the points are collinear or coincident).
pub(crate) fn rotation_from_covariance(a: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    use nalgebra::Matrix3;
    let m = Matrix3::new(
        a[0][0], a[0][1], a[0][2], a[1][0], a[1][1], a[1][2], a[2][0], a[2][1], a[2][2],
    );
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let s = svd.singular_values;
    // Sort order of nalgebra's singular values is not guaranteed: find the two largest.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| s[j].total_cmp(&s[i]));
    let smax = s[order[0]];
    if !finite_positive(smax) || s[order[1]] <= smax * 1e-12 {
        return None;
    }
    let d = (u * vt).determinant();
    let mut c = Matrix3::identity();
    if d < 0.0 {
        // Flip the axis of the smallest singular value.
        c[(order[2], order[2])] = -1.0;
    }
    let r = u * c * vt;
    Some([
        [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
        [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
        [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
    ])
}

/// The rigid transform minimising `Σ w_i |R y_i + t − x_i|²` (weighted Kabsch).
/// `None` when the weighted source points are collinear/coincident or the weights sum to 0.
pub(crate) fn weighted_kabsch(pairs: impl Iterator<Item = (P3, P3, f64)> + Clone) -> Option<Rigid> {
    let mut wsum = 0.0;
    let mut my = [0.0; 3];
    let mut mx = [0.0; 3];
    for (y, x, w) in pairs.clone() {
        wsum += w;
        my = add(my, scale(y, w));
        mx = add(mx, scale(x, w));
    }
    if !finite_positive(wsum) {
        return None;
    }
    my = scale(my, 1.0 / wsum);
    mx = scale(mx, 1.0 / wsum);
    let mut a = [[0.0; 3]; 3];
    for (y, x, w) in pairs {
        let dx = sub(x, mx);
        let dy = sub(y, my);
        for i in 0..3 {
            for j in 0..3 {
                a[i][j] += w * dx[i] * dy[j];
            }
        }
    }
    let rotation = rotation_from_covariance(&a)?;
    let mut rigid = Rigid {
        rotation,
        translation: [0.0; 3],
    };
    rigid.translation = sub(mx, rigid.apply(my));
    Some(rigid)
}

/// `n` distinct indices of `0..len` (all of them when `len <= n`), drawn with a seeded
/// partial Fisher–Yates shuffle, returned sorted.
pub fn seeded_subsample(len: usize, n: usize, seed: u64) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..len).collect();
    if len <= n {
        return idx;
    }
    let mut rng = ribreg_core::math::rng::Rng::new(seed);
    for i in 0..n {
        // `below` takes u32; clouds here are far below 2^32 points.
        let span = u32::try_from(len - i).unwrap_or(u32::MAX);
        let j = i + rng.below(span) as usize;
        idx.swap(i, j);
    }
    idx.truncate(n);
    idx.sort_unstable();
    idx
}
