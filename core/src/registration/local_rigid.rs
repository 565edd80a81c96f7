//! Skeleton-graph non-rigid mapping (paper Eq. 6): every point is moved by the rigid
//! transform that best maps its `N_r` nearest template skeleton points onto their paired
//! target skeleton points.
//!
//! # Collinear neighbourhoods
//! Ten nearest points that lie almost on one line fix the rotation about that line only
//! weakly, and noise then turns it wildly. The rule: the neighbourhood's spread across
//! its main direction (standard deviation along its second principal axis) must be at
//! least [`MIN_CROSS_SPREAD`] of the spread along it; while it is not, the neighbourhood
//! is widened by the skeleton point nearest to its centroid that it does not hold yet (up
//! to all 30, whose spread always covers several ribs). The result is always a well-posed
//! Kabsch problem, and it depends on the N_r-set alone.
//!
//! # Transform reuse
//! A neighbourhood is a 30-bit set of skeleton indices. Points with the same N_r-set
//! share one transform (widening depends on the set only): it is fitted once and kept in
//! a [`TransformCache`] (open addressing, fixed capacity). When the cache is full it is
//! emptied and starts over with the new transform ([`TransformCache::restarts`] counts
//! it): points close together share sets, so the recent sets are the ones worth keeping
//! (the controller's carried SOM nodes, in grid order, with a 64-entry cache: 43.4 M
//! instructions when a full cache kept nothing new, 32.7 M when it starts over). The
//! transform of a set does not depend on the cache, so neither does any result.

use crate::error::{Cloud, Error, Result};
use crate::limits::SKELETON_POINTS;
use crate::math::geom::{validate, Rigid};
use crate::math::kabsch;
use crate::Vec3;
use nalgebra::{Matrix3, SymmetricEigen};

/// Smallest accepted ratio (second / first principal spread) of a neighbourhood.
pub const MIN_CROSS_SPREAD: f32 = 0.15;

/// Fixed-capacity map from neighbourhood bit set to its fitted transform.
#[derive(Clone)]
pub struct TransformCache<const CAP: usize> {
    /// Neighbourhood → (transform, widened neighbourhood).
    map: heapless::index_map::FnvIndexMap<u32, (Rigid, u32), CAP>,
    /// Transforms looked up and found.
    pub hits: u32,
    /// Transforms fitted.
    pub fits: u32,
    /// Times the cache was full and started over.
    pub restarts: u32,
}

impl<const CAP: usize> Default for TransformCache<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAP: usize> TransformCache<CAP> {
    /// An empty cache.
    pub const fn new() -> Self {
        TransformCache {
            map: heapless::index_map::FnvIndexMap::new(),
            hits: 0,
            fits: 0,
            restarts: 0,
        }
    }

    /// The kept transform of neighbourhood `key` and the widened set it was fitted on
    /// (a hit is counted).
    pub fn get(&mut self, key: u32) -> Option<(Rigid, u32)> {
        let found = self.map.get(&key).copied();
        if found.is_some() {
            self.hits += 1;
        }
        found
    }

    /// Keeps the freshly fitted transform `t` of neighbourhood `key` (widened to `mask`),
    /// counted in [`TransformCache::fits`]; a full cache starts over (module docs).
    pub fn keep(&mut self, key: u32, t: Rigid, mask: u32) {
        self.fits += 1;
        if self.map.insert(key, (t, mask)).is_err() {
            self.restarts += 1;
            self.map.clear();
            // Note: the map was just emptied; a capacity-0 cache keeps nothing.
            let _ = self.map.insert(key, (t, mask));
        }
    }

    /// Distinct neighbourhoods kept.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// True when nothing is kept.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

/// A neighbourhood being widened for [`LocalRigid::transform_step`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lookup {
    /// The point's `N_r`-set (the cache key).
    key: u32,
    /// Widened so far.
    mask: u32,
    /// `mask` is final: the next step fits it.
    ready: bool,
}

/// The 30 paired skeleton points and the mapping they define.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalRigid {
    source: [Vec3; SKELETON_POINTS],
    target: [Vec3; SKELETON_POINTS],
    neighbours: usize,
}

impl LocalRigid {
    /// Mapping from `source` (template skeleton) to `target` (target skeleton), `N_r =
    /// neighbours` (3..=30).
    pub fn new(
        source: [Vec3; SKELETON_POINTS],
        target: [Vec3; SKELETON_POINTS],
        neighbours: usize,
    ) -> Result<Self> {
        if !(3..=SKELETON_POINTS).contains(&neighbours) {
            return Err(Error::Config("N_r must be in 3..=30"));
        }
        Ok(LocalRigid {
            source,
            target,
            neighbours,
        })
    }

