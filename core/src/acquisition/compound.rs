//! Compounding a tracked sweep into a bounded bone-surface cloud (SPEC pipeline step 1).
//!
//! Each annotated frame is placed with the flange pose interpolated at its time minus the
//! temporal-calibration lag ([`crate::acquisition::track`]), its bone pixels go through the spatial
//! calibration ([`crate::acquisition::probe`]) into the robot base frame, and every point lands in a
//! [`VoxelCloud`]: a fixed-capacity voxel grid that keeps one centroid per occupied voxel.
//!
//! # The voxel cloud
//! A voxel takes 12 bytes (the size of the centroid it becomes, in place): a `u32`
//! Morton (Z-order) code, a `u16` point count and the running mean as a `u16` per axis,
//! an offset from the voxel's lowest corner in 1/65536 of its edge. Voxels are kept
//! sorted by code, so a lookup is a binary search and the cloud needs no hash table.
//!
//! The code interleaves 10 bits per axis: voxels are indexed in a window of 1024 finest
//! voxels per axis whose origin the first point fixes (a multiple of 2^[`MAX_COARSENINGS`]
//! finest voxels, 512 or a little less below it), so every point within 504 finest voxels
//! of the first on every axis (±1 m at 2 mm) is inside; a point outside is refused and
//! counted ([`VoxelStats::refused_outside`]).
//!
//! When a point needs a new voxel and the cloud is full, the grid is coarsened in place:
//! the voxel edge doubles, which shifts every Morton code right by three bits (keeping
//! the order, since the origin is a multiple of the coarsest edge) and merges the voxels
//! that now share a code, means weighted by count. Coarsening stops at
//! [`VoxelCloud::max_voxel_mm`]; past it a point needing a new voxel is refused and
//! counted. Nothing is dropped without a counter: see [`VoxelStats`].
//!
//! Accuracy contract (tested against an `f64` mean): a centroid is within 2⁻¹⁶ of the
//! edge per axis of the mean of its points for one point, and the error of the running
//! mean grows by at most half a 1/65536 unit per point merged: for n points at most
//! (n + 1) / 2 units, 0.02 mm for 1,000 points in a 3 mm voxel (the points' own spread is
//! millimetres). A coarsening adds a quarter unit per voxel and a weighted merge half a
//! unit.

use crate::acquisition::imaged::ImagedArea;
use crate::acquisition::probe::Calibration;
use crate::acquisition::track::{PoseTrack, TrackedPose};
use crate::error::{Cloud, Error, Result, Stream};
use crate::limits::{IMAGED_LINES, PENDING_POINTS};
use crate::math::geom::Rigid;
use crate::Vec3;

/// Bits of each axis index in a voxel's Morton code: 3 × 10 = 30 of its `u32`.
const AXIS_BITS: u32 = 10;
/// Voxels along each axis of the grid window at the finest level.
const AXIS_VOXELS: i64 = 1 << AXIS_BITS;
/// Most coarsenings a cloud may be configured for: the window's origin is a multiple of
/// 2^`MAX_COARSENINGS` finest voxels placed at most 512 below the first point, so the
/// first point lies in the window and every point within 512 − 2⁸ = 256 finest voxels of
/// it on every axis does too (with [`DEFAULT_MAX_COARSENINGS`], 504).
pub const MAX_COARSENINGS: u8 = 8;
/// A voxel's mean is kept as its offset from the voxel's lowest corner in 1/65536 of the
/// edge (`u16` per axis).
const MEAN_SCALE: f64 = 65_536.0;
/// Smallest finest-voxel edge, mm.
pub const MIN_VOXEL_MM: f32 = 0.1;
/// Coarsenings allowed by default: the voxel edge may grow 8× (e.g. 2 → 16 mm).
pub const DEFAULT_MAX_COARSENINGS: u8 = 3;
/// [`VoxelCloud::work`] of one inserted point besides the voxels it shifts: its `f64`
/// voxel arithmetic and binary search cost about 2,500 instructions on the Cortex-M4F.
pub const INSERT_WORK: u64 = 128;
/// Default finest voxel edge, mm: below the registration's SOM-1 spacing (~4 mm between
/// 400 nodes on a cage), above the pixel size and the annotation noise.
pub const DEFAULT_VOXEL_MM: f32 = 2.0;

/// What happened to the points offered to a [`VoxelCloud`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VoxelStats {
    /// Points accepted (merged into a voxel or starting one).
    pub accepted: u32,
    /// Of those, points merged into a voxel that already held points.
    pub merged: u32,
    /// Points refused because the cloud was full at its coarsest voxel size.
    pub refused_full: u32,
    /// Points refused because they lie outside the grid window (module docs: at least
    /// 504 finest voxels from the first point on some axis).
    pub refused_outside: u32,
    /// Times the grid was coarsened.
    pub coarsenings: u8,
}

