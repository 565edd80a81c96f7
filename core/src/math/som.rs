//! Kohonen self-organising map on a rectangular `R × C` grid (paper Eq. 2).
//!
//! Training, for iteration `i = 0..T`:
//! 1. draw a sample `P(k)` with the seeded [`Rng`] (`k = rng.below(n)`);
//! 2. find the best matching unit (BMU): the node nearest to `P(k)`;
//! 3. update every node within the cut-off of the BMU on the grid:
//!    `W += θ(BMU, i) · lr(i) · (P(k) − W)` with the Gaussian neighbourhood
//!    `θ = exp(−d² / (2σ(i)²))`, `d` the grid distance to the BMU.
//!
//! Radius and learning rate decay geometrically from their start to their end value:
//! `σ(i) = σ₀ (σ₁/σ₀)^(i/(T−1))`, likewise `lr(i)`. Only nodes within `±⌈3σ(i)⌉` rows
//! and columns of the BMU are updated (beyond `3σ`, `θ < 0.012`), so late iterations cost
//! little more than the BMU search.
//! The Gaussian is separable, `θ = g(dr) g(dc)`, so one iteration evaluates `R + C`
//! exponentials instead of `R · C`.
//!
//! Initialisation is linear: nodes spread evenly over `±2σ` of the cloud's first two
//! principal axes (columns along the first), which makes the result independent of how
//! the cloud is posed and needs no random start.

use crate::config::SomConfig;
use crate::error::{Error, Result};
use crate::limits::{LIVE_SAMPLES, MAX_GRID_SIDE};
use crate::math::geom::Frame;
use crate::math::rng::Rng;
use crate::Vec3;

/// A trained (or initialised) map of `rows × cols ≤ CAP` nodes, stored row after row.
///
/// One array per coordinate (12 B a node, as `[Vec3; CAP]`): the BMU scan and the
/// update then read consecutive floats, which the host's compiler turns into SIMD (four
/// nodes an instruction). The Cortex-M4F needs three loads a node where one `vldm` read
/// a `Vec3`; its scan's early exit more than makes up for that ([`Som::bmu`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Som<const CAP: usize> {
    rows: usize,
    cols: usize,
    /// The coordinate (0 x, 1 y, 2 z) along which the map spreads most, where the
    /// one-pass scan looks first ([`Som::bmu`]).
    lead: usize,
    x: [f32; CAP],
    y: [f32; CAP],
    z: [f32; CAP],
}

/// Distances [`Som::bmu`]'s passes test at once for the least one.
const BLOCK: usize = 16;

impl<const CAP: usize> Som<CAP> {
    /// Trains a map on `points` (any non-empty size; nothing is copied) with `frame` the
    /// principal axes of `points` (for the linear initialisation).
    pub fn train(points: &[Vec3], frame: &Frame, cfg: &SomConfig) -> Result<Self> {
        let (mut som, mut trainer) = Self::start(points, frame, cfg)?;
        trainer.run(&mut som, points, u32::MAX);
        Ok(som)
    }

    /// The initialised map and its trainer, to train a bounded number of iterations at a
    /// time ([`SomTrainer::run`]); the result is the same as [`Som::train`]'s.
    pub fn start(points: &[Vec3], frame: &Frame, cfg: &SomConfig) -> Result<(Self, SomTrainer)> {
        cfg.check(CAP)?;
        if points.is_empty() {
            return Err(Error::Config("SOM needs a non-empty cloud"));
        }
        let som = Self::linear_init(frame, cfg.rows, cfg.cols)?;
        Ok((
            som,
            SomTrainer {
                cfg: *cfg,
                rng: Rng::new(cfg.seed),
                done: 0,
            },
        ))
    }

