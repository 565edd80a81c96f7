//! The robotic-ultrasound acquisition chain (paper section III, steps 1–2): spatial
//! calibration, the tracked pose window, temporal calibration and bounded compounding
//! of annotated bone pixels into the US point cloud.
//!
//! Contract: depends on [`crate::math`], [`crate::limits`] and [`crate::error`] only.
//! Every buffer is fixed-capacity: the pose window holds [`crate::limits::TRACK_CAPACITY`]
//! poses, the voxel cloud a const-generic number of voxels and coarsens in place when full
//! (counted, never a silent drop); a pose or pixel that cannot be placed is refused and
//! counted.

pub mod compound;
pub mod probe;
pub mod temporal;
pub mod track;
