//! Optimal-step non-rigid ICP (Amberg, Romdhani & Vetter, CVPR 2007), landmark term off.
//!
//! Every graph node `i` carries an affine transform `X_i` (4×3, applied as `[v; 1]ᵀ X_i`).
//! For each stiffness `α` of a decreasing schedule, the algorithm alternates (at most
//! [`NricpParams::max_iterations_per_step`] times): closest target point `u_i` of every
//! transformed node (exact k-d tree), then the exact minimiser of
//!
//! `E(X) = Σ_i w_i |[v_i; 1]ᵀ X_i − u_i|² + α² ‖(M ⊗ G) X‖²_F`
//!
//! (paper Eq. 6–12), `M` the node–arc incidence matrix of the graph, `G = diag(1, 1, 1, γ)`.
//! The normal equations `(α² (MᵀM) ⊗ G² + Dᵀ W D) X = Dᵀ W U` (4n unknowns per coordinate)
//! are solved with block-Jacobi-preconditioned conjugate gradients on a CSR matrix, warm
//! started from the previous `X`.
//!
//! Conventions follow `trimesh.registration.nricp_amberg` (trimesh 4.x/5.x) so that the two
//! can be compared on the same inputs:
//! * coordinates are normalised by the template: `v_n = (v − c) / s`, `c` the template
//!   centroid and `s` the diagonal of its bounding box;
//! * incidence rows are weighted by `1 / |v_a − v_b|` (normalised units);
//! * data weights `w_i` are 1, or 0 when the closest target point is farther than
//!   [`NricpParams::distance_threshold`] (normalised units, default 0.1 = 10 % of the
//!   template's diagonal);
//! * a step ends when the mean weighted distance `mean_i(w_i |u_i − [v_i;1]ᵀX_i|)` stops
//!   decreasing by more than [`NricpParams::eps`] (default 1e-4, normalised units), or after
//!   the per-step cap (default 10).
//!
//! # Graph and mapping
//! The template is a point cloud, not a mesh: the graph nodes are a seeded subsample of at
//! most [`NricpParams::max_nodes`] (default 1500) template points, edges join each node to
//! its [`NricpParams::graph_k`] (default 6) nearest nodes (symmetrised, each edge once). Any
//! point `p` (a template point or a waypoint) is mapped by the inverse-square-distance
//! weighted mean of the affine transforms of its [`NricpParams::interp_k`] (default 8)
//! nearest nodes applied to `p` itself; a node maps exactly by its own transform. (8 rather
//! than fewer because a waypoint lies in the gap between two cartilages: its 8 nearest nodes
//! usually include both, where 4 often sit on one side only — 0.4 mm lower waypoint error
//! on phantoms 0–4.)
//! [`fit_graph`] takes explicit nodes and edges instead (e.g. a mesh's vertices and edges,
//! which is how the comparison script checks this implementation against trimesh).
//!
//! # Stiffness schedule
//! `stiffness` (default `[50, 20, 5, 2, 0.8, 0.5, 0.2]`, the decreasing schedule of Amberg's
//! paper as used by menpo3d, which uses unweighted incidence rows) is multiplied by
//! `stiffness_unit`; by default that is the mean normalised edge length of the graph, which
//! turns the `1/length`-weighted rows back into roughly unit-weighted ones, so the schedule
//! means the same whatever the node density. (trimesh's own default `steps` pair a small
//! stiffness with landmark weights; with the landmark term off they do not apply.)
//!
//! # Initial alignment
//! Like [`super::icp`], the template is first translated onto the target centroid
//! (`align_centroids`, default on); the paper likewise pre-aligned ICP and non-rigid ICP.

use super::kdtree::KdTree;
use super::{
    add, centroid, check_cloud, check_param, dist2, dot, finite_positive, scale, seeded_subsample,
    sub, BaselineError, FitReport, Mapping, Method, Role, P3,
};

const M: Method = Method::NonRigidIcp;

