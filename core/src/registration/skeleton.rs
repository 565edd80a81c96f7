//! Skeleton graph of one rib-cartilage cloud (paper III-C) and the 30 paired rib points.
//!
//! [`SkeletonGraph::build`]: SOM 1 (20 × 20) unifies the cloud to 400 points, SOM 2
//! (5 × 8) reduces those to 40 key points, Prim's MST connects them, and the endpoint
//! rule below picks the 8 rib endpoints. [`RibSkeleton::build`] then walks the tree path
//! between each rib's two endpoints, keeps points by the turn-angle rule (Eq. 4), fits
//! cubics and resamples them (Eq. 5).
//!
//! # Endpoint rule
//! The paper takes "the key points forming the convex hull" as the eight endpoints but a
//! hull may have more or fewer than eight vertices, and some vertices (the top and bottom
//! of the sternum) are not rib ends. We use, in the coronal plane of the key points (first
//! two principal axes `u`, `v`; `u` lateral):
//! 1. the midline is the median `u` of the key points; side 0 is `u` below it, side 1 above;
//! 2. candidates are tree leaves (degree 1) lying laterally: at least
//!    [`LATERAL_FRACTION`] of that side's half-width away from the midline — this drops
//!    the sternum's ends;
//! 3. on each side, candidates are ranked by the length of the tree branch they end
//!    (from the leaf to the first branching node): rib ends terminate long cartilage
//!    chains, spurious leaves (a key point between two ribs) terminate short twigs; the
//!    four longest are kept, a convex-hull vertex winning a tie;
//! 4. if a side has fewer than four, the lateral convex-hull vertices of that side that
//!    are not yet chosen are added, most lateral first (a rib whose chain was joined to a
//!    neighbour at its lateral end still has its tip on the hull);
//! 5. if a side still has fewer than four, [`Error::Endpoints`] names the side and count.
//!
//! # Rib order
//! Template: each endpoint takes the rib label of the nearest labelled template point
//! when labels are given ([`Error::RibOrder`] unless every rib gets exactly one endpoint
//! per side); without labels, endpoints are ordered cranio-caudally on each side (the
//! template is in the patient frame: `+y` cranial). Target: endpoints inherit the label
//! of the template endpoint they are matched to (see [`crate::registration::endpoints`]). Both clouds'
//! endpoints come from the same rule.

use crate::config::Config;
use crate::config::{LATERAL_FRACTION, RIBS, RIB_SAMPLES};
use crate::error::{Cloud, Error, Result};
use crate::limits::{KEY_POINTS, SKELETON_POINTS, SOM1_CAPACITY};
use crate::math::fit::{equal_steps, Poly};
use crate::math::geom::{Frame, Rigid};
use crate::math::hull::{gift_wrap, Vec2};
use crate::math::mst::Tree;
use crate::math::som::{LiveScan, Som, SomTrainer};
use crate::Vec3;

/// The SOM / MST / endpoint stage of one cloud (6,840 B; see the README's memory table).
#[derive(Clone, Debug, PartialEq)]
pub struct SkeletonGraph {
    /// Live SOM 1 nodes (at most 400; see [`Som::live_nodes`]).
    pub som1: heapless::Vec<Vec3, SOM1_CAPACITY>,
    /// Live SOM 2 nodes: the key points (at most 40).
    pub key_points: heapless::Vec<Vec3, KEY_POINTS>,
    /// MST over the key points.
    pub tree: Tree<KEY_POINTS>,
    /// Principal axes of the key points (u lateral, v along the sternum).
    pub frame: Frame,
    /// Convex-hull vertices of the key points in the (u, v) plane, counter-clockwise.
    pub hull: heapless::Vec<u16, KEY_POINTS>,
    /// Median `u` of the key points: the midline separating side 0 (below) from side 1.
    pub midline: f32,
    /// The endpoint rule's four endpoints of each side (key-point indices), most cranial
    /// (+v) first, or why the rule found fewer. A labelled template does not need them.
    pub endpoints: Result<[[u8; 4]; 2]>,
}

impl SkeletonGraph {
    /// A graph of nothing (a placeholder for one moved out).
    pub fn empty() -> Self {
        SkeletonGraph {
            som1: heapless::Vec::new(),
            key_points: heapless::Vec::new(),
            tree: Tree::default(),
            frame: Frame::identity(),
            hull: heapless::Vec::new(),
            midline: 0.0,
            endpoints: Err(Error::Config("an empty graph has no endpoints")),
        }
    }

