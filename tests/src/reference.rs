//! # f64 reference implementation of the skeleton-graph pipeline
//!
//! A plain `std`, `f64`, allocate-as-you-like rendering of every step of the ribreg
//! pipeline, written from the documented algorithms (paper III and the core's module
//! docs), not from the core's code. It exists to be compared with the `f32`, `no_std`
//! core step by step: where the two agree within a few ulps of `f32` the core's
//! fixed-capacity, single-precision implementation is doing what the documentation says.
//!
//! Independent choices (deliberately different algorithms where the result is defined
//! by the maths alone):
//! - symmetric eigenproblems (principal axes, collinearity test, Horn's 4×4 matrix) are
//!   solved by cyclic Jacobi rotations ([`sym_eigen`]) instead of QR iterations;
//! - rigid fits use Horn's unit-quaternion method ([`kabsch`]), which optimises over
//!   proper rotations only, so the reflection fix of SVD Kabsch is built in;
//! - polynomial least squares is solved by Householder QR of the scaled Vandermonde
//!   matrix ([`Poly::fit`]) instead of Cholesky on the normal equations;
//! - tree paths come from a breadth-first search instead of climbing parent links;
//! - the 8×8 endpoint assignment is an exhaustive enumeration of all 8! permutations;
//! - closest-point metrics are brute force.
//!
//! Where the result depends on a *rule* (sampling sequence, SOM schedule, tie breaks, the
//! endpoint rule, the sign convention of principal axes), the reference follows the rule
//! as documented, so that both implementations see the same decisions on the same data:
//! - [`Rng`]: SplitMix64 and Lemire's multiply-shift `below(n)`, so sample indices agree
//!   bit for bit;
//! - principal axes: decreasing variance; axes 2 and 3 point to the positive third moment,
//!   axis 1 = axis 2 × axis 3; clouds over 1024 points are estimated from a seeded sample;
//! - SOM: geometric decay of σ and lr from start to end over `T − 1` steps, BMU ties to
//!   the first node in row-major order, Gaussian neighbourhood `θ = g(Δr)·g(Δc)` applied
//!   inside the window `|Δr|, |Δc| ≤ ⌈3σ⌉`, linear initialisation over ±2σ of the first
//!   two principal axes (columns along axis 1, rows along axis 2), "live" nodes = nodes
//!   that are the BMU of at least one point (all points up to 1024, or a seeded sample
//!   of 1024);
//! - Prim: from node 0; the next node is the cheapest, ties to the lowest index; a node's
//!   parent is the first tree node (in insertion order) reaching the minimum distance;
//! - hull: gift wrapping from the lowest (then leftmost) point, counter-clockwise, points
//!   on an edge are not vertices, duplicates count once (lowest index);
//! - endpoint rule: median midline, lateral fraction 0.35 of the side's half-width,
//!   leaves ranked by branch length (hull vertex, then lower index, wins a tie), hull
//!   fallback (most lateral first), 4 per side, most cranial (+v) first.
//!
//! Everything is `O(n²)`-or-worse where that is simplest: the inputs are small.

// Index loops read like the maths they implement.
#![allow(clippy::needless_range_loop)]

/// A point or vector, mm.
pub type P3 = [f64; 3];
/// A 2-D point, mm.
pub type P2 = [f64; 2];

// ---------------------------------------------------------------------------------------
// Small vector algebra
// ---------------------------------------------------------------------------------------

/// `a + b`.
pub fn add(a: P3, b: P3) -> P3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `a − b`.
pub fn sub(a: P3, b: P3) -> P3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `s · a`.
pub fn scale(a: P3, s: f64) -> P3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Dot product.
pub fn dot(a: P3, b: P3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product.
pub fn cross(a: P3, b: P3) -> P3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Euclidean norm.
pub fn norm(a: P3) -> f64 {
    dot(a, a).sqrt()
}

/// Squared distance.
pub fn dist2(a: P3, b: P3) -> f64 {
    let d = sub(a, b);
    dot(d, d)
}

/// Distance.
pub fn dist(a: P3, b: P3) -> f64 {
    dist2(a, b).sqrt()
}

/// Mean of a non-empty set.
pub fn mean(points: &[P3]) -> P3 {
    let mut s = [0.0; 3];
    for p in points {
        s = add(s, *p);
    }
    scale(s, 1.0 / points.len().max(1) as f64)
}

/// `M v` for a row-major 3×3 matrix.
pub fn mat_vec(m: &[[f64; 3]; 3], v: P3) -> P3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

/// `A B` for row-major 3×3 matrices.
pub fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}

/// Transpose of a 3×3 matrix.
pub fn transpose(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in m.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            out[j][i] = *v;
        }
    }
    out
}

// ---------------------------------------------------------------------------------------
// Seeded sampling
// ---------------------------------------------------------------------------------------

/// SplitMix64 (Steele, Lea & Flood 2014), written from the published constants.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// Seeded generator.
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }

    /// Next 64 bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Next 32 bits: the high half of the next 64.
    pub fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    /// Uniform index in `0..n` by Lemire's multiply-shift (`(u32 · n) >> 32`).
    pub fn below(&mut self, n: u32) -> u32 {
        let x = u128::from(self.next_u32()) * u128::from(n);
        (x >> 32) as u32
    }

    /// Uniform `f64` in `[0, 1)`, 53 bits.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.unit();
        let u2 = self.unit();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

// ---------------------------------------------------------------------------------------
// Symmetric eigenproblems (cyclic Jacobi)
// ---------------------------------------------------------------------------------------

/// Eigenvalues and eigenvectors of a symmetric `N × N` matrix by cyclic Jacobi rotations.
/// Returns `(values, vectors)` with `vectors[i][k]` the `i`-th component of the `k`-th
/// eigenvector (eigenvectors are columns), unsorted.
pub fn sym_eigen<const N: usize>(mut a: [[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    let mut v = [[0.0; N]; N];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let total: f64 = a.iter().flatten().map(|x| x * x).sum();
    for _sweep in 0..64 {
        let mut off = 0.0;
        for p in 0..N {
            for q in 0..N {
                if p != q {
                    off += a[p][q] * a[p][q];
                }
            }
        }
        if off <= 1e-30 * total || off == 0.0 {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                if a[p][q] == 0.0 {
                    continue;
                }
                // Numerical Recipes 11.1: θ = cot 2φ, t = tan φ (smaller root).
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut() {
                    let (kp, kq) = (row[p], row[q]);
                    row[p] = c * kp - s * kq;
                    row[q] = s * kp + c * kq;
                }
                for k in 0..N {
                    let (pk, qk) = (a[p][k], a[q][k]);
                    a[p][k] = c * pk - s * qk;
                    a[q][k] = s * pk + c * qk;
                }
                for row in v.iter_mut() {
                    let (kp, kq) = (row[p], row[q]);
                    row[p] = c * kp - s * kq;
                    row[q] = s * kp + c * kq;
                }
            }
        }
    }
    let mut values = [0.0; N];
    for (i, val) in values.iter_mut().enumerate() {
        *val = a[i][i];
    }
    (values, v)
}

/// Population covariance (and mean) of a non-empty set.
pub fn covariance(points: &[P3]) -> (P3, [[f64; 3]; 3]) {
    let m = mean(points);
    let mut c = [[0.0; 3]; 3];
    for p in points {
        let d = sub(*p, m);
        for i in 0..3 {
            for j in 0..3 {
                c[i][j] += d[i] * d[j];
            }
        }
    }
    let n = points.len().max(1) as f64;
    for row in c.iter_mut() {
        for v in row.iter_mut() {
            *v /= n;
        }
    }
    (m, c)
}

/// Eigen pairs of a symmetric 3×3 matrix sorted by decreasing eigenvalue: the values and
/// the unit vectors.
pub fn sorted_eigen3(c: [[f64; 3]; 3]) -> ([f64; 3], [P3; 3]) {
    let (val, vec) = sym_eigen(c);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| val[b].total_cmp(&val[a]));
    let vals = order.map(|k| val[k]);
    let vecs = order.map(|k| {
        let v = [vec[0][k], vec[1][k], vec[2][k]];
        scale(v, 1.0 / norm(v))
    });
    (vals, vecs)
}