    /// `rows × cols` nodes spread evenly over ±2σ of the first two principal axes.
    pub fn linear_init(frame: &Frame, rows: usize, cols: usize) -> Result<Self> {
        let span = |k: usize, of: usize| {
            if of <= 1 {
                0.0
            } else {
                2.0 * (k as f32 / (of - 1) as f32) - 1.0
            }
        };
        if rows.saturating_mul(cols) > CAP {
            return Err(Error::Capacity {
                capacity: CAP as u32,
            });
        }
        let e1 = frame.axes.column(0) * (2.0 * frame.spread[0]);
        let e2 = frame.axes.column(1) * (2.0 * frame.spread[1]);
        // Each coordinate's variance over the cloud, from its principal axes.
        let variance = |k: usize| {
            (0..3)
                .map(|a| {
                    let v = frame.axes[(k, a)] * frame.spread[a];
                    v * v
                })
                .sum::<f32>()
        };
        let lead = (1..3).fold(0, |best, k| {
            if variance(k) > variance(best) {
                k
            } else {
                best
            }
        });
        let mut som = Som {
            rows,
            cols,
            lead,
            x: [0.0; CAP],
            y: [0.0; CAP],
            z: [0.0; CAP],
        };
        for r in 0..rows {
            for c in 0..cols {
                som.set(
                    r * cols + c,
                    frame.origin + e1 * span(c, cols) + e2 * span(r, rows),
                );
            }
        }
        Ok(som)
    }

    /// Number of nodes, `rows × cols`.
    fn len(&self) -> usize {
        // Note: linear_init checked rows × cols <= CAP.
        self.rows * self.cols
    }

    /// Node `k` (row after row), `k < CAP`.
    fn node(&self, k: usize) -> Vec3 {
        Vec3::new(self.x[k], self.y[k], self.z[k])
    }

    fn set(&mut self, k: usize, w: Vec3) {
        (self.x[k], self.y[k], self.z[k]) = (w.x, w.y, w.z);
    }

    /// Grid position (row, column) of the node nearest to `p`; ties go to the first.
    ///
    /// Two scans give that answer bit for bit (`bmu_equals_a_plain_scan`): the one of
    /// straight passes that a host's SIMD runs fastest, and one pass with an early exit
    /// where every instruction is a scalar one (the Cortex-M4F: the passes cost it 22 %
    /// more instructions for the whole registration).
    pub fn bmu(&self, p: &Vec3) -> (usize, usize) {
        let best = if cfg!(target_arch = "arm") {
            match self.lead {
                0 => self.nearest_by_one_pass::<0>(p),
                1 => self.nearest_by_one_pass::<1>(p),
                _ => self.nearest_by_one_pass::<2>(p),
            }
        } else {
            self.nearest_by_passes(p)
        };
        (best / self.cols.max(1), best % self.cols.max(1))
    }

    /// [`Som::bmu`]'s node in one pass with one running minimum, a node left as soon as
    /// a partial sum of its distance reaches the best: first the square of coordinate
    /// `LEAD` alone, then `dx² + dy²` (unless `LEAD` is z, whose square comes last).
    /// Each is a term or the first terms of the full sum `(dx² + dy²) + dz²`, which
    /// rounding never makes smaller than them, so a node skipped could not have been
    /// strictly nearer (the first of equal distances wins). Most nodes of a map lie far
    /// from a sample along its longest coordinate alone: the controller's registration
    /// took 140.9 M instructions with the exit on x, 147.2 M without (the same exit ran
    /// 4 % slower on x86, its branches mispredicted, hence the passes there). The lead
    /// is the coordinate along which the map spreads most ([`Som::linear_init`]): with x
    /// always first, a robot base turned by 270° against the patient cost 153.0 M, over
    /// the 150 M budget; with the lead, 149.8 M (README, "The robot base anywhere around
    /// the bed").
    fn nearest_by_one_pass<const LEAD: usize>(&self, p: &Vec3) -> usize {
        let n = self.len();
        let (xs, ys, zs) = (&self.x[..n], &self.y[..n], &self.z[..n]);
        let (mut best_d, mut best) = (f32::INFINITY, 0usize);
        for (k, ((&x, &y), &z)) in xs.iter().zip(ys).zip(zs).enumerate() {
            // The terms as `distance_sq` adds them, from the left.
            let square = |a: f32, b: f32| (a - b) * (a - b);
            let lead = match LEAD {
                0 => square(x, p.x),
                1 => square(y, p.y),
                _ => square(z, p.z),
            };
            if lead >= best_d {
                continue;
            }
            let sx = if LEAD == 0 { lead } else { square(x, p.x) };
            let sy = if LEAD == 1 { lead } else { square(y, p.y) };
            let sxy = sx + sy;
            if LEAD != 2 && sxy >= best_d {
                continue;
            }
            let sz = if LEAD == 2 { lead } else { square(z, p.z) };
            let d = sxy + sz;
            if d < best_d {
                (best_d, best) = (d, k);
            }
        }
        best
    }

