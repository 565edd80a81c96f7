//! Coherent Point Drift (Myronenko & Song, IEEE TPAMI 2010): rigid (Fig. 2) and non-rigid
//! (Fig. 4).
//!
//! The template points `Y` (M of them) are the centroids of a Gaussian mixture, isotropic
//! variance σ², plus a uniform outlier component of weight `w`; the target points `X` (N)
//! are the data. EM alternates the posterior `P` (E-step) with the transform and σ²
//! (M-step).
//!
//! # Rigid (Fig. 2), scale fixed
//! `T(y) = R y + t` with `s = 1` **fixed**: the template and the patient are both in mm and
//! the inter-patient size difference is exactly what a rigid baseline must not absorb, so,
//! as in the paper's comparison, no scaling is estimated (Myronenko's `opt.scale = 0`). The
//! σ² update is then the full residual `(tr(X̂ᵀ d(Pᵀ1) X̂) − 2 tr(AᵀR) + tr(Ŷᵀ d(P1) Ŷ)) /
//! (N_P D)` (the reference MATLAB code's `opt.scale = 0` branch; the scaled formula
//! `(… − s tr(AᵀR))/(N_P D)` only holds at the optimal `s`). Start: `R = I`, `t = 0`,
//! σ² = `Σ_mn |x_n − y_m|² / (D M N)`. Runs in mm, un-normalised (like pycpd and probreg).
//!
//! # Non-rigid (Fig. 4)
//! `T(y) = y + G(y, Y) W` with the Gaussian kernel `G(a, b) = exp(−|a − b|² / (2β²))`,
//! regulariser `λ/2 tr(Wᵀ G W)`. As in the authors' reference implementation
//! (`cpd_normalize`), both clouds are first normalised, **each by its own** mean and scale
//! `sqrt(Σ|p − p̄|² / n)`, so β and λ are in normalised units (defaults β = 2, λ = 2, as in
//! the reference code, pycpd and probreg) and σ² starts at the same formula as the rigid
//! case. A consequence worth knowing: the normalisation maps the template onto the target's
//! overall size before any deformation, i.e. it includes a global scale of
//! `target_scale / template_scale` (the rigid variant does not).
//!
//! For speed the mixture uses at most [`NonRigidParams::max_control_points`] (default
//! 1500) template points `Y_c`, a seeded subsample; every other point — and any query point
//! — moves by the same kernel interpolation `G(p, Y_c) W`, which is exactly how CPD's
//! displacement field extends off the centroids.
//!
//! The M-step `(d(P1) G + λσ² I) W = P X − d(P1) Y` (Eq. 22) is solved, by default
//! ([`Solver::LowRank`]), with a pivoted-Cholesky factor `G ≈ L Lᵀ` (computed once, stopped
//! when the trace of `G − L Lᵀ` — a bound on its spectral norm — is below 1e-10·M; with
//! β = 2 the rank is ~80 for 1,500 phantom control points) and the Woodbury identity, O(M K²)
//! per iteration. [`Solver::Dense`] instead factorises the symmetric form
//! `(G + λσ² d(P1)⁻¹) W = d(P1)⁻¹ P X − Y` with a dense Cholesky every iteration (`P1`
//! floored at `1e-10·max P1`, so centroids with no data get `W ≈ 0`, the limit of the exact
//! solution); it is ~6× slower at M = 1,500 and agrees with the low-rank solve to ~1e-5 mm on
//! the phantoms (and with pycpd's dense solve, see `scripts/baselines/REPORT.md`).
//!
//! # Stopping rule (both)
//! As the reference MATLAB code: stop when the relative change of the negative
//! log-likelihood `L = −Σ_n log(Σ_m e^{−|x_n − T(y_m)|²/2σ²} + c) + (D N / 2) log σ²`
//! (`+ λ/2 tr(WᵀGW)` for non-rigid) falls below `tolerance` (default 1e-5, the reference
//! code's `opt.tol`), when σ² falls to `10·ε`, or after `max_iterations` (default 150, also
//! the reference code's) EM iterations.