// ---------------------------------------------------------------------------------------
// Principal axes
// ---------------------------------------------------------------------------------------

/// Clouds above this size are sampled for principal axes (the core's documented 1024).
pub const PCA_SAMPLE: usize = 1024;

/// Principal frame: centroid, unit axes (decreasing spread, right-handed) and the
/// standard deviation along each.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Centroid (of the sample).
    pub origin: P3,
    /// Axes 1, 2, 3 as unit vectors.
    pub axes: [P3; 3],
    /// Standard deviation along each axis.
    pub spread: P3,
}

impl Frame {
    /// Principal axes with the canonical signs (see the module docs); `None` when empty.
    pub fn principal(points: &[P3], seed: u64) -> Option<Frame> {
        if points.is_empty() {
            return None;
        }
        let sample: Vec<P3> = if points.len() <= PCA_SAMPLE {
            points.to_vec()
        } else {
            let mut rng = Rng::new(seed);
            let n = u32::try_from(points.len()).ok()?;
            (0..PCA_SAMPLE)
                .map(|_| points[rng.below(n) as usize])
                .collect()
        };
        let (origin, cov) = covariance(&sample);
        let (vals, mut axes) = sorted_eigen3(cov);
        let spread = vals.map(|v| v.max(0.0).sqrt());
        for k in [1, 2] {
            let skew: f64 = sample
                .iter()
                .map(|p| dot(axes[k], sub(*p, origin)).powi(3))
                .sum();
            if skew < 0.0 {
                axes[k] = scale(axes[k], -1.0);
            }
        }
        axes[0] = cross(axes[1], axes[2]);
        Some(Frame {
            origin,
            axes,
            spread,
        })
    }

    /// Flip axis 1 to `+x` and axis 2 to `+y` of the world frame; axis 3 = 1 × 2.
    pub fn oriented_to_patient(mut self) -> Frame {
        if self.axes[0][0] < 0.0 {
            self.axes[0] = scale(self.axes[0], -1.0);
        }
        if self.axes[1][1] < 0.0 {
            self.axes[1] = scale(self.axes[1], -1.0);
        }
        self.axes[2] = cross(self.axes[0], self.axes[1]);
        self
    }

    /// Coordinates in the frame.
    pub fn local(&self, p: P3) -> P3 {
        let d = sub(p, self.origin);
        [
            dot(self.axes[0], d),
            dot(self.axes[1], d),
            dot(self.axes[2], d),
        ]
    }

    /// World coordinates of frame coordinates.
    pub fn world(&self, q: P3) -> P3 {
        let mut p = self.origin;
        for k in 0..3 {
            p = add(p, scale(self.axes[k], q[k]));
        }
        p
    }
}

// ---------------------------------------------------------------------------------------
// SOM
// ---------------------------------------------------------------------------------------

/// SOM training schedule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SomParams {
    /// Grid rows (along the second principal axis at initialisation).
    pub rows: usize,
    /// Grid columns (along the first principal axis).
    pub cols: usize,
    /// Samples drawn.
    pub iterations: u32,
    /// Learning rate at the first iteration.
    pub lr_start: f64,
    /// Learning rate at the last iteration.
    pub lr_end: f64,
    /// σ at the first iteration (grid units).
    pub radius_start: f64,
    /// σ at the last iteration.
    pub radius_end: f64,
    /// Sampling seed.
    pub seed: u64,
}

/// The paper's SOM 1 schedule as configured in ribreg (20 × 20 grid).
pub const SOM1: SomParams = SomParams {
    rows: 20,
    cols: 20,
    iterations: 6000,
    lr_start: 0.5,
    lr_end: 0.01,
    radius_start: 6.0,
    radius_end: 0.3,
    seed: 0x5EED_0001,
};

/// The SOM 2 schedule (5 × 8 grid).
pub const SOM2: SomParams = SomParams {
    rows: 5,
    cols: 8,
    iterations: 3000,
    lr_start: 0.5,
    lr_end: 0.01,
    radius_start: 3.0,
    radius_end: 0.1,
    seed: 0x5EED_0002,
};

/// Points checked (at most) when finding live nodes.
pub const LIVE_SAMPLES: usize = 1024;

/// A map of `rows × cols` nodes, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Som {
    /// Grid rows.
    pub rows: usize,
    /// Grid columns.
    pub cols: usize,
    /// Nodes, row after row.
    pub nodes: Vec<P3>,
}

impl Som {
    /// Linear initialisation: column `c` at `−1 + 2c/(C−1)` of 2σ₁ along axis 1, row `r`
    /// likewise along axis 2, around the centroid.
    pub fn linear_init(rows: usize, cols: usize, frame: &Frame) -> Som {
        let span = |k: usize, of: usize| {
            if of <= 1 {
                0.0
            } else {
                2.0 * k as f64 / (of - 1) as f64 - 1.0
            }
        };
        let e1 = scale(frame.axes[0], 2.0 * frame.spread[0]);
        let e2 = scale(frame.axes[1], 2.0 * frame.spread[1]);
        let mut nodes = Vec::with_capacity(rows * cols);
        for r in 0..rows {
            for c in 0..cols {
                nodes.push(add(
                    frame.origin,
                    add(scale(e1, span(c, cols)), scale(e2, span(r, rows))),
                ));
            }
        }
        Som { rows, cols, nodes }
    }

    /// Trains from the linear initialisation.
    pub fn train(points: &[P3], rows: usize, cols: usize, frame: &Frame, p: &SomParams) -> Som {
        let mut som = Som::linear_init(rows, cols, frame);
        let mut rng = Rng::new(p.seed);
        let n = points.len() as u32;
        let last = f64::from(p.iterations.saturating_sub(1).max(1));
        for i in 0..p.iterations {
            let t = f64::from(i) / last;
            // σ(t) = σ₀ (σ₁/σ₀)^t, lr(t) likewise.
            let sigma = p.radius_start * (p.radius_end / p.radius_start).powf(t);
            let lr = p.lr_start * (p.lr_end / p.lr_start).powf(t);
            let x = points[rng.below(n) as usize];
            let b = som.bmu(x);
            let (br, bc) = (b / cols, b % cols);
            let reach = (3.0 * sigma).ceil() as usize;
            for r in 0..rows {
                for c in 0..cols {
                    let (dr, dc) = (r.abs_diff(br), c.abs_diff(bc));
                    if dr > reach || dc > reach {
                        continue;
                    }
                    let d2 = (dr * dr + dc * dc) as f64;
                    let theta = (-d2 / (2.0 * sigma * sigma)).exp();
                    let w = &mut som.nodes[r * cols + c];
                    *w = add(*w, scale(sub(x, *w), theta * lr));
                }
            }
        }
        som
    }

    /// Flat index of the node nearest to `x` (first on ties).
    pub fn bmu(&self, x: P3) -> usize {
        let mut best = 0;
        let mut bd = f64::INFINITY;
        for (k, w) in self.nodes.iter().enumerate() {
            let d = dist2(*w, x);
            if d < bd {
                bd = d;
                best = k;
            }
        }
        best
    }

    /// Which nodes are the BMU of at least one point (all points up to 4096, else a
    /// seeded sample of 4096).
    pub fn live_mask(&self, points: &[P3], seed: u64) -> Vec<bool> {
        let mut hit = vec![false; self.nodes.len()];
        if points.len() <= LIVE_SAMPLES {
            for p in points {
                hit[self.bmu(*p)] = true;
            }
        } else {
            let mut rng = Rng::new(seed);
            let n = points.len() as u32;
            for _ in 0..LIVE_SAMPLES {
                hit[self.bmu(points[rng.below(n) as usize])] = true;
            }
        }
        hit
    }

