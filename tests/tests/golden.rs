//! The core's geometric kernels against the golden vectors of `tests/fixtures/golden/`
//! (NumPy / SciPy, see `tests/golden/README.md` for the schemas and caveats).
//!
//! Tolerances are derived from `f32` precision at the data's magnitude. With
//! `u = 2⁻²⁴` (half an `f32` ulp, relative), `ε = 2u = f32::EPSILON` and `C` the largest
//! coordinate magnitude of a case:
//! - rounding a fixture coordinate to `f32` moves it by at most `u·C`, so a point by
//!   `√3·u·C` and a distance by at most `2√3·u·C = √3·ε·C`;
//! - one `f32` distance evaluation adds at most ~`2ε·d` (subtraction, squares, sum, root);
//! - an `f32` sum of `m` terms adds at most `m·u·Σ`.
//!
//! Kernels whose accuracy is not a matter of rounding alone (least squares, SVD) are held
//! to the core's documented contracts instead (`fit`: `1e-3·max|y| + 1e-3` mm; `kabsch`:
//! rotation 1e-4 per element, translation 1e-3 mm).
//! `cargo test -p ribreg-tests --test golden -- --nocapture` prints the measured errors.

use ribreg_core::math::fit::{equal_steps, Poly};
use ribreg_core::math::hull::{gift_wrap, Vec2};
use ribreg_core::math::kabsch;
use ribreg_core::math::mst::Tree;
use ribreg_core::registration::metrics::{closest_distances, compare, KdTree};
use ribreg_tests::reference::{self as r, P3};
use ribreg_tests::support::*;
use serde_json::Value;

const EPS: f64 = f32::EPSILON as f64;

fn cases(file: &str) -> Vec<Value> {
    let path = format!("{}/fixtures/golden/{file}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let v: Value = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"));
    let cases = v["cases"].as_array().expect("cases").clone();
    assert!(!cases.is_empty(), "{path}: no cases");
    cases
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn points3(v: &Value) -> Vec<P3> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|p| [f(&p[0]), f(&p[1]), f(&p[2])])
        .collect()
}

fn points2(v: &Value) -> Vec<[f64; 2]> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|p| [f(&p[0]), f(&p[1])])
        .collect()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().expect("array").iter().map(f).collect()
}

fn matrix(v: &Value) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| f(&v[i][j])))
}

fn max_abs(points: &[P3]) -> f64 {
    points.iter().flatten().fold(0.0f64, |m, c| m.max(c.abs()))
}

fn name(c: &Value) -> &str {
    c["name"].as_str().unwrap_or("?")
}

/// `Tree::prim`: total weight, edge count, and the edge set where the MST is unique by a
/// margin above the rounding.
///
/// ```text
/// weight   atol (n−1)·√3·ε·C + (n+3)·ε·W     per edge: input rounding √3·ε·C and 2ε·d
///                                            evaluation; the f32 sum of n−1 edges n·u·W
/// edges    identical set when uniqueness_margin > 2·(√3·ε·C + 2ε·d_max): rounding cannot
///          reorder two candidate edges (n2: one edge; n18_duplicates: ties, weight only)
/// measured: worst weight error 3.6e-4 mm (bound ≥ 5e-2 mm for the cases near 1000 mm)
/// ```
#[test]
fn mst_golden() {
    let mut worst = 0.0f64;
    for c in cases("mst.json") {
        let pts = points3(&c["points"]);
        let n = pts.len();
        let p32 = cloud32(&pts);
        let tree = Tree::<255>::prim(&p32).unwrap();
        let want = f(&c["total_weight"]);
        let got = f64::from(tree.weight(&p32));
        let big_c = max_abs(&pts);
        let atol = (n as f64 - 1.0) * 3f64.sqrt() * EPS * big_c + (n as f64 + 3.0) * EPS * want;
        worst = worst.max((got - want).abs());
        assert_close(&format!("{}: total weight", name(&c)), got, want, 0.0, atol);
        let count = c["edges"].as_u64().unwrap() as usize;
        assert_eq!(tree.edges().count(), count, "{}: edge count", name(&c));
        assert_eq!(count, n - 1);
        let golden: Vec<(usize, usize)> = c["tree_edges"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| {
                (
                    e[0].as_u64().unwrap() as usize,
                    e[1].as_u64().unwrap() as usize,
                )
            })
            .collect();
        let mut golden = golden;
        golden.sort_unstable();
        let d_max = golden
            .iter()
            .map(|&(a, b)| r::dist(pts[a], pts[b]))
            .fold(0.0, f64::max);
        let needed = 2.0 * (3f64.sqrt() * EPS * big_c + 2.0 * EPS * d_max);
        let compare_edges = match c["uniqueness_margin"].as_f64() {
            None => n == 2,
            Some(m) => m > needed,
        };
        if compare_edges {
            assert_eq!(core_edges(&tree), golden, "{}: edge set", name(&c));
        } else {
            assert_eq!(
                name(&c),
                "n18_duplicates",
                "only the duplicate case is expected to skip edges"
            );
        }
    }
    eprintln!("mst golden: worst weight error {worst:.2e} mm");
}

