//! Unit tests of the baselines (synthetic clouds, a few seconds each in the dev profile).
//! The phantom evaluation and the comparison-data export are `#[ignore]`d, see `eval.rs`.

use super::*;
use ribreg_core::math::rng::Rng;

/// A bumpy, asymmetric open surface patch (mm), `n` seeded random points.
fn surface(n: usize, seed: u64) -> Vec<P3> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let x = rng.next_f64() * 120.0 - 60.0;
            let y = rng.next_f64() * 80.0 - 40.0;
            let z = 10.0 * (x / 25.0).sin() * (y / 20.0).cos() + 0.004 * x * x + 0.05 * y;
            [x, y, z]
        })
        .collect()
}

/// Rotation by `deg` about the unit-normalised `axis`, then translation `t`.
fn rigid(axis: P3, deg: f64, t: P3) -> Rigid {
    let n = dot(axis, axis).sqrt();
    let [x, y, z] = scale(axis, 1.0 / n);
    let (s, c) = deg.to_radians().sin_cos();
    let k = 1.0 - c;
    Rigid {
        rotation: [
            [c + x * x * k, x * y * k - z * s, x * z * k + y * s],
            [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
            [z * x * k - y * s, z * y * k + x * s, c + z * z * k],
        ],
        translation: t,
    }
}

fn max_err(a: &[P3], b: &[P3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| dist2(*p, *q).sqrt())
        .fold(0.0, f64::max)
}

fn mean_err(a: &[P3], b: &[P3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| dist2(*p, *q).sqrt())
        .sum::<f64>()
        / a.len() as f64
}

/// Mean distance from each point of `a` to its closest point of `b`.
fn mean_closest(a: &[P3], b: &[P3]) -> f64 {
    let tree = kdtree::KdTree::new(b);
    a.iter()
        .map(|p| tree.nearest(p).map_or(f64::INFINITY, |(_, d2)| d2.sqrt()))
        .sum::<f64>()
        / a.len() as f64
}

fn rotation_err(a: &Rigid, b: &Rigid) -> f64 {
    let mut e: f64 = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            e = e.max((a.rotation[i][j] - b.rotation[i][j]).abs());
        }
        e = e.max((a.translation[i] - b.translation[i]).abs());
    }
    e
}

/// A smooth non-rigid warp (mm): a bend of a few mm plus a small rigid motion.
fn warp(p: P3) -> P3 {
    let [x, y, z] = p;
    rigid([0.2, 0.1, 1.0], 2.0, [1.5, -1.0, 2.0]).apply([
        x + 3.0 * (y / 40.0).sin(),
        y + 2.0 * (x / 60.0).cos(),
        z + 6.0 * (x / 50.0).sin() + 0.001 * x * y,
    ])
}

#[test]
fn method_names_are_stable() {
    let names: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
    assert_eq!(names, ["icp", "cpd_rigid", "cpd_nonrigid", "nricp"]);
    assert_eq!(Method::NonRigidIcp.to_string(), "nricp");
}

#[test]
fn icp_recovers_small_rigid_motion_exactly() {
    let src = surface(800, 1);
    let truth = rigid([0.3, -0.5, 1.0], 4.0, [3.0, -2.0, 1.5]);
    let dst: Vec<P3> = src.iter().map(|&p| truth.apply(p)).collect();
    let r = icp::fit(&src, &dst, &icp::IcpParams::default()).unwrap();
    assert!(r.report.converged, "{:?}", r.report);
    assert!(
        rotation_err(&r.transform, &truth) < 1e-6,
        "{:?}",
        r.transform
    );
    assert!(max_err(&r.map_all(&src), &dst) < 1e-6);
    assert!(r.report.final_error < 1e-6);
    // The RMS never increases (ICP's monotonicity).
    for w in r.rms_history.windows(2) {
        assert!(w[1] <= w[0] + 1e-9, "{:?}", r.rms_history);
    }
}