    /// The live nodes, row-major.
    pub fn live_nodes(&self, points: &[P3], seed: u64) -> Vec<P3> {
        let hit = self.live_mask(points, seed);
        self.nodes
            .iter()
            .zip(hit)
            .filter(|(_, h)| *h)
            .map(|(w, _)| *w)
            .collect()
    }
}

// ---------------------------------------------------------------------------------------
// Minimum spanning tree
// ---------------------------------------------------------------------------------------

/// A spanning tree as parent links (node 0 is the root, its own parent) plus adjacency.
#[derive(Clone, Debug, PartialEq)]
pub struct Tree {
    /// Parent of each node.
    pub parent: Vec<usize>,
    /// Neighbours of each node (sorted).
    pub adj: Vec<Vec<usize>>,
}

impl Tree {
    /// From parent links.
    pub fn from_parents(parent: Vec<usize>) -> Tree {
        let n = parent.len();
        let mut adj = vec![Vec::new(); n];
        for (v, &p) in parent.iter().enumerate().skip(1) {
            adj[v].push(p);
            adj[p].push(v);
        }
        for a in &mut adj {
            a.sort_unstable();
        }
        Tree { parent, adj }
    }

    /// Dense Prim from node 0 over Euclidean distances (see the module docs for tie
    /// rules). Empty input → empty tree.
    pub fn prim(points: &[P3]) -> Tree {
        Tree::prim_by(points.len(), |u, v| dist(points[u], points[v]))
    }

    /// Dense Prim from node 0 on the complete graph with symmetric weights `w(u, v)`.
    pub fn prim_by(n: usize, w: impl Fn(usize, usize) -> f64) -> Tree {
        let mut parent = vec![0usize; n];
        let mut key = vec![f64::INFINITY; n];
        let mut in_tree = vec![false; n];
        if n == 0 {
            return Tree::from_parents(parent);
        }
        key[0] = 0.0;
        for _ in 0..n {
            let u = (0..n)
                .filter(|&v| !in_tree[v])
                .min_by(|&a, &b| key[a].total_cmp(&key[b]).then(a.cmp(&b)))
                .expect("a node is left");
            in_tree[u] = true;
            for v in 0..n {
                if !in_tree[v] {
                    let d = w(u, v);
                    if d < key[v] {
                        key[v] = d;
                        parent[v] = u;
                    }
                }
            }
        }
        Tree::from_parents(parent)
    }

    /// Nodes.
    pub fn len(&self) -> usize {
        self.parent.len()
    }

    /// No nodes.
    pub fn is_empty(&self) -> bool {
        self.parent.is_empty()
    }

    /// Edges `(min, max)`, sorted.
    pub fn edges(&self) -> Vec<(usize, usize)> {
        let mut e: Vec<(usize, usize)> = (1..self.len())
            .map(|v| (v.min(self.parent[v]), v.max(self.parent[v])))
            .collect();
        e.sort_unstable();
        e
    }

    /// Total length.
    pub fn weight(&self, points: &[P3]) -> f64 {
        self.edges()
            .iter()
            .map(|&(a, b)| dist(points[a], points[b]))
            .sum()
    }

    /// Degree of each node.
    pub fn degrees(&self) -> Vec<usize> {
        self.adj.iter().map(Vec::len).collect()
    }

    /// The unique path `a → b` (both included), by breadth-first search from `a`.
    pub fn path(&self, a: usize, b: usize) -> Vec<usize> {
        let n = self.len();
        let mut prev = vec![usize::MAX; n];
        let mut queue = std::collections::VecDeque::from([a]);
        prev[a] = a;
        while let Some(u) = queue.pop_front() {
            if u == b {
                break;
            }
            for &w in &self.adj[u] {
                if prev[w] == usize::MAX {
                    prev[w] = u;
                    queue.push_back(w);
                }
            }
        }
        let mut out = vec![b];
        let mut cur = b;
        while cur != a {
            cur = prev[cur];
            out.push(cur);
        }
        out.reverse();
        out
    }

    /// Length from leaf `v` along the tree to the first node whose degree is not 2.
    pub fn branch_length(&self, v: usize, points: &[P3]) -> f64 {
        let deg = self.degrees();
        let mut len = 0.0;
        let (mut prev, mut cur) = (usize::MAX, v);
        while let Some(&next) = self.adj[cur].iter().find(|&&w| w != prev) {
            len += dist(points[cur], points[next]);
            prev = cur;
            cur = next;
            if deg[cur] != 2 {
                break;
            }
        }
        len
    }
}

// ---------------------------------------------------------------------------------------
// Convex hull
// ---------------------------------------------------------------------------------------

/// Gift wrapping: hull vertex indices counter-clockwise from the lowest (then leftmost)
/// point; edge points are not vertices; duplicates count once (lowest index).
pub fn gift_wrap(points: &[P2]) -> Vec<usize> {
    let n = points.len();
    if n == 0 {
        return Vec::new();
    }
    let start = (0..n)
        .min_by(|&a, &b| {
            points[a][1]
                .total_cmp(&points[b][1])
                .then(points[a][0].total_cmp(&points[b][0]))
                .then(a.cmp(&b))
        })
        .expect("non-empty");
    let orient =
        |o: P2, a: P2, b: P2| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let d2 = |a: P2, b: P2| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    let mut hull = vec![start];
    let mut cur = start;
    for _ in 0..=n {
        // The next vertex: no point lies strictly clockwise of cur → next; on a tie the
        // farthest collinear point, then the lowest index.
        let mut next: Option<usize> = None;
        for r in 0..n {
            if points[r] == points[cur] {
                continue;
            }
            next = match next {
                None => Some(r),
                Some(q) => {
                    let o = orient(points[cur], points[q], points[r]);
                    if o < 0.0
                        || (o == 0.0 && d2(points[r], points[cur]) > d2(points[q], points[cur]))
                    {
                        Some(r)
                    } else {
                        Some(q)
                    }
                }
            };
        }
        match next {
            None => return hull,
            Some(q) if points[q] == points[start] => return hull,
            Some(q) => {
                hull.push(q);
                cur = q;
            }
        }
    }
    hull
}

// ---------------------------------------------------------------------------------------
// Errors of the reference pipeline
// ---------------------------------------------------------------------------------------

/// Why a reference step gave no result (mirrors the core's error kinds loosely).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RefError {
    /// Second principal spread below 1 mm.
    Degenerate,
    /// Fewer than 12 live key points.
    TooFewKeyPoints(usize),
    /// A side shows fewer than 4 endpoint candidates.
    Endpoints {
        /// Side 0 or 1.
        side: usize,
        /// Candidates found.
        found: usize,
    },
    /// Labels give a rib other than one endpoint on a side.
    RibOrder {
        /// Side.
        side: usize,
        /// Rib 2..=5.
        rib: u8,
        /// Endpoints carrying its label.
        found: usize,
    },
    /// Fewer than two path points left, or a singular fit.
    RibPath {
        /// Rib 2..=5.
        rib: u8,
        /// Points kept.
        found: usize,
    },
    /// Coincident points in a rigid fit.
    RigidFit,
    /// Label count differs from the point count.
    LabelCount,
}

// ---------------------------------------------------------------------------------------
// Skeleton graph and the endpoint rule
// ---------------------------------------------------------------------------------------

/// Fraction of a side's half-width a leaf must lie from the midline.
pub const LATERAL_FRACTION: f64 = 0.35;
/// Ribs registered.
pub const RIBS: [u8; 4] = [2, 3, 4, 5];
/// Points per rib.
pub const RIB_SAMPLES: [usize; 4] = [6, 6, 8, 10];
/// Paper Eq. 4 threshold, degrees.
pub const TURN_ANGLE_DEG: f64 = 60.0;
/// Paper N_r.
pub const NEIGHBOURS: usize = 10;
/// Collinearity limit of a neighbourhood (σ₂/σ₁).
pub const MIN_CROSS_SPREAD: f64 = 0.15;
/// Fewest live key points accepted.
pub const MIN_KEY_POINTS: usize = 12;
/// Smallest second principal spread of a cloud, mm.
pub const MIN_SPREAD_MM: f64 = 1.0;

