//! Where a sweep imaged, so that a rib end the cloud shows can be told from one the sweep
//! cut.
//!
//! A cloud alone cannot tell a cartilage that ends from one the sweep stopped short of:
//! both end where the points end. The probe's track can. Every tracked flange pose
//! ([`crate::acquisition::compound::Compounder::add_pose`]) places its image — a frame
//! with no bone pixels images empty tissue, which is evidence too, and such frames are
//! often not even logged — and a point counts as imaged when it lies in the region the
//! images swept.
//!
//! # Lines
//! A sweep moves the probe along its image plane's normal, line after line (serpentine:
//! across the chest, a step to the next line, back). The images are followed as they
//! come: each time the image's centre has moved [`STEP_MM`] it is classed as moving
//! along its normal (forward or back: within 45°) or sideways. A run of moves in one
//! direction is a line; a sideways move or a reversal ends it. A line keeps its first
//! and its last image, and the region it swept is taken as the points
//! * ahead of its first image's plane and behind its last's (in 3-D, each end plane as
//!   the probe stood there, tilted with the skin), and
//! * within half the image's width of the chord between the two images' centres,
//!   measured along their mean width axis.
//!
//! The end planes place a line's end exactly, at any depth: that is what tells a cut
//! rib end. (One map for the whole sweep, projected along one beam, cannot: on a curved
//! chest the beam turns 30–40° between the middle and the sides, and the deep part of a
//! tilted image would cover points it never imaged.) The width is what a straight line
//! sweeps; depth is not bounded (a line along a curved chest bows below its chord; the
//! cartilage lies within the image's depth wherever the probe stood). Holes inside a
//! line's region (lost frames) are not kept — the cloud shows them. A sweep that is not
//! made of lines (freehand circles, a probe turned about its beam while moving) gives
//! few lines and little imaged region: refusals, never a false "imaged".
//!
//! `LINES` lines are kept (const generic, 48 B each,
//! [`crate::limits::IMAGED_LINES`] in the compounding); lines beyond are counted
//! ([`ImagedArea::dropped`]) and their region is not imaged. Constant work per pose,
//! nothing allocated; [`ImagedArea::reach`] costs a few hundred instructions per line.

use crate::acquisition::probe::ProbeModel;
use crate::error::{Error, Result};
#[cfg(test)]
use crate::limits::IMAGED_LINES;
use crate::math::geom::Rigid;
use crate::Vec3;

/// Distance the image's centre moves between two classings of the motion, mm: well
/// above the tracker's noise (0.05 mm) and a 100 Hz pose's step (0.2 mm at 20 mm/s).
pub const STEP_MM: f32 = 2.0;
/// Least cosine between a move and the image normal for it to count as along the line
/// (45°).
const ALONG: f32 = core::f32::consts::FRAC_1_SQRT_2;
/// Shortest line kept, mm (a sideways step's jitter is no line).
const MIN_LINE_MM: f32 = 3.0;
/// A unit vector's components in `i16`: 1/32767 (a point 1 m away is placed to 0.03 mm).
const UNIT: f32 = 32_767.0;

/// One end of a line as [`ImagedArea::lines`] gives it and [`ImagedArea::push_line`]
/// takes it (robot base frame): the image's centre, its unit width axis and its unit
/// normal along the line's motion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineEnd {
    /// The image's centre, mm.
    pub centre: Vec3,
    /// Unit axis along the image's width.
    pub across: Vec3,
    /// Unit normal of the image plane, along the line's motion.
    pub normal: Vec3,
}

/// One image as a line keeps it: its centre (robot base) and unit width axis and
/// normal, the normal along the line's motion.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Image {
    centre: Vec3,
    across: [i16; 3],
    normal: [i16; 3],
}

fn pack(v: &Vec3) -> [i16; 3] {
    // `as` saturates; a unit vector's components are within ±1.
    [
        (v.x * UNIT) as i16,
        (v.y * UNIT) as i16,
        (v.z * UNIT) as i16,
    ]
}

