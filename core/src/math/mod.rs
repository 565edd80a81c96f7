//! Numerical building blocks: geometry, seeded sampling, fits, graphs and maps.
//!
//! Contract: every function here is a general algorithm with no knowledge of ribs,
//! probes or messages; it depends only on [`crate::limits`], [`crate::config`] (the SOM
//! schedule type) and [`crate::error`]. Nothing allocates; every buffer is a const-generic
//! capacity or a caller's slice, and a full buffer or a degenerate input is an
//! [`crate::Error`], never a panic. Where `f32` is not accurate enough (Kabsch sums,
//! polynomial normal equations) the work is done in `f64`; each module's tests, and the
//! f64 reference in `tests/`, state the accuracy reached.

pub mod fit;
pub mod geom;
pub mod hull;
pub mod kabsch;
pub mod kdtree;
pub mod mst;
pub mod rng;
pub mod som;
pub mod spline;

/// A test skeleton of 30 points: four curved "ribs" at different heights, each its
/// `RIB_SAMPLES` points from x = -100 to 100 mm (for the mapping's unit tests).
#[cfg(test)]
pub(crate) fn curved_skeleton() -> [crate::Vec3; crate::limits::SKELETON_POINTS] {
    let mut out = [crate::Vec3::zeros(); crate::limits::SKELETON_POINTS];
    let mut k = 0;
    for (r, n) in crate::config::RIB_SAMPLES.iter().enumerate() {
        for j in 0..*n {
            let x = -100.0 + 200.0 * j as f32 / (*n - 1) as f32;
            out[k] = crate::Vec3::new(x, -28.0 * r as f32 - 0.002 * x * x, -0.004 * x * x);
            k += 1;
        }
    }
    out
}