use super::{
    add, check_cloud, check_param, dist2, dot, finite_positive, rotation_from_covariance, scale,
    seeded_subsample, sub, BaselineError, FitReport, Mapping, Method, Rigid, Role, P3,
};

/// Rigid CPD settings.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidParams {
    /// Weight of the uniform outlier component, in [0, 1) (default 0.1).
    pub w: f64,
    /// Maximum EM iterations (default 150).
    pub max_iterations: usize,
    /// Relative change of the objective at which EM stops (default 1e-5, as the reference
    /// MATLAB code).
    pub tolerance: f64,
    /// Initial σ², mm²; `None` (default) = `Σ|x − y|² / (D M N)`.
    pub sigma2_init: Option<f64>,
    /// Return [`BaselineError::NotConverged`] when the cap is reached (default `false`).
    pub strict: bool,
}

impl Default for RigidParams {
    fn default() -> Self {
        Self {
            w: 0.1,
            max_iterations: 150,
            tolerance: 1e-5,
            sigma2_init: None,
            strict: false,
        }
    }
}

/// Non-rigid CPD settings.
#[derive(Clone, Debug, PartialEq)]
pub struct NonRigidParams {
    /// Weight of the uniform outlier component, in [0, 1) (default 0.1).
    pub w: f64,
    /// Gaussian kernel width β, normalised units (default 2.0).
    pub beta: f64,
    /// Regularisation weight λ (default 2.0).
    pub lambda: f64,
    /// Maximum EM iterations (default 150).
    pub max_iterations: usize,
    /// Relative change of the objective at which EM stops (default 1e-5, as the reference
    /// MATLAB code).
    pub tolerance: f64,
    /// Mixture centroids (kernel control points) drawn from the template (default 1500).
    pub max_control_points: usize,
    /// Seed of the control-point subsample (default 0).
    pub seed: u64,
    /// Normalise each cloud to zero mean, unit RMS radius first (default `true`, as the
    /// reference implementation).
    pub normalize: bool,
    /// How the M-step system is solved (default: low rank, trace tolerance 1e-10).
    pub solver: Solver,
    /// Return [`BaselineError::NotConverged`] when the cap is reached (default `false`).
    pub strict: bool,
}

/// M-step solver of non-rigid CPD.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solver {
    /// Dense Cholesky of the M×M system every iteration: exact, O(M³) per iteration.
    Dense,
    /// `G ≈ L Lᵀ` by pivoted Cholesky, stopped when the trace of the remainder is below
    /// `trace_tolerance · M` (it bounds the spectral norm of `G − L Lᵀ`); the M-step is then
    /// solved exactly for that `G` with the Woodbury identity, O(M K²) per iteration.
    LowRank {
        /// Relative trace tolerance of the pivoted Cholesky, in (0, 1].
        trace_tolerance: f64,
    },
}

impl Default for NonRigidParams {
    fn default() -> Self {
        Self {
            w: 0.1,
            beta: 2.0,
            lambda: 2.0,
            max_iterations: 150,
            tolerance: 1e-5,
            max_control_points: 1500,
            seed: 0,
            normalize: true,
            solver: Solver::LowRank {
                trace_tolerance: 1e-10,
            },
            strict: false,
        }
    }
}

/// A fitted rigid CPD registration.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidResult {
    /// Template frame → target frame (`s = 1`).
    pub transform: Rigid,
    /// Final GMM variance σ², mm².
    pub sigma2: f64,
    /// How the fit ended (`final_error` = σ, mm).
    pub report: FitReport,
}

impl Mapping for RigidResult {
    fn map(&self, p: P3) -> P3 {
        self.transform.apply(p)
    }
    fn report(&self) -> &FitReport {
        &self.report
    }
}

