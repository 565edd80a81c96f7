//! Automatic labels for an unlabelled CT template cloud of the sternum and the costal
//! cartilages of ribs 2..=5 (both sides).
//!
//! Input: points in ribreg's patient frame (mm; **x** toward the patient's left, **y**
//! cranial, **z** anterior), the whole surface of the sternum and of the eight cartilages
//! as one connected cloud (cartilages entering the sternum's lateral faces, as in
//! [`crate::phantom`]). The origin does not matter (CT world coordinates are not centred)
//! and the cloud may be rotated by a few degrees. Output: label 1 = sternum, 2..=5 = the rib
//! whose cartilage the point lies on (the same label on both sides), 0 = unlabelled.
//!
//! # The rule
//! 1. **Spacing.** `s` = median distance of a point to its nearest distinct neighbour;
//!    link distance `L` = [`LINK_FACTOR`] · `s`. "Connected" below always means single
//!    linkage: chains of points less than `L` apart (a hash grid; O(n) per pass).
//! 2. **Midline.** A line `x = a + b·y`; every point gets a signed lateral distance
//!    `d = x − (a + b·y)` (`d > 0` left, `d < 0` right). The first pass uses a vertical
//!    line (`b = 0`) through the median of the x-medians of [`MIDLINE_CHUNKS`] equal-count
//!    chunks of the cloud sorted by y.
//! 3. **Cartilages and sternum edge, per side.** A component is *large* when it holds at
//!    least `m` = max([`MIN_COMPONENT_POINTS`], ⌈[`MIN_COMPONENT_FRACTION`] · n⌉) points.
//!    For a threshold `w`, the side's *lateral* points are those with `|d| ≥ w`; `count(w)`
//!    is the number of large connected components among them. Lowering `w` from +∞ point
//!    by point (no step size: every point's `|d|` is a threshold) the cartilages appear at
//!    their tips and grow toward the sternum; they merge when `w` reaches the sternum's
//!    lateral face. The side's **sternum edge** `e` is the `|d|` of the first point whose
//!    addition makes `count` drop from 4; the four large components just before it are
//!    the side's cartilages. Only `|d| ≥` [`EDGE_RANGE_MM`]`.0` is looked at.
//! 4. **Labels.** A point of a side's cartilage component with `|d| > e + δ`
//!    (`δ` = [`EDGE_BAND_FACTOR`] · `s`) gets that cartilage's rib. Ribs are numbered
//!    2..=5 by *attachment height* (mean y of the cartilage's labelled points with
//!    `|d| ≤ e + δ +` [`ATTACHMENT_BAND_MM`]), highest first, on each side separately.
//!    The *central* points (`|d| ≤ e + δ`, with the `e` of their side) are linked into
//!    components; the largest is the sternum (1). Everything else (small lateral
//!    fragments, other central pieces) is 0.
//! 5. **Refined midline.** The line is refitted to the sternum just found: Theil–Sen
//!    (median pairwise slope, median intercept) through the (median y, mid-range x) of
//!    [`MIDLINE_CHUNKS`] equal-count chunks of the sternum's points sorted by y (the
//!    mid-range sits between the two flat lateral faces). Steps 3–5 are repeated with it
//!    until the line moves less than [`MIDLINE_TOLERANCE_MM`] over the sternum's height,
//!    at most [`MIDLINE_PASSES`] passes in all; the last pass's labels are returned, and a
//!    refusal in any pass is the answer.
//!
//! Points of a cartilage that lie on the sternum side of `e + δ` (where the tube pokes
//! out of the sternum's rounded corners) come out as sternum: on the phantoms that is
//! about 0.5 % of the points (see the tests). Giving points near the edge the label of
//! their nearest clear neighbour was measured and is worse (it pulls the sternum's
//! lateral face into the ribs).
//!
//! # Refusals ([`AutoLabelError`])
//! Never a silent guess: the cloud is refused when it has fewer than [`MIN_POINTS`]
//! points or a non-finite one, when no spacing can be measured, when on a side more than
//! four large components appear before the sternum edge or the count never reaches four
//! ([`AutoLabelError::CartilageCount`]), when four are found but never merge
//! ([`AutoLabelError::SternumEdgeNotFound`]), when the edge lies beyond
//! [`EDGE_RANGE_MM`]`.1` from the midline, when rib `k`'s attachment heights on the two
//! sides differ by more than [`SIDE_AGREEMENT_FRACTION`] of the smallest neighbouring
//! attachment gap ([`AutoLabelError::SidesDisagree`]), when the central points hold no
//! large component ([`AutoLabelError::SternumNotFound`]), or when a cartilage does not
//! come within `L` of the sternum ([`AutoLabelError::CartilageDetached`]).

