//! `ribreg eval`: every method on N phantom pairs (aligned and misaligned), in parallel,
//! with a progress line, written as a markdown + JSON table like the paper's Table I,
//! paired t-tests, and figures; [`robustness`]: the same methods on turned, moved and
//! incomplete sweeps, counting refusals and silent failures.

pub mod robustness;

use crate::baselines;
use crate::demo::write_figures;
use crate::error::CliError;
use crate::io;
use crate::phantom::{
    HardPart, Part, PhantomConfig, PhantomPair, Preset, Variant, STERNUM_LABEL, WAYPOINT_PLAN,
};
use crate::plot::{self, Series};
use crate::register::{check_edges, register_clouds, to_core, to_file, Ablation, Method, Options};
use crate::stats::{paired_t_test, Summary};
use ribreg_core::acquisition::imaged::ImagedArea;
use ribreg_core::error::Cloud as Which;
use ribreg_core::limits::IMAGED_LINES;
use ribreg_core::registration::metrics::compare;
use ribreg_core::Vec3;
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// A method compared by `eval`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EvalMethod {
    /// Ours, paper or improved, with the template's labels or without.
    Ours(Method, bool),
    /// Ours (improved) with one step left out (`eval --ablation`).
    Without(Ablation),
    /// Ours (improved), mapping every waypoint and marking those the sweep does not
    /// reach instead of refusing (`register --partial`; `eval --partial`).
    Partial,
    /// A baseline.
    Baseline(baselines::Method),
}

impl EvalMethod {
    /// Every method, ours first.
    pub fn all() -> Vec<EvalMethod> {
        let mut v = vec![
            EvalMethod::Ours(Method::Improved, true),
            EvalMethod::Ours(Method::Paper, true),
            EvalMethod::Ours(Method::Paper, false),
        ];
        v.extend(
            baselines::Method::ALL
                .iter()
                .map(|&m| EvalMethod::Baseline(m)),
        );
        v
    }

    /// Name in tables and figures.
    pub fn name(self) -> String {
        match self {
            EvalMethod::Ours(m, true) => format!("ours ({})", m.name()),
            EvalMethod::Ours(m, false) => format!("ours ({}, unlabelled)", m.name()),
            EvalMethod::Without(a) => format!("ours (improved), no {}", a.name()),
            EvalMethod::Partial => "ours (improved, partial)".into(),
            EvalMethod::Baseline(m) => m.name().to_string(),
        }
    }
}

/// Where a sweep imaged, as the controller keeps it.
type Imaged = ImagedArea<IMAGED_LINES>;

/// What `eval` runs.
#[derive(Clone, Debug)]
pub struct EvalConfig {
    /// Phantom pairs per variant and preset (seeds `first_seed..first_seed + pairs`).
    pub pairs: u64,
    /// The first phantom seed: phantoms no constant was set on are a fresh sample.
    pub first_seed: u64,
    /// Phantom families.
    pub presets: Vec<Preset>,
    /// Difficulties the hard phantoms leave out.
    pub hard_without: Vec<HardPart>,
    /// Pose variants.
    pub variants: Vec<Variant>,
    /// Methods.
    pub methods: Vec<EvalMethod>,
    /// Worker threads.
    pub jobs: usize,
    /// Robustness sweep: each case's sweep comes with the lines its probe imaged, and
    /// ours checks every rib end against them as `register --imaged` does
    /// ([`robustness::probe_track`]).
    pub imaged: bool,
}

impl EvalConfig {
    /// The phantom seeds of each (preset, variant) group.
    pub fn seeds(&self) -> std::ops::Range<u64> {
        self.first_seed..self.first_seed.saturating_add(self.pairs)
    }

    /// The seeds as tables name them: "0..20".
    pub fn seed_range(&self) -> String {
        let r = self.seeds();
        format!("{}..{}", r.start, r.end)
    }
}

/// One method on one phantom pair.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct CaseResult {
    /// Method name.
    pub method: String,
    /// Phantom family: `standard` or `hard`.
    pub preset: String,
    /// `aligned` or `misaligned`.
    pub variant: String,
    /// Phantom seed.
    pub seed: u64,
    /// Why the method failed, if it did (then the numbers are absent).
    pub error: Option<String>,
    /// Registered template → target closest-point distances (mm).
    pub ed: Summary,
    /// Symmetric Hausdorff distance (mm).
    pub hd: f64,
    /// Registered template points against their true positions (mm).
    pub dense: Summary,
    /// The same by structure: [`STRUCTURES`] (the sternum, then ribs 2..5).
    pub dense_by_structure: Vec<Summary>,
    /// The dense error with each sternum point's truth taken by the sternum's landmarks
    /// ([`PhantomPair::true_positions_by_landmarks`]): every point, then the sternum's.
    pub dense_by_landmarks: [Summary; 2],
    /// Mean dense error of the cartilage points (every rib, both sides) in each of
    /// [`ALONG_BINS`] equal stretches from the sternum (material s 0) to the lateral tip
    /// (s 1), mm (NaN where a stretch holds no point).
    pub dense_along_cartilage: Vec<f64>,
    /// Per-waypoint errors (mm), waypoint order.
    pub waypoint_errors: Vec<f64>,
    /// Per waypoint, whether the method supports it: `false` only where a partial
    /// mapping ([`EvalMethod::Partial`]) marked it as not reached by the sweep.
    pub waypoint_supported: Vec<bool>,
    /// The same errors' component across the gap ([`crate::phantom::Gap::across`], mm, unsigned): what
    /// moves the probe toward a rib.
    pub waypoint_across_gap: Vec<f64>,
    /// Per waypoint, the clearance [`crate::phantom::Gap::split`] leaves (mm): how far the probe's centre
    /// stays from the outline of the cartilage it moved toward; negative, it is over one.
    pub waypoint_clearance: Vec<f64>,
    /// Wall time of the registration and mapping (ms).
    pub runtime_ms: f64,
}