    /// The `N_r` nearest source skeleton points of `p`, as a bit set.
    pub fn neighbourhood(&self, p: &Vec3) -> u32 {
        nearest_set(&self.source, p, self.neighbours, 0)
    }

    /// `mask` widened until it is not collinear (see the module docs).
    pub fn widened(&self, mut mask: u32) -> u32 {
        while let Some(wider) = self.widen_once(mask) {
            mask = wider;
        }
        mask
    }

    /// `mask` with the next skeleton point added, or `None` when it is final (not
    /// collinear, or all 30 points).
    pub fn widen_once(&self, mask: u32) -> Option<u32> {
        if mask.count_ones() >= SKELETON_POINTS as u32 || !self.collinear(mask) {
            return None;
        }
        let mut sum = Vec3::zeros();
        for i in bits(mask) {
            sum += self.source[i];
        }
        let centroid = sum / mask.count_ones() as f32;
        Some(nearest_set(&self.source, &centroid, 1, mask))
    }

    fn collinear(&self, mask: u32) -> bool {
        let mut sum = Vec3::zeros();
        let mut n = 0.0;
        for i in bits(mask) {
            sum += self.source[i];
            n += 1.0;
        }
        let mean = sum / n;
        let mut cov = Matrix3::zeros();
        for i in bits(mask) {
            let d = self.source[i] - mean;
            cov += d * d.transpose();
        }
        let mut ev = SymmetricEigen::new(cov / n).eigenvalues;
        ev.as_mut_slice().sort_unstable_by(|a, b| b.total_cmp(a));
        // Compare variances: (σ2/σ1)² < ratio².
        ev[1] < MIN_CROSS_SPREAD * MIN_CROSS_SPREAD * ev[0]
    }

    /// The transform that maps `p` and the RMS residual of its fit over its (widened)
    /// neighbourhood, mm: how far the skeleton around `p` is from moving rigidly, a
    /// quality figure for a mapped waypoint (lower is better).
    pub fn transform_with_residual(&self, p: &Vec3) -> Result<(Rigid, f32)> {
        let mask = self.widened(self.neighbourhood(p));
        let t = self.fit(mask)?;
        Ok((t, self.residual(&t, mask)))
    }

    /// RMS distance, mm, between the target points of `mask` and its source points moved
    /// by `t` ([`LocalRigid::transform_with_residual`]).
    pub fn residual(&self, t: &Rigid, mask: u32) -> f32 {
        let mut sum = 0.0;
        for i in bits(mask) {
            sum += (t.apply(&self.source[i]) - self.target[i]).norm_squared();
        }
        libm::sqrtf(sum / mask.count_ones().max(1) as f32)
    }

    /// Fits the rigid transform of a neighbourhood.
    pub fn fit(&self, mask: u32) -> Result<Rigid> {
        let mut a = heapless::Vec::<Vec3, SKELETON_POINTS>::new();
        let mut b = heapless::Vec::<Vec3, SKELETON_POINTS>::new();
        for i in bits(mask) {
            // Note: at most 30 bits are set, the capacity.
            let _ = a.push(self.source[i]);
            let _ = b.push(self.target[i]);
        }
        kabsch::fit(&a, &b)
    }

    /// The transform for `p`, from the cache when its neighbourhood was seen before.
    pub fn transform_for<const CAP: usize>(
        &self,
        p: &Vec3,
        cache: &mut TransformCache<CAP>,
    ) -> Result<Rigid> {
        let mut lookup = None;
        loop {
            if let Some((t, _)) = self.transform_step(p, &mut lookup, cache, u32::MAX)? {
                return Ok(t);
            }
        }
    }

