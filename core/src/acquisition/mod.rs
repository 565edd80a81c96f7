//! The robotic-ultrasound acquisition chain (paper section III, steps 1–2): spatial
//! calibration, the tracked pose window, temporal calibration and bounded compounding
//! of annotated bone pixels into the US point cloud, with the region the sweep's
//! images passed over (what tells a rib end from one the sweep cut).
//!
//! Contract: depends on [`crate::math`], [`crate::limits`] and [`crate::error`] only.
//! Every buffer is fixed-capacity: the pose window holds [`crate::limits::TRACK_CAPACITY`]
//! poses, the voxel cloud a const-generic number of voxels and coarsens in place when full
//! (counted, never a silent drop), the imaged region [`crate::limits::IMAGED_LINES`]
//! lines (more are counted and count as not imaged); a pose or pixel that cannot be
//! placed is refused and counted.

pub mod compound;
pub mod imaged;
pub mod probe;
pub mod temporal;
pub mod track;