    /// SOM 1 → SOM 2 → MST → hull → endpoints for `cloud`. With `patient_frame` the
    /// cloud is taken to be in the patient frame (x lateral, y cranial) and the axes are
    /// oriented to it (used for the template); otherwise their signs are arbitrary.
    pub fn build(cloud: &[Vec3], which: Cloud, cfg: &Config, patient_frame: bool) -> Result<Self> {
        let mut b = GraphBuild::start(cloud, which, cfg, patient_frame)?;
        while !b.step(cloud, cfg, u32::MAX)? {}
        b.into_graph()
            .ok_or(Error::Config("the skeleton graph build did not finish"))
    }

    /// MST, hull, midline and endpoints of the trained key points.
    #[inline(never)]
    fn from_key_points(
        som1: heapless::Vec<Vec3, SOM1_CAPACITY>,
        key_points: heapless::Vec<Vec3, KEY_POINTS>,
        which: Cloud,
        patient_frame: bool,
    ) -> Result<Self> {
        if key_points.len() < MIN_KEY_POINTS {
            return Err(Error::Endpoints {
                cloud: which,
                side: 0,
                found: 0,
                expected: 4,
            });
        }
        let tree = Tree::prim(&key_points)?;
        let mut frame = Frame::principal(&key_points, 0).ok_or(Error::Degenerate {
            cloud: which,
            spread_mm: 0.0,
        })?;
        if patient_frame {
            frame = frame.oriented_to_patient();
        }
        let uv: heapless::Vec<Vec2, KEY_POINTS> = key_points
            .iter()
            .map(|p| {
                let q = frame.local(p);
                Vec2::new(q.x, q.y)
            })
            .collect();
        let mut hull = heapless::Vec::new();
        gift_wrap(&uv, &mut hull)?;
        let midline = median_u(&uv);
        let endpoints = select_endpoints(&key_points, &tree, &uv, &hull, midline, which);
        Ok(SkeletonGraph {
            som1,
            key_points,
            tree,
            frame,
            hull,
            midline,
            endpoints,
        })
    }

    /// Side of a key point: 0 below the midline, 1 above.
    pub fn side(&self, k: usize) -> usize {
        usize::from(self.frame.local(&self.key_points[k]).x > self.midline)
    }
}

/// A [`SkeletonGraph`] being built a bounded number of SOM iterations at a time (the
/// controller's incremental registration); [`SkeletonGraph::build`] runs it to the end.
#[derive(Clone)]
pub struct GraphBuild {
    which: Cloud,
    patient_frame: bool,
    stage: GraphStage,
}

// The stages are exclusive and the enum lives once per registration: boxing is not an
// option without a heap, and the size is the largest stage's anyway.
#[allow(clippy::large_enum_variant)]
#[derive(Clone)]
enum GraphStage {
    Som1(Som<SOM1_CAPACITY>, SomTrainer, LiveScan<SOM1_CAPACITY>),
    Som2(
        heapless::Vec<Vec3, SOM1_CAPACITY>,
        Som<KEY_POINTS>,
        SomTrainer,
        LiveScan<KEY_POINTS>,
    ),
    /// The live SOM-1 nodes and the key points, before MST, hull and endpoints.
    Keys(
        heapless::Vec<Vec3, SOM1_CAPACITY>,
        heapless::Vec<Vec3, KEY_POINTS>,
    ),
    Done(SkeletonGraph),
    Failed,
}

impl GraphBuild {
    /// Principal axes of `cloud` and the initialised SOM 1 (O(samples), no training).
    pub fn start(cloud: &[Vec3], which: Cloud, cfg: &Config, patient_frame: bool) -> Result<Self> {
        let frame0 = Frame::principal(cloud, cfg.som1.seed).ok_or(Error::TooFewPoints {
            cloud: which,
            found: 0,
            min: 1,
        })?;
        if frame0.spread[1].is_nan() || frame0.spread[1] < MIN_SPREAD_MM {
            return Err(Error::Degenerate {
                cloud: which,
                spread_mm: frame0.spread[1],
            });
        }
        let (map, trainer) = Som::<SOM1_CAPACITY>::start(cloud, &frame0, &cfg.som1)?;
        Ok(GraphBuild {
            which,
            patient_frame,
            stage: GraphStage::Som1(map, trainer, LiveScan::new(cfg.som1.seed)),
        })
    }

