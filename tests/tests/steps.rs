//! The `f32` core against the `f64` reference (`ribreg_tests::reference`), one pipeline
//! step at a time, each on the SAME inputs: clouds are generated in `f64`, rounded to
//! `f32` once, and the rounded values are what both implementations see (so differences
//! measure arithmetic, not input rounding). Where a step consumes the output of an earlier
//! one (key points, frames, trees), the reference is fed the core's values.
//!
//! Tolerances follow numpy's `isclose`: `|core − ref| ≤ atol + rtol·|ref|`; each test
//! states its bound, why it is what it is, and what was measured
//! (`cargo test -p ribreg-tests --test steps -- --nocapture` prints the measurements).
//! `ε` below is `f32::EPSILON` = 1.19e-7.

use ribreg_core::config::{Config, SomConfig};
use ribreg_core::limits::SKELETON_POINTS;
use ribreg_core::math::fit::{equal_steps, Poly};
use ribreg_core::math::geom::Frame;
use ribreg_core::math::hull::{gift_wrap, Vec2};
use ribreg_core::math::mst::Tree;
use ribreg_core::math::rng::Rng;
use ribreg_core::math::som::Som;
use ribreg_core::math::spline::ThinPlate;
use ribreg_core::registration::endpoints::{best_assignment, match_endpoints};
use ribreg_core::registration::local_rigid::{LocalRigid, TransformCache};
use ribreg_core::registration::metrics::{closest_distances, compare, KdTree};
use ribreg_core::registration::pipeline::{register, Template};
use ribreg_core::registration::skeleton::{turn_filter, RibEnds, RibSkeleton, SkeletonGraph};
use ribreg_core::{math::kabsch, Vec3};
use ribreg_tests::reference::{self as r, P3};
use ribreg_tests::support::*;

const EPS: f64 = f32::EPSILON as f64;

fn max_abs_coord(points: &[P3]) -> f64 {
    points.iter().flatten().fold(0.0f64, |m, c| m.max(c.abs()))
}

/// The cage moved by a rotation of `deg` about `axis` and a translation `t`, stretched.
fn moved_cage(stretch: f32, axis: P3, deg: f64, t: P3) -> Vec<Vec3> {
    let m = rigid(axis, deg, t);
    cage(stretch).iter().map(|p| m.apply(p)).collect()
}

/// A few clouds on which the graph stage is compared.
fn graph_clouds() -> Vec<(&'static str, Vec<Vec3>, bool)> {
    vec![
        ("cage(0)", cage(0.0), true),
        ("cage(0.08)", cage(0.08), true),
        ("cage(-0.05)", cage(-0.05), true),
        (
            "cage(0.08) 15° moved",
            moved_cage(0.08, [0.3, 1.0, 0.2], 15.0, [12.0, -8.0, 20.0]),
            false,
        ),
        (
            "cage(0.03) 90° about z",
            moved_cage(0.03, [0.0, 0.0, 1.0], 90.0, [-40.0, 25.0, 5.0]),
            false,
        ),
        (
            "cage(0) 180° about y",
            moved_cage(0.0, [0.0, 1.0, 0.0], 180.0, [0.0, 0.0, 60.0]),
            false,
        ),
    ]
}

// ---------------------------------------------------------------------------------------

/// SplitMix64 and `below(n)`: bit-identical (integer arithmetic only). Tolerance: exact.
#[test]
fn rng_same_integer_sequence() {
    for seed in [0u64, 1, 0x5EED_0001, 0x5EED_0002, u64::MAX] {
        let (mut a, mut b) = (Rng::new(seed), r::Rng::new(seed));
        for _ in 0..1000 {
            assert_eq!(a.next_u64(), b.next_u64());
        }
        for n in [1u32, 2, 7, 40, 400, 2318, 4096, 1 << 24, u32::MAX] {
            for _ in 0..1000 {
                assert_eq!(a.below(n), b.below(n), "seed {seed}, n {n}");
            }
        }
    }
}

/// Principal axes (origin, axes, spreads, canonical signs).
///
/// ```text
/// origin   atol 1e-4 · extent        f32 sums of ≤ 2048 offsets from the first point
/// axes     atol 1e-4 per component   eigenvector error ~ ε‖C‖/gap; all clouds here have
///                                    spread ratios ≥ 1.3 between consecutive axes
/// spread   rtol 1e-5, atol 1e-4 mm
/// signs    exact (axis·axis_ref > 0.99)
/// measured (max over clouds): origin 5.5e-5 mm, axes 2.0e-6, spread rel 4.8e-6
/// ```
#[test]
fn principal_axes_agree() {
    let mut clouds: Vec<(String, Vec<P3>)> = graph_clouds()
        .into_iter()
        .map(|(name, c, _)| (name.to_string(), cloud64(&c)))
        .collect();
    clouds.push(("skeleton-like".into(), f32_exact(&skeleton_like(1))));
    clouds.push((
        "box 3000 (sampled), far".into(),
        f32_exact(&random_cloud(
            7,
            3000,
            [300.0, -200.0, 100.0],
            [100.0, 50.0, 10.0],
        )),
    ));
    clouds.push((
        "box 500".into(),
        f32_exact(&random_cloud(8, 500, [0.0; 3], [80.0, 40.0, 15.0])),
    ));
    let (mut worst_o, mut worst_a, mut worst_s) = (0.0f64, 0.0f64, 0.0f64);
    for (name, pts) in &clouds {
        for seed in [0u64, 0x5EED_0001] {
            let c = Frame::principal(&cloud32(pts), seed).unwrap();
            let f = r::Frame::principal(pts, seed).unwrap();
            for (oriented, (c, f)) in [
                (false, (c, f)),
                (true, (c.oriented_to_patient(), f.oriented_to_patient())),
            ] {
                let c = frame_to64(&c);
                let extent = f.spread[0] * 4.0;
                let dorig = r::dist(c.origin, f.origin);
                worst_o = worst_o.max(dorig);
                assert!(dorig <= 1e-4 * extent, "{name}: origin off by {dorig}");
                for k in 0..3 {
                    assert!(
                        r::dot(c.axes[k], f.axes[k]) > 0.99,
                        "{name} (oriented {oriented}): axis {k} sign differs"
                    );
                    let da = (0..3)
                        .map(|i| (c.axes[k][i] - f.axes[k][i]).abs())
                        .fold(0.0, f64::max);
                    worst_a = worst_a.max(da);
                    assert!(da <= 1e-4, "{name}: axis {k} off by {da}");
                    assert_close(
                        &format!("{name}: spread {k}"),
                        c.spread[k],
                        f.spread[k],
                        1e-5,
                        1e-4,
                    );
                    worst_s = worst_s.max((c.spread[k] - f.spread[k]).abs() / f.spread[k]);
                }
            }
        }
    }
    eprintln!("principal axes: max |Δorigin| {worst_o:.2e} mm, |Δaxis| {worst_a:.2e}, rel Δspread {worst_s:.2e}");
}