/// The structures of [`CaseResult::dense_by_structure`], by template label.
pub const STRUCTURES: [(&str, i32); 5] = [
    ("sternum", STERNUM_LABEL),
    ("rib 2", 2),
    ("rib 3", 3),
    ("rib 4", 4),
    ("rib 5", 5),
];
/// Stretches along the cartilage of [`CaseResult::dense_along_cartilage`].
pub const ALONG_BINS: usize = 5;
/// Half the window a probe must land in between two ribs (the ~5 mm of clinical
/// tolerance), mm: the error across the gap counted as beyond it.
pub const HALF_WINDOW_MM: f64 = 2.5;

/// The position class of waypoint `i` (index into [`WAYPOINT_PLAN`]; both sides share
/// one): "gap 2–3, medial (s 0.35)".
fn waypoint_class(i: usize) -> String {
    let (upper, s) = WAYPOINT_PLAN[i % WAYPOINT_PLAN.len()];
    let where_ = if s < 0.5 {
        "medial"
    } else if s > 0.5 {
        "lateral"
    } else {
        "middle"
    };
    format!("gap {upper}–{}, {where_} (s {s})", upper + 1)
}

fn variant_name(v: Variant) -> &'static str {
    match v {
        Variant::Aligned => "aligned",
        Variant::Misaligned => "misaligned",
    }
}

/// A method's output on one pair: mapped template points, mapped waypoints, time (ms).
/// Registered template points, mapped waypoints, whether each is supported (empty: all),
/// and the wall time (ms).
type Mapped = (Vec<[f64; 3]>, Vec<[f64; 3]>, Vec<bool>, f64);

/// Runs one method on one pair; `Err` carries the method's own error message.
fn run_method(
    m: EvalMethod,
    pair: &PhantomPair,
    imaged: Option<&Imaged>,
) -> Result<Mapped, String> {
    match m {
        EvalMethod::Ours(method, labelled) => run_ours(pair, method.into(), labelled, imaged),
        EvalMethod::Without(a) => {
            let how = Options {
                without: Some(a),
                ..Method::Improved.into()
            };
            run_ours(pair, how, true, imaged)
        }
        EvalMethod::Partial => {
            let how = Options {
                partial: true,
                ..Method::Improved.into()
            };
            run_ours(pair, how, true, imaged)
        }
        EvalMethod::Baseline(b) => {
            let t0 = Instant::now();
            let map = baselines::run(b, &pair.template.points, &pair.target)
                .map_err(|e| e.to_string())?;
            let dense = map.map_all(&pair.template.points);
            let wps = map.map_all(&pair.template_waypoints);
            Ok((dense, wps, vec![], t0.elapsed().as_secs_f64() * 1e3))
        }
    }
}

/// Ours on one pair, `how`, with the template's labels or without; with where the
/// sweep imaged, every rib end the target shows is checked against it as `register
/// --imaged` does ([`check_edges`]).
fn run_ours(
    pair: &PhantomPair,
    how: Options,
    labelled: bool,
    imaged: Option<&Imaged>,
) -> Result<Mapped, String> {
    let t0 = Instant::now();
    let tpl = to_core(&pair.template.points, Which::Template).map_err(|e| e.to_string())?;
    let tgt = to_core(&pair.target, Which::Target).map_err(|e| e.to_string())?;
    let wps = to_core(&pair.template_waypoints, Which::Query).map_err(|e| e.to_string())?;
    let labels = pair.core_labels();
    let labels = labelled.then_some(labels.as_slice());
    let o = register_clouds(&tpl, labels, &tgt, Some(&wps), how, &mut |_| ())
        .map_err(|e| e.to_string())?;
    let cut = match imaged {
        Some(area) => {
            check_edges(&o.registration, &o.reach, area, how.partial)
                .map_err(|e| e.to_string())?
                .1
        }
        None => [false; 2],
    };
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    // Only a partial mapping marks waypoints; any other judges them all.
    let supported = match how.partial {
        true => crate::register::supported(&o.reach, cut),
        false => vec![],
    };
    Ok((
        to_file(&o.registered),
        to_file(&o.waypoints.unwrap_or_default()),
        supported,
        ms,
    ))
}