/// SOM / MST / hull / endpoints of one cloud.
#[derive(Clone, Debug)]
pub struct Graph {
    /// Live SOM 1 nodes.
    pub som1: Vec<P3>,
    /// Live SOM 2 nodes (key points).
    pub key_points: Vec<P3>,
    /// Prim MST of the key points.
    pub tree: Tree,
    /// Principal frame of the key points (patient-oriented for the template).
    pub frame: Frame,
    /// Key points in the (u, v) plane of the frame.
    pub uv: Vec<P2>,
    /// Hull vertices of `uv`.
    pub hull: Vec<usize>,
    /// Median `u` of the key points (side 0 is `u ≤ midline`).
    pub midline: f64,
    /// The endpoint rule's four endpoints per side, most cranial first, or why it failed
    /// (a labelled template does not need them).
    pub endpoints: Result<[[usize; 4]; 2], RefError>,
}

/// Coordinates of the key points in the first two axes of `frame`.
pub fn project_uv(points: &[P3], frame: &Frame) -> Vec<P2> {
    points
        .iter()
        .map(|p| {
            let q = frame.local(*p);
            [q[0], q[1]]
        })
        .collect()
}

/// Median of the `u` coordinates (mean of the middle two for an even count).
pub fn median_u(uv: &[P2]) -> f64 {
    let n = uv.len();
    if n == 0 {
        return 0.0;
    }
    let mut us: Vec<f64> = uv.iter().map(|q| q[0]).collect();
    us.sort_by(f64::total_cmp);
    if n.is_multiple_of(2) {
        (us[n / 2 - 1] + us[n / 2]) / 2.0
    } else {
        us[n / 2]
    }
}

/// The endpoint rule (see the module docs): four endpoints per side, most cranial first.
pub fn select_endpoints(
    key: &[P3],
    tree: &Tree,
    uv: &[P2],
    hull: &[usize],
) -> Result<[[usize; 4]; 2], RefError> {
    let n = key.len();
    let mid = median_u(uv);
    let lo = uv.iter().map(|q| q[0]).fold(f64::INFINITY, f64::min);
    let hi = uv.iter().map(|q| q[0]).fold(f64::NEG_INFINITY, f64::max);
    let half = [mid - lo, hi - mid];
    let side = |i: usize| usize::from(uv[i][0] > mid);
    let lateral = |i: usize| (uv[i][0] - mid).abs() >= LATERAL_FRACTION * half[side(i)];
    let deg = tree.degrees();
    let mut out = [[0usize; 4]; 2];
    for (s, slot) in out.iter_mut().enumerate() {
        // Leaves: (branch length, on hull, index), longest first, hull wins, lower index.
        let mut leaves: Vec<(f64, bool, usize)> = (0..n)
            .filter(|&i| deg[i] == 1 && side(i) == s && lateral(i))
            .map(|i| (tree.branch_length(i, key), hull.contains(&i), i))
            .collect();
        leaves.sort_by(|a, b| b.0.total_cmp(&a.0).then(b.1.cmp(&a.1)).then(a.2.cmp(&b.2)));
        let mut chosen: Vec<usize> = leaves.iter().take(4).map(|l| l.2).collect();
        if chosen.len() < 4 {
            let mut extra: Vec<(f64, usize)> = hull
                .iter()
                .copied()
                .filter(|&i| side(i) == s && lateral(i) && !chosen.contains(&i))
                .map(|i| ((uv[i][0] - mid).abs(), i))
                .collect();
            extra.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
            for (_, i) in extra {
                if chosen.len() == 4 {
                    break;
                }
                chosen.push(i);
            }
        }
        if chosen.len() < 4 {
            return Err(RefError::Endpoints {
                side: s,
                found: chosen.len(),
            });
        }
        chosen.sort_by(|&a, &b| uv[b][1].total_cmp(&uv[a][1]));
        slot.copy_from_slice(&chosen);
    }
    Ok(out)
}

/// Pipeline parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// SOM 1 schedule.
    pub som1: SomParams,
    /// SOM 2 schedule.
    pub som2: SomParams,
    /// Eq. 4 threshold, degrees.
    pub turn_angle_deg: f64,
    /// N_r.
    pub neighbours: usize,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            som1: SOM1,
            som2: SOM2,
            turn_angle_deg: TURN_ANGLE_DEG,
            neighbours: NEIGHBOURS,
        }
    }
}

impl Graph {
    /// SOM 1 (20 × 20) → live nodes → SOM 2 (5 × 8) → live key points → Prim → frame →
    /// hull → endpoints.
    pub fn build(cloud: &[P3], cfg: &Config, patient_frame: bool) -> Result<Graph, RefError> {
        let frame0 = Frame::principal(cloud, cfg.som1.seed).ok_or(RefError::Degenerate)?;
        if frame0.spread[1].is_nan() || frame0.spread[1] < MIN_SPREAD_MM {
            return Err(RefError::Degenerate);
        }
        let map1 = Som::train(cloud, cfg.som1.rows, cfg.som1.cols, &frame0, &cfg.som1);
        let som1 = map1.live_nodes(cloud, cfg.som1.seed);
        let frame1 = Frame::principal(&som1, cfg.som2.seed).ok_or(RefError::Degenerate)?;
        let map2 = Som::train(&som1, cfg.som2.rows, cfg.som2.cols, &frame1, &cfg.som2);
        let key_points = map2.live_nodes(&som1, cfg.som2.seed);
        Graph::from_key_points(som1, key_points, patient_frame)
    }

    /// The MST / frame / hull / endpoint stage on given key points.
    pub fn from_key_points(
        som1: Vec<P3>,
        key_points: Vec<P3>,
        patient_frame: bool,
    ) -> Result<Graph, RefError> {
        if key_points.len() < MIN_KEY_POINTS {
            return Err(RefError::TooFewKeyPoints(key_points.len()));
        }
        let tree = Tree::prim(&key_points);
        let mut frame = Frame::principal(&key_points, 0).ok_or(RefError::Degenerate)?;
        if patient_frame {
            frame = frame.oriented_to_patient();
        }
        Graph::from_parts(som1, key_points, tree, frame)
    }

    /// Hull and endpoints for a given tree and frame.
    pub fn from_parts(
        som1: Vec<P3>,
        key_points: Vec<P3>,
        tree: Tree,
        frame: Frame,
    ) -> Result<Graph, RefError> {
        let uv = project_uv(&key_points, &frame);
        let hull = gift_wrap(&uv);
        let midline = median_u(&uv);
        let endpoints = select_endpoints(&key_points, &tree, &uv, &hull);
        Ok(Graph {
            som1,
            key_points,
            tree,
            frame,
            uv,
            hull,
            midline,
            endpoints,
        })
    }

    /// Side of key point `k`: 0 at or below the midline, 1 above.
    pub fn side(&self, k: usize) -> usize {
        usize::from(self.uv[k][0] > self.midline)
    }
}