    /// [`LocalRigid::transform_for`] in bounded steps, for the controller: each call
    /// either finds the transform in the cache, or widens the neighbourhood by at most
    /// `widenings` points (a widening costs about a symmetric 3×3 eigen-decomposition),
    /// or fits it (an `f64` Kabsch). `lookup` carries the neighbourhood between the calls
    /// for one point: start with `None` and pass the same `p` until the transform comes
    /// back with its final neighbourhood (for [`LocalRigid::residual`]); `lookup` is then
    /// `None` again. The result equals [`LocalRigid::transform_for`]'s.
    pub fn transform_step<const CAP: usize>(
        &self,
        p: &Vec3,
        lookup: &mut Option<Lookup>,
        cache: &mut TransformCache<CAP>,
        widenings: u32,
    ) -> Result<Option<(Rigid, u32)>> {
        let mut l = match *lookup {
            Some(l) => l,
            None => {
                let key = self.neighbourhood(p);
                if let Some(found) = cache.get(key) {
                    return Ok(Some(found));
                }
                Lookup {
                    key,
                    mask: key,
                    ready: false,
                }
            }
        };
        if l.ready {
            *lookup = None;
            let t = self.fit(l.mask)?;
            cache.keep(l.key, t, l.mask);
            return Ok(Some((t, l.mask)));
        }
        for _ in 0..widenings.max(1) {
            match self.widen_once(l.mask) {
                Some(wider) => l.mask = wider,
                None => {
                    l.ready = true;
                    break;
                }
            }
        }
        *lookup = Some(l);
        Ok(None)
    }

    /// Maps one point. A point with a NaN, infinite or out-of-range coordinate is
    /// refused (index 0 in the error; [`LocalRigid::map_in_place`] names the index).
    pub fn map_point<const CAP: usize>(
        &self,
        p: &Vec3,
        cache: &mut TransformCache<CAP>,
    ) -> Result<Vec3> {
        validate(core::slice::from_ref(p), Cloud::Query, 1, 1)?;
        Ok(self.transform_for(p, cache)?.apply(p))
    }

    /// Maps points in place (any number: nothing is buffered). All points are checked
    /// first, so on bad input nothing is changed.
    pub fn map_in_place<const CAP: usize>(
        &self,
        points: &mut [Vec3],
        cache: &mut TransformCache<CAP>,
    ) -> Result<()> {
        validate(points, Cloud::Query, 0, usize::MAX)?;
        for p in points {
            *p = self.transform_for(p, cache)?.apply(p);
        }
        Ok(())
    }

    /// Template skeleton points.
    pub fn source(&self) -> &[Vec3; SKELETON_POINTS] {
        &self.source
    }

    /// Target skeleton points.
    pub fn target(&self) -> &[Vec3; SKELETON_POINTS] {
        &self.target
    }
}

/// `extra` more indices of `points` nearest to `p` (ties to the lower index) added to `have`.
fn nearest_set(points: &[Vec3; SKELETON_POINTS], p: &Vec3, extra: usize, have: u32) -> u32 {
    // The order (distance by `f32::total_cmp`, then index) as one integer key: the
    // distance's bits mapped as `total_cmp` orders them, above the index.
    let mut order: [u64; SKELETON_POINTS] = core::array::from_fn(|i| {
        let bits = (points[i] - p).norm_squared().to_bits();
        let key = if bits >> 31 == 1 {
            !bits
        } else {
            bits | 1 << 31
        };
        (u64::from(key) << 8) | i as u64
    });
    // A full sort of 30, not `extra` minimum searches: the searches are faster on the
    // host but slower on the Cortex-M4F, where they pushed a control-loop turn from
    // 139 k to 178 k instructions (budget 168 k). The integer keys sort in a quarter of
    // the instructions of the pairs compared by a closure (callgrind, one host
    // `register`: 18.2 M → 5.0 M).
    order.sort_unstable();
    let mut mask = have;
    for i in order
        .iter()
        .map(|&k| (k & 0xff) as u32)
        .filter(|i| have & (1 << i) == 0)
        .take(extra)
    {
        mask |= 1 << i;
    }
    mask
}