/// `m` on `pair`, judged against its truth; `imaged`: where the sweep imaged, for
/// [`run_ours`].
fn evaluate(
    m: EvalMethod,
    pair: &PhantomPair,
    variant: Variant,
    seed: u64,
    imaged: Option<&Imaged>,
) -> CaseResult {
    let mut r = CaseResult {
        method: m.name(),
        preset: pair.config.preset.name().into(),
        variant: variant_name(variant).into(),
        seed,
        error: None,
        ed: Summary::default(),
        hd: f64::NAN,
        dense: Summary::default(),
        dense_by_structure: vec![],
        dense_by_landmarks: Default::default(),
        dense_along_cartilage: vec![],
        waypoint_errors: vec![],
        waypoint_supported: vec![],
        waypoint_across_gap: vec![],
        waypoint_clearance: vec![],
        runtime_ms: f64::NAN,
    };
    match run_method(m, pair, imaged) {
        Err(e) => r.error = Some(e),
        Ok((dense, wps, supported, ms)) => {
            let to32 = |p: &[[f64; 3]]| -> Vec<Vec3> {
                p.iter()
                    .map(|q| Vec3::new(q[0] as f32, q[1] as f32, q[2] as f32))
                    .collect()
            };
            let mut reg = to32(&dense);
            let mut tgt = to32(&pair.target);
            let metrics = compare(&mut reg, &mut tgt);
            r.ed = Summary {
                mean: f64::from(metrics.ed.mean),
                sd: f64::from(metrics.ed.sd),
                max: f64::from(metrics.ed.max),
                n: metrics.ed.count as usize,
            };
            r.hd = f64::from(metrics.hausdorff);
            let truth = pair.true_positions();
            let d: Vec<f64> = dense.iter().zip(&truth).map(|(a, b)| dist(a, b)).collect();
            r.dense = Summary::of(&d);
            (r.dense_by_structure, r.dense_along_cartilage) = dense_breakdown(pair, &d);
            let by_landmarks: Vec<f64> = dense
                .iter()
                .zip(pair.true_positions_by_landmarks())
                .map(|(a, b)| dist(a, &b))
                .collect();
            r.dense_by_landmarks = [
                Summary::of(&by_landmarks),
                labelled(pair, &by_landmarks, STERNUM_LABEL),
            ];
            r.waypoint_errors = wps
                .iter()
                .zip(&pair.true_waypoints)
                .map(|(a, b)| dist(a, b))
                .collect();
            (r.waypoint_across_gap, r.waypoint_clearance) = pair
                .across_the_gaps(&wps)
                .into_iter()
                .map(|(across, clearance)| (across.abs(), clearance))
                .unzip();
            r.waypoint_supported = supported;
            r.runtime_ms = ms;
        }
    }
    r
}

/// The summary of the per-point dense errors `d` of `pair`'s template points labelled
/// `label`.
fn labelled(pair: &PhantomPair, d: &[f64], label: i32) -> Summary {
    let v: Vec<f64> = d
        .iter()
        .zip(&pair.template.labels)
        .filter(|(_, &l)| l == label)
        .map(|(e, _)| *e)
        .collect();
    Summary::of(&v)
}

/// Per-point dense errors `d` of `pair`'s template by structure and along the cartilage.
fn dense_breakdown(pair: &PhantomPair, d: &[f64]) -> (Vec<Summary>, Vec<f64>) {
    let by_structure = STRUCTURES
        .iter()
        .map(|&(_, label)| labelled(pair, d, label))
        .collect();
    let mut sum = [0.0; ALONG_BINS];
    let mut count = [0usize; ALONG_BINS];
    for (e, m) in d.iter().zip(&pair.template.material) {
        if let Part::Cartilage { .. } = m.part {
            let b = ((m.s.clamp(0.0, 1.0) * ALONG_BINS as f64) as usize).min(ALONG_BINS - 1);
            sum[b] += e;
            count[b] += 1;
        }
    }
    let along = sum
        .iter()
        .zip(count)
        .map(|(s, n)| if n > 0 { s / n as f64 } else { f64::NAN })
        .collect();
    (by_structure, along)
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// `f` of every case on `jobs` threads, the results in completion order; after each case
/// `progress` gets one line ("eval: 3/40 {what}, 2 s").
fn parallel<C: Sync, R: Send>(
    cases: &[C],
    jobs: usize,
    what: &str,
    progress: &mut (dyn FnMut(&str) + Send),
    f: impl Fn(&C) -> Vec<R> + Sync,
) -> Vec<R> {
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results = Mutex::new(Vec::<R>::new());
    let progress = Mutex::new(progress);
    let t0 = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1) {
            s.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(case) = cases.get(k) else {
                    break;
                };
                let rows = f(case);
                results
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .extend(rows);
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                let mut p = progress.lock().unwrap_or_else(|p| p.into_inner());
                p(&format!(
                    "eval: {n}/{} {what}, {:.0} s",
                    cases.len(),
                    t0.elapsed().as_secs_f64()
                ));
            });
        }
    });
    results.into_inner().unwrap_or_else(|p| p.into_inner())
}

