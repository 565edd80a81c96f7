//! `ribreg register`: read the template and target clouds, register, map the template
//! (and waypoints), write the results and a JSON report.
//!
//! Clouds of any size are handled without down-sampling: the core trains its SOMs on
//! seeded samples of the borrowed cloud and maps points one at a time, so memory grows
//! only with the clouds themselves (measured: 200,000 + 200,000 points register in well
//! under a second, see the README).

use crate::io::prepared::TemplateFile;
use crate::io::{self, Cloud, PlyFormat};
use ribreg_core::acquisition::imaged::ImagedArea;
use ribreg_core::config::{Config, RIBS, RIB_SAMPLES};
use ribreg_core::error::Cloud as Which;
use ribreg_core::error::Side as CoreSide;
use ribreg_core::limits::IMAGED_LINES;
use ribreg_core::registration::local_rigid::TransformCache;
use ribreg_core::registration::metrics::{closest_distances, KdTree, Metrics};
use ribreg_core::registration::pipeline::{register, Registration, Template};
use ribreg_core::registration::reach::{self, WaypointReach};
use ribreg_core::registration::{anterior, guided};

use ribreg_core::limits::MAX_COORD_MM;
use ribreg_core::{Error, Vec3};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Which registration to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Method {
    /// The paper's method as published (graph rib model, whole template surface).
    Paper,
    /// The paper's method with this project's improvements: guided rib model and an
    /// anterior-surface template (ribreg_core::registration::guided, ribreg_core::registration::anterior). Needs a
    /// labelled template.
    #[default]
    Improved,
}

impl Method {
    /// The core configuration of the method.
    pub fn config(self) -> Config {
        match self {
            Method::Paper => Config::default(),
            Method::Improved => Config::improved(),
        }
    }

    /// Name used in reports.
    pub fn name(self) -> &'static str {
        match self {
            Method::Paper => "paper",
            Method::Improved => "improved",
        }
    }
}

/// A step of the improved method that an ablation row of `ribreg eval --ablation` leaves
/// out, to measure what it brings (the README's ablation table).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ablation {
    /// Lengthening a rib side the target shows shorter than every other
    /// (`Config::lengthen_short_ribs`): the rib extents as observed.
    LengthenShortRibs,
    /// The thin-plate spline mapping (`Config::mapping`): each point by the local rigid
    /// transform of its skeleton neighbourhood, as in the paper.
    ThinPlate,
    /// The sternum stations the spline pairs besides the rib skeleton
    /// (`Config::sternum_stations`): the ribs' 30 pairs alone.
    SternumStations,
    /// The search for each rib's tips beyond its outermost nodes (`Config::rib_tips`):
    /// the rib extents the nodes show.
    RibTips,
}

impl Ablation {
    /// Every step an ablation row can leave out.
    pub const ALL: [Ablation; 4] = [
        Ablation::LengthenShortRibs,
        Ablation::ThinPlate,
        Ablation::SternumStations,
        Ablation::RibTips,
    ];

    /// What is left out, in a table row's name.
    pub fn name(self) -> &'static str {
        match self {
            Ablation::LengthenShortRibs => "short ribs lengthened",
            Ablation::ThinPlate => "thin-plate mapping",
            Ablation::SternumStations => "sternum stations",
            Ablation::RibTips => "rib tips searched",
        }
    }

    /// `cfg` without the step.
    fn remove(self, cfg: &mut Config) {
        match self {
            Ablation::LengthenShortRibs => cfg.lengthen_short_ribs = false,
            Ablation::ThinPlate => cfg.mapping = ribreg_core::config::Mapping::LocalRigid,
            Ablation::SternumStations => cfg.sternum_stations = false,
            Ablation::RibTips => cfg.rib_tips = false,
        }
    }
}

/// How to register: the method and its options. A [`Method`] alone is its defaults (no
/// orientation prior).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Options {
    /// The method.
    pub method: Method,
    /// Improved method: the patient's anterior direction in the target's frame, roughly
    /// (`register --target-up X,Y,Z`; see `Config::target_up`).
    pub target_up: Option<Vec3>,
    /// SOM-1 and SOM-2 training iterations instead of the method's (6,000 and 3,000): the
    /// same code on a fraction of the work, for the `register` fuzz target. `None` for
    /// every real use.
    pub som_iterations: Option<(u32, u32)>,
    /// A step left out, for `eval --ablation` (`None` for every real use).
    pub without: Option<Ablation>,
    /// Map every waypoint and mark those the sweep does not reach
    /// ([`Mapped::reach`]) instead of refusing the registration (`register --partial`).
    pub partial: bool,
}