/// One voxel in 12 bytes, as three words (the size of the [`Vec3`] centroid it becomes,
/// in place, at [`VoxelCloud::finish`]): the Morton code of its window indices at the
/// current level; the point count (`u16`, saturating) and the mean's x; the mean's y and
/// z. Mean components are offsets from the voxel's lowest corner in 1/65536 of its edge.
type Slot = [u32; 3];

// A voxel becomes its centroid in place.
const _: () = assert!(core::mem::size_of::<Slot>() == core::mem::size_of::<Vec3>());

fn slot(code: u32, count: u16, mean: [u16; 3]) -> Slot {
    [
        code,
        u32::from(count) | (u32::from(mean[0]) << 16),
        u32::from(mean[1]) | (u32::from(mean[2]) << 16),
    ]
}

fn count_of(s: &Slot) -> u16 {
    s[1] as u16
}

fn mean_of(s: &Slot) -> [u16; 3] {
    [(s[1] >> 16) as u16, s[2] as u16, (s[2] >> 16) as u16]
}

/// A fixed-capacity voxel-grid down-sampling of a point stream (module docs).
#[derive(Clone)]
pub struct VoxelCloud<const CAP: usize> {
    /// Voxels by Morton code, ascending; after [`VoxelCloud::finish`], the centroids.
    slots: [Slot; CAP],
    len: usize,
    finest_mm: f32,
    /// The window's lowest corner, finest-level indices (a multiple of
    /// 2^`max_level` on every axis); set by the first accepted point.
    origin: Option<[i64; 3]>,
    level: u8,
    max_level: u8,
    finished: bool,
    /// Voxels turned into centroids (after the first [`VoxelCloud::finish_some`]).
    converted: usize,
    /// Work done by inserts, in [`VoxelCloud::work`] units.
    work: u64,
    /// Counters.
    pub stats: VoxelStats,
}

impl<const CAP: usize> VoxelCloud<CAP> {
    /// An empty cloud with finest voxel edge `voxel_mm` (at least [`MIN_VOXEL_MM`]) that
    /// may coarsen `max_coarsenings` times (at most [`MAX_COARSENINGS`]).
    pub fn new(voxel_mm: f32, max_coarsenings: u8) -> Result<Self> {
        let mut cloud = Self::empty();
        cloud.reset(voxel_mm, max_coarsenings)?;
        Ok(cloud)
    }

    /// An empty cloud of 1 mm voxels that may not coarsen, built at compile time (a
    /// `static` on the controller: no stack copy of its arrays).
    pub const fn empty() -> Self {
        VoxelCloud {
            slots: [[0; 3]; CAP],
            len: 0,
            finest_mm: 1.0,
            origin: None,
            level: 0,
            max_level: 0,
            finished: false,
            converted: 0,
            work: 0,
            stats: VoxelStats {
                accepted: 0,
                merged: 0,
                refused_full: 0,
                refused_outside: 0,
                coarsenings: 0,
            },
        }
    }

    /// Empties the cloud in place for new settings (see [`VoxelCloud::new`]); on a
    /// configuration error it is left unchanged.
    pub fn reset(&mut self, voxel_mm: f32, max_coarsenings: u8) -> Result<()> {
        if !(MIN_VOXEL_MM..=1000.0).contains(&voxel_mm) {
            return Err(Error::Config("voxel size must be between 0.1 and 1000 mm"));
        }
        if CAP == 0 || max_coarsenings > MAX_COARSENINGS {
            return Err(Error::Config(
                "voxel cloud needs a capacity and at most 8 coarsenings",
            ));
        }
        self.len = 0;
        self.finest_mm = voxel_mm;
        self.origin = None;
        self.level = 0;
        self.max_level = max_coarsenings;
        self.finished = false;
        self.converted = 0;
        self.stats = VoxelStats::default();
        Ok(())
    }

    /// Occupied voxels.
    pub fn len(&self) -> usize {
        self.len
    }

    /// No voxel occupied.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Current voxel edge, mm.
    pub fn voxel_mm(&self) -> f32 {
        self.finest_mm * (1u32 << self.level) as f32
    }

    /// Work done by [`VoxelCloud::insert`] so far, a cost proxy for callers that bound
    /// their work per call: [`INSERT_WORK`] per point (its `f64` voxel arithmetic and
    /// search), plus one per voxel shifted to make room for a new one, plus two per voxel
    /// passed over by a coarsening. One unit is at most about 20 instructions on the
    /// Cortex-M4F.
    pub fn work(&self) -> u64 {
        self.work
    }

    /// Coarsest voxel edge the cloud may reach, mm.
    pub fn max_voxel_mm(&self) -> f32 {
        self.finest_mm * (1u32 << self.max_level) as f32
    }