    /// [`Som::bmu`]'s node in three straight passes: every squared distance, the least
    /// of them, the first node at it. The least is an integer minimum of
    /// [`order_key`]s, which compilers vectorise (a float one they may not reorder).
    fn nearest_by_passes(&self, p: &Vec3) -> usize {
        let n = self.len();
        let mut bits = [0i32; CAP];
        let bits = &mut bits[..n];
        let (xs, ys, zs) = (&self.x[..n], &self.y[..n], &self.z[..n]);
        for (((b, &x), &y), &z) in bits.iter_mut().zip(xs).zip(ys).zip(zs) {
            *b = order_key(distance_sq(x, y, z, p));
        }
        let least = bits.iter().fold(i32::MAX, |m, &b| m.min(b));
        // A NaN is never less than the infinity a scan starts from: then the first node.
        if least > f32::INFINITY.to_bits() as i32 {
            return 0;
        }
        // Sixteen at a time, a block's test one SIMD compare, then the node within it.
        bits.chunks(BLOCK)
            .enumerate()
            .find(|(_, c)| c.iter().fold(false, |hit, &b| hit | (b == least)))
            .and_then(|(k, c)| Some(k * BLOCK + c.iter().position(|&b| b == least)?))
            .unwrap_or(0)
    }

    /// The nodes that are the best matching unit of at least one of `points` (all of
    /// them when at most [`LIVE_SAMPLES`], else a seeded sample of that size), row after
    /// row, into `out`. Nodes that win no point are the "dead units" a grid leaves in the
    /// gaps between separate structures (between two ribs): they lie on no surface.
    pub fn live_nodes<const M: usize>(
        &self,
        points: &[Vec3],
        seed: u64,
        out: &mut heapless::Vec<Vec3, M>,
    ) -> Result<()> {
        let mut scan = LiveScan::<CAP>::new(seed);
        while !scan.step(self, points, u32::MAX) {}
        scan.finish(self, out)
    }

    /// All nodes, row after row.
    pub fn nodes(&self) -> impl Iterator<Item = Vec3> + '_ {
        (0..self.len()).map(|k| self.node(k))
    }
}

/// A squared distance's bits as an integer that orders as the distance does: a sum of
/// squares is +0 or above, where an IEEE float's bits order as its value, or NaN, whose
/// sign bit (set in x86's default NaN) is cleared so that every NaN orders above +∞.
#[inline(always)]
fn order_key(d2: f32) -> i32 {
    // Note: with the sign bit cleared the value is below 2^31, the cast keeps it.
    (d2.to_bits() & 0x7fff_ffff) as i32
}

/// The squared distance from the node at `(x, y, z)` to `p`, `norm_squared`'s term for
/// term: `w − p`, then `dx² + dy² + dz²` from the left.
#[inline(always)]
fn distance_sq(x: f32, y: f32, z: f32, p: &Vec3) -> f32 {
    let (dx, dy, dz) = (x - p.x, y - p.y, z - p.z);
    dx * dx + dy * dy + dz * dz
}