/// A fitted non-rigid CPD registration.
#[derive(Clone, Debug, PartialEq)]
pub struct NonRigidResult {
    /// Indices (into the template) of the control points, sorted.
    pub control_indices: Vec<usize>,
    /// Control points in normalised template coordinates.
    pub control: Vec<P3>,
    /// Kernel weights W, one row per control point (normalised units).
    pub weights: Vec<P3>,
    /// Kernel width β (normalised units).
    pub beta: f64,
    /// Template normalisation: `p_n = (p − mean) / scale`.
    pub template_mean: P3,
    /// Template normalisation scale, mm.
    pub template_scale: f64,
    /// Target normalisation: `x = x_n · scale + mean`.
    pub target_mean: P3,
    /// Target normalisation scale, mm.
    pub target_scale: f64,
    /// Final GMM variance σ², normalised units.
    pub sigma2: f64,
    /// Rank K of the kernel approximation (M for [`Solver::Dense`]).
    pub kernel_rank: usize,
    /// How the fit ended (`final_error` = σ in mm, i.e. `sqrt(σ²)·target_scale`).
    pub report: FitReport,
}

impl NonRigidResult {
    /// Displacement `G(p, Y_c) W` of a normalised template point.
    fn displacement(&self, pn: P3) -> P3 {
        let k = -1.0 / (2.0 * self.beta * self.beta);
        let mut d = [0.0; 3];
        for (c, w) in self.control.iter().zip(&self.weights) {
            let g = (k * dist2(pn, *c)).exp();
            d = add(d, scale(*w, g));
        }
        d
    }
}

impl Mapping for NonRigidResult {
    fn map(&self, p: P3) -> P3 {
        let pn = scale(sub(p, self.template_mean), 1.0 / self.template_scale);
        let tn = add(pn, self.displacement(pn));
        add(scale(tn, self.target_scale), self.target_mean)
    }
    fn report(&self) -> &FitReport {
        &self.report
    }
}

fn validate_common(
    template: &[P3],
    target: &[P3],
    w: f64,
    tolerance: f64,
    max_iterations: usize,
) -> Result<(), BaselineError> {
    check_cloud(template, Role::Template, 3)?;
    check_cloud(target, Role::Target, 3)?;
    check_param("w", w, 0.0, 1.0 - 1e-12, false, "0 <= w < 1")?;
    check_param(
        "tolerance",
        tolerance,
        0.0,
        f64::MAX,
        false,
        "a finite value >= 0",
    )?;
    if max_iterations == 0 {
        return Err(BaselineError::InvalidParameter {
            name: "max_iterations",
            value: 0.0,
            expected: "at least 1",
        });
    }
    Ok(())
}

/// `Σ_mn |x_n − y_m|² / (D M N)` in O(M + N).
fn initial_sigma2(x: &[P3], y: &[P3]) -> f64 {
    let (n, m) = (x.len() as f64, y.len() as f64);
    let mut sx = [0.0; 3];
    let mut sy = [0.0; 3];
    let mut qx = 0.0;
    let mut qy = 0.0;
    for p in x {
        sx = add(sx, *p);
        qx += dot(*p, *p);
    }
    for p in y {
        sy = add(sy, *p);
        qy += dot(*p, *p);
    }
    // Σ_mn |x|² + |y|² − 2 x·y = M Σ|x|² + N Σ|y|² − 2 (Σx)·(Σy)
    (m * qx + n * qy - 2.0 * dot(sx, sy)) / (3.0 * m * n)
}

/// Sufficient statistics of one E-step.
struct EStep {
    /// `P 1`, per centroid.
    p1: Vec<f64>,
    /// `Pᵀ 1`, per data point.
    pt1: Vec<f64>,
    /// `P X`, per centroid.
    px: Vec<P3>,
    /// `Σ P`.
    np: f64,
    /// Negative log-likelihood (without the regulariser).
    nll: f64,
}

