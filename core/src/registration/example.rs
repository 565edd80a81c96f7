//! A small built-in rib-cage cloud (sternum and the costal cartilages of ribs 2..5 on
//! both sides, as tube surfaces) for examples, doc-tests and the firmware's default
//! phantom. Deterministic, no allocation: points come from an iterator.
//!
//! Patient frame, mm: x lateral, y cranial, z anterior. `stretch` makes a different
//! "patient": lateral lengths scale by `1 + stretch`, the rib drop by `1 − stretch / 2`.

use crate::Vec3;

/// Rib attachment heights at the sternum (mm): spacings 31.6, 26.1, 24.2 as in the paper.
const RIB_Y: [f32; 4] = [0.0, -31.6, -57.7, -81.9];
/// Cartilage lateral lengths from the sternum edge (mm).
const RIB_LEN: [f32; 4] = [60.0, 70.0, 82.0, 95.0];
/// Downward slope of each cartilage (mm of y per mm of x).
const RIB_SLOPE: [f32; 4] = [0.05, 0.12, 0.2, 0.28];
/// Sternum half-width, mm.
const STERNUM_HALF_WIDTH: f32 = 13.0;
/// Tube radius, mm.
const RADIUS: f32 = 4.5;
/// Samples around a tube.
const AROUND: usize = 8;
/// Sample step along a tube, mm.
const STEP: f32 = 3.0;

/// Chest curvature: anterior surface height at lateral position `x`.
fn chest_z(x: f32) -> f32 {
    -x * x / 300.0
}

/// Points of the built-in cage (about 2,300).
pub fn cage(stretch: f32) -> impl Iterator<Item = Vec3> {
    let sternum = (0..36).flat_map(move |j| {
        let y = 12.0 - STEP * j as f32;
        (0..9).flat_map(move |i| {
            let x = -STERNUM_HALF_WIDTH + 26.0 * i as f32 / 8.0;
            [
                Vec3::new(x, y, chest_z(x) + 4.0),
                Vec3::new(x, y, chest_z(x) - 4.0),
            ]
        })
    });
    let ribs = (0..8).flat_map(move |k| {
        let (rib, side) = (k / 2, if k % 2 == 0 { -1.0 } else { 1.0 });
        let len = RIB_LEN[rib] * (1.0 + stretch);
        let steps = (len / STEP) as usize;
        (0..=steps).flat_map(move |j| {
            let d = STEP * j as f32;
            let x = side * (STERNUM_HALF_WIDTH + d);
            let y = RIB_Y[rib] - RIB_SLOPE[rib] * (1.0 - 0.5 * stretch) * d;
            let z = chest_z(x);
            (0..AROUND).map(move |a| {
                let phi = a as f32 * core::f32::consts::TAU / AROUND as f32;
                Vec3::new(
                    x,
                    y + RADIUS * libm::cosf(phi),
                    z + RADIUS * libm::sinf(phi),
                )
            })
        })
    });
    sternum.chain(ribs)
}
