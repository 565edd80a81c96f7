//! The probe-facing (anterior) part of a template.
//!
//! Ultrasound shows only the probe-facing surface of the cartilage, while a CT
//! segmentation covers the whole surface. A skeleton of the whole CT surface therefore
//! sits about half a cartilage thickness deeper than the US skeleton, and every mapped
//! point inherits that offset. [`anterior_mask`] keeps the template points a probe above
//! the patient could see, so that both skeletons describe the same surface.
//!
//! No allocation: the caller lends one scratch cell per point; the cells are sorted in
//! place and the 3 × 3 neighbourhood of each point is found by binary search
//! (`O(n log n)`).

use crate::error::{Error, Result};
use crate::math::geom::sat_u32;
use crate::Vec3;

/// Grid cell (x-y) of the visibility test, mm.
pub const VISIBILITY_CELL_MM: f32 = 2.0;
/// Depth below the locally highest point still counted as visible, mm. A cylinder of
/// radius R keeps the arc within ~72° of the probe direction for R = 5 mm, the arc that
/// the simulated probe (surface normal within 75° of the beam) sees.
pub const VISIBILITY_DEPTH_MM: f32 = 3.5;

/// One scratch entry of [`anterior_mask`]: a grid cell and the highest `z` seen in it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cell {
    key: (i64, i64),
    top: f32,
}

fn cell_of(p: &Vec3) -> (i64, i64) {
    (
        libm::floorf(p.x / VISIBILITY_CELL_MM) as i64,
        libm::floorf(p.y / VISIBILITY_CELL_MM) as i64,
    )
}

/// For each point (patient frame, +z toward the probe): is it within
/// [`VISIBILITY_DEPTH_MM`] of the highest point in its 3 × 3 neighbourhood of
/// [`VISIBILITY_CELL_MM`] cells (a z-buffer seen from +z)? Writes `mask[i]` for
/// `points[i]`; `scratch` needs one [`Cell`] per point. A point with a non-finite
/// coordinate is never visible.
///
/// # Errors
/// [`Error::Capacity`] when `mask` or `scratch` is shorter than `points`.
pub fn anterior_mask(points: &[Vec3], scratch: &mut [Cell], mask: &mut [bool]) -> Result<()> {
    let n = points.len();
    if mask.len() < n || scratch.len() < n {
        return Err(Error::Capacity {
            capacity: sat_u32(mask.len().min(scratch.len())),
        });
    }
    for (c, p) in scratch.iter_mut().zip(points) {
        *c = Cell {
            key: cell_of(p),
            top: p.z,
        };
    }
    let cells = &mut scratch[..n];
    cells.sort_unstable_by_key(|c| c.key);
    // Fold each run of equal keys into its first entry (f32::max ignores NaN, as the
    // running maximum of a z-buffer should).
    let mut len = 0;
    for i in 0..n {
        if len > 0 && cells[len - 1].key == cells[i].key {
            cells[len - 1].top = cells[len - 1].top.max(cells[i].top);
        } else {
            cells[len] = Cell {
                key: cells[i].key,
                top: f32::NEG_INFINITY.max(cells[i].top),
            };
            len += 1;
        }
    }
    let cells = &cells[..len];
    for (m, p) in mask.iter_mut().zip(points) {
        let (cx, cy) = cell_of(p);
        let mut highest = f32::NEG_INFINITY;
        for dx in -1..=1i64 {
            for dy in -1..=1i64 {
                let key = (cx.saturating_add(dx), cy.saturating_add(dy));
                if let Ok(k) = cells.binary_search_by_key(&key, |c| c.key) {
                    highest = highest.max(cells[k].top);
                }
            }
        }
        *m = p.z >= highest - VISIBILITY_DEPTH_MM;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_top_of_a_tube() {
        // A tube of radius 5 along x, sampled every 10°.
        let pts: std::vec::Vec<Vec3> = (0..36)
            .flat_map(|a| {
                let t = (a as f32 * 10.0).to_radians();
                (0..20).map(move |i| Vec3::new(i as f32, 5.0 * t.cos(), 5.0 * t.sin()))
            })
            .collect();
        let mut scratch = std::vec![Cell::default(); pts.len()];
        let mut mask = std::vec![false; pts.len()];
        anterior_mask(&pts, &mut scratch, &mut mask).unwrap();
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

    #[test]
    fn short_buffers_are_refused() {
        let pts = [Vec3::zeros(); 3];
        let mut scratch = [Cell::default(); 2];
        let mut mask = [false; 3];
        assert!(matches!(
            anterior_mask(&pts, &mut scratch, &mut mask),
            Err(Error::Capacity { capacity: 2 })
        ));
    }
}