/// Template rib ends `ends[rib][side]` (key-point indices): the endpoint rule's
/// endpoints in both cases.
///
/// Without labels: whose sides are already sorted most cranial first, so rib 2 is the
/// first of each side.
///
/// With labels (one per cloud point; only 2..=5 count): every endpoint takes the label of
/// the nearest labelled cloud point (first on ties); each rib must get exactly one
/// endpoint per side, else [`RefError::RibOrder`] for the first rib (2..5) whose count
/// on that side is not 1.
pub fn template_rib_ends(
    graph: &Graph,
    cloud: &[P3],
    labels: Option<&[u8]>,
) -> Result<[[usize; 2]; 4], RefError> {
    let e = graph.endpoints?;
    let Some(labels) = labels else {
        return Ok(std::array::from_fn(|r| [e[0][r], e[1][r]]));
    };
    if labels.len() != cloud.len() {
        return Err(RefError::LabelCount);
    }
    let labelled: Vec<(P3, u8)> = cloud
        .iter()
        .zip(labels)
        .filter(|(_, l)| RIBS.contains(l))
        .map(|(p, l)| (*p, *l))
        .collect();
    let mut ends = [[0usize; 2]; 4];
    for (s, side) in e.iter().enumerate() {
        let mut count = [0usize; 4];
        for &k in side {
            let p = graph.key_points[k];
            let mut nearest: Option<(f64, u8)> = None;
            for (q, l) in &labelled {
                let d = dist2(*q, p);
                if nearest.is_none_or(|(bd, _)| d < bd) {
                    nearest = Some((d, *l));
                }
            }
            let (_, rib) = nearest.ok_or(RefError::RibOrder {
                side: s,
                rib: RIBS[0],
                found: 0,
            })?;
            let r = usize::from(rib - 2);
            count[r] += 1;
            ends[r][s] = k;
        }
        if let Some(r) = (0..4).find(|&r| count[r] != 1) {
            return Err(RefError::RibOrder {
                side: s,
                rib: RIBS[r],
                found: count[r],
            });
        }
    }
    Ok(ends)
}

// ---------------------------------------------------------------------------------------
// Rigid fit
// ---------------------------------------------------------------------------------------

/// `x ↦ R x + t` (R row-major).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    /// Rotation.
    pub r: [[f64; 3]; 3],
    /// Translation.
    pub t: P3,
}

impl Rigid {
    /// Identity.
    pub fn identity() -> Rigid {
        Rigid {
            r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            t: [0.0; 3],
        }
    }

    /// Apply.
    pub fn apply(&self, p: P3) -> P3 {
        add(mat_vec(&self.r, p), self.t)
    }
}

/// Rotation matrix of a unit quaternion `(w, x, y, z)`.
pub fn quat_to_matrix(q: [f64; 4]) -> [[f64; 3]; 3] {
    let [w, x, y, z] = q;
    [
        [
            w * w + x * x - y * y - z * z,
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            w * w - x * x + y * y - z * z,
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            w * w - x * x - y * y + z * z,
        ],
    ]
}

/// Rotation (axis, angle in radians) as a matrix (Rodrigues).
pub fn axis_angle(axis: P3, angle: f64) -> [[f64; 3]; 3] {
    let a = scale(axis, 1.0 / norm(axis));
    let (s, c) = (0.5 * angle).sin_cos();
    quat_to_matrix([c, a[0] * s, a[1] * s, a[2] * s])
}

/// Least-squares proper rigid transform `b ≈ R a + t` (Horn 1987: `R` from the unit
/// quaternion of the largest eigenvalue of the symmetric 4×4 matrix of the
/// cross-covariance `S = Σ (aᵢ − ā)(bᵢ − b̄)ᵀ`). `None` for empty, unequal or coincident
/// input.
pub fn kabsch(a: &[P3], b: &[P3]) -> Option<Rigid> {
    if a.is_empty() || a.len() != b.len() {
        return None;
    }
    let (ca, cb) = (mean(a), mean(b));
    let mut s = [[0.0; 3]; 3];
    let mut spread = 0.0;
    for (p, q) in a.iter().zip(b) {
        let (da, db) = (sub(*p, ca), sub(*q, cb));
        spread += dot(da, da);
        for i in 0..3 {
            for j in 0..3 {
                s[i][j] += da[i] * db[j];
            }
        }
    }
    if spread.is_nan() || spread <= 0.0 {
        return None;
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let n = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (val, vec) = sym_eigen(n);
    let k = (0..4).max_by(|&i, &j| val[i].total_cmp(&val[j]))?;
    let mut q = [vec[0][k], vec[1][k], vec[2][k], vec[3][k]];
    let qn = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    for v in &mut q {
        *v /= qn;
    }
    let r = quat_to_matrix(q);
    Some(Rigid {
        r,
        t: sub(cb, mat_vec(&r, ca)),
    })
}

/// RMS of `‖R aᵢ + t − bᵢ‖`.
pub fn rmsd(t: &Rigid, a: &[P3], b: &[P3]) -> f64 {
    let s: f64 = a.iter().zip(b).map(|(p, q)| dist2(t.apply(*p), *q)).sum();
    (s / a.len().max(1) as f64).sqrt()
}

// ---------------------------------------------------------------------------------------
// Endpoint matching
// ---------------------------------------------------------------------------------------

/// ICP iterations per coarse start.
pub const COARSE_ITERATIONS: usize = 30;
/// Rounds of the endpoint ICP.
pub const ENDPOINT_ITERATIONS: usize = 10;

/// Result of [`match_endpoints`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EndpointMatch {
    /// Target endpoints as `[rib][side]` key-point indices.
    pub ends: [[usize; 2]; 4],
    /// Final pose target → template.
    pub pose: Rigid,
    /// Best coarse RMS.
    pub coarse_rms: f64,
    /// RMS of the final assignment.
    pub endpoint_rms: f64,
    /// Which of the five starts won.
    pub start: usize,
}

fn nearest_index(set: &[P3], p: P3) -> (usize, f64) {
    let mut best = (0, f64::INFINITY);
    for (j, q) in set.iter().enumerate() {
        let d = dist2(*q, p);
        if d < best.1 {
            best = (j, d);
        }
    }
    best
}

/// Point-to-point ICP, `COARSE_ITERATIONS` rounds of (pair with nearest, refit); returns
/// the pose after the last refit and the RMS of the last pairing.
pub fn icp(src: &[P3], dst: &[P3], mut pose: Rigid) -> Result<(Rigid, f64), RefError> {
    let mut rms = f64::INFINITY;
    for _ in 0..COARSE_ITERATIONS {
        let mut paired = Vec::with_capacity(src.len());
        let mut sum = 0.0;
        for p in src {
            let (j, d2) = nearest_index(dst, pose.apply(*p));
            paired.push(dst[j]);
            sum += d2;
        }
        rms = (sum / src.len() as f64).sqrt();
        pose = kabsch(src, &paired).ok_or(RefError::RigidFit)?;
    }
    Ok((pose, rms))
}

/// The five coarse starts: identity, then the proper rotations taking the source axes
/// `(s₁ e₁, s₂ e₂, s₁e₁ × s₂e₂)` onto the destination axes for
/// `(s₁, s₂) = (+,−), (−,+), (+,+), (−,−)`; each with centroids aligned.
pub fn coarse_starts(src: &Frame, dst: &Frame) -> [Rigid; 5] {
    std::array::from_fn(|start| {
        let r = if start == 0 {
            Rigid::identity().r
        } else {
            let s1 = if start % 2 == 1 { 1.0 } else { -1.0 };
            let s2 = if start == 2 || start == 3 { 1.0 } else { -1.0 };
            let a0 = scale(src.axes[0], s1);
            let a1 = scale(src.axes[1], s2);
            let a = [a0, a1, cross(a0, a1)];
            // R = Σ_k d_k a_kᵀ maps a_k onto d_k.
            let mut r = [[0.0; 3]; 3];
            for k in 0..3 {
                for i in 0..3 {
                    for j in 0..3 {
                        r[i][j] += dst.axes[k][i] * a[k][j];
                    }
                }
            }
            r
        };
        Rigid {
            r,
            t: sub(dst.origin, mat_vec(&r, src.origin)),
        }
    })
}

/// Optimal assignment of an 8×8 cost matrix by enumerating all 8! permutations:
/// `(assign, total)` with `assign[row] = column`.
pub fn best_assignment(cost: &[[f64; 8]; 8]) -> ([usize; 8], f64) {
    fn go(
        cost: &[[f64; 8]; 8],
        row: usize,
        used: &mut [bool; 8],
        cur: &mut [usize; 8],
        acc: f64,
        best: &mut ([usize; 8], f64),
    ) {
        if row == 8 {
            if acc < best.1 {
                *best = (*cur, acc);
            }
            return;
        }
        for col in 0..8 {
            if !used[col] {
                used[col] = true;
                cur[row] = col;
                go(cost, row + 1, used, cur, acc + cost[row][col], best);
                used[col] = false;
            }
        }
    }
    let mut best = ([0; 8], f64::INFINITY);
    go(cost, 0, &mut [false; 8], &mut [0; 8], 0.0, &mut best);
    best
}

