#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]
//! # ribreg-core
//!
//! Skeleton-graph non-rigid registration of rib-cartilage point clouds (Jiang et al.,
//! "Skeleton Graph-based Ultrasound-CT Non-rigid Registration", RA-L 2023) in `no_std`,
//! without allocation, with fixed capacities: the same code runs on the host and on the
//! Cortex-M4F probe-positioning controller.
//!
//! Pipeline (one module each):
//! [`rng`] seeded sampling → [`som`] SOM 1 (20×20) and SOM 2 (5×8) → [`mst`] Prim's tree
//! → [`hull`] gift-wrapping hull and the endpoint rule in [`skeleton`] → [`endpoints`]
//! US→CT endpoint matching by ICP → [`skeleton`] tree paths, Eq. 4 turn filter → [`fit`]
//! cubics and resampling (6/6/8/10 points) → [`local_rigid`] per-point Kabsch
//! ([`kabsch`]) over the N_r = 10 nearest skeleton pairs → [`metrics`] ED and Hausdorff.
//! Nearest-node queries over SOM node sets use exact k-d trees ([`kdtree`]).
//! [`pipeline`] strings them together; [`pipeline::Config::default`] is the paper's
//! method, [`pipeline::Config::improved`] replaces the SOM-2 / MST / endpoint stage by
//! ribs carried over from the labelled template ([`guided`]), which the README's phantom
//! evaluation shows the published stage needs. One registration's working state is about
//! 37 KiB (README, "Performance and memory").
//!
//! The US cloud itself is built from a robot-tracked sweep: [`probe`] spatial calibration
//! (paper Eq. 1), [`temporal`] lag estimation by normalised cross-correlation, [`track`]
//! pose window with lerp/slerp interpolation, [`compound`] bounded voxel compounding.
//!
//! The controller that runs all this on the Cortex-M4F is [`controller`] (a host-testable
//! state machine: upload, sweep, registration in bounded steps, setpoints, pose
//! watchdog), speaking the versioned, COBS/CRC-32 framed protocol of [`wire`].
//!
//! ```
//! use ribreg_core::{pipeline::{register, Config, Template}, local_rigid::TransformCache, Vec3};
//! # fn cage() -> Vec<Vec3> { ribreg_core::example::cage(0.0).collect() }
//! let ct: Vec<Vec3> = cage();                       // template, patient frame
//! let us: Vec<Vec3> = cage().iter().map(|p| p + Vec3::new(3.0, -2.0, 10.0)).collect();
//! let cfg = Config::default();
//! let template = Template::build(&ct, None, &cfg)?;
//! let reg = register(&template, &us, &cfg)?;
//! let mut waypoint = [Vec3::new(20.0, -15.0, 5.0)];
//! reg.map.map_in_place(&mut waypoint, &mut TransformCache::<128>::new())?;
//! assert!((waypoint[0] - Vec3::new(23.0, -17.0, 15.0)).norm() < 1.0);
//! # Ok::<(), ribreg_core::Error>(())
//! ```
//!
//! No input makes the core panic: every failure is an [`Error`] that says what was
//! found and what was expected. Clouds are borrowed, never copied: their size is bounded
//! only by [`pipeline::MAX_CLOUD_POINTS`].

pub mod compound;
pub mod controller;
pub mod endpoints;
pub mod error;
pub mod example;
pub mod fit;
pub mod geom;
pub mod guided;
pub mod hull;
pub mod kabsch;
pub mod kdtree;
pub mod local_rigid;
pub mod metrics;
pub mod mst;
pub mod pipeline;
pub mod probe;
pub mod rng;
pub mod skeleton;
pub mod som;
pub mod temporal;
pub mod track;
pub mod wire;

pub use error::{Error, Result, Stream};

/// A point or vector in millimetres.
pub type Vec3 = nalgebra::Vector3<f32>;

/// Largest coordinate magnitude accepted, mm (100 m: beyond it a cloud is not in mm, and
/// squared distances would lose all precision in `f32`).
pub const MAX_COORD_MM: f32 = 1.0e5;
