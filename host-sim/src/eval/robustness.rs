//! `ribreg eval --robustness`: every method on phantom pairs turned and moved as a robot
//! base may stand against the patient, and on sweeps that miss part of the chest. Counts,
//! per case and method, the runs accepted, refused, and accepted but wrong (a *silent
//! failure*: a waypoint more than [`SILENT_FAILURE_MM`] off, reported as a success).
//!
//! The cases, on every pair (the truth is turned and moved with the target):
//! - `yaw D°` for D = 0, 45, …, 315: turned about the patient's anterior axis through the
//!   sweep's centroid, then moved [`MOVE_MM`] (a robot beside the bed, at its head, …);
//! - `rotation k` for k = 1..=[`ROTATIONS`]: a uniformly random 3-D rotation, then moved;
//! - `sparse`: [`SPARSE_FRACTION`] of the sweep's points, at random (complete coverage);
//! - `left side missing`, `right side missing`, `rib 5 missing`: that cartilage's points
//!   removed (outliers and the sternum kept). These sweeps cannot support every waypoint:
//!   the product's goal is that they are refused;
//! - `left side stops short`, `right side stops short`, `both sides stop short`: the
//!   cartilages beyond [`SHORT_SIDE_S`] of their length left out on that side or both;
//!   `both sides stop at a line`: everything farther from the midline than
//!   [`SHORT_SIDE_S`] of each side's outermost cartilage left out, as a band of probe
//!   lines too narrow leaves it. The lateral waypoints are not reached: refused too.
//!
//! With `--imaged` ([`EvalConfig::imaged`]) each case's sweep also comes with the lines
//! its probe imaged ([`probe_track`]), and ours checks every rib end against them, as
//! `register --imaged` and the controller do: a cloud cut short is then a sweep whose
//! lines stopped there.
//!
//! A hard phantom's own sweep holes can do the same to any case: a run whose sweep does
//! not reach a waypoint ([`PhantomPair::unreached_waypoints`]) is counted apart
//! ([`Coverage::Holes`]), neither among the complete sweeps, whose refusals are false
//! alarms, nor among the cut ones.

use super::{evaluate, parallel, phantom, prepare, variant_name, CaseResult, EvalConfig, Imaged};
use crate::error::CliError;
use crate::io;
use crate::phantom::{centroid, gaussian, Part, PhantomPair, Pose, Side};
use crate::sweep::{self, SweepConfig};
use ribreg_core::math::rng::Rng;
use serde_json::json;
use std::fmt::Write as _;
use std::path::Path;

/// A waypoint this far off (mm) in an accepted run is a silent failure: twice the window
/// between two ribs, so the probe would land on a rib or beside the chest.
pub const SILENT_FAILURE_MM: f64 = 10.0;
/// How far every turned case is also moved, mm (the sweep arrives in the robot's base
/// frame, half a metre or more from where the template sits).
pub const MOVE_MM: f64 = 500.0;
/// Random 3-D rotations per pair.
pub const ROTATIONS: u64 = 4;
/// The share of the sweep's points the sparse case keeps.
pub const SPARSE_FRACTION: f64 = 0.3;
/// Where a sweep that stops short on one side ([`Case::ShortSide`]) leaves that side's
/// cartilages, as a share of their length from the sternum: past the medial waypoints
/// (s = 0.35, and 0.5 in gap 4–5) and short of the lateral ones (s = 0.7).
pub const SHORT_SIDE_S: f64 = 0.6;
/// Yaw steps, degrees.
const YAW_STEP_DEG: u32 = 45;

/// One perturbation of a phantom pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Case {
    /// Turned about the anterior axis by this many degrees, then moved.
    Yaw(u32),
    /// The k-th random rotation (1-based), then moved.
    Rotation(u64),
    /// A random [`SPARSE_FRACTION`] of the points.
    Sparse,
    /// One side's cartilages not scanned.
    SideMissing(Side),
    /// Rib 5's cartilages (both sides) not scanned.
    Rib5Missing,
    /// The sweep stops short on one side: its cartilages beyond [`SHORT_SIDE_S`] of
    /// their length not scanned.
    ShortSide(Side),
    /// The sweep stops short on both sides (a band too narrow): every cartilage beyond
    /// [`SHORT_SIDE_S`] of its length not scanned.
    Narrow,
    /// The sweep stops short on both sides at one lateral position, as a band of probe
    /// lines too narrow does: nothing (cartilage or outlier) farther from the midline
    /// than [`SHORT_SIDE_S`] of the side's outermost cartilage point, in the patient's
    /// frame. The shorter cartilages keep more of their length than the longer ones.
    Band,
}

