//! Hand-run evaluation of the baselines on phantoms and export of the comparison data.
//! Both are `#[ignore]`d (release build recommended):
//!
//! ```text
//! cargo test --release -p ribreg-sim baselines::eval::phantom_table -- --ignored --nocapture
//! cargo test --release -p ribreg-sim baselines::eval::export_comparison_data -- --ignored --nocapture
//! ```
//!
//! `export_comparison_data` writes `host-sim/scripts/baselines/data/` for `compare.py`.

use super::*;
use crate::io::{self, Cloud, PlyFormat};
use crate::phantom::{PhantomConfig, PhantomPair, Variant};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn errors(mapped: &[P3], truth: &[P3]) -> (f64, f64) {
    let e: Vec<f64> = mapped
        .iter()
        .zip(truth)
        .map(|(a, b)| dist2(*a, *b).sqrt())
        .collect();
    let mean = e.iter().sum::<f64>() / e.len() as f64;
    (mean, e.iter().cloned().fold(0.0, f64::max))
}

/// Seeds 0..5 × {aligned, misaligned} × every method: waypoint error mean / max, error of
/// every template point against its true position, runtime.
#[test]
#[ignore]
fn phantom_table() {
    let seeds: u64 = std::env::var("BASELINE_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let mut rows = Vec::new();
    println!(
        "| variant | seed | method | waypoint mean (mm) | waypoint max (mm) | all-points mean (mm) | iters | conv | time (s) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for variant in [Variant::Aligned, Variant::Misaligned] {
        for seed in 0..seeds {
            let pair = PhantomPair::generate(&PhantomConfig {
                seed,
                variant,
                ..Default::default()
            });
            let truth_all = pair.true_positions();
            for m in Method::ALL {
                let t0 = Instant::now();
                let res = run(m, &pair.template.points, &pair.target);
                let secs = t0.elapsed().as_secs_f64();
                match res {
                    Ok(map) => {
                        let (wm, wx) =
                            errors(&map.map_all(&pair.template_waypoints), &pair.true_waypoints);
                        let (am, _) = errors(&map.map_all(&pair.template.points), &truth_all);
                        let r = map.report();
                        println!(
                            "| {variant:?} | {seed} | {m} | {wm:.2} | {wx:.2} | {am:.2} | {} | {} | {secs:.2} |",
                            r.iterations, r.converged
                        );
                        rows.push((variant, m, wm, wx, am, secs));
                    }
                    Err(e) => {
                        println!("| {variant:?} | {seed} | {m} | error: {e} | | | | | {secs:.2} |")
                    }
                }
            }
        }
    }
    println!("\nSummary over seeds (mean of per-seed means, max of maxima, mean runtime):\n");
    println!("| variant | method | waypoint mean (mm) | waypoint max (mm) | all-points mean (mm) | time (s) |");
    println!("|---|---|---|---|---|---|");
    for variant in [Variant::Aligned, Variant::Misaligned] {
        for m in Method::ALL {
            let sel: Vec<_> = rows.iter().filter(|r| r.0 == variant && r.1 == m).collect();
            if sel.is_empty() {
                continue;
            }
            let k = sel.len() as f64;
            println!(
                "| {variant:?} | {m} | {:.2} | {:.2} | {:.2} | {:.2} |",
                sel.iter().map(|r| r.2).sum::<f64>() / k,
                sel.iter().map(|r| r.3).fold(0.0, f64::max),
                sel.iter().map(|r| r.4).sum::<f64>() / k,
                sel.iter().map(|r| r.5).sum::<f64>() / k,
            );
        }
    }
}

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/baselines/data")
}

fn write_pts(path: &Path, points: &[P3]) {
    io::write_ply(
        path,
        &Cloud {
            points: points.to_vec(),
            labels: None,
        },
        PlyFormat::BinaryLittleEndian,
    )
    .unwrap_or_else(|e| panic!("{e}"));
}