/// E-step: posteriors of the centroids `ty` for the data `x`.
fn expectation(x: &[P3], ty: &[P3], sigma2: f64, w: f64) -> EStep {
    let (n, m) = (x.len(), ty.len());
    let c = (2.0 * std::f64::consts::PI * sigma2).powf(1.5) * w / (1.0 - w) * m as f64 / n as f64;
    let k = -1.0 / (2.0 * sigma2);
    // exp underflows to 0 below −745: skip the call for such pairs.
    let cutoff = 745.0 * 2.0 * sigma2;
    let mut p1 = vec![0.0; m];
    let mut px = vec![[0.0; 3]; m];
    let mut pt1 = vec![0.0; n];
    let mut col = vec![0.0; m];
    let mut nll = 0.0;
    for (xn, pt1n) in x.iter().zip(pt1.iter_mut()) {
        let mut sum = 0.0;
        for (cm, y) in col.iter_mut().zip(ty) {
            let d2 = dist2(*xn, *y);
            *cm = if d2 < cutoff { (k * d2).exp() } else { 0.0 };
            sum += *cm;
        }
        let den = sum + c;
        nll -= den.max(f64::MIN_POSITIVE).ln();
        if den <= 0.0 {
            continue; // no centroid can explain this point (only when w = 0)
        }
        let inv = 1.0 / den;
        let mut colsum = 0.0;
        for ((cm, p1m), pxm) in col.iter().zip(p1.iter_mut()).zip(px.iter_mut()) {
            if *cm != 0.0 {
                let p = cm * inv;
                *p1m += p;
                *pxm = add(*pxm, scale(*xn, p));
                colsum += p;
            }
        }
        *pt1n = colsum;
    }
    nll += 1.5 * n as f64 * sigma2.ln();
    let np = p1.iter().sum();
    EStep {
        p1,
        pt1,
        px,
        np,
        nll,
    }
}

fn numerical(method: Method, what: &str) -> BaselineError {
    BaselineError::Numerical {
        method,
        what: what.into(),
    }
}

/// Relative change of the objective, as the reference code (`|ΔL / L|`).
fn relative_change(prev: f64, cur: f64) -> f64 {
    if cur == 0.0 {
        (cur - prev).abs()
    } else {
        ((cur - prev) / cur).abs()
    }
}