    /// Adds a point. `Ok(true)` if kept, `Ok(false)` if refused because the cloud is full
    /// at its coarsest level or the point is outside the grid window (counted in
    /// [`VoxelStats::refused_full`], [`VoxelStats::refused_outside`]). A point that is not
    /// finite or beyond [`crate::limits::MAX_COORD_MM`] is [`Error::NonFinite`] /
    /// [`Error::OutOfRange`] (cloud `Target`), and after [`VoxelCloud::finish`] every
    /// insert is [`Error::Config`]; the cloud is unchanged then.
    pub fn insert(&mut self, p: &Vec3) -> Result<bool> {
        if self.finished {
            return Err(Error::Config("the voxel cloud is finished"));
        }
        if !p.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                cloud: Cloud::Target,
                index: self.stats.accepted,
            });
        }
        if p.amax() > crate::limits::MAX_COORD_MM {
            return Err(Error::OutOfRange {
                cloud: Cloud::Target,
                index: self.stats.accepted,
            });
        }
        self.work = self.work.wrapping_add(INSERT_WORK);
        // Finest-level indices (|p| <= 1e5 mm and the edge >= 0.1 mm: within ±2^20).
        let finest = f64::from(self.finest_mm);
        let a = p.map(|v| libm::floor(f64::from(v) / finest) as i64);
        let origin = *self.origin.get_or_insert_with(|| {
            let block = 1i64 << self.max_level;
            [a.x, a.y, a.z].map(|k| (k - AXIS_VOXELS / 2).div_euclid(block) * block)
        });
        let r = [a.x - origin[0], a.y - origin[1], a.z - origin[2]];
        loop {
            let level = u32::from(self.level);
            if r.iter().any(|&k| k < 0 || k >= AXIS_VOXELS << level) {
                self.stats.refused_outside = self.stats.refused_outside.saturating_add(1);
                return Ok(false);
            }
            let k = r.map(|k| (k >> level) as u32);
            let code = morton(k);
            let edge = finest * f64::from(1u32 << level);
            let corner = |i: usize| (((k[i] as i64) << level) + origin[i]) as f64 * finest;
            let q: [u16; 3] = core::array::from_fn(|i| {
                let frac = (f64::from(p[i]) - corner(i)) / edge;
                libm::floor(frac * MEAN_SCALE).clamp(0.0, MEAN_SCALE - 1.0) as u16
            });
            match self.slots[..self.len].binary_search_by_key(&code, |s| s[0]) {
                Ok(i) => {
                    let s = &mut self.slots[i];
                    let n = count_of(s).saturating_add(1);
                    let m = mean_of(s);
                    // The running mean in f32 (exact for these integers; the error of
                    // one update is below half a unit of the 1/65536 scale).
                    let mean = core::array::from_fn(|a| {
                        let (m, q) = (f32::from(m[a]), f32::from(q[a]));
                        libm::roundf(m + (q - m) / f32::from(n)).clamp(0.0, 65_535.0) as u16
                    });
                    *s = slot(code, n, mean);
                    self.stats.merged = self.stats.merged.saturating_add(1);
                }
                Err(i) if self.len < CAP => {
                    self.work = self.work.wrapping_add((self.len - i) as u64);
                    self.slots.copy_within(i..self.len, i + 1);
                    self.slots[i] = slot(code, 1, q);
                    self.len += 1;
                }
                Err(_) if self.level < self.max_level => {
                    self.coarsen();
                    continue;
                }
                Err(_) => {
                    self.stats.refused_full = self.stats.refused_full.saturating_add(1);
                    return Ok(false);
                }
            }
            self.stats.accepted = self.stats.accepted.saturating_add(1);
            return Ok(true);
        }
    }

    /// Doubles the voxel edge and merges voxels that now share a code. A child's mean
    /// becomes its parent's by halving after adding a half edge on each axis where the
    /// child is the upper one; merged means are weighted by count (in `f32`: the
    /// Cortex-M4F's single-precision unit, no 64-bit division).
    fn coarsen(&mut self) {
        self.work = self.work.wrapping_add(2 * self.len as u64);
        self.level += 1;
        self.stats.coarsenings = self.stats.coarsenings.saturating_add(1);
        let len = self.len.min(CAP);
        let slots = &mut self.slots[..len];
        // Merged voxels, the last one at `w - 1` (w <= r: the write never passes the read).
        let mut w = 0usize;
        for r in 0..len {
            let s = slots[r];
            let code = s[0] >> 3;
            let n = count_of(&s);
            let m = mean_of(&s);
            let mean: [u16; 3] = core::array::from_fn(|a| {
                let upper = (s[0] >> a) & 1;
                ((u32::from(m[a]) + (upper << 16)) >> 1) as u16
            });
            if w > 0 && slots[w - 1][0] == code {
                let (n0, m0) = (count_of(&slots[w - 1]), mean_of(&slots[w - 1]));
                let (f0, f1) = (f32::from(n0), f32::from(n));
                let merged = core::array::from_fn(|a| {
                    let v = (f32::from(m0[a]) * f0 + f32::from(mean[a]) * f1) / (f0 + f1);
                    libm::roundf(v).clamp(0.0, 65_535.0) as u16
                });
                slots[w - 1] = slot(code, n0.saturating_add(n), merged);
            } else {
                slots[w] = slot(code, n, mean);
                w += 1;
            }
        }
        self.len = w;
    }

    /// Turns the voxels into their centroids, in place, and returns them (Morton order).
    /// The cloud accepts no more points afterwards; calling it again returns the same
    /// slice.
    pub fn finish(&mut self) -> &[Vec3] {
        while !self.finish_some(usize::MAX) {}
        bytemuck::cast_slice(&self.slots[..self.len])
    }

    /// [`VoxelCloud::finish`] in bounded steps: turns at most `budget` more voxels into
    /// their centroids (about a thousand soft-float instructions each on the
    /// Cortex-M4F); `true` when all are. The cloud accepts no more points from the
    /// first call on.
    pub fn finish_some(&mut self, budget: usize) -> bool {
        self.finished = true;
        let end = self.converted.saturating_add(budget).min(self.len);
        let origin = self.origin.unwrap_or([0; 3]);
        let level = u32::from(self.level);
        let finest = f64::from(self.finest_mm);
        let edge = finest * f64::from(1u32 << level);
        for i in self.converted..end {
            let s = self.slots[i];
            let k = demorton(s[0]);
            let m = mean_of(&s);
            let c: [f32; 3] = core::array::from_fn(|a| {
                let corner = (((k[a] as i64) << level) + origin[a]) as f64 * finest;
                (corner + (f64::from(m[a]) + 0.5) / MEAN_SCALE * edge) as f32
            });
            self.slots[i] = bytemuck::cast(Vec3::from(c));
        }
        self.converted = end;
        end >= self.len
    }
}