use std::collections::HashMap;
use std::fmt;
use std::hash::BuildHasherDefault;

use crate::phantom::{Side, RIBS, RIB_COUNT, STERNUM_LABEL};

/// Fewest points accepted.
pub const MIN_POINTS: usize = 100;
/// Link distance of the single linkage, in median nearest-neighbour distances.
pub const LINK_FACTOR: f64 = 2.5;
/// Width of the band beyond the sternum edge that still counts as sternum, in median
/// nearest-neighbour distances (absorbs the scatter of the sternum's lateral face).
pub const EDGE_BAND_FACTOR: f64 = 0.1;
/// A component is large when it holds at least this fraction of the cloud's points ...
pub const MIN_COMPONENT_FRACTION: f64 = 0.01;
/// ... and at least this many points.
pub const MIN_COMPONENT_POINTS: usize = 10;
/// Range of the sternum edge (distance from the midline) searched and accepted, mm.
pub const EDGE_RANGE_MM: (f64, f64) = (5.0, 45.0);
/// Lateral extent of a cartilage's medial end over which its attachment height is taken, mm.
pub const ATTACHMENT_BAND_MM: f64 = 10.0;
/// Chunks of equal point count the midline is fitted through.
pub const MIDLINE_CHUNKS: usize = 32;
/// Largest left/right difference of a rib's attachment height, as a fraction of the
/// smallest gap between that rib's attachment and its neighbours'.
pub const SIDE_AGREEMENT_FRACTION: f64 = 0.5;
/// Most passes of the rule (the first with a vertical midline, each further one with the
/// midline refitted to the sternum found by the previous).
pub const MIDLINE_PASSES: usize = 10;
/// Passes stop when the refitted midline moves less than this over the sternum's height, mm.
pub const MIDLINE_TOLERANCE_MM: f64 = 0.05;
/// Cartilages expected per side.
pub const EXPECTED_CARTILAGES: usize = RIB_COUNT;

/// Why a cloud could not be labelled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AutoLabelError {
    /// Fewer than [`MIN_POINTS`] points.
    TooFewPoints {
        /// Points given.
        found: usize,
        /// Points required.
        min: usize,
    },
    /// A coordinate is NaN or infinite.
    NonFinite {
        /// Index of the first such point.
        index: usize,
    },
    /// No nearest-neighbour spacing could be measured (all points coincide).
    NoSpacing,
    /// A side does not show exactly [`EXPECTED_CARTILAGES`] cartilages before the sternum.
    CartilageCount {
        /// The side.
        side: Side,
        /// Largest number of large components seen on that side (before the sternum edge).
        found: usize,
    },
    /// A side shows four cartilages that never join through a sternum.
    SternumEdgeNotFound {
        /// The side.
        side: Side,
    },
    /// The sternum edge found lies implausibly far from the midline.
    EdgeOutOfRange {
        /// The side.
        side: Side,
        /// Distance of the edge from the midline, mm.
        edge_mm: f64,
    },
    /// A rib's cartilages on the two sides attach at grossly different heights.
    SidesDisagree {
        /// Rib number (2..=5) by rank on each side.
        rib: u8,
        /// Attachment height on the left, mm.
        left_mm: f64,
        /// Attachment height on the right, mm.
        right_mm: f64,
    },
    /// The central points hold no large component.
    SternumNotFound,
    /// A cartilage does not touch the sternum.
    CartilageDetached {
        /// The side.
        side: Side,
        /// Rib number.
        rib: u8,
    },
}

fn side_name(side: Side) -> &'static str {
    match side {
        Side::Left => "left",
        Side::Right => "right",
    }
}