/// One phantom pair of an evaluation.
type PairId = (Preset, Variant, u64);

/// Creates the output folder; the (preset, variant, seed) of every pair `cfg` asks for.
fn prepare(cfg: &EvalConfig, out: &Path) -> Result<Vec<PairId>, CliError> {
    std::fs::create_dir_all(out).map_err(|source| io::IoError::Io {
        path: out.to_owned(),
        op: "cannot create the directory",
        source,
    })?;
    Ok(cfg
        .presets
        .iter()
        .flat_map(|&p| {
            cfg.variants
                .iter()
                .flat_map(move |&v| cfg.seeds().map(move |s| (p, v, s)))
        })
        .collect())
}

/// The phantom pair of one (preset, variant, seed).
fn phantom(cfg: &EvalConfig, &(preset, variant, seed): &PairId) -> PhantomPair {
    PhantomPair::generate(&PhantomConfig {
        seed,
        variant,
        preset,
        hard_without: cfg.hard_without.clone(),
        ..PhantomConfig::default()
    })
}

/// The (preset, variant) groups of `cfg`, in table order, with their names.
fn groups(cfg: &EvalConfig) -> Vec<(&'static str, &'static str)> {
    cfg.presets
        .iter()
        .flat_map(|p| cfg.variants.iter().map(|&v| (p.name(), variant_name(v))))
        .collect()
}

/// Runs the evaluation and writes `out/table.md`, `out/results.json` and the figures.
/// Returns the markdown table.
pub fn run_eval(
    cfg: &EvalConfig,
    out: &Path,
    progress: &mut (dyn FnMut(&str) + Send),
) -> Result<String, CliError> {
    let cases = prepare(cfg, out)?;
    let what = format!("pairs ({} methods each)", cfg.methods.len());
    let mut results = parallel(&cases, cfg.jobs, &what, progress, |id| {
        let pair = phantom(cfg, id);
        cfg.methods
            .iter()
            .map(|&m| evaluate(m, &pair, id.1, id.2, None))
            .collect()
    });
    results.sort_by(|a, b| {
        (&a.preset, &a.variant, a.seed, &a.method).cmp(&(&b.preset, &b.variant, b.seed, &b.method))
    });
    let table = markdown(cfg, &results);
    io::write_text(&out.join("table.md"), &table)?;
    let json = json!({ "pairs": cfg.pairs, "first_seed": cfg.first_seed,
        "presets": cfg.presets.iter().map(|p| p.name()).collect::<Vec<_>>(),
        "hard_without": cfg.hard_without, "methods": cfg.methods.iter().map(|m| m.name()).collect::<Vec<_>>(),
        "summary": summary_json(cfg, &results), "cases": results });
    let text = serde_json::to_string_pretty(&json)
        .map_err(|e| CliError::Output(format!("results: {e}")))?;
    io::write_text(&out.join("results.json"), &text)?;
    figures(cfg, &results, out)?;
    Ok(table)
}

/// A (preset, variant) group of pairs.
type Group = (&'static str, &'static str);

fn rows<'a>(
    results: &'a [CaseResult],
    m: &str,
    (p, v): Group,
) -> impl Iterator<Item = &'a CaseResult> {
    let m = m.to_string();
    results
        .iter()
        .filter(move |r| r.method == m && r.preset == p && r.variant == v)
}

/// Per-waypoint errors of a method, in (seed, waypoint) order, failed cases left out.
fn waypoint_errors(results: &[CaseResult], m: &str, v: Group) -> Vec<(u64, usize, f64)> {
    per_waypoint(results, m, v, |r| &r.waypoint_errors)
}

/// `field` of every waypoint of a method's cases, in (seed, waypoint) order, failed cases
/// left out.
fn per_waypoint(
    results: &[CaseResult],
    m: &str,
    v: Group,
    field: fn(&CaseResult) -> &[f64],
) -> Vec<(u64, usize, f64)> {
    rows(results, m, v)
        .filter(|r| r.error.is_none())
        .flat_map(|r| {
            field(r)
                .iter()
                .enumerate()
                .map(move |(i, &e)| (r.seed, i, e))
        })
        .collect()
}

/// The values of [`per_waypoint`] alone.
fn values(w: &[(u64, usize, f64)]) -> Vec<f64> {
    w.iter().map(|w| w.2).collect()
}