impl Case {
    /// Every case, in table order.
    pub fn all() -> Vec<Case> {
        let mut v: Vec<Case> = (0..360 / YAW_STEP_DEG)
            .map(|k| Case::Yaw(k * YAW_STEP_DEG))
            .collect();
        v.extend((1..=ROTATIONS).map(Case::Rotation));
        v.extend([
            Case::Sparse,
            Case::SideMissing(Side::Left),
            Case::SideMissing(Side::Right),
            Case::Rib5Missing,
            Case::ShortSide(Side::Left),
            Case::ShortSide(Side::Right),
            Case::Narrow,
            Case::Band,
        ]);
        v
    }

    /// Name in tables.
    pub fn name(self) -> String {
        match self {
            Case::Yaw(d) => format!("yaw {d}°"),
            Case::Rotation(k) => format!("rotation {k}"),
            Case::Sparse => format!("sparse ({:.0} %)", SPARSE_FRACTION * 100.0),
            Case::SideMissing(Side::Left) => "left side missing".into(),
            Case::SideMissing(Side::Right) => "right side missing".into(),
            Case::Rib5Missing => "rib 5 missing".into(),
            Case::ShortSide(Side::Left) => "left side stops short".into(),
            Case::ShortSide(Side::Right) => "right side stops short".into(),
            Case::Narrow => "both sides stop short".into(),
            Case::Band => "both sides stop at a line".into(),
        }
    }

    /// Whether the case leaves the sweep whole (it may still miss a waypoint through the
    /// phantom's own holes: [`Coverage`]).
    pub fn complete(self) -> bool {
        !matches!(
            self,
            Case::SideMissing(_)
                | Case::Rib5Missing
                | Case::ShortSide(_)
                | Case::Narrow
                | Case::Band
        )
    }

    /// `pair` perturbed: the target's points (and their materials) filtered and moved,
    /// the truth (pose, true waypoints) moved with them. `seed` drives the random choices.
    pub fn apply(self, pair: &PhantomPair, seed: u64) -> PhantomPair {
        let mut rng = Rng::new(seed ^ 0x005E_ED0F_0B05_u64.wrapping_mul(self.stream()));
        // Band: lateral positions in the patient's frame, and each side's limit.
        let back = pair.pose.inverse();
        let lateral = |p: &[f64; 3]| back.apply(*p)[0];
        let mut outermost = [0.0f64; 2];
        let band = self == Case::Band;
        for (p, m) in pair
            .target
            .iter()
            .zip(&pair.target_material)
            .filter(|_| band)
        {
            if let Some(crate::phantom::Material {
                part: Part::Cartilage { side, .. },
                ..
            }) = m
            {
                let o = &mut outermost[side.index()];
                *o = o.max(lateral(p).abs());
            }
        }
        let within = |p: &[f64; 3]| {
            let x = lateral(p);
            let side = if x >= 0.0 { Side::Left } else { Side::Right };
            x.abs() <= SHORT_SIDE_S * outermost[side.index()]
        };
        let keep = |p: &[f64; 3], m: &Option<crate::phantom::Material>, rng: &mut Rng| match (
            self, m,
        ) {
            (Case::Band, _) => within(p),
            (Case::Sparse, _) => rng.next_f64() < SPARSE_FRACTION,
            (Case::SideMissing(s), Some(m)) => {
                !matches!(m.part, Part::Cartilage { side, .. } if side == s)
            }
            (Case::Rib5Missing, Some(m)) => !matches!(m.part, Part::Cartilage { rib: 5, .. }),
            (Case::ShortSide(s), Some(m)) => {
                !matches!(m.part, Part::Cartilage { side, .. } if side == s && m.s > SHORT_SIDE_S)
            }
            (Case::Narrow, Some(m)) => {
                !matches!(m.part, Part::Cartilage { .. } if m.s > SHORT_SIDE_S)
            }
            _ => true,
        };
        let (target, target_material): (Vec<_>, Vec<_>) = pair
            .target
            .iter()
            .zip(&pair.target_material)
            .filter(|(p, m)| keep(p, m, &mut rng))
            .map(|(p, m)| (*p, *m))
            .unzip();
        let moved = match self {
            Case::Yaw(d) => {
                let anterior = pair.pose.apply_vector([0.0, 0.0, 1.0]);
                about_centroid(&target, anterior, f64::from(d).to_radians(), &mut rng)
            }
            Case::Rotation(_) => {
                let (axis, angle) = random_rotation(&mut rng);
                about_centroid(&target, axis, angle, &mut rng)
            }
            _ => Pose::identity(),
        };
        let mut out = pair.clone();
        out.target = target;
        out.target_material = target_material;
        out.moved(&moved)
    }