/// [`Som::live_nodes`] in bounded steps: [`LiveScan::step`] finds the best matching
/// unit of at most `budget` points per call (one scan of the map each).
#[derive(Clone, Debug, PartialEq)]
pub struct LiveScan<const CAP: usize> {
    hit: [bool; CAP],
    rng: Rng,
    next: u32,
}

impl<const CAP: usize> LiveScan<CAP> {
    /// Before the first point; `seed` draws the sample of a cloud above [`LIVE_SAMPLES`].
    pub fn new(seed: u64) -> Self {
        LiveScan {
            hit: [false; CAP],
            rng: Rng::new(seed),
            next: 0,
        }
    }

    /// At most `budget` more points; `true` when all are seen. `som` and `points` must be
    /// the same at every call.
    pub fn step(&mut self, som: &Som<CAP>, points: &[Vec3], budget: u32) -> bool {
        let n = points.len();
        let total = n.min(LIVE_SAMPLES);
        let start = self.next as usize;
        let end = start.saturating_add(budget as usize).min(total);
        for k in start..end {
            let p = if n <= LIVE_SAMPLES {
                points[k]
            } else {
                points[self.rng.below(crate::math::geom::sat_u32(n)) as usize]
            };
            let (r, c) = som.bmu(&p);
            if let Some(h) = self.hit.get_mut(r * som.cols + c) {
                *h = true;
            }
        }
        // Note: end <= LIVE_SAMPLES = 1024.
        self.next = end as u32;
        end >= total
    }

    /// The live nodes, row after row, into `out`.
    pub fn finish<const M: usize>(
        &self,
        som: &Som<CAP>,
        out: &mut heapless::Vec<Vec3, M>,
    ) -> Result<()> {
        out.clear();
        for (w, &h) in som.nodes().zip(&self.hit) {
            if h {
                out.push(w)
                    .map_err(|_| Error::Capacity { capacity: M as u32 })?;
            }
        }
        Ok(())
    }
}

/// The state of a map's training between bounded runs (see [`Som::start`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SomTrainer {
    cfg: SomConfig,
    rng: Rng,
    done: u32,
}

impl SomTrainer {
    /// Iterations done so far.
    pub fn done(&self) -> u32 {
        self.done
    }

    /// All iterations done.
    pub fn finished(&self) -> bool {
        self.done >= self.cfg.iterations
    }

