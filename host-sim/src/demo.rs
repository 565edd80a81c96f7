//! `ribreg phantom` (write a phantom pair to files) and `ribreg demo` (the README's main
//! job: build the default phantom pair, register it, compare with the ground truth).

use crate::error::CliError;
use crate::io::{self, Cloud, Mesh, PlyFormat};
use crate::phantom::{PhantomConfig, PhantomPair};
use crate::plot::{self, SkeletonPanels};
use crate::register::{register_clouds, to_core, to_file, Method};
use ribreg_core::config::RIB_SAMPLES;
use ribreg_core::error::Cloud as Which;
use ribreg_core::math::geom::Rigid;
use ribreg_core::registration::skeleton::{RibSkeleton, SkeletonGraph};
use ribreg_core::Vec3;
use serde_json::json;
use std::path::Path;
use std::time::Instant;

/// Writes a phantom pair into `dir` (created if missing): `template.ply` (with labels),
/// `template_mesh.ply` and `.obj`, `target.ply`, `waypoints.csv` (planned, template frame),
/// `true_waypoints.csv` (ground truth, target frame) and `params.json`.
pub fn write_phantom(pair: &PhantomPair, dir: &Path) -> Result<(), CliError> {
    std::fs::create_dir_all(dir).map_err(|source| io::IoError::Io {
        path: dir.to_owned(),
        op: "cannot create the directory",
        source,
    })?;
    let template = Cloud {
        points: pair.template.points.clone(),
        labels: Some(pair.template.labels.clone()),
    };
    io::write_ply(
        &dir.join("template.ply"),
        &template,
        PlyFormat::BinaryLittleEndian,
    )?;
    let mesh = Mesh {
        vertices: pair.template_mesh.0.clone(),
        triangles: pair.template_mesh.1.clone(),
    };
    io::write_mesh_ply(&dir.join("template_mesh.ply"), &mesh)?;
    io::write_mesh_obj(&dir.join("template_mesh.obj"), &mesh)?;
    io::write_ply(
        &dir.join("target.ply"),
        &Cloud {
            points: pair.target.clone(),
            labels: None,
        },
        PlyFormat::BinaryLittleEndian,
    )?;
    io::write_points_csv(&dir.join("waypoints.csv"), &pair.template_waypoints)?;
    io::write_points_csv(&dir.join("true_waypoints.csv"), &pair.true_waypoints)?;
    let params = serde_json::to_string_pretty(&pair.write_params_json())
        .map_err(|e| CliError::Output(format!("params: {e}")))?;
    io::write_text(&dir.join("params.json"), &params)?;
    Ok(())
}

/// Writes the pair's CT as a segmentation and planning workflow hands it over
/// ([`crate::phantom::ct`]) into `dir` (created if missing): `labelmap.nii.gz`
/// (TotalSegmentator ids, distractor cartilages 1, 6 and 7), `parts/sternum.stl` and
/// `parts/rib2.stl`..`rib5.stl` (Slicer-style binary STL, `SPACE=LPS`), and the plan as
/// 3D Slicer markups, `plan.mrk.json` (LPS) — all in the CT's world, which is the
/// phantom's frame moved by [`crate::phantom::ct::WORLD_SHIFT_MM`].
pub fn write_ct(pair: &PhantomPair, dir: &Path) -> Result<(), CliError> {
    let parts = dir.join("parts");
    std::fs::create_dir_all(&parts).map_err(|source| io::IoError::Io {
        path: parts.clone(),
        op: "cannot create the directory",
        source,
    })?;
    let volume = crate::phantom::ct::labelmap(&pair.template_params);
    io::volume::write_nifti(&dir.join("labelmap.nii.gz"), &volume)?;
    for (label, mesh) in crate::phantom::ct::part_meshes(&pair.template_params) {
        let name = if label == 1 {
            "sternum.stl".to_owned()
        } else {
            format!("rib{label}.stl")
        };
        io::write_mesh_stl(&parts.join(name), &mesh, io::Space::Lps)?;
    }
    let plan = io::Waypoints {
        points: pair
            .template_waypoints
            .iter()
            .map(|p| crate::phantom::ct::to_world(*p))
            .collect(),
        labels: (0..pair.template_waypoints.len())
            .map(|i| format!("W{}", i + 1))
            .collect(),
        supported: vec![],
    };
    io::write_waypoints(&dir.join("plan.mrk.json"), &plan)?;
    Ok(())
}

