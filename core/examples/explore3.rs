use ribreg_core::{error::Cloud, example::cage, skeleton::SkeletonGraph, som::SomConfig, geom::nearest, Vec3};
fn main() {
    let ct: Vec<Vec3> = cage(0.0).collect();
    for (it1, r1, it2, r2) in [(6000, 0.5, 3000, 0.3), (6000, 0.1, 3000, 0.1), (12000, 0.1, 3000, 0.1), (6000, 0.2, 3000, 0.2), (6000, 0.3, 3000, 0.1), (20000, 0.1, 5000, 0.1)] {
        let s1 = SomConfig { iterations: it1, radius_end: r1, ..SomConfig::SOM1 };
        let s2 = SomConfig { iterations: it2, radius_end: r2, ..SomConfig::SOM2 };
        let t0 = std::time::Instant::now();
        let g = SkeletonGraph::build(&ct, Cloud::Template, &s1, &s2, true);
        let el = t0.elapsed();
        match g {
            Ok(g) => {
                let mut cl = vec![];
                let ry = [0.0f32, -31.6, -57.7, -81.9]; let rl = [60.0f32, 70.0, 82.0, 95.0]; let rs = [0.05f32, 0.12, 0.2, 0.28];
                for r in 0..4 { for side in [-1.0f32, 1.0] { for j in 0..200 { let d = rl[r] * j as f32 / 199.0; let x = side * (13.0 + d); cl.push(Vec3::new(x, ry[r] - rs[r] * d, -x * x / 300.0)); } } }
                for j in 0..200 { cl.push(Vec3::new(0.0, 12.0 - 105.0 * j as f32 / 199.0, 0.0)); }
                let off = |pts: &[Vec3]| pts.iter().map(|p| nearest(&cl, p).unwrap().1.sqrt()).sum::<f32>() / pts.len() as f32;
                println!("{it1} {r1} {it2} {r2}: {el:?} som1 live {} off {:.2} key {} off {:.2}", g.som1.len(), off(&g.som1), g.key_points.len(), off(&g.key_points));
            }
            Err(e) => println!("{it1} {r1} {it2} {r2}: {e}"),
        }
    }
}