    /// Whether the case cuts the sweep short laterally on `side`: that side missing or
    /// stopping short, or both sides stopping short or at a line.
    fn cuts(self, side: Side) -> bool {
        match self {
            Case::SideMissing(s) | Case::ShortSide(s) => s == side,
            Case::Narrow | Case::Band => true,
            _ => false,
        }
    }

    fn stream(self) -> u64 {
        match self {
            Case::Yaw(d) => 1 + u64::from(d),
            Case::Rotation(k) => 1000 + k,
            Case::Sparse => 2000,
            Case::SideMissing(Side::Left) => 2001,
            Case::SideMissing(Side::Right) => 2002,
            Case::Rib5Missing => 2003,
            Case::ShortSide(Side::Left) => 2004,
            Case::ShortSide(Side::Right) => 2005,
            Case::Narrow => 2006,
            Case::Band => 2007,
        }
    }
}

/// The lines a probe imaged to give `moved`, [`Case::apply`] of `case` to a pair whose
/// patient's chest spans `chest` ([`sweep::chest_extent`]): the default sweep's
/// serpentine lines ([`sweep::imaged_band`]) over the chest's cranio-caudal extent.
/// Laterally they run [`SweepConfig::margin_mm`] past the chest on a side the case
/// leaves whole (the protocol: scan 20 mm past the cartilages' ends), but only as far as
/// the outermost cartilage or sternum point it keeps on a side it cuts (that side
/// missing or stopping short, or both sides stopping short or at a line: a band of
/// lines too narrow). In the target's frame, turned and moved with it. The chest's
/// extent is widened to every point the case keeps, outliers too: what a probe's images
/// show lies where they passed (the phantom draws outliers in a box around the cloud).
/// Rib 5 missing keeps the chest's whole height (a cut of the cloud, as the case is;
/// the coverage check refuses it).
pub fn probe_track(case: Case, moved: &PhantomPair, chest: [[f64; 2]; 2]) -> Imaged {
    let margin = SweepConfig::default().margin_mm;
    let back = moved.pose.inverse();
    let patient: Vec<[f64; 3]> = moved.target.iter().map(|p| back.apply(*p)).collect();
    let [mut lo, mut hi] = chest;
    for p in &patient {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    // Lateral ends: the patient's right (−x), then left.
    let mut x = [lo[0] - margin, hi[0] + margin];
    for (end, side) in [(0, Side::Right), (1, Side::Left)] {
        if case.cuts(side) {
            let outermost = (patient.iter().zip(&moved.target_material))
                .filter(|(_, m)| m.is_some())
                .map(|(p, _)| side.sign() * p[0])
                .fold(0.0, f64::max);
            x[end] = side.sign() * outermost;
        }
    }
    sweep::imaged_band(&moved.patient_params, x, [lo[1], hi[1]], &moved.pose)
}

/// Rotation by `angle` about `axis` through the centroid of `points`, then a move of
/// [`MOVE_MM`] in a random direction.
fn about_centroid(points: &[[f64; 3]], axis: [f64; 3], angle: f64, rng: &mut Rng) -> Pose {
    let turn = Pose::about(axis, angle, centroid(points));
    let (dir, _) = random_rotation(rng);
    Pose {
        translation: [0, 1, 2].map(|i| turn.translation[i] + MOVE_MM * dir[i]),
        ..turn
    }
}

/// A uniformly random rotation (a unit quaternion of four Gaussians) as axis and angle.
fn random_rotation(rng: &mut Rng) -> ([f64; 3], f64) {
    loop {
        let q = [gaussian(rng), gaussian(rng), gaussian(rng), gaussian(rng)];
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let v = (q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
        if n > 1e-6 && v > 1e-9 {
            let angle = 2.0 * v.atan2(q[0].abs());
            let s = q[0].signum() / v;
            return ([q[1] * s, q[2] * s, q[3] * s], angle);
        }
    }
}

/// How much of the chest a perturbed pair's sweep shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coverage {
    /// Every waypoint's two cartilages reach past it.
    Complete,
    /// The case cuts nothing, but the phantom's own sweep holes or a lost lateral tip
    /// leave a cartilage short of a waypoint (hard phantoms 26, 40, 76, 92 of 0–99): no
    /// registration can support that waypoint, so it is refused or a silent failure,
    /// never a false alarm.
    Holes,
    /// The case cuts a side or rib 5 away.
    Cut,
    /// The case stops the sweep short on one side or both ([`Case::ShortSide`],
    /// [`Case::Narrow`], [`Case::Band`]): the lateral waypoints there are not reached,
    /// the others are.
    Short,
}

impl Coverage {
    /// The coverage of `case`'s sweep, which does not reach the waypoints `unreached`.
    pub fn of(case: Case, unreached: &[usize]) -> Coverage {
        match (case.complete(), unreached.is_empty()) {
            (false, _) if matches!(case, Case::ShortSide(_) | Case::Narrow | Case::Band) => {
                Coverage::Short
            }
            (false, _) => Coverage::Cut,
            (true, true) => Coverage::Complete,
            (true, false) => Coverage::Holes,
        }
    }

    /// Name in tables and the JSON.
    pub fn name(self) -> &'static str {
        match self {
            Coverage::Complete => "complete",
            Coverage::Holes => "holes hide a waypoint",
            Coverage::Cut => "side or rib 5 cut",
            Coverage::Short => "stops short",
        }
    }
}