fn unpack(v: &[i16; 3]) -> Vec3 {
    Vec3::new(f32::from(v[0]), f32::from(v[1]), f32::from(v[2])) / UNIT
}

impl Image {
    /// The image of `probe` placed by `b_t_us`.
    fn of(b_t_us: &Rigid, probe: &ProbeModel) -> Image {
        let centre = b_t_us.apply(&Vec3::new(
            0.5 * probe.footprint_mm,
            0.5 * probe.depth_mm,
            0.0,
        ));
        let across: Vec3 = b_t_us.rotation.column(0).into();
        let normal: Vec3 = b_t_us.rotation.column(2).into();
        Image {
            centre,
            across: pack(&across),
            normal: pack(&normal),
        }
    }

    /// The same image, its normal turned by `sign`.
    fn turned(&self, sign: f32) -> Image {
        Image {
            normal: pack(&(unpack(&self.normal) * sign)),
            ..*self
        }
    }

    fn end(&self) -> LineEnd {
        LineEnd {
            centre: self.centre,
            across: unpack(&self.across),
            normal: unpack(&self.normal),
        }
    }
}

/// A line of the sweep: its first and last image, normals along the motion.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Line {
    first: Image,
    last: Image,
}

impl Line {
    /// The interval of `s` over which `from + s·u` lies in the line's region (module
    /// docs), empty when its low end is above its high end.
    fn span(&self, from: &Vec3, u: &Vec3, half_width: f32) -> (f32, f32) {
        let (c0, c1) = (self.first.centre, self.last.centre);
        let (m0, m1) = (unpack(&self.first.normal), unpack(&self.last.normal));
        let across = (unpack(&self.first.across) + unpack(&self.last.across))
            .try_normalize(1e-6)
            .unwrap_or_else(|| unpack(&self.first.across));
        // The offset across the chord, linear in the point: across · (p − c0) less the
        // chord's own drift across at the point's fraction along it.
        let chord = c1 - c0;
        let length = chord.norm();
        let g = if length > 1e-3 {
            across - chord * (chord.dot(&across) / (length * length))
        } else {
            across
        };
        let (p0, p1) = (from - c0, from - c1);
        let mut span = (f32::NEG_INFINITY, f32::INFINITY);
        // Each constraint α + β·s ≤ γ.
        for (alpha, beta, gamma) in [
            (-p0.dot(&m0), -u.dot(&m0), 0.0),
            (p1.dot(&m1), u.dot(&m1), 0.0),
            (p0.dot(&g), u.dot(&g), half_width),
            (-p0.dot(&g), -u.dot(&g), half_width),
        ] {
            clip(&mut span, alpha, beta, gamma);
        }
        span
    }
}

/// Narrows `span` to where `alpha + beta·s ≤ gamma`.
fn clip(span: &mut (f32, f32), alpha: f32, beta: f32, gamma: f32) {
    let slack = gamma - alpha;
    if beta > 0.0 {
        span.1 = span.1.min(slack / beta);
    } else if beta < 0.0 {
        span.0 = span.0.max(slack / beta);
    } else if slack.is_nan() || slack < 0.0 {
        *span = (f32::INFINITY, f32::NEG_INFINITY);
    }
}

/// The region a sweep imaged (module docs), up to `LINES` lines.
#[derive(Clone, Debug, PartialEq)]
pub struct ImagedArea<const LINES: usize> {
    lines: heapless::Vec<Line, LINES>,
    /// The line being swept.
    open: Option<Line>,
    /// The image at the last classed move.
    anchor: Option<Image>,
    half_width: f32,
    /// Poses placed.
    pub poses: u32,
    /// Lines not kept: the area was full.
    pub dropped: u32,
}

impl<const LINES: usize> Default for ImagedArea<LINES> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const LINES: usize> ImagedArea<LINES> {
    /// Nothing imaged yet.
    pub const fn new() -> Self {
        ImagedArea {
            lines: heapless::Vec::new(),
            open: None,
            anchor: None,
            half_width: 0.0,
            poses: 0,
            dropped: 0,
        }
    }