impl fmt::Display for AutoLabelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooFewPoints { found, min } => {
                write!(f, "too few points to label: {found} (need {min})")
            }
            Self::NonFinite { index } => write!(f, "point {index} is not finite"),
            Self::NoSpacing => write!(f, "no point spacing measurable (points coincide)"),
            Self::CartilageCount { side, found } => write!(
                f,
                "{} side: found {found} cartilages, expected {EXPECTED_CARTILAGES}",
                side_name(side)
            ),
            Self::SternumEdgeNotFound { side } => write!(
                f,
                "{} side: four cartilages found but no sternum joining them",
                side_name(side)
            ),
            Self::EdgeOutOfRange { side, edge_mm } => write!(
                f,
                "{} side: sternum edge {edge_mm:.1} mm from the midline (accepted up to {:.0} mm)",
                side_name(side),
                EDGE_RANGE_MM.1
            ),
            Self::SidesDisagree {
                rib,
                left_mm,
                right_mm,
            } => write!(
                f,
                "rib {rib}: left and right attach at different heights \
                 ({left_mm:.1} vs {right_mm:.1} mm)"
            ),
            Self::SternumNotFound => write!(f, "no sternum found between the cartilages"),
            Self::CartilageDetached { side, rib } => write!(
                f,
                "{} side: cartilage of rib {rib} does not touch the sternum",
                side_name(side)
            ),
        }
    }
}

impl std::error::Error for AutoLabelError {}

/// Labels found by [`auto_labels`] and a summary of what was found.
#[derive(Clone, Debug, PartialEq)]
pub struct AutoLabels {
    /// Label per input point: 1 sternum, 2..=5 rib, 0 none.
    pub labels: Vec<i32>,
    /// Points per label 0..=5 (index = label).
    pub counts: [usize; 6],
    /// Midline x at the sternum's median height [`AutoLabels::midline_y_mm`], mm.
    pub midline_x_mm: f64,
    /// The height at which [`AutoLabels::midline_x_mm`] is given (median y of the sternum), mm.
    pub midline_y_mm: f64,
    /// Tilt of the midline in the x–y plane (positive: x grows cranially), degrees.
    pub midline_tilt_deg: f64,
    /// Sternum edge on [left, right]: distance of the lateral face from the midline, mm.
    pub sternum_edges_mm: [f64; 2],
    /// Attachment height of ribs 2..=5 on [left, right], mm.
    pub rib_heights_mm: [[f64; RIB_COUNT]; 2],
    /// Median nearest-neighbour distance `s`, mm.
    pub spacing_mm: f64,
    /// Link distance `L`, mm.
    pub link_mm: f64,
}

impl AutoLabels {
    /// Sternum half-width found: the mean of the two edges, mm.
    pub fn sternum_half_width_mm(&self) -> f64 {
        0.5 * (self.sternum_edges_mm[0] + self.sternum_edges_mm[1])
    }
}

impl fmt::Display for AutoLabels {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.counts;
        write!(
            f,
            "auto labels: sternum {}, ribs 2/3/4/5 {}/{}/{}/{}, unlabelled {}; midline x {:.1} mm \
             at y {:.1} (tilt {:.1}°), sternum half-width {:.1} mm (left {:.1}, right {:.1}), \
             spacing {:.2} mm, link {:.2} mm",
            c[1],
            c[2],
            c[3],
            c[4],
            c[5],
            c[0],
            self.midline_x_mm,
            self.midline_y_mm,
            self.midline_tilt_deg,
            self.sternum_half_width_mm(),
            self.sternum_edges_mm[0],
            self.sternum_edges_mm[1],
            self.spacing_mm,
            self.link_mm
        )
    }
}

/// Labels (1 sternum, 2..=5 rib, 0 none) for a cloud in the patient frame, by the rule of
/// the module docs; a typed refusal when the cloud does not show that anatomy unambiguously.
pub fn auto_labels(points: &[[f64; 3]]) -> Result<AutoLabels, AutoLabelError> {
    auto_labels_with(points, EDGE_BAND_FACTOR, MIDLINE_PASSES)
}