#[test]
fn cpd_rigid_recovers_motion_with_and_without_outliers() {
    let src = surface(500, 2);
    let truth = rigid([0.1, 1.0, 0.2], 6.0, [4.0, 2.0, -3.0]);
    let mut dst: Vec<P3> = src.iter().map(|&p| truth.apply(p)).collect();
    let params = cpd::RigidParams {
        tolerance: 1e-12,
        max_iterations: 300,
        ..Default::default()
    };
    let r = cpd::fit_rigid(&src, &dst, &params).unwrap();
    assert!(rotation_err(&r.transform, &truth) < 1e-6, "{:?}", r.report);
    assert!(max_err(&r.map_all(&src), &dst[..src.len()]) < 1e-6);

    // 10 % uniform outliers in the (expanded) bounding box of the target.
    let mut rng = Rng::new(7);
    let n_out = src.len() / 10;
    for _ in 0..n_out {
        dst.push([
            rng.next_f64() * 160.0 - 80.0,
            rng.next_f64() * 120.0 - 60.0,
            rng.next_f64() * 60.0 - 30.0,
        ]);
    }
    let r = cpd::fit_rigid(&src, &dst, &params).unwrap();
    assert!(rotation_err(&r.transform, &truth) < 1e-6, "{:?}", r.report);
    assert!(max_err(&r.map_all(&src), &dst[..src.len()]) < 1e-6);
}

#[test]
fn cpd_rigid_default_params_converge_on_noisy_copy() {
    let src = surface(400, 3);
    let truth = rigid([1.0, 0.0, 0.3], 3.0, [2.0, 2.0, 2.0]);
    let mut rng = Rng::new(9);
    let dst: Vec<P3> = src
        .iter()
        .map(|&p| add(truth.apply(p), [0, 1, 2].map(|_| rng.next_f64() - 0.5)))
        .collect();
    let r = run(Method::CpdRigid, &src, &dst).unwrap();
    assert!(r.report().converged);
    assert_eq!(r.report().method, Method::CpdRigid);
    let truth_pts: Vec<P3> = src.iter().map(|&p| truth.apply(p)).collect();
    assert!(mean_err(&r.map_all(&src), &truth_pts) < 0.1);
}

fn small_nonrigid_params() -> cpd::NonRigidParams {
    cpd::NonRigidParams {
        max_control_points: 300,
        ..Default::default()
    }
}

#[test]
fn cpd_nonrigid_fits_warped_copy_and_keeps_rigid_copy_rigid() {
    let src = surface(600, 4);
    let dst: Vec<P3> = src.iter().map(|&p| warp(p)).collect();
    let before = mean_closest(&src, &dst);
    let r = cpd::fit_nonrigid(&src, &dst, &small_nonrigid_params()).unwrap();
    assert_eq!(r.control_indices.len(), 300);
    let after = mean_closest(&r.map_all(&src), &dst);
    eprintln!(
        "before {before}, after {after}, true-warp error {e}",
        e = mean_err(
            &r.map_all(&src),
            &src.iter().map(|&p| warp(p)).collect::<Vec<_>>()
        )
    );
    assert!(after < 0.35 * before, "before {before}, after {after}");
    // Same surface, warped: the mapping should land near the true images.
    let truth: Vec<P3> = src.iter().map(|&p| warp(p)).collect();
    let e = mean_err(&r.map_all(&src), &truth);
    assert!(e < 1.5, "mean error to the true warp {e} mm");

    // Rigid copy: the result stays near-rigid.
    let motion = rigid([0.0, 0.3, 1.0], 3.0, [2.0, -1.0, 1.0]);
    let dst: Vec<P3> = src.iter().map(|&p| motion.apply(p)).collect();
    let r = cpd::fit_nonrigid(&src, &dst, &small_nonrigid_params()).unwrap();
    let truth: Vec<P3> = src.iter().map(|&p| motion.apply(p)).collect();
    let e = mean_err(&r.map_all(&src), &truth);
    assert!(
        e < 1.0,
        "rigid copy: mean deviation from the rigid motion {e} mm"
    );
}

