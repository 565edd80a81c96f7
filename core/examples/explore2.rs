use nalgebra::{Rotation3, Unit};
use ribreg_core::{error::Cloud, example::cage, pipeline::*, skeleton::SkeletonGraph, Vec3};
fn dump(g: &SkeletonGraph, back: &Rotation3<f32>) {
    let deg = g.tree.degrees();
    for (i, p) in g.key_points.iter().enumerate() {
        let q = back * p;
        let e = g.endpoints.iter().flatten().any(|&k| k as usize == i);
        println!("  {i:2} ({:7.1},{:7.1},{:7.1}) deg {} par {:2} {}", q.x, q.y, q.z, deg[i], g.tree.parent(i), if e { "END" } else { "" });
    }
}
fn main() {
    let ct: Vec<Vec3> = cage(0.0).collect();
    let cfg = Config::default();
    let g = SkeletonGraph::build(&ct, Cloud::Template, &cfg.som1, &cfg.som2, true).unwrap();
    println!("template"); dump(&g, &Rotation3::identity());
    let rot = Rotation3::from_axis_angle(&Unit::new_normalize(Vec3::new(0.0, 0.0, 1.0)), f32::to_radians(90.0));
    let us: Vec<Vec3> = ct.iter().map(|p| rot * p).collect();
    let g = SkeletonGraph::build(&us, Cloud::Target, &cfg.som1, &cfg.som2, false).unwrap();
    println!("target"); dump(&g, &rot.inverse());
}
