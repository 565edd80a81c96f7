//! Whether the sweep reaches each planned waypoint (guided model).
//!
//! A waypoint lies in the gap between two cartilages, and the registration places it by
//! what the sweep shows of them. Where a sweep hole or a lost lateral tip took the
//! cartilage beyond some point, the registration still maps a waypoint out there — by
//! the template's shape, not by the patient's — and nothing says so: the rib-side
//! coverage ([`crate::registration::guided::check_coverage`]) passes a side seen over
//! 60 % of its length. So each waypoint is checked on its own: its two bounding ribs are
//! the two whose template skeleton passes nearest the planned point, and the mapped
//! point, taken into the last fitting frame ([`Registration::pose`], x lateral), must
//! not lie beyond either rib's observed end on its side
//! ([`Registration::reach`], the nodes and tips the sweep shows, before any short rib
//! is lengthened) by more than [`MAX_BEYOND_MM`].
//!
//! [`WaypointReach::check`] refuses an unreached waypoint with
//! [`Error::NotReached`]; a caller that maps what is reached and marks the rest (`ribreg
//! register --partial`, the controller's partial plans) reads
//! [`WaypointReach::supported`] instead, which marks every waypoint on the side of an
//! unreached one. Constant work per waypoint (the 30 skeleton
//! points), nothing allocated.

use crate::config::{RIBS, RIB_SAMPLES};
use crate::error::{Error, Result, Side};
use crate::limits::SKELETON_POINTS;
use crate::registration::guided::tenths;
use crate::registration::pipeline::{Registration, Template};
use crate::Vec3;

/// How far a mapped waypoint may lie beyond the end of a bounding rib the sweep shows,
/// in x of the fitting frame, mm (see the module docs).
pub const MAX_BEYOND_MM: f32 = 3.0;

/// How far one mapped waypoint lies beyond what the sweep shows of its gap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WaypointReach {
    /// The two ribs (2..=5) bounding the waypoint's gap, nearest first.
    pub ribs: [u8; 2],
    /// The one of them whose observed end the waypoint lies farthest beyond.
    pub rib: u8,
    /// The side of the sternum the waypoint lies on, by that rib's midline.
    pub side: Side,
    /// How far beyond that rib's observed end, mm in x (negative: inside it; infinite
    /// for a rib the sweep does not show, NaN for a waypoint not finite).
    pub beyond_mm: f32,
}

impl WaypointReach {
    /// Of a waypoint planned at `planned` (template frame) and mapped to `mapped`
    /// (target frame) by `registration` of `template` ([`WaypointReach::against`]).
    /// `None` for a registration without rib extents (the graph model).
    pub fn of(
        template: &Template,
        registration: &Registration,
        planned: &Vec3,
        mapped: &Vec3,
    ) -> Option<WaypointReach> {
        let ends = registration.reach?;
        let q = registration.pose.apply(mapped);
        Some(Self::against(&template.skeleton.points, &ends, planned, &q))
    }

    /// Of a waypoint planned at `planned` on the template skeleton `skeleton`, mapped to
    /// `q` in the fitting frame, against the rib extents `ends` there
    /// ([`Registration::reach`]).
    pub fn against(
        skeleton: &[Vec3; SKELETON_POINTS],
        ends: &[(f32, f32, f32); 4],
        planned: &Vec3,
        q: &Vec3,
    ) -> WaypointReach {
        let [nearest, second] = bounding_ribs(skeleton, planned);
        let at = |r: usize| {
            let (x0, mid, x1) = ends[r];
            let seen = x0 <= x1;
            let (side, beyond) = match (seen, q.x < mid) {
                (true, true) => (Side::Right, x0 - q.x),
                (true, false) => (Side::Left, q.x - x1),
                // A rib the sweep does not show: no side of it is reached.
                (false, _) if q.x < 0.0 => (Side::Right, f32::INFINITY),
                (false, _) => (Side::Left, f32::INFINITY),
            };
            WaypointReach {
                ribs: [RIBS[nearest], RIBS[second]],
                rib: RIBS[r],
                side,
                beyond_mm: beyond,
            }
        };
        let (a, b) = (at(nearest), at(second));
        // The farther beyond of the two; NaN (a point not finite) is the worst of all.
        if b.beyond_mm <= a.beyond_mm || a.beyond_mm.is_nan() {
            a
        } else {
            b
        }
    }