    /// SOM iterations done and in all (for progress reports).
    pub fn progress(&self, cfg: &Config) -> (u32, u32) {
        let total = cfg.som1.iterations + cfg.som2.iterations;
        match &self.stage {
            GraphStage::Som1(_, t, _) => (t.done(), total),
            GraphStage::Som2(_, _, t, _) => (cfg.som1.iterations + t.done(), total),
            GraphStage::Keys(..) | GraphStage::Done(_) | GraphStage::Failed => (total, total),
        }
    }

    /// What the next step works on, for cost reports: `"som1"`, `"scan1"` (SOM-1
    /// dead units), `"som2"`, `"scan2"`, `"graph"` (MST, hull, endpoints), `"built"`.
    pub fn stage(&self) -> &'static str {
        match &self.stage {
            GraphStage::Som1(_, t, _) if !t.finished() => "som1",
            GraphStage::Som1(..) => "scan1",
            GraphStage::Som2(_, _, t, _) if !t.finished() => "som2",
            GraphStage::Som2(..) => "scan2",
            GraphStage::Keys(..) => "graph",
            GraphStage::Done(_) | GraphStage::Failed => "built",
        }
    }

    /// At most `budget` SOM iterations (a stage change — dead-unit pruning, the SOM-2
    /// initialisation, or MST/hull/endpoints at the end — counts as one call of its own);
    /// `true` when the graph is built ([`GraphBuild::graph`]). `cloud` and `cfg` must be
    /// those given to [`GraphBuild::start`]. The graph is built in place: nothing of
    /// kilobytes passes through the caller's stack (the controller's 100 Hz loop).
    #[inline(never)]
    pub fn step(&mut self, cloud: &[Vec3], cfg: &Config, budget: u32) -> Result<bool> {
        let som2 = &cfg.som2;
        match &mut self.stage {
            GraphStage::Som1(map, trainer, scan) => {
                if !trainer.finished() {
                    trainer.run(map, cloud, budget);
                    return Ok(false);
                }
                // The dead-unit scan: one map scan per point, as a SOM iteration; the
                // stage change after it is a call of its own.
                if !scan.step(map, cloud, 0) {
                    scan.step(map, cloud, budget);
                    return Ok(false);
                }
                let mut live1 = heapless::Vec::new();
                scan.finish(map, &mut live1)?;
                let frame1 = Frame::principal(&live1, som2.seed).ok_or(Error::Degenerate {
                    cloud: self.which,
                    spread_mm: 0.0,
                })?;
                let (map2, trainer2) = Som::<KEY_POINTS>::start(&live1, &frame1, som2)?;
                self.stage = GraphStage::Som2(live1, map2, trainer2, LiveScan::new(som2.seed));
                Ok(false)
            }
            GraphStage::Som2(live1, map, trainer, scan) => {
                if !trainer.finished() {
                    trainer.run(map, live1, budget);
                    return Ok(false);
                }
                // A scan of the 40-node map costs a tenth of a SOM-1 one. MST, hull and
                // endpoints after it are a call of their own.
                if !scan.step(map, live1, 0) {
                    scan.step(map, live1, budget.saturating_mul(8));
                    return Ok(false);
                }
                let mut key_points = heapless::Vec::new();
                scan.finish(map, &mut key_points)?;
                let live1 = core::mem::take(live1);
                self.stage = GraphStage::Keys(live1, key_points);
                Ok(false)
            }
            GraphStage::Keys(live1, key_points) => {
                let (live1, key_points) = (core::mem::take(live1), core::mem::take(key_points));
                self.stage = GraphStage::Failed;
                let graph = SkeletonGraph::from_key_points(
                    live1,
                    key_points,
                    self.which,
                    self.patient_frame,
                )?;
                self.stage = GraphStage::Done(graph);
                Ok(true)
            }
            GraphStage::Done(_) => Ok(true),
            GraphStage::Failed => Err(Error::Config("the skeleton graph build failed before")),
        }
    }

    /// The graph, once [`GraphBuild::step`] returned `true`.
    pub fn graph(&self) -> Option<&SkeletonGraph> {
        match &self.stage {
            GraphStage::Done(g) => Some(g),
            _ => None,
        }
    }

    /// The graph, once built, moved out (the build is left failed).
    pub fn take_graph(&mut self) -> Option<SkeletonGraph> {
        match core::mem::replace(&mut self.stage, GraphStage::Failed) {
            GraphStage::Done(g) => Some(g),
            other => {
                self.stage = other;
                None
            }
        }
    }

    /// The graph, once built.
    pub fn into_graph(self) -> Option<SkeletonGraph> {
        match self.stage {
            GraphStage::Done(g) => Some(g),
            _ => None,
        }
    }
}