/// [`auto_labels`] with the edge band and the number of passes adjustable (for measurements).
pub(crate) fn auto_labels_with(
    points: &[[f64; 3]],
    band_factor: f64,
    passes: usize,
) -> Result<AutoLabels, AutoLabelError> {
    let n = points.len();
    if n < MIN_POINTS {
        return Err(AutoLabelError::TooFewPoints {
            found: n,
            min: MIN_POINTS,
        });
    }
    if let Some(index) = points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(AutoLabelError::NonFinite { index });
    }
    let spacing = median_spacing(points).ok_or(AutoLabelError::NoSpacing)?;
    let link = LINK_FACTOR * spacing;
    let min_size = MIN_COMPONENT_POINTS.max((MIN_COMPONENT_FRACTION * n as f64).ceil() as usize);
    let ctx = Ctx {
        points,
        link,
        band: band_factor * spacing,
        min_size,
    };
    let all: Vec<u32> = (0..n as u32).collect();
    let mut line = (midline_knots(points, &all, Knot::Median).1, 0.0);
    let mut found = ctx.pass(line)?;
    for _ in 1..passes {
        let next = theil_sen(&midline_knots(points, &found.sternum, Knot::Midrange).0);
        let span = found
            .sternum
            .iter()
            .map(|&i| points[i as usize][1])
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
                (lo.min(y), hi.max(y))
            });
        let shift = [span.0, span.1]
            .iter()
            .map(|y| ((next.0 + next.1 * y) - (line.0 + line.1 * y)).abs())
            .fold(0.0, f64::max);
        if shift < MIDLINE_TOLERANCE_MM {
            break;
        }
        line = next;
        found = ctx.pass(line)?;
    }
    let mut labels = found.labels;
    let mut counts = [0usize; 6];
    for l in &mut labels {
        counts[*l as usize] += 1;
    }
    let mut ys: Vec<f64> = found
        .sternum
        .iter()
        .map(|&i| points[i as usize][1])
        .collect();
    let midline_y_mm = median(&mut ys);
    Ok(AutoLabels {
        labels,
        counts,
        midline_x_mm: line.0 + line.1 * midline_y_mm,
        midline_y_mm,
        midline_tilt_deg: line.1.atan().to_degrees(),
        sternum_edges_mm: found.edges,
        rib_heights_mm: found.heights,
        spacing_mm: spacing,
        link_mm: link,
    })
}

// ---------------------------------------------------------------------------------------
// One pass of the rule for a given midline
// ---------------------------------------------------------------------------------------

struct Ctx<'a> {
    points: &'a [[f64; 3]],
    link: f64,
    band: f64,
    min_size: usize,
}

struct Pass {
    labels: Vec<i32>,
    sternum: Vec<u32>,
    edges: [f64; 2],
    heights: [[f64; RIB_COUNT]; 2],
}