    /// Whether the sweep shows the waypoint's gap as far out as it lies (within
    /// [`MAX_BEYOND_MM`]).
    pub fn reached(&self) -> bool {
        self.beyond_mm <= MAX_BEYOND_MM
    }

    /// Whether a partial plan keeps this waypoint, given the reach of every waypoint
    /// of the plan (`plan`, this one among them): no waypoint on its side of the
    /// sternum is unreached. A rib the sweep shows short is extrapolated by the
    /// registration, and the skeleton of that side with it: measured with `eval
    /// --robustness --partial` (100 pairs per preset, seeds 0–199), marking only the
    /// gaps beside the short rib kept waypoints 12.5–14.1 mm off in the next gap (hard
    /// phantom 55 thinned to 30 %), so the whole side is marked.
    pub fn supported<'a>(&self, plan: impl IntoIterator<Item = &'a WaypointReach>) -> bool {
        self.reached() && plan.into_iter().all(|w| w.reached() || w.side != self.side)
    }

    /// Refuses waypoint `index` (0-based) unless [`WaypointReach::reached`]:
    /// [`Error::NotReached`].
    pub fn check(&self, index: usize) -> Result<()> {
        if self.reached() {
            return Ok(());
        }
        Err(Error::NotReached {
            waypoint: u8::try_from(index).unwrap_or(u8::MAX),
            rib: self.rib,
            side: self.side,
            beyond_dmm: tenths(self.beyond_mm),
            max_beyond_dmm: tenths(MAX_BEYOND_MM),
        })
    }
}

/// Refuses a plan, given each waypoint's reach in plan order (`None`: not measured,
/// the graph model): with `partial` only a plan that keeps no waypoint
/// ([`WaypointReach::supported`]), otherwise any with a waypoint not reached. The
/// refusal is the first unreached waypoint's [`Error::NotReached`].
pub fn check_plan<'a, I>(plan: I, partial: bool) -> Result<()>
where
    I: Iterator<Item = Option<&'a WaypointReach>> + Clone,
{
    let kept = |r: Option<&WaypointReach>| r.is_none_or(|r| r.supported(plan.clone().flatten()));
    if partial && plan.clone().any(kept) {
        return Ok(());
    }
    for (i, r) in plan.enumerate() {
        if let Some(r) = r {
            r.check(i)?;
        }
    }
    Ok(())
}

/// Least distance the sweep must have imaged beyond each rib end it shows, mm
/// ([`check_edges`]). A cartilage that ends was imaged past its end — empty tissue — a
/// cartilage the sweep stopped short of was not: its points end where the probe
/// turned back.
pub const MIN_EDGE_CLEARANCE_MM: f32 = 3.0;
/// Farthest [`edge_clearances`] looks beyond a rib end, mm.
pub const EDGE_LOOK_MM: f32 = 20.0;

/// Per rib (2..=5) and side (`[right, left]`), the end of the rib the sweep shows
/// ([`rib_end`] of each).
pub fn rib_ends(registration: &Registration) -> [[Option<(Vec3, Vec3)>; 2]; 4] {
    core::array::from_fn(|r| rib_end(registration, r))
}

/// Per side (`[right, left]`), the end of rib `RIBS[r]` the sweep shows
/// ([`Registration::reach`], before any short rib is lengthened) as a point of the
/// target frame, and the direction on out along the rib there: the target skeleton's
/// polyline of that rib, in the fitting frame, at the end's x (extended along its last
/// segment beyond the polyline). `None` for a rib not seen, the graph model, or a
/// skeleton not finite.
pub fn rib_end(registration: &Registration, r: usize) -> [Option<(Vec3, Vec3)>; 2] {
    let mut out = [None; 2];
    let (Some(reach), Some(&n)) = (registration.reach, RIB_SAMPLES.get(r)) else {
        return out;
    };
    let offset: usize = RIB_SAMPLES[..r].iter().sum();
    let rib = &registration.skeleton.points[offset..offset + n];
    let (x0, _, x1) = reach[r];
    // A rib not seen: no end (NaN compares false).
    if x0.is_nan() || x1.is_nan() || x0 > x1 {
        return out;
    }
    let to_target = registration.pose.inverse();
    for (end, (x, outward)) in out.iter_mut().zip([(x0, -1.0f32), (x1, 1.0)]) {
        // The segment whose x range lies nearest the end's x.
        let mut best: Option<(f32, Vec3, Vec3)> = None;
        for s in rib.windows(2) {
            let (a, b) = (
                registration.pose.apply(&s[0]),
                registration.pose.apply(&s[1]),
            );
            let (lo, hi) = (a.x.min(b.x), a.x.max(b.x));
            let gap = (lo - x).max(x - hi).max(0.0);
            if best.is_none_or(|(g, _, _)| gap < g) {
                best = Some((gap, a, b));
            }
        }
        let Some((_, a, b)) = best else { continue };
        let d = b - a;
        if d.x.is_nan() || d.x.abs() <= 1e-3 {
            continue;
        }
        let at = a + d * ((x - a.x) / d.x);
        let dir = if d.x * outward >= 0.0 { d } else { -d };
        let (p, u) = (to_target.apply(&at), to_target.rotation * dir);
        if p.iter().chain(u.iter()).all(|v| v.is_finite()) {
            *end = Some((p, u));
        }
    }
    out
}