fn bits(mask: u32) -> impl Iterator<Item = usize> {
    (0..32).filter(move |i| mask & (1 << i) != 0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::NEIGHBOURS;
    use crate::limits::CACHE_CAPACITY;
    use nalgebra::Rotation3;

    /// The selection equals the first `extra` eligible points of a full sort in the
    /// order (distance, index), ties and all.
    #[test]
    fn nearest_set_is_the_sorted_prefix() {
        let mut rng = crate::math::rng::Rng::new(7);
        for case in 0..500 {
            let points: [Vec3; SKELETON_POINTS] = core::array::from_fn(|_| {
                // Coarse coordinates make equal distances (ties) common.
                Vec3::new(
                    rng.below(5) as f32,
                    rng.below(5) as f32,
                    rng.below(3) as f32,
                )
            });
            let p = Vec3::new(rng.below(5) as f32, 1.0, 0.0);
            let have = if case % 3 == 0 { rng.below(1 << 20) } else { 0 };
            let extra = rng.below(31) as usize;
            let mut order: Vec<(f32, usize)> = (0..SKELETON_POINTS)
                .map(|i| ((points[i] - p).norm_squared(), i))
                .collect();
            order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let mut expect = have;
            for (_, i) in order
                .iter()
                .filter(|(_, i)| have & (1 << i) == 0)
                .take(extra)
            {
                expect |= 1 << i;
            }
            assert_eq!(nearest_set(&points, &p, extra, have), expect, "case {case}");
        }
    }

    use crate::math::curved_skeleton as skeleton;

    #[test]
    fn rigid_motion_of_the_skeleton_moves_every_point_rigidly() {
        let src = skeleton();
        let rot = Rotation3::from_euler_angles(0.2, -0.3, 0.4);
        let t = Vec3::new(5.0, -7.0, 30.0);
        let dst = src.map(|p| rot * p + t);
        let map = LocalRigid::new(src, dst, NEIGHBOURS).unwrap();
        let mut cache = TransformCache::<CACHE_CAPACITY>::new();
        for i in 0..200 {
            let p = Vec3::new(i as f32 - 100.0, -(i % 90) as f32, (i % 7) as f32);
            let q = map.map_point(&p, &mut cache).unwrap();
            assert!((q - (rot * p + t)).norm() < 1e-3);
        }
        assert!(cache.hits > 0 && cache.fits as usize == cache.len());
        assert_eq!(cache.hits + cache.fits, 200);
    }

    #[test]
    fn collinear_neighbourhoods_are_widened() {
        // Rib 5 is a straight line of 10 points far from the others.
        let mut src = skeleton();
        for (j, p) in src[20..].iter_mut().enumerate() {
            *p = Vec3::new(-100.0 + 20.0 * j as f32, -400.0, 0.0);
        }
        let map = LocalRigid::new(src, src, NEIGHBOURS).unwrap();
        let mask = map.neighbourhood(&Vec3::new(0.0, -400.0, 0.0));
        assert_eq!(mask, 0x3FF << 20, "the 10 points of the straight rib");
        let wide = map.widened(mask);
        assert!(wide.count_ones() > NEIGHBOURS as u32 && wide & mask == mask);
        assert!(!map.collinear(wide));
        // An ordinary neighbourhood is not widened.
        let ordinary = map.neighbourhood(&Vec3::new(0.0, -30.0, 0.0));
        assert_eq!(map.widened(ordinary), ordinary);
    }

    /// The bounded lookup gives `transform_for`'s transform and
    /// `transform_with_residual`'s residual, one widening per call, a fit in a call of
    /// its own, and a cache hit at once.
    #[test]
    fn transform_steps_equal_the_direct_lookup() {
        let src = skeleton();
        let dst = src.map(|p| p + Vec3::new(0.01 * p.y, 2.0, -1.0));
        let map = LocalRigid::new(src, dst, NEIGHBOURS).unwrap();
        // A point by the straight rib needs widening, one by a curved rib may not.
        for p in [Vec3::new(0.0, -400.0, 0.0), Vec3::new(0.0, -30.0, 0.0)] {
            let mut cache = TransformCache::<4>::new();
            let (mut lookup, mut calls) = (None, 0);
            let (t, mask) = loop {
                calls += 1;
                if let Some(found) = map.transform_step(&p, &mut lookup, &mut cache, 1).unwrap() {
                    break found;
                }
            };
            let (direct, residual) = map.transform_with_residual(&p).unwrap();
            assert_eq!(t, direct);
            assert_eq!(map.residual(&t, mask), residual);
            let widenings = (mask.count_ones() - map.neighbourhood(&p).count_ones()) as usize;
            assert_eq!(calls, widenings + 2, "{p}");
            assert_eq!(lookup, None);
            // Now cached: one call, same transform and neighbourhood.
            let again = map.transform_step(&p, &mut lookup, &mut cache, 1).unwrap();
            assert_eq!(again, Some((t, mask)));
            assert_eq!((cache.fits, cache.hits), (1, 1));
        }
    }

    #[test]
    fn full_cache_starts_over_and_counts() {
        let src = skeleton();
        let map = LocalRigid::new(src, src, NEIGHBOURS).unwrap();
        let mut cache = TransformCache::<2>::new();
        for i in 0..50 {
            let p = Vec3::new(4.0 * i as f32 - 100.0, -2.0 * i as f32, 0.0);
            assert!((map.map_point(&p, &mut cache).unwrap() - p).norm() < 1e-3);
        }
        assert!(cache.len() <= 2);
        assert!(cache.restarts > 0);
        assert_eq!(cache.fits + cache.hits, 50);
        assert!(LocalRigid::new(src, src, 2).is_err());
    }
}
