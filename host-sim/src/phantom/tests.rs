//! Tests of the phantom.

use super::*;
use std::collections::HashMap;
use std::f64::consts::PI;
use std::sync::OnceLock;

/// The default pair, generated once for the tests that only read it.
fn default_pair() -> &'static PhantomPair {
    static PAIR: OnceLock<PhantomPair> = OnceLock::new();
    PAIR.get_or_init(|| PhantomPair::generate(&PhantomConfig::default()))
}

/// A cheaper configuration for tests that generate their own pairs.
fn coarse(seed: u64, variant: Variant) -> PhantomConfig {
    PhantomConfig {
        spacing_mm: 4.0,
        us_spacing_mm: 3.5,
        seed,
        variant,
        ..PhantomConfig::default()
    }
}

#[test]
fn phantom_same_config_same_pair_and_seed_matters() {
    let a = PhantomPair::generate(&coarse(7, Variant::Aligned));
    let b = PhantomPair::generate(&coarse(7, Variant::Aligned));
    assert_eq!(a, b);
    let c = PhantomPair::generate(&coarse(8, Variant::Aligned));
    assert_ne!(a.patient_params, c.patient_params);
    assert_ne!(a.target, c.target);
    assert_ne!(a.pose, c.pose);
    // The template subject is fixed; only its sampling depends on the seed.
    assert_eq!(a.template_params, c.template_params);
    assert_eq!(a.template_waypoints, c.template_waypoints);
}

#[test]
fn phantom_counts_and_labels() {
    let pair = default_pair();
    let n = pair.template.points.len();
    assert!((2000..8000).contains(&n), "template points: {n}");
    assert_eq!(pair.template.labels.len(), n);
    assert_eq!(pair.template.material.len(), n);
    for label in 1..=5 {
        assert!(
            pair.template.labels.contains(&label),
            "label {label} missing"
        );
    }
    for part in Part::ALL {
        let count = pair
            .template
            .material
            .iter()
            .filter(|m| m.part == part)
            .count();
        assert!(count > 30, "{part:?}: {count} points");
    }
    for (l, m) in pair.template.labels.iter().zip(&pair.template.material) {
        assert_eq!(*l, m.part.label());
    }
    assert!(!pair.target.is_empty());
    assert_eq!(pair.target.len(), pair.target_material.len());
    let outliers = pair.outlier_count();
    let inliers = pair.target.len() - outliers;
    assert_eq!(outliers, (0.01 * inliers as f64).round() as usize);
    assert_eq!(pair.template_waypoints.len(), 10);
    assert_eq!(pair.true_waypoints.len(), 10);
    let (verts, tris) = &pair.template_mesh;
    assert!(!tris.is_empty());
    assert!(tris.iter().flatten().all(|&i| (i as usize) < verts.len()));
}

/// Smallest distance between two dense surface samples, searched up to `reach` mm
/// (returns `reach` when nothing is closer). `b` is bucketed in a sparse grid of `reach`
/// cells; only the 27 cells around each point of `a` are scanned.
fn sampled_gap(a: &[P3], b: &[P3], reach: f64) -> f64 {
    let key = |p: &P3| p.map(|v| (v / reach).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<P3>> = HashMap::new();
    for p in b {
        grid.entry(key(p)).or_default().push(*p);
    }
    let mut best = reach * reach;
    let mut near: Vec<&Vec<P3>> = Vec::with_capacity(27);
    let mut last_key = None;
    for p in a {
        let k = key(p);
        if last_key != Some(k) {
            // Consecutive samples mostly share a cell: reuse its neighbourhood.
            near.clear();
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        if let Some(cell) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                            near.push(cell);
                        }
                    }
                }
            }
            last_key = Some(k);
        }
        for cell in &near {
            for q in cell.iter() {
                best = best.min(dist2(*p, *q));
            }
        }
    }
    best.sqrt()
}

/// Surface samples of one cartilage about 1.2 mm apart along s and around.
fn dense_tube(geom: &SubjectGeometry, rib: u8, side: Side) -> Vec<P3> {
    let part = Part::Cartilage { rib, side };
    let len = geom.params().cartilage_length_mm[side.index()][rib_index(rib)] + CARTILAGE_INSET_MM;
    let n_s = (len * 1.4 / 1.2).ceil() as usize; // arc length ≤ 1.4 × lateral length
    let n_phi = 32;
    let mut out = Vec::with_capacity((n_s + 1) * n_phi);
    // phi-major order keeps consecutive samples in the same grid cell.
    for j in 0..n_phi {
        for i in 0..=n_s {
            let m = Material {
                part,
                s: i as f64 / n_s as f64,
                phi: TAU * j as f64 / n_phi as f64,
            };
            out.push(geom.position(&m));
        }
    }
    out
}