impl Ctx<'_> {
    fn pass(&self, line: (f64, f64)) -> Result<Pass, AutoLabelError> {
        let pts = self.points;
        let n = pts.len();
        let d: Vec<f64> = pts
            .iter()
            .map(|p| p[0] - (line.0 + line.1 * p[1]))
            .collect();
        let mut labels = vec![0i32; n];
        let mut edges = [0.0; 2];
        let mut heights = [[0.0; RIB_COUNT]; 2];
        let mut ribs: [Vec<Vec<u32>>; 2] = [Vec::new(), Vec::new()];
        for side in Side::BOTH {
            let s = side.index();
            let sd: Vec<f64> = d.iter().map(|v| v * side.sign()).collect();
            let (edge, comps) = self.sweep_side(&sd, side)?;
            edges[s] = edge;
            let limit = edge + self.band;
            // Attachment heights, then ranks (highest first).
            let mut ranked: Vec<(f64, Vec<u32>)> = comps
                .into_iter()
                .map(|c| {
                    let kept: Vec<u32> =
                        c.into_iter().filter(|&i| sd[i as usize] > limit).collect();
                    let near: Vec<f64> = kept
                        .iter()
                        .filter(|&&i| sd[i as usize] <= limit + ATTACHMENT_BAND_MM)
                        .map(|&i| pts[i as usize][1])
                        .collect();
                    let h = if near.is_empty() {
                        f64::NAN
                    } else {
                        near.iter().sum::<f64>() / near.len() as f64
                    };
                    (h, kept)
                })
                .collect();
            if ranked.iter().any(|(h, _)| !h.is_finite()) {
                return Err(AutoLabelError::SternumEdgeNotFound { side });
            }
            ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
            for (k, (h, comp)) in ranked.into_iter().enumerate() {
                heights[s][k] = h;
                for &i in &comp {
                    labels[i as usize] = i32::from(RIBS[k]);
                }
                ribs[s].push(comp);
            }
        }
        // Left and right must agree rib by rib.
        for k in 0..RIB_COUNT {
            let mut gap = f64::INFINITY;
            for h in &heights {
                if k > 0 {
                    gap = gap.min(h[k - 1] - h[k]);
                }
                if k + 1 < RIB_COUNT {
                    gap = gap.min(h[k] - h[k + 1]);
                }
            }
            let (l, r) = (heights[0][k], heights[1][k]);
            if (l - r).abs() > SIDE_AGREEMENT_FRACTION * gap {
                return Err(AutoLabelError::SidesDisagree {
                    rib: RIBS[k],
                    left_mm: l,
                    right_mm: r,
                });
            }
        }
        let edge_of = |i: usize| if d[i] >= 0.0 { edges[0] } else { edges[1] };
        let l2 = self.link * self.link;
        // Central points: the largest connected piece is the sternum.
        let central: Vec<u32> = (0..n as u32)
            .filter(|&i| {
                let i = i as usize;
                labels[i] == 0 && d[i].abs() <= edge_of(i) + self.band
            })
            .collect();
        let grid = Grid::new(pts, &central, self.link);
        let mut uf = UnionFind::new(n);
        for &i in &central {
            grid.for_near(pts[i as usize], |j| {
                if j < i && dist2(pts[i as usize], pts[j as usize]) <= l2 {
                    uf.union(i, j);
                }
            });
        }
        let mut sizes: HashMap<u32, usize> = HashMap::new();
        for &i in &central {
            *sizes.entry(uf.find(i)).or_default() += 1;
        }
        let best = sizes
            .iter()
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
            .filter(|(_, &c)| c >= self.min_size)
            .map(|(&r, _)| r)
            .ok_or(AutoLabelError::SternumNotFound)?;
        let sternum: Vec<u32> = central
            .iter()
            .copied()
            .filter(|&i| uf.find(i) == best)
            .collect();
        for &i in &sternum {
            labels[i as usize] = STERNUM_LABEL;
        }
        // Every cartilage must touch the sternum.
        let sgrid = Grid::new(pts, &sternum, self.link);
        for side in Side::BOTH {
            for (k, comp) in ribs[side.index()].iter().enumerate() {
                let touches = comp.iter().any(|&i| {
                    let mut hit = false;
                    sgrid.for_near(pts[i as usize], |j| {
                        hit |= dist2(pts[i as usize], pts[j as usize]) <= l2;
                    });
                    hit
                });
                if !touches {
                    return Err(AutoLabelError::CartilageDetached { side, rib: RIBS[k] });
                }
            }
        }
        Ok(Pass {
            labels,
            sternum,
            edges,
            heights,
        })
    }

    /// Step 3 of the rule on one side (`sd` = lateral distance, positive on that side):
    /// the sternum edge and the four cartilage components just before it.
    fn sweep_side(&self, sd: &[f64], side: Side) -> Result<(f64, Vec<Vec<u32>>), AutoLabelError> {
        let pts = self.points;
        let mut order: Vec<u32> = (0..pts.len() as u32)
            .filter(|&i| sd[i as usize] >= EDGE_RANGE_MM.0)
            .collect();
        order.sort_by(|&a, &b| sd[b as usize].total_cmp(&sd[a as usize]).then(a.cmp(&b)));
        let grid = Grid::new(pts, &order, self.link);
        let l2 = self.link * self.link;
        let m = self.min_size;
        let grow = |stop: Option<usize>| {
            let mut uf = UnionFind::new(pts.len());
            let mut added = vec![false; pts.len()];
            let mut count = 0usize;
            let mut max_count = 0usize;
            let mut edge_at = None;
            for (k, &i) in order.iter().enumerate() {
                if Some(k) == stop {
                    break;
                }
                let before = count;
                added[i as usize] = true;
                grid.for_near(pts[i as usize], |j| {
                    if added[j as usize] && j != i && dist2(pts[i as usize], pts[j as usize]) <= l2
                    {
                        let (ra, rb) = (uf.find(i), uf.find(j));
                        if ra != rb {
                            let big_before = usize::from(uf.size[ra as usize] as usize >= m)
                                + usize::from(uf.size[rb as usize] as usize >= m);
                            let r = uf.union(ra, rb);
                            count =
                                count + usize::from(uf.size[r as usize] as usize >= m) - big_before;
                        }
                    }
                });
                if before == EXPECTED_CARTILAGES && count < EXPECTED_CARTILAGES {
                    // The edge: nothing after it is needed.
                    edge_at = Some(k);
                    break;
                }
                max_count = max_count.max(count);
            }
            (uf, edge_at, max_count)
        };
        let (_, edge_at, max_count) = grow(None);
        let Some(k) = edge_at else {
            return Err(if max_count == EXPECTED_CARTILAGES {
                AutoLabelError::SternumEdgeNotFound { side }
            } else {
                AutoLabelError::CartilageCount {
                    side,
                    found: max_count,
                }
            });
        };
        if max_count > EXPECTED_CARTILAGES {
            return Err(AutoLabelError::CartilageCount {
                side,
                found: max_count,
            });
        }
        let edge = sd[order[k] as usize];
        if edge > EDGE_RANGE_MM.1 {
            return Err(AutoLabelError::EdgeOutOfRange {
                side,
                edge_mm: edge,
            });
        }
        // Rebuild the state just before the merge and collect the four large components.
        let (mut uf, _, _) = grow(Some(k));
        let mut comps: HashMap<u32, Vec<u32>> = HashMap::new();
        for &i in &order[..k] {
            let r = uf.find(i);
            if uf.size[r as usize] as usize >= m {
                comps.entry(r).or_default().push(i);
            }
        }
        let mut comps: Vec<Vec<u32>> = comps.into_values().collect();
        comps.sort_by_key(|c| c[0]);
        Ok((edge, comps))
    }
}

