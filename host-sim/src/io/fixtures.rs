//! Tests against fixture files written by independent writers: Open3D for the clouds,
//! `tests/fixtures/formats/gen_clouds.py` for 3D Slicer markups and STL headers (from
//! the documented formats, with its own frame conversion). The expected values are in
//! `clouds/expected.json` beside them.

use std::path::{Path, PathBuf};

use serde_json::Value;

use super::{read_cloud, read_mesh, read_mesh_in, read_waypoints, Space};

fn dir() -> PathBuf {
    Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/formats/clouds"
    ))
    .to_path_buf()
}

fn expected() -> Value {
    let text = std::fs::read_to_string(dir().join("expected.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn points(v: &Value) -> Vec<[f64; 3]> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let p: Vec<f64> = p
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c.as_f64().unwrap())
                .collect();
            [p[0], p[1], p[2]]
        })
        .collect()
}

fn assert_close(got: &[[f64; 3]], want: &[[f64; 3]], tolerance: f64, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: point count");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        for k in 0..3 {
            assert!(
                (g[k] - w[k]).abs() <= tolerance,
                "{what}: point {i}: {g:?} vs {w:?}"
            );
        }
    }
}

#[test]
fn open3d_clouds() {
    let expected = expected();
    let clouds = expected["clouds"].as_object().unwrap();
    assert_eq!(clouds.len(), 7);
    for (name, want) in clouds {
        let cloud = read_cloud(&dir().join(name)).unwrap();
        // Text bodies are decimal, which Open3D reads through float32 and we read as
        // f64. Binary bodies hold float32 values: ours are those exactly, Open3D's own
        // read-back differs from them in the last bit of the f64 at most.
        let text = !name.ends_with(".pcd") || name.contains("ascii");
        let tolerance = if text { 1e-5 } else { 1e-9 };
        assert_close(&cloud.points, &points(want), tolerance, name);
        if !text {
            let exact = |c: &f64| f64::from(*c as f32) == *c;
            assert!(cloud.points.iter().flatten().all(exact), "{name}");
        }
        assert_eq!(cloud.labels, None, "{name}");
    }
}

#[test]
fn slicer_waypoints() {
    let expected = expected();
    let waypoints = expected["waypoints"].as_object().unwrap();
    assert_eq!(waypoints.len(), 5);
    for (name, want) in waypoints {
        let w = read_waypoints(&dir().join(name)).unwrap();
        assert_close(&w.points, &points(&want["points"]), 1e-9, name);
        let labels: Vec<&str> = want["labels"]
            .as_array()
            .unwrap()
            .iter()
            .map(|l| l.as_str().unwrap())
            .collect();
        assert_eq!(w.labels, labels, "{name}");
    }
}

#[test]
fn stl_space_headers() {
    let expected = expected();
    let meshes = expected["meshes"].as_object().unwrap();
    assert_eq!(meshes.len(), 2);
    for (name, want) in meshes {
        let path = dir().join(name);
        let (mesh, space) = read_mesh_in(&path, Space::Patient).unwrap();
        assert_eq!(
            Some(space),
            Space::parse(want["space"].as_str().unwrap()),
            "{name}"
        );
        assert_close(&mesh.vertices, &points(&want["vertices"]), 1e-9, name);
        assert_eq!(
            mesh.triangles.len() as u64,
            want["triangles"].as_u64().unwrap()
        );
        // read_mesh leaves the file's coordinates alone.
        let raw = read_mesh(&path).unwrap();
        let back: Vec<[f64; 3]> = mesh
            .vertices
            .iter()
            .map(|&v| space.from_patient(v))
            .collect();
        assert_eq!(raw.vertices, back, "{name}");
        assert_eq!(raw.triangles, mesh.triangles, "{name}");
    }
}

#[test]
fn mutated_fixtures_never_panic() {
    let mut s: u64 = 14;
    let names = [
        "slicer_lps.mrk.json",
        "slicer_lps.fcsv",
        "slicer_markups_lps.csv",
        "o3d.xyzn",
        "o3d_compressed.pcd",
        "slicer_lps_binary.stl",
    ];
    for name in names {
        let seed = std::fs::read(dir().join(name)).unwrap();
        for m in crate::io::mutants(&seed, 500, b"0123456789 \n-,\"#=[]{}:.e", &mut s) {
            let _ = super::pcd::parse_pcd(&m);
            let _ = super::mesh::tests_declared_space(&m);
            if let Ok(text) = std::str::from_utf8(&m) {
                let _ = super::parse_markups_json(text);
                let _ = super::parse_fcsv(text);
                let _ = super::parse_waypoints_csv(text);
                let _ = super::parse_cloud_csv(text);
                let _ = super::parse_xyz(text);
            }
        }
    }
}