/// Fewest live key points from which 8 endpoints and 4 paths can come.
pub const MIN_KEY_POINTS: usize = 12;

/// A cloud whose second principal spread is below this (mm) has no rib-cage extent.
pub const MIN_SPREAD_MM: f32 = 1.0;

fn median_u(uv: &[Vec2]) -> f32 {
    let n = uv.len();
    let mut us: heapless::Vec<f32, KEY_POINTS> = uv.iter().map(|q| q.x).collect();
    us.sort_unstable_by(f32::total_cmp);
    match n {
        0 => 0.0,
        _ if n.is_multiple_of(2) => 0.5 * (us[n / 2 - 1] + us[n / 2]),
        _ => us[n / 2],
    }
}

fn select_endpoints(
    key: &[Vec3],
    tree: &Tree<KEY_POINTS>,
    uv: &[Vec2],
    hull: &[u16],
    mid: f32,
    which: Cloud,
) -> Result<[[u8; 4]; 2]> {
    let n = key.len();
    let lo = uv.iter().map(|q| q.x).fold(f32::INFINITY, f32::min);
    let hi = uv.iter().map(|q| q.x).fold(f32::NEG_INFINITY, f32::max);
    let half = [mid - lo, hi - mid];
    let side_of = |i: usize| usize::from(uv[i].x > mid);
    let lateral = |i: usize| {
        let s = side_of(i);
        (uv[i].x - mid).abs() >= LATERAL_FRACTION * half[s]
    };
    let on_hull = |i: usize| hull.iter().any(|&h| usize::from(h) == i);
    let degrees = tree.degrees();

    let mut out = [[0u8; 4]; 2];
    for (side, slot) in out.iter_mut().enumerate() {
        // (index, branch length, on hull) of lateral leaves on this side.
        let mut cands = heapless::Vec::<(usize, f32, bool), KEY_POINTS>::new();
        for i in 0..n {
            if degrees[i] == 1 && side_of(i) == side && lateral(i) {
                // Note: at most KEY_POINTS entries, the capacity.
                let _ = cands.push((i, tree.branch_length(i, key, &degrees), on_hull(i)));
            }
        }
        cands.sort_unstable_by(|a, b| b.1.total_cmp(&a.1).then(b.2.cmp(&a.2)).then(a.0.cmp(&b.0)));
        cands.truncate(4);
        if cands.len() < 4 {
            // Rule 4: lateral hull vertices, most lateral first.
            let mut extra = heapless::Vec::<(usize, f32, bool), KEY_POINTS>::new();
            for &h in hull {
                let i = usize::from(h);
                if side_of(i) == side && lateral(i) && !cands.iter().any(|c| c.0 == i) {
                    let _ = extra.push((i, (uv[i].x - mid).abs(), true));
                }
            }
            extra.sort_unstable_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            for e in extra {
                if cands.len() == 4 {
                    break;
                }
                let _ = cands.push(e);
            }
        }
        if cands.len() < 4 {
            return Err(Error::Endpoints {
                cloud: which,
                side: side as u8,
                found: cands.len() as u8,
                expected: 4,
            });
        }
        // Most cranial (+v) first.
        cands.sort_unstable_by(|a, b| uv[b.0].y.total_cmp(&uv[a.0].y));
        for (k, c) in cands.iter().enumerate() {
            slot[k] = c.0 as u8;
        }
    }
    Ok(out)
}

/// For each rib 2..5 (index 0..4), its endpoint on side 0 and on side 1 (key-point indices).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RibEnds(pub [[u8; 2]; 4]);