/// Non-rigid ICP settings.
#[derive(Clone, Debug, PartialEq)]
pub struct NricpParams {
    /// Stiffness schedule α (dimensionless, multiplied by `stiffness_unit`), decreasing.
    pub stiffness: Vec<f64>,
    /// Multiplier of `stiffness`; `None` (default) = mean normalised edge length.
    pub stiffness_unit: Option<f64>,
    /// Correspondence + solve rounds per stiffness (default 10).
    pub max_iterations_per_step: usize,
    /// A step ends when the mean weighted distance decreases by less than this
    /// (normalised units, default 1e-4).
    pub eps: f64,
    /// Weight of the translation column against the linear part (default 1).
    pub gamma: f64,
    /// Correspondences farther than this get weight 0 (normalised units, default 0.1).
    pub distance_threshold: f64,
    /// Neighbours per node in the k-NN graph (default 6).
    pub graph_k: usize,
    /// Maximum number of graph nodes (default 1500).
    pub max_nodes: usize,
    /// Nodes blended when mapping a point (default 8).
    pub interp_k: usize,
    /// Seed of the node subsample (default 0).
    pub seed: u64,
    /// Translate the template onto the target centroid first (default `true`).
    pub align_centroids: bool,
    /// Relative residual at which conjugate gradients stop (default 1e-9).
    pub cg_tolerance: f64,
    /// Conjugate-gradient iteration cap per solve (default 20 000).
    pub cg_max_iterations: usize,
    /// Return [`BaselineError::NotConverged`] when a step hits its cap (default `false`).
    pub strict: bool,
}

impl Default for NricpParams {
    fn default() -> Self {
        Self {
            stiffness: vec![50.0, 20.0, 5.0, 2.0, 0.8, 0.5, 0.2],
            stiffness_unit: None,
            max_iterations_per_step: 10,
            eps: 1e-4,
            gamma: 1.0,
            distance_threshold: 0.1,
            graph_k: 6,
            max_nodes: 1500,
            interp_k: 8,
            seed: 0,
            align_centroids: true,
            cg_tolerance: 1e-9,
            cg_max_iterations: 20_000,
            strict: false,
        }
    }
}

/// Normalisation frame: `v_n = (v − centre) / scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Centre, mm.
    pub centre: P3,
    /// Scale, mm.
    pub scale: f64,
}

/// A fitted non-rigid ICP registration.
#[derive(Clone, Debug)]
pub struct NricpResult {
    /// Initial translation applied to every point before the node transforms, mm.
    pub initial_translation: P3,
    /// Normalisation frame (of the translated template).
    pub frame: Frame,
    /// Node positions, normalised (after the initial translation).
    pub nodes: Vec<P3>,
    /// Indices of the nodes in the template (for [`fit`]; `0..n` for [`fit_graph`]).
    pub node_indices: Vec<usize>,
    /// Graph edges (node index pairs).
    pub edges: Vec<[usize; 2]>,
    /// Affine transform of each node: rows `X_i[0..3]` multiply x, y, z, row 3 is the
    /// translation (normalised units).
    pub transforms: Vec<[P3; 4]>,
    /// The stiffness values actually used (schedule × unit).
    pub stiffness_used: Vec<f64>,
    /// Solves per stiffness step.
    pub iterations_per_step: Vec<usize>,
    /// Conjugate-gradient iterations of each solve.
    pub cg_iterations: Vec<usize>,
    /// Nodes blended per mapped point.
    pub interp_k: usize,
    tree: KdTree,
    /// How the fit ended (`final_error`: mean weighted closest-point distance, mm).
    pub report: FitReport,
}

fn affine(x: &[P3; 4], p: P3) -> P3 {
    let mut o = x[3];
    for (k, row) in x.iter().take(3).enumerate() {
        o = add(o, scale(*row, p[k]));
    }
    o
}

impl NricpResult {
    /// The transformed graph nodes, mm (template frame → target frame).
    pub fn node_positions(&self) -> Vec<P3> {
        self.nodes
            .iter()
            .zip(&self.transforms)
            .map(|(v, x)| self.denormalise(affine(x, *v)))
            .collect()
    }

    fn denormalise(&self, p: P3) -> P3 {
        add(scale(p, self.frame.scale), self.frame.centre)
    }
}

