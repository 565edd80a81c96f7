//! Tests of the automatic labelling on phantom templates.

use super::*;
use crate::phantom::{Part, PhantomConfig, PhantomPair, SubjectParams};
use ribreg_core::math::rng::Rng;

/// A labelled template cloud of `subject`, sampled at `spacing_mm` with seed `seed` (the US
/// side of the pair is made cheap: it is not used).
fn template_cloud(subject: &SubjectParams, spacing_mm: f64, seed: u64) -> PhantomPair {
    let cfg = PhantomConfig {
        spacing_mm,
        us_spacing_mm: 25.0,
        missing_patches: 0,
        outlier_fraction: 0.0,
        seed,
        ..PhantomConfig::default()
    };
    PhantomPair::generate_with(subject, &SubjectParams::template(), &cfg)
}

/// Fraction of points whose label matches the truth, and whether every part's majority
/// label is its own (rib numbering right on both sides, sternum found).
fn score(pair: &PhantomPair, labels: &[i32]) -> (f64, bool) {
    let truth = &pair.template.labels;
    let agree = truth.iter().zip(labels).filter(|(t, l)| t == l).count();
    let mut numbering_ok = true;
    for part in Part::ALL {
        let mut votes = [0usize; 6];
        for (m, &l) in pair.template.material.iter().zip(labels) {
            if m.part == part {
                votes[l as usize] += 1;
            }
        }
        let best = (0..6).max_by_key(|&l| votes[l]).unwrap_or(0) as i32;
        numbering_ok &= best == part.label();
    }
    (agree as f64 / truth.len() as f64, numbering_ok)
}