#[test]
fn phantom_neighbouring_cartilages_keep_clear_gap() {
    let mut worst = f64::INFINITY;
    let subjects: Vec<SubjectParams> = std::iter::once(SubjectParams::template())
        .chain((0..50u64).map(|k| SubjectParams::random(1000 + k)))
        .collect();
    for p in &subjects {
        let geom = SubjectGeometry::new(p);
        assert!(geom.min_gap_lower_bound() >= MIN_CARTILAGE_GAP_MM);
        for side in Side::BOTH {
            let tubes: Vec<Vec<P3>> = RIBS.iter().map(|&r| dense_tube(&geom, r, side)).collect();
            for k in 0..RIB_COUNT - 1 {
                let gap = sampled_gap(&tubes[k], &tubes[k + 1], 10.0);
                worst = worst.min(gap);
                assert!(
                    gap >= MIN_CARTILAGE_GAP_MM,
                    "gap {gap} mm between ribs {} and {}",
                    k + 2,
                    k + 3
                );
            }
        }
    }
    println!("worst sampled clear gap over the subjects: {worst:.2} mm");
    assert!(
        worst < 10.0,
        "the gap check should find the close pairs (worst {worst})"
    );
}

#[test]
fn phantom_surface_point_reproduces_template_points() {
    let pair = default_pair();
    for (p, m) in pair.template.points.iter().zip(&pair.template.material) {
        let (q, n) = surface_point(&pair.template_params, m);
        assert!(norm(sub(*p, q)) <= 1e-9);
        assert!((norm(n) - 1.0).abs() < 1e-9);
    }
}

#[test]
fn phantom_true_position_identity_case() {
    let t = SubjectParams::template();
    let mut pair = PhantomPair::generate_with(&t, &t, &coarse(3, Variant::Aligned));
    pair.pose = Pose::identity();
    for i in 0..pair.template.points.len() {
        assert!(norm(sub(pair.true_position(i), pair.template.points[i])) <= 1e-12);
    }
    let all = pair.true_positions();
    assert_eq!(all, pair.template.points);
    // Same subject, real pose: true positions and waypoints are the template ones posed.
    let pair2 = PhantomPair::generate_with(&t, &t, &coarse(3, Variant::Misaligned));
    let inv = pair2.pose.inverse();
    for (a, b) in pair2.true_waypoints.iter().zip(&pair2.template_waypoints) {
        assert!(norm(sub(inv.apply(*a), *b)) < 1e-9);
    }
    for (i, p) in pair2.template.points.iter().enumerate() {
        assert!(norm(sub(inv.apply(pair2.true_position(i)), *p)) < 1e-9);
    }
}

/// The sternum's truth by its landmarks: the template's ends and rib attachments land on
/// the patient's, the points between keep their share of the way, the same subject maps
/// onto itself, and the cartilages' truth is the plain one.
#[test]
fn sternum_truth_by_landmarks_takes_landmarks_to_landmarks() {
    let t = SubjectParams::template();
    let tg = SubjectGeometry::new(&t);
    let same = PhantomPair::generate_with(&t, &t, &coarse(3, Variant::Aligned));
    assert_eq!(same.true_positions_by_landmarks(), same.true_positions());
    for seed in [3, 11, 40] {
        let p = SubjectParams::random_for(seed, Preset::Hard, &[]);
        let pg = SubjectGeometry::new(&p);
        let (from, to) = (tg.sternum_landmarks(), pg.sternum_landmarks());
        let s_at =
            |g: &SubjectGeometry, y: f64| (g.sternum_top - y) / (g.sternum_top - g.sternum_bottom);
        for k in 0..from.len() {
            let s = pg.sternum_s_by_landmarks(&tg, s_at(&tg, from[k]));
            assert!(
                (pg.sternum_y(s) - to[k]).abs() < 1e-9,
                "seed {seed}, landmark {k}"
            );
        }
        // Halfway between rib 3's and rib 4's attachments on both.
        let mid = |l: &[f64]| 0.5 * (l[2] + l[3]);
        let s = pg.sternum_s_by_landmarks(&tg, s_at(&tg, mid(&from)));
        assert!((pg.sternum_y(s) - mid(&to)).abs() < 1e-9, "seed {seed}");
        // Monotone: top to bottom stays top to bottom.
        let ss: Vec<f64> = (0..=20)
            .map(|i| pg.sternum_s_by_landmarks(&tg, f64::from(i) / 20.0))
            .collect();
        assert!(ss.windows(2).all(|w| w[0] <= w[1]), "{ss:?}");
        let pair = PhantomPair::generate_with(&t, &p, &coarse(seed, Variant::Misaligned));
        let (plain, anatomical) = (pair.true_positions(), pair.true_positions_by_landmarks());
        for ((a, b), m) in plain.iter().zip(&anatomical).zip(&pair.template.material) {
            if let Part::Cartilage { .. } = m.part {
                assert_eq!(a, b);
            }
        }
    }
}