impl RibEnds {
    /// Template rib ends: the endpoint rule's eight endpoints, ordered into ribs. With
    /// `labels` (rib number per cloud point; values other than 2..=5 are ignored) each
    /// endpoint takes the label of the nearest labelled point and every rib must get
    /// exactly one endpoint per side ([`Error::RibOrder`] otherwise); without labels they
    /// are ordered cranio-caudally on each side (+y cranial). The target's endpoints come
    /// from the same rule, so both clouds' rib ends are found the same way (the paper:
    /// hull endpoints, grouped by the template's rib order).
    pub fn from_template(
        graph: &SkeletonGraph,
        cloud: &[Vec3],
        labels: Option<&[u8]>,
    ) -> Result<Self> {
        let e = graph.endpoints?;
        let Some(labels) = labels else {
            // `endpoints` are already most cranial first.
            return Ok(RibEnds(core::array::from_fn(|r| [e[0][r], e[1][r]])));
        };
        if labels.len() != cloud.len() {
            return Err(Error::LabelCount {
                found: crate::math::geom::sat_u32(labels.len()),
                expected: crate::math::geom::sat_u32(cloud.len()),
            });
        }
        let mut ends = [[0u8; 2]; 4];
        for (side, side_ends) in e.iter().enumerate() {
            let mut count = [0u8; 4];
            for &k in side_ends {
                let p = graph.key_points[usize::from(k)];
                let rib = cloud
                    .iter()
                    .zip(labels)
                    .filter(|(_, l)| RIBS.contains(l))
                    .min_by(|a, b| {
                        (a.0 - p)
                            .norm_squared()
                            .total_cmp(&(b.0 - p).norm_squared())
                    })
                    .map(|(_, &l)| l)
                    .ok_or(Error::RibOrder {
                        side: side as u8,
                        rib: RIBS[0],
                        found: 0,
                    })?;
                let r = usize::from(rib - RIBS[0]);
                count[r] += 1;
                ends[r][side] = k;
            }
            if let Some(r) = count.iter().position(|&c| c != 1) {
                return Err(Error::RibOrder {
                    side: side as u8,
                    rib: RIBS[r],
                    found: count[r],
                });
            }
        }
        Ok(RibEnds(ends))
    }
}

/// The 30 resampled rib points of one cloud (paper Eq. 5), rib 2 first, each rib from
/// side 0 to side 1, and what the turn filter kept.
#[derive(Clone, Debug, PartialEq)]
pub struct RibSkeleton {
    /// Resampled points: ribs 2, 3, 4, 5 with 6, 6, 8, 10 points.
    pub points: [Vec3; SKELETON_POINTS],
    /// Per rib, the key points kept on its path (up to 40, side 0 first).
    pub paths: [heapless::Vec<u8, KEY_POINTS>; 4],
    /// Per rib, the polynomial degree fitted (3 unless the path kept fewer than 4 points).
    pub degree: [u8; 4],
}

impl RibSkeleton {
    /// Paths, turn filter, fit and resampling for the rib `ends` of `graph`.
    pub fn build(
        graph: &SkeletonGraph,
        ends: &RibEnds,
        cfg: &Config,
        which: Cloud,
    ) -> Result<Self> {
        let turn_angle_deg = cfg.turn_angle_deg;
        if turn_angle_deg.is_nan() || turn_angle_deg <= 0.0 || turn_angle_deg > 180.0 {
            return Err(Error::Config("turn angle must be in (0, 180] degrees"));
        }
        let cos_max = libm::cosf(turn_angle_deg.to_radians());
        let mut points = [Vec3::zeros(); SKELETON_POINTS];
        let mut paths: [heapless::Vec<u8, KEY_POINTS>; 4] = Default::default();
        let mut degree = [0u8; 4];
        let mut offset = 0;
        for (r, [a, b]) in ends.0.iter().enumerate() {
            let mut raw = heapless::Vec::<u8, KEY_POINTS>::new();
            graph
                .tree
                .path(usize::from(*a), usize::from(*b), &mut raw)?;
            turn_filter(&graph.key_points, &raw, cos_max, &mut paths[r]);
            let kept = &paths[r];
            if kept.len() < 2 {
                return Err(Error::RibPath {
                    cloud: which,
                    rib: RIBS[r],
                    found: kept.len() as u8,
                    min: 2,
                });
            }
            let local: heapless::Vec<Vec3, KEY_POINTS> = kept
                .iter()
                .map(|&k| graph.frame.local(&graph.key_points[usize::from(k)]))
                .collect();
            let (x0, x1) = (local[0].x, local[local.len() - 1].x);
            let out = &mut points[offset..offset + RIB_SAMPLES[r]];
            degree[r] = fit_rib(&local, x0, x1, |q| graph.frame.world(q), out).map_err(|_| {
                Error::RibPath {
                    cloud: which,
                    rib: RIBS[r],
                    found: kept.len() as u8,
                    min: 2,
                }
            })?;
            offset += RIB_SAMPLES[r];
        }
        Ok(RibSkeleton {
            points,
            paths,
            degree,
        })
    }