/// Interleaves the low 10 bits of x, y, z: bit `i` of x → bit `3i`, y → `3i + 1`,
/// z → `3i + 2`.
fn morton(k: [u32; 3]) -> u32 {
    spread(k[0]) | (spread(k[1]) << 1) | (spread(k[2]) << 2)
}

/// Inverse of [`morton`].
fn demorton(code: u32) -> [u32; 3] {
    [compact(code), compact(code >> 1), compact(code >> 2)]
}

fn spread(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00ff;
    x = (x | (x << 8)) & 0x0300_f00f;
    x = (x | (x << 4)) & 0x030c_30c3;
    (x | (x << 2)) & 0x0924_9249
}

fn compact(v: u32) -> u32 {
    let mut x = v & 0x0924_9249;
    x = (x | (x >> 2)) & 0x030c_30c3;
    x = (x | (x >> 4)) & 0x0300_f00f;
    x = (x | (x >> 8)) & 0x0300_00ff;
    (x | (x >> 16)) & 0x3ff
}

/// Frames placed and refused by a [`Compounder`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameStats {
    /// Frames whose pixels went into the cloud.
    pub placed: u32,
    /// Frames refused because their lag-corrected time is outside the tracked range (or
    /// across a gap in it).
    pub outside_track: u32,
    /// Frames refused for a bad pixel or time stamp.
    pub invalid: u32,
}

/// A sweep being compounded: calibration and lag, the pose window and the cloud.
///
/// A frame is placed at once ([`Compounder::queue_frame`]: pose, calibration, checks),
/// but its points may wait in a queue of [`PENDING_POINTS`] for the voxel cloud
/// ([`Compounder::insert_queued`], a bounded number per call): an insertion costs a few
/// thousand soft-float instructions on the Cortex-M4F, a whole frame's several hundred
/// thousand, too much for one call of the controller's loop. [`Compounder::add_frame`]
/// does both at once. Points leave the queue in order, so the cloud is the same.
#[derive(Clone)]
pub struct Compounder<const POSES: usize, const VOXELS: usize> {
    calibration: Calibration,
    ee_t_us: Rigid,
    lag_s: f64,
    pending: heapless::Deque<Vec3, PENDING_POINTS>,
    closed: bool,
    /// The tracked flange poses.
    pub track: PoseTrack<POSES>,
    /// The bone-surface cloud, robot base frame.
    pub cloud: VoxelCloud<VOXELS>,
    /// Frame counters.
    pub frames: FrameStats,
    /// Where the tracked poses' images passed ([`Compounder::add_pose`]).
    pub imaged: ImagedArea<IMAGED_LINES>,
}

