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