    /// The skeleton moved by a rigid transform (for tests and diagnostics).
    pub fn transformed(&self, t: &Rigid) -> Self {
        let mut s = self.clone();
        for p in &mut s.points {
            *p = t.apply(p);
        }
        s
    }
}

/// Paper Eq. 5 for one rib: least-squares `y(x)`, `z(x)` through `local` (points in a
/// frame whose x runs along the rib; degree 3, or `len − 1` when fewer than 4 points),
/// resampled at `out.len()` equal x steps from `x0` to `x1` and taken back to the world
/// by `to_world`. Returns the degree used.
pub fn fit_rib(
    local: &[Vec3],
    x0: f32,
    x1: f32,
    to_world: impl Fn(&Vec3) -> Vec3,
    out: &mut [Vec3],
) -> Result<u8> {
    const CAP: usize = crate::limits::SOM1_CAPACITY;
    if local.len() < 2 || local.len() > CAP {
        return Err(Error::Config("a rib fit needs 2..=400 points"));
    }
    let xs: heapless::Vec<f32, CAP> = local.iter().map(|q| q.x).collect();
    let ys: heapless::Vec<f32, CAP> = local.iter().map(|q| q.y).collect();
    let zs: heapless::Vec<f32, CAP> = local.iter().map(|q| q.z).collect();
    let deg = (local.len() - 1).min(3);
    let fy = Poly::fit(&xs, &ys, deg)?;
    let fz = Poly::fit(&xs, &zs, deg)?;
    let n = out.len();
    for (p, x) in out.iter_mut().zip(equal_steps(x0, x1, n)) {
        *p = to_world(&Vec3::new(x, fy.eval(x), fz.eval(x)));
    }
    Ok(deg as u8)
}

/// Paper Eq. 4: keep the first two path points, then a point only if the turn from the
/// last kept segment to it is at most T_θ. A point coinciding with the last kept one is
/// dropped (no direction).
pub fn turn_filter<const N: usize>(
    pts: &[Vec3],
    path: &[u8],
    cos_max: f32,
    out: &mut heapless::Vec<u8, N>,
) {
    out.clear();
    for &k in path {
        let p = pts[usize::from(k)];
        let n = out.len();
        let keep = match n {
            0 => true,
            1 => (p - pts[usize::from(out[0])]).norm_squared() > 0.0,
            _ => {
                let a = pts[usize::from(out[n - 1])] - pts[usize::from(out[n - 2])];
                let b = p - pts[usize::from(out[n - 1])];
                let (na, nb) = (a.norm(), b.norm());
                nb > 0.0 && na > 0.0 && a.dot(&b) >= cos_max * na * nb
            }
        };
        if keep && out.push(k).is_err() {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turn_filter_follows_eq4() {
        // A straight run, a 90° kink point, then back on the line.
        let pts = [
            Vec3::new(0., 0., 0.),
            Vec3::new(1., 0., 0.),
            Vec3::new(2., 0., 0.),
            Vec3::new(2., 5., 0.),  // 90° turn from (1,0)->(2,0): dropped
            Vec3::new(3., 0.5, 0.), // small turn from the last kept segment: kept
            Vec3::new(3., 0.5, 0.), // coincident: dropped
        ];
        let mut out = heapless::Vec::<u8, 8>::new();
        turn_filter(
            &pts,
            &[0, 1, 2, 3, 4, 5],
            libm::cosf(60f32.to_radians()),
            &mut out,
        );
        assert_eq!(out.as_slice(), &[0, 1, 2, 4]);
    }
}