/// `hull::gift_wrap`: the vertices' coordinates equal qhull's up to a cyclic shift (both
/// counter-clockwise; qhull starts anywhere), the area matches.
///
/// ```text
/// vertex coordinates   exact: a core vertex is one of the f32 input points, i.e. the
///                      f32 rounding of the golden vertex (duplicates compare by value)
/// area                 atol ε·C·perimeter    rounding moves each edge by ≤ √3·u·C
/// ```
/// The collinear cases (square with edge points, 10×10 grid) are integers, exact in
/// `f32`, so the orientation tests are exact and only the corners are vertices.
#[test]
fn hull_golden() {
    for c in cases("hull.json") {
        let pts = points2(&c["points"]);
        let p32: Vec<Vec2> = pts
            .iter()
            .map(|p| Vec2::new(p[0] as f32, p[1] as f32))
            .collect();
        let mut out = heapless::Vec::<u16, 256>::new();
        gift_wrap(&p32, &mut out).unwrap();
        let got: Vec<Vec2> = out.iter().map(|&i| p32[usize::from(i)]).collect();
        let want: Vec<Vec2> = points2(&c["vertex_points"])
            .iter()
            .map(|p| Vec2::new(p[0] as f32, p[1] as f32))
            .collect();
        assert_eq!(
            got.len(),
            want.len(),
            "{}: vertex count {got:?} vs {want:?}",
            name(&c)
        );
        let shift = got
            .iter()
            .position(|v| *v == want[0])
            .unwrap_or_else(|| panic!("{}: {:?} is not a vertex", name(&c), want[0]));
        for (k, w) in want.iter().enumerate() {
            assert_eq!(
                got[(k + shift) % got.len()],
                *w,
                "{}: vertex {k} (cyclic shift {shift})",
                name(&c)
            );
        }
        let area = 0.5
            * (0..got.len())
                .map(|k| {
                    let (a, b) = (got[k], got[(k + 1) % got.len()]);
                    f64::from(a.x) * f64::from(b.y) - f64::from(b.x) * f64::from(a.y)
                })
                .sum::<f64>();
        let big_c = pts.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        assert_close(
            &format!("{}: area", name(&c)),
            area,
            f(&c["area"]),
            0.0,
            EPS * big_c * f(&c["perimeter"]),
        );
    }
}

/// `fit::Poly::fit` + `eval` at `x_eval` vs `numpy.polyval`, and `fit::equal_steps` vs
/// `x_eval` (`numpy.linspace`).
///
/// ```text
/// values      atol 1e-3·max|y| + 1e-3 mm     the core's documented contract
/// abscissae   atol 4ε·max|x|                 one f32 multiply-add per step
/// measured: worst |Δy| 7.4e-5 mm
/// ```
#[test]
fn polyfit_golden() {
    let mut worst = 0.0f64;
    for c in cases("polyfit.json") {
        let x = floats(&c["x"]);
        let y = floats(&c["y"]);
        let deg = c["degree"].as_u64().unwrap() as usize;
        let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let y32: Vec<f32> = y.iter().map(|&v| v as f32).collect();
        let p = Poly::fit(&x32, &y32, deg).unwrap_or_else(|e| panic!("{}: {e}", name(&c)));
        let x_eval = floats(&c["x_eval"]);
        let y_eval = floats(&c["y_eval"]);
        let ymax = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let xmax = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let lo = x32.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = x32.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let steps: Vec<f32> = equal_steps(lo, hi, x_eval.len()).collect();
        for ((&xe, &ye), &xs) in x_eval.iter().zip(&y_eval).zip(&steps) {
            assert_close(
                &format!("{}: equal_steps", name(&c)),
                f64::from(xs),
                xe,
                0.0,
                4.0 * EPS * xmax,
            );
            let got = f64::from(p.eval(xe as f32));
            worst = worst.max((got - ye).abs());
            assert_close(
                &format!("{}: y({xe})", name(&c)),
                got,
                ye,
                0.0,
                1e-3 * ymax + 1e-3,
            );
        }
    }
    eprintln!("polyfit golden: worst |Δy| {worst:.2e} mm");
}