/// trimesh's `Trimesh.centroid` (area-weighted triangle centroids) and `Trimesh.scale`
/// (bounding-box diagonal of the vertices).
fn trimesh_frame(vertices: &[P3], triangles: &[[u32; 3]]) -> nricp::Frame {
    let mut c = [0.0; 3];
    let mut area = 0.0;
    for t in triangles {
        let [a, b, d] = t.map(|i| vertices[i as usize]);
        let (u, v) = (sub(b, a), sub(d, a));
        let cr = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        let ar = 0.5 * dot(cr, cr).sqrt();
        c = add(c, scale(add(add(a, b), d), ar / 3.0));
        area += ar;
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in vertices {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let d = sub(hi, lo);
    nricp::Frame {
        centre: scale(c, 1.0 / area),
        scale: dot(d, d).sqrt(),
    }
}

/// Writes `data/template_mesh.ply` (the template surface, the same for every seed) and, per
/// phantom pair, the inputs (`template.ply`, `target.ply`) and our outputs:
/// `ours_cpd_nonrigid.ply` / `ours_nricp.ply` (mapped template points), `ours.json`
/// (template and true waypoints, our mapped waypoints, runtimes, iteration counts, the
/// rigid transforms and every parameter the script needs to run the libraries identically),
/// and `ours_nricp_mesh_every5.ply` (every 5th mesh vertex after NRICP on the mesh graph),
/// which checks the NRICP implementation against trimesh on identical inputs.
#[test]
#[ignore]
fn export_comparison_data() {
    let cases = [(0u64, Variant::Aligned), (1u64, Variant::Misaligned)];
    for (seed, variant) in cases {
        let pair = PhantomPair::generate(&PhantomConfig {
            seed,
            variant,
            ..Default::default()
        });
        let dir = data_dir().join(format!("pair{seed}_{variant:?}").to_lowercase());
        std::fs::create_dir_all(&dir).unwrap();
        write_pts(&dir.join("template.ply"), &pair.template.points);
        write_pts(&dir.join("target.ply"), &pair.target);
        let (verts, tris) = &pair.template_mesh;
        // The template subject is the same for every seed: one mesh file serves all pairs.
        let mesh_path = data_dir().join("template_mesh.ply");
        let mesh = io::Mesh {
            vertices: verts.clone(),
            triangles: tris.clone(),
        };
        if io::read_mesh(&mesh_path).ok().as_ref() != Some(&mesh) {
            io::write_mesh_ply(&mesh_path, &mesh).unwrap();
        }
        let mut methods = serde_json::Map::new();
        for m in Method::ALL {
            let t0 = Instant::now();
            let map = run(m, &pair.template.points, &pair.target).unwrap();
            let secs = t0.elapsed().as_secs_f64();
            if matches!(m, Method::CpdNonRigid | Method::NonRigidIcp) {
                // (The rigid results are given by R, t below.)
                write_pts(
                    &dir.join(format!("ours_{m}.ply")),
                    &map.map_all(&pair.template.points),
                );
            }
            let r = map.report();
            methods.insert(
                m.name().into(),
                json!({
                    "seconds": secs,
                    "iterations": r.iterations,
                    "converged": r.converged,
                    "final_error": r.final_error,
                    "waypoints": map.map_all(&pair.template_waypoints),
                }),
            );
        }
        // Details the script needs to run the libraries with identical settings.
        let ip = icp::IcpParams::default();
        let icp = icp::fit(&pair.template.points, &pair.target, &ip).unwrap();
        let rp = cpd::RigidParams::default();
        let cr = cpd::fit_rigid(&pair.template.points, &pair.target, &rp).unwrap();
        let cn =
            cpd::fit_nonrigid(&pair.template.points, &pair.target, &Default::default()).unwrap();
        let np = nricp::NricpParams::default();
        let nr = nricp::fit(&pair.template.points, &pair.target, &np).unwrap();
        // NRICP on the template mesh (trimesh's graph: every face edge, duplicates kept;
        // trimesh's normalisation frame) with the same absolute stiffness values.
        let mesh_edges: Vec<[usize; 2]> = tris
            .iter()
            .flat_map(|t| {
                let [a, b, c] = t.map(|i| i as usize);
                [[a, b], [b, c], [c, a]]
            })
            .collect();
        let mesh_params = nricp::NricpParams {
            stiffness: nr.stiffness_used.clone(),
            stiffness_unit: Some(1.0),
            ..np.clone()
        };
        let t0 = Instant::now();
        let nm = nricp::fit_graph(
            verts,
            &mesh_edges,
            &pair.target,
            &mesh_params,
            Some(trimesh_frame(verts, tris)),
        )
        .unwrap();
        let mesh_secs = t0.elapsed().as_secs_f64();
        // Every 5th mesh vertex keeps the data small.
        let moved = nm.node_positions();
        // Waypoints moved like the script moves them with trimesh's output (which has no
        // per-vertex transforms): inverse-square-distance weighted displacement of the
        // `interp_k` nearest mesh vertices.
        let rest: Vec<P3> = verts
            .iter()
            .map(|p| add(*p, nm.initial_translation))
            .collect();
        let rest_tree = kdtree::KdTree::new(&rest);
        let wp_disp: Vec<P3> = pair
            .template_waypoints
            .iter()
            .map(|w| {
                let q = add(*w, nm.initial_translation);
                let mut acc = [0.0; 3];
                let mut ws = 0.0;
                for (j, d2) in rest_tree.k_nearest(&q, np.interp_k) {
                    let wt = 1.0 / d2.max(1e-24);
                    acc = add(acc, scale(sub(moved[j], rest[j]), wt));
                    ws += wt;
                }
                add(q, scale(acc, 1.0 / ws))
            })
            .collect();
        let every5: Vec<P3> = moved.iter().step_by(5).copied().collect();
        write_pts(&dir.join("ours_nricp_mesh_every5.ply"), &every5);
        let d = cpd::NonRigidParams::default();
        let info = json!({
            "seed": seed,
            "variant": format!("{variant:?}"),
            "template_waypoints": pair.template_waypoints,
            "true_waypoints": pair.true_waypoints,
            "methods": methods,
            "icp": {
                "max_iterations": ip.max_iterations, "tolerance_mm": ip.tolerance_mm,
                "initial_translation": icp.initial.translation,
                "rotation": icp.transform.rotation, "translation": icp.transform.translation,
                "iterations": icp.report.iterations,
            },
            "cpd_rigid": {
                "w": rp.w, "max_iterations": rp.max_iterations, "tolerance": rp.tolerance,
                "iterations": cr.report.iterations,
                "rotation": cr.transform.rotation, "translation": cr.transform.translation,
                "sigma2": cr.sigma2,
            },
            "cpd_nonrigid": {
                "w": d.w, "beta": d.beta, "lambda": d.lambda, "max_iterations": d.max_iterations,
                "tolerance": d.tolerance, "iterations": cn.report.iterations,
                "control_indices": cn.control_indices,
                "template_mean": cn.template_mean, "template_scale": cn.template_scale,
                "target_mean": cn.target_mean, "target_scale": cn.target_scale,
                "sigma2": cn.sigma2, "kernel_rank": cn.kernel_rank,
            },
            "nricp": {
                "stiffness": np.stiffness, "stiffness_used": nr.stiffness_used,
                "max_iterations_per_step": np.max_iterations_per_step, "eps": np.eps,
                "gamma": np.gamma, "distance_threshold": np.distance_threshold,
                "graph_k": np.graph_k, "interp_k": np.interp_k,
                "initial_translation": nr.initial_translation,
                "frame_centre": nr.frame.centre, "frame_scale": nr.frame.scale,
                "iterations_per_step": nr.iterations_per_step,
                "cg_iterations": nr.cg_iterations,
                "mesh": {
                    "initial_translation": nm.initial_translation,
                    "frame_centre": nm.frame.centre, "frame_scale": nm.frame.scale,
                    "iterations_per_step": nm.iterations_per_step,
                    "seconds": mesh_secs,
                    "waypoints": nm.map_all(&pair.template_waypoints),
                    "waypoints_displacement_idw": wp_disp,
                    "cg_iterations": nm.cg_iterations,
                },
            },
        });
        std::fs::write(dir.join("ours.json"), serde_json::to_string(&info).unwrap()).unwrap();
        println!("wrote {}", dir.display());
    }
}