/// Rigid CPD (Fig. 2) with `s = 1` fixed.
///
/// # Errors
/// Empty/non-finite clouds, fewer than 3 points in either, invalid parameters, a degenerate
/// (collinear) template, a numerical breakdown, or with `strict` no convergence.
pub fn fit_rigid(
    template: &[P3],
    target: &[P3],
    params: &RigidParams,
) -> Result<RigidResult, BaselineError> {
    const M: Method = Method::CpdRigid;
    validate_common(
        template,
        target,
        params.w,
        params.tolerance,
        params.max_iterations,
    )?;
    let mut sigma2 = match params.sigma2_init {
        Some(s) => {
            check_param("sigma2_init", s, 0.0, f64::MAX, true, "a finite value > 0")?;
            s
        }
        None => initial_sigma2(target, template),
    };
    if !finite_positive(sigma2) {
        return Err(BaselineError::Degenerate {
            method: M,
            what: "all template and target points coincide (initial σ² = 0)".into(),
        });
    }
    let y = template;
    let x = target;
    let mut transform = Rigid::IDENTITY;
    let mut ty: Vec<P3> = y.to_vec();
    let mut prev = f64::NAN;
    let mut iterations = 0;
    let mut converged = false;
    let mut last_change = f64::INFINITY;
    let sigma2_floor = 10.0 * f64::EPSILON;
    while iterations < params.max_iterations {
        let e = expectation(x, &ty, sigma2, params.w);
        iterations += 1;
        if !finite_positive(e.np) || !e.nll.is_finite() {
            return Err(numerical(
                M,
                "no template point explains any target point (all posteriors are 0)",
            ));
        }
        // M-step (Fig. 2).
        let inv_np = 1.0 / e.np;
        let mut mu_x = [0.0; 3];
        for (xn, p) in x.iter().zip(&e.pt1) {
            mu_x = add(mu_x, scale(*xn, *p));
        }
        mu_x = scale(mu_x, inv_np);
        let mut mu_y = [0.0; 3];
        for (ym, p) in y.iter().zip(&e.p1) {
            mu_y = add(mu_y, scale(*ym, *p));
        }
        mu_y = scale(mu_y, inv_np);
        // A = X̂ᵀ Pᵀ Ŷ = Σ_m (P X)_m ŷ_mᵀ − μx (Σ_m P1_m ŷ_m)ᵀ, the last sum being 0.
        let mut a = [[0.0; 3]; 3];
        let mut ypy = 0.0;
        for ((ym, pxm), p1m) in y.iter().zip(&e.px).zip(&e.p1) {
            let yh = sub(*ym, mu_y);
            let pxh = sub(*pxm, scale(mu_x, *p1m));
            for i in 0..3 {
                for j in 0..3 {
                    a[i][j] += pxh[i] * yh[j];
                }
            }
            ypy += p1m * dot(yh, yh);
        }
        let mut xpx = 0.0;
        for (xn, p) in x.iter().zip(&e.pt1) {
            let xh = sub(*xn, mu_x);
            xpx += p * dot(xh, xh);
        }
        let r = rotation_from_covariance(&a).ok_or_else(|| BaselineError::Degenerate {
            method: M,
            what: "the weighted cross-covariance has rank < 2 (collinear template or target)"
                .into(),
        })?;
        let tr_ar: f64 = (0..3)
            .map(|i| (0..3).map(|j| a[i][j] * r[i][j]).sum::<f64>())
            .sum();
        transform = Rigid {
            rotation: r,
            translation: [0.0; 3],
        };
        transform.translation = sub(mu_x, transform.apply(mu_y));
        sigma2 = ((xpx - 2.0 * tr_ar + ypy) / (3.0 * e.np)).abs();
        for (t, p) in ty.iter_mut().zip(y) {
            *t = transform.apply(*p);
        }
        if !sigma2.is_finite() || !transform.translation.iter().all(|v| v.is_finite()) {
            return Err(numerical(M, "σ² or the transform became non-finite"));
        }
        if prev.is_finite() {
            last_change = relative_change(prev, e.nll);
            if last_change <= params.tolerance {
                converged = true;
                break;
            }
        }
        prev = e.nll;
        if sigma2 <= sigma2_floor {
            // Exact fit: the mixture collapsed onto the data.
            sigma2 = sigma2_floor;
            converged = true;
            break;
        }
    }
    if !converged && params.strict {
        return Err(BaselineError::NotConverged {
            method: M,
            iterations,
            last_change,
            tolerance: params.tolerance,
        });
    }
    Ok(RigidResult {
        transform,
        sigma2,
        report: FitReport {
            method: M,
            iterations,
            converged,
            final_error: sigma2.sqrt(),
        },
    })
}

/// Mean and RMS radius of a cloud.
fn normalisation(points: &[P3]) -> (P3, f64) {
    let mean = super::centroid(points);
    let ss: f64 = points.iter().map(|p| dist2(*p, mean)).sum();
    (mean, (ss / points.len() as f64).sqrt())
}