impl From<Method> for Options {
    fn from(method: Method) -> Self {
        Options {
            method,
            ..Options::default()
        }
    }
}

impl Options {
    /// The core configuration.
    pub fn config(&self) -> Config {
        let mut cfg = Config {
            target_up: self.target_up,
            ..self.method.config()
        };
        if let Some((som1, som2)) = self.som_iterations {
            cfg.som1.iterations = som1;
            cfg.som2.iterations = som2;
        }
        if let Some(a) = self.without {
            a.remove(&mut cfg);
        }
        cfg
    }
}

/// Transform cache capacity on the host (distinct 10-neighbour sets kept).
pub const HOST_CACHE: usize = 1024;

/// Inputs and outputs of one `register` run (the `ribreg register` arguments).
#[derive(Clone, Debug, Default, clap::Args)]
pub struct RegisterJob {
    /// CT template: a point cloud (PLY; optional integer `label`: rib 2..5, 1 = sternum)
    /// or a prepared template (`ribreg template --prepared`, improved method).
    #[arg(long)]
    pub template: PathBuf,
    /// US target point cloud: PLY, PCD (ascii, binary, binary_compressed), XYZ or CSV.
    #[arg(long)]
    pub target: PathBuf,
    /// Planned waypoints on the template: CSV (`x,y,z` in the template's frame, other
    /// columns such as `label` allowed; or 3D Slicer's `label,l,p,s,...` / `label,r,a,s,...`),
    /// Slicer Markups `.mrk.json` or `.fcsv`. Slicer's LPS / RAS coordinates are converted
    /// into ribreg's patient frame; labels are kept.
    #[arg(long)]
    pub waypoints: Option<PathBuf>,
    /// Output: the template's points, same order, registered (PLY).
    #[arg(long)]
    pub out: PathBuf,
    /// Output: mapped waypoints, in the target's frame, labels kept: CSV (`x,y,z` and
    /// `label` when the input had labels) or Slicer Markups `.mrk.json`, by the
    /// extension.
    #[arg(long)]
    pub out_waypoints: Option<PathBuf>,
    /// Output: JSON report (skeletons, rigid part, ED/HD, timings).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write the output PLY as ASCII (default: binary little-endian).
    #[arg(long)]
    pub ascii: bool,
    /// `paper`: as published; `improved`: guided ribs + anterior template (needs labels).
    #[arg(long, value_enum, default_value_t = Method::Improved)]
    pub method: Method,
    /// Improved method, optional: the patient's anterior (the chest's front) as a
    /// direction `X,Y,Z` in the target's frame, roughly — e.g. `0,0,1` for a supine
    /// patient under a robot whose base z points up. Poses that turn it more than 60° from
    /// the template's anterior are not considered. Default: none, any pose.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_direction, allow_hyphen_values = true)]
    pub target_up: Option<Vec3>,
    /// Improved method: map every waypoint and mark those the sweep does not reach (a
    /// sweep hole or a side scanned short of them) — a `supported` column in the CSV
    /// output (`false`: never drive there), a description in a `.mrk.json` — instead of
    /// refusing the registration. Still refused: a registration that reaches no
    /// waypoint, and every check of the pose and the rib coverage.
    #[arg(long)]
    pub partial: bool,
    /// Improved method: the lines of the sweep the target was compounded from
    /// (`ribreg compound --imaged`), to check that the sweep imaged past every rib end it
    /// shows: a rib end at the sweep's edge may be a cartilage the sweep stopped short
    /// of, and the registration is refused (with `--partial`, that side's waypoints are
    /// marked). The target must be in the sweep's frame (the robot base), as
    /// `compound` writes it.
    #[arg(long, value_name = "LINES.csv")]
    pub imaged: Option<PathBuf>,
}

/// `X,Y,Z`: three finite numbers, not all zero.
fn parse_direction(text: &str) -> Result<Vec3, String> {
    let v: Vec<f32> = text
        .split(',')
        .map(|t| t.trim().parse::<f32>().map_err(|e| format!("{t:?}: {e}")))
        .collect::<Result<_, _>>()?;
    direction(&v).ok_or_else(|| {
        format!("{text:?}: expected a direction X,Y,Z (three finite numbers, not all zero)")
    })
}

/// A direction for [`Options::target_up`]: three finite numbers, not all zero.
pub fn direction(v: &[f32]) -> Option<Vec3> {
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) && (x, y, z) != (0.0, 0.0, 0.0) => {
            Some(Vec3::new(x, y, z))
        }
        _ => None,
    }
}

pub use crate::error::CliError;

