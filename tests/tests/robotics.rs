//! The core's robotic-US steps against the f64 reference: the spatial calibration chain
//! (paper Eq. 1) and pose interpolation (lerp + slerp), on seeded random draws.
//!
//! Tolerances (`|core − ref| ≤ atol`): positions within ±500 mm of the base pass through
//! three f32 transforms, each adding a few ε·500 mm ≈ 6e-5 mm: atol 1e-3 mm. Rotations
//! through f32 quaternions: 1e-5 rad. Measured maxima are printed with `--nocapture`.

use nalgebra::{Matrix3, UnitQuaternion};
use ribreg_core::acquisition::probe::{Calibration, ProbeModel};
use ribreg_core::acquisition::track::{PoseTrack, TrackedPose};
use ribreg_core::math::geom::Rigid as Rigid32;
use ribreg_core::math::rng::Rng;
use ribreg_core::Vec3;
use ribreg_tests::reference::{self as r, Rigid};

fn unit(rng: &mut Rng) -> [f64; 4] {
    loop {
        let q: [f64; 4] = std::array::from_fn(|_| rng.next_f64() * 2.0 - 1.0);
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if n > 0.1 && n <= 1.0 {
            return q.map(|v| v / n);
        }
    }
}

fn draw_rigid(rng: &mut Rng, reach: f64) -> Rigid {
    Rigid {
        r: r::quat_to_matrix(unit(rng)),
        t: std::array::from_fn(|_| (rng.next_f64() * 2.0 - 1.0) * reach),
    }
}

fn to32(t: &Rigid) -> Rigid32 {
    Rigid32 {
        rotation: Matrix3::from_fn(|i, j| t.r[i][j] as f32),
        translation: Vec3::new(t.t[0] as f32, t.t[1] as f32, t.t[2] as f32),
    }
}

/// Both implementations see the f32-rounded transforms.
fn rounded(t: &Rigid) -> Rigid {
    let t32 = to32(t);
    Rigid {
        r: std::array::from_fn(|i| std::array::from_fn(|j| f64::from(t32.rotation[(i, j)]))),
        t: std::array::from_fn(|i| f64::from(t32.translation[i])),
    }
}

#[test]
fn pixel_to_base_matches_the_f64_chain() {
    let mut rng = Rng::new(11);
    let mut worst: f64 = 0.0;
    for _ in 0..500 {
        let probe = ProbeModel {
            width_px: 64 + rng.below(900) as u16,
            height_px: 64 + rng.below(900) as u16,
            footprint_mm: 20.0 + 40.0 * rng.next_f32(),
            depth_mm: 20.0 + 100.0 * rng.next_f32(),
        };
        let (tcp, ee, b) = (
            rounded(&draw_rigid(&mut rng, 30.0)),
            rounded(&draw_rigid(&mut rng, 200.0)),
            rounded(&draw_rigid(&mut rng, 500.0)),
        );
        let cal = Calibration {
            probe,
            tcp_t_us: to32(&tcp),
            ee_t_tcp: to32(&ee),
        };
        cal.validate().unwrap();
        let (u, v) = (
            rng.next_f32() * f32::from(probe.width_px),
            rng.next_f32() * f32::from(probe.height_px),
        );
        let core = cal.pixel_to_base(&to32(&b), u, v).unwrap();
        let (sx, sy) = probe.scale();
        let reference = r::pixel_to_base(
            (f64::from(sx), f64::from(sy)),
            &tcp,
            &ee,
            &b,
            f64::from(u),
            f64::from(v),
        );
        let d = (0..3)
            .map(|i| (f64::from(core[i]) - reference[i]).abs())
            .fold(0.0, f64::max);
        worst = worst.max(d);
        assert!(d <= 1e-3, "{core} vs {reference:?}");
    }
    println!("pixel → base: worst |core − ref| {worst:.2e} mm");
}

#[test]
fn pose_interpolation_matches_lerp_and_slerp() {
    let mut rng = Rng::new(12);
    let mut track = PoseTrack::<64>::new();
    let mut rows = Vec::new();
    for k in 0..64 {
        let q = unit(&mut rng);
        let p: [f64; 3] = std::array::from_fn(|_| (rng.next_f64() * 2.0 - 1.0) * 400.0);
        let t = f64::from(k) * 0.01 + 1000.0; // a clock well past its start
        let q32 = q.map(|v| v as f32);
        let p32 = Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32);
        let pose = TrackedPose::new(t, p32, q32).unwrap();
        track.push(pose).unwrap();
        let qc = pose.orientation.into_inner();
        rows.push((
            t,
            p32.map(f64::from),
            [qc.w, qc.i, qc.j, qc.k].map(f64::from),
        ));
    }
    let (mut worst_p, mut worst_a): (f64, f64) = (0.0, 0.0);
    for _ in 0..1000 {
        let k = rng.below(63) as usize;
        let s = rng.next_f64();
        let (a, b) = (&rows[k], &rows[k + 1]);
        let t = a.0 + s * (b.0 - a.0);
        let core = track.at(t).unwrap();
        let p = a.1 + (b.1 - a.1) * s;
        let q = r::slerp(a.2, b.2, s);
        worst_p = worst_p.max((core.translation.map(f64::from) - p).amax());
        let qr = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
        let qc = UnitQuaternion::from_matrix(&core.rotation.map(f64::from));
        worst_a = worst_a.max(qc.angle_to(&qr));
    }
    println!("interpolation: worst position {worst_p:.2e} mm, worst angle {worst_a:.2e} rad");
    assert!(worst_p <= 1e-3 && worst_a <= 1e-5, "{worst_p} {worst_a}");
}