impl<const POSES: usize, const VOXELS: usize> Compounder<POSES, VOXELS> {
    /// A compounder for `calibration` (validated) and a lag (s, positive when the video
    /// lags the tracker, within ±10 s), into voxels of `voxel_mm` (see [`VoxelCloud::new`]).
    pub fn new(
        calibration: Calibration,
        lag_s: f64,
        voxel_mm: f32,
        max_coarsenings: u8,
    ) -> Result<Self> {
        let mut c = Self::empty();
        c.reset(calibration, lag_s, voxel_mm, max_coarsenings)?;
        Ok(c)
    }

    /// An idle compounder built at compile time (identity calibration of a 1×1-pixel
    /// probe); [`Compounder::reset`] sets it up in place.
    pub const fn empty() -> Self {
        const IDENTITY: Rigid = Rigid {
            rotation: nalgebra::Matrix3::from_array_storage(nalgebra::ArrayStorage([
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ])),
            translation: Vec3::new(0.0, 0.0, 0.0),
        };
        Compounder {
            calibration: Calibration {
                probe: crate::acquisition::probe::ProbeModel {
                    width_px: 1,
                    height_px: 1,
                    footprint_mm: 1.0,
                    depth_mm: 1.0,
                },
                tcp_t_us: IDENTITY,
                ee_t_tcp: IDENTITY,
            },
            ee_t_us: IDENTITY,
            lag_s: 0.0,
            pending: heapless::Deque::new(),
            closed: false,
            track: PoseTrack::new(),
            cloud: VoxelCloud::empty(),
            frames: FrameStats {
                placed: 0,
                outside_track: 0,
                invalid: 0,
            },
            imaged: ImagedArea::new(),
        }
    }

    /// Empties the compounder in place for a new sweep with these settings (see
    /// [`Compounder::new`]); on a configuration error it is left unchanged.
    pub fn reset(
        &mut self,
        calibration: Calibration,
        lag_s: f64,
        voxel_mm: f32,
        max_coarsenings: u8,
    ) -> Result<()> {
        calibration.validate()?;
        if !(lag_s.is_finite() && libm::fabs(lag_s) <= 10.0) {
            return Err(Error::Config("lag must be finite and within ±10 s"));
        }
        self.cloud.reset(voxel_mm, max_coarsenings)?;
        self.calibration = calibration;
        self.ee_t_us = calibration.ee_t_us();
        self.lag_s = lag_s;
        self.track.clear();
        self.frames = FrameStats::default();
        self.imaged.clear();
        self.pending.clear();
        self.closed = false;
        Ok(())
    }

    /// Ends the sweep: frames are refused from now on ([`Error::Config`]); the points
    /// still queued go into the cloud with the next [`Compounder::insert_queued`].
    pub fn close(&mut self) {
        self.closed = true;
    }

    /// Points waiting for the voxel cloud.
    pub fn queued(&self) -> usize {
        self.pending.len()
    }

    /// Moves queued points into the voxel cloud, oldest first, until about `budget` units
    /// of [`VoxelCloud::work`] are done (at least one point if any is queued; the last
    /// may overshoot by one insert: a point and a shift of the whole cloud; an insert
    /// into a full cloud, which may coarsen it, comes first in its call); `true` when
    /// none is left.
    pub fn insert_queued(&mut self, budget: u64) -> bool {
        let start = self.cloud.work();
        while self.cloud.work().wrapping_sub(start) < budget {
            // A full cloud may coarsen at the next point: that starts a call of its own.
            if self.cloud.len() >= VOXELS && self.cloud.work() != start {
                break;
            }
            let Some(q) = self.pending.pop_front() else {
                break;
            };
            // Note: cannot fail: the point was checked when queued, and the cloud is
            // finished only by its owner after the queue is empty (a full cloud refuses
            // with Ok(false), counted in its stats).
            let _ = self.cloud.insert(&q);
        }
        self.pending.is_empty()
    }

    /// The lag in use, s.
    pub fn lag_s(&self) -> f64 {
        self.lag_s
    }

    /// Adds a tracked flange pose (see [`PoseTrack::push`]) and marks its image in
    /// [`Compounder::imaged`].
    pub fn add_pose(&mut self, pose: TrackedPose) -> Result<()> {
        self.track.push(pose)?;
        let b_t_us = pose.to_rigid().after(&self.ee_t_us);
        self.imaged.place(&b_t_us, &self.calibration.probe);
        Ok(())
    }

