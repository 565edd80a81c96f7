//! The phantom as a CT segmentation would hand it over: a TotalSegmentator-style labelmap
//! (`ribreg phantom --ct`), so that `ribreg template` can be tried, and tested, end to end
//! without patient data.
//!
//! The volume holds, with TotalSegmentator v2 ids, the sternum (116), ONE cartilage mask
//! (117) for the cartilages of ribs 2..=5 **and distractors** — the cartilages of ribs 1,
//! 6 and 7 (copies of ribs 2 and 5's, moved a rib spacing up and down) and an
//! interchondral bridge joining cartilages 5 and 6, so that the mask is one connected
//! piece, as real cartilage masks are — and a stub of bony rib at each cartilage's
//! lateral tip (`rib_left_N` 91 + N, `rib_right_N` 103 + N), the costochondral junction
//! that tells the cartilages apart. The voxel grid is anisotropic and oblique (its axes
//! turned against the patient's), and the whole scene sits at a scanner position
//! [`WORLD_SHIFT_MM`] away from the phantom's patient frame, as a CT's world does.
//!
//! Voxels are painted from dense samples of each part's solid (segments from the
//! centreline to the surface), ribs first, then cartilage, then the sternum, each over
//! the one before.

use super::{Material, Part, Side, SubjectGeometry, SubjectParams};
use crate::io::volume::LabelVolume;
use crate::io::Space;

/// Where the phantom's patient-frame origin lies in the CT's world (patient axes), mm.
pub const WORLD_SHIFT_MM: [f64; 3] = [18.0, -412.0, 75.0];
/// Voxel size along the grid's i, j, k axes, mm.
pub const VOXEL_MM: [f64; 3] = [0.8, 0.9, 1.25];
/// Sample step over the solids, mm (well under half the smallest voxel, so no voxel
/// inside a part is missed).
const STEP_MM: f64 = 0.3;
/// Length of the bony rib stub past each cartilage's tip, mm.
const RIB_STUB_MM: f64 = 35.0;
/// How far the distractor cartilages 6 and 7 sit below 5 and 6, in rib-4–5 spacings: a
/// plain copy one spacing down runs within a voxel of cartilage 5 along its steep lateral
/// part (the tubes fall caudally *and* posteriorly there), which makes the two touch
/// along a line equally far from both ribs — a tie no rule can break. Real cartilages
/// 6 and 7 are longer and join the ones above at interchondral joints, as the bridge does.
const LOWER_SHIFT: f64 = 1.5;
/// TotalSegmentator v2 ids.
const STERNUM_ID: u16 = 116;
const CARTILAGE_ID: u16 = 117;
fn rib_id(side: Side, n: u8) -> u16 {
    match side {
        Side::Left => 91 + u16::from(n),
        Side::Right => 103 + u16::from(n),
    }
}

type P3 = [f64; 3];

fn add(a: P3, b: P3) -> P3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn sub(a: P3, b: P3) -> P3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn scale(a: P3, s: f64) -> P3 {
    a.map(|c| c * s)
}
fn norm(a: P3) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}
fn cross(a: P3, b: P3) -> P3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn unit(a: P3) -> P3 {
    scale(a, 1.0 / norm(a).max(1e-12))
}