/// Matches target endpoints to the template's rib order `ends` (coarse five-start ICP of
/// the key points, then the endpoint ICP with optimal assignment).
pub fn match_endpoints(
    target: &Graph,
    template: &Graph,
    ends: &[[usize; 2]; 4],
) -> Result<EndpointMatch, RefError> {
    let mut best: Option<(Rigid, f64, usize)> = None;
    for (k, init) in coarse_starts(&target.frame, &template.frame)
        .into_iter()
        .enumerate()
    {
        let (pose, rms) = icp(&target.key_points, &template.key_points, init)?;
        if best.is_none_or(|b| rms < b.1) {
            best = Some((pose, rms, k));
        }
    }
    let (mut pose, coarse_rms, start) = best.ok_or(RefError::RigidFit)?;
    let ct: [P3; 8] = std::array::from_fn(|k| template.key_points[ends[k / 2][k % 2]]);
    let found = target.endpoints?;
    let us_idx: [usize; 8] = std::array::from_fn(|i| found[i / 4][i % 4]);
    let us: [P3; 8] = us_idx.map(|i| target.key_points[i]);
    let mut assign = [usize::MAX; 8];
    let mut rms = f64::INFINITY;
    for _ in 0..ENDPOINT_ITERATIONS {
        let moved = us.map(|p| pose.apply(p));
        let cost: [[f64; 8]; 8] =
            std::array::from_fn(|i| std::array::from_fn(|j| dist2(moved[i], ct[j])));
        let (next, total) = best_assignment(&cost);
        rms = (total / 8.0).sqrt();
        if next == assign {
            break;
        }
        assign = next;
        let paired: Vec<P3> = assign.iter().map(|&j| ct[j]).collect();
        pose = kabsch(&us, &paired).ok_or(RefError::RigidFit)?;
    }
    let mut out = [[0usize; 2]; 4];
    for (i, &slot) in assign.iter().enumerate() {
        out[slot / 2][slot % 2] = us_idx[i];
    }
    Ok(EndpointMatch {
        ends: out,
        pose,
        coarse_rms,
        endpoint_rms: rms,
        start,
    })
}

// ---------------------------------------------------------------------------------------
// Rib paths, Eq. 4, fit and resampling
// ---------------------------------------------------------------------------------------

/// Paper Eq. 4: keep the first point; keep the second unless it coincides with the first;
/// keep each later point `p` only if the angle between the last kept segment and the
/// segment from the last kept point to `p` is at most `max_turn_deg` (zero-length
/// segments have no direction: the point is dropped).
pub fn turn_filter(points: &[P3], path: &[usize], max_turn_deg: f64) -> Vec<usize> {
    let mut kept: Vec<usize> = Vec::new();
    for &k in path {
        let p = points[k];
        let keep = match kept.len() {
            0 => true,
            1 => dist2(p, points[kept[0]]) > 0.0,
            m => {
                let a = sub(points[kept[m - 1]], points[kept[m - 2]]);
                let b = sub(p, points[kept[m - 1]]);
                let (na, nb) = (norm(a), norm(b));
                na > 0.0 && nb > 0.0 && {
                    let cos = (dot(a, b) / (na * nb)).clamp(-1.0, 1.0);
                    cos.acos().to_degrees() <= max_turn_deg
                }
            }
        };
        if keep {
            kept.push(k);
        }
    }
    kept
}

/// Least-squares polynomial in the scaled abscissa `s = (x − c)/h ∈ [−1, 1]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Poly {
    /// `c`.
    pub center: f64,
    /// `h`.
    pub half_range: f64,
    /// Coefficients of `s⁰, s¹, …`.
    pub coeffs: Vec<f64>,
}

impl Poly {
    /// Fit of degree `deg` by Householder QR of the scaled Vandermonde matrix. `None`
    /// when there are not more points than the degree or the abscissae coincide.
    pub fn fit(x: &[f64], y: &[f64], deg: usize) -> Option<Poly> {
        let n = x.len();
        if n != y.len() || n <= deg {
            return None;
        }
        let lo = x.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let (center, half_range) = ((lo + hi) / 2.0, (hi - lo) / 2.0);
        if !(half_range > 0.0 && half_range.is_finite()) {
            return None;
        }
        let m = deg + 1;
        // A: n × m, column-major for Householder.
        let mut a: Vec<Vec<f64>> = (0..m)
            .map(|j| {
                x.iter()
                    .map(|&xi| ((xi - center) / half_range).powi(j as i32))
                    .collect()
            })
            .collect();
        let mut rhs = y.to_vec();
        for j in 0..m {
            let alpha = {
                let nrm = a[j][j..].iter().map(|v| v * v).sum::<f64>().sqrt();
                if a[j][j] > 0.0 {
                    -nrm
                } else {
                    nrm
                }
            };
            if alpha == 0.0 {
                return None;
            }
            let mut v: Vec<f64> = a[j][j..].to_vec();
            v[0] -= alpha;
            let vv: f64 = v.iter().map(|t| t * t).sum();
            if vv == 0.0 {
                continue;
            }
            for col in a.iter_mut().skip(j) {
                let f = 2.0 * v.iter().zip(&col[j..]).map(|(p, q)| p * q).sum::<f64>() / vv;
                for (c, vi) in col[j..].iter_mut().zip(&v) {
                    *c -= f * vi;
                }
            }
            let f = 2.0 * v.iter().zip(&rhs[j..]).map(|(p, q)| p * q).sum::<f64>() / vv;
            for (c, vi) in rhs[j..].iter_mut().zip(&v) {
                *c -= f * vi;
            }
        }
        // Back substitution on the m × m upper triangle.
        let mut coeffs = vec![0.0; m];
        for i in (0..m).rev() {
            let s: f64 = (i + 1..m).map(|k| a[k][i] * coeffs[k]).sum();
            if a[i][i].abs() < 1e-12 * a[0][0].abs().max(1e-300) {
                return None;
            }
            coeffs[i] = (rhs[i] - s) / a[i][i];
        }
        Some(Poly {
            center,
            half_range,
            coeffs,
        })
    }

    /// Value at `x` (Horner).
    pub fn eval(&self, x: f64) -> f64 {
        let s = (x - self.center) / self.half_range;
        self.coeffs.iter().rev().fold(0.0, |acc, c| acc * s + c)
    }
}

/// `n` equal steps from `from` to `to`, both included.
pub fn equal_steps(from: f64, to: f64, n: usize) -> Vec<f64> {
    if n == 1 {
        return vec![from];
    }
    (0..n)
        .map(|k| from + (to - from) * k as f64 / (n - 1) as f64)
        .collect()
}

/// The resampled rib points of one cloud.
#[derive(Clone, Debug, PartialEq)]
pub struct RibSkeleton {
    /// 30 points: ribs 2..5 with 6, 6, 8, 10 points, each from side 0 to side 1.
    pub points: Vec<P3>,
    /// Kept key points per rib.
    pub paths: Vec<Vec<usize>>,
    /// Degree fitted per rib.
    pub degree: [usize; 4],
}

