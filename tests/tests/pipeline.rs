//! The whole pipeline, core (`pipeline::Template::build` + `pipeline::register` + the
//! local-rigid mapping, all `f32`) against the `f64` reference
//! (`reference::register_detailed`), on fixture clouds: the built-in cage as template and
//! a moved, stretched copy as target, labels on and off, the paper's configuration (the
//! graph rib model; the reference does not implement the core's guided improvement).
//!
//! Each implementation runs end to end on its own (the reference computes its own frames,
//! SOMs, trees, endpoints, matches, fits and transforms from the same input points), so
//! differences accumulate over every step; the per-step bounds are in `steps.rs`.
//!
//! ```text
//! matched rib ends (template and target)   identical
//! 30 + 30 skeleton points                  ≤ 0.1 mm
//! mapped waypoints (18 intercostal points) ≤ 0.1 mm
//! mapped template cloud (≈ 2,300 points)   ≤ 0.1 mm
//! measured (max over the 4 runs below; printed with --nocapture), core 22266f9:
//!   template skeleton 1.2e-4 mm, target skeleton 7.7e-5 mm, waypoints 6.0e-4 mm,
//!   template cloud 5.6e-3 mm;
//! at e05cb20 (LIVE_SAMPLES 4096) the cage's rib-3 path kept 4 key points with clustered
//!   abscissae (see steps.rs polyfit_clustered_abscissae): template skeleton 9.9e-3 mm,
//!   target skeleton 6.7e-3 mm, waypoints 1.2e-2 mm, template cloud 3.6e-2 mm
//! ```
//! The brief expected "a few tenths of a mm"; the agreement is one to three orders of
//! magnitude better. The bound of 0.1 mm keeps a margin of ×3 over the worst case seen.

use ribreg_core::config::Config;
use ribreg_core::registration::local_rigid::TransformCache;
use ribreg_core::registration::pipeline::{register, Template};
use ribreg_core::Vec3;
use ribreg_tests::reference as r;
use ribreg_tests::support::*;

/// The target of the brief: `cage(0.08)` rotated 15° and translated.
fn target() -> Vec<Vec3> {
    let m = rigid([0.3, 1.0, 0.2], 15.0, [12.0, -8.0, 20.0]);
    cage(0.08).iter().map(|p| m.apply(p)).collect()
}

/// Runs both pipelines and returns the largest differences (template skeleton, target
/// skeleton, waypoints, template cloud), asserting the bounds of the module docs.
fn compare(template: &[Vec3], labels: Option<&[u8]>, target: &[Vec3], name: &str) -> [f64; 4] {
    let cfg = Config::default();
    let tpl = match Template::build(template, labels, &cfg) {
        Ok(t) => t,
        Err(e) => {
            // Both implementations must refuse the same way (the paper's endpoint rule
            // gives some labelled cages two ends on one rib, see `labelled_rib_paths_span_both_sides`).
            let want = r::register_detailed(
                &cloud64(template),
                labels,
                &cloud64(target),
                &r::Config::default(),
            );
            assert_eq!(
                want.err(),
                Some(ref_error(e)),
                "{name}: core and reference refuse alike"
            );
            eprintln!("{name}: both refuse: {e}");
            return [0.0; 4];
        }
    };
    let reg = register(&tpl, target, &cfg).unwrap_or_else(|e| panic!("{name}: core register: {e}"));
    let (t64, g64) = (cloud64(template), cloud64(target));
    let rreg = r::register_detailed(&t64, labels, &g64, &r::Config::default())
        .unwrap_or_else(|e| panic!("{name}: reference register: {e:?}"));

    let tpl_ends = tpl.ends.expect("graph rib model");
    let matching = reg.matching.as_ref().expect("graph rib model");
    assert_eq!(
        tpl_ends.0.map(|e| e.map(usize::from)),
        rreg.template_ends,
        "{name}: template rib ends"
    );
    assert_eq!(
        matching.ends.0.map(|e| e.map(usize::from)),
        rreg.matching.ends,
        "{name}: target rib ends"
    );
    let d_tpl = max_pair_dist(&tpl.skeleton.points, &rreg.template_skeleton.points);
    let d_tgt = max_pair_dist(&reg.skeleton.points, &rreg.target_skeleton.points);

    let mut cache = TransformCache::<128>::new();
    let mut waypoints = cage_waypoints(0.0);
    let w64 = cloud64(&waypoints);
    reg.map.map_in_place(&mut waypoints, &mut cache).unwrap();
    let want: Vec<r::P3> = w64.iter().map(|p| rreg.map.map(*p).unwrap()).collect();
    let d_wp = max_pair_dist(&waypoints, &want);

    let mut cloud = template.to_vec();
    reg.map.map_in_place(&mut cloud, &mut cache).unwrap();
    let want: Vec<r::P3> = t64.iter().map(|p| rreg.map.map(*p).unwrap()).collect();
    let d_cloud = max_pair_dist(&cloud, &want);

    eprintln!(
        "{name}: max |core − reference|: template skeleton {d_tpl:.2e}, target skeleton {d_tgt:.2e}, \
         waypoints {d_wp:.2e}, template cloud {d_cloud:.2e} mm"
    );
    for (what, d) in [
        ("template skeleton", d_tpl),
        ("target skeleton", d_tgt),
        ("waypoints", d_wp),
        ("template cloud", d_cloud),
    ] {
        assert!(d <= 0.1, "{name}: {what} differ by {d} mm");
    }
    [d_tpl, d_tgt, d_wp, d_cloud]
}