fn small_nricp_params() -> nricp::NricpParams {
    nricp::NricpParams {
        max_nodes: 400,
        ..Default::default()
    }
}

#[test]
fn nricp_fits_warped_copy_and_keeps_rigid_copy_rigid() {
    let src = surface(700, 4);
    let dst: Vec<P3> = src.iter().map(|&p| warp(p)).collect();
    let before = mean_closest(&src, &dst);
    let r = nricp::fit(&src, &dst, &small_nricp_params()).unwrap();
    assert_eq!(r.nodes.len(), 400);
    let mapped = r.map_all(&src);
    let after = mean_closest(&mapped, &dst);
    eprintln!(
        "before {before}, after {after}, true-warp error {e}",
        e = mean_err(
            &r.map_all(&src),
            &src.iter().map(|&p| warp(p)).collect::<Vec<_>>()
        )
    );
    assert!(after < 0.35 * before, "before {before}, after {after}");
    let truth: Vec<P3> = src.iter().map(|&p| warp(p)).collect();
    let e = mean_err(&mapped, &truth);
    assert!(e < 2.0, "mean error to the true warp {e} mm");
    // Nodes map exactly by their own transform.
    let nodes = r.node_positions();
    let direct: Vec<P3> = r.node_indices.iter().map(|&i| mapped[i]).collect();
    assert!(max_err(&nodes, &direct) < 1e-9);

    let motion = rigid([0.0, 0.3, 1.0], 3.0, [2.0, -1.0, 1.0]);
    let dst: Vec<P3> = src.iter().map(|&p| motion.apply(p)).collect();
    let r = nricp::fit(&src, &dst, &small_nricp_params()).unwrap();
    let truth: Vec<P3> = src.iter().map(|&p| motion.apply(p)).collect();
    let e = mean_err(&r.map_all(&src), &truth);
    assert!(
        e < 1.0,
        "rigid copy: mean deviation from the rigid motion {e} mm"
    );
}

#[test]
fn csr_and_cg_solve_a_small_spd_system() {
    // 1-D Laplacian + identity, three right-hand sides.
    let n = 50;
    let mut t = Vec::new();
    for i in 0..n {
        t.push((i, i, 3.0));
        if i > 0 {
            t.push((i, i - 1, -1.0));
            t.push((i - 1, i, -1.0));
        }
    }
    t.push((0, 0, 0.0)); // duplicate entry: summed
    let a = nricp::Csr::from_triplets(n, t);
    assert_eq!(a.get(3, 2), -1.0);
    assert_eq!(a.get(3, 9), 0.0);
    let truth: Vec<P3> = (0..n).map(|i| [i as f64, 1.0, (i as f64).sin()]).collect();
    let mut b = vec![[0.0; 3]; n];
    a.mul3(&truth, &mut b);
    let mut x = vec![[0.0; 3]; n];
    let id = |r: &[P3], z: &mut [P3]| z.copy_from_slice(r);
    let its = nricp::conjugate_gradient(&a, &b, &mut x, &id, 1e-12, 500).unwrap();
    assert!(its <= n + 1);
    assert!(max_err(&x, &truth) < 1e-9);
    // Too few iterations: typed failure, no panic.
    let mut x = vec![[0.0; 3]; n];
    assert!(nricp::conjugate_gradient(&a, &b, &mut x, &id, 1e-14, 2).is_err());
}

#[test]
fn cholesky_solves_spd_system() {
    let n = 30;
    let pts = surface(n, 11);
    let mut a = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            a[i * n + j] = (-dist2(pts[i], pts[j]) / 800.0).exp() + if i == j { 0.5 } else { 0.0 };
        }
    }
    let truth: Vec<P3> = (0..n).map(|i| [i as f64, -1.0, 0.5 * i as f64]).collect();
    let mut b: Vec<P3> = (0..n)
        .map(|i| {
            let mut s = [0.0; 3];
            for j in 0..n {
                s = add(s, scale(truth[j], a[i * n + j]));
            }
            s
        })
        .collect();
    let mut l = a.clone();
    cpd::cholesky_in_place(&mut l, n).unwrap();
    cpd::cholesky_solve(&l, n, &mut b);
    assert!(max_err(&b, &truth) < 1e-9);
    let mut bad = vec![0.0; 4];
    bad[0] = -1.0;
    assert_eq!(cpd::cholesky_in_place(&mut bad, 2), Err(0));
}