/// Paths between each rib's endpoints, Eq. 4, cubic `y(x)`, `z(x)` in the frame, resampled
/// at equal `x` steps from the first to the last kept point.
pub fn rib_skeleton(
    graph: &Graph,
    ends: &[[usize; 2]; 4],
    cfg: &Config,
) -> Result<RibSkeleton, RefError> {
    let max_turn_deg = cfg.turn_angle_deg;
    let mut points = Vec::with_capacity(30);
    let mut paths = Vec::new();
    let mut degree = [0; 4];
    for (r, [a, b]) in ends.iter().enumerate() {
        let path = graph.tree.path(*a, *b);
        let kept = turn_filter(&graph.key_points, &path, max_turn_deg);
        if kept.len() < 2 {
            return Err(RefError::RibPath {
                rib: RIBS[r],
                found: kept.len(),
            });
        }
        let local: Vec<P3> = kept
            .iter()
            .map(|&k| graph.frame.local(graph.key_points[k]))
            .collect();
        let xs: Vec<f64> = local.iter().map(|q| q[0]).collect();
        let ys: Vec<f64> = local.iter().map(|q| q[1]).collect();
        let zs: Vec<f64> = local.iter().map(|q| q[2]).collect();
        let deg = (kept.len() - 1).min(3);
        let err = RefError::RibPath {
            rib: RIBS[r],
            found: kept.len(),
        };
        let fy = Poly::fit(&xs, &ys, deg).ok_or(err)?;
        let fz = Poly::fit(&xs, &zs, deg).ok_or(err)?;
        degree[r] = deg;
        for x in equal_steps(xs[0], xs[xs.len() - 1], RIB_SAMPLES[r]) {
            points.push(graph.frame.world([x, fy.eval(x), fz.eval(x)]));
        }
        paths.push(kept);
    }
    Ok(RibSkeleton {
        points,
        paths,
        degree,
    })
}

// ---------------------------------------------------------------------------------------
// Thin-plate spline
// ---------------------------------------------------------------------------------------

/// The 3-D thin-plate spline through paired points, in `f64` and in the textbook form:
/// `f(p) = a₀ + A p + Σ wᵢ ‖p − sᵢ‖` with `[K P; Pᵀ 0][w; a] = [t; 0]`, solved on the raw
/// coordinates (no centring or scaling) by Gaussian elimination with partial pivoting.
#[derive(Clone, Debug, PartialEq)]
pub struct ThinPlate {
    /// Source points.
    pub source: Vec<P3>,
    /// One row per unknown (weights, then constant and the three linear columns), per
    /// output coordinate.
    pub coef: Vec<P3>,
}

impl ThinPlate {
    /// The spline through `source[i] → target[i]`; `None` if the system is singular.
    pub fn fit(source: &[P3], target: &[P3]) -> Option<ThinPlate> {
        let n = source.len();
        let m = n + 4;
        let mut a = vec![vec![0.0f64; m + 3]; m];
        for i in 0..n {
            for j in 0..n {
                a[i][j] = dist(source[i], source[j]);
            }
            a[i][n] = 1.0;
            a[n][i] = 1.0;
            for k in 0..3 {
                a[i][n + 1 + k] = source[i][k];
                a[n + 1 + k][i] = source[i][k];
                a[i][m + k] = target[i][k];
            }
        }
        for col in 0..m {
            let piv = (col..m).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
            if a[piv][col].abs() < 1e-12 {
                return None;
            }
            a.swap(col, piv);
            for r in col + 1..m {
                let f = a[r][col] / a[col][col];
                for k in col..m + 3 {
                    a[r][k] -= f * a[col][k];
                }
            }
        }
        let mut coef = vec![[0.0; 3]; m];
        for col in (0..m).rev() {
            for k in 0..3 {
                let mut v = a[col][m + k];
                for j in col + 1..m {
                    v -= a[col][j] * coef[j][k];
                }
                coef[col][k] = v / a[col][col];
            }
        }
        Some(ThinPlate {
            source: source.to_vec(),
            coef,
        })
    }

    /// Where the spline takes `p`.
    pub fn apply(&self, p: P3) -> P3 {
        let n = self.source.len();
        let mut out = [0.0; 3];
        for (k, o) in out.iter_mut().enumerate() {
            *o = self.coef[n][k]
                + (0..3).map(|d| self.coef[n + 1 + d][k] * p[d]).sum::<f64>()
                + (0..n)
                    .map(|i| self.coef[i][k] * dist(p, self.source[i]))
                    .sum::<f64>();
        }
        out
    }
}

// ---------------------------------------------------------------------------------------
// Local rigid mapping
// ---------------------------------------------------------------------------------------

/// The mapping of paper Eq. 6 over paired skeleton points.
#[derive(Clone, Debug, PartialEq)]
pub struct LocalRigid {
    /// Template skeleton.
    pub source: Vec<P3>,
    /// Target skeleton.
    pub target: Vec<P3>,
    /// N_r.
    pub neighbours: usize,
}

impl LocalRigid {
    /// New mapping.
    pub fn new(source: Vec<P3>, target: Vec<P3>, neighbours: usize) -> LocalRigid {
        LocalRigid {
            source,
            target,
            neighbours,
        }
    }

    /// True when the set's second principal spread is below 0.15 of its first.
    pub fn collinear(&self, set: &[usize]) -> bool {
        let pts: Vec<P3> = set.iter().map(|&i| self.source[i]).collect();
        let (_, cov) = covariance(&pts);
        let (vals, _) = sorted_eigen3(cov);
        // σ₂/σ₁ < 0.15 ⇔ λ₂ < 0.15² λ₁ (λ the variances).
        vals[1] < MIN_CROSS_SPREAD * MIN_CROSS_SPREAD * vals[0]
    }

    /// The `N_r` nearest source points of `p` (distance, then index), sorted.
    pub fn nearest(&self, p: P3) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.source.len()).collect();
        order.sort_by(|&a, &b| {
            dist2(self.source[a], p)
                .total_cmp(&dist2(self.source[b], p))
                .then(a.cmp(&b))
        });
        let mut set = order[..self.neighbours.min(order.len())].to_vec();
        set.sort_unstable();
        set
    }

    /// `set` widened while collinear: each step adds the source point nearest to the
    /// set's centroid that the set does not hold yet (ties to the lower index), up to all
    /// points. Sorted.
    pub fn widened(&self, set: &[usize]) -> Vec<usize> {
        let mut set = set.to_vec();
        while set.len() < self.source.len() && self.collinear(&set) {
            let c = mean(&set.iter().map(|&i| self.source[i]).collect::<Vec<_>>());
            let next = (0..self.source.len())
                .filter(|i| !set.contains(i))
                .min_by(|&a, &b| {
                    dist2(self.source[a], c)
                        .total_cmp(&dist2(self.source[b], c))
                        .then(a.cmp(&b))
                })
                .expect("a point is left");
            set.push(next);
        }
        set.sort_unstable();
        set
    }

    /// The neighbourhood whose transform maps `p`: its `N_r` nearest, widened.
    pub fn neighbourhood(&self, p: P3) -> Vec<usize> {
        self.widened(&self.nearest(p))
    }

    /// The local transform of `p`.
    pub fn transform(&self, p: P3) -> Option<Rigid> {
        let set = self.neighbourhood(p);
        let a: Vec<P3> = set.iter().map(|&i| self.source[i]).collect();
        let b: Vec<P3> = set.iter().map(|&i| self.target[i]).collect();
        kabsch(&a, &b)
    }

    /// Maps `p`.
    pub fn map(&self, p: P3) -> Option<P3> {
        Some(self.transform(p)?.apply(p))
    }
}

// ---------------------------------------------------------------------------------------
// Metrics
// ---------------------------------------------------------------------------------------

/// Mean, population SD and max of distances.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DistanceStats {
    /// Mean.
    pub mean: f64,
    /// Population SD.
    pub sd: f64,
    /// Max (directed Hausdorff).
    pub max: f64,
}

/// Brute-force distance from each point of `a` to its nearest point of `b`.
pub fn closest_distances(a: &[P3], b: &[P3]) -> Vec<f64> {
    a.iter()
        .map(|p| b.iter().map(|q| dist(*p, *q)).fold(f64::INFINITY, f64::min))
        .collect()
}

