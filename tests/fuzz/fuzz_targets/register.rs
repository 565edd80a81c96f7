//! The whole registration (prepare the template, register, map the template and the
//! waypoints, measure) on structured-arbitrary clouds: any coordinates (NaN, ±∞, huge),
//! labels, sizes. An error or a result, never a panic; mapped points are finite.
//! The SOMs train for a twentieth of the paper's iterations: every stage's code runs,
//! at a cost that lets the fuzzer reach millions of executions.
#![no_main]
use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use ribreg_core::Vec3;
use ribreg_sim::register::{register_clouds, Method, Options};

#[derive(Arbitrary, Debug)]
struct Input {
    /// Points as small integers (mm, quantised) so the fuzzer reaches real shapes.
    template: Vec<([i16; 3], u8)>,
    target: Vec<[i16; 3]>,
    waypoints: Vec<[i16; 3]>,
    /// Raw f32 coordinates spliced in: NaN, infinities, huge values.
    raw: Vec<(u16, [f32; 3])>,
    paper: bool,
    scale: u8,
}

fuzz_target!(|input: Input| {
    let s = f32::from(input.scale.max(1)) / 16.0;
    let v = |p: &[i16; 3]| {
        Vec3::new(
            f32::from(p[0]) * s,
            f32::from(p[1]) * s,
            f32::from(p[2]) * s,
        )
    };
    let mut template: Vec<Vec3> = input
        .template
        .iter()
        .take(3000)
        .map(|(p, _)| v(p))
        .collect();
    let labels: Vec<u8> = input
        .template
        .iter()
        .take(3000)
        .map(|(_, l)| l % 6)
        .collect();
    let mut target: Vec<Vec3> = input.target.iter().take(3000).map(v).collect();
    let waypoints: Vec<Vec3> = input.waypoints.iter().take(64).map(v).collect();
    for (i, p) in &input.raw {
        let n = template.len() + target.len();
        if n == 0 {
            break;
        }
        let i = usize::from(*i) % n;
        let q = Vec3::new(p[0], p[1], p[2]);
        if i < template.len() {
            template[i] = q;
        } else {
            target[i - template.len()] = q;
        }
    }
    let how = Options {
        method: if input.paper {
            Method::Paper
        } else {
            Method::Improved
        },
        som_iterations: Some((300, 150)),
        ..Options::default()
    };
    if let Ok(out) = register_clouds(
        &template,
        Some(&labels),
        &target,
        Some(&waypoints),
        how,
        &mut |_| {},
    ) {
        assert!(out
            .registered
            .iter()
            .all(|p| p.iter().all(|c| c.is_finite())));
    }
});
