//! Shared helpers of the host tests: `f32` ↔ `f64` conversion, the labelled built-in cage
//! and its waypoints, rigid motions, and tolerance checks.

use crate::reference::{self as r, P3};
use ribreg_core::math::geom::Rigid;
use ribreg_core::Vec3;

/// `f32` point → `f64`.
pub fn to64(p: &Vec3) -> P3 {
    [f64::from(p.x), f64::from(p.y), f64::from(p.z)]
}

/// `f64` point → `f32` (rounded to nearest).
pub fn to32(p: P3) -> Vec3 {
    Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32)
}

/// A cloud → `f64`.
pub fn cloud64(points: &[Vec3]) -> Vec<P3> {
    points.iter().map(to64).collect()
}

/// A cloud → `f32`.
pub fn cloud32(points: &[P3]) -> Vec<Vec3> {
    points.iter().map(|p| to32(*p)).collect()
}

/// Distance between an `f32` and an `f64` point, in `f64`.
pub fn dist_mixed(a: &Vec3, b: P3) -> f64 {
    r::dist(to64(a), b)
}

/// The built-in cage `ribreg_core::registration::example::cage(stretch)`.
pub fn cage(stretch: f32) -> Vec<Vec3> {
    ribreg_core::registration::example::cage(stretch).collect()
}

/// Cartilage lengths of the built-in cage, ribs 2..5 (mm; copied from `core/src/example.rs`).
const RIB_LEN: [f32; 4] = [60.0, 70.0, 82.0, 95.0];
/// Rib heights at the sternum (mm).
const RIB_Y: [f32; 4] = [0.0, -31.6, -57.7, -81.9];
/// Rib slopes.
const RIB_SLOPE: [f32; 4] = [0.05, 0.12, 0.2, 0.28];

/// Per-point labels of `cage(stretch)`: 1 for the sternum, 2..5 for the rib cartilages.
/// The cage emits the sternum (36 × 9 × 2 points) and then the eight cartilages in the
/// order rib 2 left, rib 2 right, …, each as `(⌊len/3⌋ + 1) × 8` points; this function
/// reproduces those counts and checks the total.
pub fn cage_labels(stretch: f32) -> Vec<u8> {
    let mut labels = vec![1u8; 36 * 9 * 2];
    for k in 0..8 {
        let rib = k / 2;
        let len = RIB_LEN[rib] * (1.0 + stretch);
        let steps = (len / 3.0) as usize;
        labels.extend(std::iter::repeat_n(rib as u8 + 2, (steps + 1) * 8));
    }
    assert_eq!(
        labels.len(),
        ribreg_core::registration::example::cage(stretch).count(),
        "cage layout changed"
    );
    labels
}

/// The cage without the cartilages of `rib` (2..=5) on both sides, and its labels.
pub fn cage_without_rib(stretch: f32, rib: u8) -> (Vec<Vec3>, Vec<u8>) {
    cage(stretch)
        .into_iter()
        .zip(cage_labels(stretch))
        .filter(|(_, l)| *l != rib)
        .unzip()
}

/// Intercostal waypoints of the built-in cage: midway between consecutive ribs (2–3,
/// 3–4, 4–5), 10, 25 and 40 mm lateral of the sternum edge on both sides, 2 mm anterior
/// of the cartilage axis: 18 points.
pub fn cage_waypoints(stretch: f32) -> Vec<Vec3> {
    let mut out = Vec::new();
    for gap in 0..3 {
        for side in [-1.0f32, 1.0] {
            for d in [10.0f32, 25.0, 40.0] {
                let y = |rib: usize| RIB_Y[rib] - RIB_SLOPE[rib] * (1.0 - 0.5 * stretch) * d;
                let x = side * (13.0 + d);
                out.push(Vec3::new(
                    x,
                    0.5 * (y(gap) + y(gap + 1)),
                    -x * x / 300.0 + 2.0,
                ));
            }
        }
    }
    out
}

/// A core rigid transform from a rotation about `axis` by `deg` degrees and a translation.
pub fn rigid(axis: P3, deg: f64, t: P3) -> Rigid {
    let m = r::axis_angle(axis, deg.to_radians());
    let mut out = Rigid::identity();
    for (i, row) in m.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            out.rotation[(i, j)] = *v as f32;
        }
    }
    out.translation = to32(t);
    out
}

/// The same transform in `f64` (from the exact axis–angle, not from the `f32` matrix).
pub fn rigid64(axis: P3, deg: f64, t: P3) -> r::Rigid {
    r::Rigid {
        r: r::axis_angle(axis, deg.to_radians()),
        t,
    }
}

/// A core rigid transform → `f64`.
pub fn rigid_to64(t: &Rigid) -> r::Rigid {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = f64::from(t.rotation[(i, j)]);
        }
    }
    r::Rigid {
        r: m,
        t: to64(&t.translation),
    }
}

/// The reference frame → a core frame (`f32`).
pub fn frame_to32(f: &r::Frame) -> ribreg_core::math::geom::Frame {
    let mut out =
        ribreg_core::math::geom::Frame::principal(&[Vec3::zeros()], 0).expect("one point");
    out.origin = to32(f.origin);
    for k in 0..3 {
        for i in 0..3 {
            out.axes[(i, k)] = f.axes[k][i] as f32;
        }
        out.spread[k] = f.spread[k] as f32;
    }
    out
}

/// A core frame → `f64`.
pub fn frame_to64(f: &ribreg_core::math::geom::Frame) -> r::Frame {
    r::Frame {
        origin: to64(&f.origin),
        axes: std::array::from_fn(|k| std::array::from_fn(|i| f64::from(f.axes[(i, k)]))),
        spread: std::array::from_fn(|k| f64::from(f.spread[k])),
    }
}