#[test]
fn cage_onto_moved_stretched_cage_without_labels() {
    compare(&cage(0.0), None, &target(), "paper, no labels");
}

#[test]
fn cage_onto_moved_stretched_cage_with_labels() {
    let labels = cage_labels(0.0);
    compare(&cage(0.0), Some(&labels), &target(), "paper, labels");
}

/// Other poses and a shrunk template: a 40° turn about the cranio-caudal axis, and a
/// 170° turn (the probe frame upside down).
#[test]
fn other_poses() {
    let labels = cage_labels(-0.05);
    let m = rigid([0.0, 1.0, 0.1], 40.0, [-30.0, 5.0, 40.0]);
    let tgt: Vec<Vec3> = cage(0.05).iter().map(|p| m.apply(p)).collect();
    compare(&cage(-0.05), Some(&labels), &tgt, "paper, 40° about y");
    let m = rigid([0.2, 0.1, 1.0], 170.0, [10.0, 10.0, -10.0]);
    let tgt: Vec<Vec3> = cage(0.0).iter().map(|p| m.apply(p)).collect();
    compare(&cage(0.0), None, &tgt, "paper, 170° about z");
}

/// The reference's convenience entry point gives the same 30 + 30 points and mapping as
/// the detailed one.
#[test]
fn reference_register_tuple_form() {
    let (tpl, tgt) = (cloud64(&cage(0.0)), cloud64(&target()));
    let (s, t, map) = r::register(&tpl, None, &tgt).unwrap();
    let d = r::register_detailed(&tpl, None, &tgt, &r::Config::default()).unwrap();
    assert_eq!(s.len(), 30);
    assert_eq!(s, d.template_skeleton.points);
    assert_eq!(t, d.target_skeleton.points);
    let p = [20.0, -15.0, 5.0];
    assert_eq!(map(p), d.map.map(p).unwrap());
}

/// Known limits of the paper's graph model on the built-in cage (README, "Known limits"),
/// found by these tests when they still expected success; core and reference agree, so
/// this is the method, not arithmetic: the Euclidean MST joins ribs across the
/// intercostal gaps (40 key points lie about as far apart along a rib as the ribs lie
/// from each other), Eq. 4's greedy walk stops following a path once it turns up the
/// sternum, and the endpoint rule takes a tip that is not a tree leaf for the wrong rib.
/// With labels the inconsistency is caught and reported; the guided model, which gets
/// the ribs from the labels, covers every rib on both sides.
#[test]
fn paper_limits_are_reported_and_the_guided_model_covers_the_ribs() {
    let cloud = cage(0.0);
    let labels = cage_labels(0.0);
    // Paper, labelled: the endpoint rule's ends contradict the labels -> typed error.
    assert!(matches!(
        Template::build(&cloud, Some(&labels), &Config::default()),
        Err(ribreg_core::Error::RibOrder { .. })
    ));
    // Guided: each rib's 6/6/8/10 points run from one side of the sternum to the other.
    let tpl = Template::build(&cloud, Some(&labels), &Config::improved()).unwrap();
    let mut offset = 0;
    for (r, n) in ribreg_core::config::RIB_SAMPLES.iter().enumerate() {
        let xs: Vec<f32> = tpl.skeleton.points[offset..offset + n]
            .iter()
            .map(|p| p.x)
            .collect();
        assert!(
            xs[0] < -50.0 && xs[n - 1] > 50.0,
            "rib {}: x from {} to {}",
            r + 2,
            xs[0],
            xs[n - 1]
        );
        assert!(
            xs.windows(2).all(|w| w[1] > w[0]),
            "rib {}: x not increasing",
            r + 2
        );
        offset += n;
    }
}