    /// Runs at most `budget` more iterations on `som` with samples of `points` (the same
    /// cloud on every call); returns whether training is finished. `som` must be the map
    /// [`Som::start`] returned with this trainer: a map of other dimensions is left as it
    /// is.
    pub fn run<const CAP: usize>(
        &mut self,
        som: &mut Som<CAP>,
        points: &[Vec3],
        budget: u32,
    ) -> bool {
        let cfg = &self.cfg;
        // Note: `start` checked the cloud is non-empty; u32 indexing covers MAX_CLOUD_POINTS.
        let n = points.len().min(u32::MAX as usize) as u32;
        if n == 0 {
            return self.finished();
        }
        let (rows, cols) = (cfg.rows, cfg.cols);
        // With the dimensions `cfg.check` bounded, every node index below is under
        // rows × cols <= CAP and every grid index under MAX_GRID_SIDE.
        if (som.rows, som.cols) != (rows, cols) {
            return self.finished();
        }
        let mut g_row = [0.0f32; MAX_GRID_SIDE];
        let mut g_col = [0.0f32; MAX_GRID_SIDE];
        let mut gauss = [0.0f32; MAX_GRID_SIDE];
        let last = (cfg.iterations - 1).max(1) as f32;
        let radius_ratio = libm::logf(cfg.radius_end / cfg.radius_start);
        let lr_ratio = libm::logf(cfg.lr_end / cfg.lr_start);
        let end = self.done.saturating_add(budget).min(cfg.iterations);
        for i in self.done..end {
            let t = i as f32 / last;
            let sigma = cfg.radius_start * libm::expf(radius_ratio * t);
            let lr = cfg.lr_start * libm::expf(lr_ratio * t);
            let p = points[self.rng.below(n) as usize];
            let (br, bc) = som.bmu(&p);
            let reach = libm::ceilf(3.0 * sigma) as usize;
            let inv = -0.5 / (sigma * sigma);
            let (r0, r1) = (br.saturating_sub(reach), (br + reach).min(rows - 1));
            let (c0, c1) = (bc.saturating_sub(reach), (bc + reach).min(cols - 1));
            // The Gaussian of each grid distance once (rows and columns share them).
            let far = (br - r0).max(r1 - br).max(bc - c0).max(c1 - bc);
            for (d, g) in gauss.iter_mut().enumerate().take(far + 1) {
                let d = d as f32;
                *g = libm::expf(inv * d * d);
            }
            for (r, g) in g_row.iter_mut().enumerate().take(r1 + 1).skip(r0) {
                *g = gauss[r.abs_diff(br)];
            }
            for (c, g) in g_col.iter_mut().enumerate().take(c1 + 1).skip(c0) {
                *g = lr * gauss[c.abs_diff(bc)];
            }
            // `w += (p − w) θ lr` per coordinate, as nalgebra's vector expression did.
            for (r, gr) in (r0..=r1).zip(&g_row[r0..=r1]) {
                let row = r * cols + c0..r * cols + c1 + 1;
                let nodes = som.x[row.clone()]
                    .iter_mut()
                    .zip(&mut som.y[row.clone()])
                    .zip(&mut som.z[row]);
                for (((x, y), z), gc) in nodes.zip(&g_col[c0..c1 + 1]) {
                    let g = gr * gc;
                    *x += (p.x - *x) * g;
                    *y += (p.y - *y) * g;
                    *z += (p.z - *z) * g;
                }
            }
        }
        self.done = end;
        self.finished()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both BMU scans equal a plain scan of `norm_squared` distances, the first of equal
    /// distances winning (coarse coordinates make ties common), and a NaN sample gives
    /// the first node, as that scan does.
    #[test]
    fn bmu_equals_a_plain_scan() {
        let mut rng = crate::math::rng::Rng::new(11);
        let coarse = |rng: &mut crate::math::rng::Rng| libm::floorf(rng.next_f32() * 8.0) - 4.0;
        for _ in 0..200 {
            // 48 nodes fill the passes' blocks of 16 evenly, 35 leave a remainder.
            let (rows, cols) = if rng.below(2) == 0 { (6, 8) } else { (5, 7) };
            let mut som = Som::<64> {
                rows,
                cols,
                lead: 0,
                x: [0.0; 64],
                y: [0.0; 64],
                z: [0.0; 64],
            };
            for k in 0..rows * cols {
                let w = Vec3::new(coarse(&mut rng), coarse(&mut rng), coarse(&mut rng));
                som.set(k, w);
            }
            for _ in 0..50 {
                let p = Vec3::new(coarse(&mut rng), coarse(&mut rng), coarse(&mut rng) + 0.5);
                let mut best = (f32::INFINITY, 0);
                for (k, w) in som.nodes().enumerate() {
                    let d = (w - p).norm_squared();
                    if d < best.0 {
                        best = (d, k);
                    }
                }
                assert_eq!(som.bmu(&p), (best.1 / cols, best.1 % cols));
                assert_eq!(som.nearest_by_one_pass::<0>(&p), best.1);
                assert_eq!(som.nearest_by_one_pass::<1>(&p), best.1);
                assert_eq!(som.nearest_by_one_pass::<2>(&p), best.1);
                assert_eq!(som.nearest_by_passes(&p), best.1);
            }
            // Both signs of NaN (x86's default NaN has the sign bit set).
            for nan in [
                Vec3::new(f32::NAN, 0.0, 0.0),
                Vec3::new(-f32::NAN, 0.0, 0.0),
            ] {
                assert_eq!(som.nearest_by_one_pass::<0>(&nan), 0);
                assert_eq!(som.nearest_by_one_pass::<2>(&nan), 0);
                assert_eq!(som.nearest_by_passes(&nan), 0);
            }
            // One node's distance a NaN made by the FPU (∞ − ∞), the others' ∞: no node
            // is nearer than the scan's start, so the first.
            let mut far = som.clone();
            far.x[5] = f32::INFINITY;
            let inf = Vec3::new(f32::INFINITY, 0.0, 0.0);
            assert_eq!(far.nearest_by_one_pass::<0>(&inf), 0);
            assert_eq!(far.nearest_by_one_pass::<1>(&inf), 0);
            assert_eq!(far.nearest_by_passes(&inf), 0);
        }
    }

    /// A filled 200 × 80 mm sheet sampled every 4 mm.
    fn sheet() -> heapless::Vec<Vec3, 1071> {
        (0..51 * 21)
            .map(|i| {
                Vec3::new(
                    4.0 * (i % 51) as f32 - 100.0,
                    4.0 * (i / 51) as f32 - 40.0,
                    5.0,
                )
            })
            .collect()
    }

    #[test]
    fn same_seed_same_map_and_nodes_land_on_the_data() {
        let pts = sheet();
        let frame = Frame::principal(&pts, 1).unwrap();
        let cfg = SomConfig {
            iterations: 4000,
            ..SomConfig::SOM2
        };
        let a = Som::<40>::train(&pts, &frame, &cfg).unwrap();
        let b = Som::<40>::train(&pts, &frame, &cfg).unwrap();
        assert_eq!(a, b);
        let c = Som::<40>::train(&pts, &frame, &SomConfig { seed: 9, ..cfg }).unwrap();
        assert_ne!(a, c);
        // Every node ends on the sheet, and the map spreads over it: the nodes cover
        // its corners to within a grid cell of the 5 × 8 map (25 × 20 mm).
        for w in a.nodes() {
            let d = crate::math::geom::nearest(&pts, &w).unwrap().1.sqrt();
            assert!(d < 3.0, "node {w:?} is {d} mm off the data");
        }
        for corner in [Vec3::new(-100.0, -40.0, 5.0), Vec3::new(100.0, 40.0, 5.0)] {
            let nodes: heapless::Vec<Vec3, 40> = a.nodes().collect();
            let d = crate::math::geom::nearest(&nodes, &corner)
                .unwrap()
                .1
                .sqrt();
            assert!(d < 25.0, "corner {corner:?} is {d} mm from the map");
        }
    }

    /// A trainer run on a map of other dimensions than its own leaves it as it is (and
    /// does not index past it).
    #[test]
    fn a_trainer_leaves_a_map_of_other_dimensions_alone() {
        let pts = sheet();
        let frame = Frame::principal(&pts, 1).unwrap();
        let (_, mut trainer) = Som::<400>::start(&pts, &frame, &SomConfig::SOM2).unwrap();
        for (rows, cols) in [(20, 20), (1, 40), (8, 5)] {
            let mut other = Som::<400>::linear_init(&frame, rows, cols).unwrap();
            let before = other.clone();
            trainer.run(&mut other, &pts, 100);
            assert_eq!(other, before);
        }
    }

    #[test]
    fn rejects_bad_schedules() {
        let pts = sheet();
        let frame = Frame::principal(&pts, 1).unwrap();
        let bad = SomConfig {
            iterations: 0,
            ..SomConfig::SOM2
        };
        assert!(matches!(
            Som::<40>::train(&pts, &frame, &bad),
            Err(Error::Config(_))
        ));
        let bad = SomConfig {
            lr_start: f32::NAN,
            ..SomConfig::SOM2
        };
        assert!(matches!(
            Som::<40>::train(&pts, &frame, &bad),
            Err(Error::Config(_))
        ));
        assert!(matches!(
            Som::<40>::train(&[], &frame, &SomConfig::SOM2),
            Err(Error::Config(_))
        ));
    }
}
