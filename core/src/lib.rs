#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]
//! ribreg core (work in progress).

pub mod rng;

/// A point or vector in millimetres.
pub type Vec3 = nalgebra::Vector3<f32>;