#[test]
fn every_method_runs_uniformly_and_deterministically() {
    let src = surface(300, 12);
    let dst: Vec<P3> = surface(300, 13).into_iter().map(warp).collect();
    let wp = [[0.0, 0.0, 0.0], [20.0, -10.0, 3.0]];
    for m in Method::ALL {
        let a = run(m, &src, &dst).unwrap();
        let b = run(m, &src, &dst).unwrap();
        assert_eq!(a.report().method, m);
        assert!(a.report().iterations > 0);
        let (pa, pb) = (a.map_all(&src), b.map_all(&src));
        assert_eq!(pa, pb, "{m} is not deterministic");
        assert_eq!(a.map_all(&wp), b.map_all(&wp));
        assert!(pa.iter().flatten().all(|v| v.is_finite()));
    }
}

#[test]
fn bad_inputs_give_typed_errors() {
    let good = surface(50, 14);
    let mut nan = good.clone();
    nan[7][1] = f64::NAN;
    let mut inf = good.clone();
    inf[3][2] = f64::INFINITY;
    for m in Method::ALL {
        assert_eq!(
            run(m, &[], &good).err(),
            Some(BaselineError::Empty(Role::Template)),
            "{m}"
        );
        assert_eq!(
            run(m, &good, &[]).err(),
            Some(BaselineError::Empty(Role::Target)),
            "{m}"
        );
        assert_eq!(
            run(m, &nan, &good).err(),
            Some(BaselineError::NonFinite {
                role: Role::Template,
                index: 7
            }),
            "{m}"
        );
        assert_eq!(
            run(m, &good, &inf).err(),
            Some(BaselineError::NonFinite {
                role: Role::Target,
                index: 3
            }),
            "{m}"
        );
        assert!(matches!(
            run(m, &good[..2], &good).err(),
            Some(BaselineError::TooFewPoints {
                role: Role::Template,
                found: 2,
                ..
            })
        ));
    }
    // Collinear template: no unique rotation.
    let line: Vec<P3> = (0..20).map(|i| [i as f64, 2.0 * i as f64, 0.0]).collect();
    assert!(matches!(
        run(Method::Icp, &line, &good).err(),
        Some(BaselineError::Degenerate { .. })
    ));
    assert!(matches!(
        run(Method::CpdRigid, &line, &good).err(),
        Some(BaselineError::Degenerate { .. })
    ));
    // Coincident template points: zero scale.
    let same = vec![[1.0, 2.0, 3.0]; 10];
    assert!(matches!(
        run(Method::CpdNonRigid, &same, &good).err(),
        Some(BaselineError::Degenerate { .. })
    ));
    assert!(matches!(
        run(Method::NonRigidIcp, &same, &good).err(),
        Some(BaselineError::Degenerate { .. })
    ));
    // Parameters.
    let e = cpd::fit_rigid(
        &good,
        &good,
        &cpd::RigidParams {
            w: 1.0,
            ..Default::default()
        },
    );
    assert!(matches!(
        e,
        Err(BaselineError::InvalidParameter { name: "w", .. })
    ));
    let e = cpd::fit_nonrigid(
        &good,
        &good,
        &cpd::NonRigidParams {
            beta: f64::NAN,
            ..Default::default()
        },
    );
    assert!(matches!(
        e,
        Err(BaselineError::InvalidParameter { name: "beta", .. })
    ));
    let e = nricp::fit(
        &good,
        &good,
        &nricp::NricpParams {
            stiffness: vec![],
            ..Default::default()
        },
    );
    assert!(matches!(
        e,
        Err(BaselineError::InvalidParameter {
            name: "stiffness",
            ..
        })
    ));
    let e = icp::fit(
        &good,
        &good,
        &icp::IcpParams {
            tolerance_mm: -1.0,
            ..Default::default()
        },
    );
    assert!(matches!(e, Err(BaselineError::InvalidParameter { .. })));
    let e = nricp::fit_graph(&good, &[[0, 50]], &good, &Default::default(), None);
    assert!(matches!(e, Err(BaselineError::Degenerate { .. })));
    // Messages are one line and name the problem.
    let msg = run(Method::Icp, &nan, &good).err().unwrap().to_string();
    assert_eq!(
        msg,
        "the template cloud has a non-finite coordinate at point 7"
    );
}