/// f64 file points → core points, with the range check done in f64 (so 1e300 is "out of
/// range", not "infinite after the cast").
pub fn to_core(points: &[[f64; 3]], which: Which) -> Result<Vec<Vec3>, Error> {
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let index = u32::try_from(i).unwrap_or(u32::MAX);
            if p.iter().any(|c| !c.is_finite()) {
                Err(Error::NonFinite {
                    cloud: which,
                    index,
                })
            } else if p.iter().any(|c| c.abs() > f64::from(MAX_COORD_MM)) {
                Err(Error::OutOfRange {
                    cloud: which,
                    index,
                })
            } else {
                Ok(Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32))
            }
        })
        .collect()
}

/// Core points → f64 file points.
pub fn to_file(points: &[Vec3]) -> Vec<[f64; 3]> {
    points
        .iter()
        .map(|p| [f64::from(p.x), f64::from(p.y), f64::from(p.z)])
        .collect()
}

/// PLY labels → core labels: 0 (unlabelled), 1 (sternum) or a rib 2..=5.
pub fn to_core_labels(path: &Path, labels: &Option<Vec<i32>>) -> Result<Option<Vec<u8>>, CliError> {
    let Some(labels) = labels else {
        return Ok(None);
    };
    labels
        .iter()
        .enumerate()
        .map(|(i, &l)| {
            u8::try_from(l).ok().filter(|l| *l <= 5).ok_or_else(|| {
                CliError::input(
                    path,
                    format!(
                        "vertex {i}: label {l} is not a rib number 2..5 (1 = sternum, 0 = unlabelled)"
                    ),
                )
            })
        })
        .collect::<Result<Vec<u8>, _>>()
        .map(Some)
}

/// What a run produced (also written into the report).
#[derive(Clone, Debug)]
pub struct RegisterOutcome {
    /// Registered template points (template order).
    pub registered: Vec<Vec3>,
    /// Mapped waypoints, if waypoints were given.
    pub waypoints: Option<Vec<Vec3>>,
    /// Per mapped waypoint, how far the sweep reaches it ([`Mapped::reach`]).
    pub reach: Vec<Option<WaypointReach>>,
    /// ED / HD of the registered template against the target.
    pub metrics: Metrics,
    /// The JSON report.
    pub report: Value,
    /// The prepared template (for plots and diagnostics).
    pub template: Box<Template>,
    /// The registration (for plots and diagnostics).
    pub registration: Box<Registration>,
}

/// The template `method` registers with: the whole cloud for the paper's method; for the
/// improved one, only its probe-facing points ([`anterior::anterior_mask`]), labels needed.
pub fn build_template(
    template: &[Vec3],
    labels: Option<&[u8]>,
    how: impl Into<Options>,
    progress: &mut dyn FnMut(&str),
) -> Result<Template, Error> {
    let how = how.into();
    let cfg = &how.config();
    match how.method {
        Method::Paper => Template::build(template, labels, cfg),
        Method::Improved => {
            let mut mask = vec![false; template.len()];
            let mut cells = vec![anterior::Cell::default(); template.len()];
            anterior::anterior_mask(template, &mut cells, &mut mask)?;
            let keep = |i: usize| mask[i];
            let front: Vec<Vec3> = (0..template.len())
                .filter(|&i| keep(i))
                .map(|i| template[i])
                .collect();
            let front_labels: Option<Vec<u8>> = labels.map(|l| {
                (0..l.len().min(mask.len()))
                    .filter(|&i| keep(i))
                    .map(|i| l[i])
                    .collect()
            });
            progress(&format!(
                "template: {} of {} points face the probe",
                front.len(),
                template.len()
            ));
            Template::build(&front, front_labels.as_deref(), cfg)
        }
    }
}

/// Registers already-loaded clouds (no file I/O): the shared core of `register` and
/// `demo`. `progress` receives one line per stage.
pub fn register_clouds(
    template: &[Vec3],
    labels: Option<&[u8]>,
    target: &[Vec3],
    waypoints: Option<&[Vec3]>,
    how: impl Into<Options>,
    progress: &mut dyn FnMut(&str),
) -> Result<RegisterOutcome, Error> {
    let how = how.into();
    let (tpl, t_template) = prepare_template(template, labels, how, progress)?;
    let labelled = labels.is_some();
    let mapped = Mapped::from_prepared(
        tpl, template, labelled, target, waypoints, how, t_template, progress,
    )?;
    Ok(mapped.measure(progress))
}