/// The grid's rotation against the patient's axes: 12° about (1, 2, 3)/√14.
fn grid_rotation() -> [[f64; 3]; 3] {
    let axis = unit([1.0, 2.0, 3.0]);
    let (s, c) = 12f64.to_radians().sin_cos();
    let [x, y, z] = axis;
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

/// Calls `paint(point, id)` for dense samples of every part's solid, in painting order.
fn for_each_sample(g: &SubjectGeometry, paint: &mut dyn FnMut(P3, u16)) {
    let p = g.params();
    // A tube: segments from `centre(s)` to `surface(s, phi)`.
    let solid = |centre: &dyn Fn(f64) -> P3,
                 surface: &dyn Fn(f64, f64) -> P3,
                 length: f64,
                 radius: f64,
                 id: u16,
                 paint: &mut dyn FnMut(P3, u16)| {
        let ns = (length / STEP_MM).ceil().max(1.0) as usize;
        let nphi = ((std::f64::consts::TAU * radius) / STEP_MM).ceil().max(8.0) as usize;
        let nt = (radius / STEP_MM).ceil().max(1.0) as usize;
        for i in 0..=ns {
            let s = i as f64 / ns as f64;
            let c = centre(s);
            for k in 0..nphi {
                let phi = std::f64::consts::TAU * k as f64 / nphi as f64;
                let q = surface(s, phi);
                for t in 0..=nt {
                    paint(add(c, scale(sub(q, c), t as f64 / nt as f64)), id);
                }
            }
        }
    };
    let tube = |part: Part| {
        let centre = move |s: f64| g.centerline(part, s);
        let surface = move |s: f64, phi: f64| g.position(&Material { part, s, phi });
        let length = norm(sub(g.centerline(part, 1.0), g.centerline(part, 0.0))) * 1.3;
        (centre, surface, length)
    };
    // Bony rib stubs, then the cartilages (2..5 and the distractors), then the sternum.
    let shifts: [(u8, u8, f64); 3] = [
        (1, 2, p.rib_spacing_mm[0]),
        (6, 5, -LOWER_SHIFT * p.rib_spacing_mm[2]),
        (7, 5, -2.0 * LOWER_SHIFT * p.rib_spacing_mm[2]),
    ];
    for side in Side::BOTH {
        let mut ribs: Vec<(u8, u8, f64)> = (2..=5).map(|n| (n, n, 0.0)).collect();
        ribs.extend(shifts);
        for &(n, like, dy) in &ribs {
            let part = Part::Cartilage { rib: like, side };
            let r = usize::from(like - 2);
            let radius = 0.45 * p.cartilage_thickness_mm[r];
            let tip = g.centerline(part, 1.0);
            let dir = unit(sub(tip, g.centerline(part, 0.97)));
            let e1 = unit(cross(dir, [0.0, 0.0, 1.0]));
            let e2 = cross(dir, e1);
            let start = -0.4 * p.cartilage_thickness_mm[r];
            let centre = |s: f64| {
                let tau = start + s * (RIB_STUB_MM - start);
                add(
                    add(tip, scale(dir, tau)),
                    [0.0, dy, -0.004 * tau.max(0.0).powi(2)],
                )
            };
            let surface = |s: f64, phi: f64| {
                add(
                    centre(s),
                    add(scale(e1, radius * phi.cos()), scale(e2, radius * phi.sin())),
                )
            };
            solid(
                &centre,
                &surface,
                RIB_STUB_MM - start,
                radius,
                rib_id(side, n),
                paint,
            );
        }
        for &(_, like, dy) in &ribs {
            let part = Part::Cartilage { rib: like, side };
            let (centre, surface, length) = tube(part);
            let r = usize::from(like - 2);
            let radius = 0.5
                * p.cartilage_width_mm[r].max(p.cartilage_thickness_mm[r])
                * p.scale[0].max(1.0);
            let moved_c = |s: f64| add(centre(s), [0.0, dy, 0.0]);
            let moved_s = |s: f64, phi: f64| add(surface(s, phi), [0.0, dy, 0.0]);
            solid(&moved_c, &moved_s, length, radius, CARTILAGE_ID, paint);
        }
        // The interchondral bridge between cartilages 5 and 6 (radius 2 mm).
        let c5 = g.centerline(Part::Cartilage { rib: 5, side }, 0.6);
        let c6 = add(c5, [0.0, -LOWER_SHIFT * p.rib_spacing_mm[2], 0.0]);
        let axis = unit(sub(c6, c5));
        let e1 = unit(cross(axis, [0.0, 0.0, 1.0]));
        let e2 = cross(axis, e1);
        let centre = |s: f64| add(c5, scale(sub(c6, c5), s));
        let surface = |s: f64, phi: f64| {
            add(
                centre(s),
                add(scale(e1, 2.0 * phi.cos()), scale(e2, 2.0 * phi.sin())),
            )
        };
        solid(
            &centre,
            &surface,
            norm(sub(c6, c5)),
            2.0,
            CARTILAGE_ID,
            paint,
        );
    }
    let (centre, surface, length) = tube(Part::Sternum);
    let radius = 0.5 * p.sternum_width_mm.max(p.sternum_thickness_mm) * 1.2;
    solid(&centre, &surface, length, radius, STERNUM_ID, paint);
}

/// The phantom subject `params` as a labelmap volume (see the module docs), in the
/// patient frame of the CT's world: the phantom's frame moved by [`WORLD_SHIFT_MM`].
pub fn labelmap(params: &SubjectParams) -> LabelVolume {
    let g = SubjectGeometry::new(params);
    let rot = grid_rotation();
    // Continuous grid coordinates (before the offset) of a world point.
    let to_grid = |q: P3| -> P3 {
        let w = add(q, WORLD_SHIFT_MM);
        std::array::from_fn(|a| (0..3).map(|r| rot[r][a] * w[r]).sum::<f64>() / VOXEL_MM[a])
    };
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for_each_sample(&g, &mut |q, _| {
        let u = to_grid(q);
        for a in 0..3 {
            lo[a] = lo[a].min(u[a]);
            hi[a] = hi[a].max(u[a]);
        }
    });
    let origin = lo.map(|v| v.round() - 3.0);
    let dims: [usize; 3] = std::array::from_fn(|a| (hi[a].round() - origin[a] + 4.0) as usize);
    let mut labels = vec![0u16; dims[0] * dims[1] * dims[2]];
    for_each_sample(&g, &mut |q, id| {
        let u = to_grid(q);
        let ijk: [usize; 3] = std::array::from_fn(|a| (u[a] - origin[a]).round() as usize);
        if ijk.iter().zip(&dims).all(|(c, d)| c < d) {
            labels[ijk[0] + dims[0] * (ijk[1] + dims[1] * ijk[2])] = id;
        }
    });
    // p = R · diag(voxel) · (ijk + origin) − shift... in world: w = R · diag(voxel) · (ijk + origin).
    let linear: [[f64; 3]; 3] =
        std::array::from_fn(|r| std::array::from_fn(|a| rot[r][a] * VOXEL_MM[a]));
    let offset: P3 = std::array::from_fn(|r| (0..3).map(|a| linear[r][a] * origin[a]).sum());
    LabelVolume {
        dims,
        labels,
        linear,
        offset,
        space: Space::Ras,
        segments: Vec::new(),
    }
}

/// A phantom point (patient frame) in the CT's world ([`labelmap`]'s frame).
pub fn to_world(p: P3) -> P3 {
    add(p, WORLD_SHIFT_MM)
}

/// The part meshes of subject `params` as a segmentation exports them: one mesh per
/// label (the sternum; each rib's cartilages, both sides in one mesh), in the CT's
/// world ([`to_world`]), with their label (1 sternum, 2..=5).
pub fn part_meshes(params: &SubjectParams) -> Vec<(i32, crate::io::Mesh)> {
    let g = SubjectGeometry::new(params);
    let mut out: Vec<(i32, crate::io::Mesh)> = Vec::new();
    for (part, mesh) in g.part_meshes(super::MESH_EDGE_MM) {
        let label = part.label();
        let k = match out.iter().position(|(l, _)| *l == label) {
            Some(k) => k,
            None => {
                out.push((label, crate::io::Mesh::default()));
                out.len() - 1
            }
        };
        let m = &mut out[k].1;
        // Vertex counts of one phantom part fit a u32.
        let base = m.vertices.len() as u32;
        m.vertices.extend(mesh.0.iter().map(|v| to_world(*v)));
        m.triangles
            .extend(mesh.1.iter().map(|t| t.map(|i| i + base)));
    }
    out
}