/// Non-rigid CPD (Fig. 4) with Gaussian kernel, control points subsampled.
///
/// # Errors
/// Empty/non-finite clouds, fewer than 3 points in either, invalid parameters, a cloud of
/// coincident points (zero scale), a numerical breakdown (the M-step system not positive
/// definite, non-finite values), or with `strict` no convergence.
pub fn fit_nonrigid(
    template: &[P3],
    target: &[P3],
    params: &NonRigidParams,
) -> Result<NonRigidResult, BaselineError> {
    const M: Method = Method::CpdNonRigid;
    validate_common(
        template,
        target,
        params.w,
        params.tolerance,
        params.max_iterations,
    )?;
    check_param(
        "beta",
        params.beta,
        0.0,
        f64::MAX,
        true,
        "a finite value > 0",
    )?;
    check_param(
        "lambda",
        params.lambda,
        0.0,
        f64::MAX,
        true,
        "a finite value > 0",
    )?;
    if params.max_control_points < 3 {
        return Err(BaselineError::InvalidParameter {
            name: "max_control_points",
            value: params.max_control_points as f64,
            expected: "at least 3",
        });
    }
    let (ym, ys, xm, xs) = if params.normalize {
        let (ym, ys) = normalisation(template);
        let (xm, xs) = normalisation(target);
        (ym, ys, xm, xs)
    } else {
        ([0.0; 3], 1.0, [0.0; 3], 1.0)
    };
    for (role, s) in [(Role::Template, ys), (Role::Target, xs)] {
        if !finite_positive(s) {
            return Err(BaselineError::Degenerate {
                method: M,
                what: format!("all {role} points coincide (zero scale)"),
            });
        }
    }
    let control_indices = seeded_subsample(template.len(), params.max_control_points, params.seed);
    let y: Vec<P3> = control_indices
        .iter()
        .map(|&i| scale(sub(template[i], ym), 1.0 / ys))
        .collect();
    let x: Vec<P3> = target
        .iter()
        .map(|p| scale(sub(*p, xm), 1.0 / xs))
        .collect();
    let m = y.len();
    // Kernel matrix, row-major, full.
    let kb = -1.0 / (2.0 * params.beta * params.beta);
    let mut g = vec![0.0; m * m];
    for i in 0..m {
        g[i * m + i] = 1.0;
        for j in 0..i {
            let v = (kb * dist2(y[i], y[j])).exp();
            g[i * m + j] = v;
            g[j * m + i] = v;
        }
    }
    let mut w = vec![[0.0; 3]; m];
    let mut ty = y.clone();
    let mut sigma2 = initial_sigma2(&x, &y);
    let mut prev = f64::NAN;
    let mut iterations = 0;
    let mut converged = false;
    let mut last_change = f64::INFINITY;
    let sigma2_floor = 10.0 * f64::EPSILON;
    let low_rank = match params.solver {
        Solver::Dense => None,
        Solver::LowRank { trace_tolerance } => {
            check_param(
                "trace_tolerance",
                trace_tolerance,
                0.0,
                1.0,
                true,
                "a value in (0, 1]",
            )?;
            Some(LowRank::new(&g, m, trace_tolerance * m as f64))
        }
    };
    let mut chol = if low_rank.is_none() {
        vec![0.0; m * m]
    } else {
        Vec::new()
    };
    let mut gw = vec![[0.0; 3]; m];
    while iterations < params.max_iterations {
        let e = expectation(&x, &ty, sigma2, params.w);
        iterations += 1;
        if !finite_positive(e.np) || !e.nll.is_finite() {
            return Err(numerical(
                M,
                "no template point explains any target point (all posteriors are 0)",
            ));
        }
        // Objective of the current state: data term + λ/2 tr(Wᵀ G W).
        let reg: f64 = gw.iter().zip(&w).map(|(a, b)| dot(*a, *b)).sum();
        let obj = e.nll + params.lambda / 2.0 * reg;
        let ls = params.lambda * sigma2;
        w = match &low_rank {
            None => {
                // Exact M-step: (G + λσ² d(P1)⁻¹) W = d(P1)⁻¹ P X − Y.
                let p1max = e.p1.iter().cloned().fold(0.0, f64::max);
                let floor = p1max * 1e-10;
                chol.copy_from_slice(&g);
                let mut rhs = vec![[0.0; 3]; m];
                for i in 0..m {
                    let p = e.p1[i].max(floor);
                    chol[i * m + i] += ls / p;
                    rhs[i] = sub(scale(e.px[i], 1.0 / p), y[i]);
                }
                cholesky_in_place(&mut chol, m).map_err(|row| {
                    numerical(
                        M,
                        &format!("M-step matrix not positive definite at row {row}"),
                    )
                })?;
                cholesky_solve(&chol, m, &mut rhs);
                rhs
            }
            Some(lr) => lr
                .solve(&e.p1, &e.px, &y, ls)
                .map_err(|what| numerical(M, &what))?,
        };
        // T = Y + G W.
        for i in 0..m {
            let row = &g[i * m..(i + 1) * m];
            let mut acc = [0.0; 3];
            for (gij, wj) in row.iter().zip(&w) {
                acc[0] += gij * wj[0];
                acc[1] += gij * wj[1];
                acc[2] += gij * wj[2];
            }
            gw[i] = acc;
            ty[i] = add(y[i], acc);
        }
        // σ² (Eq. 23, with the new T).
        let mut xpx = 0.0;
        for (xn, p) in x.iter().zip(&e.pt1) {
            xpx += p * dot(*xn, *xn);
        }
        let mut tpt = 0.0;
        let mut trpxt = 0.0;
        for ((t, p1), pxm) in ty.iter().zip(&e.p1).zip(&e.px) {
            tpt += p1 * dot(*t, *t);
            trpxt += dot(*pxm, *t);
        }
        sigma2 = ((xpx - 2.0 * trpxt + tpt) / (3.0 * e.np)).abs();
        if !sigma2.is_finite() || !w.iter().flatten().all(|v| v.is_finite()) {
            return Err(numerical(M, "σ² or the kernel weights became non-finite"));
        }
        if prev.is_finite() {
            last_change = relative_change(prev, obj);
            if last_change <= params.tolerance {
                converged = true;
                break;
            }
        }
        prev = obj;
        if sigma2 <= sigma2_floor {
            sigma2 = sigma2_floor;
            converged = true;
            break;
        }
    }
    if !converged && params.strict {
        return Err(BaselineError::NotConverged {
            method: M,
            iterations,
            last_change,
            tolerance: params.tolerance,
        });
    }
    Ok(NonRigidResult {
        control_indices,
        control: y,
        weights: w,
        beta: params.beta,
        template_mean: ym,
        template_scale: ys,
        target_mean: xm,
        target_scale: xs,
        sigma2,
        kernel_rank: low_rank.as_ref().map_or(m, |lr| lr.k),
        report: FitReport {
            method: M,
            iterations,
            converged,
            final_error: sigma2.sqrt() * xs,
        },
    })
}