impl Mapping for NricpResult {
    fn map(&self, p: P3) -> P3 {
        let q = add(p, self.initial_translation);
        let qn = scale(sub(q, self.frame.centre), 1.0 / self.frame.scale);
        let near = self.tree.k_nearest(&qn, self.interp_k.max(1));
        let mut acc = [0.0; 3];
        let mut wsum = 0.0;
        for &(j, d2) in &near {
            if d2 == 0.0 {
                return self.denormalise(affine(&self.transforms[j], qn));
            }
            let w = 1.0 / d2;
            acc = add(acc, scale(affine(&self.transforms[j], qn), w));
            wsum += w;
        }
        if !finite_positive(wsum) {
            // Only for a non-finite query: propagate NaN rather than panic.
            return [f64::NAN; 3];
        }
        self.denormalise(scale(acc, 1.0 / wsum))
    }
    fn report(&self) -> &FitReport {
        &self.report
    }
}

fn validate(params: &NricpParams) -> Result<(), BaselineError> {
    if params.stiffness.is_empty() {
        return Err(BaselineError::InvalidParameter {
            name: "stiffness",
            value: 0.0,
            expected: "at least one stiffness value",
        });
    }
    for &a in &params.stiffness {
        check_param("stiffness", a, 0.0, f64::MAX, true, "finite values > 0")?;
    }
    if let Some(u) = params.stiffness_unit {
        check_param(
            "stiffness_unit",
            u,
            0.0,
            f64::MAX,
            true,
            "a finite value > 0",
        )?;
    }
    check_param(
        "eps",
        params.eps,
        0.0,
        f64::MAX,
        false,
        "a finite value >= 0",
    )?;
    check_param(
        "gamma",
        params.gamma,
        0.0,
        f64::MAX,
        true,
        "a finite value > 0",
    )?;
    check_param(
        "distance_threshold",
        params.distance_threshold,
        0.0,
        f64::MAX,
        true,
        "a finite value > 0",
    )?;
    check_param(
        "cg_tolerance",
        params.cg_tolerance,
        0.0,
        1.0,
        true,
        "a value in (0, 1]",
    )?;
    for (name, v, min) in [
        ("max_iterations_per_step", params.max_iterations_per_step, 1),
        ("graph_k", params.graph_k, 1),
        ("max_nodes", params.max_nodes, 4),
        ("interp_k", params.interp_k, 1),
        ("cg_max_iterations", params.cg_max_iterations, 1),
    ] {
        if v < min {
            return Err(BaselineError::InvalidParameter {
                name,
                value: v as f64,
                expected: "a larger count (see NricpParams)",
            });
        }
    }
    Ok(())
}

/// Non-rigid ICP of a template point cloud: k-NN graph on a node subsample.
///
/// # Errors
/// Empty/non-finite clouds, fewer than 4 template points, invalid parameters, a template of
/// coincident points, a numerical breakdown, or with `strict` a step hitting its cap.
pub fn fit(
    template: &[P3],
    target: &[P3],
    params: &NricpParams,
) -> Result<NricpResult, BaselineError> {
    check_cloud(template, Role::Template, 4)?;
    check_cloud(target, Role::Target, 1)?;
    validate(params)?;
    let node_indices = seeded_subsample(template.len(), params.max_nodes, params.seed);
    let nodes: Vec<P3> = node_indices.iter().map(|&i| template[i]).collect();
    let edges = knn_graph(&nodes, params.graph_k);
    let t0 = if params.align_centroids {
        sub(centroid(target), centroid(template))
    } else {
        [0.0; 3]
    };
    let shifted: Vec<P3> = template.iter().map(|p| add(*p, t0)).collect();
    let frame = bbox_frame(&shifted, centroid(&shifted));
    let mut r = solve(&nodes, &edges, target, params, t0, frame)?;
    r.node_indices = node_indices;
    Ok(r)
}