#[test]
fn phantom_poisson_min_distance() {
    let pts = &default_pair().template.points;
    let r2 = (2.5f64 * 0.999).powi(2);
    let mut sorted: Vec<&P3> = pts.iter().collect();
    sorted.sort_by(|a, b| a[0].total_cmp(&b[0]));
    for i in 0..sorted.len() {
        for j in i + 1..sorted.len() {
            if sorted[j][0] - sorted[i][0] > 2.5 {
                break;
            }
            assert!(dist2(*sorted[i], *sorted[j]) >= r2);
        }
    }
}

#[test]
fn phantom_target_is_anterior_facing_and_noise_is_bounded() {
    let pair = default_pair();
    let pg = SubjectGeometry::new(&pair.patient_params);
    let inv = pair.pose.inverse();
    let mut sum2 = 0.0;
    let mut n = 0usize;
    for (p, m) in pair.target.iter().zip(&pair.target_material) {
        if let Some(m) = m {
            let (q, normal) = pg.surface_point(m);
            assert!(normal[2] > ANTERIOR_MIN_NORMAL_Z);
            let d = dist2(inv.apply(*p), q);
            sum2 += d;
            n += 1;
        }
    }
    // RMS 3-D noise ≈ √3 · 0.7 mm.
    let rms = (sum2 / n as f64).sqrt();
    assert!((rms - 3f64.sqrt() * 0.7).abs() < 0.1, "rms {rms}");
}

#[test]
fn phantom_poses_are_proper_and_in_range() {
    for seed in 0..200u64 {
        for variant in [Variant::Aligned, Variant::Misaligned] {
            let pose = Pose::random(variant, &mut Rng::new(seed));
            let r = pose.rotation;
            for i in 0..3 {
                for j in 0..3 {
                    let rrt: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                    let id = if i == j { 1.0 } else { 0.0 };
                    assert!((rrt - id).abs() < 1e-12);
                }
            }
            let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
                - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
                + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
            assert!((det - 1.0).abs() < 1e-12);
            let (angle, shift) = (pose.rotation_angle_deg(), pose.translation_norm());
            match variant {
                Variant::Aligned => {
                    assert!(angle <= 3.0 + 1e-9 && shift <= 5.0 + 1e-9);
                }
                Variant::Misaligned => {
                    assert!(
                        (10.0 - 1e-9..=20.0 + 1e-9).contains(&angle),
                        "angle {angle}"
                    );
                    assert!(
                        (20.0 - 1e-9..=40.0 + 1e-9).contains(&shift),
                        "shift {shift}"
                    );
                }
            }
            let p = [12.0, -40.0, 7.5];
            let back = pose.inverse().apply(pose.apply(p));
            assert!(norm(sub(back, p)) < 1e-12);
            let id = pose.compose(&pose.inverse());
            assert!(id.rotation_angle_deg() < 1e-6 && id.translation_norm() < 1e-9);
        }
    }
    let pair = PhantomPair::generate(&coarse(11, Variant::Misaligned));
    let angle = pair.pose.rotation_angle_deg();
    assert!((10.0..=20.0).contains(&angle));
    assert!((20.0..=40.0).contains(&pair.pose.translation_norm()));
}