/// [`build_template`], timed, with its progress line.
fn prepare_template(
    template: &[Vec3],
    labels: Option<&[u8]>,
    how: Options,
    progress: &mut dyn FnMut(&str),
) -> Result<(Template, std::time::Duration), Error> {
    let t0 = Instant::now();
    let tpl = build_template(template, labels, how, progress)?;
    let t_template = t0.elapsed();
    progress(&format!(
        "template: skeleton from {} SOM-1 nodes, {} key points -> 30 rib points ({:.1} ms)",
        tpl.graph.som1.len(),
        tpl.graph.key_points.len(),
        ms(t_template)
    ));
    Ok((tpl, t_template))
}

/// A registration with the template's points and the waypoints mapped, before its
/// metrics ([`Mapped::measure`]): `ribreg register` writes the mapped points while the
/// metrics are measured.
pub struct Mapped {
    /// Registered template points (template order).
    pub registered: Vec<Vec3>,
    /// Mapped waypoints, if waypoints were given.
    pub waypoints: Option<Vec<Vec3>>,
    /// Per mapped waypoint, how far it lies beyond what the sweep shows of its gap
    /// ([`WaypointReach`]; empty without waypoints, `None`s for the paper's method).
    /// Without [`Options::partial`] every one is reached: the registration is refused
    /// otherwise.
    pub reach: Vec<Option<WaypointReach>>,
    /// The sides (`[right, left]`) with a rib end at the sweep's edge
    /// ([`Mapped::check_edges`]).
    cut: [bool; 2],
    tpl: Box<Template>,
    reg: Box<Registration>,
    method: Method,
    labelled: bool,
    cache: Box<TransformCache<HOST_CACHE>>,
    /// The target as the ED's k-d tree, built while the registration ran.
    target_tree: KdTree<Vec<Vec3>>,
    timings: [std::time::Duration; 3],
}

impl Mapped {
    /// Registers `target` to the template already prepared (`tpl`, built from
    /// `template` by [`build_template`] or read from a prepared file), and maps the
    /// template's points and the waypoints. `t_template` is what preparing took (zero
    /// when read), for the report.
    #[allow(clippy::too_many_arguments)]
    pub fn from_prepared(
        tpl: Template,
        template: &[Vec3],
        labelled: bool,
        target: &[Vec3],
        waypoints: Option<&[Vec3]>,
        how: impl Into<Options>,
        t_template: std::time::Duration,
        progress: &mut dyn FnMut(&str),
    ) -> Result<Self, Error> {
        let how = how.into();
        let cfg = &how.config();
        let t1 = Instant::now();
        // The ED's k-d tree over the target is built on another core meanwhile.
        let (reg, target_tree) = std::thread::scope(|s| {
            let tree = s.spawn(|| KdTree::build(target.to_vec()));
            let reg = register(&tpl, target, cfg);
            (reg, joined(tree))
        });
        let reg = reg?;
        let t_register = t1.elapsed();
        progress(&format!(
            "target: {} points -> 30 rib points paired with the template's, rigid part {:.1}° ({:.1} ms)",
            target.len(),
            reg.pose.angle_deg(),
            ms(t_register)
        ));
        let t2 = Instant::now();
        let mut cache = Box::new(TransformCache::<HOST_CACHE>::new());
        let mut registered = template.to_vec();
        reg.map_in_place(&mut registered, &mut cache)?;
        let mapped_wp = match waypoints {
            Some(w) => {
                let mut w = w.to_vec();
                reg.map_in_place(&mut w, &mut cache)?;
                Some(w)
            }
            None => None,
        };
        let reach: Vec<Option<WaypointReach>> = waypoints
            .iter()
            .zip(&mapped_wp)
            .flat_map(|(planned, mapped)| planned.iter().zip(mapped))
            .map(|(p, m)| WaypointReach::of(&tpl, &reg, p, m))
            .collect();
        reach::check_plan(reach.iter().map(Option::as_ref), how.partial)?;
        let t_map = t2.elapsed();
        let by = match &reg.spline {
            Some(s) => format!("the thin-plate spline of {} skeleton pairs", s.pairs()),
            None => format!("{} local transforms", cache.fits),
        };
        progress(&format!(
            "mapped {} points with {by} ({:.1} ms)",
            registered.len() + mapped_wp.as_ref().map_or(0, Vec::len),
            ms(t_map)
        ));
        Ok(Mapped {
            registered,
            waypoints: mapped_wp,
            reach,
            cut: [false; 2],
            tpl: Box::new(tpl),
            reg: Box::new(reg),
            method: how.method,
            labelled,
            cache,
            target_tree,
            timings: [t_template, t_register, t_map],
        })
    }

