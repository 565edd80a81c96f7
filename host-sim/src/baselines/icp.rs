//! Rigid point-to-point ICP (Besl & McKay 1992).
//!
//! * Initial alignment: centroid alignment only — `R = I`, `t = mean(target) −
//!   mean(template)`.
//! * Each iteration: every (transformed) template point is paired with its nearest target
//!   point (exact k-d tree search, [`super::kdtree`]); the rigid transform minimising the
//!   sum of squared pair distances (Kabsch, reflection-corrected) is composed onto the
//!   current one.
//! * Stopping rule, as Open3D's `registration_icp`: correspondences and their RMS distance
//!   are computed for the initial pose, then each iteration updates the transform and
//!   recomputes them; the loop stops when the RMS changed by less than
//!   [`IcpParams::tolerance_mm`] (default 1e-6 mm), or after [`IcpParams::max_iterations`]
//!   updates (default 100). No correspondence is rejected (Open3D with an unbounded
//!   `max_correspondence_distance`).

use super::kdtree::KdTree;
use super::{
    centroid, check_cloud, check_param, sub, weighted_kabsch, BaselineError, FitReport, Mapping,
    Method, Rigid, Role, P3,
};

/// ICP settings.
#[derive(Clone, Debug, PartialEq)]
pub struct IcpParams {
    /// Maximum number of transform updates (default 100).
    pub max_iterations: usize,
    /// Stop when the RMS closest-point distance changes by less than this, mm (default 1e-6).
    pub tolerance_mm: f64,
    /// Start from centroid alignment (default `true`); `false` starts from the identity.
    pub align_centroids: bool,
    /// Return [`BaselineError::NotConverged`] when the cap is reached (default `false`).
    pub strict: bool,
}

impl Default for IcpParams {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            tolerance_mm: 1e-6,
            align_centroids: true,
            strict: false,
        }
    }
}

/// A fitted rigid ICP registration.
#[derive(Clone, Debug, PartialEq)]
pub struct IcpResult {
    /// Template frame → target frame.
    pub transform: Rigid,
    /// The centroid-alignment start pose.
    pub initial: Rigid,
    /// RMS closest-point distance after each evaluation (initial pose first), mm.
    pub rms_history: Vec<f64>,
    /// How the fit ended (`final_error`: RMS closest-point distance, mm).
    pub report: FitReport,
}

impl Mapping for IcpResult {
    fn map(&self, p: P3) -> P3 {
        self.transform.apply(p)
    }
    fn report(&self) -> &FitReport {
        &self.report
    }
}

/// Fit `template` onto `target` with rigid ICP.
///
/// # Errors
/// Empty or non-finite clouds; fewer than 3 template points; invalid parameters; a
/// degenerate correspondence set (template collinear); with `strict`, no convergence.
pub fn fit(template: &[P3], target: &[P3], params: &IcpParams) -> Result<IcpResult, BaselineError> {
    check_cloud(template, Role::Template, 3)?;
    check_cloud(target, Role::Target, 1)?;
    check_param(
        "tolerance_mm",
        params.tolerance_mm,
        0.0,
        f64::MAX,
        false,
        "a finite value >= 0",
    )?;
    if params.max_iterations == 0 {
        return Err(BaselineError::InvalidParameter {
            name: "max_iterations",
            value: 0.0,
            expected: "at least 1",
        });
    }
    let tree = KdTree::new(target);
    let initial = if params.align_centroids {
        Rigid {
            translation: sub(centroid(target), centroid(template)),
            ..Rigid::IDENTITY
        }
    } else {
        Rigid::IDENTITY
    };
    let mut transform = initial;
    let mut moved: Vec<P3> = template.iter().map(|&p| transform.apply(p)).collect();
    let mut matched = vec![0usize; template.len()];
    let mut rms = correspond(&tree, &moved, &mut matched);
    let mut rms_history = vec![rms];
    let mut converged = false;
    let mut last_change = f64::INFINITY;
    let mut iterations = 0;
    while iterations < params.max_iterations {
        let pairs = moved
            .iter()
            .zip(&matched)
            .map(|(&y, &j)| (y, target[j], 1.0));
        let update = weighted_kabsch(pairs).ok_or_else(|| BaselineError::Degenerate {
            method: Method::Icp,
            what: "the template points are collinear or coincident: no unique rotation".into(),
        })?;
        transform = update.compose(&transform);
        for (m, &p) in moved.iter_mut().zip(template) {
            *m = transform.apply(p);
        }
        iterations += 1;
        let new_rms = correspond(&tree, &moved, &mut matched);
        if !new_rms.is_finite() {
            return Err(BaselineError::Numerical {
                method: Method::Icp,
                what: "the RMS distance became non-finite".into(),
            });
        }
        rms_history.push(new_rms);
        last_change = (new_rms - rms).abs();
        rms = new_rms;
        if last_change < params.tolerance_mm {
            converged = true;
            break;
        }
    }
    if !converged && params.strict {
        return Err(BaselineError::NotConverged {
            method: Method::Icp,
            iterations,
            last_change,
            tolerance: params.tolerance_mm,
        });
    }
    Ok(IcpResult {
        transform,
        initial,
        rms_history,
        report: FitReport {
            method: Method::Icp,
            iterations,
            converged,
            final_error: rms,
        },
    })
}

/// Nearest target index of every moved point; returns the RMS distance.
fn correspond(tree: &KdTree, moved: &[P3], matched: &mut [usize]) -> f64 {
    let mut sum = 0.0;
    for (m, slot) in moved.iter().zip(matched.iter_mut()) {
        // The tree is non-empty (checked by the caller).
        let (j, d2) = tree.nearest(m).unwrap_or((0, f64::INFINITY));
        *slot = j;
        sum += d2;
    }
    (sum / moved.len() as f64).sqrt()
}