#[test]
fn phantom_template_rib_spacing_at_sternum() {
    let geom = SubjectGeometry::new(&SubjectParams::template());
    let expected = [31.6, 26.1, 24.2];
    for side in Side::BOTH {
        for k in 0..3 {
            let (a, b) = (RIBS[k], RIBS[k + 1]);
            let pa = geom.centerline(
                Part::Cartilage { rib: a, side },
                geom.sternum_edge_s(a, side),
            );
            let pb = geom.centerline(
                Part::Cartilage { rib: b, side },
                geom.sternum_edge_s(b, side),
            );
            let d = norm(sub(pa, pb));
            assert!((d - expected[k]).abs() <= 0.5, "L{a}{b} = {d}");
            assert!((d - expected[k]).abs() <= 1e-9, "L{a}{b} = {d}");
            // The edge point lies on the sternum's lateral face at mid-thickness.
            let half = geom.half_sternum_width();
            assert!((pa[0].abs() - half).abs() < 1e-9);
            assert!((pa[2] - geom.sternum_center_z(pa[1])).abs() < 1e-9);
        }
    }
}

#[test]
fn phantom_random_subjects_are_plausible() {
    let t = SubjectParams::template();
    assert_eq!(
        SubjectParams::from_draws(&[1.5; N_DRAWS], 0.0, &Spread::STANDARD),
        t
    );
    assert_eq!(SubjectParams::random(5), SubjectParams::random(5));
    assert_ne!(SubjectParams::random(5), SubjectParams::random(6));
    for seed in 0..100u64 {
        let p = SubjectParams::random(seed);
        for a in 0..3 {
            assert!((p.scale[a] - 1.0).abs() <= 0.1 + 1e-12);
        }
        for side in 0..2 {
            for r in 0..RIB_COUNT {
                let rel = p.cartilage_length_mm[side][r] / t.cartilage_length_mm[side][r];
                assert!((0.85 * 0.95 - 1e-9..=1.15 * 1.05 + 1e-9).contains(&rel));
            }
        }
        for k in 0..3 {
            let rel = p.rib_spacing_mm[k] / t.rib_spacing_mm[k];
            assert!((0.85 - 1e-9..=1.15 + 1e-9).contains(&rel));
        }
        let l2 = p.cartilage_length_mm[0][0];
        let l5 = p.cartilage_length_mm[0][3];
        assert!(l2 > 45.0 && l5 > 80.0 && l5 < 125.0);
        assert_eq!(p.sanitized(), p);
    }
}

#[test]
fn phantom_waypoints_lie_between_ribs() {
    let geom = SubjectGeometry::new(&SubjectParams::template());
    let wps = geom.waypoints();
    assert_eq!(wps.len(), 10);
    for (i, wp) in wps.iter().enumerate() {
        let side = Side::BOTH[i / 5];
        let (upper, s) = WAYPOINT_PLAN[i % 5];
        let ya = geom.centerline(Part::Cartilage { rib: upper, side }, s)[1];
        let yb = geom.centerline(
            Part::Cartilage {
                rib: upper + 1,
                side,
            },
            s,
        )[1];
        assert!(wp[1] < ya && wp[1] > yb);
        assert!(wp[0] * side.sign() > geom.half_sternum_width());
        let za = geom.centerline(Part::Cartilage { rib: upper, side }, s)[2];
        let zb = geom.centerline(
            Part::Cartilage {
                rib: upper + 1,
                side,
            },
            s,
        )[2];
        let lift = wp[2] - 0.5 * (za + zb);
        // Lifted by about the half-thickness (the tube's anterior side is tilted).
        assert!(lift > 2.0 && lift < 4.5, "waypoint lift {lift} mm");
    }
}

