//! `ribreg sample`: Poisson-disc sampling of a surface mesh (PLY, OBJ or STL, as a 3D
//! Slicer or MeshLab segmentation export), the paper's way of turning the segmented CT
//! cartilage into a point cloud.
//!
//! Candidates are drawn uniformly over the surface (a triangle with probability
//! proportional to its area, a uniform point inside it), [`CANDIDATES_PER_DISC`] of them
//! per `spacing²` of area; dart throwing then keeps a candidate only if no kept point is
//! closer than `spacing`. The result is seeded and deterministic, and no two points are
//! closer than `spacing`.

use crate::io::Mesh;
use crate::phantom::sampling::dart_throw;
use ribreg_core::math::rng::Rng;

/// Candidates per `spacing²` of surface: enough that the kept set is close to maximal.
pub const CANDIDATES_PER_DISC: f64 = 12.0;
/// Most candidates drawn (about 180 MB of work): a finer spacing is refused.
pub const MAX_CANDIDATES: usize = 20_000_000;

/// Why a mesh cannot be sampled.
#[derive(Clone, Debug, PartialEq)]
pub enum SampleError {
    /// The spacing is not a positive finite number.
    Spacing(f64),
    /// The mesh has no triangle of positive area.
    NoArea,
    /// The spacing asks for more candidates than [`MAX_CANDIDATES`].
    TooFine {
        /// Surface area, mm².
        area: f64,
        /// The smallest spacing accepted for this area, mm.
        min_spacing: f64,
    },
}

impl std::fmt::Display for SampleError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SampleError::Spacing(s) => {
                write!(f, "spacing {s} mm: expected a positive number of mm")
            }
            SampleError::NoArea => f.write_str("the mesh has no triangle of positive area"),
            SampleError::TooFine { area, min_spacing } => write!(
                f,
                "a {area:.0} mm² surface needs a spacing of at least {min_spacing:.3} mm here"
            ),
        }
    }
}

impl std::error::Error for SampleError {}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn area(m: &Mesh, t: &[u32; 3]) -> f64 {
    let [a, b, c] = t.map(|i| m.vertices.get(i as usize).copied().unwrap_or([f64::NAN; 3]));
    let (u, v) = (sub(b, a), sub(c, a));
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    let a2 = 0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if a2.is_finite() {
        a2
    } else {
        0.0
    }
}

/// A Poisson-disc sample of the surface of `mesh` with minimum distance `spacing` (mm).
pub fn poisson_disc(mesh: &Mesh, spacing: f64, seed: u64) -> Result<Vec<[f64; 3]>, SampleError> {
    if !spacing.is_finite() || spacing <= 0.0 {
        return Err(SampleError::Spacing(spacing));
    }
    // Cumulative areas for area-weighted triangle choice.
    let mut cdf = Vec::with_capacity(mesh.triangles.len());
    let mut total = 0.0;
    for t in &mesh.triangles {
        total += area(mesh, t);
        cdf.push(total);
    }
    if total <= 0.0 {
        return Err(SampleError::NoArea);
    }
    let wanted = (CANDIDATES_PER_DISC * total / (spacing * spacing)).ceil();
    if wanted > MAX_CANDIDATES as f64 {
        let min_spacing = (CANDIDATES_PER_DISC * total / MAX_CANDIDATES as f64).sqrt();
        return Err(SampleError::TooFine {
            area: total,
            min_spacing,
        });
    }
    let mut rng = Rng::new(seed);
    let candidates: Vec<[f64; 3]> = (0..wanted as usize)
        .map(|_| {
            let x = rng.next_f64() * total;
            let k = cdf
                .partition_point(|&c| c <= x)
                .min(mesh.triangles.len() - 1);
            let [a, b, c] = mesh.triangles[k].map(|i| mesh.vertices[i as usize]);
            // Uniform in the triangle: fold the unit square onto it.
            let (mut r, mut s) = (rng.next_f64(), rng.next_f64());
            if r + s > 1.0 {
                (r, s) = (1.0 - r, 1.0 - s);
            }
            let (u, v) = (sub(b, a), sub(c, a));
            [
                a[0] + r * u[0] + s * v[0],
                a[1] + r * u[1] + s * v[1],
                a[2] + r * u[2] + s * v[2],
            ]
        })
        .collect();
    let order: Vec<usize> = (0..candidates.len()).collect();
    Ok(dart_throw(&candidates, &order, spacing)
        .into_iter()
        .map(|i| candidates[i])
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 100 × 60 mm rectangle as two triangles, plus a degenerate one.
    fn sheet() -> Mesh {
        Mesh {
            vertices: vec![
                [0.0, 0.0, 5.0],
                [100.0, 0.0, 5.0],
                [100.0, 60.0, 5.0],
                [0.0, 60.0, 5.0],
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3], [0, 0, 1]],
        }
    }

    #[test]
    fn spacing_holds_and_the_surface_is_covered() {
        let pts = poisson_disc(&sheet(), 2.0, 7).unwrap();
        for (i, p) in pts.iter().enumerate() {
            assert!(
                (p[2] - 5.0).abs() < 1e-9
                    && (0.0..=100.0).contains(&p[0])
                    && (0.0..=60.0).contains(&p[1])
            );
            for q in &pts[i + 1..] {
                let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
                assert!(d >= 2.0, "{p:?} {q:?}");
            }
        }
        // Maximal-ish: every probe of the interior has a sample within 2 spacings.
        for x in (2..99).step_by(3) {
            for y in (2..59).step_by(3) {
                let near = pts
                    .iter()
                    .any(|p| (p[0] - f64::from(x)).powi(2) + (p[1] - f64::from(y)).powi(2) < 16.0);
                assert!(near, "hole at ({x}, {y})");
            }
        }
        assert_eq!(pts, poisson_disc(&sheet(), 2.0, 7).unwrap());
        assert_ne!(pts, poisson_disc(&sheet(), 2.0, 8).unwrap());
    }

    #[test]
    fn bad_input() {
        assert_eq!(
            poisson_disc(&sheet(), 0.0, 1),
            Err(SampleError::Spacing(0.0))
        );
        assert!(matches!(
            poisson_disc(&sheet(), f64::NAN, 1),
            Err(SampleError::Spacing(_))
        ));
        let flat = Mesh {
            vertices: vec![[0.0; 3]; 3],
            triangles: vec![[0, 1, 2]],
        };
        assert_eq!(poisson_disc(&flat, 1.0, 1), Err(SampleError::NoArea));
        assert!(matches!(
            poisson_disc(&sheet(), 1e-4, 1),
            Err(SampleError::TooFine { .. })
        ));
    }
}
