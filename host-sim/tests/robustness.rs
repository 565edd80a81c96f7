//! Refuse instead of failing silently: the improved method on phantom sweeps turned and
//! moved as a robot base may stand, and on sweeps that miss a side or a rib (the cases of
//! `ribreg eval --robustness`). Every run is refused or lands every waypoint within
//! `SILENT_FAILURE_MM`; incomplete sweeps are refused, naming what is missing.

use ribreg_core::error::Cloud;
use ribreg_core::Error;
use ribreg_sim::eval::robustness::{Case, SILENT_FAILURE_MM};
use ribreg_sim::phantom::{
    HardPart, Material, Part, PhantomConfig, PhantomPair, Preset, Side, Variant,
};
use ribreg_sim::register::{register_clouds, to_core, Method, Options};

/// The improved method on `pair`: the largest waypoint error, or the core's refusal.
fn run(pair: &PhantomPair) -> Result<f64, Error> {
    run_with(pair, None)
}

/// [`run`] with an up prior (`register --target-up`).
fn run_with(pair: &PhantomPair, target_up: Option<[f64; 3]>) -> Result<f64, Error> {
    let how = Options {
        method: Method::Improved,
        target_up: target_up.map(|u| ribreg_core::Vec3::new(u[0] as f32, u[1] as f32, u[2] as f32)),
        ..Options::default()
    };
    let tpl = to_core(&pair.template.points, Cloud::Template).unwrap();
    let tgt = to_core(&pair.target, Cloud::Target).unwrap();
    let wps = to_core(&pair.template_waypoints, Cloud::Query).unwrap();
    let labels: Vec<u8> = pair.template.labels.iter().map(|&l| l as u8).collect();
    match register_clouds(&tpl, Some(&labels), &tgt, Some(&wps), how, &mut |_| ()) {
        Ok(o) => Ok(o
            .waypoints
            .unwrap()
            .iter()
            .zip(&pair.true_waypoints)
            .map(|(a, b)| {
                (0..3)
                    .map(|k| (f64::from(a[k]) - b[k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .fold(0.0, f64::max)),
        Err(e) => Err(e),
    }
}

fn pair(seed: u64) -> PhantomPair {
    PhantomPair::generate(&PhantomConfig {
        seed,
        variant: Variant::Misaligned,
        ..PhantomConfig::default()
    })
}

/// Hard phantom `seed`, aligned.
fn hard(seed: u64) -> PhantomPair {
    PhantomPair::generate(&PhantomConfig {
        seed,
        preset: Preset::Hard,
        variant: Variant::Aligned,
        ..PhantomConfig::default()
    })
}

#[test]
fn turned_and_moved_sweeps_are_registered_or_refused_never_wrong() {
    let cases = [Case::Yaw(90), Case::Yaw(180), Case::Rotation(1)];
    let (mut accepted, mut runs) = (0, 0);
    for seed in 0..6 {
        let p = pair(seed);
        for case in cases {
            runs += 1;
            match run(&case.apply(&p, seed)) {
                Ok(max) => {
                    assert!(
                        max <= SILENT_FAILURE_MM,
                        "seed {seed}, {}: accepted with a waypoint {max:.1} mm off",
                        case.name()
                    );
                    accepted += 1;
                }
                Err(e) => eprintln!("seed {seed}, {}: refused: {e}", case.name()),
            }
        }
    }
    // Refusing everything would pass the loop above: most runs must go through.
    assert!(accepted * 10 >= runs * 9, "{accepted} of {runs} accepted");
}

#[test]
fn sweeps_missing_a_side_or_a_rib_are_refused() {
    for seed in 0..4 {
        let p = pair(seed);
        for case in [
            Case::SideMissing(Side::Left),
            Case::SideMissing(Side::Right),
            Case::Rib5Missing,
        ] {
            let e = run(&case.apply(&p, seed)).expect_err(&format!("seed {seed}, {}", case.name()));
            assert!(
                matches!(
                    e,
                    Error::NotSeen { .. }
                        | Error::RibPath { .. }
                        | Error::Ambiguous { .. }
                        | Error::Unsupported { .. }
                ),
                "seed {seed}, {}: {e}",
                case.name()
            );
        }
    }
}

/// Phantom 12's lateral and cranial spreads are close: turned, its principal axes come in
/// the other order than the template's, and with only the sign starts it came back
/// flipped (waypoints 108 mm off, exit 0), then was refused as not seen. The swapped-axes
/// starts and the refined-residual choice register it at every turn.
#[test]
fn a_chest_whose_axes_swap_when_turned_is_registered() {
    let p = pair(12);
    for case in [
        Case::Yaw(0),
        Case::Yaw(90),
        Case::Yaw(180),
        Case::Rotation(1),
    ] {
        let max = run(&case.apply(&p, 12)).unwrap_or_else(|e| panic!("{}: {e}", case.name()));
        assert!(max <= 6.0, "{}: {max:.1} mm", case.name());
    }
}

/// A sweep of something that is not a rib cage (a smooth bowl of the same size) is refused,
/// never registered.
#[test]
fn a_sweep_of_something_else_is_refused() {
    let p = pair(0);
    let mut q = p.clone();
    let n = q.target.len();
    q.target = (0..n)
        .map(|i| {
            let (u, v) = ((i % 80) as f64 / 79.0, (i / 80) as f64 / (n / 80) as f64);
            let (x, y) = (240.0 * (u - 0.5), 160.0 * (v - 0.5));
            [x, y, 40.0 - (x * x + y * y) / 600.0]
        })
        .collect();
    let e = run(&q).expect_err("a bowl registered as a chest");
    assert!(matches!(e, Error::Ambiguous { .. }), "{e}");
}

/// The optional up prior: the patient's true anterior (turned with the sweep), or one
/// roughly like it, gives the same registration as none; a prior 90° or 180° off is
/// refused, never followed onto a wrong pose.
#[test]
fn an_up_prior_narrows_the_search_and_a_wrong_one_is_refused() {
    for seed in [0, 12] {
        let p = pair(seed);
        for case in [Case::Yaw(90), Case::Rotation(2)] {
            let q = case.apply(&p, seed);
            let up = q.pose.apply_vector([0.0, 0.0, 1.0]);
            let free = run(&q).unwrap();
            assert_eq!(
                run_with(&q, Some(up)).unwrap(),
                free,
                "seed {seed}, {}",
                case.name()
            );
            // About 27° off: still within the cone.
            let rough = [up[0] + 0.4, up[1] - 0.3, up[2]];
            assert_eq!(run_with(&q, Some(rough)).unwrap(), free);
            let side = q.pose.apply_vector([1.0, 0.0, 0.0]);
            let down = [-up[0], -up[1], -up[2]];
            for wrong in [side, down] {
                let e = run_with(&q, Some(wrong)).unwrap_err();
                assert!(
                    matches!(
                        e,
                        Error::AgainstPrior { .. }
                            | Error::Ambiguous { .. }
                            | Error::NotSeen { .. }
                            | Error::Unsupported { .. }
                    ),
                    "seed {seed}, {}: {e}",
                    case.name()
                );
            }
        }
    }
}

#[test]
fn a_hard_sweep_turned_in_its_plane_comes_out_as_unturned() {
    // On these hard phantoms the principal-axis starts end 9–16° off about the anterior
    // axis (a shallow ICP minimum: the cartilages are near-parallel curves), and before the
    // refined pose was also tried turned by ±12°, every yaw but 0° (where the identity start
    // lands near the truth) was refused ("rib 5 not seen") or mapped more than 30 mm off.
    // Seed 31's turned sweeps ended in a minimum 3.3° from the unturned one's, which ±12°
    // does not reach: 16.5 mm off, accepted (a silent failure), before the ±4° turns.
    for seed in [6, 12, 14, 31] {
        turned_as_unturned(seed, &[Case::Yaw(45), Case::Yaw(90)], 1.0);
    }
}

/// Hard phantom `seed` (aligned), in each of `cases`, is registered with its worst
/// waypoint within `tolerance_mm` of the unturned sweep's (yaw 0°, moved).
fn turned_as_unturned(seed: u64, cases: &[Case], tolerance_mm: f64) {
    let p = hard(seed);
    let unturned = run(&Case::Yaw(0).apply(&p, seed))
        .unwrap_or_else(|e| panic!("seed {seed}, yaw 0°: refused: {e}"));
    for case in cases {
        let turned = run(&case.apply(&p, seed))
            .unwrap_or_else(|e| panic!("seed {seed}, {}: refused: {e}", case.name()));
        assert!(
            (turned - unturned).abs() < tolerance_mm,
            "seed {seed}, {}: worst waypoint {turned:.1} mm, unturned {unturned:.1} mm",
            case.name()
        );
    }
}

/// Hard phantoms 109 and 142: unturned, the identity start finds the right pose, but
/// every quarter-turn principal-axis start ended in another minimum, so every turned or
/// rotated sweep of them was refused ("rib 2 not seen on the patient's right"). A start
/// halfway between the quarter turns reaches the unturned run's pose
/// (`endpoints::DIAGONAL_STARTS`; README "Starts halfway between the quarter turns").
#[test]
fn a_sweep_whose_axes_lie_between_the_quarter_turns_comes_out_as_unturned() {
    for seed in [109, 142] {
        turned_as_unturned(
            seed,
            &[Case::Yaw(90), Case::Yaw(225), Case::Rotation(1)],
            0.5,
        );
    }
}

/// Hard phantoms 117 and 153: unturned, the identity start finds the right pose. Turned,
/// 153's better-refined coarse hypothesis was a flip whose turns stayed flips, and the
/// other ended 13° off the right pose, which only its own −12° turn reaches; 117's
/// better one labelled a rib side away, and its turns into the right minimum, 2° off,
/// were dropped as the same minimum, which the other's turn keeps. Every turned sweep
/// but yaw 0° was refused ("rib 5 not seen", "rib 2 not seen"); this test fails with
/// only the better hypothesis turned
/// (`guided::TURNS`; README "Turning the other pose hypothesis too").
#[test]
fn the_other_pose_hypothesis_is_turned_too() {
    for seed in [117, 153] {
        turned_as_unturned(
            seed,
            &[Case::Yaw(45), Case::Yaw(270), Case::Rotation(1)],
            1.0,
        );
    }
}

/// A patient far from the template's shape is registered, not refused: hard phantoms 4
/// and 38 (long sternums, ±20 % cartilages) end their right pose at a node residual of
/// 7.9–8.5 mm, and the 7 mm bound that the standard phantoms had set refused them at
/// every pose; this test fails with it (`guided::MAX_POSE_RESIDUAL_MM`, README "A
/// residual bound for the patient's shape").
#[test]
fn a_patient_far_from_the_template_s_shape_is_registered() {
    for seed in [4, 38] {
        hard_sweep_registered_within_the_line(seed, &[Case::Yaw(0), Case::Yaw(90)]);
    }
}

/// Hard phantom `seed` (aligned), in each of `cases`, is registered with every waypoint
/// within `SILENT_FAILURE_MM`.
fn hard_sweep_registered_within_the_line(seed: u64, cases: &[Case]) {
    let p = hard(seed);
    for case in cases {
        let max = run(&case.apply(&p, seed))
            .unwrap_or_else(|e| panic!("seed {seed}, {}: refused: {e}", case.name()));
        assert!(
            max <= SILENT_FAILURE_MM,
            "seed {seed}, {}: {max:.1} mm",
            case.name()
        );
    }
}

/// The rib ends the sweep shows, as the controller checks them against where its
/// images passed (`reach::rib_ends`, `reach::edge_clearances`): each lies at its rib's
/// observed end in the fitting frame, within about a cartilage's thickness of the
/// target's points (the skeleton runs inside the cartilage, the sweep shows its
/// surface: 5–11 mm here), and points outward.
#[test]
fn rib_ends_lie_where_the_sweep_shows_the_ribs_end_and_point_outward() {
    use ribreg_core::config::Config;
    use ribreg_core::registration::pipeline::{register, Template};
    use ribreg_core::registration::reach::{check_edges, edge_clearances, rib_ends};
    let p = hard(3);
    let cfg = Config::improved();
    let tpl = to_core(&p.template.points, Cloud::Template).unwrap();
    let labels: Vec<u8> = p.template.labels.iter().map(|&l| l as u8).collect();
    let template = Template::build(&tpl, Some(&labels), &cfg).unwrap();
    // Turned and moved as a robot base may stand: the ends come back in its frame.
    let turned = Case::Rotation(2).apply(&p, 3);
    let tgt = to_core(&turned.target, Cloud::Target).unwrap();
    let reg = register(&template, &tgt, &cfg).unwrap();
    let reach = reg.reach.unwrap();
    let ends = rib_ends(&reg);
    for (r, sides) in ends.iter().enumerate() {
        for (s, end) in sides.iter().enumerate() {
            let (at, out) = end.unwrap_or_else(|| panic!("rib {} side {s}", r + 2));
            let q = reg.pose.apply(&at);
            let x = if s == 0 { reach[r].0 } else { reach[r].2 };
            assert!(
                (q.x - x).abs() < 1e-2,
                "rib {} side {s}: {} vs {x}",
                r + 2,
                q.x
            );
            let u = reg.pose.rotation * out;
            assert!(
                // Lateral within 60°: the lower cartilages run on down and back.
                (if s == 0 { -u.x } else { u.x }) > 0.5 * u.norm(),
                "rib {} side {s}: {u:?}",
                r + 2
            );
            let nearest = tgt
                .iter()
                .map(|t| (t - at).norm())
                .fold(f32::INFINITY, f32::min);
            assert!(nearest < 12.0, "rib {} side {s}: {nearest} mm", r + 2);
        }
    }
    // Imaged out to x = ±(end + 8 mm) in the fitting frame: 8 mm past every end passes,
    // 1 mm past rib 4's right end refuses it.
    let walk = |cut: f32| {
        move |from: &ribreg_core::Vec3, u: &ribreg_core::Vec3, max: f32| {
            let (q, v) = (reg.pose.apply(from), reg.pose.rotation * u.normalize());
            let x = if q.x < 0.0 { -q.x } else { q.x };
            let (r, edge) = (0..4)
                .map(|r| (r, if q.x < 0.0 { -reach[r].0 } else { reach[r].2 }))
                .min_by(|a, b| (a.1 - x).abs().total_cmp(&(b.1 - x).abs()))
                .unwrap();
            let margin = if r == 2 && q.x < 0.0 { cut } else { 8.0 };
            ((edge + margin - x) / v.x.abs()).clamp(0.0, max)
        }
    };
    let edges = edge_clearances(&reg, walk(8.0));
    assert!(edges.iter().flatten().all(|&c| c > 7.0), "{edges:?}");
    assert_eq!(check_edges(&edges), Ok(()));
    let edges = edge_clearances(&reg, walk(1.0));
    assert!(
        matches!(
            check_edges(&edges),
            Err(Error::SweepEdge {
                rib: 4,
                side: ribreg_core::error::Side::Right,
                ..
            })
        ),
        "{edges:?}"
    );
}

/// A sweep thinned to 30 % spaces each rib's points 1.5–4 mm apart, and the tip search,
/// which lets a point 11 mean spacings past the next count as a rib's tip, took ribs on
/// to lone outliers, 26–38 mm beyond where they end now: standard phantoms 71, 87, 103,
/// 136, 192 and 197, thinned, were silent failures, a lateral waypoint 10.6–15.0 mm
/// off. With the support at most `guided::TIP_SUPPORT_MAX_MM` each is within 6.5 mm
/// (README "A lone point past a thinned rib").
#[test]
fn a_thinned_sweep_s_ribs_do_not_reach_for_an_outlier() {
    for seed in [71, 87, 103, 136, 192, 197] {
        let max = run(&Case::Sparse.apply(&pair(seed), seed))
            .unwrap_or_else(|e| panic!("seed {seed}, thinned: refused: {e}"));
        eprintln!("standard phantom {seed}, thinned: worst waypoint {max:.1} mm");
        assert!(max < 7.0, "seed {seed}, thinned: {max:.1} mm");
    }
}

/// The pose turns walk downhill: each starts from the best pose refined so far. Hard
/// phantom 21, turned by any yaw or rotation, ended in a worse minimum than unturned
/// (node residual 6.38 mm against 4.67) with a waypoint 10.4 mm off, accepted: a silent
/// failure. Its +12° turn had found a better pose, but the ±4° turns started from the
/// coarse one; from the +12° turn's pose a +4° turn reaches 4.99 mm, and the worst
/// waypoint is 8.8 mm off (README "Pose turns that walk downhill").
#[test]
fn pose_turns_start_from_the_best_pose_so_far() {
    hard_sweep_registered_within_the_line(21, &[Case::Yaw(90), Case::Rotation(2)]);
}

/// A registration whose mapped template the sweep supports closely is accepted even
/// when the rigid residual cannot tell its pose from a flip, or a rib side is short.
/// Hard phantom 7 (runner-up 1.24 times the winner's residual) and 36 (1.16) were
/// refused as ambiguous at every pose, and 37 (its right rib 2 spanning 57 % of the
/// template's) as a rib not seen, though each maps within 6.2 mm; this test fails
/// without `guided::MAX_SUPPORT_MM` (README "The template's support").
#[test]
fn a_closely_supported_template_is_registered_though_a_flip_fits_nearly_as_well() {
    for seed in [7, 36, 37] {
        hard_sweep_registered_within_the_line(seed, &[Case::Yaw(0), Case::Rotation(1)]);
    }
}

/// Coverage is measured through the last guided round's mapping. Measured from the first
/// round's rigid pose, a patient whose ribs differ from the template's was refused as a
/// rib not seen though it maps within 6 mm: hard phantom 68 at every pose (rib 4 on the
/// right at 59 % of the template's span, 76 % in the last round) and 97 turned (rib 2 on
/// the right at 51 %). This test fails with the first round's coverage.
#[test]
fn a_patient_whose_ribs_differ_from_the_template_s_is_not_refused_as_not_seen() {
    hard_sweep_registered_within_the_line(68, &[Case::Yaw(0), Case::Yaw(90)]);
    hard_sweep_registered_within_the_line(97, &[Case::Yaw(90)]);
}

/// A one-sided sweep whose pose comes out wrong spreads the last round's labels onto the
/// seen side's cartilage: hard phantom 7 without its right side passes the coverage
/// check there (64 %) and the margin (1.39), 130 mm off. The sweep does not support its
/// mapped template (7.9 mm RMS): refused, naming the support. It was a silent failure
/// with the last round's coverage and no `guided::MAX_CHECKED_SUPPORT_MM`.
#[test]
fn a_one_sided_sweep_whose_labels_spread_is_refused_as_unsupported() {
    let p = hard(7);
    let e = run(&Case::SideMissing(Side::Right).apply(&p, 7)).expect_err("one side missing");
    assert!(
        matches!(
            e,
            Error::Unsupported {
                support_dmm: 66..,
                max_support_dmm: 65
            }
        ),
        "{e}"
    );
}

/// A flip can be supported almost as closely as a right registration: hard phantom 153
/// (seed 100–199, `eval --first-seed 100`) turned by 180° is registered onto its flip
/// (146 mm off) with a clear margin (1.45), the last round's coverage at 61 % and a
/// support of 6.5–6.8 mm. The 6.5 mm bound (`guided::MAX_CHECKED_SUPPORT_MM`, the right
/// runs' edge) refused it; at 7.0 mm it was a silent failure. Since the other pose
/// hypothesis is turned too (`guided::TURNS`), the right pose is found (7.3 mm) and wins,
/// but the flip's line reaches 7.6 mm: refused as ambiguous ([`Error::Ambiguous`]).
#[test]
fn a_flip_supported_nearly_as_closely_as_a_right_pose_is_refused() {
    let p = hard(153);
    match run(&Case::Yaw(180).apply(&p, 153)) {
        Err(e) => assert!(
            matches!(e, Error::Unsupported { .. } | Error::Ambiguous { .. }),
            "{e}"
        ),
        Ok(max) => panic!("accepted with a waypoint {max:.1} mm off"),
    }
}

/// `pair` with rib 3's cartilage on the patient's left lost beyond `s` of its length (a
/// sweep hole over its lateral end).
fn rib_3_left_lost_beyond(pair: &PhantomPair, s: f64) -> PhantomPair {
    let lost = |m: &Option<Material>| {
        matches!(m, Some(m) if m.s > s
            && m.part == Part::Cartilage { rib: 3, side: Side::Left })
    };
    let mut out = pair.clone();
    let keep: Vec<bool> = pair.target_material.iter().map(|m| !lost(m)).collect();
    let mut k = keep.iter();
    out.target.retain(|_| *k.next().unwrap());
    out.target_material.retain(|m| !lost(m));
    out
}

/// A rib end the sweep lost is extrapolated from the template: a waypoint mapped beyond
/// it is refused by default, naming the rib and side, and a partial mapping marks every
/// waypoint on that side and lands the rest. On these two phantoms the waypoint beyond
/// it comes out 14.4–14.8 mm off, and another beside the rib 12.2–13.3 mm off.
#[test]
fn a_waypoint_beyond_a_lost_rib_end_is_refused_or_left_out_of_a_partial_plan() {
    for preset in [Preset::Standard, Preset::Hard] {
        let p = rib_3_left_lost_beyond(
            &PhantomPair::generate(&PhantomConfig {
                seed: 4,
                preset,
                variant: Variant::Aligned,
                ..PhantomConfig::default()
            }),
            0.55,
        );
        assert_eq!(p.unreached_waypoints(), [1, 3], "{preset:?}");
        match run(&p) {
            Err(Error::NotReached {
                waypoint: 3,
                rib: 3,
                side: ribreg_core::error::Side::Left,
                ..
            }) => {}
            other => panic!("{preset:?}: {other:?}"),
        }
        let how = Options {
            method: Method::Improved,
            partial: true,
            ..Options::default()
        };
        let o = register_clouds(
            &to_core(&p.template.points, Cloud::Template).unwrap(),
            Some(
                &p.template
                    .labels
                    .iter()
                    .map(|&l| l as u8)
                    .collect::<Vec<_>>(),
            ),
            &to_core(&p.target, Cloud::Target).unwrap(),
            Some(&to_core(&p.template_waypoints, Cloud::Query).unwrap()),
            how,
            &mut |_| (),
        )
        .unwrap();
        let supported = ribreg_sim::register::supported(&o.reach, [false; 2]);
        let expected = [
            false, false, false, false, false, true, true, true, true, true,
        ];
        assert_eq!(supported, expected, "{preset:?}");
        for ((a, b), kept) in o
            .waypoints
            .unwrap()
            .iter()
            .zip(&p.true_waypoints)
            .zip(supported)
        {
            let e = (0..3)
                .map(|k| (f64::from(a[k]) - b[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(
                !kept || e <= 6.0,
                "{preset:?}: a kept waypoint {e:.1} mm off"
            );
        }
    }
}

/// A sweep that stops short on one side (that side's cartilages beyond 0.6 of their
/// length not scanned) is refused: before the side check, 195 of 200 such standard runs
/// of `eval --robustness --pairs 50` were silent failures, the lateral waypoints pulled
/// 10–35 mm toward the sternum. Most are refused as a side cut short; since a rib side
/// is lengthened to at least 0.9 of its other side (`guided::COUNTERPART_SHARE`), the
/// skeleton of a side cut short reaches past its points in the early rounds, and some
/// come out with a rib of that side not seen (seed 2, seed 5's left) or the template
/// unsupported (seed 5's right). (Patients with long cartilages, whose short side still
/// spans 80 % or more of the template's: the next test.)
#[test]
fn a_sweep_that_stops_short_on_one_side_is_refused() {
    for seed in [1, 2, 4, 5] {
        let p = pair(seed);
        for side in [Side::Left, Side::Right] {
            let e = run(&Case::ShortSide(side).apply(&p, seed));
            let named = match e {
                Err(Error::SideShort { side: s, .. } | Error::NotSeen { side: s, .. }) => Some(s),
                Err(Error::Unsupported { .. }) => None,
                _ => panic!("seed {seed}, {side:?}: {e:?}"),
            };
            assert!(
                named.is_none_or(|s| s == core_side(side)),
                "seed {seed}, {side:?}: {e:?}"
            );
        }
        // Refused as a side cut short on both sides of phantoms 1 and 4.
        if seed == 1 || seed == 4 {
            for side in [Side::Left, Side::Right] {
                let e = run(&Case::ShortSide(side).apply(&p, seed));
                assert!(
                    matches!(e, Err(Error::SideShort { side: s, .. }) if s == core_side(side)),
                    "seed {seed}, {side:?}: {e:?}"
                );
            }
        }
    }
}

/// A sweep that stops short on one side of a patient whose cartilages are long, so that
/// the short side still spans 80 % or more of the template's, is refused when that side
/// spans less than 82 % of the other side's (`guided::MIN_LONG_SIDE_RATIO`). Each of
/// these was a silent failure before (waypoints 31–35 mm off); the same sweeps whole
/// are accepted. Since a rib side is lengthened to at least 0.9 of its other side
/// (`guided::COUNTERPART_SHARE`), the short side reads just below 80 % of the template's
/// on all but phantom 0 (78–80 %), and those are refused by the 84 % bound.
#[test]
fn a_sweep_that_stops_short_on_one_side_of_a_long_patient_is_refused() {
    let standard = [(0, pair(0)), (3, pair(3)), (7, pair(7))];
    let hard = [(99, hard(99), Side::Left), (184, hard(184), Side::Right)];
    let cases = standard
        .into_iter()
        .map(|(seed, p)| (seed, p, Side::Left))
        .chain(hard);
    for (seed, p, side) in cases {
        let e = run(&Case::ShortSide(side).apply(&p, seed));
        assert!(
            matches!(
                e,
                Err(Error::SideShort { side: s, .. }) if s == core_side(side)
            ),
            "seed {seed}, {side:?}: {e:?}"
        );
        if seed == 0 {
            assert!(
                matches!(
                    e,
                    Err(Error::SideShort {
                        min_ratio_percent: 82,
                        ..
                    })
                ),
                "{e:?}"
            );
        }
        assert!(run(&p).is_ok(), "seed {seed}: {:?}", run(&p));
    }
}

/// A sweep that stops short on both sides (every cartilage beyond 0.6 of its length
/// not scanned) is refused as such: before the mean-share check, 157 of 200 such
/// standard runs and 81 of 200 hard ones of `eval --robustness --pairs 100` were silent
/// failures, every lateral waypoint pulled toward the sternum, since both sides look
/// alike and the side check compares one with the other.
#[test]
fn a_sweep_that_stops_short_on_both_sides_is_refused() {
    // Each a silent failure before (standard misaligned, hard aligned).
    for (seed, p) in [(0, pair(0)), (1, pair(1)), (1, hard(1)), (9, hard(9))] {
        let e = run(&Case::Narrow.apply(&p, seed));
        assert!(
            matches!(e, Err(Error::SweepShort { .. })),
            "seed {seed}: {e:?}"
        );
        // The same sweep whole is accepted.
        assert!(run(&p).is_ok(), "seed {seed}: {:?}", run(&p));
    }
}

/// A sweep whose band of probe lines is too narrow (nothing farther from the midline
/// than 0.6 of each side's outermost cartilage) cuts ribs 4 and 5 most and leaves
/// ribs 2 and 3 nearly whole: refused as such. Each of these was a silent failure
/// with the mean share of all ribs alone.
#[test]
fn a_sweep_band_too_narrow_is_refused() {
    for (seed, p) in [(9, pair(9)), (13, pair(13)), (13, hard(13)), (22, hard(22))] {
        let e = run(&Case::Band.apply(&p, seed));
        assert!(
            matches!(e, Err(Error::SweepShort { from_rib: 4, .. })),
            "seed {seed}: {e:?}"
        );
    }
}

fn core_side(side: Side) -> ribreg_core::error::Side {
    match side {
        Side::Left => ribreg_core::error::Side::Left,
        Side::Right => ribreg_core::error::Side::Right,
    }
}

/// A side taken for the next rib: hard phantom 4 without its tip holes, misaligned,
/// ended in a pose about 2° about the anterior axis from the aligned run's, whose
/// labels put the left side's cartilages a rib off (rib 2 there unlabelled, rib 3
/// labelled 2). Margin (1.64), support (6.1 mm), coverage and sides all passed: the
/// waypoints of that side came out 14–35 mm off, a silent failure. Its ribs 2 and 3 meet
/// the sternum 8.6 and 7.9 mm apart in height (`guided::rib_levels`; right runs stay
/// within 3.1 mm): refused, naming rib 2. The aligned run of the same patient and sweep
/// is registered within 5 mm.
#[test]
fn a_side_taken_for_the_next_rib_is_refused_not_mapped() {
    let phantom = |variant| {
        PhantomPair::generate(&PhantomConfig {
            seed: 4,
            preset: Preset::Hard,
            variant,
            hard_without: vec![HardPart::TipHoles],
            ..PhantomConfig::default()
        })
    };
    let e = run(&phantom(Variant::Misaligned)).expect_err("one side a rib off");
    assert!(
        matches!(
            e,
            Error::RibLevels {
                rib: 2,
                step_dmm: 60..,
                max_dmm: 50
            }
        ),
        "{e}"
    );
    let worst = run(&phantom(Variant::Aligned)).expect("the aligned run");
    assert!(worst < 5.0, "aligned: {worst:.1} mm");
}
