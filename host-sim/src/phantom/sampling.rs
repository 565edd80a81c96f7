//! Poisson-disc sampling of a subject's surface (area-weighted candidates, dart throwing).

use std::f64::consts::{FRAC_PI_2, TAU};

use super::*;

// ---------------------------------------------------------------------------------------
// Poisson-disc sampling
// ---------------------------------------------------------------------------------------

/// Area-weighted, jittered candidate material points over the whole (union) surface.
pub(super) fn surface_candidates(
    geom: &SubjectGeometry,
    spacing: f64,
    rng: &mut Rng,
) -> (Vec<P3>, Vec<Material>) {
    let h = spacing / CELLS_PER_SPACING;
    let density = CANDIDATES_PER_SPACING_SQ / (spacing * spacing);
    let mut points = Vec::new();
    let mut materials = Vec::new();
    for part in Part::ALL {
        let at = |s: f64, phi: f64| geom.position(&Material { part, s, phi });
        let samples = EXTENT_SAMPLES as f64;
        let length: f64 = (0..EXTENT_SAMPLES)
            .map(|i| {
                norm(sub(
                    at((i + 1) as f64 / samples, FRAC_PI_2),
                    at(i as f64 / samples, FRAC_PI_2),
                ))
            })
            .sum();
        let perimeter: f64 = (0..EXTENT_SAMPLES)
            .map(|j| {
                norm(sub(
                    at(0.5, TAU * (j + 1) as f64 / samples),
                    at(0.5, TAU * j as f64 / samples),
                ))
            })
            .sum();
        let n_s = ((length / h).ceil() as usize).max(4);
        let n_phi = ((perimeter / h).ceil() as usize).max(8);
        let (cs, cphi) = (1.0 / n_s as f64, TAU / n_phi as f64);
        for i in 0..n_s {
            for j in 0..n_phi {
                let area = geom.area_density(part, (i as f64 + 0.5) * cs, (j as f64 + 0.5) * cphi)
                    * cs
                    * cphi;
                let expected = area * density;
                let count = if expected.is_finite() {
                    (expected + rng.next_f64()).floor() as usize
                } else {
                    0
                };
                for _ in 0..count {
                    let m = Material {
                        part,
                        s: (i as f64 + rng.next_f64()) * cs,
                        phi: (j as f64 + rng.next_f64()) * cphi,
                    };
                    let raw = geom.position_raw(&m);
                    if !geom.hidden_raw(&m, raw) {
                        points.push(geom.scaled(raw));
                        materials.push(m);
                    }
                }
            }
        }
    }
    (points, materials)
}

/// Dart throwing: visit `points` in `order`, accept a point when no accepted point lies
/// closer than `radius`. Returns the accepted indices in ascending order.
pub(crate) fn dart_throw(points: &[P3], order: &[usize], radius: f64) -> Vec<usize> {
    if points.is_empty() {
        return Vec::new();
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let ext = sub(hi, lo);
    let volume: f64 = ext.iter().map(|e| e.max(radius)).product();
    let cell = radius.max((volume / MAX_GRID_CELLS).cbrt());
    let dims = ext.map(|e| (e / cell).floor() as usize + 1);
    let cell_of = |p: &P3| -> [usize; 3] {
        let mut c = [0usize; 3];
        for a in 0..3 {
            c[a] = (((p[a] - lo[a]) / cell).floor().max(0.0) as usize).min(dims[a] - 1);
        }
        c
    };
    let flat = |c: [usize; 3]| (c[2] * dims[1] + c[1]) * dims[0] + c[0];
    const EMPTY: u32 = u32::MAX;
    let mut head = vec![EMPTY; dims[0] * dims[1] * dims[2]];
    let mut next = vec![EMPTY; points.len()];
    let r2 = radius * radius;
    let mut accepted = Vec::new();
    for &i in order {
        let p = points[i];
        let c = cell_of(&p);
        let mut free = true;
        'scan: for z in c[2].saturating_sub(1)..=(c[2] + 1).min(dims[2] - 1) {
            for y in c[1].saturating_sub(1)..=(c[1] + 1).min(dims[1] - 1) {
                for x in c[0].saturating_sub(1)..=(c[0] + 1).min(dims[0] - 1) {
                    let mut k = head[flat([x, y, z])];
                    while k != EMPTY {
                        if dist2(points[k as usize], p) < r2 {
                            free = false;
                            break 'scan;
                        }
                        k = next[k as usize];
                    }
                }
            }
        }
        if free {
            let f = flat(c);
            next[i] = head[f];
            head[f] = i as u32;
            accepted.push(i);
        }
    }
    accepted.sort_unstable();
    accepted
}

/// Poisson-disc sample of the subject's whole (union) surface with minimum distance `spacing`.
pub(super) fn poisson_surface(
    geom: &SubjectGeometry,
    spacing: f64,
    rng: &mut Rng,
) -> (Vec<P3>, Vec<Material>) {
    let (points, materials) = surface_candidates(geom, spacing, rng);
    let mut order: Vec<usize> = (0..points.len()).collect();
    shuffle(&mut order, rng);
    let keep = dart_throw(&points, &order, spacing);
    (
        keep.iter().map(|&i| points[i]).collect(),
        keep.iter().map(|&i| materials[i]).collect(),
    )
}
