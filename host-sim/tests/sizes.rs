//! Size report of the core's working state (the README's memory table comes from
//! `cargo test -p ribreg-sim --test sizes -- --nocapture`). Goal: one registration's
//! state under 64 KiB.

use core::mem::size_of;
use ribreg_core::guided::{NodeTree, TargetSkeleton};
use ribreg_core::local_rigid::{TransformCache, CACHE_CAPACITY};
use ribreg_core::pipeline::{Registering, Registration, Template};
use ribreg_core::skeleton::{SkeletonGraph, SOM1_CAPACITY};
use ribreg_core::som::Som;

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
    println!(
        "{:50} {:6} B  {:5.1} KiB",
        "total (template + registering + mapping cache)",
        total,
        total as f64 / 1024.0
    );
    assert!(total < 64 * 1024);
}

/// The sweep state the controller keeps while compounding (pose window + voxel cloud);
/// its finished cloud is the registration's target, so it is live beside the state above.
#[test]
fn sweep_state_fits_64_kib() {
    use ribreg_core::compound::{Compounder, VoxelCloud, VOXEL_CAPACITY};
    use ribreg_core::track::{PoseTrack, TRACK_CAPACITY};
    let rows = [
        (
            "PoseTrack<128> (1.28 s at 100 Hz)",
            size_of::<PoseTrack<TRACK_CAPACITY>>(),
        ),
        ("VoxelCloud<2048>", size_of::<VoxelCloud<VOXEL_CAPACITY>>()),
        (
            "Compounder<128, 2048> (both + calibration)",
            size_of::<Compounder<TRACK_CAPACITY, VOXEL_CAPACITY>>(),
        ),
    ];
    for (name, bytes) in rows {
        println!("{name:50} {bytes:6} B  {:5.1} KiB", bytes as f64 / 1024.0);
    }
    assert!(size_of::<Compounder<TRACK_CAPACITY, VOXEL_CAPACITY>>() < 64 * 1024);
}
