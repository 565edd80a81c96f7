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
#[derive(Clone, Debug, PartialEq)]
pub struct Som<const CAP: usize> {
    rows: usize,
    cols: usize,
    nodes: heapless::Vec<Vec3, CAP>,
}

/// Independent running minima of [`Som::bmu`].
const LANES: usize = 4;

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
        let e1 = frame.axes.column(0) * (2.0 * frame.spread[0]);
        let e2 = frame.axes.column(1) * (2.0 * frame.spread[1]);
        let mut nodes = heapless::Vec::new();
        for r in 0..rows {
            for c in 0..cols {
                nodes
                    .push(frame.origin + e1 * span(c, cols) + e2 * span(r, rows))
                    .map_err(|_| Error::Capacity {
                        capacity: CAP as u32,
                    })?;
            }
        }
        Ok(Som { rows, cols, nodes })
    }

    /// Grid position (row, column) of the node nearest to `p`; ties go to the first.
    pub fn bmu(&self, p: &Vec3) -> (usize, usize) {
        // Four running minima (node k in lane k mod 4), so that each distance waits on
        // its lane's last comparison, not on every earlier node's: the first node of the
        // least distance wins either way (each lane keeps its first, then the lowest
        // index among equal lane minima).
        let mut lane = [(f32::INFINITY, 0usize); LANES];
        let chunks = self.nodes.chunks_exact(LANES);
        let rest = chunks.remainder();
        for (c, chunk) in chunks.enumerate() {
            let d: [f32; LANES] = core::array::from_fn(|l| (chunk[l] - p).norm_squared());
            // Indexed, not zipped: the zipped loop measured 10 % slower on the host
            // (whole `register`), its lanes no longer kept in registers.
            #[allow(clippy::needless_range_loop)]
            for l in 0..LANES {
                if d[l] < lane[l].0 {
                    lane[l] = (d[l], c * LANES + l);
                }
            }
        }
        let first = self.nodes.len() - rest.len();
        for (j, w) in rest.iter().enumerate() {
            let d = (w - p).norm_squared();
            if d < lane[j].0 {
                lane[j] = (d, first + j);
            }
        }
        let (mut best_d, mut best) = lane[0];
        for &(d, k) in &lane[1..] {
            if d < best_d || (d == best_d && k < best) {
                (best_d, best) = (d, k);
            }
        }
        (best / self.cols.max(1), best % self.cols.max(1))
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
    pub fn nodes(&self) -> &[Vec3] {
        &self.nodes
    }
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
        for (w, &h) in som.nodes.iter().zip(&self.hit) {
            if h {
                out.push(*w)
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
    /// cloud on every call); returns whether training is finished.
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
            for (row, gr) in som
                .nodes
                .chunks_exact_mut(cols)
                .skip(r0)
                .take(r1 + 1 - r0)
                .zip(&g_row[r0..=r1])
            {
                for (w, gc) in row[c0..=c1].iter_mut().zip(&g_col[c0..=c1]) {
                    *w += (p - *w) * (gr * gc);
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

    /// The four-lane BMU search equals a plain scan of `norm_squared` distances, the
    /// first of equal distances winning (coarse coordinates make ties common).
    #[test]
    fn bmu_equals_a_plain_scan() {
        let mut rng = crate::math::rng::Rng::new(11);
        let coarse = |rng: &mut crate::math::rng::Rng| libm::floorf(rng.next_f32() * 8.0) - 4.0;
        for _ in 0..200 {
            // 48 nodes fill the four lanes evenly, 35 leave a remainder.
            let (rows, cols) = if rng.below(2) == 0 { (6, 8) } else { (5, 7) };
            let mut nodes = heapless::Vec::<Vec3, 64>::new();
            for _ in 0..rows * cols {
                let _ = nodes.push(Vec3::new(
                    coarse(&mut rng),
                    coarse(&mut rng),
                    coarse(&mut rng),
                ));
            }
            let som = Som { rows, cols, nodes };
            for _ in 0..50 {
                let p = Vec3::new(coarse(&mut rng), coarse(&mut rng), coarse(&mut rng) + 0.5);
                let mut best = (f32::INFINITY, 0);
                for (k, w) in som.nodes.iter().enumerate() {
                    let d = (w - p).norm_squared();
                    if d < best.0 {
                        best = (d, k);
                    }
                }
                assert_eq!(som.bmu(&p), (best.1 / cols, best.1 % cols));
            }
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
            let d = crate::math::geom::nearest(&pts, w).unwrap().1.sqrt();
            assert!(d < 3.0, "node {w:?} is {d} mm off the data");
        }
        for corner in [Vec3::new(-100.0, -40.0, 5.0), Vec3::new(100.0, 40.0, 5.0)] {
            let d = crate::math::geom::nearest(a.nodes(), &corner)
                .unwrap()
                .1
                .sqrt();
            assert!(d < 25.0, "corner {corner:?} is {d} mm from the map");
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