/// Non-rigid ICP on explicit graph nodes and edges (duplicated edges count twice, as in
/// trimesh, which uses every face edge). `frame` defaults to the nodes' centroid and
/// bounding-box diagonal.
///
/// # Errors
/// As [`fit`]; also an edge index out of range or an edge joining a node to itself.
pub fn fit_graph(
    nodes: &[P3],
    edges: &[[usize; 2]],
    target: &[P3],
    params: &NricpParams,
    frame: Option<Frame>,
) -> Result<NricpResult, BaselineError> {
    check_cloud(nodes, Role::Template, 4)?;
    check_cloud(target, Role::Target, 1)?;
    validate(params)?;
    if let Some(e) = edges
        .iter()
        .find(|e| e[0] >= nodes.len() || e[1] >= nodes.len() || e[0] == e[1])
    {
        return Err(BaselineError::Degenerate {
            method: M,
            what: format!("bad edge {:?} for {} nodes", e, nodes.len()),
        });
    }
    let t0 = if params.align_centroids {
        sub(centroid(target), centroid(nodes))
    } else {
        [0.0; 3]
    };
    let frame = match frame {
        Some(f) => {
            check_param(
                "frame.scale",
                f.scale,
                0.0,
                f64::MAX,
                true,
                "a finite value > 0",
            )?;
            Frame {
                centre: add(f.centre, t0),
                scale: f.scale,
            }
        }
        None => {
            let shifted: Vec<P3> = nodes.iter().map(|p| add(*p, t0)).collect();
            bbox_frame(&shifted, centroid(&shifted))
        }
    };
    let mut r = solve(nodes, edges, target, params, t0, frame)?;
    r.node_indices = (0..nodes.len()).collect();
    Ok(r)
}

/// Centre `c`, scale = bounding-box diagonal.
fn bbox_frame(points: &[P3], c: P3) -> Frame {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let d = sub(hi, lo);
    Frame {
        centre: c,
        scale: dot(d, d).sqrt(),
    }
}