fn summary_json(cfg: &EvalConfig, results: &[CaseResult]) -> Value {
    let mut out = serde_json::Map::new();
    for v in groups(cfg) {
        let mut per = serde_json::Map::new();
        for m in &cfg.methods {
            let name = m.name();
            let ok: Vec<&CaseResult> = rows(results, &name, v)
                .filter(|r| r.error.is_none())
                .collect();
            let wp = values(&waypoint_errors(results, &name, v));
            let mut rt: Vec<f64> = ok.iter().map(|r| r.runtime_ms).collect();
            rt.sort_by(f64::total_cmp);
            per.insert(
                name.clone(),
                json!({
                    "cases": rows(results, &name, v).count(),
                    "failed": rows(results, &name, v).filter(|r| r.error.is_some()).count(),
                    "ed_mean": Summary::of(&ok.iter().map(|r| r.ed.mean).collect::<Vec<_>>()),
                    "ed_max": Summary::of(&ok.iter().map(|r| r.ed.max).collect::<Vec<_>>()),
                    "hd": Summary::of(&ok.iter().map(|r| r.hd).collect::<Vec<_>>()),
                    "dense_mean": Summary::of(&ok.iter().map(|r| r.dense.mean).collect::<Vec<_>>()),
                    "waypoint": Summary::of(&wp),
                    "waypoint_across_gap": Summary::of(&values(&per_waypoint(results, &name, v, |r| &r.waypoint_across_gap))),
                    "waypoints_over_a_cartilage": per_waypoint(results, &name, v, |r| &r.waypoint_clearance)
                        .iter().filter(|w| w.2 < 0.0).count(),
                    "runtime_ms_median": rt.get(rt.len() / 2),
                    "t_test_vs_ours": t_test(results, &cfg.methods[0].name(), &name, v),
                }),
            );
        }
        out.insert(format!("{}, {}", v.0, v.1), Value::Object(per));
    }
    Value::Object(out)
}

/// Paired t-test of the waypoint errors of `ours` against `other` (pairs present in both).
fn t_test(results: &[CaseResult], ours: &str, other: &str, v: Group) -> Option<(f64, f64)> {
    if ours == other {
        return None;
    }
    let a = waypoint_errors(results, ours, v);
    let b = waypoint_errors(results, other, v);
    let (x, y): (Vec<f64>, Vec<f64>) = a
        .iter()
        .filter_map(|&(s, i, e)| b.iter().find(|w| w.0 == s && w.1 == i).map(|w| (e, w.2)))
        .unzip();
    paired_t_test(&x, &y)
}