/// Per rib (2..=5) and side (`[right, left]`), how far beyond the rib's end
/// ([`rib_ends`]) the sweep imaged without a break ([`edge_clearance`] of each).
pub fn edge_clearances(
    registration: &Registration,
    reach: impl Fn(&Vec3, &Vec3, f32) -> f32,
) -> [[f32; 2]; 4] {
    core::array::from_fn(|r| edge_clearance(registration, r, &reach))
}

/// Per side (`[right, left]`), how far beyond the end of rib `RIBS[r]` ([`rib_end`])
/// the sweep imaged without a break, mm, up to [`EDGE_LOOK_MM`]: `reach(from,
/// direction, max)` is the imaged region's
/// ([`crate::acquisition::imaged::ImagedArea::reach`], target frame = robot base). NaN
/// where [`rib_end`] gives none.
pub fn edge_clearance(
    registration: &Registration,
    r: usize,
    reach: impl Fn(&Vec3, &Vec3, f32) -> f32,
) -> [f32; 2] {
    rib_end(registration, r).map(|end| end.map_or(f32::NAN, |(p, u)| reach(&p, &u, EDGE_LOOK_MM)))
}

/// Refuses a registration a rib end of which lies at the edge of what the sweep
/// imaged ([`edge_clearances`] below [`MIN_EDGE_CLEARANCE_MM`]): [`Error::SweepEdge`]
/// for the least. The sweep may have stopped short of that cartilage, and the
/// registration would squeeze the template's rib onto what it shows, pulling that
/// side's waypoints toward the sternum. NaN clearances (a rib side not seen) are left
/// to the coverage checks.
pub fn check_edges(clearances: &[[f32; 2]; 4]) -> Result<()> {
    let mut least: Option<(usize, usize, f32)> = None;
    for (r, sides) in clearances.iter().enumerate() {
        for (s, &c) in sides.iter().enumerate() {
            if c < MIN_EDGE_CLEARANCE_MM && least.is_none_or(|(_, _, l)| c < l) {
                least = Some((r, s, c));
            }
        }
    }
    match least {
        None => Ok(()),
        Some((r, s, c)) => Err(Error::SweepEdge {
            rib: RIBS[r],
            side: if s == 0 { Side::Right } else { Side::Left },
            clearance_dmm: tenths(c),
            min_dmm: tenths(MIN_EDGE_CLEARANCE_MM),
        }),
    }
}

/// The least of [`edge_clearances`]' `clearances`, mm: NaN (a rib side not seen) is
/// left out, and none measured is NaN.
pub fn least_clearance(clearances: &[[f32; 2]; 4]) -> f32 {
    clearances.iter().flatten().fold(f32::NAN, |a, &b| a.min(b))
}

/// The sides (`[right, left]`) with a rib end below [`MIN_EDGE_CLEARANCE_MM`]: a partial
/// plan drives to no waypoint there.
pub fn cut_sides(clearances: &[[f32; 2]; 4]) -> [bool; 2] {
    core::array::from_fn(|s| clearances.iter().any(|c| c[s] < MIN_EDGE_CLEARANCE_MM))
}