/// Low-rank factor `G ≈ L Lᵀ` (L is M×K, stored row-major) of the kernel matrix.
struct LowRank {
    m: usize,
    k: usize,
    l: Vec<f64>,
}

impl LowRank {
    /// Pivoted (incomplete) Cholesky of the row-major SPD `g` (M×M), stopped when the trace
    /// of `G − L Lᵀ` is at most `trace_tol`.
    fn new(g: &[f64], m: usize, trace_tol: f64) -> LowRank {
        let mut diag: Vec<f64> = (0..m).map(|i| g[i * m + i]).collect();
        let mut cols: Vec<Vec<f64>> = Vec::new(); // column j of L, length M
        let mut used = vec![false; m];
        loop {
            let rest: f64 = diag
                .iter()
                .zip(&used)
                .filter(|(_, u)| !**u)
                .map(|(d, _)| d.max(0.0))
                .sum();
            if rest <= trace_tol || cols.len() == m {
                break;
            }
            // Largest remaining diagonal (lowest index on ties).
            let mut piv = usize::MAX;
            for i in 0..m {
                if !used[i] && (piv == usize::MAX || diag[i] > diag[piv]) {
                    piv = i;
                }
            }
            let d = diag[piv];
            if !finite_positive(d) {
                break;
            }
            let sd = d.sqrt();
            let mut col = vec![0.0; m];
            for i in 0..m {
                if used[i] {
                    continue;
                }
                let mut v = g[i * m + piv];
                for c in &cols {
                    v -= c[i] * c[piv];
                }
                col[i] = v / sd;
            }
            col[piv] = sd;
            used[piv] = true;
            for i in 0..m {
                if !used[i] {
                    diag[i] -= col[i] * col[i];
                }
            }
            cols.push(col);
        }
        let k = cols.len();
        let mut l = vec![0.0; m * k];
        for (j, c) in cols.iter().enumerate() {
            for i in 0..m {
                l[i * k + j] = c[i];
            }
        }
        LowRank { m, k, l }
    }