/// Each waypoint's window, checked against the cartilages' surfaces sampled densely over
/// a stretch of s about the waypoint's (not only the cross-section at its s): seen along
/// the anterior axis, the window's ends touch the two outlines, and the segment between
/// them, 0.5 mm short of each end, is clear of both.
#[test]
fn phantom_waypoint_gaps_end_at_the_cartilages_outlines() {
    let subjects = [
        SubjectParams::template(),
        SubjectParams::random_for(3, Preset::Hard, &[]),
        SubjectParams::random_for(11, Preset::Hard, &[]),
    ];
    for params in subjects {
        let geom = SubjectGeometry::new(&params);
        let gaps = geom.waypoint_gaps();
        for ((i, w), g) in geom.waypoints().iter().enumerate().zip(&gaps) {
            let side = Side::BOTH[i / 5];
            let (upper, s) = WAYPOINT_PLAN[i % 5];
            assert!((norm(g.across) - 1.0).abs() < 1e-9 && g.across[2] == 0.0);
            assert!(g.across[1] < -0.8, "across {:?} not caudal", g.across);
            assert!(g.to_upper > 3.0 && g.to_lower > 3.0, "{g:?}");
            // The outline's points in the chest's plane (z dropped), 0.2 mm apart or less.
            let outline = |rib: u8| -> Vec<[f64; 2]> {
                let part = Part::Cartilage { rib, side };
                let mut v = vec![];
                for k in 0..=400 {
                    let si = s - 0.2 + 0.4 * k as f64 / 400.0;
                    for j in 0..256 {
                        let p = geom.position(&Material {
                            part,
                            s: si,
                            phi: 2.0 * PI * j as f64 / 256.0,
                        });
                        v.push([p[0], p[1]]);
                    }
                }
                v
            };
            let (a, b) = (outline(upper), outline(upper + 1));
            let gap_to = |pts: &[[f64; 2]], t: f64| {
                let q = add(*w, mul(g.across, t));
                pts.iter()
                    .map(|p| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt())
                    .fold(f64::INFINITY, f64::min)
            };
            assert!(
                gap_to(&b, g.to_lower) < 0.4,
                "waypoint {i}: lower end off the outline"
            );
            assert!(
                gap_to(&a, -g.to_upper) < 0.4,
                "waypoint {i}: upper end off the outline"
            );
            for k in 0..=20 {
                let t = -(g.to_upper - 0.5) + (g.to_upper + g.to_lower - 1.0) * k as f64 / 20.0;
                assert!(
                    gap_to(&a, t).min(gap_to(&b, t)) > 0.25,
                    "waypoint {i}: the window is not clear {t:.1} mm across"
                );
            }
        }
        // Moved across by e, the clearance shrinks by e toward that rib.
        let g = gaps[0];
        let close = |(a, c): (f64, f64), (a0, c0): (f64, f64)| {
            assert!((a - a0).abs() < 1e-12 && (c - c0).abs() < 1e-12, "{a} {c}");
        };
        close(g.split(mul(g.across, 2.0)), (2.0, g.to_lower - 2.0));
        close(g.split(mul(g.across, -2.0)), (-2.0, g.to_upper - 2.0));
        // Moved along the gap or in depth, nothing changes across it.
        let along = [-g.across[1], g.across[0], 0.0];
        let (across, clearance) = g.split(add(mul(along, 7.0), [0.0, 0.0, 5.0]));
        assert!(across.abs() < 1e-12 && (clearance - g.to_lower).abs() < 1e-12);
    }
}

#[test]
fn phantom_mesh_is_outward_wound() {
    let geom = SubjectGeometry::new(&SubjectParams::template());
    let (verts, tris) = geom.mesh(MESH_EDGE_MM);
    assert!(tris.iter().flatten().all(|&i| (i as usize) < verts.len()));
    let mut area = 0.0;
    for t in &tris {
        let [a, b, c] = t.map(|i| verts[i as usize]);
        let n = norm(cross(sub(b, a), sub(c, a)));
        assert!(n > 0.0, "degenerate triangle");
        area += 0.5 * n;
    }
    // Total area close to the analytic estimate (≈ 3 · 10⁴ mm²).
    assert!((20_000.0..45_000.0).contains(&area), "mesh area {area}");
    // Each part encloses a positive volume. Tubes are open at the medial end: taking the
    // origin at the centroid of that (planar) ring makes the missing disc contribute 0.
    for (part, (v, t)) in geom.part_meshes(MESH_EDGE_MM) {
        let o = match part {
            Part::Sternum => [0.0; 3],
            _ => mul(
                v[..MESH_TUBE_SEGMENTS]
                    .iter()
                    .fold([0.0; 3], |s, p| add(s, *p)),
                1.0 / MESH_TUBE_SEGMENTS as f64,
            ),
        };
        let volume: f64 = t
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| sub(v[i as usize], o));
                dot(a, cross(b, c)) / 6.0
            })
            .sum();
        let expected = match part {
            Part::Sternum => 28.0 * 10.0 * 128.0,
            Part::Cartilage { rib, .. } => {
                let r = rib_index(rib);
                let p = geom.params();
                // Elliptic cylinder along the centreline's arc length.
                let arc: f64 = (0..200)
                    .map(|i| {
                        let c0 = geom.centerline(part, i as f64 / 200.0);
                        let c1 = geom.centerline(part, (i + 1) as f64 / 200.0);
                        norm(sub(c1, c0))
                    })
                    .sum();
                PI / 4.0 * p.cartilage_width_mm[r] * p.cartilage_thickness_mm[r] * arc
            }
        };
        assert!(
            volume > 0.8 * expected && volume < 1.2 * expected,
            "{part:?}: volume {volume} vs {expected}"
        );
    }
}