/// The two ribs (indices into [`RIBS`]) whose skeleton polylines (`skeleton`, the 30
/// points rib by rib, [`RIB_SAMPLES`] each) pass nearest `p`, nearest first: the
/// cartilages bounding the gap a waypoint at `p` lies in.
pub fn bounding_ribs(skeleton: &[Vec3; SKELETON_POINTS], p: &Vec3) -> [usize; 2] {
    let mut dist = [f32::INFINITY; 4];
    let mut offset = 0;
    for (d, &n) in dist.iter_mut().zip(&RIB_SAMPLES) {
        let rib = &skeleton[offset..offset + n];
        *d = rib
            .windows(2)
            .map(|s| segment_distance_sq(p, &s[0], &s[1]))
            .fold(f32::INFINITY, f32::min);
        offset += n;
    }
    let nearest = (0..4).fold(0, |b, r| if dist[r] < dist[b] { r } else { b });
    let second = (0..4)
        .filter(|&r| r != nearest)
        .fold(usize::from(nearest == 0), |b, r| {
            if dist[r] < dist[b] {
                r
            } else {
                b
            }
        });
    [nearest, second]
}

/// Squared distance from `p` to the segment `a`–`b`.
fn segment_distance_sq(p: &Vec3, a: &Vec3, b: &Vec3) -> f32 {
    let ab = b - a;
    let len = ab.norm_squared();
    let t = if len > 0.0 {
        ((p - a).dot(&ab) / len).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t - p).norm_squared()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Four straight ribs along x from −100 to 100 mm: rib 2 at y = 40, rib 3 at 20,
    /// rib 4 at 0, rib 5 at −20 ([`RIB_SAMPLES`] points each).
    fn skeleton() -> [Vec3; SKELETON_POINTS] {
        let mut out = [Vec3::zeros(); SKELETON_POINTS];
        let mut k = 0;
        for (r, &n) in RIB_SAMPLES.iter().enumerate() {
            for i in 0..n {
                let x = -100.0 + 200.0 * i as f32 / (n - 1) as f32;
                out[k] = Vec3::new(x, 40.0 - 20.0 * r as f32, 0.0);
                k += 1;
            }
        }
        out
    }

    #[test]
    fn a_gap_is_bounded_by_the_ribs_above_and_below_it() {
        let s = skeleton();
        assert_eq!(bounding_ribs(&s, &Vec3::new(50.0, 31.0, 5.0)), [0, 1]);
        assert_eq!(bounding_ribs(&s, &Vec3::new(-70.0, 12.0, -3.0)), [1, 2]);
        assert_eq!(bounding_ribs(&s, &Vec3::new(0.0, -11.0, 0.0)), [3, 2]);
        // Beyond the ribs' ends, the nearest segment ends still decide.
        assert_eq!(bounding_ribs(&s, &Vec3::new(130.0, -8.0, 0.0)), [2, 3]);
    }

    /// A waypoint is reached while it lies within [`MAX_BEYOND_MM`] of both bounding
    /// ribs' observed ends on its side; the shorter rib names the refusal.
    #[test]
    fn a_waypoint_beyond_a_bounding_rib_end_is_not_reached() {
        let s = skeleton();
        // Rib 3 seen on the left only to x = 60, rib 2 to 90; the right to −90.
        let ends = [
            (-90.0, 0.0, 90.0),
            (-90.0, 0.0, 60.0),
            (-90.0, 0.0, 90.0),
            (-90.0, 0.0, 90.0),
        ];
        let planned = Vec3::new(70.0, 30.0, 0.0);
        let inside = WaypointReach::against(&s, &ends, &planned, &Vec3::new(62.5, 31.0, 2.0));
        assert_eq!(
            (inside.ribs, inside.rib, inside.side),
            ([2, 3], 3, Side::Left)
        );
        assert!((inside.beyond_mm - 2.5).abs() < 1e-4 && inside.reached());
        assert_eq!(inside.check(4), Ok(()));
        let out = WaypointReach::against(&s, &ends, &planned, &Vec3::new(70.0, 30.0, 0.0));
        assert!((out.beyond_mm - 10.0).abs() < 1e-4 && !out.reached());
        assert_eq!(
            out.check(4),
            Err(Error::NotReached {
                waypoint: 4,
                rib: 3,
                side: Side::Left,
                beyond_dmm: 100,
                max_beyond_dmm: 30,
            })
        );
        // The same gap on the right is seen far enough.
        let right = WaypointReach::against(&s, &ends, &planned, &Vec3::new(-70.0, 30.0, 0.0));
        assert_eq!(right.side, Side::Right);
        assert!((right.beyond_mm + 20.0).abs() < 1e-4 && right.reached());
        // A partial plan marks every waypoint on the side of an unreached one, and
        // nothing on the other side.
        let medial = |x: f32, y: f32| {
            WaypointReach::against(&s, &ends, &Vec3::new(x, y, 0.0), &Vec3::new(x, y, 0.0))
        };
        let below = medial(30.0, 10.0);
        let lower = medial(30.0, -10.0);
        assert_eq!((below.ribs, lower.ribs), ([3, 4], [4, 5]));
        let plan = [inside, out, right, below, lower];
        let kept: [bool; 5] = core::array::from_fn(|i| plan[i].supported(&plan));
        assert_eq!(kept, [false, false, true, false, false]);
        let whole = [inside, right, below, lower];
        assert!(whole.iter().all(|w| w.supported(&whole)));
        // A plan: refused at its first unreached waypoint, unless partial and something
        // is kept; a partial plan that keeps nothing is refused too.
        let some = [Some(&inside), None, Some(&out), Some(&right)];
        let e = check_plan(some.iter().copied(), false).unwrap_err();
        assert!(matches!(e, Error::NotReached { waypoint: 2, .. }), "{e:?}");
        assert_eq!(check_plan(some.iter().copied(), true), Ok(()));
        let none_kept = [Some(&inside), Some(&out)];
        let e = check_plan(none_kept.iter().copied(), true).unwrap_err();
        assert!(matches!(e, Error::NotReached { waypoint: 1, .. }), "{e:?}");
        assert_eq!(check_plan([None, Some(&right)].into_iter(), false), Ok(()));
    }

    /// A rib end the sweep imaged less than [`MIN_EDGE_CLEARANCE_MM`] past refuses the
    /// registration (the least names it) and, in a partial plan, its side; a rib side
    /// not seen (NaN) is the coverage checks' to refuse.
    #[test]
    fn a_rib_end_at_the_sweep_s_edge_refuses_its_side() {
        let mut c = [[20.0f32; 2]; 4];
        c[1][0] = f32::NAN;
        assert_eq!(check_edges(&c), Ok(()));
        assert_eq!(cut_sides(&c), [false, false]);
        assert_eq!(least_clearance(&c), 20.0);
        assert!(least_clearance(&[[f32::NAN; 2]; 4]).is_nan());
        c[3][1] = 2.9;
        c[2][1] = 0.3;
        assert_eq!(least_clearance(&c), 0.3);
        assert_eq!(
            check_edges(&c),
            Err(Error::SweepEdge {
                rib: 4,
                side: Side::Left,
                clearance_dmm: 3,
                min_dmm: 30,
            })
        );
        assert_eq!(cut_sides(&c), [false, true]);
        c[0][0] = 0.0;
        assert_eq!(cut_sides(&c), [true, true]);
        assert!(matches!(
            check_edges(&c),
            Err(Error::SweepEdge {
                rib: 2,
                side: Side::Right,
                clearance_dmm: 0,
                ..
            })
        ));
    }

    #[test]
    fn a_rib_not_seen_or_a_waypoint_not_finite_is_never_reached() {
        let s = skeleton();
        let mut ends = [(-90.0, 0.0, 90.0); 4];
        ends[2] = (f32::INFINITY, f32::NAN, f32::NEG_INFINITY);
        let planned = Vec3::new(-40.0, 10.0, 0.0);
        let r = WaypointReach::against(&s, &ends, &planned, &Vec3::new(-40.0, 10.0, 0.0));
        assert_eq!(
            (r.rib, r.side, r.beyond_mm),
            (4, Side::Right, f32::INFINITY)
        );
        assert!(!r.reached());
        assert!(matches!(
            r.check(300),
            Err(Error::NotReached {
                waypoint: 255,
                beyond_dmm: u16::MAX,
                ..
            })
        ));
        let ends = [(-90.0, 0.0, 90.0); 4];
        let nan = Vec3::new(f32::NAN, 0.0, 0.0);
        let r = WaypointReach::against(&s, &ends, &planned, &nan);
        assert!(r.beyond_mm.is_nan() && !r.reached());
    }
}