/// `kabsch::fit` vs SciPy's `align_vectors`.
///
/// ```text
/// every case        R proper: |det − 1| ≤ 1e-4, ‖RᵀR − I‖max ≤ 1e-4
///                   rmsd (core transform, f64 data) ≤ golden rmsd + 1e-3 mm + 2·h
///                   h: the cross spread of a for nearly_collinear, else 0
/// well-determined   rotation      atol 1e-4 per element (contract)
///                   translation   atol 1e-3 mm + 1e-4·|ā|   (R's error times the
///                                 centroid distance: far_from_origin has |ā| ≈ 1250 mm)
///                   mapped points atol 1e-3 mm + 1e-4·max|a − ā|
/// nearly_collinear  h_sv ≈ [1.8e4, 0.03, 0.014]: σ₂/σ₁ < ε, R about the line is not
///                   determined in f32 — mapped points atol 1e-3 mm + 2·h only
/// reflection_trap   det +1 (not the mirror), rmsd 12.1976 mm rtol 1e-5
/// measured: worst R 2.8e-7, t 3.2e-4 mm; nearly_collinear mapped 1.8e-2 mm (h = 0.067 mm)
/// ```
#[test]
fn kabsch_golden() {
    let (mut wr, mut wt) = (0.0f64, 0.0f64);
    for c in cases("kabsch.json") {
        let nm = name(&c).to_string();
        let a = points3(&c["a"]);
        let b = points3(&c["b"]);
        let fit = kabsch::fit(&cloud32(&a), &cloud32(&b)).unwrap_or_else(|e| panic!("{nm}: {e}"));
        let core = rigid_to64(&fit);
        let rot = matrix(&c["rotation"]);
        let t = floats(&c["translation"]);
        let golden = r::Rigid {
            r: rot,
            t: [t[0], t[1], t[2]],
        };
        let det = r::dot(core.r[0], r::cross(core.r[1], core.r[2]));
        assert!((det - 1.0).abs() <= 1e-4, "{nm}: det {det}");
        let rtr = r::mat_mul(&r::transpose(&core.r), &core.r);
        for (i, row) in rtr.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((v - want).abs() <= 1e-4, "{nm}: RᵀR[{i}][{j}] = {v}");
            }
        }
        let ca = r::mean(&a);
        let extent = a.iter().map(|p| r::dist(*p, ca)).fold(0.0, f64::max);
        let collinear = nm == "nearly_collinear";
        let h = if collinear {
            let (_, cov) = r::covariance(&a);
            let (ev, _) = r::sorted_eigen3(cov);
            (ev[1] + ev[2]).sqrt()
        } else {
            0.0
        };
        let rmsd = r::rmsd(&core, &a, &b);
        assert!(
            rmsd <= f(&c["rmsd"]) + 1e-3 + 2.0 * h,
            "{nm}: rmsd {rmsd} vs {}",
            f(&c["rmsd"])
        );
        let mapped = a
            .iter()
            .map(|p| r::dist(core.apply(*p), golden.apply(*p)))
            .fold(0.0, f64::max);
        if collinear {
            assert!(
                mapped <= 1e-3 + 2.0 * h,
                "{nm}: mapped points {mapped} mm apart (h = {h})"
            );
            eprintln!("kabsch golden {nm}: mapped {mapped:.2e} mm, h {h:.2e} mm");
            continue;
        }
        let dr = (0..9)
            .map(|k| (core.r[k / 3][k % 3] - rot[k / 3][k % 3]).abs())
            .fold(0.0, f64::max);
        let dt = r::dist(core.t, golden.t);
        wr = wr.max(dr);
        wt = wt.max(dt);
        assert!(dr <= 1e-4, "{nm}: rotation off by {dr}");
        assert!(
            dt <= 1e-3 + 1e-4 * r::norm(ca),
            "{nm}: translation off by {dt} mm (|ā| {})",
            r::norm(ca)
        );
        assert!(
            mapped <= 1e-3 + 1e-4 * extent,
            "{nm}: mapped points {mapped} mm apart"
        );
        if nm == "reflection_trap" {
            assert_close("reflection_trap rmsd", rmsd, f(&c["rmsd"]), 1e-5, 0.0);
            assert!(
                f(&c["orthogonal_best_rmsd"]) < 1e-6,
                "the mirror would fit exactly"
            );
        }
    }
    eprintln!("kabsch golden: worst |ΔR| {wr:.2e}, |Δt| {wt:.2e} mm");
}

