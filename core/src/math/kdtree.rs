//! Exact nearest-node queries over a small point set (a SOM node set) with a k-d tree
//! that stores nothing but a permutation of the point indices.
//!
//! # Layout
//! The tree over `points` is `order: [u16; CAP]`, a permutation of `0..len`. A range
//! `lo..hi` of more than [`LEAF`] entries is split at `mid = lo + (hi − lo)/2`: `order[mid]`
//! is the median point along the axis of the range's largest extent, `lo..mid` holds the
//! points at or below it on that axis, `mid+1..hi` those at or above; the axis lives in the
//! top two bits of `order[mid]`. Smaller ranges are leaves, scanned in full. 2 bytes a
//! point: 800 B for a 400-node SOM-1 set.
//!
//! # Exactly the brute-force answer
//! [`KdTree::nearest`] returns what [`crate::math::geom::nearest`] returns — the smallest
//! squared distance, ties to the lowest index — restricted to `d² ≤ max_d2`, bit for
//! bit: distances are computed by the same expression, and a subtree is skipped only when
//! the squared distance to its splitting plane exceeds the best so far (rounding is
//! monotonic, so that bound never exceeds a distance it stands for). The tree's shape
//! changes the work, never the answer.
//!
//! # Bounded building
//! [`KdTree::build_some`] splits ranges until about `budget` points were partitioned (a
//! median selection of `m` points costs a few `m` comparisons, about a nearest-node scan
//! of `m` nodes), so the controller builds trees inside its per-call bound.

use crate::error::{Error, Result};
use crate::Vec3;

/// Ranges of at most this many points are leaves.
pub const LEAF: usize = 6;
/// Largest capacity: indices keep 14 bits, the axis 2.
pub const MAX_CAPACITY: usize = 1 << 14;
const INDEX_MASK: u16 = (1 << 14) - 1;
/// Pending ranges of a build: a depth-first build keeps at most one range per level, and
/// `2^14 / LEAF` needs 12 levels.
const PENDING: usize = 16;

/// A k-d tree over at most `CAP` points (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct KdTree<const CAP: usize> {
    order: [u16; CAP],
    len: u16,
    pending: heapless::Vec<(u16, u16), PENDING>,
}

impl<const CAP: usize> Default for KdTree<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAP: usize> KdTree<CAP> {
    const CAPACITY_OK: () = assert!(CAP <= MAX_CAPACITY, "KdTree capacity above 2^14");

