//! Endpoint correspondence target (US) → template (CT): which target endpoint belongs to
//! which rib and side.
//!
//! 1. **Coarse pose.** Rigid ICP of the 40 target key points onto the 40 template key
//!    points from five starts — the identity and the four proper rotations that align
//!    the two clouds' principal axes (axis signs `(±1, ±1)`, third from the cross
//!    product) — each after centroid alignment, [`COARSE_ITERATIONS`] iterations of
//!    nearest-neighbour pairing and [`crate::kabsch::fit`]. The start with the lowest
//!    final RMS wins (the sternum and the unequal cartilage lengths break the
//!    near-symmetries of the chest). No initial alignment of the clouds is needed.
//! 2. **Endpoint ICP.** The paper's small ICP on the eight endpoints, starting from the
//!    coarse pose; the pairing is the optimal one-to-one assignment (exhaustive search
//!    with pruning over the 8! pairings), so two target endpoints can never claim the
//!    same rib; repeated until the assignment stops changing (at most
//!    [`ENDPOINT_ITERATIONS`]).
//! 3. Each target endpoint takes the rib and side of the template endpoint it is paired
//!    with.

use crate::error::Result;
use crate::geom::{nearest, Frame, Rigid};
use crate::kabsch;
use crate::skeleton::{RibEnds, SkeletonGraph};
use crate::Vec3;
use nalgebra::Matrix3;

/// ICP iterations of the coarse key-point alignment from each start.
pub const COARSE_ITERATIONS: usize = 30;
/// Maximum rounds of the endpoint ICP.
pub const ENDPOINT_ITERATIONS: usize = 10;

/// Result of matching target endpoints to the template's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EndpointMatch {
    /// Target rib ends in the template's rib and side order.
    pub ends: RibEnds,
    /// Rigid pose target → template found by the endpoint ICP.
    pub pose: Rigid,
    /// RMS distance (mm) of the coarse key-point alignment.
    pub coarse_rms: f32,
    /// RMS distance (mm) of the paired endpoints after the endpoint ICP.
    pub endpoint_rms: f32,
}

/// Matches the endpoints of `target` to those of `template` whose rib order is `ends`.
pub fn match_endpoints(
    target: &SkeletonGraph,
    template: &SkeletonGraph,
    ends: &RibEnds,
) -> Result<EndpointMatch> {
    let (coarse, coarse_rms) = coarse_pose(
        &target.key_points,
        &target.frame,
        &template.key_points,
        &template.frame,
    )?;
    // Template endpoints in slot order k = 2·rib + side.
    let ct: [Vec3; 8] =
        core::array::from_fn(|k| template.key_points[usize::from(ends.0[k / 2][k % 2])]);
    let found = target.endpoints?;
    let us_idx: [u8; 8] = core::array::from_fn(|k| found[k / 4][k % 4]);
    let us: [Vec3; 8] = us_idx.map(|i| target.key_points[usize::from(i)]);
    let mut pose = coarse;
    let mut assign = [u8::MAX; 8];
    let mut rms = f32::INFINITY;
    for _ in 0..ENDPOINT_ITERATIONS {
        let moved = us.map(|p| pose.apply(&p));
        let cost: [[f32; 8]; 8] =
            core::array::from_fn(|i| core::array::from_fn(|j| (moved[i] - ct[j]).norm_squared()));
        let (next, total) = best_assignment(&cost);
        rms = libm::sqrtf(total / 8.0);
        if next == assign {
            break;
        }
        assign = next;
        let paired: [Vec3; 8] = core::array::from_fn(|i| ct[usize::from(assign[i])]);
        pose = kabsch::fit(&us, &paired)?;
    }
    let mut out = [[0u8; 2]; 4];
    for (i, &slot) in assign.iter().enumerate() {
        out[usize::from(slot) / 2][usize::from(slot) % 2] = us_idx[i];
    }
    Ok(EndpointMatch {
        ends: RibEnds(out),
        pose,
        coarse_rms,
        endpoint_rms: rms,
    })
}

