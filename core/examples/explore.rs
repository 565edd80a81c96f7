use nalgebra::{Rotation3, Unit};
use ribreg_core::{example::cage, local_rigid::TransformCache, pipeline::*, Vec3};
fn main() {
    let ct: Vec<Vec3> = cage(0.0).collect();
    let cfg = Config::default();
    let t0 = std::time::Instant::now();
    let template = Template::build(&ct, None, &cfg).unwrap();
    println!("template {:?} ends {:?} deg {:?}", t0.elapsed(), template.ends, template.skeleton.degree);
    for (axis, deg) in [((1.0, 0.3, 0.2), 0.0), ((1.0, 0.3, 0.2), 20.0), ((0.2, 1.0, 0.5), 20.0), ((0.0, 0.0, 1.0), 90.0), ((0.3, 0.2, 1.0), 180.0), ((1.0, 1.0, 1.0), 120.0)] {
        let rot = Rotation3::from_axis_angle(&Unit::new_normalize(Vec3::new(axis.0, axis.1, axis.2)), f32::to_radians(deg));
        let t = Vec3::new(30.0, -40.0, 500.0);
        let us: Vec<Vec3> = ct.iter().map(|p| rot * p + t).collect();
        let t0 = std::time::Instant::now();
        match register(&template, &us, &cfg) {
            Ok(reg) => {
                let mut pts = ct.clone();
                reg.map.map_in_place(&mut pts, &mut TransformCache::<128>::new()).unwrap();
                let err: Vec<f32> = pts.iter().zip(&ct).map(|(m, p)| (m - (rot * p + t)).norm()).collect();
                let mean = err.iter().sum::<f32>() / err.len() as f32;
                let max = err.iter().cloned().fold(0.0, f32::max);
                println!("{deg:5}° {:?}: mean {mean:.3} max {max:.3} coarse {:.2} ep {:.2}", t0.elapsed(), reg.matching.coarse_rms, reg.matching.endpoint_rms);
            }
            Err(e) => println!("{deg}°: {e}"),
        }
    }
}