    /// Adds a frame stamped `t` (video clock) with its bone pixels `(u, v)` to the cloud
    /// ([`Compounder::queue_frame`], then every queued point inserted). Returns the points
    /// kept by the cloud in this call.
    pub fn add_frame(&mut self, t: f64, pixels: &[[f32; 2]]) -> Result<u32> {
        let before = self.cloud.stats.accepted;
        self.queue_frame(t, pixels)?;
        while !self.insert_queued(u64::MAX) {}
        Ok(self.cloud.stats.accepted.wrapping_sub(before))
    }

    /// Places a frame stamped `t` (video clock) with its bone pixels `(u, v)` and queues
    /// its points for the cloud; returns how many. The frame is all or nothing: a pixel
    /// outside the image or not finite is [`Error::Pixel`], a time outside the tracked
    /// range [`Error::OutsideTrack`] or [`Error::TrackGap`], after
    /// [`Compounder::close`] [`Error::Config`]; nothing of that frame is added and
    /// [`Compounder::frames`] counts it. When the queue is full the oldest points go into
    /// the cloud first (the caller fell behind with [`Compounder::insert_queued`]).
    pub fn queue_frame(&mut self, t: f64, pixels: &[[f32; 2]]) -> Result<usize> {
        if self.closed {
            return Err(Error::Config("the sweep has ended"));
        }
        let probe = self.calibration.probe;
        if let Some(i) = pixels
            .iter()
            .position(|p| probe.pixel_to_image(p[0], p[1]).is_none())
        {
            self.frames.invalid = self.frames.invalid.saturating_add(1);
            return Err(Error::Pixel { index: i as u32 });
        }
        if self.cloud.finished {
            return Err(Error::Config("the voxel cloud is finished"));
        }
        if !t.is_finite() {
            self.frames.invalid = self.frames.invalid.saturating_add(1);
            return Err(Error::Sample {
                stream: Stream::Frames,
                index: self.frames.placed,
            });
        }
        let b_t_ee = match self.track.at(t - self.lag_s) {
            Ok(pose) => pose,
            Err(e) => {
                self.frames.outside_track = self.frames.outside_track.saturating_add(1);
                return Err(e);
            }
        };
        let b_t_us = b_t_ee.after(&self.ee_t_us);
        let point = |p: &[f32; 2]| {
            probe
                .pixel_to_image(p[0], p[1])
                .map(|q| b_t_us.apply(&q))
                .filter(|q| {
                    q.iter().all(|v| v.is_finite()) && q.amax() <= crate::limits::MAX_COORD_MM
                })
        };
        // All or nothing: a point beyond MAX_COORD_MM (a pose at the edge of the range)
        // refuses the frame before anything is inserted.
        if let Some(i) = pixels.iter().position(|p| point(p).is_none()) {
            self.frames.invalid = self.frames.invalid.saturating_add(1);
            return Err(Error::Pixel { index: i as u32 });
        }
        let mut queued = 0;
        for q in pixels.iter().filter_map(point) {
            if self.pending.is_full() {
                self.insert_queued(1);
            }
            // Note: room was just made.
            let _ = self.pending.push_back(q);
            queued += 1;
        }
        self.frames.placed = self.frames.placed.saturating_add(1);
        Ok(queued)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acquisition::probe::ProbeModel;
    use nalgebra::Matrix3;

    #[test]
    fn morton_round_trip() {
        for k in [[0, 0, 0], [1, 2, 3], [0x3ff, 0, 0x155], [123, 999, 1023]] {
            assert_eq!(demorton(morton(k)), k);
        }
        assert_eq!(morton([0x3ff; 3]), (1 << 30) - 1);
        // Halving every index is a 3-bit shift.
        let k = [1000u32, 777, 99];
        assert_eq!(morton(k) >> 3, morton([500, 388, 49]));
    }

    /// The accuracy contract (module docs) against an `f64` reference: every centroid
    /// within (n + 1) / 2 of the 1/65536 units of its voxel's edge per axis of the mean of
    /// its n points, through coarsenings; the voxels are the ones the final edge gives.
    #[test]
    fn centroids_match_an_f64_mean() {
        check_against_f64::<4096>(1, 200, 0);
        check_against_f64::<256>(2, 5_000, 3);
        check_against_f64::<64>(3, 20_000, 3);
    }

    fn check_against_f64<const N: usize>(seed: u64, n_points: usize, coarsenings: u8) {
        use std::collections::BTreeMap;
        let mut rng = crate::math::rng::Rng::new(seed);
        let pts: std::vec::Vec<Vec3> = (0..n_points)
            .map(|_| {
                Vec3::new(
                    rng.next_f32() * 80.0 - 1234.5,
                    rng.next_f32() * 40.0 + 300.0,
                    rng.next_f32() * 10.0 - 0.3,
                )
            })
            .collect();
        let mut c = VoxelCloud::<N>::new(1.5, 6).unwrap();
        for p in &pts {
            assert_eq!(c.insert(p), Ok(true));
        }
        assert_eq!(c.stats.coarsenings, coarsenings);
        let edge = f64::from(c.voxel_mm());
        let key = |p: &Vec3| p.map(|v| libm::floor(f64::from(v) / edge) as i64);
        let mut reference: BTreeMap<[i64; 3], (f64, [f64; 3])> = BTreeMap::new();
        for p in &pts {
            let k = key(p);
            let e = reference.entry([k.x, k.y, k.z]).or_default();
            e.0 += 1.0;
            for a in 0..3 {
                e.1[a] += f64::from(p[a]);
            }
        }
        let centroids = c.finish();
        assert_eq!(centroids.len(), reference.len());
        let mut worst = 0.0f64;
        for q in centroids {
            let k = key(q);
            let (n, sum) = reference[&[k.x, k.y, k.z]];
            for a in 0..3 {
                let err = (f64::from(q[a]) - sum[a] / n).abs();
                // Plus the f32 rounding of a coordinate near 1,234 mm.
                let bound = (n + 1.0) / 2.0 / MEAN_SCALE * edge + 1e-4;
                assert!(err <= bound, "{err} > {bound} (n = {n}, edge {edge} mm)");
                worst = worst.max(err);
            }
        }
        std::eprintln!(
            "{n_points} points, {} voxels of {edge} mm: worst {worst:.2e} mm",
            centroids.len()
        );
    }

    #[test]
    fn merges_points_of_a_voxel_into_their_centroid() {
        let mut c = VoxelCloud::<16>::new(2.0, 0).unwrap();
        for p in [
            [0.2, 0.2, 0.2],
            [1.8, 1.0, 0.4],
            [-0.5, 0.0, 0.0],
            [10.1, -3.9, 5.0],
        ] {
            assert_eq!(c.insert(&Vec3::new(p[0], p[1], p[2])), Ok(true));
        }
        assert_eq!(c.len(), 3);
        assert_eq!(c.stats.merged, 1);
        let pts = c.finish();
        assert!(pts
            .iter()
            .any(|p| (p - Vec3::new(1.0, 0.6, 0.3)).norm() < 1e-4));
        assert!(pts
            .iter()
            .any(|p| (p - Vec3::new(-0.5, 0.0, 0.0)).norm() < 1e-4));
        assert!(pts
            .iter()
            .any(|p| (p - Vec3::new(10.1, -3.9, 5.0)).norm() < 1e-4));
        assert!(matches!(c.insert(&Vec3::zeros()), Err(Error::Config(_))));
    }

    /// A full cloud coarsens exactly: the result equals a cloud built at the coarse size.
    #[test]
    fn coarsening_equals_building_coarse() {
        let mut rng = crate::math::rng::Rng::new(5);
        let pts: std::vec::Vec<Vec3> = (0..3000)
            .map(|_| {
                Vec3::new(
                    rng.next_f32() * 60.0 - 30.0,
                    rng.next_f32() * 20.0 + 100.0,
                    rng.next_f32() * 3.0,
                )
            })
            .collect();
        let mut small = VoxelCloud::<64>::new(1.0, 4).unwrap();
        for p in &pts {
            assert_eq!(small.insert(p), Ok(true));
        }
        assert!(small.stats.coarsenings >= 1);
        let edge = small.voxel_mm();
        let mut direct = VoxelCloud::<64>::new(edge, 0).unwrap();
        for p in &pts {
            assert_eq!(direct.insert(p), Ok(true));
        }
        // The windows' origins differ (multiples of 16 and of 1 voxel), so the Morton
        // orders do too: compare in one order. Means agree within the contract.
        let sorted = |c: &mut VoxelCloud<64>| {
            let mut v = c.finish().to_vec();
            v.sort_by(|p, q| p.as_slice().partial_cmp(q.as_slice()).unwrap());
            v
        };
        let (a, b) = (sorted(&mut small), sorted(&mut direct));
        assert_eq!(a.len(), b.len());
        for (p, q) in a.iter().zip(&b) {
            assert!((p - q).norm() < 0.05, "{p} vs {q}");
        }
        // At its coarsest level a full cloud refuses and counts.
        let mut tiny = VoxelCloud::<4>::new(1.0, 0).unwrap();
        for p in pts.iter().take(100) {
            tiny.insert(p).unwrap();
        }
        assert_eq!(tiny.len(), 4);
        assert_eq!(tiny.stats.accepted + tiny.stats.refused_full, 100);
        assert!(tiny.stats.refused_full > 0);
    }

    #[test]
    fn bad_points_are_refused_unchanged() {
        let mut c = VoxelCloud::<8>::new(1.0, 0).unwrap();
        assert!(matches!(
            c.insert(&Vec3::new(f32::NAN, 0.0, 0.0)),
            Err(Error::NonFinite { .. })
        ));
        assert!(matches!(
            c.insert(&Vec3::new(2e5, 0.0, 0.0)),
            Err(Error::OutOfRange { .. })
        ));
        assert!(c.is_empty());
        assert!(VoxelCloud::<8>::new(0.01, 0).is_err());
        assert!(VoxelCloud::<8>::new(f32::NAN, 0).is_err());
    }

    /// A probe held still above a flat plate: every frame lands on the same line, placed
    /// with the interpolated pose; frames outside the track are refused and counted.
    #[test]
    fn compounds_frames_with_lag_corrected_poses() {
        let cal = Calibration::centred(ProbeModel::LINEAR_38MM, Rigid::identity());
        let mut c = Compounder::<16, 256>::new(cal, 0.25, 1.0, 0).unwrap();
        // The flange moves along base y at 100 mm/s, beam along base z.
        for i in 0..10 {
            let t = f64::from(i) * 0.01;
            let pose = Rigid {
                rotation: Matrix3::identity(),
                translation: Vec3::new(0.0, 100.0 * t as f32, 0.0),
            };
            c.add_pose(TrackedPose::from_rigid(t, &pose)).unwrap();
        }
        // Frame stamped 0.295 s shows the pose at 0.045 s: y = 4.5 mm; row 200 = 20 mm deep.
        let kept = c.add_frame(0.295, &[[192.0, 200.0], [0.0, 200.0]]).unwrap();
        assert_eq!(kept, 2);
        assert!(matches!(
            c.add_frame(0.2, &[[1.0, 1.0]]),
            Err(Error::OutsideTrack { .. })
        ));
        assert!(matches!(
            c.add_frame(0.3, &[[1.0, 1e4]]),
            Err(Error::Pixel { index: 0 })
        ));
        assert_eq!(
            c.frames,
            FrameStats {
                placed: 1,
                outside_track: 1,
                invalid: 1
            }
        );
        let pts = c.cloud.finish();
        assert!(
            pts.iter()
                .any(|p| (p - Vec3::new(0.0, 4.5, 20.0)).norm() < 1e-4),
            "{pts:?}"
        );
        assert!(
            pts.iter()
                .any(|p| (p - Vec3::new(-19.2, 4.5, 20.0)).norm() < 1e-4),
            "{pts:?}"
        );
    }

    /// Frames queued and inserted a little at a time (even through a coarsening) give
    /// the cloud `add_frame` gives, bit for bit; every call with queued points makes
    /// progress; a full queue makes room by inserting its oldest points; after `close`
    /// frames are refused and the queued points still go in.
    #[test]
    fn queued_frames_give_the_same_cloud() {
        let cal = Calibration::centred(ProbeModel::LINEAR_38MM, Rigid::identity());
        let new = || Compounder::<64, 96>::new(cal, 0.0, 1.0, 3).unwrap();
        let (mut direct, mut queued) = (new(), new());
        for i in 0..40 {
            let t = f64::from(i) * 0.01;
            let pose = Rigid {
                rotation: Matrix3::identity(),
                translation: Vec3::new(0.0, 100.0 * t as f32, 0.0),
            };
            let pose = TrackedPose::from_rigid(t, &pose);
            direct.add_pose(pose).unwrap();
            queued.add_pose(pose).unwrap();
        }
        let mut rng = crate::math::rng::Rng::new(3);
        let mut calls = 0;
        for f in 0..30 {
            let pixels: std::vec::Vec<[f32; 2]> = (0..PENDING_POINTS / 3)
                .map(|_| [rng.next_f32() * 380.0, 50.0 + rng.next_f32() * 200.0])
                .collect();
            let t = 0.01 + f64::from(f) * 0.012;
            direct.add_frame(t, &pixels).unwrap();
            assert_eq!(queued.queue_frame(t, &pixels), Ok(pixels.len()));
            // Drained only every other frame: the queue fills and makes room itself.
            if f % 2 == 0 {
                let before = queued.queued();
                while !queued.insert_queued(300) {
                    calls += 1;
                }
                assert!(before == 0 || calls > 0);
            }
            assert!(queued.queued() <= PENDING_POINTS);
        }
        assert!(direct.cloud.stats.coarsenings >= 1);
        queued.close();
        assert_eq!(
            queued.queue_frame(0.2, &[[1.0, 1.0]]),
            Err(Error::Config("the sweep has ended"))
        );
        assert!(queued.queued() > 0);
        let mut steps = 0;
        while !queued.insert_queued(1) {
            steps += 1;
        }
        assert!(steps > 0);
        assert_eq!(queued.cloud.stats, direct.cloud.stats);
        assert_eq!(queued.cloud.finish(), direct.cloud.finish());
    }
}