/// Rigid pose taking `src` onto `dst` from five starts (see the module docs), whatever
/// their relative pose; `fs`, `fd` are their principal axes. Returns the pose and RMS.
#[inline(never)]
pub fn coarse_pose(src: &[Vec3], fs: &Frame, dst: &[Vec3], fd: &Frame) -> Result<(Rigid, f32)> {
    let mut best: Option<(Rigid, f32)> = None;
    for start in 0..5 {
        let rotation = if start == 0 {
            Matrix3::identity()
        } else {
            let (s1, s2) = (
                if start & 1 == 1 { 1.0 } else { -1.0 },
                if start & 2 == 2 { 1.0 } else { -1.0 },
            );
            let mut axes = fs.axes;
            axes.set_column(0, &(fs.axes.column(0) * s1));
            axes.set_column(1, &(fs.axes.column(1) * s2));
            let third = axes.column(0).cross(&axes.column(1));
            axes.set_column(2, &third);
            fd.axes * axes.transpose()
        };
        let init = Rigid {
            rotation,
            translation: fd.origin - rotation * fs.origin,
        };
        let (pose, rms) = icp(src, dst, init, COARSE_ITERATIONS)?;
        if best.is_none_or(|(_, b)| rms < b) {
            best = Some((pose, rms));
        }
    }
    // Note: the loop above runs five times and sets `best` on the first.
    best.ok_or(crate::error::Error::RigidFit)
}

/// Largest source set of [`icp`] (a SOM-1 node set).
pub const ICP_CAPACITY: usize = crate::skeleton::SOM1_CAPACITY;

/// Point-to-point ICP of `src` (at most [`ICP_CAPACITY`] points) onto `dst` from `pose`,
/// `iterations` rounds; returns the pose and the RMS of the last pairing.
#[inline(never)]
pub fn icp(src: &[Vec3], dst: &[Vec3], mut pose: Rigid, iterations: usize) -> Result<(Rigid, f32)> {
    if src.len() > ICP_CAPACITY {
        return Err(crate::error::Error::Capacity {
            capacity: ICP_CAPACITY as u32,
        });
    }
    let mut rms = f32::INFINITY;
    for _ in 0..iterations {
        let mut paired = [Vec3::zeros(); ICP_CAPACITY];
        let mut sum = 0.0;
        for (p, q) in src.iter().zip(paired.iter_mut()) {
            let m = pose.apply(p);
            let (j, d2) = nearest(dst, &m).unwrap_or((0, 0.0));
            *q = dst[j];
            sum += d2;
        }
        rms = libm::sqrtf(sum / src.len().max(1) as f32);
        pose = kabsch::fit(src, &paired[..src.len()])?;
    }
    Ok((pose, rms))
}

/// Optimal one-to-one assignment for an 8×8 cost matrix: `assign[i]` is the column of
/// row `i`; returns it with its total cost. Depth-first search with pruning.
pub fn best_assignment(cost: &[[f32; 8]; 8]) -> ([u8; 8], f32) {
    fn go(
        cost: &[[f32; 8]; 8],
        row: usize,
        used: u8,
        acc: f32,
        cur: &mut [u8; 8],
        best: &mut ([u8; 8], f32),
    ) {
        if acc >= best.1 {
            return;
        }
        if row == 8 {
            *best = (*cur, acc);
            return;
        }
        for col in 0..8 {
            if used & (1 << col) == 0 {
                cur[row] = col as u8;
                go(
                    cost,
                    row + 1,
                    used | (1 << col),
                    acc + cost[row][col],
                    cur,
                    best,
                );
            }
        }
    }
    // Start from the diagonal so the bound is finite from the first leaf on.
    let diag: f32 = (0..8).map(|i| cost[i][i]).sum();
    let mut best = (
        [0, 1, 2, 3, 4, 5, 6, 7],
        if diag.is_finite() { diag } else { f32::MAX },
    );
    let mut cur = [0u8; 8];
    go(cost, 0, 0, 0.0, &mut cur, &mut best);
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn assignment_finds_the_permutation() {
        let perm = [3u8, 0, 7, 1, 6, 2, 5, 4];
        let cost: [[f32; 8]; 8] = core::array::from_fn(|i| {
            core::array::from_fn(|j| {
                if perm[i] as usize == j {
                    0.1
                } else {
                    1.0 + (i * j) as f32
                }
            })
        });
        let (a, total) = best_assignment(&cost);
        assert_eq!(a, perm);
        assert!((total - 0.8).abs() < 1e-5);
    }

    #[test]
    fn assignment_beats_greedy() {
        // Greedy row 0 takes column 0 (cost 1) and forces row 1 onto cost 100.
        let mut cost = [[50.0f32; 8]; 8];
        for (i, row) in cost.iter_mut().enumerate().skip(2) {
            row[i] = 0.0;
        }
        cost[0][0] = 1.0;
        cost[0][1] = 2.0;
        cost[1][0] = 2.0;
        cost[1][1] = 100.0;
        let (a, total) = best_assignment(&cost);
        assert_eq!(&a[..2], &[1, 0]);
        assert!((total - 4.0).abs() < 1e-5);
    }
}