/// One method on one perturbed pair.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RobustResult {
    /// The case's name.
    pub case: String,
    /// Whether the sweep covers every waypoint: the case cuts nothing and no sweep hole
    /// hides one ([`PhantomPair::unreached_waypoints`]). A refusal of such a run is a
    /// false alarm.
    pub complete: bool,
    /// [`Coverage::name`] of the run's sweep.
    pub coverage: &'static str,
    /// The waypoints the sweep does not reach (indices into the waypoints).
    pub unreached: Vec<usize>,
    /// `accepted`, `refused` or `silent failure` (judged on the waypoints the method
    /// supports: a partial mapping's marked ones are never driven to).
    pub outcome: &'static str,
    /// The largest error of an accepted run's supported waypoints, mm.
    pub waypoint_max: Option<f64>,
    /// The waypoints the method marked as not reached by the sweep (a partial mapping).
    pub unsupported: Vec<usize>,
    /// The run itself.
    pub result: CaseResult,
}

fn outcome(r: &CaseResult) -> (&'static str, Option<f64>) {
    if r.error.is_some() {
        return ("refused", None);
    }
    // A NaN error is as silent as a large one (`f64::max` would drop it); a waypoint
    // marked unsupported is not driven to.
    let supported = |i: usize| r.waypoint_supported.get(i).is_none_or(|&s| s);
    let max = (r.waypoint_errors.iter().enumerate())
        .filter(|&(i, _)| supported(i))
        .map(|(_, &e)| e)
        .fold(0.0, |a: f64, e| {
            if a.is_nan() || e.is_nan() {
                f64::NAN
            } else {
                a.max(e)
            }
        });
    if max.is_nan() || max > SILENT_FAILURE_MM {
        ("silent failure", Some(max))
    } else {
        ("accepted", Some(max))
    }
}