#[test]
fn phantom_params_json_round_trips() {
    let pair = default_pair();
    let v = pair.write_params_json();
    let back: SubjectParams = serde_json::from_value(v["patient_params"].clone()).unwrap();
    assert_eq!(back, pair.patient_params);
    let pose: Pose = serde_json::from_value(v["pose"].clone()).unwrap();
    assert_eq!(pose, pair.pose);
    let cfg: PhantomConfig = serde_json::from_value(v["config"].clone()).unwrap();
    assert_eq!(cfg, pair.config);
    assert_eq!(v["counts"]["template"], pair.template.points.len());
}

#[test]
fn phantom_gaussian_moments() {
    let mut rng = Rng::new(42);
    let n = 20_000;
    let xs: Vec<f64> = (0..n).map(|_| gaussian(&mut rng)).collect();
    let mean = xs.iter().sum::<f64>() / n as f64;
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
    assert!(mean.abs() < 0.03 && (var - 1.0).abs() < 0.05);
}

use super::defects::{BREATHING_EXCURSION_MM, BREATHING_HZ, JUNCTION_SEEN_FRACTION, TIP_HOLES};

/// A coarse hard phantom, some difficulties left out.
fn hard(seed: u64, without: &[HardPart]) -> PhantomPair {
    PhantomPair::generate(&PhantomConfig {
        preset: Preset::Hard,
        hard_without: without.to_vec(),
        ..coarse(seed, Variant::Aligned)
    })
}

#[test]
fn hard_without_every_difficulty_is_the_standard_phantom() {
    let all = [
        HardPart::Spread,
        HardPart::Sternum,
        HardPart::TipHoles,
        HardPart::Junction,
        HardPart::Breathing,
    ];
    for seed in 0..3 {
        let h = hard(seed, &all);
        let s = PhantomPair::generate(&coarse(seed, Variant::Aligned));
        assert_eq!(h.patient_params, s.patient_params);
        assert_eq!(h.target, s.target);
        assert_eq!(h.true_waypoints, s.true_waypoints);
        assert_eq!(h.template, s.template);
        assert!(s.defects.is_none() && h.defects.is_some());
    }
}

#[test]
fn hard_patients_have_a_manubrium_and_xiphoid_in_range_and_vary_more() {
    let mut spread = [0.0f64; 2];
    for seed in 0..40u64 {
        let p = SubjectParams::random_for(seed, Preset::Hard, &[]);
        let [top, bottom] = p.sternum_margin_mm;
        assert!(
            (HARD_MANUBRIUM_MM.0..=HARD_MANUBRIUM_MM.1).contains(&top),
            "{top}"
        );
        assert!(
            (HARD_XIPHOID_MM.0..=HARD_XIPHOID_MM.1).contains(&bottom),
            "{bottom}"
        );
        assert!(p.gap_is_safe());
        let s = SubjectParams::random_for(seed, Preset::Standard, &[]);
        assert_eq!(s, SubjectParams::random(seed));
        let t = SubjectParams::template();
        for (k, q) in [s, p].iter().enumerate() {
            for side in 0..2 {
                for r in 0..RIB_COUNT {
                    let rel = q.cartilage_length_mm[side][r] / t.cartilage_length_mm[side][r];
                    spread[k] = spread[k].max((rel - 1.0).abs());
                }
            }
        }
    }
    // Length ±15 % and asymmetry ±5 % (standard) against ±20 % and ±12 % (hard).
    assert!(spread[0] <= 1.15 * 1.05 - 1.0 + 1e-9, "{spread:?}");
    assert!(
        spread[1] > spread[0] && spread[1] <= 1.2 * 1.12 - 1.0 + 1e-9,
        "{spread:?}"
    );
}