/// Symmetrised k-nearest-neighbour graph, each edge once as `[small, large]`, sorted.
pub fn knn_graph(nodes: &[P3], k: usize) -> Vec<[usize; 2]> {
    let tree = KdTree::new(nodes);
    let mut edges = Vec::with_capacity(nodes.len() * k);
    for (i, p) in nodes.iter().enumerate() {
        for (j, _) in tree.k_nearest(p, k + 1) {
            if j != i {
                edges.push([i.min(j), i.max(j)]);
            }
        }
    }
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// A square sparse matrix in compressed-sparse-row form.
#[derive(Clone, Debug)]
pub struct Csr {
    n: usize,
    row_ptr: Vec<usize>,
    cols: Vec<usize>,
    vals: Vec<f64>,
}

impl Csr {
    /// Build from `(row, col, value)` triplets; duplicates are summed.
    pub fn from_triplets(n: usize, mut t: Vec<(usize, usize, f64)>) -> Csr {
        t.sort_unstable_by_key(|a| (a.0, a.1));
        let mut row_ptr = vec![0usize; n + 1];
        let mut cols = Vec::with_capacity(t.len());
        let mut vals: Vec<f64> = Vec::with_capacity(t.len());
        let mut last: Option<(usize, usize)> = None;
        for (r, c, v) in t {
            if last == Some((r, c)) {
                if let Some(x) = vals.last_mut() {
                    *x += v;
                }
                continue;
            }
            last = Some((r, c));
            cols.push(c);
            vals.push(v);
            row_ptr[r + 1] += 1;
        }
        for i in 0..n {
            row_ptr[i + 1] += row_ptr[i];
        }
        Csr {
            n,
            row_ptr,
            cols,
            vals,
        }
    }

    /// `y = A x` for three right-hand sides at once.
    pub fn mul3(&self, x: &[P3], y: &mut [P3]) {
        for (r, yr) in y.iter_mut().enumerate().take(self.n) {
            let mut acc = [0.0; 3];
            for k in self.row_ptr[r]..self.row_ptr[r + 1] {
                let v = self.vals[k];
                let xc = &x[self.cols[k]];
                acc[0] += v * xc[0];
                acc[1] += v * xc[1];
                acc[2] += v * xc[2];
            }
            *yr = acc;
        }
    }

    /// Entry `(r, c)` (0 if absent).
    pub fn get(&self, r: usize, c: usize) -> f64 {
        (self.row_ptr[r]..self.row_ptr[r + 1])
            .find(|&k| self.cols[k] == c)
            .map_or(0.0, |k| self.vals[k])
    }
}

/// Preconditioned conjugate gradients on `A X = B` for three columns, warm-started at `x`.
/// `precond(r, z)` applies the preconditioner. Returns the iterations used, or `Err` with
/// the worst relative residual reached.
pub fn conjugate_gradient(
    a: &Csr,
    b: &[P3],
    x: &mut [P3],
    precond: &dyn Fn(&[P3], &mut [P3]),
    tol: f64,
    max_iter: usize,
) -> Result<usize, f64> {
    let n = b.len();
    let mut r = vec![[0.0; 3]; n];
    a.mul3(x, &mut r);
    for (ri, bi) in r.iter_mut().zip(b) {
        *ri = sub(*bi, *ri);
    }
    let col_norm2 = |v: &[P3]| -> P3 {
        let mut s = [0.0; 3];
        for p in v {
            for c in 0..3 {
                s[c] += p[c] * p[c];
            }
        }
        s
    };
    let bn = col_norm2(b);
    // Columns with b = 0 are solved when r = 0; measure them against 1.
    let target: P3 = [0, 1, 2].map(|c| (tol * tol) * if bn[c] > 0.0 { bn[c] } else { 1.0 });
    let mut z = vec![[0.0; 3]; n];
    precond(&r, &mut z);
    let mut p = z.clone();
    let mut rz = [0.0; 3];
    for (ri, zi) in r.iter().zip(&z) {
        for c in 0..3 {
            rz[c] += ri[c] * zi[c];
        }
    }
    let mut ap = vec![[0.0; 3]; n];
    let mut done = [false; 3];
    for it in 0..=max_iter {
        let rn = col_norm2(&r);
        for c in 0..3 {
            done[c] = done[c] || rn[c] <= target[c];
        }
        if done.iter().all(|&d| d) {
            return Ok(it);
        }
        if it == max_iter {
            let worst = (0..3)
                .map(|c| (rn[c] / target[c]).sqrt() * tol)
                .fold(0.0, f64::max);
            return Err(worst);
        }
        a.mul3(&p, &mut ap);
        let mut pap = [0.0; 3];
        for (pi, api) in p.iter().zip(&ap) {
            for c in 0..3 {
                pap[c] += pi[c] * api[c];
            }
        }
        let mut alpha = [0.0; 3];
        for c in 0..3 {
            if !done[c] && pap[c] > 0.0 {
                alpha[c] = rz[c] / pap[c];
            }
        }
        for i in 0..n {
            for c in 0..3 {
                x[i][c] += alpha[c] * p[i][c];
                r[i][c] -= alpha[c] * ap[i][c];
            }
        }
        precond(&r, &mut z);
        let mut rz_new = [0.0; 3];
        for (ri, zi) in r.iter().zip(&z) {
            for c in 0..3 {
                rz_new[c] += ri[c] * zi[c];
            }
        }
        for c in 0..3 {
            let beta = if rz[c] > 0.0 { rz_new[c] / rz[c] } else { 0.0 };
            for i in 0..n {
                p[i][c] = z[i][c] + beta * p[i][c];
            }
        }
        rz = rz_new;
    }
    Err(f64::INFINITY)
}

/// Invert a symmetric 4×4 matrix (Gauss–Jordan with partial pivoting); `None` if singular.
fn invert4(a: [[f64; 4]; 4]) -> Option<[[f64; 4]; 4]> {
    let mut m = a;
    let mut inv = [[0.0; 4]; 4];
    for (i, row) in inv.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let norm = a.iter().flatten().fold(0.0f64, |s, v| s.max(v.abs()));
    for col in 0..4 {
        let piv = (col..4).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        let p = m[piv][col].abs();
        if p.is_nan() || p <= norm * 1e-14 {
            return None;
        }
        m.swap(col, piv);
        inv.swap(col, piv);
        let d = 1.0 / m[col][col];
        for k in 0..4 {
            m[col][k] *= d;
            inv[col][k] *= d;
        }
        for r in 0..4 {
            if r != col {
                let f = m[r][col];
                if f != 0.0 {
                    for k in 0..4 {
                        m[r][k] -= f * m[col][k];
                        inv[r][k] -= f * inv[col][k];
                    }
                }
            }
        }
    }
    Some(inv)
}

/// The optimisation proper. `nodes` in mm (untranslated); `t0` the initial translation.
fn solve(
    nodes_mm: &[P3],
    edges: &[[usize; 2]],
    target: &[P3],
    params: &NricpParams,
    t0: P3,
    frame: Frame,
) -> Result<NricpResult, BaselineError> {
    if !finite_positive(frame.scale) {
        return Err(BaselineError::Degenerate {
            method: M,
            what: "all template points coincide (zero bounding box)".into(),
        });
    }
    let n = nodes_mm.len();
    let inv_s = 1.0 / frame.scale;
    let nodes: Vec<P3> = nodes_mm
        .iter()
        .map(|p| scale(sub(add(*p, t0), frame.centre), inv_s))
        .collect();
    let target_n: Vec<P3> = target
        .iter()
        .map(|p| scale(sub(*p, frame.centre), inv_s))
        .collect();
    let tree = KdTree::new(&target_n);

    // Weighted graph Laplacian L = MᵀM with incidence weights 1/len.
    let mut lap: Vec<(usize, usize, f64)> = Vec::with_capacity(4 * edges.len());
    let mut len_sum = 0.0;
    for e in edges {
        let len = dist2(nodes[e[0]], nodes[e[1]]).sqrt();
        if !finite_positive(len) {
            return Err(BaselineError::Degenerate {
                method: M,
                what: format!("graph edge {e:?} joins two coincident nodes"),
            });
        }
        len_sum += len;
        let c2 = 1.0 / (len * len);
        lap.push((e[0], e[0], c2));
        lap.push((e[1], e[1], c2));
        lap.push((e[0], e[1], -c2));
        lap.push((e[1], e[0], -c2));
    }
    let lap = Csr::from_triplets(n, lap);
    let unit = match params.stiffness_unit {
        Some(u) => u,
        None if !edges.is_empty() => len_sum / edges.len() as f64,
        None => 1.0,
    };
    let stiffness_used: Vec<f64> = params.stiffness.iter().map(|a| a * unit).collect();
    let g2 = [1.0, 1.0, 1.0, params.gamma * params.gamma];

    // Unknowns: X, 4n rows × 3 columns, identity start.
    let mut x: Vec<P3> = vec![[0.0; 3]; 4 * n];
    for i in 0..n {
        x[4 * i] = [1.0, 0.0, 0.0];
        x[4 * i + 1] = [0.0, 1.0, 0.0];
        x[4 * i + 2] = [0.0, 0.0, 1.0];
    }
    let vt = |i: usize| -> [f64; 4] { [nodes[i][0], nodes[i][1], nodes[i][2], 1.0] };
    let transformed = |x: &[P3], i: usize| -> P3 {
        let v = vt(i);
        let mut o = [0.0; 3];
        for k in 0..4 {
            o = add(o, scale(x[4 * i + k], v[k]));
        }
        o
    };

    let mut total_iterations = 0;
    let mut cg_iterations = Vec::new();
    let mut iterations_per_step = Vec::with_capacity(stiffness_used.len());
    let mut all_converged = true;
    let mut error = f64::NAN;
    let thr2 = params.distance_threshold * params.distance_threshold;
    let mut weights = vec![0.0; n];
    let mut nearest = vec![[0.0; 3]; n];
    for &ws in &stiffness_used {
        let a2 = ws * ws;
        // Stiffness part of the matrix (constant over the step).
        let mut last_error = f32::MAX as f64;
        let mut err = 65504.0; // float16 max, as trimesh
        let mut count = 0;
        while last_error - err > params.eps && count < params.max_iterations_per_step {
            // Correspondences.
            for i in 0..n {
                let t = transformed(&x, i);
                let (j, d2) = tree.nearest(&t).unwrap_or((0, f64::INFINITY));
                nearest[i] = target_n[j];
                weights[i] = if d2 <= thr2 { 1.0 } else { 0.0 };
            }
            // Normal equations: α² L ⊗ G² + blockdiag(w v vᵀ), rhs D ᵀW U.
            let mut trip: Vec<(usize, usize, f64)> =
                Vec::with_capacity(16 * n + 4 * lap.vals.len());
            for r in 0..n {
                for k in lap.row_ptr[r]..lap.row_ptr[r + 1] {
                    let c = lap.cols[k];
                    let v = a2 * lap.vals[k];
                    for (d, g) in g2.iter().enumerate() {
                        trip.push((4 * r + d, 4 * c + d, v * g));
                    }
                }
            }
            let mut rhs = vec![[0.0; 3]; 4 * n];
            for i in 0..n {
                if weights[i] > 0.0 {
                    let v = vt(i);
                    for a in 0..4 {
                        for b in 0..4 {
                            trip.push((4 * i + a, 4 * i + b, weights[i] * v[a] * v[b]));
                        }
                        rhs[4 * i + a] = scale(nearest[i], weights[i] * v[a]);
                    }
                }
            }
            let mat = Csr::from_triplets(4 * n, trip);
            // Block-Jacobi preconditioner (4×4 diagonal blocks).
            let mut blocks = Vec::with_capacity(n);
            for i in 0..n {
                let mut blk = [[0.0; 4]; 4];
                for (a, row) in blk.iter_mut().enumerate() {
                    for (b, v) in row.iter_mut().enumerate() {
                        *v = mat.get(4 * i + a, 4 * i + b);
                    }
                }
                let tr = blk[0][0] + blk[1][1] + blk[2][2] + blk[3][3];
                let inv = invert4(blk).or_else(|| {
                    let mut b2 = blk;
                    for (d, row) in b2.iter_mut().enumerate() {
                        row[d] += 1e-12 * tr.max(1.0);
                    }
                    invert4(b2)
                });
                blocks.push(inv.unwrap_or([[0.0; 4]; 4]));
            }
            let precond = |r: &[P3], z: &mut [P3]| {
                for (i, blk) in blocks.iter().enumerate() {
                    for a in 0..4 {
                        let mut acc = [0.0; 3];
                        for (b, v) in blk[a].iter().enumerate() {
                            acc = add(acc, scale(r[4 * i + b], *v));
                        }
                        z[4 * i + a] = acc;
                    }
                }
            };
            let cg_its = conjugate_gradient(
                &mat,
                &rhs,
                &mut x,
                &precond,
                params.cg_tolerance,
                params.cg_max_iterations,
            )
            .map_err(|worst| BaselineError::Numerical {
                method: M,
                what: format!(
                    "conjugate gradients stopped at relative residual {worst:e} after {} iterations",
                    params.cg_max_iterations
                ),
            })?;
            cg_iterations.push(cg_its);
            if !x.iter().flatten().all(|v| v.is_finite()) {
                return Err(BaselineError::Numerical {
                    method: M,
                    what: "the node transforms became non-finite".into(),
                });
            }
            last_error = err;
            let mut s = 0.0;
            for i in 0..n {
                s += weights[i] * dist2(nearest[i], transformed(&x, i)).sqrt();
            }
            err = s / n as f64;
            count += 1;
        }
        let step_converged =
            count < params.max_iterations_per_step || last_error - err <= params.eps;
        all_converged &= step_converged;
        if !step_converged && params.strict {
            return Err(BaselineError::NotConverged {
                method: M,
                iterations: total_iterations + count,
                last_change: last_error - err,
                tolerance: params.eps,
            });
        }
        total_iterations += count;
        iterations_per_step.push(count);
        error = err;
    }
    let transforms: Vec<[P3; 4]> = (0..n)
        .map(|i| [x[4 * i], x[4 * i + 1], x[4 * i + 2], x[4 * i + 3]])
        .collect();
    Ok(NricpResult {
        initial_translation: t0,
        frame,
        tree: KdTree::new(&nodes),
        nodes,
        node_indices: Vec::new(),
        edges: edges.to_vec(),
        transforms,
        stiffness_used,
        iterations_per_step,
        cg_iterations,
        interp_k: params.interp_k,
        report: FitReport {
            method: M,
            iterations: total_iterations,
            converged: all_converged,
            final_error: error * frame.scale,
        },
    })
}