/// Runs the sweep; writes `out/robustness.md` and `out/robustness.json`; returns the table.
pub fn run_robustness(
    cfg: &EvalConfig,
    out: &Path,
    progress: &mut (dyn FnMut(&str) + Send),
) -> Result<String, CliError> {
    let cases = prepare(cfg, out)?;
    let what = format!(
        "pairs ({} cases × {} methods each)",
        Case::all().len(),
        cfg.methods.len()
    );
    let mut results = parallel(&cases, cfg.jobs, &what, progress, |id| {
        let pair = phantom(cfg, id);
        let (_, variant, seed) = *id;
        let chest = cfg
            .imaged
            .then(|| sweep::chest_extent(&pair.patient_params));
        let mut rows = vec![];
        for case in Case::all() {
            let moved = case.apply(&pair, seed);
            let unreached = moved.unreached_waypoints();
            let coverage = Coverage::of(case, &unreached);
            let track = chest.map(|c| probe_track(case, &moved, c));
            for &m in &cfg.methods {
                let result = evaluate(m, &moved, variant, seed, track.as_ref());
                let (outcome, waypoint_max) = outcome(&result);
                let unsupported = (result.waypoint_supported.iter().enumerate())
                    .filter(|(_, &s)| !s)
                    .map(|(i, _)| i)
                    .collect();
                rows.push(RobustResult {
                    case: case.name(),
                    complete: coverage == Coverage::Complete,
                    coverage: coverage.name(),
                    unreached: unreached.clone(),
                    outcome,
                    waypoint_max,
                    unsupported,
                    result,
                });
            }
        }
        rows
    });
    let names: Vec<String> = Case::all().into_iter().map(Case::name).collect();
    results.sort_by_cached_key(|r| {
        let case = names.iter().position(|n| *n == r.case);
        (
            r.result.preset.clone(),
            case,
            r.result.variant.clone(),
            r.result.seed,
            r.result.method.clone(),
        )
    });
    let table = markdown(cfg, &results);
    io::write_text(&out.join("robustness.md"), &table)?;
    let json = json!({ "pairs": cfg.pairs, "first_seed": cfg.first_seed, "silent_failure_mm": SILENT_FAILURE_MM,
        "move_mm": MOVE_MM, "imaged": cfg.imaged, "cases": results });
    let text = serde_json::to_string_pretty(&json)
        .map_err(|e| CliError::Output(format!("robustness results: {e}")))?;
    io::write_text(&out.join("robustness.json"), &text)?;
    Ok(table)
}

/// Counts of one group of runs.
#[derive(Default)]
struct Counts {
    runs: usize,
    accepted: usize,
    refused: usize,
    silent: usize,
    /// Runs reported as a success with a waypoint marked unsupported (partial).
    marked: usize,
    worst: f64,
    /// Runs reported as a success (accepted or silent) with a waypoint's centre over a
    /// cartilage (negative clearance).
    on_cartilage: usize,
    /// The largest waypoint error across the gap of a run reported as a success, mm.
    worst_across: f64,
}

impl Counts {
    fn of<'a>(rows: impl Iterator<Item = &'a RobustResult>) -> Counts {
        let mut c = Counts::default();
        for r in rows {
            c.runs += 1;
            match r.outcome {
                "accepted" => c.accepted += 1,
                "refused" => c.refused += 1,
                _ => c.silent += 1,
            }
            if r.outcome == "accepted" {
                c.worst = c.worst.max(r.waypoint_max.unwrap_or(0.0));
            }
            if r.outcome != "refused" {
                c.marked += usize::from(!r.unsupported.is_empty());
                let res = &r.result;
                c.on_cartilage += usize::from(res.waypoint_clearance.iter().any(|&x| x < 0.0));
                // A NaN (a waypoint not mapped) is the worst there is.
                c.worst_across = res
                    .waypoint_across_gap
                    .iter()
                    .fold(c.worst_across, |w, &x| {
                        if x.is_nan() {
                            f64::INFINITY
                        } else {
                            w.max(x)
                        }
                    });
            }
        }
        c
    }

    fn row(&self, label: &str, method: &str) -> String {
        let worst = if self.accepted > 0 {
            format!("{:.1}", self.worst)
        } else {
            "—".into()
        };
        let across = if self.accepted + self.silent > 0 {
            format!("{:.1}", self.worst_across)
        } else {
            "—".into()
        };
        format!(
            "| {label} | {method} | {} | {} | {} | {} | {} | {worst} | {} | {across} |",
            self.runs, self.accepted, self.refused, self.silent, self.marked, self.on_cartilage
        )
    }
}

/// A markdown table of [`Counts`]: one row per (group, method), the group's name in the
/// column headed `first`.
fn counts_table(
    s: &mut String,
    first: &str,
    methods: &[String],
    groups: Vec<(String, Vec<&RobustResult>)>,
) {
    let _ = writeln!(
        s,
        "| {first} | method | runs | accepted | refused | silent failures | partial | worst \
         accepted | on a cartilage | worst across the gap |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    for (label, rows) in groups {
        for m in methods {
            let c = Counts::of(rows.iter().copied().filter(|r| &r.result.method == m));
            let _ = writeln!(s, "{}", c.row(&label, m));
        }
    }
}