/// Distances between paired points: mean, population SD, max (mm).
pub fn paired_errors(a: &[Vec3], truth: &[[f64; 3]]) -> (f64, f64, f64) {
    let d: Vec<f64> = a
        .iter()
        .zip(truth)
        .map(|(p, t)| {
            let v = [
                f64::from(p.x) - t[0],
                f64::from(p.y) - t[1],
                f64::from(p.z) - t[2],
            ];
            (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
        })
        .collect();
    let n = d.len().max(1) as f64;
    let mean = d.iter().sum::<f64>() / n;
    let sd = (d.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n).sqrt();
    (mean, sd, d.iter().copied().fold(0.0, f64::max))
}

/// Generates the pair for `cfg`, registers it, writes everything into `out`, and returns
/// the report (also written as `out/report.json`).
pub fn run_demo(
    cfg: &PhantomConfig,
    method: Method,
    out: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<serde_json::Value, CliError> {
    let t0 = Instant::now();
    let pair = PhantomPair::generate(cfg);
    progress(&format!(
        "phantom: template {} points, target {} points, pose {:.1}° / {:.1} mm ({:.0} ms)",
        pair.template.points.len(),
        pair.target.len(),
        pair.pose.rotation_angle_deg(),
        pair.pose.translation_norm(),
        t0.elapsed().as_secs_f64() * 1e3
    ));
    write_phantom(&pair, &out.join("phantom"))?;
    let template = to_core(&pair.template.points, Which::Template)?;
    let target = to_core(&pair.target, Which::Target)?;
    let waypoints = to_core(&pair.template_waypoints, Which::Query)?;
    let labels = pair.core_labels();
    let t1 = Instant::now();
    let mut outcome = register_clouds(
        &template,
        Some(&labels),
        &target,
        Some(&waypoints),
        method,
        progress,
    )?;
    let total_ms = t1.elapsed().as_secs_f64() * 1e3;
    let mapped = outcome.waypoints.clone().unwrap_or_default();
    let (wp_mean, wp_sd, wp_max) = paired_errors(&mapped, &pair.true_waypoints);
    let (dense_mean, dense_sd, dense_max) =
        paired_errors(&outcome.registered, &pair.true_positions());
    // Across the gap: toward a rib, and the clearance left to the cartilage's outline.
    let (across, clearance): (Vec<f64>, Vec<f64>) = pair
        .across_the_gaps(&to_file(&mapped))
        .into_iter()
        .map(|(across, clearance)| (across.abs(), clearance))
        .unzip();
    outcome.report["ground_truth"] = json!({
        "waypoint_error_mm": { "mean": wp_mean, "sd": wp_sd, "max": wp_max },
        "across_gap_mm": {
            "max": across.iter().copied().fold(0.0, f64::max),
            "least_clearance": clearance.iter().copied().fold(f64::INFINITY, f64::min),
        },
        "dense_error_mm": { "mean": dense_mean, "sd": dense_sd, "max": dense_max },
    });
    outcome.report["timings_ms"]["total"] = json!(total_ms);
    outcome.report["phantom"] = pair.write_params_json();
    let labels_i32 = Some(pair.template.labels.clone());
    io::write_ply(
        &out.join("registered.ply"),
        &Cloud {
            points: to_file(&outcome.registered),
            labels: labels_i32,
        },
        PlyFormat::BinaryLittleEndian,
    )?;
    io::write_points_csv(&out.join("mapped_waypoints.csv"), &to_file(&mapped))?;
    let text = serde_json::to_string_pretty(&outcome.report)
        .map_err(|e| CliError::Output(format!("report: {e}")))?;
    io::write_text(&out.join("report.json"), &text)?;
    let mine = vec![(format!("ribreg ({})", method.name()), to_file(&mapped))];
    write_figures(
        out,
        &template,
        &target,
        &outcome,
        &pair.true_waypoints,
        &mine,
    )?;
    progress(&format!(
        "wrote {} (registered.ply, mapped_waypoints.csv, report.json, figures)",
        out.display()
    ));
    Ok(outcome.report)
}

/// Coronal (x, y) projection of points in the template's patient frame.
fn coronal(points: &[Vec3]) -> Vec<[f64; 2]> {
    points
        .iter()
        .map(|p| [f64::from(p.x), f64::from(p.y)])
        .collect()
}

/// The paper's Fig. 4 for one cloud: SOM 1, SOM 2, MST with endpoints, rib paths and
/// the 30 skeleton points, projected on the template's coronal plane (`to_patient` takes
/// the cloud's frame there).
fn skeleton_panels(
    cloud: &[Vec3],
    graph: &SkeletonGraph,
    skeleton: &RibSkeleton,
    to_patient: &Rigid,
) -> SkeletonPanels {
    let moved = |pts: &[Vec3]| -> Vec<Vec3> { pts.iter().map(|p| to_patient.apply(p)).collect() };
    let key = moved(&graph.key_points);
    let mut offset = 0;
    let rib_paths = RIB_SAMPLES
        .iter()
        .zip(&skeleton.paths)
        .map(|(&n, path)| {
            let line = if path.is_empty() {
                moved(&skeleton.points[offset..offset + n])
            } else {
                path.iter().map(|&k| key[usize::from(k)]).collect()
            };
            offset += n;
            coronal(&line)
        })
        .collect();
    SkeletonPanels {
        cloud: coronal(&moved(cloud)),
        som1: coronal(&moved(&graph.som1)),
        key_points: coronal(&key),
        edges: graph.tree.edges().collect(),
        endpoints: graph
            .endpoints
            .map(|e| e.iter().flatten().map(|&k| usize::from(k)).collect())
            .unwrap_or_default(),
        rib_paths,
        skeleton: coronal(&moved(&skeleton.points)),
    }
}

/// Writes `skeleton_template`, `skeleton_target` (the paper's Fig. 4) and `waypoints`
/// (Fig. 6: the true waypoints and each method's mapped ones, target frame) figures,
/// SVG + PNG, into `out`.
pub fn write_figures(
    out: &Path,
    template: &[Vec3],
    target: &[Vec3],
    outcome: &crate::register::RegisterOutcome,
    truth: &[[f64; 3]],
    methods: &[(String, Vec<[f64; 3]>)],
) -> Result<(), CliError> {
    let fig = |e: plot::PlotError| CliError::Output(format!("figure: {e}"));
    let tpl = &outcome.template;
    let reg = &outcome.registration;
    let panels = skeleton_panels(template, &tpl.graph, &tpl.skeleton, &Rigid::identity());
    plot::skeleton_figure(
        &out.join("skeleton_template"),
        "CT template skeleton (patient frame)",
        &panels,
    )
    .map_err(fig)?;
    let panels = skeleton_panels(target, &reg.graph, &reg.skeleton, &reg.pose);
    plot::skeleton_figure(
        &out.join("skeleton_target"),
        "US target skeleton (rigidly aligned to the template)",
        &panels,
    )
    .map_err(fig)?;
    // Target frame, seen on the template's coronal plane (through the rigid pose).
    let view = |p: &[f64; 3]| {
        let q = reg
            .pose
            .apply(&Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32));
        [f64::from(q.x), f64::from(q.y)]
    };
    let sets: Vec<plot::WaypointSet> = methods
        .iter()
        .map(|(label, pts)| plot::WaypointSet {
            label: label.clone(),
            points: pts.iter().map(view).collect(),
        })
        .collect();
    plot::waypoint_transfer(
        &out.join("waypoints"),
        "Planned waypoints mapped onto the patient",
        &to_file(target).iter().map(view).collect::<Vec<_>>(),
        &truth.iter().map(view).collect::<Vec<_>>(),
        &sets,
    )
    .map_err(fig)
}