/// Rotation matrix by `deg` about `axis` (Rodrigues).
fn rotation(axis: [f64; 3], deg: f64) -> [[f64; 3]; 3] {
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let [x, y, z] = [axis[0] / n, axis[1] / n, axis[2] / n];
    let (s, c) = deg.to_radians().sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

fn transform(points: &[[f64; 3]], r: [[f64; 3]; 3], t: [f64; 3]) -> Vec<[f64; 3]> {
    points
        .iter()
        .map(|p| {
            let mut q = t;
            for (a, row) in r.iter().enumerate() {
                q[a] += row[0] * p[0] + row[1] * p[1] + row[2] * p[2];
            }
            q
        })
        .collect()
}

/// Spacing used for seed `seed` (2.0, 2.5 or 3.0 mm: the rule must not depend on it).
fn spacing_of(seed: u64) -> f64 {
    2.0 + 0.5 * (seed % 3) as f64
}

#[test]
fn autolabel_phantom_templates_many_subjects() {
    let mut worst = (1.0, u64::MAX);
    let mut sum = 0.0;
    let mut cases = 0usize;
    for seed in 0..=40u64 {
        // Seed 40 is the template subject itself (as `PhantomPair::generate` builds it).
        let pair = if seed == 40 {
            PhantomPair::generate(&PhantomConfig {
                us_spacing_mm: 25.0,
                missing_patches: 0,
                ..PhantomConfig::default()
            })
        } else {
            template_cloud(&SubjectParams::random(1000 + seed), spacing_of(seed), seed)
        };
        let found = auto_labels(&pair.template.points)
            .unwrap_or_else(|e| panic!("seed {seed}: refused: {e}"));
        let (agree, numbering) = score(&pair, &found.labels);
        assert!(numbering, "seed {seed}: rib numbering wrong ({found})");
        assert!(agree >= 0.99, "seed {seed}: agreement {agree:.4} ({found})");
        sum += agree;
        cases += 1;
        if agree < worst.0 {
            worst = (agree, seed);
        }
    }
    println!(
        "autolabel agreement: worst {:.4} (seed {}), mean {:.4} over {cases} templates",
        worst.0,
        worst.1,
        sum / cases as f64
    );
}

#[test]
fn autolabel_survives_small_rotations_and_a_far_origin() {
    let pair = template_cloud(&SubjectParams::random(77), 2.5, 3);
    let axes = [
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [0.0, 1.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, -2.0, 3.0],
    ];
    for axis in axes {
        let r = rotation(axis, 5.0);
        let moved = transform(&pair.template.points, r, [300.0, -300.0, 300.0]);
        let found = auto_labels(&moved).unwrap_or_else(|e| panic!("axis {axis:?}: refused: {e}"));
        let (agree, numbering) = score(&pair, &found.labels);
        println!("axis {axis:?}: agreement {agree:.4}; {found}");
        assert!(numbering, "axis {axis:?}: rib numbering wrong");
        assert!(
            agree >= 0.99,
            "axis {axis:?}: agreement {agree:.4} ({found})"
        );
        assert!((found.midline_x_mm - 300.0).abs() < 20.0, "{found}");
    }
}

#[test]
fn autolabel_refuses_a_missing_cartilage() {
    let pair = template_cloud(&SubjectParams::template(), 2.5, 5);
    for side in Side::BOTH {
        for rib in RIBS {
            let gone = Part::Cartilage { rib, side };
            let points: Vec<[f64; 3]> = pair
                .template
                .points
                .iter()
                .zip(&pair.template.material)
                .filter(|(_, m)| m.part != gone)
                .map(|(p, _)| *p)
                .collect();
            assert_eq!(
                auto_labels(&points),
                Err(AutoLabelError::CartilageCount { side, found: 3 }),
                "{gone:?} removed"
            );
        }
    }
}

#[test]
fn autolabel_refuses_sides_at_different_heights() {
    let pair = template_cloud(&SubjectParams::template(), 2.5, 8);
    for shift in [-15.0, 15.0] {
        // The patient-left half slid caudally/cranially by more than half a rib gap.
        let slid: Vec<[f64; 3]> = pair
            .template
            .points
            .iter()
            .map(|&[x, y, z]| {
                if x > 0.0 {
                    [x, y + shift, z]
                } else {
                    [x, y, z]
                }
            })
            .collect();
        let err = auto_labels(&slid).expect_err("slid sides labelled");
        println!("left half slid {shift} mm: {err}");
        assert!(matches!(err, AutoLabelError::SidesDisagree { .. }), "{err}");
    }
}

#[test]
fn autolabel_refuses_a_single_side() {
    let pair = template_cloud(&SubjectParams::template(), 2.5, 6);
    // The sternum and the left cartilages only.
    let one_side: Vec<[f64; 3]> = pair
        .template
        .points
        .iter()
        .zip(&pair.template.material)
        .filter(|(_, m)| {
            !matches!(
                m.part,
                Part::Cartilage {
                    side: Side::Right,
                    ..
                }
            )
        })
        .map(|(p, _)| *p)
        .collect();
    let err = auto_labels(&one_side).expect_err("one side labelled");
    println!("one side (with sternum): {err}");
    // Half a cloud cut at the midline.
    let half: Vec<[f64; 3]> = pair
        .template
        .points
        .iter()
        .copied()
        .filter(|p| p[0] > 0.0)
        .collect();
    let err = auto_labels(&half).expect_err("half cloud labelled");
    println!("half cloud: {err}");
}

#[test]
fn autolabel_refuses_tiny_and_unstructured_clouds() {
    assert_eq!(
        auto_labels(&[]),
        Err(AutoLabelError::TooFewPoints {
            found: 0,
            min: MIN_POINTS
        })
    );
    assert!(matches!(
        auto_labels(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
        Err(AutoLabelError::TooFewPoints { found: 3, .. })
    ));
    assert_eq!(
        auto_labels(&vec![[1.0, 2.0, 3.0]; 500]),
        Err(AutoLabelError::NoSpacing)
    );
    let mut bad = vec![[0.0; 3]; 200];
    bad[17][1] = f64::NAN;
    assert_eq!(
        auto_labels(&bad),
        Err(AutoLabelError::NonFinite { index: 17 })
    );
    for seed in 0..3 {
        let mut rng = Rng::new(seed);
        let uniform: Vec<[f64; 3]> = (0..5000)
            .map(|_| {
                [
                    200.0 * rng.next_f64() - 100.0,
                    200.0 * rng.next_f64() - 100.0,
                    50.0 * rng.next_f64(),
                ]
            })
            .collect();
        let err = auto_labels(&uniform).expect_err("uniform cloud labelled");
        println!("uniform cloud {seed}: {err}");
    }
}

/// Measurements behind the constants (run with `--ignored --nocapture`).
#[test]
#[ignore]
fn autolabel_measure_variants() {
    let pairs: Vec<PhantomPair> = (0..40u64)
        .map(|seed| template_cloud(&SubjectParams::random(1000 + seed), spacing_of(seed), seed))
        .collect();
    for (band, passes) in [
        (0.0, 1),
        (0.0, MIDLINE_PASSES),
        (0.1, 1),
        (0.1, MIDLINE_PASSES),
        (0.25, MIDLINE_PASSES),
    ] {
        let mut worst = 1.0f64;
        let mut sum = 0.0;
        let mut bad = 0;
        for pair in &pairs {
            match auto_labels_with(&pair.template.points, band, passes) {
                Ok(f) => {
                    let (a, ok) = score(pair, &f.labels);
                    bad += usize::from(!ok);
                    worst = worst.min(a);
                    sum += a;
                }
                Err(_) => bad += 1,
            }
        }
        println!(
            "band {band} passes {passes}: worst {worst:.4} mean {:.4} refused/misnumbered {bad}",
            sum / pairs.len() as f64
        );
    }
}

/// Runtime on a dense cloud: three Poisson samplings of the template subject merged,
/// about 200k points (run with `--ignored --nocapture`; the phantom's sampler caps one
/// sampling near 80k points).
#[test]
#[ignore]
fn autolabel_timing_dense() {
    let mut points = Vec::new();
    let mut truth = Vec::new();
    for seed in 1..=3 {
        let pair = template_cloud(&SubjectParams::template(), 0.5, seed);
        points.extend_from_slice(&pair.template.points);
        truth.extend_from_slice(&pair.template.labels);
    }
    let t = std::time::Instant::now();
    let found = auto_labels(&points).expect("dense template");
    println!("{} points: {:?}; {found}", points.len(), t.elapsed());
    let agree = truth
        .iter()
        .zip(&found.labels)
        .filter(|(t, l)| t == l)
        .count();
    println!("agreement {:.4}", agree as f64 / truth.len() as f64);
}
