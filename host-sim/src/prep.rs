//! Template preparation on the host.
//!
//! Ultrasound shows only the probe-facing (anterior) surface of the cartilage, while a CT
//! segmentation covers the whole surface. A skeleton of the whole CT surface therefore
//! sits about half a cartilage thickness deeper than the US skeleton, and every mapped
//! point inherits that offset. [`anterior_mask`] keeps the template points a probe above
//! the patient could see, so that both skeletons describe the same surface.

use ribreg_core::Vec3;
use std::collections::HashMap;

/// Grid cell (x-y) of the visibility test, mm.
pub const VISIBILITY_CELL_MM: f32 = 2.0;
/// Depth below the locally highest point still counted as visible, mm. A cylinder of
/// radius R keeps the arc within ~72° of the probe direction for R = 5 mm, the arc that
/// the simulated probe (surface normal within 75° of the beam) sees.
pub const VISIBILITY_DEPTH_MM: f32 = 3.5;

/// For each point (patient frame, +z toward the probe): is it within
/// [`VISIBILITY_DEPTH_MM`] of the highest point in its 3 × 3 neighbourhood of
/// [`VISIBILITY_CELL_MM`] cells (a z-buffer seen from +z)?
pub fn anterior_mask(points: &[Vec3]) -> Vec<bool> {
    let cell = |p: &Vec3| {
        (
            (p.x / VISIBILITY_CELL_MM).floor() as i64,
            (p.y / VISIBILITY_CELL_MM).floor() as i64,
        )
    };
    let mut top: HashMap<(i64, i64), f32> = HashMap::new();
    for p in points {
        let e = top.entry(cell(p)).or_insert(f32::NEG_INFINITY);
        *e = e.max(p.z);
    }
    points
        .iter()
        .map(|p| {
            let (cx, cy) = cell(p);
            let mut highest = f32::NEG_INFINITY;
            for dx in -1..=1 {
                for dy in -1..=1 {
                    if let Some(z) = top.get(&(cx + dx, cy + dy)) {
                        highest = highest.max(*z);
                    }
                }
            }
            p.z >= highest - VISIBILITY_DEPTH_MM
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_top_of_a_tube() {
        // A tube of radius 5 along x, sampled every 10°.
        let pts: Vec<Vec3> = (0..36)
            .flat_map(|a| {
                let t = (a as f32 * 10.0).to_radians();
                (0..20).map(move |i| Vec3::new(i as f32, 5.0 * t.cos(), 5.0 * t.sin()))
            })
            .collect();
        let mask = anterior_mask(&pts);
        for (p, keep) in pts.iter().zip(&mask) {
            // The top (within 3.5 mm of z = 5) is always seen, the lower half never; the
            // flanks in between are judged against their own 3 × 3 cells.
            if p.z >= 1.5 {
                assert!(*keep, "{p:?}");
            }
            if p.z < 0.0 {
                assert!(!*keep, "{p:?}");
            }
        }
    }
}