    /// Forgets everything placed.
    pub fn clear(&mut self) {
        *self = Self::new();
    }

    /// Whether nothing was placed.
    pub fn is_empty(&self) -> bool {
        self.poses == 0 && self.lines.is_empty()
    }

    /// Lines found so far (the one being swept among them).
    pub fn line_count(&self) -> usize {
        self.lines.len() + usize::from(self.open.is_some())
    }

    /// The lines found so far, first and last image (the one being swept last).
    pub fn lines(&self) -> impl Iterator<Item = [LineEnd; 2]> + '_ {
        self.all_lines().map(|l| [l.first.end(), l.last.end()])
    }

    /// The images' width, mm (0 before the first pose).
    pub fn width_mm(&self) -> f32 {
        2.0 * self.half_width
    }

    /// Places the image of `probe` at `b_t_us` (image → robot base), the next pose of
    /// the sweep. A pose that is not finite is ignored.
    pub fn place(&mut self, b_t_us: &Rigid, probe: &ProbeModel) {
        let finite = b_t_us.rotation.iter().all(|v| v.is_finite())
            && b_t_us.translation.iter().all(|v| v.is_finite());
        if !finite {
            return;
        }
        self.poses = self.poses.saturating_add(1);
        self.half_width = 0.5 * probe.footprint_mm;
        let image = Image::of(b_t_us, probe);
        let Some(anchor) = self.anchor else {
            self.anchor = Some(image);
            return;
        };
        let moved = image.centre - anchor.centre;
        let distance = moved.norm();
        if distance < STEP_MM {
            // Between classings an open line still follows the probe forward.
            if let Some(line) = &mut self.open {
                let m = unpack(&line.last.normal);
                if (image.centre - line.last.centre).dot(&m) > 0.0 {
                    line.last = image.turned(m.dot(&unpack(&image.normal)).signum());
                }
            }
            return;
        }
        let along = moved.dot(&unpack(&image.normal));
        let sign = if along >= ALONG * distance {
            1.0
        } else if along <= -ALONG * distance {
            -1.0
        } else {
            0.0
        };
        let onward = self
            .open
            .is_some_and(|l| moved.dot(&unpack(&l.last.normal)) >= ALONG * distance);
        match &mut self.open {
            Some(line) if onward => line.last = image.turned(sign),
            _ => {
                self.close();
                if sign != 0.0 {
                    self.open = Some(Line {
                        first: anchor.turned(sign),
                        last: image.turned(sign),
                    });
                }
            }
        }
        self.anchor = Some(image);
    }

    /// Keeps the open line if it is long enough (counted as dropped when full).
    fn close(&mut self) {
        if let Some(line) = self.open.take() {
            if (line.last.centre - line.first.centre).norm() >= MIN_LINE_MM
                && self.lines.push(line).is_err()
            {
                self.dropped = self.dropped.saturating_add(1);
            }
        }
    }

    /// Adds a line swept elsewhere (as [`ImagedArea::lines`] gave it) by a probe whose
    /// image is `width_mm` wide: the host reads a sweep's lines back from a file.
    /// Refused: axes that are not unit vectors (within 1 %), a normal that points from
    /// the last image to the first, input not finite, or a width not positive or not
    /// the lines' before ([`Error::Config`]); a full area ([`Error::Capacity`]).
    pub fn push_line(&mut self, ends: [LineEnd; 2], width_mm: f32) -> Result<()> {
        let unit = |v: &Vec3| (v.norm() - 1.0).abs() <= 0.01;
        let ok = ends.iter().all(|e| {
            e.centre
                .iter()
                .all(|v| v.is_finite() && v.abs() <= crate::limits::MAX_COORD_MM)
                && unit(&e.across)
                && unit(&e.normal)
        });
        let forward = (ends[1].centre - ends[0].centre).dot(&ends[0].normal);
        if !ok || forward.is_nan() || forward < 0.0 {
            return Err(Error::Config(
                "a sweep line needs finite centres, unit axes and its normal along its motion",
            ));
        }
        let half = 0.5 * width_mm;
        let same = self.line_count() == 0 || self.half_width == half;
        if !(width_mm > 0.0 && width_mm <= 1000.0 && same) {
            return Err(Error::Config(
                "a sweep line's image width must be positive and the same for every line",
            ));
        }
        let image = |e: &LineEnd| Image {
            centre: e.centre,
            across: pack(&e.across.normalize()),
            normal: pack(&e.normal.normalize()),
        };
        let line = Line {
            first: image(&ends[0]),
            last: image(&ends[1]),
        };
        self.lines.push(line).map_err(|_| Error::Capacity {
            capacity: LINES as u32,
        })?;
        self.half_width = half;
        Ok(())
    }

    /// Whether `p` (robot base frame) lies in the imaged region.
    pub fn contains(&self, p: &Vec3) -> bool {
        let up = Vec3::new(0.0, 0.0, 1.0);
        self.all_lines().any(|l| {
            let (lo, hi) = l.span(p, &up, self.half_width);
            lo <= 0.0 && 0.0 <= hi
        })
    }

    /// How far from `from` along `direction` (robot base frame; normalised here) the
    /// imaged region reaches without a break, mm, up to `max_mm`: 0 when `from` itself
    /// is not imaged, NaN for a direction of no length or input not finite.
    pub fn reach(&self, from: &Vec3, direction: &Vec3, max_mm: f32) -> f32 {
        let n = direction.norm();
        if !(n > 0.0 && n.is_finite() && max_mm >= 0.0 && from.iter().all(|v| v.is_finite())) {
            return f32::NAN;
        }
        let u = direction / n;
        // Each line's span along the ray (empty ones left out), sorted by where it
        // starts (insertion sort: at most LINES²/2 moves, no allocation); then one pass
        // joins those that start within the run so far.
        let mut spans = [(0.0f32, 0.0f32); LINES];
        let mut count = 0;
        let open = self.open.map(|l| l.span(from, &u, self.half_width));
        for (lo, hi) in self
            .lines
            .iter()
            .map(|l| l.span(from, &u, self.half_width))
            .chain(open)
        {
            // NaN fails `lo <= hi`. With LINES lines kept, the one being swept is left
            // out (not imaged, as lines beyond LINES are).
            if lo <= hi && count < LINES {
                let mut k = count;
                while k > 0 && spans[k - 1].0 > lo {
                    spans[k] = spans[k - 1];
                    k -= 1;
                }
                spans[k] = (lo, hi);
                count += 1;
            }
        }
        const TOUCH: f32 = 1e-3;
        let (mut run, mut covered) = (0.0f32, false);
        for &(lo, hi) in &spans[..count] {
            if lo > run + TOUCH {
                break;
            }
            if hi >= 0.0 {
                covered = true;
                run = run.max(hi);
            }
        }
        if covered {
            run.min(max_mm)
        } else {
            0.0
        }
    }

    fn all_lines(&self) -> impl Iterator<Item = &Line> {
        self.lines.iter().chain(self.open.iter())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;

    fn probe() -> ProbeModel {
        ProbeModel {
            width_px: 384,
            height_px: 350,
            footprint_mm: 38.4,
            depth_mm: 35.0,
        }
    }

    /// The image frame of a probe standing at (x, y) on the plane z = 0 of the base,
    /// beam along −z turned by `tilt` (rad) about y (positive: toward −x going down, as
    /// on the +x side of a dome), image width along y (a line along x sweeps it
    /// sideways), image centred on (x, y) across.
    fn at(x: f32, y: f32, tilt: f32) -> Rigid {
        // Image x → base y, image y (depth) → base −z, image z → base −x; then the tilt.
        let r = Matrix3::new(0.0, 0.0, -1.0, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
        let (s, c) = (libm::sinf(tilt), libm::cosf(tilt));
        let about_y = Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c);
        Rigid {
            rotation: about_y * r,
            translation: Vec3::new(x, y - 19.2, 0.0),
        }
    }

    /// Serpentine lines along x from −100 to 100 mm at y = −40, −30, …, 40, a pose every
    /// 0.2 mm, the step to the next line too; the probe tilted by `tilt(x)`.
    fn swept(tilt: impl Fn(f32) -> f32) -> ImagedArea<IMAGED_LINES> {
        let mut area = ImagedArea::new();
        for line in 0..9 {
            let y = -40.0 + 10.0 * line as f32;
            for k in 0..=1000 {
                let x = -100.0 + 0.2 * k as f32;
                let x = if line % 2 == 0 { x } else { -x };
                area.place(&at(x, y, tilt(x)), &probe());
            }
            let x = if line % 2 == 0 { 100.0 } else { -100.0 };
            for k in 1..50 {
                area.place(&at(x, y + 0.2 * k as f32, tilt(x)), &probe());
            }
        }
        area
    }

    #[test]
    fn a_line_sweep_images_its_outline() {
        let area = swept(|_| 0.0);
        assert_eq!((area.line_count(), area.dropped), (9, 0));
        // Inside, at any depth.
        for p in [(0.0, 0.0, -20.0), (-99.9, 50.0, -5.0), (99.9, -59.0, -30.0)] {
            assert!(area.contains(&Vec3::new(p.0, p.1, p.2)), "{p:?}");
        }
        // Past the lines' ends and past the images' width beyond the outer lines.
        for p in [
            (100.3, 0.0, -20.0),
            (-100.3, 0.0, -20.0),
            (0.0, 59.5, -20.0),
        ] {
            assert!(!area.contains(&Vec3::new(p.0, p.1, p.2)), "{p:?}");
        }
        // Given back and read in again: the same region.
        let mut copy = ImagedArea::<IMAGED_LINES>::new();
        for ends in area.lines() {
            copy.push_line(ends, area.width_mm()).unwrap();
        }
        assert_eq!(copy.width_mm(), 38.4);
        for p in [(0.0, 0.0, -20.0), (99.9, -59.0, -30.0), (100.3, 0.0, -20.0)] {
            let p = Vec3::new(p.0, p.1, p.2);
            assert_eq!(copy.contains(&p), area.contains(&p), "{p:?}");
        }
        let mut ends = area.lines().next().unwrap();
        assert!(copy.push_line(ends, 20.0).is_err());
        ends[0].normal *= 2.0;
        assert!(copy.push_line(ends, 38.4).is_err());
        ends[0].normal /= -2.0;
        assert!(copy.push_line(ends, 38.4).is_err());
    }

    #[test]
    fn reach_is_how_far_the_imaged_region_goes_without_a_break() {
        let area = swept(|_| 0.0);
        let lateral = Vec3::new(1.0, 0.0, 0.0);
        // A rib end 10 mm inside the lines' end: imaged 10 mm beyond it.
        let r = area.reach(&Vec3::new(90.0, 5.0, -20.0), &lateral, 20.0);
        assert!((r - 10.0).abs() <= 0.01, "{r}");
        // Going on down and across: the lines' ends still bound it.
        let slant = Vec3::new(1.0, 0.3, -0.4);
        let r = area.reach(&Vec3::new(90.0, 5.0, -20.0), &slant, 20.0);
        assert!((r - 10.0 * slant.norm()).abs() <= 0.01, "{r}");
        // One at the lines' end: nothing beyond, all of it behind.
        let end = Vec3::new(99.9, 5.0, -20.0);
        assert_eq!(area.reach(&end, &(-lateral), 20.0), 20.0);
        assert!(area.reach(&end, &lateral, 20.0) < 0.2);
        // Not imaged at all, or no direction.
        assert_eq!(area.reach(&Vec3::new(150.0, 0.0, 0.0), &lateral, 20.0), 0.0);
        assert!(area.reach(&Vec3::zeros(), &Vec3::zeros(), 20.0).is_nan());
        assert!(area
            .reach(&Vec3::new(f32::NAN, 0.0, 0.0), &lateral, 20.0)
            .is_nan());
    }

    /// Lines that overlap end to end, given in any order, join into one run; a gap
    /// between two stops it.
    #[test]
    fn overlapping_lines_join_and_a_gap_stops_the_run() {
        let x = Vec3::new(1.0, 0.0, 0.0);
        let end = |cx: f32| LineEnd {
            centre: Vec3::new(cx, 0.0, -17.5),
            across: Vec3::new(0.0, 1.0, 0.0),
            normal: x,
        };
        let mut area = ImagedArea::<IMAGED_LINES>::new();
        for (a, b) in [(55.0, 90.0), (0.0, 30.0), (25.0, 60.0), (95.0, 120.0)] {
            area.push_line([end(a), end(b)], 38.4).unwrap();
        }
        let from = Vec3::new(10.0, 5.0, -20.0);
        assert_eq!(area.reach(&from, &x, 200.0), 80.0);
        assert_eq!(area.reach(&from, &x, 50.0), 50.0);
        assert_eq!(area.reach(&from, &-x, 200.0), 10.0);
        assert_eq!(area.reach(&Vec3::new(92.0, 0.0, -20.0), &x, 200.0), 0.0);
    }

    /// On a curved chest the probe stands tilted at a line's end: a point beside the
    /// rib end at depth is measured against the tilted last image, not against the
    /// probe's position on the skin.
    #[test]
    fn a_tilted_end_image_bounds_the_line_at_every_depth() {
        // 18° at the ends, the beam turned inward going down, as on a dome's sides.
        let area = swept(|x| 0.00314 * x);
        let tilt = 0.314f32;
        // The last image's plane at x = 100: its points at depth d lie at
        // x = 100 − d·sin(tilt) (a probe standing upright there would image 2–9 mm
        // more at these depths).
        for depth in [5.0f32, 20.0, 30.0] {
            let edge = 100.0 - depth * libm::sinf(tilt);
            let z = -depth * libm::cosf(tilt);
            assert!(area.contains(&Vec3::new(edge - 0.3, 0.0, z)), "{depth}");
            assert!(!area.contains(&Vec3::new(edge + 0.3, 0.0, z)), "{depth}");
        }
    }

    #[test]
    fn a_full_area_drops_lines_and_a_bad_pose_places_nothing() {
        let mut area = ImagedArea::<IMAGED_LINES>::new();
        assert!(area.is_empty() && !area.contains(&Vec3::zeros()));
        let mut bad = at(0.0, 0.0, 0.0);
        bad.translation.x = f32::NAN;
        area.place(&bad, &probe());
        assert!(area.is_empty());
        // Four serpentine lines 60 mm apart (each closed by its sideways step), room for
        // two: the last two are not kept, their region not imaged.
        let mut small = ImagedArea::<2>::new();
        for line in 0..4 {
            let y = 60.0 * line as f32;
            let x = |k: i32| {
                if line % 2 == 0 {
                    k as f32
                } else {
                    100.0 - k as f32
                }
            };
            for k in 0..=100 {
                small.place(&at(x(k), y, 0.0), &probe());
            }
            for k in 1..60 {
                small.place(&at(x(100), y + k as f32, 0.0), &probe());
            }
        }
        assert_eq!((small.line_count(), small.dropped), (2, 2));
        assert!(small.contains(&Vec3::new(50.0, 60.0, -10.0)));
        assert!(!small.contains(&Vec3::new(50.0, 120.0, -10.0)));
        let ends = small.lines().next().unwrap();
        assert_eq!(
            small.push_line(ends, 38.4),
            Err(Error::Capacity { capacity: 2 })
        );
        small.clear();
        assert!(small.is_empty() && small.line_count() == 0);
    }
}
