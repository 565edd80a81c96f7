//! Criterion benchmarks of the registration (issue: skeleton extraction on a 3,000-point
//! cloud, mapping 5,000 points, a whole `register` of a 3,000-point target and a
//! 5,000-point template). Run: `cargo bench -p ribreg-sim --bench pipeline`.

use criterion::{criterion_group, criterion_main, Criterion};
use ribreg_core::error::Cloud as Which;
use ribreg_core::local_rigid::TransformCache;
use ribreg_core::pipeline::{register, Config, Template};
use ribreg_core::skeleton::SkeletonGraph;
use ribreg_core::Vec3;
use ribreg_sim::phantom::{PhantomConfig, PhantomPair};
use ribreg_sim::register::{register_clouds, to_core, Method, HOST_CACHE};
use std::hint::black_box;

/// Template ≈ 5,000 points, target ≈ 3,000 points.
fn pair() -> (Vec<Vec3>, Vec<u8>, Vec<Vec3>, Vec<Vec3>) {
    let pair = PhantomPair::generate(&PhantomConfig {
        spacing_mm: 1.95,
        us_spacing_mm: 1.72,
        ..PhantomConfig::default()
    });
    let template = to_core(&pair.template.points, Which::Template).unwrap();
    let labels = pair.template.labels.iter().map(|&l| l as u8).collect();
    let target = to_core(&pair.target, Which::Target).unwrap();
    let waypoints = to_core(&pair.template_waypoints, Which::Query).unwrap();
    (template, labels, target, waypoints)
}

fn benches(c: &mut Criterion) {
    let (template, labels, target, _) = pair();
    eprintln!(
        "template {} points, target {} points",
        template.len(),
        target.len()
    );
    let cfg = Config::default();
    c.bench_function("skeleton_graph_target_3k", |b| {
        b.iter(|| SkeletonGraph::build(black_box(&target), Which::Target, &cfg, false).unwrap())
    });
    let tpl = Template::build(&template, Some(&labels), &Config::improved()).unwrap();
    let reg = register(&tpl, &target, &Config::improved()).unwrap();
    c.bench_function("map_5k_points", |b| {
        b.iter(|| {
            let mut pts = template.clone();
            let mut cache = Box::new(TransformCache::<HOST_CACHE>::new());
            reg.map
                .map_in_place(black_box(&mut pts), &mut cache)
                .unwrap();
            pts
        })
    });
    // The paper's method runs unlabelled here: on this phantom its endpoint rule
    // contradicts the labels (README, "Known limits"), and a refusal is no benchmark.
    for (method, labels) in [
        (Method::Paper, None),
        (Method::Improved, Some(labels.as_slice())),
    ] {
        c.bench_function(&format!("register_5k_onto_3k_{}", method.name()), |b| {
            b.iter(|| {
                // Everything `ribreg register` does between reading and writing files:
                // template preparation, registration, mapping all points, ED/HD.
                register_clouds(
                    black_box(&template),
                    labels,
                    &target,
                    None,
                    method,
                    &mut |_| (),
                )
                .unwrap()
            })
        });
    }
}

criterion_group! {
    name = pipeline;
    config = Criterion::default().sample_size(20);
    targets = benches
}
criterion_main!(pipeline);