// ---------------------------------------------------------------------------------------
// Midline, spacing, grid, union-find
// ---------------------------------------------------------------------------------------

fn dist2(a: [f64; 3], b: [f64; 3]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// Median of a non-empty slice (reorders it); NaN when empty.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    *m
}

/// How a chunk of points is summarised by one x.
#[derive(Clone, Copy)]
enum Knot {
    /// The median x (robust; for the whole cloud).
    Median,
    /// The mean of the smallest and largest x (precise on the sternum's flat lateral faces).
    Midrange,
}

/// The (median y, summary x) of [`MIDLINE_CHUNKS`] equal-count chunks of `subset` sorted
/// by y, and the median of the chunks' x.
fn midline_knots(points: &[[f64; 3]], subset: &[u32], knot: Knot) -> (Vec<(f64, f64)>, f64) {
    let mut idx = subset.to_vec();
    idx.sort_by(|&a, &b| points[a as usize][1].total_cmp(&points[b as usize][1]));
    let chunks = MIDLINE_CHUNKS.min(idx.len()).max(1);
    let mut knots = Vec::with_capacity(chunks);
    for c in 0..chunks {
        let part = &idx[c * idx.len() / chunks..(c + 1) * idx.len() / chunks];
        if part.is_empty() {
            continue;
        }
        let mut ys: Vec<f64> = part.iter().map(|&i| points[i as usize][1]).collect();
        let mut xs: Vec<f64> = part.iter().map(|&i| points[i as usize][0]).collect();
        let x = match knot {
            Knot::Median => median(&mut xs),
            Knot::Midrange => {
                let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                0.5 * (lo + hi)
            }
        };
        knots.push((median(&mut ys), x));
    }
    let mut xs: Vec<f64> = knots.iter().map(|k| k.1).collect();
    let mid = median(&mut xs);
    (knots, if mid.is_finite() { mid } else { 0.0 })
}

/// Theil–Sen line `x = a + b·y` through `knots` (y, x): `b` the median pairwise slope, `a`
/// the median intercept. Returns `(a, b)`.
fn theil_sen(knots: &[(f64, f64)]) -> (f64, f64) {
    let mut slopes = Vec::new();
    for (i, a) in knots.iter().enumerate() {
        for b in &knots[i + 1..] {
            if (b.0 - a.0).abs() > 1e-9 {
                slopes.push((b.1 - a.1) / (b.0 - a.0));
            }
        }
    }
    let b = if slopes.is_empty() {
        0.0
    } else {
        median(&mut slopes)
    };
    let mut icepts: Vec<f64> = knots.iter().map(|k| k.1 - b * k.0).collect();
    let a = median(&mut icepts);
    (if a.is_finite() { a } else { 0.0 }, b)
}

