//! The `ribreg template` job: read one source, label, write the template (and its
//! prepared parts).

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::CliError;
use crate::io::prepared::write_prepared;
use crate::io::volume::read_labelmap;
use crate::io::{self, Cloud, PlyFormat, Space};
use crate::register::{build_template, to_core, to_core_labels, Method};
use ribreg_core::error::Cloud as Which;

use super::autolabel::auto_labels;
use super::labelmap::{template_from_labelmap, LabelIds};

/// Arguments of `ribreg template` (the library's, so tests can build one).
#[derive(Clone, Debug, clap::Args)]
pub struct TemplateJob {
    /// A labelmap volume: NIfTI-1 (`.nii`, `.nii.gz`), NRRD (`.nrrd`, `.seg.nrrd`), or a
    /// folder of TotalSegmentator per-class files. Ids: TotalSegmentator v2 `total`
    /// (sternum 116, costal_cartilages 117, rib_left_N 91+N, rib_right_N 103+N), the
    /// segment names of a `.seg.nrrd`, or `--label-map`.
    #[arg(long, conflicts_with_all = ["parts", "cloud"])]
    pub labelmap: Option<PathBuf>,
    /// JSON object of class name → label value for `--labelmap`, TotalSegmentator's
    /// names: `{"sternum": 3, "costal_cartilages": 4, "rib_left_2": 10, ...}`.
    #[arg(long, requires = "labelmap")]
    pub label_map: Option<PathBuf>,
    /// The labelmap's rib number to take as rib 2 (TotalSegmentator's numbering can be
    /// off by one; the summary says which ids were taken).
    #[arg(long, default_value_t = 2)]
    pub rib2: usize,
    /// `LABEL=FILE`, repeated: a surface mesh (PLY, OBJ, STL) of one part, `LABEL` being
    /// `sternum` or a rib `2`..`5` (one side or both in one file). An STL's
    /// `SPACE=LPS|RAS` header is honoured; other meshes are in `--space`.
    #[arg(long = "part", value_name = "LABEL=FILE", conflicts_with = "cloud")]
    pub parts: Vec<String>,
    /// A point cloud (PLY, PCD, XYZ, CSV): its `label`s are kept when present, otherwise
    /// found by the rule of `ribreg_sim::template::autolabel`.
    #[arg(long)]
    pub cloud: Option<PathBuf>,
    /// The frame of meshes and clouds that declare none: `patient` (ribreg's: x left,
    /// y cranial, z anterior), `LPS` or `RAS`. Labelmaps always declare theirs.
    #[arg(long, value_parser = parse_space, default_value = "patient")]
    pub space: Space,
    /// Distance between template points, mm.
    #[arg(long, default_value_t = 2.5)]
    pub spacing: f64,
    /// Output: the labelled template cloud (PLY with `label`; binary unless `--ascii`).
    #[arg(long)]
    pub out: PathBuf,
    /// Output: also the prepared template (everything the improved method computes of
    /// it, once), for `ribreg register --template` and the controller.
    #[arg(long)]
    pub prepared: Option<PathBuf>,
    /// Write `--out` as ASCII PLY.
    #[arg(long)]
    pub ascii: bool,
    /// Seed of the mesh sampling.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

fn parse_space(s: &str) -> Result<Space, String> {
    Space::parse(s).ok_or_else(|| format!("unknown space \"{s}\" (expected patient, LPS or RAS)"))
}

/// What `ribreg template` made.
#[derive(Clone, Debug)]
pub struct TemplateOutcome {
    /// The labelled template cloud (patient frame).
    pub cloud: Cloud,
    /// Points per label 0..=5.
    pub counts: [usize; 6],
    /// One line on where the labels came from.
    pub source: String,
}

/// A `--part` label: `sternum` → 1, `2`..`5`.
fn part_label(s: &str) -> Option<i32> {
    match s.trim().to_ascii_lowercase().as_str() {
        "sternum" | "1" => Some(1),
        other => other.parse().ok().filter(|l| (2..=5).contains(l)),
    }
}

/// Runs `ribreg template`. Nothing is written unless everything succeeded.
///
/// # Errors
/// [`CliError::Usage`] for no source or `--spacing` out of range; the readers' errors;
/// [`CliError::Input`] for a source that cannot give a labelled template (a rib
/// missing, ambiguous labels, a mesh with no area); the core's refusal of the
/// template when preparing it.
pub fn run(job: &TemplateJob, progress: &mut dyn FnMut(&str)) -> Result<TemplateOutcome, CliError> {
    if !(job.spacing.is_finite() && (0.5..=20.0).contains(&job.spacing)) {
        return Err(CliError::Usage(format!(
            "--spacing {}: expected 0.5..=20 mm",
            job.spacing
        )));
    }
    let inputs: Vec<&Path> = job
        .labelmap
        .iter()
        .chain(&job.cloud)
        .map(PathBuf::as_path)
        .chain(
            job.parts
                .iter()
                .filter_map(|p| p.split_once('=').map(|(_, f)| Path::new(f))),
        )
        .collect();
    let outputs: Vec<&Path> = std::iter::once(job.out.as_path())
        .chain(job.prepared.as_deref())
        .collect();
    for (i, o) in outputs.iter().enumerate() {
        if outputs[..i].contains(o) || inputs.contains(o) {
            return Err(CliError::Usage(format!(
                "{}: used twice (inputs and outputs must differ)",
                o.display()
            )));
        }
    }
    let t0 = Instant::now();
    let (cloud, source) = if let Some(path) = &job.labelmap {
        let volume = read_labelmap(path)?;
        progress(&format!(
            "read {}: {} × {} × {} voxels, {} world ({:.1} ms)",
            path.display(),
            volume.dims[0],
            volume.dims[1],
            volume.dims[2],
            volume.space.name(),
            t0.elapsed().as_secs_f64() * 1e3
        ));
        let ids = match &job.label_map {
            Some(map) => LabelIds::from_json(map)?,
            None if !volume.segments.is_empty() => {
                let ids =
                    LabelIds::from_names(volume.segments.iter().map(|(n, v)| (n.as_str(), *v)));
                if ids.sternum.is_empty() || ids.cartilage.is_empty() {
                    return Err(CliError::input(
                        path,
                        "its segments are not named as ribreg expects (sternum, \
                         costal_cartilages, rib_left_N, rib_right_N); give --label-map",
                    ));
                }
                ids
            }
            None => LabelIds::totalsegmentator(),
        };
        let (cloud, summary) = template_from_labelmap(&volume, &ids, job.rib2, job.spacing, path)?;
        (cloud, summary.to_string())
    } else if !job.parts.is_empty() {
        let mut cloud = Cloud {
            points: Vec::new(),
            labels: Some(Vec::new()),
        };
        let mut spaces = Vec::new();
        for (k, part) in job.parts.iter().enumerate() {
            let (label, file) = part
                .split_once('=')
                .ok_or_else(|| CliError::Usage(format!("--part {part}: expected LABEL=FILE")))?;
            let label = part_label(label).ok_or_else(|| {
                CliError::Usage(format!(
                    "--part {part}: label \"{label}\" is not sternum or a rib 2..5"
                ))
            })?;
            let file = Path::new(file);
            let (mesh, space) = io::read_mesh_in(file, job.space)?;
            let points =
                crate::sample::poisson_disc(&mesh, job.spacing, job.seed.wrapping_add(k as u64))
                    .map_err(|e| CliError::input(file, e.to_string()))?;
            progress(&format!(
                "{}: {} points labelled {label} ({} frame)",
                file.display(),
                points.len(),
                space.name()
            ));
            spaces.push(space.name());
            let n = points.len();
            cloud.points.extend(points);
            if let Some(l) = cloud.labels.as_mut() {
                l.extend(std::iter::repeat_n(label, n));
            }
        }
        (
            cloud,
            format!("{} meshes ({})", job.parts.len(), spaces.join(", ")),
        )
    } else if let Some(path) = &job.cloud {
        let mut cloud = io::read_cloud(path)?;
        if job.space != Space::Patient {
            for p in &mut cloud.points {
                *p = job.space.to_patient(*p);
            }
        }
        match &cloud.labels {
            Some(_) => (cloud, format!("{}: labels as given", path.display())),
            None => {
                let found = auto_labels(&cloud.points).map_err(|e| {
                    CliError::input(path, format!("cannot label it automatically: {e}"))
                })?;
                let line = format!("{}: labels found automatically ({found})", path.display());
                cloud.labels = Some(found.labels);
                (cloud, line)
            }
        }
    } else {
        return Err(CliError::Usage(
            "give a source: --labelmap FILE, --part LABEL=FILE (repeated) or --cloud FILE".into(),
        ));
    };
    let mut counts = [0usize; 6];
    for l in cloud.labels.iter().flatten() {
        if let Some(c) = usize::try_from(*l).ok().and_then(|l| counts.get_mut(l)) {
            *c += 1;
        }
    }
    let path = job
        .labelmap
        .as_deref()
        .or(job.cloud.as_deref())
        .unwrap_or(Path::new("--part"));
    let missing: Vec<String> = (1..=5)
        .filter(|&l| counts[l] == 0)
        .map(|l| {
            if l == 1 {
                "sternum".to_owned()
            } else {
                format!("rib {l}")
            }
        })
        .collect();
    if !missing.is_empty() {
        return Err(CliError::input(
            path,
            format!("no template points labelled {}", missing.join(", ")),
        ));
    }
    progress(&source);
    // Prepare before writing anything, so a template the core refuses leaves nothing.
    let prepared = match &job.prepared {
        Some(_) => {
            let labels = to_core_labels(path, &cloud.labels)?;
            let points = to_core(&cloud.points, Which::Template)?;
            let t = Instant::now();
            let tpl = build_template(&points, labels.as_deref(), Method::Improved, progress)?;
            progress(&format!(
                "prepared: {} SOM-1 nodes -> 30 rib points ({:.1} ms)",
                tpl.graph.som1.len(),
                t.elapsed().as_secs_f64() * 1e3
            ));
            Some(super::prepared::to_file(&cloud, &tpl))
        }
        None => None,
    };
    let format = if job.ascii {
        PlyFormat::Ascii
    } else {
        PlyFormat::BinaryLittleEndian
    };
    io::write_ply(&job.out, &cloud, format)?;
    if let (Some(p), Some(file)) = (&prepared, &job.prepared) {
        if let Err(e) = write_prepared(file, p) {
            let _ = std::fs::remove_file(&job.out);
            return Err(e.into());
        }
    }
    Ok(TemplateOutcome {
        cloud,
        counts,
        source,
    })
}