#[test]
fn hard_sweeps_lose_tips_and_junction_points_and_breathe() {
    let full = hard(
        4,
        &[HardPart::TipHoles, HardPart::Junction, HardPart::Breathing],
    );
    let pair = hard(4, &[]);
    let d = pair
        .defects
        .clone()
        .expect("hard phantoms record their defects");
    assert_eq!(d.tip_holes.len(), TIP_HOLES);
    assert!(pair.target.len() < full.target.len());
    // No seen point lies inside a tip hole (noise aside: 3 SD of 0.7 mm).
    let pg = SubjectGeometry::new(&pair.patient_params);
    for &(part, s, radius) in &d.tip_holes {
        let centre = pg.position(&Material {
            part,
            s,
            phi: std::f64::consts::FRAC_PI_2,
        });
        for m in pair.target_material.iter().flatten() {
            assert!(dist2(pg.position(m), centre).sqrt() > radius - 1e-9);
        }
    }
    // Junction zones keep about JUNCTION_SEEN_FRACTION of their points.
    let in_zone = |p: &PhantomPair| {
        p.target_material
            .iter()
            .flatten()
            .filter(|m| match m.part {
                Part::Cartilage { rib, side } => {
                    m.s > d.junction_from_s[side.index()][rib_index(rib)]
                        && !d.tip_holes.iter().any(|h| h.0 == m.part)
                }
                Part::Sternum => false,
            })
            .count() as f64
    };
    let kept = in_zone(&pair) / in_zone(&full);
    assert!((kept - JUNCTION_SEEN_FRACTION).abs() < 0.15, "{kept}");
    // Breathing: in range, and zero-mean over the sweep, so the truth is unchanged.
    assert!(
        (BREATHING_EXCURSION_MM.0..=BREATHING_EXCURSION_MM.1).contains(&d.breathing_excursion_mm)
    );
    assert!((BREATHING_HZ.0..=BREATHING_HZ.1).contains(&d.breathing_hz));
    assert!(d.sweep_duration_s > 60.0, "{}", d.sweep_duration_s);
    let still = hard(4, &[HardPart::Breathing]);
    assert_eq!(still.true_waypoints, pair.true_waypoints);
    // Outliers are drawn in the moved cloud's box: compare the surface points only.
    let shift: Vec<f64> = still
        .target
        .iter()
        .zip(&pair.target)
        .zip(&pair.target_material)
        .filter(|(_, m)| m.is_some())
        .map(|((a, b), _)| norm(sub(*b, *a)))
        .collect();
    let worst = shift.iter().copied().fold(0.0, f64::max);
    assert!(
        worst <= 0.5 * d.breathing_excursion_mm + 1e-6 && worst > 0.0,
        "{worst}"
    );
}

#[test]
fn hard_part_names_are_the_command_line_names() {
    use clap::ValueEnum;
    for p in HardPart::value_variants() {
        let v = p
            .to_possible_value()
            .expect("every part is on the command line");
        assert_eq!(v.get_name(), p.name());
    }
    for p in Preset::value_variants() {
        let v = p
            .to_possible_value()
            .expect("every preset is on the command line");
        assert_eq!(v.get_name(), p.name());
    }
}

/// A robot base turned about the patient's anterior axis turns the target and its truth
/// together: the anterior axis and every distance stay, the patient frame maps to the
/// same points, and a turn of 0 changes nothing.
#[test]
fn a_turned_base_turns_the_target_and_its_truth_together() {
    let pair = default_pair().clone();
    assert_eq!(pair.clone().turned(0.0), pair);
    let turned = pair.clone().turned(180.0);
    let d = |a: [f64; 3], b: [f64; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
    let (w, t) = (pair.true_waypoints[3], turned.true_waypoints[3]);
    assert!((d(pair.target[9], w) - d(turned.target[9], t)).abs() < 1e-9);
    // Half a turn: the waypoint moved by about twice its distance from the axis.
    assert!(d(w, t) > 20.0, "{}", d(w, t));
    let up = |p: &PhantomPair| p.pose.apply_vector([0.0, 0.0, 1.0]);
    let (a, b) = (up(&pair), up(&turned));
    assert!((0..3).all(|i| (a[i] - b[i]).abs() < 1e-12), "{a:?} {b:?}");
    // The same patient point lands on the turned target point.
    let back = |p: &PhantomPair, q: [f64; 3]| p.pose.inverse().apply(q);
    let (p0, p1) = (back(&pair, pair.target[9]), back(&turned, turned.target[9]));
    assert!(d(p0, p1) < 1e-9, "{p0:?} {p1:?}");
    // The turn is about the target's centroid: it stays.
    let (c0, c1) = (centroid(&pair.target), centroid(&turned.target));
    assert!(d(c0, c1) < 1e-9);
}
