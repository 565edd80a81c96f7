//! Size report of the core's working state (the README's memory table comes from
//! `cargo test -p ribreg-sim --test sizes -- --nocapture`). Goal: one registration's
//! state under 64 KiB.

use core::mem::size_of;
use ribreg_core::limits::{CACHE_CAPACITY, SOM1_CAPACITY, TRACK_CAPACITY, VOXEL_CAPACITY};
use ribreg_core::math::som::Som;
use ribreg_core::registration::guided::{NodeTree, TargetSkeleton};
use ribreg_core::registration::local_rigid::TransformCache;
use ribreg_core::registration::pipeline::{Registering, Registration, Template};
use ribreg_core::registration::skeleton::SkeletonGraph;

#[test]
fn working_state_fits_64_kib() {
    let rows = [
        (
            "Template (CT skeleton, kept for every patient)",
            size_of::<Template>(),
        ),
        (
            "Registration (target graph, skeleton, mapping)",
            size_of::<Registration>(),
        ),
        (
            "TransformCache<128> (mapping)",
            size_of::<TransformCache<CACHE_CAPACITY>>(),
        ),
        (
            "SkeletonGraph (one inside each of the two above)",
            size_of::<SkeletonGraph>(),
        ),
        (
            "Registering (in progress: its largest stage)",
            size_of::<Registering>(),
        ),
        (
            "  SOM-1 map being trained (graph stage)",
            size_of::<Som<SOM1_CAPACITY>>(),
        ),
        (
            "  TargetSkeleton (guided stage, with a graph)",
            size_of::<TargetSkeleton>(),
        ),
        (
            "    NodeTree (k-d tree of 400 nodes; three)",
            size_of::<NodeTree>(),
        ),
    ];
    for (name, bytes) in rows {
        println!("{name:50} {bytes:6} B  {:5.1} KiB", bytes as f64 / 1024.0);
    }
    // The registration in progress ends up holding the Registration.
    let total = size_of::<Template>()
        + size_of::<Registering>().max(size_of::<Registration>())
        + size_of::<TransformCache<CACHE_CAPACITY>>();
    assert_eq!(total, ribreg_core::registration::WORKING_STATE);
    println!(
        "{:50} {:6} B  {:5.1} KiB",
        "total (template + registering + mapping cache)",
        total,
        total as f64 / 1024.0
    );
    assert!(total <= ribreg_core::limits::MAX_WORKING_STATE);
}

/// The sweep state the controller keeps while compounding (pose window + voxel cloud);
/// its finished cloud is the registration's target, so it is live beside the state above.
/// A voxel takes 12 bytes (code, count, fixed-point mean), so the controller holds twice
/// the 1,536 voxels of 24 B it held in the same 36 KiB.
#[test]
fn sweep_state_fits_64_kib() {
    use ribreg_core::acquisition::compound::{Compounder, VoxelCloud};
    use ribreg_core::acquisition::imaged::ImagedArea;
    use ribreg_core::acquisition::track::PoseTrack;
    use ribreg_core::limits::{CONTROLLER_VOXELS, IMAGED_LINES};
    let rows = [
        (
            format!("PoseTrack<{TRACK_CAPACITY}> (1.28 s at 100 Hz)"),
            size_of::<PoseTrack<TRACK_CAPACITY>>(),
        ),
        (
            format!("VoxelCloud<{VOXEL_CAPACITY}>"),
            size_of::<VoxelCloud<VOXEL_CAPACITY>>(),
        ),
        (
            format!("VoxelCloud<{CONTROLLER_VOXELS}> (the controller's)"),
            size_of::<VoxelCloud<CONTROLLER_VOXELS>>(),
        ),
        (
            format!("ImagedArea<{IMAGED_LINES}> (the sweep's lines)"),
            size_of::<ImagedArea<IMAGED_LINES>>(),
        ),
        (
            format!("Compounder<{TRACK_CAPACITY}, {VOXEL_CAPACITY}> (all + calibration)"),
            size_of::<Compounder<TRACK_CAPACITY, VOXEL_CAPACITY>>(),
        ),
    ];
    for (name, bytes) in rows {
        println!("{name:50} {bytes:6} B  {:5.1} KiB", bytes as f64 / 1024.0);
    }
    assert!(size_of::<Compounder<TRACK_CAPACITY, VOXEL_CAPACITY>>() < 64 * 1024);
    let per_voxel = (size_of::<VoxelCloud<2048>>() - size_of::<VoxelCloud<1024>>()) / 1024;
    assert_eq!(per_voxel, 12, "bytes per voxel");
    const { assert!(CONTROLLER_VOXELS >= 2 * 1536) };
    assert!(size_of::<VoxelCloud<CONTROLLER_VOXELS>>() <= 36 * 1024 + 128);
    // 48 B a line (limits::IMAGED_LINES).
    assert!(size_of::<ImagedArea<IMAGED_LINES>>() <= IMAGED_LINES * 48 + 128);
}