fn markdown(cfg: &EvalConfig, results: &[RobustResult]) -> String {
    let mut s = String::new();
    let variants: Vec<&str> = cfg.variants.iter().map(|&v| variant_name(v)).collect();
    let _ = writeln!(
        s,
        "Robustness sweep: phantom pairs {} (seeds {}, {}), each turned and moved \
         {MOVE_MM:.0} mm or cut as the case says. A silent failure is a run reported as a \
         success with a waypoint more than {SILENT_FAILURE_MM:.0} mm off; worst: the largest \
         waypoint error of an accepted run, mm. Of the runs reported as a success (accepted \
         or silent): on a cartilage, those with a waypoint whose centre lands over a \
         cartilage; worst across the gap, the largest error toward a rib (\"Across the \
         gap\" in the README), mm. Coverage: complete, every waypoint's two cartilages \
         seen past it; holes hide a waypoint, the case cuts nothing but the phantom's own \
         sweep holes leave a cartilage short of a waypoint (no registration can support \
         it: a refusal is right); stops short, the sweep leaves one side's cartilages or \
         both sides' beyond {SHORT_SIDE_S} of their length out, or everything farther from \
         the midline than {SHORT_SIDE_S} of each side's outermost cartilage (the lateral \
         waypoints there are not reached); side or rib 5 cut, the cut cases. Partial: runs reported as a \
         success with waypoints marked as not reached by the sweep (a partial mapping; \
         they are never driven to, and the other columns judge the rest).\n",
        cfg.pairs,
        cfg.seed_range(),
        variants.join(" and ")
    );
    if cfg.imaged {
        let _ = writeln!(
            s,
            "Each case's sweep comes with the lines its probe imaged (`--imaged`): 20 mm past \
             the chest on a side the case leaves whole, as far as its outermost point on a \
             side it cuts; ours refuses a rib end the probe did not image past, as \
             `register --imaged` and the controller do.\n"
        );
    }
    let methods: Vec<String> = cfg.methods.iter().map(|m| m.name()).collect();
    for preset in &cfg.presets {
        let of = |r: &&RobustResult| r.result.preset == preset.name();
        let _ = writeln!(s, "### {} phantoms\n", preset.name());
        let mine: Vec<&RobustResult> = results.iter().filter(of).collect();
        let by_case = Case::all()
            .into_iter()
            .map(|c| {
                let name = c.name();
                let rows = mine.iter().copied().filter(|r| r.case == name).collect();
                (name, rows)
            })
            .collect();
        counts_table(&mut s, "case", &methods, by_case);
        let _ = writeln!(s, "\nIn all ({} phantoms):\n", preset.name());
        let by_coverage = [
            Coverage::Complete,
            Coverage::Holes,
            Coverage::Short,
            Coverage::Cut,
        ]
        .into_iter()
        .map(|c| {
            let rows = mine
                .iter()
                .copied()
                .filter(|r| r.coverage == c.name())
                .collect();
            (c.name().to_string(), rows)
        })
        .collect();
        counts_table(&mut s, "coverage", &methods, by_coverage);
        let _ = writeln!(s);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::phantom::PhantomConfig;

    fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
        (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
    }

    #[test]
    fn turned_cases_move_the_truth_with_the_target() {
        let pair = PhantomPair::generate(&PhantomConfig::default());
        for case in [Case::Yaw(90), Case::Yaw(180), Case::Rotation(1)] {
            let moved = case.apply(&pair, 3);
            assert_eq!(moved.target.len(), pair.target.len());
            // Rigid: distances between points are kept.
            let d0 = dist(pair.target[0], pair.target[100]);
            let d1 = dist(moved.target[0], moved.target[100]);
            assert!((d0 - d1).abs() < 1e-9, "{case:?}");
            // The truth moved with it: a target point keeps its offset from a waypoint.
            let (w0, w1) = (pair.true_waypoints[0], moved.true_waypoints[0]);
            assert!((dist(pair.target[7], w0) - dist(moved.target[7], w1)).abs() < 1e-9);
            let (t0, t1) = (pair.true_positions(), moved.true_positions());
            assert!((dist(pair.target[7], t0[5]) - dist(moved.target[7], t1[5])).abs() < 1e-9);
            // Moved about half a metre.
            let shift = dist(pair.target[0], moved.target[0]);
            assert!(shift > 0.5 * MOVE_MM, "{case:?}: {shift}");
        }
        // Yaw is about the anterior axis: the anterior component is unchanged up to the move.
        let yaw = Case::Yaw(90).apply(&pair, 3);
        let z = pair.pose.apply_vector([0.0, 0.0, 1.0]);
        let along = |a: [f64; 3], b: [f64; 3]| (0..3).map(|i| (a[i] - b[i]) * z[i]).sum::<f64>();
        let before = along(pair.target[0], pair.target[100]);
        let after = along(yaw.target[0], yaw.target[100]);
        assert!((before - after).abs() < 1e-9);
    }

    /// With the lines its probe imaged, a sweep cut short is refused at the sweep's edge
    /// and a whole one turned is accepted. Each cut one here was a silent failure
    /// without them (`eval --robustness`, 23.5, 28.4 and 24.9 mm off).
    #[test]
    fn a_sweep_cut_short_is_refused_by_its_probe_track() {
        use crate::eval::EvalMethod;
        use crate::phantom::{Preset, Variant};
        use crate::register::Method;
        let ours = EvalMethod::Ours(Method::Improved, true);
        for (seed, preset, cut) in [
            (9, Preset::Standard, Case::ShortSide(Side::Left)),
            (199, Preset::Hard, Case::Band),
            (126, Preset::Standard, Case::Band),
        ] {
            let pair = PhantomPair::generate(&PhantomConfig {
                seed,
                preset,
                ..PhantomConfig::default()
            });
            let chest = sweep::chest_extent(&pair.patient_params);
            for case in [cut, Case::Yaw(90)] {
                let moved = case.apply(&pair, seed);
                let track = probe_track(case, &moved, chest);
                let with = evaluate(ours, &moved, Variant::Aligned, seed, Some(&track));
                let without = evaluate(ours, &moved, Variant::Aligned, seed, None);
                let what = format!("{seed} {case:?}: {:?}", with.error);
                if case == cut {
                    assert_eq!(outcome(&without).0, "silent failure", "{what}");
                    let e = with.error.unwrap_or_default();
                    assert!(e.contains("edge of the sweep"), "{seed} {case:?}: {e}");
                } else {
                    assert_eq!(outcome(&with).0, "accepted", "{what}");
                    assert_eq!(with.waypoint_errors, without.waypoint_errors, "{what}");
                }
            }
        }
    }

    #[test]
    fn cut_cases_remove_exactly_their_part() {
        let pair = PhantomPair::generate(&PhantomConfig::default());
        let left = Case::SideMissing(Side::Left).apply(&pair, 0);
        assert!(left.target.len() < pair.target.len());
        assert!(left.target_material.iter().flatten().all(|m| !matches!(
            m.part,
            Part::Cartilage {
                side: Side::Left,
                ..
            }
        )));
        assert!(left.target_material.iter().flatten().any(|m| matches!(
            m.part,
            Part::Cartilage {
                side: Side::Right,
                ..
            }
        )));
        assert_eq!(left.outlier_count(), pair.outlier_count());
        let rib5 = Case::Rib5Missing.apply(&pair, 0);
        assert!(rib5
            .target_material
            .iter()
            .flatten()
            .all(|m| !matches!(m.part, Part::Cartilage { rib: 5, .. })));
        let sparse = Case::Sparse.apply(&pair, 0);
        let share = sparse.target.len() as f64 / pair.target.len() as f64;
        assert!((share - SPARSE_FRACTION).abs() < 0.05, "{share}");
        // Not moved.
        assert_eq!(rib5.true_waypoints, pair.true_waypoints);
    }

    #[test]
    fn a_far_waypoint_is_a_silent_failure_and_an_error_a_refusal() {
        let mut r = CaseResult {
            method: "m".into(),
            variant: "aligned".into(),
            waypoint_errors: vec![1.0, 10.5],
            ..CaseResult::default()
        };
        assert_eq!(outcome(&r).0, "silent failure");
        r.waypoint_errors = vec![1.0, f64::NAN];
        assert_eq!(outcome(&r).0, "silent failure");
        r.waypoint_errors = vec![1.0, 9.9];
        assert_eq!(outcome(&r), ("accepted", Some(9.9)));
        r.error = Some("no".into());
        assert_eq!(outcome(&r).0, "refused");
    }

    /// A sweep whose holes leave a cartilage short of a waypoint is not complete coverage;
    /// a cut case never is, and a whole sweep of a standard phantom always is.
    #[test]
    fn a_sweep_that_does_not_reach_a_waypoint_is_not_complete() {
        use crate::phantom::Preset;
        let hard = |seed| {
            PhantomPair::generate(&PhantomConfig {
                seed,
                preset: Preset::Hard,
                ..PhantomConfig::default()
            })
        };
        // Hard phantom 40: a sweep hole takes rib 2's right cartilage from s 0.41 on, so
        // the right side's lateral waypoint of gap 2–3 (index 5 + 1, s 0.7) is not reached.
        let pair = hard(40);
        let reach = pair.sweep_reach()[Side::Right.index()][0];
        assert!((0.3..0.7).contains(&reach), "{reach}");
        assert_eq!(pair.unreached_waypoints(), vec![6]);
        for case in [Case::Yaw(90), Case::Rotation(2), Case::Sparse] {
            let u = case.apply(&pair, 40).unreached_waypoints();
            assert!(u.contains(&6), "{case:?}: {u:?}");
            assert_eq!(Coverage::of(case, &u), Coverage::Holes);
        }
        // Hard phantom 0 reaches every waypoint: complete.
        assert_eq!(hard(0).unreached_waypoints(), Vec::<usize>::new());
        let whole = PhantomPair::generate(&PhantomConfig::default());
        assert_eq!(whole.unreached_waypoints(), Vec::<usize>::new());
        assert_eq!(Coverage::of(Case::Yaw(0), &[]), Coverage::Complete);
        // Cutting the left side leaves every left waypoint (0..5) unreached.
        let cut = Case::SideMissing(Side::Left).apply(&whole, 0);
        assert_eq!(cut.unreached_waypoints(), vec![0, 1, 2, 3, 4]);
        assert_eq!(Coverage::of(Case::Rib5Missing, &[]), Coverage::Cut);
        let rib5 = Case::Rib5Missing.apply(&whole, 0).unreached_waypoints();
        assert_eq!(rib5, vec![4, 9]);
    }

    /// A waypoint a partial mapping marks is not judged: the robot never goes there.
    /// One marked waypoint does not hide another's error, and a NaN error anywhere is
    /// a silent failure (a NaN before a finite error was once dropped by `f64::max`).
    #[test]
    fn marked_waypoints_are_not_judged_the_others_are() {
        let judged = |errors: Vec<f64>, supported: Vec<bool>| {
            outcome(&CaseResult {
                waypoint_errors: errors,
                waypoint_supported: supported,
                ..CaseResult::default()
            })
        };
        assert_eq!(
            judged(vec![3.0, 25.0], vec![true, false]),
            ("accepted", Some(3.0))
        );
        assert_eq!(
            judged(vec![3.0, 25.0], vec![]),
            ("silent failure", Some(25.0))
        );
        let (o, max) = judged(vec![12.0, 25.0], vec![true, false]);
        assert_eq!((o, max), ("silent failure", Some(12.0)));
        let (o, _) = judged(vec![f64::NAN, 1.0], vec![true, true]);
        assert_eq!(o, "silent failure");
    }

    /// A run reported as a success with a waypoint over a cartilage is counted, whatever
    /// its Euclidean error; a refused run is not, and a NaN across the gap is the worst.
    #[test]
    fn runs_on_a_cartilage_are_counted_among_those_reported_as_a_success() {
        let run = |errors: Vec<f64>, across: Vec<f64>, clearance: Vec<f64>, error: bool| {
            let result = CaseResult {
                method: "m".into(),
                error: error.then(|| "no".into()),
                waypoint_errors: errors,
                waypoint_across_gap: across,
                waypoint_clearance: clearance,
                ..CaseResult::default()
            };
            let (outcome, waypoint_max) = outcome(&result);
            RobustResult {
                case: "yaw 0°".into(),
                complete: true,
                coverage: Coverage::Complete.name(),
                unreached: vec![],
                outcome,
                waypoint_max,
                unsupported: vec![],
                result,
            }
        };
        let rows = [
            run(vec![3.0], vec![2.0], vec![-0.5], false), // accepted, yet over a cartilage
            run(vec![12.0], vec![0.4], vec![8.0], false), // silent, along the gap
            run(vec![0.0], vec![30.0], vec![-20.0], true), // refused: not counted
        ];
        let c = Counts::of(rows.iter());
        assert_eq!((c.accepted, c.silent, c.refused), (1, 1, 1));
        assert_eq!((c.on_cartilage, c.worst_across), (1, 2.0));
        assert_eq!(
            c.row("l", "m"),
            "| l | m | 3 | 1 | 1 | 1 | 0 | 3.0 | 1 | 2.0 |"
        );
        let nan = [run(vec![1.0], vec![f64::NAN], vec![f64::NAN], false)];
        assert_eq!(Counts::of(nan.iter()).worst_across, f64::INFINITY);
    }
}