/// `metrics::compare` (ED mean / SD / max, Hausdorff) and `metrics::closest_distances`
/// (directed b → a) vs SciPy.
///
/// ```text
/// distances (mean, max, directed, Hausdorff)   atol √3·ε·C + 2ε·d
/// SD                                           same + 1e-6 mm (1-Lipschitz in the
///                                              distances; f64 E[d²] − E[d]²)
/// measured: worst 1.2e-5 mm (coordinates ≤ 300 mm)
/// ```
#[test]
fn hausdorff_golden() {
    let mut worst = 0.0f64;
    for c in cases("hausdorff.json") {
        let nm = name(&c);
        let a = points3(&c["a"]);
        let b = points3(&c["b"]);
        let big_c = max_abs(&a).max(max_abs(&b));
        let tol = |d: f64| 3f64.sqrt() * EPS * big_c + 2.0 * EPS * d;
        let (mut a32, mut b32) = (cloud32(&a), cloud32(&b));
        let m = compare(&mut a32, &mut b32);
        let mut a32 = cloud32(&a);
        let tree = KdTree::build(&mut a32);
        let back = closest_distances(&cloud32(&b), &tree);
        for (what, got, key, extra) in [
            ("ED mean", m.ed.mean, "ed_mean", 0.0),
            ("ED sd", m.ed.sd, "ed_sd", 1e-6),
            ("ED max", m.ed.max, "ed_max", 0.0),
            ("directed a→b", m.ed.max, "directed_ab", 0.0),
            ("directed b→a", back.max, "directed_ba", 0.0),
            ("Hausdorff", m.hausdorff, "hausdorff", 0.0),
        ] {
            let want = f(&c[key]);
            worst = worst.max((f64::from(got) - want).abs());
            assert_close(
                &format!("{nm}: {what}"),
                f64::from(got),
                want,
                0.0,
                tol(want) + extra,
            );
        }
        assert_eq!(m.ed.count as usize, a.len());
        if nm == "identical" {
            assert_eq!(
                (m.ed.mean, m.ed.sd, m.ed.max, m.hausdorff),
                (0.0, 0.0, 0.0, 0.0)
            );
        }
    }
    eprintln!("hausdorff golden: worst difference {worst:.2e} mm");
}

/// The core's k-d tree and the reference's brute force on the golden clouds: the same
/// closest-point distances, point by point (ED is exact, nothing is subsampled).
#[test]
fn hausdorff_golden_pointwise() {
    for c in cases("hausdorff.json") {
        let a = points3(&c["a"]);
        let b = points3(&c["b"]);
        let big_c = max_abs(&a).max(max_abs(&b));
        let (a32, mut b32) = (cloud32(&a), cloud32(&b));
        let tree = KdTree::build(&mut b32);
        // The reference on the same (f32-rounded) points.
        let d = r::closest_distances(&f32_exact(&a), &f32_exact(&b));
        for (p, want) in a32.iter().zip(d) {
            let got = f64::from(tree.nearest_sq(p)).sqrt();
            assert_close(name(&c), got, want, 4.0 * EPS, 4.0 * EPS * big_c);
        }
    }
}

/// A sanity check of the fixtures themselves: the reference reproduces them in f64.
#[test]
fn reference_reproduces_the_golden_vectors() {
    for c in cases("mst.json") {
        let pts = points3(&c["points"]);
        assert_close(
            name(&c),
            r::Tree::prim(&pts).weight(&pts),
            f(&c["total_weight"]),
            1e-12,
            1e-9,
        );
    }
    for c in cases("kabsch.json") {
        let (a, b) = (points3(&c["a"]), points3(&c["b"]));
        let fit = r::kabsch(&a, &b).unwrap();
        assert_close(name(&c), r::rmsd(&fit, &a, &b), f(&c["rmsd"]), 1e-9, 1e-9);
    }
    for c in cases("polyfit.json") {
        let (x, y) = (floats(&c["x"]), floats(&c["y"]));
        let p = r::Poly::fit(&x, &y, c["degree"].as_u64().unwrap() as usize).unwrap();
        for (xe, ye) in floats(&c["x_eval"]).into_iter().zip(floats(&c["y_eval"])) {
            assert_close(name(&c), p.eval(xe), ye, 1e-9, 1e-9);
        }
    }
    for c in cases("hull.json") {
        let pts = points2(&c["points"]);
        let hull = r::gift_wrap(&pts);
        assert_eq!(
            hull.len(),
            c["vertices"].as_array().unwrap().len(),
            "{}",
            name(&c)
        );
    }
    for c in cases("hausdorff.json") {
        let (a, b) = (points3(&c["a"]), points3(&c["b"]));
        assert_close(
            name(&c),
            r::hausdorff(&a, &b),
            f(&c["hausdorff"]),
            1e-12,
            1e-9,
        );
        let ed = r::ed(&a, &b);
        assert_close(name(&c), ed.sd, f(&c["ed_sd"]), 1e-9, 1e-9);
    }
}