#[test]
fn non_convergence_is_reported_not_panicking() {
    let src = surface(300, 15);
    let dst: Vec<P3> = src
        .iter()
        .map(|&p| rigid([0.0, 0.0, 1.0], 8.0, [5.0, 0.0, 0.0]).apply(p))
        .collect();
    // Lenient (default): a result with `converged == false`.
    let lenient = icp::fit(
        &src,
        &dst,
        &icp::IcpParams {
            max_iterations: 1,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(!lenient.report.converged);
    assert_eq!(lenient.report.iterations, 1);
    // Strict: a typed error.
    let strict = icp::fit(
        &src,
        &dst,
        &icp::IcpParams {
            max_iterations: 1,
            strict: true,
            ..Default::default()
        },
    );
    assert!(matches!(
        strict,
        Err(BaselineError::NotConverged {
            method: Method::Icp,
            iterations: 1,
            ..
        })
    ));
    let strict = cpd::fit_rigid(
        &src,
        &dst,
        &cpd::RigidParams {
            max_iterations: 2,
            strict: true,
            ..Default::default()
        },
    );
    assert!(matches!(strict, Err(BaselineError::NotConverged { .. })));
    let strict = cpd::fit_nonrigid(
        &src,
        &dst,
        &cpd::NonRigidParams {
            max_iterations: 2,
            max_control_points: 100,
            strict: true,
            ..Default::default()
        },
    );
    assert!(matches!(strict, Err(BaselineError::NotConverged { .. })));
    let strict = nricp::fit(
        &src,
        &dst,
        &nricp::NricpParams {
            max_iterations_per_step: 1,
            max_nodes: 100,
            eps: 0.0,
            strict: true,
            ..Default::default()
        },
    );
    assert!(matches!(strict, Err(BaselineError::NotConverged { .. })));
}

#[test]
fn seeded_subsample_is_deterministic_and_distinct() {
    let a = seeded_subsample(3000, 1500, 0);
    assert_eq!(a, seeded_subsample(3000, 1500, 0));
    assert_ne!(a, seeded_subsample(3000, 1500, 1));
    assert_eq!(a.len(), 1500);
    assert!(a.windows(2).all(|w| w[0] < w[1]));
    assert_eq!(seeded_subsample(10, 1500, 0), (0..10).collect::<Vec<_>>());
}

#[test]
fn cpd_low_rank_solver_matches_dense() {
    let src = surface(400, 16);
    let dst: Vec<P3> = src.iter().map(|&p| warp(p)).collect();
    let base = cpd::NonRigidParams {
        max_control_points: 250,
        max_iterations: 40,
        ..Default::default()
    };
    let dense = cpd::fit_nonrigid(
        &src,
        &dst,
        &cpd::NonRigidParams {
            solver: cpd::Solver::Dense,
            ..base.clone()
        },
    )
    .unwrap();
    let low = cpd::fit_nonrigid(&src, &dst, &base).unwrap();
    assert_eq!(dense.kernel_rank, 250);
    assert!(low.kernel_rank < 250, "rank {}", low.kernel_rank);
    let e = max_err(&dense.map_all(&src), &low.map_all(&src));
    assert!(
        e < 1e-4,
        "low-rank vs dense: {e} mm (rank {})",
        low.kernel_rank
    );
}
