//! Evaluation of a subject's surface: positions, normals, centrelines, waypoints.

use std::f64::consts::{FRAC_PI_2, TAU};

use super::*;

// ---------------------------------------------------------------------------------------
// Geometry
// ---------------------------------------------------------------------------------------

/// A subject's parameters with the derived quantities (attachment heights, sternum extent)
/// solved once; evaluate many material points through this rather than [`surface_point`].
#[derive(Clone, Debug, PartialEq)]
pub struct SubjectGeometry {
    pub(super) params: SubjectParams,
    /// y of each centreline at the sternum edge (before scaling), mm.
    pub(super) rib_height: [f64; RIB_COUNT],
    /// y of the sternum's top and bottom ends (before scaling), mm.
    pub(super) sternum_top: f64,
    pub(super) sternum_bottom: f64,
}

/// A cartilage centreline frame: tangent, cross-section axes.
pub(super) struct Frame {
    pub(super) t: P3,
    pub(super) n1: P3,
    pub(super) n2: P3,
}

impl SubjectGeometry {
    /// Solve the derived geometry of `params` (sanitised first, see [`SubjectParams::sanitized`]).
    pub fn new(params: &SubjectParams) -> Self {
        let params = params.sanitized();
        let mut rib_height = [params.rib2_height_mm; RIB_COUNT];
        for k in 1..RIB_COUNT {
            let y0 = rib_height[k - 1];
            let d = params.rib_spacing_mm[k - 1];
            // 3-D distance between the attachment points grows with the height step δ
            // (D(δ) ≥ δ), so δ ∈ [0, d]: bisection.
            let zc = |y: f64| -y * y / (2.0 * params.chest_radius_mm[1]);
            let dist = |delta: f64| {
                let dz = zc(y0) - zc(y0 - delta);
                (delta * delta + dz * dz).sqrt()
            };
            let (mut lo, mut hi) = (0.0, d);
            for _ in 0..BISECTION_ITERATIONS {
                let mid = 0.5 * (lo + hi);
                if dist(mid) < d {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            rib_height[k] = y0 - 0.5 * (lo + hi);
        }
        let sternum_top = rib_height[0] + params.sternum_margin_mm[0];
        let sternum_bottom = rib_height[RIB_COUNT - 1] - params.sternum_margin_mm[1];
        Self {
            params,
            rib_height,
            sternum_top,
            sternum_bottom,
        }
    }

    /// The (sanitised) parameters of this subject.
    pub fn params(&self) -> &SubjectParams {
        &self.params
    }

    /// Height y of a rib's centreline at the sternum edge, before the anisotropic scale, mm.
    pub fn rib_height_mm(&self, rib: u8) -> f64 {
        self.rib_height[rib_index(rib)]
    }

    /// Heights (before the anisotropic scale, mm) of the sternum's landmarks, top to
    /// bottom: its top end, the four rib attachments ([`SubjectGeometry::rib_height_mm`])
    /// and its bottom end.
    pub(super) fn sternum_landmarks(&self) -> [f64; RIB_COUNT + 2] {
        let mut l = [self.sternum_top; RIB_COUNT + 2];
        l[1..=RIB_COUNT].copy_from_slice(&self.rib_height);
        l[RIB_COUNT + 1] = self.sternum_bottom;
        l
    }

    /// The material s on this subject's sternum of the point at material s `s` of
    /// `other`'s: the same share of the way between the same two landmarks
    /// (its ends and the four rib attachments, [`SubjectGeometry::rib_height_mm`]), where
    /// the material s itself is the share of the whole sternum's length. The two agree
    /// when the sternum's parts keep their proportions; a manubrium or xiphoid longer
    /// than `other`'s, beside the same ribs, shifts the body's points by up to tens of mm
    /// in material s but not here (README "The sternum's ends").
    pub fn sternum_s_by_landmarks(&self, other: &SubjectGeometry, s: f64) -> f64 {
        let (from, to) = (other.sternum_landmarks(), self.sternum_landmarks());
        let y = other.sternum_y(s.clamp(0.0, 1.0));
        let k = (0..=RIB_COUNT)
            .find(|&k| y >= from[k + 1])
            .unwrap_or(RIB_COUNT);
        let span = from[k] - from[k + 1];
        let f = if span > 0.0 {
            ((from[k] - y) / span).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let y_here = to[k] - f * (to[k] - to[k + 1]);
        let length = self.sternum_top - self.sternum_bottom;
        if length > 0.0 {
            ((self.sternum_top - y_here) / length).clamp(0.0, 1.0)
        } else {
            s
        }
    }

    /// The material s at which a cartilage centreline crosses the sternum edge (u = 0).
    pub fn sternum_edge_s(&self, rib: u8, side: Side) -> f64 {
        let l = self.params.cartilage_length_mm[side.index()][rib_index(rib)];
        CARTILAGE_INSET_MM / (l + CARTILAGE_INSET_MM)
    }

    pub(super) fn scaled(&self, p: P3) -> P3 {
        let s = self.params.scale;
        [p[0] * s[0], p[1] * s[1], p[2] * s[2]]
    }

    pub(super) fn half_sternum_width(&self) -> f64 {
        0.5 * self.params.sternum_width_mm
    }

    pub(super) fn half_sternum_thickness(&self) -> f64 {
        0.5 * self.params.sternum_thickness_mm
    }

    /// Centre z of the sternum cross-section at height y (before scaling).
    pub(super) fn sternum_center_z(&self, y: f64) -> f64 {
        -y * y / (2.0 * self.params.chest_radius_mm[1])
            - self.params.sternum_depth_mm
            - self.half_sternum_thickness()
    }

    // --- cartilage -------------------------------------------------------------------

    pub(super) fn rib_length(&self, r: usize, side: Side) -> f64 {
        self.params.cartilage_length_mm[side.index()][r]
    }

    /// Lateral distance u from the sternum edge at material s.
    pub(super) fn rib_u(&self, r: usize, side: Side, s: f64) -> f64 {
        -CARTILAGE_INSET_MM + s * (self.rib_length(r, side) + CARTILAGE_INSET_MM)
    }

    /// (tan slope, quadratic coefficient) of the centreline's y(u).
    pub(super) fn rib_shape(&self, r: usize, side: Side) -> (f64, f64) {
        let i = side.index();
        let tan = self.params.cartilage_slope_deg[i][r].to_radians().tan();
        let kappa = self.params.cartilage_drop_mm[i][r] / (DROP_REFERENCE_MM * DROP_REFERENCE_MM);
        (tan, kappa)
    }

    /// Centreline point, first and second derivative in u (before scaling).
    pub(super) fn rib_centerline_raw(&self, r: usize, side: Side, u: f64) -> (P3, P3, P3) {
        let sg = side.sign();
        let (tan, kappa) = self.rib_shape(r, side);
        let [rx, ry] = self.params.chest_radius_mm;
        let a = self.half_sternum_width();
        let x = sg * (a + u);
        let y = self.rib_height[r] - tan * u - kappa * u * u;
        let z = -y * y / (2.0 * ry)
            - (x * x - a * a) / (2.0 * rx)
            - self.params.sternum_depth_mm
            - self.half_sternum_thickness();
        let dy = -tan - 2.0 * kappa * u;
        let dz = -x * sg / rx - y * dy / ry;
        let ddy = -2.0 * kappa;
        let ddz = -1.0 / rx - (dy * dy + y * ddy) / ry;
        ([x, y, z], [sg, dy, dz], [0.0, ddy, ddz])
    }

    /// Cross-section frame at a centreline point (before scaling).
    pub(super) fn rib_frame(&self, side: Side, c: P3, dc: P3) -> Frame {
        let t = normalize_or(dc, [side.sign(), 0.0, 0.0]);
        let [rx, ry] = self.params.chest_radius_mm;
        let chest_normal = [c[0] / rx, c[1] / ry, 1.0];
        let n2 = normalize_or(
            sub(chest_normal, mul(t, dot(chest_normal, t))),
            [0.0, 0.0, 1.0],
        );
        let n1 = mul(cross(n2, t), side.sign());
        Frame { t, n1, n2 }
    }

    /// Radius factor of the ellipsoidal lateral cap (1 along the body, → 0 at the tip).
    pub(super) fn rib_taper(&self, r: usize, side: Side, u: f64) -> f64 {
        let l = self.rib_length(r, side);
        let cap = self.rib_cap_length(r);
        if u <= l - cap {
            1.0
        } else {
            let w = (u - (l - cap)) / cap;
            (1.0 - w * w).max(0.0).sqrt()
        }
    }

    /// Length of the lateral cap: the half-thickness, mm.
    pub(super) fn rib_cap_length(&self, r: usize) -> f64 {
        0.5 * self.params.cartilage_thickness_mm[r]
    }

    pub(super) fn rib_point_raw(&self, r: usize, side: Side, s: f64, phi: f64) -> P3 {
        let u = self.rib_u(r, side, s);
        let (c, dc, _) = self.rib_centerline_raw(r, side, u);
        let f = self.rib_taper(r, side, u);
        let fr = self.rib_frame(side, c, dc);
        let a = 0.5 * self.params.cartilage_width_mm[r] * f;
        let b = 0.5 * self.params.cartilage_thickness_mm[r] * f;
        add(c, add(mul(fr.n1, a * phi.cos()), mul(fr.n2, b * phi.sin())))
    }

    // --- sternum ----------------------------------------------------------------------

    pub(super) fn sternum_y(&self, s: f64) -> f64 {
        self.sternum_top - s * (self.sternum_top - self.sternum_bottom)
    }

    /// Radius factor of the rounded sternum ends at height y.
    pub(super) fn sternum_taper(&self, y: f64) -> f64 {
        let c = STERNUM_CAP_MM;
        let w = if y > self.sternum_top - c {
            (y - (self.sternum_top - c)) / c
        } else if y < self.sternum_bottom + c {
            ((self.sternum_bottom + c) - y) / c
        } else {
            0.0
        };
        (1.0 - w * w).max(0.0).sqrt()
    }

    /// Rounded-rectangle cross-section point at perimeter angle phi (before taper).
    pub(super) fn sternum_section(&self, phi: f64) -> (f64, f64) {
        let a = self.half_sternum_width();
        let b = self.half_sternum_thickness();
        let rc = STERNUM_CORNER_FRACTION * b.min(a);
        let straight_side = b - rc;
        let arc = FRAC_PI_2 * rc;
        let straight_top = a - rc;
        let quarter = straight_side + arc + straight_top;
        let l = phi.rem_euclid(TAU) / TAU * 4.0 * quarter;
        let q = ((l / quarter).floor() as i64).clamp(0, 3);
        let local = l - q as f64 * quarter;
        // First quadrant, from (a, 0) counter-clockwise to (0, b).
        let first = |m: f64| -> (f64, f64) {
            let m = m.clamp(0.0, quarter);
            if m <= straight_side {
                (a, m)
            } else if m <= straight_side + arc {
                let th = (m - straight_side) / rc.max(1e-12);
                (a - rc + rc * th.cos(), b - rc + rc * th.sin())
            } else {
                (a - rc - (m - straight_side - arc), b)
            }
        };
        match q {
            0 => first(local),
            1 => {
                let (x, z) = first(quarter - local);
                (-x, z)
            }
            2 => {
                let (x, z) = first(local);
                (-x, -z)
            }
            _ => {
                let (x, z) = first(quarter - local);
                (x, -z)
            }
        }
    }

    pub(super) fn sternum_point_raw(&self, s: f64, phi: f64) -> P3 {
        let y = self.sternum_y(s);
        let f = self.sternum_taper(y);
        let (x, z) = self.sternum_section(phi);
        [f * x, y, self.sternum_center_z(y) + f * z]
    }

    /// Whether a point (before scaling) lies strictly inside the sternum.
    pub(super) fn inside_sternum_raw(&self, p: P3) -> bool {
        if p[1] <= self.sternum_bottom || p[1] >= self.sternum_top {
            return false;
        }
        let f = self.sternum_taper(p[1]);
        let a = self.half_sternum_width() * f;
        let b = self.half_sternum_thickness() * f;
        let rc = STERNUM_CORNER_FRACTION * b.min(a);
        let x = p[0].abs();
        let z = (p[2] - self.sternum_center_z(p[1])).abs();
        if x >= a || z >= b {
            return false;
        }
        let qx = x - (a - rc);
        let qz = z - (b - rc);
        qx <= 0.0 || qz <= 0.0 || qx * qx + qz * qz < rc * rc
    }

    /// Whether a point (before scaling) lies strictly inside a cartilage tube.
    pub(super) fn inside_cartilage_raw(&self, p: P3, r: usize, side: Side) -> bool {
        let l = self.rib_length(r, side);
        let mut u = (p[0].abs() - self.half_sternum_width()).clamp(-CARTILAGE_INSET_MM, l);
        for _ in 0..PROJECTION_ITERATIONS {
            let (c, dc, ddc) = self.rib_centerline_raw(r, side, u);
            let q = sub(p, c);
            let g = dot(q, dc);
            let dg = dot(q, ddc) - dot(dc, dc);
            if dg.abs() < 1e-12 {
                break;
            }
            u = (u - g / dg).clamp(-CARTILAGE_INSET_MM, l);
        }
        let (c, dc, _) = self.rib_centerline_raw(r, side, u);
        let q = sub(p, c);
        let fr = self.rib_frame(side, c, dc);
        if dot(q, fr.t).abs() > 1e-6 {
            return false; // projection hit an end of the centreline
        }
        let f = self.rib_taper(r, side, u);
        let a = 0.5 * self.params.cartilage_width_mm[r] * f;
        let b = 0.5 * self.params.cartilage_thickness_mm[r] * f;
        if a <= 0.0 || b <= 0.0 {
            return false;
        }
        let e1 = dot(q, fr.n1) / a;
        let e2 = dot(q, fr.n2) / b;
        e1 * e1 + e2 * e2 < 1.0
    }

    /// Whether the surface point `m` (position `raw`, before scaling) lies strictly inside
    /// another part, i.e. is not on the surface of the union.
    pub(super) fn hidden_raw(&self, m: &Material, raw: P3) -> bool {
        match m.part {
            Part::Cartilage { .. } => self.inside_sternum_raw(raw),
            Part::Sternum => {
                let side = if raw[0] >= 0.0 {
                    Side::Left
                } else {
                    Side::Right
                };
                raw[0].abs() > 0.5 * self.half_sternum_width()
                    && (0..RIB_COUNT).any(|r| self.inside_cartilage_raw(raw, r, side))
            }
        }
    }

    // --- public evaluation ------------------------------------------------------------

    /// Position of material point `m` before the anisotropic scale.
    pub(super) fn position_raw(&self, m: &Material) -> P3 {
        let s = if m.s.is_finite() {
            m.s.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let phi = if m.phi.is_finite() { m.phi } else { 0.0 };
        match m.part {
            Part::Sternum => self.sternum_point_raw(s, phi),
            Part::Cartilage { rib, side } => self.rib_point_raw(rib_index(rib), side, s, phi),
        }
    }

    /// Position of material point `m` on this subject (patient frame, mm).
    pub fn position(&self, m: &Material) -> [f64; 3] {
        self.scaled(self.position_raw(m))
    }

    /// Centreline point of `part` at `s` (patient frame, mm). For the sternum, the centre of
    /// its cross-section at that height.
    pub fn centerline(&self, part: Part, s: f64) -> [f64; 3] {
        let s = if s.is_finite() {
            s.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let raw = match part {
            Part::Sternum => {
                let y = self.sternum_y(s);
                [0.0, y, self.sternum_center_z(y)]
            }
            Part::Cartilage { rib, side } => {
                let r = rib_index(rib);
                self.rib_centerline_raw(r, side, self.rib_u(r, side, s)).0
            }
        };
        self.scaled(raw)
    }

    /// Position and outward unit normal of material point `m` (patient frame).
    ///
    /// The normal is the normalised cross product of central finite differences in s and
    /// phi of the (scaled) position, oriented away from the centreline; at the degenerate
    /// ends (cartilage tip, sternum top and bottom) it is the centreline direction.
    pub fn surface_point(&self, m: &Material) -> ([f64; 3], [f64; 3]) {
        let s = if m.s.is_finite() {
            m.s.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let at = |s: f64, phi: f64| {
            self.position(&Material {
                part: m.part,
                s,
                phi,
            })
        };
        let pos = at(s, m.phi);
        let (s_lo, s_hi) = ((s - FD_STEP).max(0.0), (s + FD_STEP).min(1.0));
        let ds = sub(at(s_hi, m.phi), at(s_lo, m.phi));
        let dphi = sub(at(s, m.phi + FD_STEP), at(s, m.phi - FD_STEP));
        // Outward hint: away from the centreline, or along it at the closed ends.
        let axis = sub(self.centerline(m.part, s_hi), self.centerline(m.part, s_lo));
        let end_dir = if s >= 0.5 { axis } else { mul(axis, -1.0) };
        let radial = sub(pos, self.centerline(m.part, s));
        let hint = if norm(radial) > 1e-9 { radial } else { end_dir };
        let n = cross(ds, dphi);
        let scale_ref = norm(ds) * norm(dphi);
        let normal = if norm(n) > 1e-9 * scale_ref && norm(n) > 1e-300 {
            let n = normalize_or(n, [0.0, 0.0, 1.0]);
            if dot(n, hint) < 0.0 {
                mul(n, -1.0)
            } else {
                n
            }
        } else {
            normalize_or(end_dir, [0.0, 0.0, 1.0])
        };
        (pos, normal)
    }

    /// Area element |∂P/∂s × ∂P/∂phi| at an interior material point, mm² per unit s·rad.
    pub(super) fn area_density(&self, part: Part, s: f64, phi: f64) -> f64 {
        let at = |s: f64, phi: f64| self.position(&Material { part, s, phi });
        let ds = mul(
            sub(at(s + FD_STEP, phi), at(s - FD_STEP, phi)),
            0.5 / FD_STEP,
        );
        let dphi = mul(
            sub(at(s, phi + FD_STEP), at(s, phi - FD_STEP)),
            0.5 / FD_STEP,
        );
        norm(cross(ds, dphi))
    }

    /// Lower bound on the clear gap between neighbouring cartilages on the same side, mm:
    /// centreline-to-centreline distance minus both largest semi-axes (times the largest
    /// scale factor), over polyline samples.
    pub(super) fn min_gap_lower_bound(&self) -> f64 {
        let smax = self.params.scale.iter().fold(0.0f64, |m, v| m.max(*v));
        let mut best = f64::INFINITY;
        for side in Side::BOTH {
            let lines: Vec<Vec<P3>> = (0..RIB_COUNT)
                .map(|r| {
                    (0..=GAP_CHECK_SAMPLES)
                        .map(|i| {
                            let u = self.rib_u(r, side, i as f64 / GAP_CHECK_SAMPLES as f64);
                            self.scaled(self.rib_centerline_raw(r, side, u).0)
                        })
                        .collect()
                })
                .collect();
            for r in 0..RIB_COUNT - 1 {
                let d = polyline_distance(&lines[r], &lines[r + 1])
                    .min(polyline_distance(&lines[r + 1], &lines[r]));
                let ra = 0.5
                    * self.params.cartilage_width_mm[r].max(self.params.cartilage_thickness_mm[r]);
                let rb = 0.5
                    * self.params.cartilage_width_mm[r + 1]
                        .max(self.params.cartilage_thickness_mm[r + 1]);
                best = best.min(d - smax * (ra + rb));
            }
        }
        best
    }

    /// The planned intercostal waypoints on this subject (patient frame): for each side
    /// (left first) and each entry `(upper, s)` of [`WAYPOINT_PLAN`], the midpoint of the
    /// centreline points of ribs `upper` and `upper + 1` at `s`, lifted to z = mean z of the
    /// two anterior surface points (phi = π/2) at `s`.
    pub fn waypoints(&self) -> Vec<[f64; 3]> {
        let mut out = Vec::with_capacity(2 * WAYPOINT_PLAN.len());
        for side in Side::BOTH {
            for &(upper, s) in WAYPOINT_PLAN.iter() {
                let a = Part::Cartilage { rib: upper, side };
                let b = Part::Cartilage {
                    rib: upper + 1,
                    side,
                };
                let c = midpoint(self.centerline(a, s), self.centerline(b, s));
                let pa = self.position(&Material {
                    part: a,
                    s,
                    phi: FRAC_PI_2,
                });
                let pb = self.position(&Material {
                    part: b,
                    s,
                    phi: FRAC_PI_2,
                });
                out.push([c[0], c[1], 0.5 * (pa[2] + pb[2])]);
            }
        }
        out
    }

    /// How far from `from` along the unit `toward` (both in the chest's plane) the ray
    /// enters `part`'s outline seen along the anterior axis: the least entry over its
    /// cross-sections from `s − GAP_S_REACH` to `s + GAP_S_REACH` (a sloped cartilage's
    /// neighbouring sections reach the ray before its own does). Each section is an
    /// ellipse, `c + n1 a cos φ + n2 b sin φ`, whose projection is the 2-D ellipse through
    /// its points at φ = 0 and π/2; the entry solves a quadratic in its unit-circle frame.
    /// Infinite where the ray meets no section.
    fn outline_entry(&self, part: Part, s: f64, from: P3, toward: P3) -> f64 {
        let xy = |p: P3| [p[0], p[1]];
        (0..=GAP_SECTIONS)
            .map(|k| s + GAP_S_REACH * (2.0 * k as f64 / GAP_SECTIONS as f64 - 1.0))
            .filter(|si| (0.0..=1.0).contains(si))
            .filter_map(|si| {
                let c = self.centerline(part, si);
                let at = |phi| xy(sub(self.position(&Material { part, s: si, phi }), c));
                let (m1, m2) = (at(0.0), at(FRAC_PI_2));
                let det = m1[0] * m2[1] - m1[1] * m2[0];
                if det.abs() < 1e-9 {
                    return None;
                }
                // M⁻¹ of M = [m1 m2] (columns), applied to a 2-vector.
                let inv = |v: [f64; 2]| {
                    [
                        (m2[1] * v[0] - m2[0] * v[1]) / det,
                        (m1[0] * v[1] - m1[1] * v[0]) / det,
                    ]
                };
                let (u, v) = (inv(xy(toward)), inv(xy(sub(from, c))));
                let (uu, uv, vv) = (
                    u[0] * u[0] + u[1] * u[1],
                    u[0] * v[0] + u[1] * v[1],
                    v[0] * v[0] + v[1] * v[1],
                );
                let disc = uv * uv - uu * (vv - 1.0);
                let t = (-uv - disc.sqrt()) / uu;
                (disc >= 0.0 && t > 0.0).then_some(t)
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// The window each of [`SubjectGeometry::waypoints`] must land in (same order, patient
    /// frame), seen along the patient's anterior axis as the probe sees it: the unit
    /// direction in the chest's plane (z left out) from rib `upper`'s centreline point at
    /// `s` toward rib `upper + 1`'s, and how far the waypoint may move along it either way
    /// before its centre is over a cartilage: to the nearest outline of the cartilage's
    /// cross-sections within ±0.1 of `s`, as the probe sees them. A mapped waypoint's error
    /// along that direction is what moves the probe toward a rib.
    pub fn waypoint_gaps(&self) -> Vec<Gap> {
        let waypoints = self.waypoints();
        let mut out = Vec::with_capacity(waypoints.len());
        for ((side, &(upper, s)), w) in Side::BOTH
            .iter()
            .flat_map(|&side| WAYPOINT_PLAN.iter().map(move |p| (side, p)))
            .zip(&waypoints)
        {
            let a = Part::Cartilage { rib: upper, side };
            let b = Part::Cartilage {
                rib: upper + 1,
                side,
            };
            let (ca, cb) = (self.centerline(a, s), self.centerline(b, s));
            let d = sub(cb, ca);
            let across = normalize_or([d[0], d[1], 0.0], [0.0, -1.0, 0.0]);
            out.push(Gap {
                across,
                to_upper: self.outline_entry(a, s, *w, mul(across, -1.0)),
                to_lower: self.outline_entry(b, s, *w, across),
            });
        }
        out
    }
}

/// Smallest distance from any point of `a` to the polyline `b`.
pub(super) fn polyline_distance(a: &[P3], b: &[P3]) -> f64 {
    let mut best = f64::INFINITY;
    for &p in a {
        for w in b.windows(2) {
            let (s0, s1) = (w[0], w[1]);
            let d = sub(s1, s0);
            let len2 = dot(d, d);
            let t = if len2 > 0.0 {
                (dot(sub(p, s0), d) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            best = best.min(dist2(p, add(s0, mul(d, t))));
        }
    }
    best.sqrt()
}

/// Position and outward unit normal of material point `m` on the subject `params`
/// (patient frame, mm). Solves the subject's derived geometry on every call; use
/// [`SubjectGeometry`] for many points.
pub fn surface_point(params: &SubjectParams, m: &Material) -> ([f64; 3], [f64; 3]) {
    SubjectGeometry::new(params).surface_point(m)
}