    /// A tree over no points.
    pub const fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::CAPACITY_OK;
        KdTree {
            order: [0; CAP],
            len: 0,
            pending: heapless::Vec::new(),
        }
    }

    /// A tree over `points`, built at once.
    pub fn build(points: &[Vec3]) -> Result<Self> {
        let mut tree = Self::new();
        tree.start(points.len())?;
        tree.build_some(points, usize::MAX)?;
        Ok(tree)
    }

    /// Starts a tree over `len` points, to be built by [`KdTree::build_some`].
    pub fn start(&mut self, len: usize) -> Result<()> {
        if len > CAP {
            return Err(Error::Capacity {
                capacity: CAP as u32,
            });
        }
        for (i, o) in self.order.iter_mut().take(len).enumerate() {
            // Note: i < len <= CAP <= 2^14.
            *o = i as u16;
        }
        self.len = len as u16;
        self.pending.clear();
        // Note: the stack is empty, a push cannot fail.
        let _ = self.pending.push((0, self.len));
        Ok(())
    }

    /// Splits pending ranges until about `budget` points were partitioned; `true` when
    /// the tree is complete. `points` must be the `len` points of [`KdTree::start`], at
    /// every call ([`Error::Config`] if their number differs).
    pub fn build_some(&mut self, points: &[Vec3], budget: usize) -> Result<bool> {
        if points.len() != usize::from(self.len) {
            return Err(Error::Config("a k-d tree is built over other points"));
        }
        let mut work = 0usize;
        while let Some((lo, hi)) = self.pending.pop() {
            let (lo, hi) = (usize::from(lo), usize::from(hi));
            if hi - lo > LEAF {
                let range = &mut self.order[lo..hi];
                let (mut min, mut max) =
                    (points[usize::from(range[0])], points[usize::from(range[0])]);
                for &i in range.iter() {
                    min = min.inf(&points[usize::from(i)]);
                    max = max.sup(&points[usize::from(i)]);
                }
                let axis = (max - min).imax();
                let mid = (hi - lo) / 2;
                range.select_nth_unstable_by(mid, |&a, &b| {
                    points[usize::from(a)][axis].total_cmp(&points[usize::from(b)][axis])
                });
                // Note: axis < 3 fits the top two bits.
                range[mid] |= (axis as u16) << 14;
                // Note: depth-first, at most one pending range per level (see PENDING).
                let _ = self.pending.push(((lo + mid + 1) as u16, hi as u16));
                let _ = self.pending.push((lo as u16, (lo + mid) as u16));
                work = work.saturating_add(hi - lo);
                if work >= budget {
                    break;
                }
            }
        }
        Ok(self.pending.is_empty())
    }

    /// True once built over `points.len()` points.
    fn ready(&self, points: &[Vec3]) -> bool {
        self.pending.is_empty() && points.len() == usize::from(self.len)
    }

    /// The point nearest to `q` with `d² ≤ max_d2` (index and `d²`, ties to the lowest
    /// index), exactly as [`crate::math::geom::nearest`] filtered by `max_d2`; `None` when no
    /// point is that near, or when the tree is not built over `points`.
    pub fn nearest(&self, points: &[Vec3], q: &Vec3, max_d2: f32) -> Option<(usize, f32)> {
        if !self.ready(points) {
            return None;
        }
        #[inline(always)]
        fn consider(points: &[Vec3], q: &Vec3, i: usize, best: &mut (f32, usize)) {
            let d2 = (points[i] - q).norm_squared();
            if d2 < best.0 || (d2 == best.0 && i < best.1) {
                *best = (d2, i);
            }
        }
        let mut best = (max_d2, usize::MAX);
        // Depth first, nearer side first, as a recursion would go, without its calls:
        // the farther side of each split waits here with the squared distance from `q`
        // to its splitting plane, and is searched only if that is within the best
        // distance when its turn comes. One range waits per level of the current path,
        // at most 12 for 2^14 points in leaves of `LEAF` (see `PENDING`).
        let mut waiting = [(0u16, 0u16, 0.0f32); PENDING];
        let mut depth = 0usize;
        let (mut lo, mut hi) = (0usize, usize::from(self.len));
        loop {
            if hi - lo > LEAF {
                let mid = lo + (hi - lo) / 2;
                let (i, axis) = (
                    usize::from(self.order[mid] & INDEX_MASK),
                    usize::from(self.order[mid] >> 14),
                );
                consider(points, q, i, &mut best);
                let diff = q[axis] - points[i][axis];
                let (near, far) = if diff < 0.0 {
                    ((lo, mid), (mid + 1, hi))
                } else {
                    ((mid + 1, hi), (lo, mid))
                };
                match waiting.get_mut(depth) {
                    // Note: ranges are under 2^14 (`MAX_CAPACITY`), so they fit a u16.
                    Some(slot) => {
                        *slot = (far.0 as u16, far.1 as u16, diff * diff);
                        depth += 1;
                    }
                    // Deeper than a tree can be; scanning the farther side in full
                    // keeps the answer exact (it does not depend on the visiting order).
                    None => {
                        for &o in &self.order[far.0..far.1] {
                            consider(points, q, usize::from(o & INDEX_MASK), &mut best);
                        }
                    }
                }
                (lo, hi) = near;
                continue;
            }
            for &o in &self.order[lo..hi] {
                consider(points, q, usize::from(o & INDEX_MASK), &mut best);
            }
            // The next waiting range still within the best distance.
            loop {
                let Some(d) = depth.checked_sub(1) else {
                    return (best.1 != usize::MAX).then_some((best.1, best.0));
                };
                depth = d;
                let (l, h, plane_d2) = waiting.get(d).copied().unwrap_or_default();
                if plane_d2 <= best.0 {
                    (lo, hi) = (usize::from(l), usize::from(h));
                    break;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::geom::nearest;
    use crate::math::rng::Rng;

    fn cloud(rng: &mut Rng, n: usize, grid: bool) -> std::vec::Vec<Vec3> {
        (0..n)
            .map(|_| {
                let p = Vec3::new(
                    rng.next_f32() * 200.0,
                    rng.next_f32() * 150.0,
                    rng.next_f32() * 20.0,
                );
                // On a coarse grid, many points share coordinates and distances tie.
                if grid {
                    p.map(|c| libm::roundf(c / 25.0) * 25.0)
                } else {
                    p
                }
            })
            .collect()
    }

    /// Random sets (some on a grid, so coordinates and distances tie), every size from
    /// empty to a few leaves, trees built at once and in small steps: the answer is
    /// brute force's, bit for bit, with and without a radius.
    #[test]
    fn nearest_is_brute_force() {
        let mut rng = Rng::new(7);
        for n in (0..40).chain([123, 400]) {
            for grid in [false, true] {
                let pts = cloud(&mut rng, n, grid);
                let tree = KdTree::<400>::build(&pts).unwrap();
                let mut stepped = KdTree::<400>::new();
                stepped.start(n).unwrap();
                let mut calls = 0;
                while !stepped.build_some(&pts, 20).unwrap() {
                    calls += 1;
                }
                assert_eq!(stepped, tree);
                assert!(n < 100 || calls > 5, "{calls}");
                for q in cloud(&mut rng, 200, grid) {
                    let brute = nearest(&pts, &q);
                    assert_eq!(tree.nearest(&pts, &q, f32::INFINITY), brute);
                    for r2 in [0.0, 100.0, 625.0] {
                        let within = brute.filter(|&(_, d2)| d2 <= r2);
                        assert_eq!(tree.nearest(&pts, &q, r2), within, "{n} {q:?} {r2}");
                    }
                }
            }
        }
    }

    /// Coincident points (no extent on any axis) and a query on one of them.
    #[test]
    fn coincident_points() {
        let pts = [Vec3::new(1.0, 2.0, 3.0); 50];
        let tree = KdTree::<64>::build(&pts).unwrap();
        assert_eq!(tree.nearest(&pts, &pts[0], 0.0), Some((0, 0.0)));
    }

    /// Too many points, or other points than those built over: typed error or `None`.
    #[test]
    fn misuse_is_refused() {
        let pts = [Vec3::zeros(); 9];
        assert_eq!(
            KdTree::<8>::build(&pts),
            Err(Error::Capacity { capacity: 8 })
        );
        let tree = KdTree::<16>::build(&pts).unwrap();
        assert_eq!(tree.nearest(&pts[..8], &Vec3::zeros(), 1.0), None);
        let mut partial = KdTree::<16>::new();
        partial.start(9).unwrap();
        assert_eq!(partial.nearest(&pts, &Vec3::zeros(), 1.0), None);
        assert!(partial.build_some(&pts[..8], 1).is_err());
        assert_eq!(partial.build_some(&pts, 1), Ok(false));
    }
}