    /// Checks every rib end the target shows against where the sweep imaged (`area`,
    /// [`reach::edge_clearances`]): refused ([`reach::check_edges`]) when one lies at the
    /// sweep's edge, unless `partial`, which marks that side's waypoints
    /// ([`Mapped::supported`]) and is refused only when it keeps none. Returns the
    /// clearances (NaN for a rib side not seen or the paper's method).
    pub fn check_edges(
        &mut self,
        area: &ImagedArea<IMAGED_LINES>,
        partial: bool,
    ) -> Result<[[f32; 2]; 4], Error> {
        let (edges, cut) = check_edges(&self.reg, &self.reach, area, partial)?;
        self.cut = cut;
        Ok(edges)
    }

    /// Per mapped waypoint, whether a partial plan keeps it ([`supported`]).
    pub fn supported(&self) -> Vec<bool> {
        supported(&self.reach, self.cut)
    }

    /// ED / HD of the registered template against the target, and the report.
    pub fn measure(self, progress: &mut dyn FnMut(&str)) -> RegisterOutcome {
        let Mapped {
            registered,
            waypoints,
            reach,
            cut,
            tpl,
            reg,
            method,
            labelled,
            cache,
            target_tree,
            timings: [t_template, t_register, t_map],
        } = self;
        let t3 = Instant::now();
        let metrics = compare_on_two_threads(&registered, &target_tree);
        let t_metrics = t3.elapsed();
        progress(&format!(
            "ED {:.2} ± {:.2} mm (max {:.2}), HD {:.2} mm ({:.1} ms)",
            metrics.ed.mean,
            metrics.ed.sd,
            metrics.ed.max,
            metrics.hausdorff,
            ms(t_metrics)
        ));
        let report = json!({
            "version": 1,
            "method": method.name(),
            "template": { "points": registered.len(), "labelled": labelled },
            "target": { "points": target_tree.points().len() },
            "skeleton": skeleton_json(&tpl, &reg),
            "endpoint_match": {
                "coarse_rms_mm": reg.matching.map(|m| m.coarse_rms),
                "endpoint_rms_mm": reg.matching.map_or(0.0, |m| m.endpoint_rms),
                "rotation_deg": reg.pose.angle_deg(),
                "rotation": rows(&reg.pose.rotation),
                "translation": reg.pose.translation.as_slice(),
            },
            "coverage": coverage_json(&tpl, &reg),
            "pose_hypotheses": confidence_json(&reg),
            "waypoint_reach": reach_json(&reach, cut),
            "metrics": {
                "ed_mean_mm": metrics.ed.mean,
                "ed_sd_mm": metrics.ed.sd,
                "ed_max_mm": metrics.ed.max,
                "hausdorff_mm": metrics.hausdorff,
            },
            "mapping": {
                "by": if reg.spline.is_some() { "thin_plate_spline" } else { "local_rigid" },
                "spline_pairs": reg.spline.as_ref().map(|s| s.pairs()),
                "neighbourhoods": cache.len(),
                "fits": cache.fits,
                "cache_hits": cache.hits,
                "cache_restarts": cache.restarts,
                "waypoints": waypoints.as_ref().map_or(0, Vec::len),
            },
            "timings_ms": {
                "template": ms(t_template),
                "register": ms(t_register),
                "map": ms(t_map),
                "metrics": ms(t_metrics),
            },
        });
        RegisterOutcome {
            registered,
            waypoints,
            reach,
            metrics,
            report,
            template: tpl,
            registration: reg,
        }
    }
}

fn skeleton_json(tpl: &Template, reg: &Registration) -> Value {
    let pts = |p: &[Vec3]| p.iter().map(|v| [v.x, v.y, v.z]).collect::<Vec<_>>();
    let mut offset = 0;
    let ribs: Vec<Value> = RIBS
        .iter()
        .zip(RIB_SAMPLES)
        .enumerate()
        .map(|(r, (rib, n))| {
            let v = json!({
                "rib": rib,
                "samples": n,
                "first": offset,
                "template_path_kept": tpl.skeleton.paths[r].len(),
                "target_path_kept": reg.skeleton.paths[r].len(),
                "template_degree": tpl.skeleton.degree[r],
                "target_degree": reg.skeleton.degree[r],
            });
            offset += n;
            v
        })
        .collect();
    json!({
        "template": pts(&tpl.skeleton.points),
        "target": pts(&reg.skeleton.points),
        "ribs": ribs,
    })
}

