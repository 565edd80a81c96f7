//! Every capacity and size bound of the core in one place.
//!
//! Contract: a leaf (imports nothing of the crate). Each constant says what it bounds and
//! how its value was derived; the `const` asserts at the end tie the capacities together
//! and bound the working state of one registration (README, "Performance and memory").

/// Largest coordinate magnitude accepted, mm (100 m: beyond it a cloud is not in mm, and
/// squared distances would lose all precision in `f32`).
pub const MAX_COORD_MM: f32 = 1.0e5;
/// Fewest points accepted in a template or target cloud.
pub const MIN_CLOUD_POINTS: usize = 100;
/// Most points accepted (sample indices are drawn as `u32`; 2²⁴ keeps every index exact
/// in an `f32` too). Nothing is copied, so this bounds no buffer.
pub const MAX_CLOUD_POINTS: usize = 1 << 24;
/// Capacity of SOM 1 (paper grid: 20 × 20 = 400 nodes; 400 × 12 B = 4.7 KiB).
pub const SOM1_CAPACITY: usize = 400;
/// Capacity of SOM 2, the skeleton key points (paper grid: 5 × 8 = 40; room for larger
/// grids up to 128 nodes, 1.5 KiB; node indices must fit a `u8`).
pub const KEY_POINTS: usize = 128;
/// Paired skeleton points: 6 + 6 + 8 + 10.
pub const SKELETON_POINTS: usize = 30;
/// Points on the sternum's midline paired between template and target (guided model):
/// the xiphoid's tip, where ribs 5 and 2 join, and the manubrium's top
/// ([`crate::registration::guided::stations_at_attachments`]).
pub const STERNUM_STATIONS: usize = 4;
/// Most point pairs a thin-plate spline takes: the skeleton and the sternum stations.
pub const SPLINE_POINTS: usize = SKELETON_POINTS + STERNUM_STATIONS;
/// Largest tree (node indices are `u8`).
pub const MAX_TREE_NODES: usize = 255;
/// Longest grid side supported (rows or columns).
pub const MAX_GRID_SIDE: usize = 64;
/// Points (at most) checked when finding the live nodes of a map: each is one scan of the
/// map, so the SOM-1 dead-unit scan costs at most as much as 1,024 SOM iterations.
pub const LIVE_SAMPLES: usize = 1024;
/// Pose window of the controller: 128 poses = 1.28 s at 100 Hz, enough for a lag of up
/// to 0.5 s plus 0.7 s of frame latency. 128 × 40 B = 5 KiB.
pub const TRACK_CAPACITY: usize = 128;
/// A mid-sized voxel capacity (benchmarks, size report): 4096 × 12 B (code 4, count 2,
/// mean 3 × 2; `acquisition::compound`) = 48 KiB. A whole-chest phantom sweep needs
/// 5,500–7,900 voxels of 2 mm, so this cloud coarsens once, to 4 mm (about 2,000
/// voxels). The controller holds fewer, [`CONTROLLER_VOXELS`] (RAM budget; README).
pub const VOXEL_CAPACITY: usize = 4096;
/// Points of placed frames that may wait for the voxel cloud: two full frame messages
/// (2 × [`MAX_FRAME_PIXELS`] = 192 points × 12 B ≈ 2.3 KiB).
pub const PENDING_POINTS: usize = 2 * MAX_FRAME_PIXELS;
/// Voxel capacity of the controller's compounding cloud: 3072 × 12 B = 36 KiB (1536 of
/// 24 B before the voxels were packed), so that the registration's stack (about 47 KiB
/// at its deepest, from the firmware's frame sizes) fits beside the controller in
/// 128 KiB of RAM.
pub const CONTROLLER_VOXELS: usize = 3072;
/// Lines of a sweep the compounding keeps to tell where it imaged
/// (`acquisition::imaged`): a chest sweep at 10 mm line spacing has 20–30 (`ribreg hil`:
/// the cartilages' 150–200 mm cranio-caudally plus an image's width); 64 × 48 B = 3 KiB
/// of the controller's static RAM. Lines beyond are counted and count as not imaged.
pub const IMAGED_LINES: usize = 64;
/// Most bone pixels in one frame message (a 384-pixel image annotated every 4th column).
pub const MAX_FRAME_PIXELS: usize = 96;
/// Default transform cache capacity (power of two). 128 entries × (4 B key + 48 B
/// transform + index) ≈ 7.2 KiB. Points in an ordinary template share far fewer sets.
pub const CACHE_CAPACITY: usize = 128;
/// Transform cache of the carried-node mapping: 64 entries × ~64 B ≈ 4 KiB. A full cache
/// starts over (see `registration::local_rigid::TransformCache`). On the emulated controller the carried nodes
/// cost 76 M instructions with 16 entries that kept nothing new once full, 43 M with 64
/// such entries, 28.5 M with 64 that start over.
pub const CARRY_CACHE: usize = 64;
/// At most this many cloud points (an even stride) enter the rib fits: about 100 per
/// rib side, for a fit of a handful of coefficients; on the controller each costs ~4,000
/// instructions (soft-float `f64` power sums), so a round's fit stays near 4 M of the
/// registration's 150 M (16,384 cost 28.7 M on a 3 mm sweep of 3,016 points).
pub const FIT_SAMPLES: usize = 1024;
/// Replies waiting to be sent: a poll emits at most one setpoint or fault and the
/// results, a received frame one reply; 32 covers a whole result (≤ 32 waypoints).
pub const OUTBOX: usize = 40;
/// Largest source and destination set of the endpoint ICP (a SOM-1 node set).
pub const ICP_CAPACITY: usize = SOM1_CAPACITY;

const _: () = assert!(KEY_POINTS <= MAX_TREE_NODES);

/// Bound on one registration's working state, bytes: the prepared template, the
/// registration in progress (or its result) and the mapping's transform cache. 64 KiB
/// leaves half of the controller's 128 KiB RAM for the sweep, the stack and the link
/// (asserted in [`crate::registration`]; measured ~37 KiB, README).
pub const MAX_WORKING_STATE: usize = 64 * 1024;