/// The built-in cage stretched by 7.2 % is a valid four-rib cage, but the paper's
/// endpoint rule finds three rib ends on side 1 (the f64 reference too): the failure is a
/// typed error naming side and count, never a wrong template. The guided model builds it.
#[test]
fn stretched_cage_is_refused_clearly_by_the_paper_model_and_built_by_the_guided_one() {
    for stretch in [0.0716f32, 0.072, 0.0733] {
        match Template::build(&cage(stretch), None, &Config::default()) {
            Ok(_) => {}
            Err(e) => assert!(
                matches!(e, ribreg_core::Error::Endpoints { .. }),
                "cage({stretch}): {e}"
            ),
        }
        let t = Template::build(
            &cage(stretch),
            Some(&cage_labels(stretch)),
            &Config::improved(),
        );
        assert!(t.is_ok(), "cage({stretch}): {:?}", t.err());
    }
}

/// The compact template the controller receives (SOM-1 nodes + labels, frame, skeleton,
/// sternum split) registers exactly like the template it was taken from.
#[test]
fn template_from_parts_registers_identically() {
    let cfg = Config::improved();
    let (ct, labels) = (cage(0.0), cage_labels(0.0));
    let full = Template::build(&ct, Some(&labels), &cfg).unwrap();
    let parts = Template::from_parts(
        &full.graph.som1,
        &full.node_labels,
        full.graph.frame,
        full.skeleton.points,
        full.midline_fraction,
    )
    .unwrap();
    let us = target();
    let a = register(&full, &us, &cfg).unwrap();
    let b = register(&parts, &us, &cfg).unwrap();
    assert_eq!(a.skeleton.points, b.skeleton.points);
    assert_eq!(a.pose, b.pose);
    // Bad parts are refused.
    let short = &full.node_labels[..full.node_labels.len() - 1];
    assert!(Template::from_parts(
        &full.graph.som1,
        short,
        full.graph.frame,
        full.skeleton.points,
        full.midline_fraction
    )
    .is_err());
    let mut frame = full.graph.frame;
    frame.axes[(0, 0)] = f32::NAN;
    assert!(Template::from_parts(
        &full.graph.som1,
        &full.node_labels,
        frame,
        full.skeleton.points,
        full.midline_fraction
    )
    .is_err());
    assert!(Template::from_parts(
        &full.graph.som1,
        &full.node_labels,
        full.graph.frame,
        full.skeleton.points,
        [2.0; 4]
    )
    .is_err());
}

/// Registration in bounded steps (the controller's way) gives exactly `register`'s result.
#[test]
fn incremental_registration_equals_register() {
    use ribreg_core::registration::pipeline::Registering;
    let labels = cage_labels(0.0);
    for (cfg, labels) in [
        (Config::improved(), Some(&labels[..])),
        (Config::default(), None),
    ] {
        let template = Template::build(&cage(0.0), labels, &cfg).unwrap();
        let us = target();
        let whole = register(&template, &us, &cfg).unwrap();
        let mut r = Registering::start(&us, &cfg).unwrap();
        let mut calls = 0;
        loop {
            calls += 1;
            if r.step(&template, &us, &cfg, 7).unwrap() {
                break;
            }
        }
        assert_eq!(r.registration(), Some(&whole));
        let total = cfg.som1.iterations + cfg.som2.iterations;
        assert_eq!(r.progress(&cfg), (total, total));
        assert!(calls as u32 >= total / 7, "{calls}");
        assert!(r.step(&template, &us, &cfg, 7).unwrap(), "done stays done");
    }
}

/// The controller's registration checks the target in chunks (one call cannot check a
/// whole cloud): a bad point past the first chunk is refused with its index in the whole
/// cloud, before any SOM work, and the registration stays failed.
#[test]
fn incremental_registration_checks_every_point() {
    use ribreg_core::error::{Cloud, Error};
    use ribreg_core::registration::pipeline::{Registering, CHECK_POINTS_PER_UNIT};
    let cfg = Config::improved();
    let labels = cage_labels(0.0);
    let template = Template::build(&cage(0.0), Some(&labels[..]), &cfg).unwrap();
    let mut us = target();
    let index = us.len() - 1;
    assert!(
        index > 3 * CHECK_POINTS_PER_UNIT,
        "the bad point is past several chunks"
    );
    us[index].x = f32::NAN;
    let mut r = Registering::start(&us, &cfg).unwrap();
    let mut calls = 0;
    let err = loop {
        calls += 1;
        match r.step(&template, &us, &cfg, 1) {
            Ok(false) => assert_eq!(r.stage(), "check"),
            Ok(true) => panic!("a NaN target registered"),
            Err(e) => break e,
        }
    };
    assert_eq!(
        err,
        Error::NonFinite {
            cloud: Cloud::Target,
            index: index as u32
        }
    );
    assert_eq!(calls, index / CHECK_POINTS_PER_UNIT + 1);
    assert_eq!(r.stage(), "failed");
    assert!(
        r.step(&template, &us, &cfg, 1).is_err(),
        "failed stays failed"
    );
}