/// Every rib end `registration` shows against where the sweep imaged (`area`,
/// [`reach::edge_clearances`]), for a plan whose waypoints' reach is `reach`: refused
/// ([`reach::check_edges`]) when one lies at the sweep's edge, unless `partial`, which
/// keeps the plan with that side marked ([`supported`]) and is refused only when that
/// keeps none. The clearances and the sides cut ([`reach::cut_sides`]).
pub fn check_edges(
    registration: &Registration,
    reach: &[Option<WaypointReach>],
    area: &ImagedArea<IMAGED_LINES>,
    partial: bool,
) -> Result<([[f32; 2]; 4], [bool; 2]), Error> {
    let edges = reach::edge_clearances(registration, |p, u, max| area.reach(p, u, max));
    let cut = reach::cut_sides(&edges);
    if !partial || !supported(reach, cut).iter().any(|&k| k) {
        reach::check_edges(&edges)?;
    }
    Ok((edges, cut))
}

/// Per waypoint, whether a partial plan keeps it ([`WaypointReach::supported`]; `true`
/// for a registration without rib extents), and not on a side whose rib ends lie at the
/// sweep's edge (`cut`, [`reach::cut_sides`]; `[false; 2]` without the sweep's lines).
pub fn supported(reach: &[Option<WaypointReach>], cut: [bool; 2]) -> Vec<bool> {
    reach
        .iter()
        .map(|r| {
            r.is_none_or(|r| {
                r.supported(reach.iter().flatten()) && !cut[usize::from(r.side == CoreSide::Left)]
            })
        })
        .collect()
}

/// Guided model: per waypoint, the bounding rib and side it lies farthest beyond, by how
/// much, and whether that is within the bound (`reach::MAX_BEYOND_MM`); `null` for the
/// graph model or without waypoints.
fn reach_json(reach: &[Option<WaypointReach>], cut: [bool; 2]) -> Value {
    if reach.is_empty() || reach.iter().any(Option::is_none) {
        return Value::Null;
    }
    let rows: Vec<Value> = (reach.iter().flatten())
        .zip(supported(reach, cut))
        .map(|(r, supported)| {
            json!({
                "ribs": r.ribs,
                "rib": r.rib,
                "side": r.side.name(),
                // JSON has no infinity: a rib not seen is null.
                "beyond_mm": r.beyond_mm.is_finite().then_some(r.beyond_mm),
                "reached": r.reached(),
                "supported": supported,
            })
        })
        .collect();
    json!({ "max_beyond_mm": reach::MAX_BEYOND_MM, "waypoints": rows })
}

/// Guided model: each rib side's span as a share of the template's, and the least
/// accepted (`guided::check_coverage`); how far apart in height each rib's two sides
/// meet the sternum, against the template's (`guided::check_levels`); `null` for the
/// graph model.
fn coverage_json(tpl: &Template, reg: &Registration) -> Value {
    let Some(spans) = reg.coverage else {
        return Value::Null;
    };
    let ribs: Vec<Value> = RIBS
        .iter()
        .zip(&spans)
        .map(|(rib, [right, left])| json!({ "rib": rib, "right": right, "left": left }))
        .collect();
    let m = guided::ShareMeans::of(&spans);
    // JSON has no NaN: a rib side not seen makes a mean `null`.
    let finite = |v: f32| v.is_finite().then_some(v);
    let levels = guided::rib_levels(
        &reg.skeleton.points,
        &reg.pose,
        &tpl.skeleton.points,
        &tpl.midline_fraction,
    );
    let levels: Vec<Value> = RIBS
        .iter()
        .zip(levels)
        .map(|(rib, level)| json!({ "rib": rib, "left_above_right_mm": level }))
        .collect();
    json!({
        "min_side_span": guided::MIN_SIDE_SPAN,
        "side_spans": ribs,
        "rib_levels": levels,
        "max_rib_level_mm": guided::MAX_RIB_LEVEL_MM,
        "means": {
            "right": finite(m.right),
            "left": finite(m.left),
            "all": finite(m.all),
            "ribs_4_5": finite(m.lower),
        },
        "short_side_share": guided::SHORT_SIDE_SHARE,
        "min_side_ratio": guided::MIN_SIDE_RATIO,
        "min_long_side_ratio": guided::MIN_LONG_SIDE_RATIO,
        "min_mean_share": guided::MIN_MEAN_SHARE,
        "min_lower_share": guided::MIN_LOWER_SHARE,
    })
}

/// Guided model: the refined pose hypotheses' residuals and the accepted bounds
/// (`guided::PoseConfidence`); `null` for the graph model.
fn confidence_json(reg: &Registration) -> Value {
    let Some(c) = reg.confidence else {
        return Value::Null;
    };
    // JSON has no infinity: no distinct runner-up is `null`.
    let finite = |v: f32| v.is_finite().then_some(v);
    json!({
        "hypotheses": c.hypotheses,
        "residual_mm": c.residual_mm,
        "runner_up_mm": finite(c.runner_up_mm),
        "margin": finite(c.margin()),
        "support_mm": finite(c.support_mm),
        "max_residual_mm": guided::MAX_POSE_RESIDUAL_MM,
        "min_margin": guided::MIN_POSE_MARGIN,
        "max_support_mm": guided::MAX_SUPPORT_MM,
    })
}