/// SOM 1 (20 × 20) and SOM 2 (5 × 8): same cloud, same seed, same initial frame (the
/// core's, handed to the reference), the full training schedule.
///
/// The two can diverge only if a best-matching-unit decision flips between `f32` and
/// `f64` (two nodes within rounding of equal distance from a sample); after that, the
/// trajectories differ by a fraction of the learning step. Without a flip the node error
/// is the accumulated rounding of 6000 (3000) updates, ~1e-4 mm.
///
/// ```text
/// SOM 1 nodes (400)   mean ≤ 0.01 mm, max ≤ 0.5 mm
/// SOM 1 live nodes    same count, each within 0.5 mm
/// SOM 2 nodes (40)    mean ≤ 0.01 mm, max ≤ 0.5 mm   (on the core's live SOM-1 nodes)
/// SOM 2 live nodes    same count
/// measured over 6 clouds × 4 seeds: without a flip SOM 1 mean ≤ 2e-5, max ≤ 2e-4 mm;
///   one flip (cage turned 180° about y, seed 0x5EED_0001, i.e. the default schedule):
///   SOM 1 mean 3.8e-4, max 6.4e-2 mm, same live nodes; SOM 2 mean ≤ 1.7e-5, max 7.1e-5 mm
/// ```
/// The brief's acceptance bound (mean node distance < 0.5 mm on the built-in cage) holds
/// with a margin of three orders of magnitude.
#[test]
fn som_nodes_agree() {
    let (mut m1, mut x1, mut m2, mut x2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (name, cloud, _) in graph_clouds() {
        let c64 = cloud64(&cloud);
        for seed in [0x5EED_0001u64, 1, 2, 99] {
            let cfg1 = SomConfig {
                seed,
                ..SomConfig::SOM1
            };
            let p1 = som_params(&cfg1);
            let frame = Frame::principal(&cloud, seed).unwrap();
            let core1 = Som::<400>::train(&cloud, &frame, &cfg1).unwrap();
            let ref1 = r::Som::train(&c64, cfg1.rows, cfg1.cols, &frame_to64(&frame), &p1);
            let (mean, max) = (
                mean_pair_dist(&core1.nodes().collect::<Vec<_>>(), &ref1.nodes),
                max_pair_dist(&core1.nodes().collect::<Vec<_>>(), &ref1.nodes),
            );
            m1 = m1.max(mean);
            x1 = x1.max(max);
            if max > 1e-3 {
                eprintln!("SOM 1 {name} seed {seed}: diverged, mean {mean:.2e} max {max:.2e} mm");
            }
            assert!(
                mean <= 0.01 && max <= 0.5,
                "{name} seed {seed}: SOM 1 nodes mean {mean} max {max} mm"
            );
            let mut live = heapless::Vec::<Vec3, 400>::new();
            core1.live_nodes(&cloud, seed, &mut live).unwrap();
            let ref_live = ref1.live_nodes(&c64, seed);
            assert_eq!(
                live.len(),
                ref_live.len(),
                "{name} seed {seed}: live SOM-1 node count"
            );
            assert!(max_pair_dist(&live, &ref_live) <= 0.5);

            let s2 = seed ^ 0xABCD;
            let cfg2 = SomConfig {
                seed: s2,
                ..SomConfig::SOM2
            };
            let p2 = som_params(&cfg2);
            let frame1 = Frame::principal(&live, s2).unwrap();
            let core2 = Som::<40>::train(&live, &frame1, &cfg2).unwrap();
            let ref2 = r::Som::train(
                &cloud64(&live),
                cfg2.rows,
                cfg2.cols,
                &frame_to64(&frame1),
                &p2,
            );
            let (mean, max) = (
                mean_pair_dist(&core2.nodes().collect::<Vec<_>>(), &ref2.nodes),
                max_pair_dist(&core2.nodes().collect::<Vec<_>>(), &ref2.nodes),
            );
            m2 = m2.max(mean);
            x2 = x2.max(max);
            assert!(
                mean <= 0.01 && max <= 0.5,
                "{name} seed {seed}: SOM 2 nodes mean {mean} max {max} mm"
            );
            let mut key = heapless::Vec::<Vec3, 40>::new();
            core2.live_nodes(&live, s2, &mut key).unwrap();
            assert_eq!(
                key.len(),
                ref2.live_nodes(&cloud64(&live), s2).len(),
                "{name} seed {seed}: live key points"
            );
        }
    }
    eprintln!(
        "SOM: SOM1 worst mean {m1:.2e} max {x1:.2e} mm; SOM2 worst mean {m2:.2e} max {x2:.2e} mm"
    );
}

/// The core's schedule in reference form, values converted exactly (`0.01f32` is not
/// `0.01`): the same inputs.
fn som_params(c: &SomConfig) -> r::SomParams {
    r::SomParams {
        rows: c.rows,
        cols: c.cols,
        iterations: c.iterations,
        lr_start: f64::from(c.lr_start),
        lr_end: f64::from(c.lr_end),
        radius_start: f64::from(c.radius_start),
        radius_end: f64::from(c.radius_end),
        seed: c.seed,
    }
}

/// The reference's own SOM chain (its own frames, live-node selection and second map) on
/// the cage vs the core's graph: the acceptance bound of the brief, mean node distance
/// < 0.5 mm, and the per-node bound of `som_nodes_agree` (mean ≤ 0.01 mm); measured
/// 1.5e-5 mm for the live SOM-1 nodes, 1.3e-5 mm for the key points.
#[test]
fn som_chain_on_the_builtin_cage() {
    let ct = cage(0.0);
    let g = SkeletonGraph::build(
        &ct,
        ribreg_core::error::Cloud::Template,
        &Config::default(),
        true,
    )
    .unwrap();
    let rg = r::Graph::build(&cloud64(&ct), &r::Config::default(), true).unwrap();
    assert_eq!(g.som1.len(), rg.som1.len());
    assert_eq!(g.key_points.len(), rg.key_points.len());
    let mean1 = mean_pair_dist(&g.som1, &rg.som1);
    let mean2 = mean_pair_dist(&g.key_points, &rg.key_points);
    eprintln!("cage SOM chain: live SOM1 mean {mean1:.2e} mm, key points mean {mean2:.2e} mm");
    assert!(mean1 < 0.5 && mean2 < 0.5);
    // The per-node bound of som_nodes_agree.
    assert!(
        mean1 <= 0.01 && mean2 <= 0.01,
        "far worse than measured (1.5e-5 mm)"
    );
}

/// Prim's MST: weight, edge set, degrees, paths, branch lengths.
///
/// ```text
/// weight          atol 4ε·(n−1)·max|coord| + rtol 4ε   per edge: |p − q| in f32 loses
///                 ≤ ½ulp(max|coord|) per component, the norm adds 2ε relative
/// edges, degrees  identical when the reference tree is ≥ 1e-3 mm away from a tie
///                 (margin = min over non-edges of d(i,j) − longest edge on the path)
/// paths           identical index sequences (same tree)
/// branch lengths  rtol 1e-5, atol 1e-4 mm
/// measured: weight rel 1.7e-7; every set had margin > 1e-3 mm and identical trees
/// ```
#[test]
fn mst_agrees() {
    let mut sets: Vec<(String, Vec<P3>)> = Vec::new();
    for (k, n) in [2usize, 3, 10, 40, 100, 255].into_iter().enumerate() {
        sets.push((
            format!("random {n}"),
            f32_exact(&random_cloud(100 + k as u64, n, [0.0; 3], [100.0; 3])),
        ));
    }
    sets.push((
        "random 60 far".into(),
        f32_exact(&random_cloud(200, 60, [10.0, 200.0, 900.0], [50.0; 3])),
    ));
    for seed in 1..=5 {
        sets.push((
            format!("skeleton-like {seed}"),
            f32_exact(&skeleton_like(seed)),
        ));
    }
    let tpl = Template::build(&cage(0.0), None, &Config::default()).unwrap();
    sets.push(("cage key points".into(), cloud64(&tpl.graph.key_points)));
    let mut worst = 0.0f64;
    for (name, pts) in &sets {
        let p32 = cloud32(pts);
        let core = Tree::<255>::prim(&p32).unwrap();
        let rt = r::Tree::prim(pts);
        let n = pts.len();
        let w = f64::from(core.weight(&p32));
        let want = rt.weight(pts);
        let atol = 4.0 * EPS * (n as f64 - 1.0) * max_abs_coord(pts);
        assert_close(&format!("{name}: weight"), w, want, 4.0 * EPS, atol);
        worst = worst.max((w - want).abs() / want.max(1e-30));
        assert_eq!(core.edges().count(), n - 1);
        let margin = mst_margin(pts, &rt);
        if margin > 1e-3 {
            assert_eq!(
                core_edges(&core),
                rt.edges(),
                "{name}: edge sets (margin {margin})"
            );
            let deg = core.degrees();
            assert_eq!(
                deg[..n].iter().map(|&d| usize::from(d)).collect::<Vec<_>>(),
                rt.degrees(),
                "{name}: degrees"
            );
            let leaves: Vec<usize> = (0..n).filter(|&i| deg[i] == 1).collect();
            let mut path = heapless::Vec::<u8, 255>::new();
            for (i, &a) in leaves.iter().enumerate().take(12) {
                for &b in leaves.iter().skip(i).take(12) {
                    core.path(a, b, &mut path).unwrap();
                    let got: Vec<usize> = path.iter().map(|&v| usize::from(v)).collect();
                    assert_eq!(got, rt.path(a, b), "{name}: path {a}..{b}");
                }
                let bl = f64::from(core.branch_length(a, &p32, &deg));
                assert_close(
                    &format!("{name}: branch length of {a}"),
                    bl,
                    rt.branch_length(a, pts),
                    1e-5,
                    1e-4,
                );
            }
        } else {
            eprintln!("{name}: MST margin {margin:.2e} mm, edge sets not compared");
        }
    }
    eprintln!("MST: worst relative weight difference {worst:.2e}");
}

/// Gift-wrapping hull: identical vertex index sequences (both start at the lowest, then
/// leftmost point and run counter-clockwise). Tolerance: exact. The orientation test is
/// the only arithmetic; on `f32`-representable inputs the `f64` orientation is exact up
/// to one rounding, and none of these sets has a triple within rounding of collinear
/// except the integer grids, where both are exact.
#[test]
fn hull_agrees() {
    let mut sets: Vec<(String, Vec<[f64; 2]>)> = Vec::new();
    for (k, n) in [3usize, 4, 5, 10, 20, 50, 200, 1000]
        .into_iter()
        .enumerate()
    {
        let pts = f32_exact(&random_cloud(
            300 + k as u64,
            n,
            [20.0, -10.0, 0.0],
            [120.0, 80.0, 0.0],
        ));
        sets.push((
            format!("random {n}"),
            pts.iter().map(|p| [p[0], p[1]]).collect(),
        ));
    }
    // Integer grid: collinear points on every edge.
    sets.push((
        "grid 9×7".into(),
        (0..63)
            .map(|i| [f64::from(i % 9) * 5.0 - 20.0, f64::from(i / 9) * 5.0])
            .collect(),
    ));
    // A circle (every point a vertex), with duplicates and the centre.
    let mut circle: Vec<[f64; 2]> = (0..24)
        .map(|k| {
            let a = f64::from(k) * std::f64::consts::TAU / 24.0;
            [
                f64::from((50.0 * a.cos()) as f32),
                f64::from((30.0 * a.sin()) as f32),
            ]
        })
        .collect();
    circle.extend_from_slice(&[[0.0, 0.0], circle[3], circle[0], circle[17]]);
    sets.push(("ellipse + duplicates".into(), circle));
    sets.push((
        "collinear".into(),
        (0..10)
            .map(|i| [f64::from(i) * 3.0, f64::from(i) * -2.0])
            .collect(),
    ));
    sets.push(("one point ×3".into(), vec![[1.5, 2.5]; 3]));
    let tpl = Template::build(&cage(0.0), None, &Config::default()).unwrap();
    let g = graph_to_ref(&tpl.graph);
    sets.push((
        "cage key points (u, v)".into(),
        g.uv.iter()
            .map(|q| [f64::from(q[0] as f32), f64::from(q[1] as f32)])
            .collect(),
    ));
    for (name, pts) in &sets {
        let p32: Vec<Vec2> = pts
            .iter()
            .map(|p| Vec2::new(p[0] as f32, p[1] as f32))
            .collect();
        let mut out = heapless::Vec::<u16, 1024>::new();
        gift_wrap(&p32, &mut out).unwrap();
        let got: Vec<usize> = out.iter().map(|&i| usize::from(i)).collect();
        assert_eq!(got, r::gift_wrap(pts), "{name}");
    }
    // The core's own hull of the cage's key points is what the reference computes.
    let core_hull: Vec<usize> = tpl.graph.hull.iter().map(|&i| usize::from(i)).collect();
    assert_eq!(core_hull, g.hull);
}

/// Cubic (quadratic, linear) least squares and equal-step resampling.
///
/// ```text
/// values at the resampled x   atol 1e-3·max|y| + 1e-3 mm   the core's documented contract
///                                                          (f32 normal equations in the
///                                                          scaled abscissa, Cholesky)
/// equal_steps abscissae       atol 4ε·max|x|
/// abscissae are stratified (one per n-th of the range), as along a rib path
/// measured: worst |Δy| 9.2e-5 mm over 200 fits
/// ```
#[test]
fn polyfit_agrees() {
    let mut rng = r::Rng::new(41);
    let mut worst = 0.0f64;
    let mut cases = 0;
    for &(n, deg, lo, hi) in &[
        (4usize, 3usize, -110.0, 100.0),
        (5, 3, -120.0, 110.0),
        (8, 3, -90.0, 95.0),
        (12, 3, -120.0, 110.0),
        (40, 3, -120.0, 110.0),
        (6, 3, 25.0, 95.0),
        (10, 2, -60.0, 80.0),
        (3, 2, -10.0, 40.0),
        (2, 1, -30.0, 50.0),
        (7, 1, 0.0, 120.0),
    ] {
        for _ in 0..20 {
            let c = [
                rng.uniform(-5.0, 60.0),
                rng.uniform(-0.5, 0.5),
                rng.uniform(-4e-3, 4e-3),
                rng.uniform(-3e-5, 3e-5),
            ];
            let noise = rng.uniform(0.0, 1.0);
            // Stratified abscissae: one per n-th of the range (rib-path-like spacing; the
            // contract does not cover clustered abscissae, see polyfit_clustered_abscissae).
            let w = (hi - lo) / n as f64;
            let x: Vec<f64> = (0..n)
                .map(|i| f64::from((lo + w * (i as f64 + rng.uniform(0.2, 0.8))) as f32))
                .collect();
            let y: Vec<f64> = x
                .iter()
                .map(|&v| {
                    f64::from(
                        (c[0] + c[1] * v + c[2] * v * v + c[3] * v * v * v + noise * rng.normal())
                            as f32,
                    )
                })
                .collect();
            let (x32, y32): (Vec<f32>, Vec<f32>) = x
                .iter()
                .zip(&y)
                .map(|(&a, &b)| (a as f32, b as f32))
                .unzip();
            let core = Poly::fit(&x32, &y32, deg).unwrap();
            let rf = r::Poly::fit(&x, &y, deg).unwrap();
            let xmin = x.iter().copied().fold(f64::INFINITY, f64::min);
            let xmax = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let ymax = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let core_x: Vec<f32> = equal_steps(xmin as f32, xmax as f32, 10).collect();
            for (k, xe) in r::equal_steps(xmin, xmax, 10).into_iter().enumerate() {
                assert_close(
                    "equal_steps",
                    f64::from(core_x[k]),
                    xe,
                    0.0,
                    4.0 * EPS * xmin.abs().max(xmax.abs()),
                );
                let got = f64::from(core.eval(xe as f32));
                let want = rf.eval(xe);
                worst = worst.max((got - want).abs());
                assert_close(
                    &format!("n {n} deg {deg}: y({xe})"),
                    got,
                    want,
                    0.0,
                    1e-3 * ymax + 1e-3,
                );
            }
            cases += 1;
        }
    }
    eprintln!("polyfit: {cases} fits, worst |Δy| {worst:.2e} mm");
}

/// The documented fit contract (values within 1e-3·max|y| + 1e-3 mm) on clustered
/// abscissae: four points, three within 10 mm, the cubic interpolating them. The core's
/// f32 normal equations square the Vandermonde condition number; values come out up to
/// 0.22 mm off (bound 0.062 mm). Such paths occur: at core e05cb20 the built-in cage's
/// rib-3 path kept four key points, two 1.2 mm apart in x, and its skeleton points
/// differed from the reference by 0.010 mm.
#[test]
fn polyfit_clustered_abscissae() {
    let cases: [([f32; 4], [f32; 4]); 3] = [
        (
            [-93.81849, 80.05481, 88.73861, 90.30389],
            [61.489563, 42.253597, 40.639786, 40.066223],
        ),
        (
            [68.861435, 86.50982, -77.989685, 79.78968],
            [70.16632, 73.42933, 54.050903, 71.797554],
        ),
        (
            [-25.315836, 45.9512, -71.20247, 45.519905],
            [38.181248, 66.44339, 21.624662, 67.469734],
        ),
    ];
    for (x32, y32) in cases {
        let x: Vec<f64> = x32.iter().map(|&v| f64::from(v)).collect();
        let y: Vec<f64> = y32.iter().map(|&v| f64::from(v)).collect();
        let core = Poly::fit(&x32, &y32, 3).unwrap();
        let rf = r::Poly::fit(&x, &y, 3).unwrap();
        let ymax = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let xmin = x.iter().copied().fold(f64::INFINITY, f64::min);
        let xmax = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        for xe in r::equal_steps(xmin, xmax, 10) {
            assert_close(
                &format!("x {x32:?}: y({xe})"),
                f64::from(core.eval(xe as f32)),
                rf.eval(xe),
                0.0,
                1e-3 * ymax + 1e-3,
            );
        }
    }
}

/// A random rotation: an isotropic axis and an angle uniform in [0°, 180°).
fn random_rotation(rng: &mut r::Rng) -> (P3, f64) {
    let axis = [rng.normal(), rng.normal(), rng.normal()];
    (axis, rng.uniform(0.0, 180.0))
}

fn mat_max_diff(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> f64 {
    (0..9)
        .map(|k| (a[k / 3][k % 3] - b[k / 3][k % 3]).abs())
        .fold(0.0, f64::max)
}

/// Kabsch (core: SVD with the reflection fix, Horn fallback) vs the reference (Horn's
/// quaternion in `f64`).
///
/// ```text
/// well-conditioned sets (second principal variance ≥ 0.05 × first; random, noisy, large
/// angles up to 179.9°, mirror images):
///   rmsd          core ≤ reference + 1e-4·s + 8ε·max|coord|   s = RMS spread of a
///   rotation      atol 1e-4 per element      the core's documented contract
///   translation   atol 1e-3 mm + 1e-4·|ā|    t = b̄ − R ā inherits R's error times |ā|
/// thin sets (second variance < 0.05 × first, here 3-point triangles): R about the long
/// axis is weakly determined by f32 data (error ∝ (σ₁/σ₂)², costing ∝ σ₂ of it), so
/// compare what matters:
///   rmsd, mapped points   atol 1e-3 mm + 1e-4·s·σ₁/σ₂   σ = principal std deviations
///   (see kabsch_nearly_collinear_mirror for the case that needs this slack)
/// near-collinear lines (cross spread 0.05 mm over 200 mm: σ₂(H)/σ₁(H) ≈ 7e-7 < ε, so f32
/// data do not determine the rotation about the line at all, any angle is as good):
///   mapped points, rmsd excess   atol 1e-3 mm + 1e-4·s + 2·h   h = RMS cross spread
/// measured: well-conditioned R 8.0e-6, t 1.9e-3 mm (|ā| up to 520 mm);
///           thin triangles: worst at 0.26 of the bound — a noisy 3-point set with
///           σ₁/σ₂ = 25 maps 0.047 mm apart (rmsd excess 9e-4 mm); an exact one 300 mm
///           from the origin has R 1.02e-4 off; a mirrored one with σ₁/σ₂ = 44 has
///           R 0.011 off and an rmsd excess of 0.011 mm;
///           near-collinear lines mapped up to 0.080 mm, rmsd excess up to 0.037 mm
///           (bound ≈ 0.15 mm: any rotation about the line is as good in f32)
/// ```
#[test]
fn kabsch_agrees() {
    let mut rng = r::Rng::new(5);
    let (mut wr, mut wt, mut wthin, mut wx) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for case in 0..200 {
        let n = [3usize, 4, 10, 30][case % 4];
        let centre = [
            rng.uniform(-300.0, 300.0),
            rng.uniform(-300.0, 300.0),
            rng.uniform(-300.0, 300.0),
        ];
        let a = f32_exact(&random_cloud(
            1000 + case as u64,
            n,
            centre,
            [80.0, 50.0, 30.0],
        ));
        let (axis, mut deg) = random_rotation(&mut rng);
        if case.is_multiple_of(10) {
            deg = 179.9;
        }
        let t = [
            rng.uniform(-200.0, 200.0),
            rng.uniform(-200.0, 200.0),
            rng.uniform(-200.0, 200.0),
        ];
        let m = rigid64(axis, deg, t);
        let noise = if case.is_multiple_of(3) { 0.5 } else { 0.0 };
        let mut b: Vec<P3> = a.iter().map(|p| m.apply(*p)).collect();
        if noise > 0.0 {
            for p in &mut b {
                for c in p.iter_mut() {
                    *c += noise * rng.normal();
                }
            }
        }
        if case.is_multiple_of(7) {
            // Mirror image: the best proper rotation is unique when the spreads differ.
            b = a.iter().map(|p| [p[0], p[1], -p[2]]).collect();
        }
        let b = f32_exact(&b);
        let (_, cov) = r::covariance(&a);
        let (ev, _) = r::sorted_eigen3(cov);
        let spread = (ev[0] + ev[1] + ev[2]).sqrt();
        let core = rigid_to64(&kabsch::fit(&cloud32(&a), &cloud32(&b)).unwrap());
        let rf = r::kabsch(&a, &b).unwrap();
        let excess = r::rmsd(&core, &a, &b) - r::rmsd(&rf, &a, &b);
        let coord = max_abs_coord(&a).max(max_abs_coord(&b));
        wx = wx.max(excess);
        // Thin sets: the weak rotation's error grows like ε_SVD·(σ₁/σ₂)², the rmsd and the
        // mapped points it costs like that times σ₂, i.e. ∝ s·σ₁/σ₂.
        let thin = (ev[0] / ev[1]).sqrt();
        let bound = if ev[1] >= 0.05 * ev[0] {
            1e-4 * spread + 8.0 * EPS * coord
        } else {
            1e-3 + 1e-4 * spread * thin
        };
        assert!(
            excess <= bound,
            "case {case}: rmsd exceeds the optimum by {excess} mm (bound {bound})"
        );
        if ev[1] >= 0.05 * ev[0] {
            let dr = mat_max_diff(&core.r, &rf.r);
            let ca = r::norm(r::mean(&a));
            let dt = r::dist(core.t, rf.t);
            wr = wr.max(dr);
            wt = wt.max(dt);
            assert!(dr <= 1e-4, "case {case}: rotation off by {dr}");
            assert!(
                dt <= 1e-3 + 1e-4 * ca,
                "case {case}: translation off by {dt} (|ā| {ca})"
            );
        } else {
            let mapped = a
                .iter()
                .map(|p| r::dist(core.apply(*p), rf.apply(*p)))
                .fold(0.0, f64::max);
            wthin = wthin.max(mapped / bound);
            assert!(
                mapped <= bound,
                "thin case {case}: mapped points differ by {mapped} mm (bound {bound})"
            );
        }
    }
    // Near-collinear: a 200 mm line with 0.05 mm cross noise.
    let mut wm = 0.0f64;
    for case in 0..40 {
        let mut a: Vec<P3> = (0..10)
            .map(|i| {
                let s = -100.0 + 200.0 * f64::from(i) / 9.0;
                [
                    s,
                    0.5 * s + 0.05 * rng.normal(),
                    -0.2 * s + 0.05 * rng.normal(),
                ]
            })
            .collect();
        a = f32_exact(&a);
        let (axis, deg) = random_rotation(&mut rng);
        let m = rigid64(axis, deg, [30.0, -10.0, 5.0]);
        let b = f32_exact(
            &a.iter()
                .map(|p| r::add(m.apply(*p), [0.02 * rng.normal(), 0.0, 0.0]))
                .collect::<Vec<_>>(),
        );
        let core = rigid_to64(&kabsch::fit(&cloud32(&a), &cloud32(&b)).unwrap());
        let rf = r::kabsch(&a, &b).unwrap();
        let mapped = a
            .iter()
            .map(|p| r::dist(core.apply(*p), rf.apply(*p)))
            .fold(0.0, f64::max);
        let excess = r::rmsd(&core, &a, &b) - r::rmsd(&rf, &a, &b);
        let (_, cov) = r::covariance(&a);
        let (ev, _) = r::sorted_eigen3(cov);
        let (spread, cross) = ((ev[0] + ev[1] + ev[2]).sqrt(), (ev[1] + ev[2]).sqrt());
        let bound = 1e-3 + 1e-4 * spread + 2.0 * cross;
        wm = wm.max(mapped);
        wx = wx.max(excess);
        assert!(
            mapped <= bound,
            "near-collinear {case}: mapped points differ by {mapped} mm (bound {bound})"
        );
        assert!(
            excess <= bound,
            "near-collinear {case}: core rmsd exceeds the optimum by {excess} mm"
        );
    }
    eprintln!(
        "kabsch: well-conditioned max |ΔR| {wr:.2e}, |Δt| {wt:.2e} mm; thin sets at {wthin:.2} of the bound; \
         near-collinear mapped {wm:.2e} mm; worst rmsd excess {wx:.2e} mm"
    );
}

/// A nearly collinear triangle (66 mm long, 0.87 mm wide: σ₂/σ₁ = 0.023) and its mirror
/// image z → −z: the two are congruent, the optimum is exact (reference rmsd 1e-14 mm).
/// A backward-stable f32 SVD would get the rotation within ε·(σ₁/σ₂)² ≈ 2.3e-4 (the
/// singular-vector error for σ₂(H)/σ₁(H) = 5.2e-4); the core is 0.011 off. Diagnosis (on
/// the same normalised f32 H, with nalgebra 0.35): `SVD::new` in f32 reconstructs H only
/// to 7.4e-6 (≈ 60ε), which the core's check accepts (tolerance 1e-3 relative, above
/// σ₂(H)/σ₁(H) itself), so the Horn fallback is never tried; the same SVD in f64 agrees
/// with the reference to 1.7e-5.
#[test]
fn kabsch_nearly_collinear_mirror() {
    let a: Vec<P3> = vec![
        [-176.07566833496094, 142.04818725585938, -228.23585510253906],
        [-181.2625732421875, 198.7360382080078, -198.31419372558594],
        [-171.28773498535156, 119.07160186767578, -240.401611328125],
    ];
    let b: Vec<P3> = a.iter().map(|p| [p[0], p[1], -p[2]]).collect();
    let core = rigid_to64(&kabsch::fit(&cloud32(&a), &cloud32(&b)).unwrap());
    let rf = r::kabsch(&a, &b).unwrap();
    assert!(r::rmsd(&rf, &a, &b) < 1e-6);
    let dr = mat_max_diff(&core.r, &rf.r);
    assert!(dr <= 1e-3, "rotation off by {dr}");
    assert!(
        r::rmsd(&core, &a, &b) <= 1e-3,
        "rmsd {} mm",
        r::rmsd(&core, &a, &b)
    );
}

/// Local-rigid mapping of a few hundred points, given the same 30 + 30 skeleton points.
///
/// ```text
/// N_r-nearest sets     identical unless two skeleton points are within 1e-3 mm² (squared
///                      distance) of a tie for the N_r-th place
/// widened sets         identical (collinearity widening, by the point nearest to the
///                      set's centroid)
/// mapped points        atol 1e-3 mm + 2e-4·L   L = lever arm, the distance from the point
///                                              to its neighbourhood's centroid: the Kabsch
///                                              rotation error (≤ 1e-4 per element, ≤ 2e-4
///                                              as an angle) times L, plus translation
/// measured: no neighbourhood difference; mapped points max 7.6e-3 mm (0.78 of its bound)
/// ```
/// 300 points (exact in `f32`) around and beyond a skeleton of the built-in cage's size,
/// for the mappings' agreement tests.
fn skeleton_queries(seed: u64) -> Vec<P3> {
    let mut rng = r::Rng::new(seed);
    (0..300)
        .map(|_| {
            f32_exact(&[[
                rng.uniform(-120.0, 120.0),
                rng.uniform(-130.0, 25.0),
                rng.uniform(-45.0, 15.0),
            ]])[0]
        })
        .collect()
}

#[test]
fn local_rigid_agrees() {
    // Skeletons: (1) the core's own template/target skeletons of the cage vs a moved,
    // stretched cage; (2) a synthetic bent skeleton with a straight rib 5 (collinear
    // neighbourhoods), under a smooth non-rigid deformation; N_r 10, 3 and 30.
    let tpl = Template::build(&cage(0.0), None, &Config::default()).unwrap();
    let us = moved_cage(0.08, [0.3, 1.0, 0.2], 15.0, [12.0, -8.0, 20.0]);
    let reg = register(&tpl, &us, &Config::default()).unwrap();
    let mut skeletons: Vec<(
        String,
        [Vec3; SKELETON_POINTS],
        [Vec3; SKELETON_POINTS],
        usize,
    )> = vec![(
        "cage → moved cage".into(),
        tpl.skeleton.points,
        reg.skeleton.points,
        10,
    )];
    let mut synth = [Vec3::zeros(); SKELETON_POINTS];
    let mut k = 0;
    for (rib, &n) in r::RIB_SAMPLES.iter().enumerate() {
        for j in 0..n {
            let x = -100.0 + 200.0 * j as f32 / (n - 1) as f32;
            synth[k] = if rib == 3 {
                Vec3::new(x, -110.0, 0.0)
            } else {
                Vec3::new(x, -28.0 * rib as f32 - 0.002 * x * x, -0.004 * x * x)
            };
            k += 1;
        }
    }
    let bend = |p: &Vec3| {
        let m = rigid(
            [0.2, 1.0, 0.1],
            0.1 * f64::from(p.x),
            [5.0, -3.0, 0.02 * f64::from(p.x)],
        );
        m.apply(p) + Vec3::new(0.0, 0.0, 1e-3 * p.y * p.y)
    };
    let bent = synth.map(|p| bend(&p));
    for nr in [10, 3, 30] {
        skeletons.push((format!("synthetic bent, N_r {nr}"), synth, bent, nr));
    }
    let queries = skeleton_queries(17);
    let (mut worst, mut worst_rel, mut differing, mut widened) = (0.0f64, 0.0f64, 0usize, 0usize);
    for (name, src, dst, nr) in &skeletons {
        let core = LocalRigid::new(*src, *dst, *nr).unwrap();
        let rf = r::LocalRigid::new(cloud64(src), cloud64(dst), *nr);
        let mut cache = TransformCache::<128>::new();
        for q in &queries {
            let bits = |mask: u32| -> Vec<usize> {
                (0..SKELETON_POINTS)
                    .filter(|i| mask & (1 << i) != 0)
                    .collect()
            };
            let mask = core.neighbourhood(&to32(*q));
            let core_set = bits(core.widened(mask));
            let ref_near = rf.nearest(*q);
            let ref_set = rf.widened(&ref_near);
            let got = core.map_point(&to32(*q), &mut cache).unwrap();
            let want = rf.map(*q).unwrap();
            if bits(mask) != ref_near {
                differing += 1;
                // Allowed only at a near-tie of the N_r-th distance.
                let mut d: Vec<f64> = rf.source.iter().map(|s| r::dist2(*s, *q)).collect();
                d.sort_by(f64::total_cmp);
                let k = *nr;
                assert!(
                    (d[k] - d[k - 1]).abs() < 1e-3,
                    "{name}: neighbourhoods of {q:?} differ without a tie"
                );
                continue;
            }
            assert_eq!(core_set, ref_set, "{name}: widened neighbourhood of {q:?}");
            widened += usize::from(core_set.len() > *nr);
            let centroid = r::mean(&ref_set.iter().map(|&i| rf.source[i]).collect::<Vec<_>>());
            let lever = r::dist(*q, centroid);
            let e = dist_mixed(&got, want);
            worst = worst.max(e);
            worst_rel = worst_rel.max(e / (1e-3 + 2e-4 * lever));
            assert!(
                e <= 1e-3 + 2e-4 * lever,
                "{name}: {q:?} maps {e} mm apart (lever arm {lever} mm)"
            );
        }
    }
    eprintln!(
        "local rigid: worst mapped difference {worst:.2e} mm ({worst_rel:.2} of the bound), \
         {differing} neighbourhood differences, {widened} widened neighbourhoods"
    );
}

/// The thin-plate spline of the improved mapping (core, `f32`, centred and scaled) against
/// the textbook `f64` solve (reference), on the skeleton pairs of registrations of
/// phantom-like clouds and a synthetic bend.
///
/// ```text
/// mapped points   atol 0.02 mm   (module docs of `math::spline`)
/// pairs           each source point within 0.01 mm of its target (both implementations)
/// measured: worst mapped difference 6.3e-4 mm, worst pair 3.5e-4 mm
/// ```
#[test]
fn thin_plate_agrees() {
    let tpl = Template::build(&cage(0.0), None, &Config::default()).unwrap();
    let mut pairs = vec![];
    for (k, stretch) in [0.0f32, 0.08, -0.1].iter().enumerate() {
        let us = moved_cage(
            *stretch,
            [0.3, 1.0, 0.2],
            15.0 * k as f64,
            [400.0, -8.0, 20.0],
        );
        let reg = register(&tpl, &us, &Config::default()).unwrap();
        pairs.push((tpl.skeleton.points, reg.skeleton.points));
    }
    // A bend no affine map follows: lateral ends stretched and lifted.
    let src = tpl.skeleton.points;
    let bent = src.map(|p| p + Vec3::new(0.1 * p.x * p.x.abs() / 100.0, 0.0, 3e-4 * p.x * p.x));
    pairs.push((src, bent));
    let queries = skeleton_queries(23);
    let (mut worst, mut worst_pair) = (0.0f64, 0.0f64);
    for (src, dst) in &pairs {
        let core = ThinPlate::fit(src, dst).unwrap();
        let rf = r::ThinPlate::fit(&cloud64(src), &cloud64(dst)).unwrap();
        for q in &queries {
            let e = dist_mixed(&core.apply(&to32(*q)), rf.apply(*q));
            assert!(e <= 0.02, "{q:?} maps {e} mm apart");
            worst = worst.max(e);
        }
        for (s, d) in src.iter().zip(dst) {
            let d64 = cloud64(core::slice::from_ref(d))[0];
            let s64 = cloud64(core::slice::from_ref(s))[0];
            let e = dist_mixed(&core.apply(s), d64).max(r::dist(rf.apply(s64), d64));
            assert!(e <= 0.01, "pair {s} → {d} missed by {e} mm");
            worst_pair = worst_pair.max(e);
        }
    }
    eprintln!(
        "thin-plate spline: worst mapped difference {worst:.1e} mm, worst pair {worst_pair:.1e} mm"
    );
}

/// ED (closest-point mean, population SD, max) and the symmetric Hausdorff distance,
/// k-d tree (core) vs brute force (reference).
///
/// ```text
/// mean, max, Hausdorff   atol 8ε·max|coord|, rtol 4ε   a distance of f32 points is
///                                                      computed with ≤ ½ulp error per
///                                                      difference plus 2ε relative
/// SD                     atol 8ε·max|coord| + 1e-6 mm  (1-Lipschitz in the distances;
///                                                      f64 E[d²] − E[d]² cancellation)
/// measured: worst 4.0e-5 mm (coordinates up to 1000 mm)
/// ```
#[test]
fn metrics_agree() {
    let mut worst = 0.0f64;
    for (k, (na, nb, off)) in [
        (300usize, 200usize, 0.0),
        (50, 400, 30.0),
        (1, 40, 5.0),
        (60, 1, 0.0),
        (120, 120, 900.0),
    ]
    .into_iter()
    .enumerate()
    {
        let a = f32_exact(&random_cloud(
            500 + k as u64,
            na,
            [off, 0.0, -off],
            [60.0, 40.0, 20.0],
        ));
        let b = f32_exact(&random_cloud(
            600 + k as u64,
            nb,
            [0.0, off / 2.0, 0.0],
            [60.0, 40.0, 20.0],
        ));
        let tol = 8.0 * EPS * max_abs_coord(&a).max(max_abs_coord(&b));
        let (mut a32, mut b32) = (cloud32(&a), cloud32(&b));
        let m = compare(&mut a32, &mut b32);
        let ed = r::ed(&a, &b);
        let h = r::hausdorff(&a, &b);
        for (what, got, want, atol) in [
            ("ED mean", m.ed.mean, ed.mean, tol),
            ("ED sd", m.ed.sd, ed.sd, tol + 1e-6),
            ("ED max", m.ed.max, ed.max, tol),
            ("Hausdorff", m.hausdorff, h, tol),
        ] {
            worst = worst.max((f64::from(got) - want).abs());
            assert_close(
                &format!("case {k}: {what}"),
                f64::from(got),
                want,
                4.0 * EPS,
                atol,
            );
        }
        assert_eq!(m.ed.count as usize, na);
        // Directed b → a with a fresh tree.
        let mut a32 = cloud32(&a);
        let tree = KdTree::build(&mut a32);
        let back = closest_distances(&cloud32(&b), &tree);
        assert_close(
            &format!("case {k}: directed b→a"),
            f64::from(back.max),
            r::ed(&b, &a).max,
            4.0 * EPS,
            tol,
        );
    }
    eprintln!("metrics: worst difference {worst:.2e} mm");
}

/// The endpoint rule given the same key points and tree: the core's key points, tree and
/// frame from `SkeletonGraph::build` on several clouds; the reference recomputes the MST
/// (must be the same tree), the hull and the four endpoints per side. Tolerance: exact.
#[test]
fn endpoint_rule_agrees() {
    let mut clouds = graph_clouds();
    let mut rng = r::Rng::new(77);
    let noisy: Vec<Vec3> = cage(0.02)
        .iter()
        .map(|p| {
            p + Vec3::new(
                rng.normal() as f32,
                rng.normal() as f32,
                rng.normal() as f32,
            )
        })
        .collect();
    clouds.push(("cage(0.02) + 1 mm noise", noisy, true));
    for (name, cloud, patient) in clouds {
        let which = if patient {
            ribreg_core::error::Cloud::Template
        } else {
            ribreg_core::error::Cloud::Target
        };
        let g = SkeletonGraph::build(&cloud, which, &Config::default(), patient).unwrap();
        let rg = graph_to_ref(&g);
        assert_eq!(core_edges(&g.tree), rg.tree.edges(), "{name}: tree");
        let core_hull: Vec<usize> = g.hull.iter().map(|&i| usize::from(i)).collect();
        assert_eq!(core_hull, rg.hull, "{name}: hull");
        let ends = r::select_endpoints(&rg.key_points, &rg.tree, &rg.uv, &rg.hull);
        assert_eq!(rg.endpoints, ends, "{name}: endpoints (core, reference)");
        assert!(ends.is_ok(), "{name}: the endpoint rule fails: {ends:?}");
        assert_close(
            &format!("{name}: midline"),
            f64::from(g.midline),
            rg.midline,
            0.0,
            1e-4,
        );
    }
}

/// Eq. 4 on random 3-D polylines (with repeated points) at several thresholds: identical
/// kept indices, except where a turn angle is within 1e-3° of the threshold (none is, in
/// these draws — the test would report it).
#[test]
fn turn_filter_agrees() {
    let mut rng = r::Rng::new(9);
    let mut kept_total = 0;
    for case in 0..300 {
        let n = 2 + case % 39;
        let mut pts: Vec<P3> = vec![[0.0; 3]];
        let mut dir = [1.0, 0.0, 0.0];
        for _ in 1..n {
            let turn = [rng.normal(), rng.normal(), rng.normal()];
            dir = r::add(dir, r::scale(turn, rng.uniform(0.0, 1.5)));
            let step = if rng.unit() < 0.05 {
                0.0
            } else {
                rng.uniform(2.0, 15.0)
            };
            let last = pts[pts.len() - 1];
            pts.push(r::add(last, r::scale(dir, step / r::norm(dir))));
        }
        let pts = f32_exact(&pts);
        let p32 = cloud32(&pts);
        let path: Vec<usize> = (0..n).collect();
        let path8: Vec<u8> = path.iter().map(|&i| i as u8).collect();
        for deg in [30.0f64, 60.0, 90.0, 150.0, 180.0] {
            let mut out = heapless::Vec::<u8, 64>::new();
            turn_filter(&p32, &path8, libm_cos_deg(deg), &mut out);
            let got: Vec<usize> = out.iter().map(|&i| usize::from(i)).collect();
            let want = r::turn_filter(&pts, &path, deg);
            if got != want {
                let first = got
                    .iter()
                    .zip(&want)
                    .position(|(a, b)| a != b)
                    .unwrap_or(got.len().min(want.len()));
                panic!(
                    "case {case}, T {deg}: kept {got:?} vs {want:?} (first difference at {first})"
                );
            }
            kept_total += got.len();
        }
    }
    eprintln!("turn filter: 1500 paths, {kept_total} points kept, all identical");
}

/// `cos(deg)` as the core computes its threshold (`libm::cosf(deg.to_radians())` in f32).
fn libm_cos_deg(deg: f64) -> f32 {
    (deg as f32).to_radians().cos()
}

/// Paths, Eq. 4, cubic fit and resampling (`RibSkeleton::build`) on the same graph: the
/// core's cage graph, and hand-made skeleton-like key points with a Prim tree.
///
/// ```text
/// kept paths, degrees   identical
/// 30 points             atol 0.05 mm     the fit's f32 error, which grows with the
///                                        clustering of the kept abscissae (see
///                                        polyfit_clustered_abscissae), plus the frame
///                                        round trip (1e-6 relative)
/// measured: 3.9e-5 mm (core 22266f9); at e05cb20 1.04e-2 mm (cage rib 3: 4 kept
///           points, two 1.2 mm apart in x), ≤ 1.1e-4 mm on every other rib
/// ```
#[test]
fn rib_skeleton_agrees() {
    let tpl = Template::build(&cage(0.0), None, &Config::default()).unwrap();
    let mut graphs = vec![(
        "cage".to_string(),
        tpl.graph.clone(),
        tpl.ends.expect("graph rib model"),
    )];
    for seed in 1..=4 {
        // Replace the key points of a cloned graph by a skeleton-like set: four chains
        // per side (ends are the chains' lateral tips) and a sternum chain.
        let kp = cloud32(&f32_exact(&skeleton_like(seed)));
        let mut g = tpl.graph.clone();
        g.key_points.clear();
        for p in &kp {
            g.key_points.push(*p).unwrap();
        }
        g.tree = Tree::prim(&kp).unwrap();
        g.frame = Frame::principal(&kp, 0).unwrap().oriented_to_patient();
        let mut ends = [[0u8; 2]; 4];
        let mut k = 4;
        for (rib, e) in ends.iter_mut().enumerate() {
            let per_side = 4 + rib / 2;
            *e = [(k + per_side - 1) as u8, (k + 2 * per_side - 1) as u8];
            k += 2 * per_side;
        }
        graphs.push((format!("skeleton-like {seed}"), g, RibEnds(ends)));
    }
    let mut worst = 0.0f64;
    for (name, g, ends) in &graphs {
        let rg = graph_to_ref(g);
        let rends = ends.0.map(|e| e.map(usize::from));
        for deg in [30.0f32, 60.0, 90.0, 180.0] {
            let cfg = Config {
                turn_angle_deg: deg,
                ..Config::default()
            };
            let rcfg = r::Config {
                turn_angle_deg: f64::from(deg),
                ..r::Config::default()
            };
            let core = RibSkeleton::build(g, ends, &cfg, ribreg_core::error::Cloud::Template);
            let rf = r::rib_skeleton(&rg, &rends, &rcfg);
            match (core, rf) {
                (Ok(c), Ok(f)) => {
                    for rib in 0..4 {
                        let got: Vec<usize> =
                            c.paths[rib].iter().map(|&v| usize::from(v)).collect();
                        assert_eq!(got, f.paths[rib], "{name} T {deg}: rib {} path", rib + 2);
                        assert_eq!(usize::from(c.degree[rib]), f.degree[rib]);
                    }
                    let e = max_pair_dist(&c.points, &f.points);
                    worst = worst.max(e);
                    assert!(e <= 0.05, "{name} T {deg}: skeleton points {e} mm apart");
                }
                (
                    Err(ribreg_core::Error::RibPath { rib, found, .. }),
                    Err(r::RefError::RibPath { rib: rr, found: rf }),
                ) => {
                    assert_eq!((rib, usize::from(found)), (rr, rf), "{name} T {deg}");
                }
                (c, f) => panic!(
                    "{name} T {deg}: core {:?} vs reference {:?}",
                    c.err(),
                    f.err()
                ),
            }
        }
    }
    eprintln!("rib skeleton: worst point difference {worst:.2e} mm");
}

/// Template rib ends from labels (most lateral key point of each rib and side) and from
/// the endpoint rule (cranio-caudal), on the core's graphs. Exact.
#[test]
fn template_rib_order_agrees() {
    for stretch in [0.0f32, 0.1, -0.05] {
        let cloud = cage(stretch);
        let labels = cage_labels(stretch);
        let g = SkeletonGraph::build(
            &cloud,
            ribreg_core::error::Cloud::Template,
            &Config::default(),
            true,
        )
        .unwrap();
        let rg = graph_to_ref(&g);
        let c64 = cloud64(&cloud);
        for labels in [None, Some(labels.as_slice())] {
            // Equal ends, or the same refusal (the paper's rule contradicts the labels on
            // some cages, see pipeline.rs).
            let core = RibEnds::from_template(&g, &cloud, labels)
                .map(|e| e.0.map(|e| e.map(usize::from)))
                .map_err(ref_error);
            let rf = r::template_rib_ends(&rg, &c64, labels);
            assert_eq!(core, rf, "stretch {stretch}, labels {}", labels.is_some());
        }
    }
}

/// Endpoint matching (five-start coarse ICP + optimal-assignment endpoint ICP) on the
/// same graphs (the core's key points, frames and endpoints).
///
/// ```text
/// matched rib ends   identical
/// pose rotation      atol 1e-3 per element   30 ICP rounds × Kabsch (1e-4 each) on
/// pose translation   atol 0.05 mm            converged pairings; lever arm ~100 mm
/// coarse, endpoint RMS  rtol 1e-3, atol 1e-3 mm
/// assignment         identical to the exhaustive 8! search on random costs
/// measured: R 5.2e-7, t 3.3e-5 mm, RMS 1.3e-5 mm
/// ```
#[test]
fn endpoint_matching_agrees() {
    let tpl = Template::build(&cage(0.0), None, &Config::default()).unwrap();
    let rtpl = graph_to_ref(&tpl.graph);
    let tpl_ends = tpl.ends.expect("graph rib model");
    let rends = tpl_ends.0.map(|e| e.map(usize::from));
    let (mut wr, mut wt, mut wrms) = (0.0f64, 0.0f64, 0.0f64);
    for (name, cloud, _) in graph_clouds() {
        let g = SkeletonGraph::build(
            &cloud,
            ribreg_core::error::Cloud::Target,
            &Config::default(),
            false,
        )
        .unwrap();
        let core = match_endpoints(&g, &tpl.graph, &tpl_ends).unwrap();
        let rf = r::match_endpoints(&graph_to_ref(&g), &rtpl, &rends).unwrap();
        assert_eq!(
            core.ends.0.map(|e| e.map(usize::from)),
            rf.ends,
            "{name}: matched ends"
        );
        let pose = rigid_to64(&core.pose);
        let (dr, dt) = (
            mat_max_diff(&pose.r, &rf.pose.r),
            r::dist(pose.t, rf.pose.t),
        );
        wr = wr.max(dr);
        wt = wt.max(dt);
        assert!(
            dr <= 1e-3 && dt <= 0.05,
            "{name}: pose differs by R {dr}, t {dt} mm"
        );
        for (what, got, want) in [
            ("coarse", core.coarse_rms, rf.coarse_rms),
            ("endpoint", core.endpoint_rms, rf.endpoint_rms),
        ] {
            assert_close(
                &format!("{name}: {what} RMS"),
                f64::from(got),
                want,
                1e-3,
                1e-3,
            );
            wrms = wrms.max((f64::from(got) - want).abs());
        }
    }
    let mut rng = r::Rng::new(12);
    for _ in 0..50 {
        let cost: [[f64; 8]; 8] = std::array::from_fn(|_| {
            std::array::from_fn(|_| f64::from(rng.uniform(0.0, 100.0) as f32))
        });
        let c32: [[f32; 8]; 8] = cost.map(|row| row.map(|v| v as f32));
        let (a, total) = best_assignment(&c32);
        let (ra, rtotal) = r::best_assignment(&cost);
        assert_eq!(a.map(usize::from), ra);
        assert_close("assignment cost", f64::from(total), rtotal, 8.0 * EPS, 0.0);
    }
    eprintln!("endpoint matching: max |ΔR| {wr:.2e}, |Δt| {wt:.2e} mm, |ΔRMS| {wrms:.2e} mm");
}

/// The reference's parameters are the core's (a guard against silent drift).
#[test]
fn reference_constants_match_the_core() {
    let same = |c: &SomConfig, p: &r::SomParams| {
        (c.rows, c.cols)
            == if p.seed == r::SOM1.seed {
                (20, 20)
            } else {
                (5, 8)
            }
            && c.iterations == p.iterations
            && c.lr_start == p.lr_start as f32
            && c.lr_end == p.lr_end as f32
            && c.radius_start == p.radius_start as f32
            && c.radius_end == p.radius_end as f32
            && c.seed == p.seed
    };
    assert!(same(&SomConfig::SOM1, &r::SOM1));
    assert!(same(&SomConfig::SOM2, &r::SOM2));
    let cfg = Config::default();
    assert_eq!(cfg.turn_angle_deg, r::TURN_ANGLE_DEG as f32);
    assert_eq!(cfg.neighbours, r::NEIGHBOURS);
    assert_eq!(ribreg_core::config::RIB_SAMPLES, r::RIB_SAMPLES);
    assert_eq!(ribreg_core::config::RIBS, r::RIBS);
    assert_eq!(
        ribreg_core::config::LATERAL_FRACTION,
        r::LATERAL_FRACTION as f32
    );
    assert_eq!(
        ribreg_core::registration::local_rigid::MIN_CROSS_SPREAD,
        r::MIN_CROSS_SPREAD as f32
    );
    assert_eq!(ribreg_core::math::geom::PCA_SAMPLE, r::PCA_SAMPLE);
    assert_eq!(ribreg_core::limits::LIVE_SAMPLES, r::LIVE_SAMPLES);
    assert_eq!(
        ribreg_core::registration::endpoints::COARSE_ITERATIONS,
        r::COARSE_ITERATIONS
    );
    assert_eq!(
        ribreg_core::registration::endpoints::ENDPOINT_ITERATIONS,
        r::ENDPOINT_ITERATIONS
    );
    assert_eq!(
        ribreg_core::registration::skeleton::MIN_KEY_POINTS,
        r::MIN_KEY_POINTS
    );
    // The reference implements the paper's graph rib model only.
    assert_eq!(cfg.rib_model, ribreg_core::config::RibModel::Graph);
}
