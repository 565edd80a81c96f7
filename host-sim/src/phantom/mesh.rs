//! Triangle mesh of a subject's surface.

use std::f64::consts::{FRAC_PI_2, TAU};

use super::*;

impl SubjectGeometry {
    /// A triangle mesh of the whole surface (vertices, outward-wound triangles): every
    /// cartilage tube open at its buried medial end and closed by its lateral cap, and the
    /// sternum closed at both ends. Edge length about `edge_mm` along each part.
    pub fn mesh(&self, edge_mm: f64) -> Mesh {
        let mut verts = Vec::new();
        let mut tris = Vec::new();
        for (_, (v, t)) in self.part_meshes(edge_mm) {
            let offset = verts.len() as u32;
            verts.extend(v);
            tris.extend(t.into_iter().map(|t| t.map(|i| i + offset)));
        }
        (verts, tris)
    }

    /// The mesh of each part separately (see [`SubjectGeometry::mesh`]), in [`Part::ALL`] order.
    pub fn part_meshes(&self, edge_mm: f64) -> Vec<(Part, Mesh)> {
        let edge = if edge_mm.is_finite() {
            edge_mm.max(MIN_SPACING_MM)
        } else {
            MESH_EDGE_MM
        };
        let cap_angle = |j: usize| j as f64 * FRAC_PI_2 / MESH_CAP_RINGS as f64;
        let mut out = Vec::with_capacity(Part::ALL.len());
        for part in Part::ALL {
            let mut rings = Vec::new();
            let (tip_start, segments) = match part {
                Part::Sternum => {
                    // Top cap rings, body, bottom cap rings (tips added by `mesh_part`).
                    let len = self.sternum_top - self.sternum_bottom;
                    let c = STERNUM_CAP_MM;
                    let to_s = |y: f64| (self.sternum_top - y) / len;
                    for j in (1..MESH_CAP_RINGS).rev() {
                        rings.push(to_s(self.sternum_top - c + c * cap_angle(j).sin()));
                    }
                    let body = len - 2.0 * c;
                    let n = ((body / edge).ceil() as usize).max(1);
                    for i in 0..=n {
                        rings.push(to_s(self.sternum_top - c - body * i as f64 / n as f64));
                    }
                    for j in 1..MESH_CAP_RINGS {
                        rings.push(to_s(self.sternum_bottom + c - c * cap_angle(j).sin()));
                    }
                    (true, MESH_STERNUM_SEGMENTS)
                }
                Part::Cartilage { rib, side } => {
                    // Body from the buried medial end, then the lateral cap rings.
                    let r = rib_index(rib);
                    let l = self.rib_length(r, side);
                    let c = self.rib_cap_length(r);
                    let to_s = |u: f64| (u + CARTILAGE_INSET_MM) / (l + CARTILAGE_INSET_MM);
                    let body = l - c + CARTILAGE_INSET_MM;
                    let n = ((body / edge).ceil() as usize).max(1);
                    for i in 0..=n {
                        rings.push(to_s(-CARTILAGE_INSET_MM + body * i as f64 / n as f64));
                    }
                    for j in 1..MESH_CAP_RINGS {
                        rings.push(to_s(l - c + c * cap_angle(j).sin()));
                    }
                    (false, MESH_TUBE_SEGMENTS)
                }
            };
            let mut verts = Vec::new();
            let mut tris = Vec::new();
            self.mesh_part(part, &rings, tip_start, segments, &mut verts, &mut tris);
            out.push((part, (verts, tris)));
        }
        out
    }

    /// Append one part's rings (at material s values) plus an end tip at s = 1 (and one at
    /// s = 0 when `tip_start`), winding every triangle along the outward surface normal.
    pub(super) fn mesh_part(
        &self,
        part: Part,
        rings: &[f64],
        tip_start: bool,
        segments: usize,
        verts: &mut Vec<P3>,
        tris: &mut Vec<[u32; 3]>,
    ) {
        let mat = |s: f64, j: usize| Material {
            part,
            s,
            phi: TAU * j as f64 / segments as f64,
        };
        let base = verts.len();
        let push_tri = |tris: &mut Vec<[u32; 3]>, verts: &[P3], t: [usize; 3], m: Material| {
            let (a, b, c) = (verts[t[0]], verts[t[1]], verts[t[2]]);
            let n = cross(sub(b, a), sub(c, a));
            let (_, reference) = self.surface_point(&m);
            let idx = |i: usize| i as u32;
            if dot(n, reference) >= 0.0 {
                tris.push([idx(t[0]), idx(t[1]), idx(t[2])]);
            } else {
                tris.push([idx(t[0]), idx(t[2]), idx(t[1])]);
            }
        };
        for &s in rings {
            for j in 0..segments {
                verts.push(self.position(&mat(s, j)));
            }
        }
        let ring = |i: usize, j: usize| base + i * segments + (j % segments);
        for i in 0..rings.len().saturating_sub(1) {
            let sm = 0.5 * (rings[i] + rings[i + 1]);
            for j in 0..segments {
                let m = Material {
                    part,
                    s: sm,
                    phi: TAU * (j as f64 + 0.5) / segments as f64,
                };
                push_tri(
                    tris,
                    verts,
                    [ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)],
                    m,
                );
                push_tri(
                    tris,
                    verts,
                    [ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)],
                    m,
                );
            }
        }
        let fan = |s_tip: f64, ring_i: usize, verts: &mut Vec<P3>, tris: &mut Vec<[u32; 3]>| {
            let tip = verts.len();
            verts.push(self.position(&mat(s_tip, 0)));
            for j in 0..segments {
                let m = Material {
                    part,
                    s: rings[ring_i],
                    phi: TAU * (j as f64 + 0.5) / segments as f64,
                };
                push_tri(tris, verts, [ring(ring_i, j), ring(ring_i, j + 1), tip], m);
            }
        };
        if rings.is_empty() {
            return;
        }
        if tip_start {
            fan(0.0, 0, verts, tris);
        }
        fan(1.0, rings.len() - 1, verts, tris);
    }
}