    /// Solve `(d(P1) L Lᵀ + c I) W = P X − d(P1) Y` by Woodbury:
    /// `W = (F − d(P1) L (c I + Lᵀ d(P1) L)⁻¹ Lᵀ F) / c`.
    fn solve(&self, p1: &[f64], px: &[P3], y: &[P3], c: f64) -> Result<Vec<P3>, String> {
        let (m, k) = (self.m, self.k);
        let f: Vec<P3> = (0..m).map(|i| sub(px[i], scale(y[i], p1[i]))).collect();
        if k == 0 {
            return Ok(f.iter().map(|v| scale(*v, 1.0 / c)).collect());
        }
        // S = c I + Lᵀ d(P1) L (K×K), r = Lᵀ F (K×3).
        let mut s = vec![0.0; k * k];
        let mut r = vec![[0.0; 3]; k];
        for i in 0..m {
            let row = &self.l[i * k..(i + 1) * k];
            let p = p1[i];
            if p != 0.0 {
                for a in 0..k {
                    let v = p * row[a];
                    if v != 0.0 {
                        let srow = &mut s[a * k..a * k + a + 1];
                        for (sb, lb) in srow.iter_mut().zip(&row[..=a]) {
                            *sb += v * lb;
                        }
                    }
                }
            }
            for a in 0..k {
                r[a] = add(r[a], scale(f[i], row[a]));
            }
        }
        for a in 0..k {
            s[a * k + a] += c;
            for b in 0..a {
                s[b * k + a] = s[a * k + b];
            }
        }
        cholesky_in_place(&mut s, k)
            .map_err(|row| format!("low-rank M-step matrix not positive definite at row {row}"))?;
        cholesky_solve(&s, k, &mut r);
        Ok((0..m)
            .map(|i| {
                let row = &self.l[i * k..(i + 1) * k];
                let mut lz = [0.0; 3];
                for (la, ra) in row.iter().zip(&r) {
                    lz = add(lz, scale(*ra, *la));
                }
                scale(sub(f[i], scale(lz, p1[i])), 1.0 / c)
            })
            .collect())
    }
}

/// Dot product with four independent accumulators (lets the compiler vectorise).
fn fast_dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let ca = a.chunks_exact(4);
    let cb = b.chunks_exact(4);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        acc[0] += x[0] * y[0];
        acc[1] += x[1] * y[1];
        acc[2] += x[2] * y[2];
        acc[3] += x[3] * y[3];
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// In-place Cholesky `A = L Lᵀ` of a row-major SPD `n×n` matrix; the lower triangle is
/// overwritten by `L` (the upper triangle is left stale). `Err(row)` if not positive
/// definite.
pub(crate) fn cholesky_in_place(a: &mut [f64], n: usize) -> Result<(), usize> {
    for i in 0..n {
        let (done, rest) = a.split_at_mut(i * n);
        let row_i = &mut rest[..n];
        for j in 0..i {
            let row_j = &done[j * n..j * n + n];
            let s = row_i[j] - fast_dot(&row_i[..j], &row_j[..j]);
            row_i[j] = s / row_j[j];
        }
        let d = row_i[i] - fast_dot(&row_i[..i], &row_i[..i]);
        if !finite_positive(d) {
            return Err(i);
        }
        row_i[i] = d.sqrt();
    }
    Ok(())
}

/// Solve `L Lᵀ x = b` for three right-hand sides in place (`l` from [`cholesky_in_place`]).
pub(crate) fn cholesky_solve(l: &[f64], n: usize, b: &mut [P3]) {
    // Forward: L z = b.
    for i in 0..n {
        let row = &l[i * n..i * n + i];
        let mut acc = b[i];
        for (lij, zj) in row.iter().zip(&b[..i]) {
            acc = sub(acc, scale(*zj, *lij));
        }
        b[i] = scale(acc, 1.0 / l[i * n + i]);
    }
    // Backward: Lᵀ x = z.
    for i in (0..n).rev() {
        let xi = scale(b[i], 1.0 / l[i * n + i]);
        b[i] = xi;
        for j in 0..i {
            let lij = l[i * n + j];
            b[j] = sub(b[j], scale(xi, lij));
        }
    }
}