fn markdown(cfg: &EvalConfig, results: &[CaseResult]) -> String {
    let mut s = String::new();
    let ours = cfg.methods[0].name();
    let _ = writeln!(
        s,
        "Phantom pairs per preset and variant: {} (seeds {}). Errors in mm, mean ± SD over pairs \
         (waypoints: over all waypoints of all pairs); p: paired t-test of the waypoint \
         errors against {ours}.\n",
        cfg.pairs,
        cfg.seed_range()
    );
    if cfg.presets.contains(&Preset::Hard) && !cfg.hard_without.is_empty() {
        let names: Vec<&str> = cfg.hard_without.iter().map(|p| p.name()).collect();
        let _ = writeln!(
            s,
            "Hard phantoms without: {} (an ablation of the phantom).\n",
            names.join(", ")
        );
    }
    for v in groups(cfg) {
        let _ = writeln!(s, "### {} phantoms, {}\n", v.0, v.1);
        let _ = writeln!(
            s,
            "| method | failed | ED mean | ED max | HD | dense error | waypoint error | waypoint max | runtime (median) | p vs {ours} |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
        for m in &cfg.methods {
            let name = m.name();
            let all: Vec<&CaseResult> = rows(results, &name, v).collect();
            let ok: Vec<&CaseResult> = all.iter().copied().filter(|r| r.error.is_none()).collect();
            if ok.is_empty() {
                // Every run failed: no figures (a mean of nothing is not 0).
                let _ = writeln!(
                    s,
                    "| {name} | {n}/{n} | — | — | — | — | — | — | — | — |",
                    n = all.len()
                );
                continue;
            }
            let f = |g: &dyn Fn(&CaseResult) -> f64| {
                Summary::of(&ok.iter().map(|r| g(r)).collect::<Vec<_>>())
            };
            let (ed, edmax, hd, dense) = (
                f(&|r| r.ed.mean),
                f(&|r| r.ed.max),
                f(&|r| r.hd),
                f(&|r| r.dense.mean),
            );
            let wp = Summary::of(&values(&waypoint_errors(results, &name, v)));
            let mut rt: Vec<f64> = ok.iter().map(|r| r.runtime_ms).collect();
            rt.sort_by(f64::total_cmp);
            let p = match t_test(results, &ours, &name, v) {
                Some((_, p)) => format!("{p:.1e}"),
                None => "—".into(),
            };
            let _ = writeln!(
                s,
                "| {name} | {}/{} | {:.2} ± {:.2} | {:.1} | {:.1} ± {:.1} | {:.2} ± {:.2} | {:.2} ± {:.2} | {:.1} | {:.0} ms | {p} |",
                all.len() - ok.len(),
                all.len(),
                ed.mean,
                ed.sd,
                edmax.mean,
                hd.mean,
                hd.sd,
                dense.mean,
                dense.sd,
                wp.mean,
                wp.sd,
                wp.max,
                rt.get(rt.len() / 2).copied().unwrap_or(f64::NAN),
            );
        }
        let _ = writeln!(s);
    }
    across_the_gap(&mut s, cfg, results);
    breakdown(&mut s, cfg, results);
    let failures: Vec<&CaseResult> = results.iter().filter(|r| r.error.is_some()).collect();
    if !failures.is_empty() {
        let _ = writeln!(s, "Failures:\n");
        for r in failures {
            let _ = writeln!(
                s,
                "- {} {} {} seed {}: {}",
                r.method,
                r.preset,
                r.variant,
                r.seed,
                r.error.as_deref().unwrap_or("")
            );
        }
    }
    s
}

fn figures(cfg: &EvalConfig, results: &[CaseResult], out: &Path) -> Result<(), CliError> {
    let fig = |e: plot::PlotError| CliError::Output(format!("figure: {e}"));
    for v in groups(cfg) {
        let series: Vec<Series> = cfg
            .methods
            .iter()
            .map(|m| Series {
                label: m.name(),
                values: values(&waypoint_errors(results, &m.name(), v)),
            })
            .collect();
        plot::error_distributions(
            &out.join(format!("waypoint_errors_{}_{}", v.0, v.1)),
            &format!(
                "Waypoint error per method ({} phantoms, {} pairs)",
                v.0, v.1
            ),
            "waypoint error (mm)",
            &series,
            Some((5.0, "clinical tolerance 5 mm")),
        )
        .map_err(fig)?;
        let across: Vec<Series> = cfg
            .methods
            .iter()
            .map(|m| Series {
                label: m.name(),
                values: values(&per_waypoint(results, &m.name(), v, |r| {
                    &r.waypoint_across_gap
                })),
            })
            .collect();
        plot::error_distributions(
            &out.join(format!("waypoint_across_gap_{}_{}", v.0, v.1)),
            &format!(
                "Waypoint error across the gap, toward a rib ({} phantoms, {} pairs)",
                v.0, v.1
            ),
            "error across the gap (mm)",
            &across,
            Some((HALF_WINDOW_MM, "half a 5 mm window")),
        )
        .map_err(fig)?;
        // Where along the cartilage the first method's dense error sits.
        let ours = cfg.methods[0].name();
        let ok: Vec<&CaseResult> = rows(results, &ours, v)
            .filter(|r| r.error.is_none())
            .collect();
        let mut along: Vec<Series> = (0..ALONG_BINS)
            .map(|b| Series {
                label: format!(
                    "s {:.1}–{:.1}",
                    b as f64 / ALONG_BINS as f64,
                    (b + 1) as f64 / ALONG_BINS as f64
                ),
                values: ok
                    .iter()
                    .filter_map(|r| r.dense_along_cartilage.get(b).copied())
                    .collect(),
            })
            .collect();
        along.push(Series {
            label: "sternum".into(),
            values: ok
                .iter()
                .filter_map(|r| r.dense_by_structure.first().map(|s| s.mean))
                .collect(),
        });
        plot::error_distributions(
            &out.join(format!("dense_along_cartilage_{}_{}", v.0, v.1)),
            &format!(
                "{ours}: dense error along the cartilage, sternum (s 0) to tip (s 1), per pair ({}, {})",
                v.0, v.1
            ),
            "mean dense error of the stretch (mm)",
            &along,
            Some((4.0, "goal for every waypoint 4 mm")),
        )
        .map_err(fig)?;
    }
    // Fig. 4 and Fig. 6 for the first aligned pair.
    let pair = PhantomPair::generate(&PhantomConfig {
        seed: 0,
        ..PhantomConfig::default()
    });
    let tpl = to_core(&pair.template.points, Which::Template)?;
    let tgt = to_core(&pair.target, Which::Target)?;
    let labels = pair.core_labels();
    let outcome = register_clouds(
        &tpl,
        Some(&labels),
        &tgt,
        None,
        Method::Improved,
        &mut |_| (),
    )?;
    let mapped: Vec<(String, Vec<[f64; 3]>)> = cfg
        .methods
        .iter()
        .filter_map(|&m| {
            run_method(m, &pair, None)
                .ok()
                .map(|(_, w, ..)| (m.name(), w))
        })
        .collect();
    write_figures(out, &tpl, &tgt, &outcome, &pair.true_waypoints, &mapped)
}

/// The (preset, variant) groups of `cfg` as table columns: the groups, the header cells
/// after the first column's, and the rule under the header.
fn group_columns(cfg: &EvalConfig) -> (Vec<Group>, String, String) {
    let groups = groups(cfg);
    let head = groups
        .iter()
        .map(|g| format!("{}, {}", g.0, g.1))
        .collect::<Vec<_>>()
        .join(" | ");
    let rule = "|---".repeat(groups.len() + 1) + "|";
    (groups, head, rule)
}

/// Every method's waypoint error across the gap, one column per (preset, variant) group.
fn across_the_gap(s: &mut String, cfg: &EvalConfig, results: &[CaseResult]) {
    let (groups, head, rule) = group_columns(cfg);
    let _ = writeln!(
        s,
        "### Waypoint error across the gap\n\nThe component of each waypoint's error toward \
         a neighbouring rib (in the chest's plane, between the two cartilages' centrelines \
         at the waypoint, as the probe sees them): mean ± SD / max (mm), the share beyond \
         {HALF_WINDOW_MM} mm (half a 5 mm window), and the waypoints whose centre lands over \
         a cartilage (past its outline; in brackets the least clearance left, mm).\n\n\
         | method | {head} |\n{rule}"
    );
    for m in &cfg.methods {
        let name = m.name();
        let cells: Vec<String> = groups
            .iter()
            .map(|&g| {
                let e = values(&per_waypoint(results, &name, g, |r| &r.waypoint_across_gap));
                let c = values(&per_waypoint(results, &name, g, |r| &r.waypoint_clearance));
                if e.is_empty() {
                    return "— (no run accepted)".into();
                }
                let sum = Summary::of(&e);
                let beyond = e.iter().filter(|&&x| x > HALF_WINDOW_MM).count();
                format!(
                    "{:.2} ± {:.2} / {:.1}, {:.1} %, {} ({:.1})",
                    sum.mean,
                    sum.sd,
                    sum.max,
                    100.0 * beyond as f64 / e.len().max(1) as f64,
                    c.iter().filter(|&&x| x < 0.0).count(),
                    c.iter().copied().fold(f64::INFINITY, f64::min),
                )
            })
            .collect();
        let _ = writeln!(s, "| {name} | {} |", cells.join(" | "));
    }
    let _ = writeln!(s);
}

/// The first method's waypoint error by position and dense error by structure, one
/// column per (preset, variant) group.
fn breakdown(s: &mut String, cfg: &EvalConfig, results: &[CaseResult]) {
    let ours = cfg.methods[0].name();
    let (groups, head, rule) = group_columns(cfg);
    let _ = writeln!(
        s,
        "### {ours}: waypoint error by position\n\nMean / max (mm) and the share beyond \
         4 mm, both sides pooled.\n\n| waypoint | {head} |\n{rule}"
    );
    for class in 0..WAYPOINT_PLAN.len() {
        let cells: Vec<String> = groups
            .iter()
            .map(|&g| {
                let e: Vec<f64> = waypoint_errors(results, &ours, g)
                    .iter()
                    .filter(|w| w.1 % WAYPOINT_PLAN.len() == class)
                    .map(|w| w.2)
                    .collect();
                let sum = Summary::of(&e);
                let beyond = e.iter().filter(|&&x| x > 4.0).count();
                format!(
                    "{:.2} / {:.1}, {:.0} %",
                    sum.mean,
                    sum.max,
                    100.0 * beyond as f64 / e.len().max(1) as f64
                )
            })
            .collect();
        let _ = writeln!(s, "| {} | {} |", waypoint_class(class), cells.join(" | "));
    }
    let _ = writeln!(
        s,
        "\n### {ours}: dense error by structure\n\nMean ± SD over pairs of each pair's mean, \
         and the largest pair mean (mm).\n\n| structure | {head} |\n{rule}"
    );
    // Mean ± SD over the accepted pairs of `of` each, and the largest, one cell a group.
    let row = |s: &mut String, name: &str, of: &dyn Fn(&CaseResult) -> Option<f64>| {
        let cells: Vec<String> = groups
            .iter()
            .map(|&g| {
                let m: Vec<f64> = rows(results, &ours, g)
                    .filter(|r| r.error.is_none())
                    .filter_map(of)
                    .collect();
                let sum = Summary::of(&m);
                format!("{:.2} ± {:.2} (max {:.1})", sum.mean, sum.sd, sum.max)
            })
            .collect();
        let _ = writeln!(s, "| {name} | {} |", cells.join(" | "));
    };
    for (k, (name, _)) in STRUCTURES.iter().enumerate() {
        row(s, name, &|r| r.dense_by_structure.get(k).map(|x| x.mean));
    }
    // The sternum and every point again, the sternum's truth by its landmarks (its ends
    // and the rib attachments, `PhantomPair::true_positions_by_landmarks`).
    row(s, "sternum, truth by its landmarks", &|r| {
        Some(r.dense_by_landmarks[1].mean)
    });
    row(s, "all, the sternum's truth by its landmarks", &|r| {
        Some(r.dense_by_landmarks[0].mean)
    });
    let _ = writeln!(s);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waypoint_classes_follow_the_plan_on_both_sides() {
        assert_eq!(waypoint_class(0), "gap 2–3, medial (s 0.35)");
        assert_eq!(waypoint_class(1), "gap 2–3, lateral (s 0.7)");
        assert_eq!(waypoint_class(4), "gap 4–5, middle (s 0.5)");
        // The right side's waypoints follow the left's in the same order.
        for i in 0..WAYPOINT_PLAN.len() {
            assert_eq!(waypoint_class(i), waypoint_class(i + WAYPOINT_PLAN.len()));
        }
    }

    /// `--first-seed` shifts every group's seeds, and the tables say which they are.
    #[test]
    fn the_first_seed_shifts_the_phantoms() {
        let cfg = EvalConfig {
            pairs: 3,
            first_seed: 100,
            presets: vec![Preset::Standard, Preset::Hard],
            hard_without: vec![],
            variants: vec![Variant::Aligned],
            methods: vec![EvalMethod::Ours(Method::Improved, true)],
            jobs: 1,
            imaged: false,
        };
        let dir = std::env::temp_dir().join(format!("ribreg-first-seed-{}", std::process::id()));
        let ids = prepare(&cfg, &dir).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        let seeds: Vec<u64> = ids.iter().map(|id| id.2).collect();
        assert_eq!(seeds, [100, 101, 102, 100, 101, 102]);
        assert_eq!(cfg.seed_range(), "100..103");
        assert!(markdown(&cfg, &[]).contains("(seeds 100..103)"));
    }

    /// The tables: a method whose every run failed shows no figures (not zeros), and the
    /// across-the-gap table counts a waypoint beyond half the window and one over a
    /// cartilage.
    #[test]
    fn tables_show_failed_methods_and_the_error_across_the_gap() {
        let cfg = EvalConfig {
            pairs: 2,
            first_seed: 0,
            presets: vec![Preset::Standard],
            hard_without: vec![],
            variants: vec![Variant::Aligned],
            methods: vec![
                EvalMethod::Ours(Method::Improved, true),
                EvalMethod::Ours(Method::Paper, true),
            ],
            jobs: 1,
            imaged: false,
        };
        let case = |m: EvalMethod, seed, error: Option<&str>| CaseResult {
            method: m.name(),
            preset: "standard".into(),
            variant: "aligned".into(),
            seed,
            error: error.map(Into::into),
            waypoint_errors: vec![1.0, 3.0],
            waypoint_across_gap: vec![0.5, 3.0],
            waypoint_clearance: vec![9.0, -1.5],
            ..CaseResult::default()
        };
        let results = vec![
            case(cfg.methods[0], 0, None),
            case(cfg.methods[0], 1, Some("refused")),
            case(cfg.methods[1], 0, Some("refused")),
            case(cfg.methods[1], 1, Some("refused")),
        ];
        let md = markdown(&cfg, &results);
        assert!(
            md.contains("| ours (paper) | 2/2 | — | — | — | — | — | — | — | — |"),
            "{md}"
        );
        assert!(
            md.contains("| ours (paper) | — (no run accepted) |"),
            "{md}"
        );
        // 0.5 and 3.0 mm across: mean 1.75, one of two beyond 2.5 mm, one over a cartilage.
        assert!(
            md.contains("| ours (improved) | 1.75 ± 1.25 / 3.0, 50.0 %, 1 (-1.5) |"),
            "{md}"
        );
    }

    /// Each template point's error lands in its structure and its stretch of cartilage:
    /// an error equal to the point's label, or to its stretch, comes back as the means.
    #[test]
    fn dense_breakdown_sorts_points_by_structure_and_by_position_along_the_cartilage() {
        let pair = PhantomPair::generate(&PhantomConfig {
            spacing_mm: 5.0,
            us_spacing_mm: 5.0,
            ..PhantomConfig::default()
        });
        let by_label: Vec<f64> = pair.template.labels.iter().map(|&l| f64::from(l)).collect();
        let (structures, _) = dense_breakdown(&pair, &by_label);
        for (s, (_, label)) in structures.iter().zip(STRUCTURES) {
            assert!(s.n > 0);
            assert_eq!((s.mean, s.max), (f64::from(label), f64::from(label)));
        }
        let n: usize = structures.iter().map(|s| s.n).sum();
        assert_eq!(n, pair.template.points.len());
        let by_stretch: Vec<f64> = pair
            .template
            .material
            .iter()
            .map(|m| {
                (m.s * ALONG_BINS as f64)
                    .floor()
                    .min(ALONG_BINS as f64 - 1.0)
            })
            .collect();
        let (_, along) = dense_breakdown(&pair, &by_stretch);
        assert_eq!(along, (0..ALONG_BINS).map(|b| b as f64).collect::<Vec<_>>());
    }
}