/// [`ribreg_core::registration::metrics::compare`]'s figures, its two directions on two
/// threads.
fn compare_on_two_threads(registered: &[Vec3], target: &KdTree<Vec<Vec3>>) -> Metrics {
    std::thread::scope(|s| {
        let ed = s.spawn(|| closest_distances(registered, target));
        let back = closest_distances(target.points(), &KdTree::build(registered.to_vec()));
        Metrics::from_directed(joined(ed), back)
    })
}

/// A scoped thread's result; its panic, if it panicked, goes on in this thread.
fn joined<T>(handle: std::thread::ScopedJoinHandle<'_, T>) -> T {
    handle
        .join()
        .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
}

fn rows(m: &nalgebra::Matrix3<f32>) -> Vec<[f32; 3]> {
    (0..3).map(|r| [m[(r, 0)], m[(r, 1)], m[(r, 2)]]).collect()
}

fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// A `--template` file: a PLY (a cloud, or a prepared template), or a cloud in any
/// format [`io::read_cloud`] reads.
fn read_template(path: &Path) -> Result<TemplateFile, CliError> {
    let ply = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    Ok(if ply {
        io::prepared::read_template_file(path)?
    } else {
        TemplateFile::Cloud(io::read_cloud(path)?)
    })
}

/// Runs `ribreg register`. Nothing is written unless everything succeeded; outputs
/// written before a failing one are removed again.
pub fn run(job: &RegisterJob, progress: &mut dyn FnMut(&str)) -> Result<RegisterOutcome, CliError> {
    let outputs: Vec<&PathBuf> = [
        Some(&job.out),
        job.out_waypoints.as_ref(),
        job.report.as_ref(),
    ]
    .into_iter()
    .flatten()
    .collect();
    if job.out_waypoints.is_some() && job.waypoints.is_none() {
        return Err(CliError::Usage("--out-waypoints needs --waypoints".into()));
    }
    for (i, a) in outputs.iter().enumerate() {
        if outputs[..i].contains(a) || [&job.template, &job.target].contains(a) {
            return Err(CliError::Usage(format!(
                "{}: used twice (inputs and outputs must differ)",
                a.display()
            )));
        }
    }
    let t0 = Instant::now();
    // The target and the waypoints are read beside the template; the template's errors
    // come first, as they would one after the other.
    let (template_file, target, planned, imaged) = std::thread::scope(|s| {
        let others = s.spawn(|| {
            let target = io::read_cloud(&job.target);
            let planned = job.waypoints.as_deref().map(io::read_waypoints);
            let imaged = job.imaged.as_deref().map(crate::sweep::read_imaged);
            (target, planned, imaged)
        });
        let template = read_template(&job.template);
        let (target, planned, imaged) = joined(others);
        (template, target, planned, imaged)
    });
    let (template, prepared): (Cloud, Option<Template>) = match template_file? {
        TemplateFile::Cloud(c) => (c, None),
        TemplateFile::Prepared(p) => {
            if job.method != Method::Improved {
                return Err(CliError::Usage(format!(
                    "{}: a prepared template is the improved method's; \
                         give --method paper the template cloud instead",
                    job.template.display()
                )));
            }
            let tpl = crate::template::prepared::from_file(&p)
                .map_err(|e| CliError::input(&job.template, e.to_string()))?;
            (p.cloud, Some(tpl))
        }
    };
    let target: Cloud = target?;
    let planned = planned.transpose()?;
    let imaged = imaged.transpose()?;
    let waypoints = planned.as_ref().map(|w| w.points.clone());
    let labels = to_core_labels(&job.template, &template.labels)?;
    let tpl = to_core(&template.points, Which::Template)?;
    let tgt = to_core(&target.points, Which::Target)?;
    let wps = waypoints
        .as_deref()
        .map(|w| to_core(w, Which::Query))
        .transpose()?;
    if let Some(w) = &waypoints {
        if w.is_empty() {
            return Err(CliError::input(
                job.waypoints.as_deref().unwrap_or(Path::new("")),
                "no waypoints (only the header)",
            ));
        }
    }
    let t_read = t0.elapsed();
    progress(&format!(
        "read {} template and {} target points ({:.1} ms)",
        tpl.len(),
        tgt.len(),
        ms(t_read)
    ));
    if job.method == Method::Improved && labels.is_none() {
        return Err(CliError::input(
            &job.template,
            "the improved method needs a labelled template (PLY vertex property `label`); \
             use --method paper for an unlabelled one",
        ));
    }
    let how = Options {
        method: job.method,
        target_up: job.target_up,
        partial: job.partial,
        ..job.method.into()
    };
    if job.method == Method::Paper && imaged.is_some() {
        return Err(CliError::Usage(
            "--imaged needs the improved method (the paper's finds no rib ends to check)".into(),
        ));
    }
    if job.method == Method::Paper && job.partial {
        return Err(CliError::Usage(
            "--partial needs the improved method (the paper's finds no rib extents to check \
             the waypoints against)"
                .into(),
        ));
    }
    if job.method == Method::Paper && job.target_up.is_some() {
        return Err(CliError::Usage(
            "--target-up needs the improved method (the paper's has no pose hypotheses)".into(),
        ));
    }
    let mapped = match prepared {
        Some(prepared) => {
            progress(&format!(
                "template: prepared, {} SOM-1 nodes -> 30 rib points",
                prepared.graph.som1.len()
            ));
            Mapped::from_prepared(
                prepared,
                &tpl,
                true,
                &tgt,
                wps.as_deref(),
                how,
                std::time::Duration::ZERO,
                progress,
            )?
        }
        None => {
            let (prepared, t_template) = prepare_template(&tpl, labels.as_deref(), how, progress)?;
            let labelled = labels.is_some();
            Mapped::from_prepared(
                prepared,
                &tpl,
                labelled,
                &tgt,
                wps.as_deref(),
                how,
                t_template,
                progress,
            )?
        }
    };
    // Every rib end the target shows against where the sweep imaged: a partial plan
    // leaves out the sides at the sweep's edge, and keeps something or is refused.
    let mut mapped = mapped;
    let edges = match &imaged {
        Some(a) => Some(mapped.check_edges(a, job.partial)?),
        None => None,
    };
    if let Some(e) = &edges {
        progress(&format!(
            "the sweep imaged {:.1} mm or more past every rib end it shows",
            e.iter().flatten().fold(f32::INFINITY, |a, &b| a.min(b))
        ));
    }
    // The mapped points are written while the metrics are measured; the report, which
    // holds them, follows.
    let t1 = Instant::now();
    let out = Cloud {
        points: to_file(&mapped.registered),
        labels: template.labels.clone(),
    };
    let format = if job.ascii {
        PlyFormat::Ascii
    } else {
        PlyFormat::BinaryLittleEndian
    };
    let mut writes: Vec<io::Output<'_>> = vec![(
        &job.out,
        Box::new(move || io::write_ply(&job.out, &out, format)),
    )];
    if let (Some(path), Some(w)) = (&job.out_waypoints, &mapped.waypoints) {
        let supported = match job.partial {
            true => mapped.supported(),
            false => vec![],
        };
        let waypoints = io::Waypoints {
            points: to_file(w),
            labels: planned.map(|p| p.labels).unwrap_or_default(),
            supported,
        };
        writes.push((
            path,
            Box::new(move || io::write_waypoints(path, &waypoints)),
        ));
    }
    let outcome = io::write_all_or_none(writes, || -> Result<_, CliError> {
        let mut outcome = mapped.measure(progress);
        let Some(path) = &job.report else {
            return Ok((outcome, None));
        };
        outcome.report["files"] = json!({
            "template": job.template, "target": job.target, "waypoints": job.waypoints,
            "out": job.out, "out_waypoints": job.out_waypoints, "imaged": job.imaged,
        });
        // Per rib (2..=5), `[right, left]`: how far past its end the sweep imaged.
        outcome.report["sweep_edges"] = match edges {
            Some(e) => {
                let cut = reach::cut_sides(&e);
                json!({
                    "clearance_mm": e.map(|s| s.map(|v| v.is_finite().then_some(v))),
                    "min_clearance_mm": reach::MIN_EDGE_CLEARANCE_MM,
                    "cut": { "right": cut[0], "left": cut[1] },
                })
            }
            None => Value::Null,
        };
        outcome.report["timings_ms"]["read"] = json!(ms(t_read));
        outcome.report["timings_ms"]["total_before_write"] = json!(ms(t0.elapsed()));
        let text = serde_json::to_string_pretty(&outcome.report)
            .map_err(|e| CliError::Output(format!("report: {e}")))?;
        let report: io::Output<'_> = (path, Box::new(move || io::write_text(path, &text)));
        Ok((outcome, Some(report)))
    })?;
    progress(&format!("wrote outputs ({:.1} ms)", ms(t1.elapsed())));
    Ok(outcome)
}