/// Statistics of `a → b` closest distances (ED).
pub fn ed(a: &[P3], b: &[P3]) -> DistanceStats {
    let d = closest_distances(a, b);
    if d.is_empty() {
        return DistanceStats::default();
    }
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    let max = d.iter().copied().fold(0.0, f64::max);
    DistanceStats { mean, sd, max }
}

/// Symmetric Hausdorff distance.
pub fn hausdorff(a: &[P3], b: &[P3]) -> f64 {
    ed(a, b).max.max(ed(b, a).max)
}

// ---------------------------------------------------------------------------------------
// Whole pipeline
// ---------------------------------------------------------------------------------------

/// Everything the reference registration computed.
#[derive(Clone, Debug)]
pub struct Registration {
    /// Template graph.
    pub template_graph: Graph,
    /// Template rib order.
    pub template_ends: [[usize; 2]; 4],
    /// Template skeleton.
    pub template_skeleton: RibSkeleton,
    /// Target graph.
    pub target_graph: Graph,
    /// Endpoint matching.
    pub matching: EndpointMatch,
    /// Target skeleton.
    pub target_skeleton: RibSkeleton,
    /// The mapping.
    pub map: LocalRigid,
}

/// Reference registration with explicit parameters.
pub fn register_detailed(
    template: &[P3],
    labels: Option<&[u8]>,
    target: &[P3],
    cfg: &Config,
) -> Result<Registration, RefError> {
    let template_graph = Graph::build(template, cfg, true)?;
    let template_ends = template_rib_ends(&template_graph, template, labels)?;
    let template_skeleton = rib_skeleton(&template_graph, &template_ends, cfg)?;
    let target_graph = Graph::build(target, cfg, false)?;
    let matching = match_endpoints(&target_graph, &template_graph, &template_ends)?;
    let target_skeleton = rib_skeleton(&target_graph, &matching.ends, cfg)?;
    let map = LocalRigid::new(
        template_skeleton.points.clone(),
        target_skeleton.points.clone(),
        cfg.neighbours,
    );
    Ok(Registration {
        template_graph,
        template_ends,
        template_skeleton,
        target_graph,
        matching,
        target_skeleton,
        map,
    })
}

/// Reference registration with the paper's parameters: the template's 30 skeleton points,
/// the target's 30 paired points and the mapping template → target.
#[allow(clippy::type_complexity)]
pub fn register(
    template: &[P3],
    labels: Option<&[u8]>,
    target: &[P3],
) -> Result<(Vec<P3>, Vec<P3>, impl Fn(P3) -> P3), RefError> {
    let reg = register_detailed(template, labels, target, &Config::default())?;
    let map = reg.map;
    let f = move |p: P3| map.map(p).unwrap_or([f64::NAN; 3]);
    Ok((reg.template_skeleton.points, reg.target_skeleton.points, f))
}

// ---------------------------------------------------------------------------------------
// Robotic US: spatial calibration chain and pose interpolation
// ---------------------------------------------------------------------------------------

/// Paper Eq. 1, one frame at a time: pixel `(u, v)` scaled by `(s_x, s_y)` mm/pixel onto
/// the image plane, then image → TCP → flange → base (`b_T_ee · ee_T_tcp · tcp_T_us`).
pub fn pixel_to_base(
    scale_mm: (f64, f64),
    tcp_t_us: &Rigid,
    ee_t_tcp: &Rigid,
    b_t_ee: &Rigid,
    u: f64,
    v: f64,
) -> P3 {
    let image = [u * scale_mm.0, v * scale_mm.1, 0.0];
    b_t_ee.apply(ee_t_tcp.apply(tcp_t_us.apply(image)))
}

/// Spherical linear interpolation of unit quaternions `(w, x, y, z)` along the shorter
/// arc, by the closed form `sin((1−s)θ)/sin θ · q0 + sin(sθ)/sin θ · q1` (linear below
/// 1e-9 rad).
pub fn slerp(q0: [f64; 4], q1: [f64; 4], s: f64) -> [f64; 4] {
    let mut d: f64 = (0..4).map(|i| q0[i] * q1[i]).sum();
    let q1 = if d < 0.0 {
        d = -d;
        q1.map(|v| -v)
    } else {
        q1
    };
    let theta = d.clamp(-1.0, 1.0).acos();
    let (a, b) = if theta < 1e-9 {
        (1.0 - s, s)
    } else {
        (
            ((1.0 - s) * theta).sin() / theta.sin(),
            (s * theta).sin() / theta.sin(),
        )
    };
    let q: [f64; 4] = std::array::from_fn(|i| a * q0[i] + b * q1[i]);
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    q.map(|v| v / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_reconstructs() {
        let a = [
            [4.0, 1.0, -2.0, 0.5],
            [1.0, 3.0, 0.0, 1.0],
            [-2.0, 0.0, 1.0, 0.3],
            [0.5, 1.0, 0.3, -2.0],
        ];
        let (val, vec) = sym_eigen(a);
        for k in 0..4 {
            for i in 0..4 {
                let av: f64 = (0..4).map(|j| a[i][j] * vec[j][k]).sum();
                assert!((av - val[k] * vec[i][k]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn splitmix_reference_values() {
        let mut r = Rng::new(1_234_567);
        assert_eq!(r.next_u64(), 6_457_827_717_110_365_317);
        assert_eq!(r.next_u64(), 3_203_168_211_198_807_973);
    }

    #[test]
    fn horn_recovers_motion_and_refuses_mirrors() {
        let mut rng = Rng::new(3);
        let a: Vec<P3> = (0..12)
            .map(|_| {
                [
                    rng.uniform(-50.0, 50.0),
                    rng.uniform(-30.0, 30.0),
                    rng.uniform(-5.0, 5.0),
                ]
            })
            .collect();
        let r = axis_angle([1.0, -2.0, 0.5], 2.9);
        let t = [10.0, -4.0, 7.0];
        let b: Vec<P3> = a.iter().map(|p| add(mat_vec(&r, *p), t)).collect();
        let f = kabsch(&a, &b).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                assert!((f.r[i][j] - r[i][j]).abs() < 1e-10);
            }
        }
        let m: Vec<P3> = a.iter().map(|p| [p[0], p[1], -p[2]]).collect();
        let f = kabsch(&a, &m).unwrap();
        let det = dot(f.r[0], cross(f.r[1], f.r[2]));
        assert!((det - 1.0).abs() < 1e-10);
    }

    #[test]
    fn qr_fit_exact_cubic() {
        let x: Vec<f64> = (0..9).map(|i| -100.0 + 25.0 * f64::from(i)).collect();
        let f = |x: f64| 1e-4 * x * x * x - 0.02 * x * x + 0.5 * x + 12.0;
        let y: Vec<f64> = x.iter().map(|&v| f(v)).collect();
        let p = Poly::fit(&x, &y, 3).unwrap();
        for &v in &x {
            assert!((p.eval(v) - f(v)).abs() < 1e-9);
        }
    }

    #[test]
    fn assignment_is_optimal() {
        let mut rng = Rng::new(8);
        let cost: [[f64; 8]; 8] = std::array::from_fn(|_| std::array::from_fn(|_| rng.unit()));
        let (a, total) = best_assignment(&cost);
        let mut seen = [false; 8];
        for &c in &a {
            seen[c] = true;
        }
        assert!(seen.iter().all(|&s| s));
        assert!((0..8).map(|i| cost[i][a[i]]).sum::<f64>() - total < 1e-12);
        assert!(total <= (0..8).map(|i| cost[i][i]).sum::<f64>());
    }

    #[test]
    fn path_and_branches() {
        let pts = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 2.0, 0.0],
            [0.0, 0.0, -1.5],
            [0.0, 0.0, -3.0],
        ];
        let t = Tree::prim(&pts);
        assert_eq!(t.degrees(), vec![3, 1, 1, 2, 1]);
        assert_eq!(t.path(4, 2), vec![4, 3, 0, 2]);
        assert!((t.branch_length(4, &pts) - 3.0).abs() < 1e-12);
    }
}