/// Median distance of a point to its nearest distinct neighbour; `None` when no point has one.
fn median_spacing(points: &[[f64; 3]]) -> Option<f64> {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let mut ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    ext.sort_by(f64::total_cmp);
    if ext[2] <= 0.0 || !ext[2].is_finite() {
        return None;
    }
    // A surface-sized first guess, doubled until most points find a neighbour within it.
    let mut cell = (ext[2] * ext[1].max(ext[2] * 1e-3) / points.len() as f64).sqrt();
    let all: Vec<u32> = (0..points.len() as u32).collect();
    for _ in 0..40 {
        let grid = Grid::new(points, &all, cell);
        let c2 = cell * cell;
        let mut nn: Vec<f64> = points
            .iter()
            .map(|&p| {
                let mut best = f64::INFINITY;
                grid.for_near(p, |j| {
                    let d = dist2(p, points[j as usize]);
                    if d > 0.0 && d < best {
                        best = d;
                    }
                });
                if best <= c2 {
                    best.sqrt()
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        let m = median(&mut nn);
        if m.is_finite() {
            return Some(m);
        }
        cell *= 2.0;
    }
    None
}

/// Hasher of the grid's packed cell keys (splitmix64; much cheaper than the default SipHash).
#[derive(Default)]
struct CellHasher(u64);

impl std::hash::Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u64(&mut self, v: u64) {
        // splitmix64's finaliser: every input bit reaches the low and the high bits.
        let mut z = (self.0 ^ v).wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        self.0 = z ^ (z >> 31);
    }
}

/// Bits per axis of a packed cell key.
const KEY_BITS: u32 = 21;

/// A uniform hash grid over a subset of points. Cell indices are packed into one `u64`
/// modulo 2^21 per axis: far cells may share a key, which only adds candidates (every
/// caller checks distances).
struct Grid {
    cell: f64,
    order: Vec<u32>,
    ranges: HashMap<u64, (u32, u32), BuildHasherDefault<CellHasher>>,
}

impl Grid {
    fn cell_of(p: [f64; 3], cell: f64) -> [i64; 3] {
        [
            (p[0] / cell).floor() as i64,
            (p[1] / cell).floor() as i64,
            (p[2] / cell).floor() as i64,
        ]
    }

    fn pack(c: [i64; 3]) -> u64 {
        let m = (1u64 << KEY_BITS) - 1;
        ((c[0] as u64 & m) << (2 * KEY_BITS)) | ((c[1] as u64 & m) << KEY_BITS) | (c[2] as u64 & m)
    }

    fn key(p: [f64; 3], cell: f64) -> u64 {
        Self::pack(Self::cell_of(p, cell))
    }

    fn new(points: &[[f64; 3]], subset: &[u32], cell: f64) -> Self {
        let mut keyed: Vec<(u64, u32)> = subset
            .iter()
            .map(|&i| (Self::key(points[i as usize], cell), i))
            .collect();
        keyed.sort_unstable();
        let mut ranges = HashMap::with_capacity_and_hasher(keyed.len() / 2 + 1, Default::default());
        let mut start = 0usize;
        for k in 1..=keyed.len() {
            if k == keyed.len() || keyed[k].0 != keyed[start].0 {
                ranges.insert(keyed[start].0, (start as u32, k as u32));
                start = k;
            }
        }
        Self {
            cell,
            order: keyed.into_iter().map(|(_, i)| i).collect(),
            ranges,
        }
    }

    /// Calls `f` with every point of the 27 cells around `p` (all points within `cell`
    /// of `p`, and some farther).
    fn for_near(&self, p: [f64; 3], mut f: impl FnMut(u32)) {
        let k = Self::cell_of(p, self.cell);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let key = Self::pack([
                        k[0].wrapping_add(dx),
                        k[1].wrapping_add(dy),
                        k[2].wrapping_add(dz),
                    ]);
                    if let Some(&(a, b)) = self.ranges.get(&key) {
                        for &j in &self.order[a as usize..b as usize] {
                            f(j);
                        }
                    }
                }
            }
        }
    }
}

struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }

    fn find(&mut self, mut i: u32) -> u32 {
        while self.parent[i as usize] != i {
            let g = self.parent[self.parent[i as usize] as usize];
            self.parent[i as usize] = g;
            i = g;
        }
        i
    }

    /// Joins the sets of `a` and `b`; returns the new root.
    fn union(&mut self, a: u32, b: u32) -> u32 {
        let (mut ra, mut rb) = (self.find(a), self.find(b));
        if ra == rb {
            return ra;
        }
        if self.size[ra as usize] < self.size[rb as usize] {
            std::mem::swap(&mut ra, &mut rb);
        }
        self.parent[rb as usize] = ra;
        self.size[ra as usize] += self.size[rb as usize];
        ra
    }
}

#[cfg(test)]
mod tests;