/// `|got − want| ≤ atol + rtol·|want|` (numpy `isclose` with the reference as `b`).
pub fn close(got: f64, want: f64, rtol: f64, atol: f64) -> bool {
    (got - want).abs() <= atol + rtol * want.abs()
}

/// Asserts [`close`] with a message naming the quantity and the bound.
#[track_caller]
pub fn assert_close(what: &str, got: f64, want: f64, rtol: f64, atol: f64) {
    assert!(
        close(got, want, rtol, atol),
        "{what}: got {got}, want {want}, |diff| {} > atol {atol} + rtol {rtol} · |want|",
        (got - want).abs()
    );
}

/// Largest pointwise distance between paired `f32` and `f64` point lists.
pub fn max_pair_dist(a: &[Vec3], b: &[P3]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| dist_mixed(p, *q))
        .fold(0.0, f64::max)
}

/// Mean pointwise distance between paired `f32` and `f64` point lists.
pub fn mean_pair_dist(a: &[Vec3], b: &[P3]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(p, q)| dist_mixed(p, *q)).sum::<f64>() / a.len().max(1) as f64
}

/// A seeded random cloud, uniform in a box of the given half-extents around `centre`.
pub fn random_cloud(seed: u64, n: usize, centre: P3, half: P3) -> Vec<P3> {
    let mut rng = r::Rng::new(seed);
    (0..n)
        .map(|_| std::array::from_fn(|k| centre[k] + rng.uniform(-half[k], half[k])))
        .collect()
}

/// Forty rib-like skeleton key points (four curved chains per side and a sternum chain),
/// seeded 0.8 mm noise.
pub fn skeleton_like(seed: u64) -> Vec<P3> {
    let mut rng = r::Rng::new(seed);
    let mut out = Vec::new();
    for y in [5.0, -20.0, -45.0, -70.0] {
        out.push([rng.normal(), y + rng.normal(), 4.0]);
    }
    for (r, (&y0, &len)) in RIB_Y.iter().zip(&RIB_LEN).enumerate() {
        for side in [-1.0, 1.0] {
            for j in 0..(4 + r / 2) {
                let d = f64::from(len) * (0.1 + 0.9 * j as f64 / (3 + r / 2) as f64);
                let x = side * (13.0 + d);
                let y = f64::from(y0) - f64::from(RIB_SLOPE[r]) * d;
                out.push([
                    x + 0.8 * rng.normal(),
                    y + 0.8 * rng.normal(),
                    -x * x / 300.0 + 0.8 * rng.normal(),
                ]);
            }
        }
    }
    out.truncate(40);
    out
}

/// A core skeleton graph in reference form, on the *same* data: key points and SOM-1
/// nodes converted exactly, the core's frame and endpoints; the tree is the reference's
/// Prim on the same key points and the hull the reference's gift wrapping (use
/// [`core_edges`] to check that the trees agree).
pub fn graph_to_ref(g: &ribreg_core::registration::skeleton::SkeletonGraph) -> r::Graph {
    let key_points = cloud64(&g.key_points);
    let tree = r::Tree::prim(&key_points);
    let frame = frame_to64(&g.frame);
    let uv = r::project_uv(&key_points, &frame);
    let hull = r::gift_wrap(&uv);
    let midline = r::median_u(&uv);
    let endpoints = g
        .endpoints
        .map(|e| std::array::from_fn(|s| std::array::from_fn(|k| usize::from(e[s][k]))))
        .map_err(ref_error);
    r::Graph {
        som1: cloud64(&g.som1),
        key_points,
        tree,
        frame,
        uv,
        hull,
        midline,
        endpoints,
    }
}

/// The reference error kind corresponding to a core error (for comparing failures).
pub fn ref_error(e: ribreg_core::Error) -> r::RefError {
    use ribreg_core::Error as E;
    match e {
        E::Endpoints { side, found, .. } => r::RefError::Endpoints {
            side: usize::from(side),
            found: usize::from(found),
        },
        E::RibOrder { side, rib, found } => r::RefError::RibOrder {
            side: usize::from(side),
            rib,
            found: usize::from(found),
        },
        E::RibPath { rib, found, .. } => r::RefError::RibPath {
            rib,
            found: usize::from(found),
        },
        E::Degenerate { .. } => r::RefError::Degenerate,
        E::LabelCount { .. } => r::RefError::LabelCount,
        _ => r::RefError::RigidFit,
    }
}

/// Edges of a core tree as sorted `(min, max)` pairs.
pub fn core_edges<const N: usize>(t: &ribreg_core::math::mst::Tree<N>) -> Vec<(usize, usize)> {
    let mut e: Vec<(usize, usize)> = t.edges().map(|(a, b)| (a.min(b), a.max(b))).collect();
    e.sort_unstable();
    e
}

/// Smallest `d(i, j) − (longest edge on the tree path i..j)` over non-tree pairs: how far
/// the MST is from a tie (`+∞` when every pair is an edge).
pub fn mst_margin(points: &[P3], tree: &r::Tree) -> f64 {
    let edges = tree.edges();
    let mut margin = f64::INFINITY;
    for i in 0..points.len() {
        for j in i + 1..points.len() {
            if edges.binary_search(&(i, j)).is_ok() {
                continue;
            }
            let path = tree.path(i, j);
            let longest = path
                .windows(2)
                .map(|w| r::dist(points[w[0]], points[w[1]]))
                .fold(0.0, f64::max);
            margin = margin.min(r::dist(points[i], points[j]) - longest);
        }
    }
    margin
}

/// Points rounded to `f32` and back: inputs both implementations see identically.
pub fn f32_exact(points: &[P3]) -> Vec<P3> {
    points.iter().map(|p| to64(&to32(*p))).collect()
}
