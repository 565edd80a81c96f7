#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
// The core never panics on input: no unwrap, expect or panic outside tests.
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
//! # ribreg-core
//!
//! Skeleton-graph non-rigid registration of rib-cartilage point clouds (Jiang et al.,
//! "Skeleton Graph-based Ultrasound-CT Non-rigid Registration", RA-L 2023) in `no_std`,
//! without allocation, with fixed capacities: the same code runs on the host and on the
//! Cortex-M4F probe-positioning controller.
//!
//! # Layers
//! The crate is one folder per concern; each `mod.rs` opens with its contract. Layers
//! import one way only, downward (checked by `tests/tests/layers.rs`):
//!
//! ```text
//! controller                       state machine, link layer, motion, probe targets
//!     │
//! wire                             versioned messages, COBS/CRC-32 framing
//!     │
//! registration   acquisition       the method (steps 4–10) │ sweep → US cloud (steps 1–2)
//!     │               │
//! math                             geometry, sampling, Kabsch, fits, hull, MST, k-d tree, SOM
//!     │
//! limits · error · config          capacities │ typed errors │ the method's parameters
//! ```
//!
//! * [`limits`]: every capacity and size bound; [`error`]: the one error type; [`config`]:
//!   [`config::Config`] (paper defaults), the rib model, the SOM schedules.
//! * [`math`]: [`math::rng`] seeded sampling, [`math::som`] SOM 1 (20×20) and SOM 2
//!   (5×8), [`math::mst`] Prim's tree, [`math::hull`] gift wrapping, [`math::kabsch`],
//!   [`math::fit`] cubics, [`math::kdtree`] exact nearest-node queries, [`math::geom`].
//! * [`registration`]: [`registration::skeleton`] endpoint rule, tree paths and the Eq. 4
//!   turn filter → [`registration::endpoints`] US→CT endpoint matching by ICP →
//!   [`registration::local_rigid`] per-point Kabsch over the N_r = 10 nearest skeleton
//!   pairs → [`registration::metrics`] ED and Hausdorff; [`registration::pipeline`]
//!   strings them together. [`config::Config::default`] is the paper's method,
//!   [`config::Config::improved`] carries the ribs over from the labelled template
//!   ([`registration::guided`]) on its probe-facing surface
//!   ([`registration::anterior`]). One registration's working state is about 37 KiB
//!   (README, "Performance and memory"; bounded by [`limits::MAX_WORKING_STATE`]).
//! * [`acquisition`]: [`acquisition::probe`] spatial calibration (paper Eq. 1),
//!   [`acquisition::temporal`] lag estimation, [`acquisition::track`] pose window with
//!   lerp/slerp, [`acquisition::compound`] bounded voxel compounding,
//!   [`acquisition::imaged`] the region the sweep's images passed over.
//! * [`wire`]: the protocol both sides share, a leaf above the method's types.
//! * [`controller`]: the host-testable state machine the firmware runs (upload, sweep,
//!   registration in bounded steps, setpoints, pose watchdog).
//!
//! ```
//! use ribreg_core::config::Config;
//! use ribreg_core::registration::{local_rigid::TransformCache, pipeline::{register, Template}};
//! use ribreg_core::Vec3;
//! # fn cage() -> Vec<Vec3> { ribreg_core::registration::example::cage(0.0).collect() }
//! let ct: Vec<Vec3> = cage();                       // template, patient frame
//! let us: Vec<Vec3> = cage().iter().map(|p| p + Vec3::new(3.0, -2.0, 10.0)).collect();
//! let cfg = Config::default();
//! let template = Template::build(&ct, None, &cfg)?;
//! let reg = register(&template, &us, &cfg)?;
//! let mut waypoint = [Vec3::new(20.0, -15.0, 5.0)];
//! reg.map_in_place(&mut waypoint, &mut TransformCache::<128>::new())?;
//! assert!((waypoint[0] - Vec3::new(23.0, -17.0, 15.0)).norm() < 1.0);
//! # Ok::<(), ribreg_core::Error>(())
//! ```
//!
//! No input makes the core panic: every failure is an [`Error`] that says what was
//! found and what was expected. Clouds are borrowed, never copied: their size is bounded
//! only by [`limits::MAX_CLOUD_POINTS`].

pub mod acquisition;
pub mod config;
pub mod controller;
pub mod error;
pub mod limits;
pub mod math;
pub mod registration;
pub mod wire;

pub use error::{Error, Result, Stream};

/// A point or vector in millimetres.
pub type Vec3 = nalgebra::Vector3<f32>;
